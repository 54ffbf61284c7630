"""A mesh cellular automaton as the GAN's feature generator (``generator.kind: nca``): cells on the
finest vertices, conditioned on w and on the encoder's finest features E_0
(:class:`mesh2tex.nn.nca.ConditionedNCA`); F_c is the mean state of each face's corners and a linear
readout of it the face colour."""

from __future__ import annotations

import torch
from torch import nn

from mesh2tex.nn.batch import MeshBatch
from mesh2tex.nn.nca import ConditionedNCA

from .base import FeatureSynthesis


class AutomatonSynthesis(FeatureSynthesis):
    """num_ws = 1 (one w conditions every cell); reads E_0 only (encoder_levels = 1)."""

    def __init__(self, cfg):
        super().__init__()
        self.num_ws, self.encoder_levels = self.sizes(cfg)
        self.channels = cfg.nca_channels
        self.nca = ConditionedNCA(
            channels=cfg.nca_channels,
            hidden=cfg.nca_hidden,
            steps=cfg.nca_steps,
            condition=cfg.nca_condition,
            w_dim=cfg.w_dim,
            geometry_dim=cfg.encoder_channels[0],
        )
        self.torgb = nn.Linear(cfg.nca_channels, 3)
        with torch.no_grad():
            self.torgb.weight.mul_(cfg.rgb_output_init)

    @classmethod
    def sizes(cls, cfg) -> tuple[int, int]:
        return 1, 1

    def forward(
        self, batch: MeshBatch, ws: torch.Tensor, encoded: list[torch.Tensor], noise_mode: str
    ) -> tuple[torch.Tensor, torch.Tensor]:
        states = self.nca(batch, ws[:, 0], encoded[0], noise_mode)  # (V, C)
        x = states[batch.quads].mean(1)  # (F_0, C): each face the mean of its corner cells
        return x, self.torgb(x)

    def transfer_parameters(self, num_blocks: int) -> list[nn.Parameter]:
        # the update rule and the colour readout: the automaton has no blocks to count
        return list(self.nca.update.parameters()) + list(self.torgb.parameters())

    # Checkpoints written before the kinds had one interface kept the automaton beside the synthesis
    # (``nca.…``, ``nca_torgb.…`` of the generator); TextureGenerator renames them on load.
    FORMER_PREFIXES = {"nca.": "synthesis.nca.", "nca_torgb.": "synthesis.torgb."}
