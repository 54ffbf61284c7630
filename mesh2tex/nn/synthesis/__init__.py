"""The texture GAN's feature generators, one file per kind, registered here by the name
``generator.kind`` takes (:class:`mesh2tex.nn.synthesis.base.FeatureSynthesis` is what each provides).

A new kind: a file beside these with a ``FeatureSynthesis`` subclass taking the ``GeneratorConfig``,
and one line in :data:`SYNTHESIS_KINDS`.
"""

from .automaton import AutomatonSynthesis
from .base import FeatureSynthesis
from .faceconv import FaceConvSynthesis, SynthesisBlock

SYNTHESIS_KINDS: dict[str, type[FeatureSynthesis]] = {
    "faceconv": FaceConvSynthesis,
    "nca": AutomatonSynthesis,
}

__all__ = ["SYNTHESIS_KINDS", "AutomatonSynthesis", "FaceConvSynthesis", "FeatureSynthesis", "SynthesisBlock"]
