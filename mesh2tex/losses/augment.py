"""Differentiable augmentation of the discriminators' inputs (the DiffAugment recipe).

With a few dozen photos a discriminator memorises them and its gradients stop telling the
generator anything; augmenting every image the discriminators see, real and fake alike, with the
same random transforms keeps it honest. The transforms are differentiable, so the generator's
gradient passes through them. Each one is applied to a sample with probability ``p`` (1: always,
as DiffAugment does; lower values approach ADA's regime, where the augmentations cannot leak into
the generated distribution).

    color        brightness x + u - 1/2, saturation (x - mean_c) * 2u + mean_c, contrast
                 (x - mean) * (u + 1/2) + mean, with u ~ U(0, 1) per sample and transform
    translation  shift by up to ``translation_ratio`` of the side in x and y (integer pixels), the
                 uncovered border filled with 0 (grey in [-1, 1])
    cutout       a square of ``cutout_ratio`` of the side at a random position set to 0
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from mesh2tex.config import check_fields

TRANSFORMS = ("color", "translation", "cutout")


@dataclass
class AugmentConfig:
    policy: str = "color,translation,cutout"  # comma-separated transforms of TRANSFORMS ("" disables)
    p: float = 1.0  # probability that each transform is applied to a sample
    translation_ratio: float = 0.125  # largest shift, as a fraction of the image side
    cutout_ratio: float = 0.5  # side of the cut-out square, as a fraction of the image side

    def __post_init__(self):
        check_fields(self, between={"p": (0.0, 1.0), "translation_ratio": (0.0, 1.0), "cutout_ratio": (0.0, 1.0)})


def parse_policy(policy: str) -> list[str]:
    """``"color,translation"`` -> ["color", "translation"]; raises ValueError on an unknown name."""
    names = [name.strip() for name in policy.split(",") if name.strip()]
    for name in names:
        if name not in TRANSFORMS:
            raise ValueError(f"unknown augmentation {name!r}; expected a comma-separated list of {', '.join(TRANSFORMS)}")
    return names


def _applied(n: int, p: float, device: torch.device) -> torch.Tensor:
    """(n, 1, 1, 1) float 0/1: which samples a transform touches."""
    if p >= 1.0:
        return torch.ones(n, 1, 1, 1, device=device)
    return (torch.rand(n, 1, 1, 1, device=device) < p).float()


def augment_color(x: torch.Tensor, p: float = 1.0) -> torch.Tensor:
    """Random brightness, saturation and contrast. x: (N, C, H, W) in [-1, 1] -> same shape."""
    n, dev = x.shape[0], x.device
    on = _applied(n, p, dev).to(x.dtype)
    x = x + (torch.rand(n, 1, 1, 1, device=dev, dtype=x.dtype) - 0.5) * on
    mean = x.mean(dim=1, keepdim=True)
    factor = 1.0 + (torch.rand(n, 1, 1, 1, device=dev, dtype=x.dtype) * 2.0 - 1.0) * on
    x = (x - mean) * factor + mean
    mean = x.mean(dim=[1, 2, 3], keepdim=True)
    factor = 1.0 + (torch.rand(n, 1, 1, 1, device=dev, dtype=x.dtype) - 0.5) * on
    return (x - mean) * factor + mean


def augment_translation(x: torch.Tensor, ratio: float = 0.125, p: float = 1.0) -> torch.Tensor:
    """Shift each image by whole pixels, up to ``ratio`` of its side; border filled with 0. (N, C, H, W)."""
    n, _, h, w = x.shape
    dev = x.device
    on = _applied(n, p, dev).view(n, 1, 1)
    sy, sx = int(h * ratio + 0.5), int(w * ratio + 0.5)
    dy = (torch.randint(-sy, sy + 1, (n, 1, 1), device=dev) * on).long()
    dx = (torch.randint(-sx, sx + 1, (n, 1, 1), device=dev) * on).long()
    rows = torch.arange(h, device=dev).view(1, h, 1) - dy  # source row of each output row
    cols = torch.arange(w, device=dev).view(1, 1, w) - dx
    inside = ((rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)).unsqueeze(1).to(x.dtype)  # (N, 1, H, W)
    flat = (rows.clamp(0, h - 1) * w + cols.clamp(0, w - 1)).reshape(n, 1, h * w).expand(-1, x.shape[1], -1)
    moved = x.reshape(n, x.shape[1], h * w).gather(2, flat).reshape(x.shape)
    return moved * inside


def augment_cutout(x: torch.Tensor, ratio: float = 0.5, p: float = 1.0) -> torch.Tensor:
    """Zero a square of ``ratio`` of the side at a random centre of each image. (N, C, H, W)."""
    n, _, h, w = x.shape
    dev = x.device
    on = _applied(n, p, dev).view(n, 1, 1)
    ch, cw = int(h * ratio + 0.5), int(w * ratio + 0.5)
    cy = torch.randint(0, h + (1 - ch % 2), (n, 1, 1), device=dev)
    cx = torch.randint(0, w + (1 - cw % 2), (n, 1, 1), device=dev)
    rows = torch.arange(h, device=dev).view(1, h, 1)
    cols = torch.arange(w, device=dev).view(1, 1, w)
    cut = (rows >= cy - ch // 2) & (rows < cy - ch // 2 + ch) & (cols >= cx - cw // 2) & (cols < cx - cw // 2 + cw)
    keep = 1.0 - (cut.to(x.dtype) * on.to(x.dtype))
    return x * keep.unsqueeze(1)


class DiffAugment:
    """Callable augmentation of discriminator inputs: images (N, C, H, W) -> augmented (N, C, H, W).

    Raises ValueError on an unknown transform name or a probability outside [0, 1].
    """

    def __init__(self, cfg: AugmentConfig | None = None):
        self.cfg = cfg or AugmentConfig()
        self.transforms = parse_policy(self.cfg.policy)
        if not 0.0 <= self.cfg.p <= 1.0:
            raise ValueError(f"augmentation probability p must be in [0, 1], got {self.cfg.p}")

    @property
    def enabled(self) -> bool:
        return bool(self.transforms) and self.cfg.p > 0

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        if not self.enabled:
            return x
        c = self.cfg
        for name in self.transforms:
            if name == "color":
                x = augment_color(x, c.p)
            elif name == "translation":
                x = augment_translation(x, c.translation_ratio, c.p)
            else:
                x = augment_cutout(x, c.cutout_ratio, c.p)
        return x.contiguous()
