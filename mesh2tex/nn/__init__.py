"""Neural networks on quad-mesh hierarchies: face convolutions, the texture generator, the neural
field psi, the image discriminator, and the rendering of generated textures.

Modules: ``batch`` (concatenating prepared shapes), ``faceconv`` (layers), ``generator``,
``field``, ``discriminator``, ``render_texture`` (imports the rasterizer; import it directly),
``pose`` and ``noc`` (the transfer's image networks) with ``view_nets`` (their config and
construction), ``vgg`` (style features).
"""

from mesh2tex.nn.batch import MeshBatch, collate_shapes
from mesh2tex.nn.discriminator import Discriminator, DiscriminatorConfig
from mesh2tex.nn.faceconv import (
    FaceConv,
    FaceResNetBlock,
    ModulatedFaceConv,
    face_pool,
    face_unpool,
    gather_neighborhood,
)
from mesh2tex.nn.field import NeuralField, sorted_cdf_coordinates, vertex_features
from mesh2tex.nn.generator import FaceTexture, GeneratorConfig, TextureGenerator

__all__ = [
    "MeshBatch",
    "collate_shapes",
    "Discriminator",
    "DiscriminatorConfig",
    "FaceConv",
    "FaceResNetBlock",
    "ModulatedFaceConv",
    "face_pool",
    "face_unpool",
    "gather_neighborhood",
    "NeuralField",
    "sorted_cdf_coordinates",
    "vertex_features",
    "FaceTexture",
    "GeneratorConfig",
    "TextureGenerator",
]
