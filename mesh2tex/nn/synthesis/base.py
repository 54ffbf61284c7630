"""What every feature generator of the texture GAN provides (:class:`FeatureSynthesis`).

A feature generator turns the latent styles ws and the geometry encoder's per-level features into
per-face features F_c and per-face colours (the proxy texture) on the finest level; the neural field
psi and everything downstream (rendering, baking, transfer, evaluation) read only those two.
"""

from __future__ import annotations

import torch
from torch import nn

from mesh2tex.nn.batch import MeshBatch


class FeatureSynthesis(nn.Module):
    """The interface of a feature generator; a kind subclasses it and registers in
    :data:`mesh2tex.nn.synthesis.SYNTHESIS_KINDS`.

    Attributes a kind sets in ``__init__``:
        num_ws: how many w vectors it reads (the mapping network repeats w that many times).
        channels: C, the width of the per-face features F_c it returns.
        encoder_levels: how many levels of the geometry encoder it reads (finest first): the encoder
            builds no coarser levels than that, so that none trains for nothing.
    """

    num_ws: int
    channels: int
    encoder_levels: int

    @classmethod
    def sizes(cls, cfg) -> tuple[int, int]:
        """(num_ws, encoder_levels) of this kind under a ``GeneratorConfig``, known before the kind is
        built: the generator builds its encoder and mapping first (the order its weights are drawn in)."""
        raise NotImplementedError

    def forward(
        self, batch: MeshBatch, ws: torch.Tensor, encoded: list[torch.Tensor], noise_mode: str
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """ws (B, num_ws, w_dim), one row per shape; encoded: E_0 (F_0, c_0), ... for ``encoder_levels``
        levels -> (features F_c (F_0, channels), colours (F_0, 3) nominally in [-1, 1])."""
        raise NotImplementedError

    def transfer_parameters(self, num_blocks: int) -> list[nn.Parameter]:
        """The parameters texture transfer fine-tunes after the latent (stage 2), the finest
        ``num_blocks`` blocks where the kind has blocks."""
        raise NotImplementedError
