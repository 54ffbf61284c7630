"""The paper's feature generator: a StyleGAN2-like U-Net of modulated face convolutions over the
quad hierarchy, coarsest level first (``generator.kind: faceconv``)."""

from __future__ import annotations

import torch
from torch import nn

from mesh2tex.nn.batch import MeshBatch
from mesh2tex.nn.faceconv import ModulatedFaceConv, face_unpool

from .base import FeatureSynthesis


class SynthesisBlock(nn.Module):
    """One level of the synthesis U-Net: two modulated face convolutions and a per-face toRGB."""

    def __init__(self, in_channels: int, skip_channels: int, out_channels: int, w_dim: int, conv_clamp: float | None):
        super().__init__()
        self.conv0 = ModulatedFaceConv(in_channels + skip_channels, out_channels, w_dim, clamp=conv_clamp)
        self.conv1 = ModulatedFaceConv(out_channels, out_channels, w_dim, clamp=conv_clamp)
        self.torgb = ModulatedFaceConv(
            out_channels,
            3,
            w_dim,
            kernel_size=1,
            demodulate=False,
            activation="linear",
            use_noise=False,
            clamp=conv_clamp,
        )

    def forward(self, x, skip, neighbors, ws, sample_index, noise_mode):
        """x: (F, in) or None, skip: (F, skip), ws: (B, 3, w_dim) -> (features (F, out), rgb (F, 3))."""
        x = skip if x is None else torch.cat([x, skip.to(x.dtype)], dim=1)
        x = self.conv0(x, neighbors, ws[:, 0], sample_index, noise_mode)
        x = self.conv1(x, neighbors, ws[:, 1], sample_index, noise_mode)
        rgb = self.torgb(x, neighbors, ws[:, 2], sample_index, noise_mode)
        return x, rgb


class FaceConvSynthesis(nn.ModuleList, FeatureSynthesis):
    """The synthesis U-Net: block i works on level L-1-i (coarsest first), three ws per block
    (conv0, conv1, toRGB), so num_ws = 3 L. Its blocks are the list's items, so that checkpoints keep
    the parameter names ``synthesis.<i>.…`` they always had."""

    def __init__(self, cfg):
        levels = cfg.num_levels
        blocks = []
        for level in reversed(range(levels)):
            in_ch = 0 if level == levels - 1 else cfg.synthesis_channels[level + 1]
            blocks.append(
                SynthesisBlock(
                    in_ch, cfg.encoder_channels[level], cfg.synthesis_channels[level], cfg.w_dim, cfg.conv_clamp
                )
            )
        super().__init__(blocks)
        self.num_ws, self.encoder_levels = self.sizes(cfg)
        self.channels = cfg.synthesis_channels[0]
        with torch.no_grad():  # a fresh proxy (and, with field_residual, psi's base) starts near grey, not saturated
            for block in self:
                block.torgb.weight.mul_(cfg.rgb_output_init)

    @classmethod
    def sizes(cls, cfg) -> tuple[int, int]:
        return 3 * cfg.num_levels, cfg.num_levels

    def __getitem__(self, index):
        if isinstance(index, slice):  # a run of blocks is a plain list (ModuleList would rebuild this class from it)
            return nn.ModuleList(list(self._modules.values())[index])
        return super().__getitem__(index)

    def forward(
        self, batch: MeshBatch, ws: torch.Tensor, encoded: list[torch.Tensor], noise_mode: str
    ) -> tuple[torch.Tensor, torch.Tensor]:
        levels = len(self)
        x = rgb = None
        for i, block in enumerate(self):
            level = levels - 1 - i
            neighbors = batch.neighbors[level]
            if x is not None:
                x = face_unpool(x, batch.pool[level], neighbors)
                rgb = face_unpool(rgb, batch.pool[level], neighbors)
            x, y = block(x, encoded[level], neighbors, ws[:, 3 * i : 3 * i + 3], batch.shape_index[level], noise_mode)
            rgb = y if rgb is None else rgb + y
        return x, rgb

    def transfer_parameters(self, num_blocks: int) -> list[nn.Parameter]:
        return [p for block in self[-num_blocks:] for p in block.parameters()]
