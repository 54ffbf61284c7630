"""Differentiable augmentation of the discriminators' inputs (the DiffAugment recipe).

With a few dozen photos a discriminator memorises them and its gradients stop telling the
generator anything; augmenting every image the discriminators see, real and fake alike, with the
same random transforms keeps it honest. The transforms are differentiable, so the generator's
gradient passes through them. Each one is applied to a sample with probability ``p`` (1: always,
as DiffAugment does; lower values approach ADA's regime, where the augmentations cannot leak into
the generated distribution).

Augmentation also hides from the discriminator what it should judge: at ``p`` 1 the colour
jitter (saturation x0 to x2, brightness +-1/2) makes a generator that paints every chair one
grey-brown hard to tell from the varied photos (with the generator held still, a fresh
discriminator was still at chance after 120 steps with augmentation, and at a loss of 0.33 without
it). So by default ``p`` adapts as StyleGAN2-ADA's does (:class:`AdaptiveAugment`): it starts at 0
and rises only while the discriminator overfits the photos, measured by r_t = E[sign D(real)].

    color        brightness x + u - 1/2, saturation (x - mean_c) * 2u + mean_c, contrast
                 (x - mean) * (u + 1/2) + mean, with u ~ U(0, 1) per sample and transform
    translation  shift by up to ``translation_ratio`` of the side in x and y (integer pixels), the
                 uncovered border filled with 0 (grey in [-1, 1])
    cutout       a square of ``cutout_ratio`` of the side at a random position set to 0
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from mesh2tex.checks import check_shape
from mesh2tex.config import check_fields

TRANSFORMS = ("color", "translation", "cutout")


@dataclass
class AugmentConfig:
    policy: str = "color,translation,cutout"  # comma-separated transforms of TRANSFORMS ("" disables)
    p: float = 0.0  # probability that each transform is applied to a sample (with ada_target > 0: its start value)
    ada_target: float = 0.6  # adapt p so that E[sign D(real)] stays at this value (StyleGAN2-ADA's 0.6; 0: p fixed)
    ada_interval: int = 4  # iterations between adjustments of p
    ada_images: float = 50000.0  # rendered images over which p can move by 1 (ADA's speed; theirs is 500k)
    translation_ratio: float = 0.125  # largest shift, as a fraction of the image side
    cutout_ratio: float = 0.5  # side of the cut-out square, as a fraction of the image side

    def __post_init__(self):
        check_fields(
            self,
            between={
                "p": (0.0, 1.0),
                "ada_target": (0.0, 1.0),
                "translation_ratio": (0.0, 1.0),
                "cutout_ratio": (0.0, 1.0),
            },
            at_least={"ada_interval": 1},
            positive=("ada_images",),
        )


def parse_policy(policy: str) -> list[str]:
    """``"color,translation"`` -> ["color", "translation"]; raises ValueError on an unknown name."""
    names = [name.strip() for name in policy.split(",") if name.strip()]
    for name in names:
        if name not in TRANSFORMS:
            raise ValueError(
                f"unknown augmentation {name!r}; expected a comma-separated list of {', '.join(TRANSFORMS)}"
            )
    return names


def _applied(n: int, p: float, device: torch.device) -> torch.Tensor:
    """(n, 1, 1, 1) float 0/1: which samples a transform touches."""
    if p >= 1.0:
        return torch.ones(n, 1, 1, 1, device=device)
    return (torch.rand(n, 1, 1, 1, device=device) < p).float()


def augment_colour(x: torch.Tensor, p: float = 1.0) -> torch.Tensor:
    """Random brightness, saturation and contrast. x: (N, C, H, W) float in [-1, 1] -> same shape."""
    check_shape(x, "augment_colour: x", ("N", "C", "H", "W"), dtype="float")
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
    """Shift each image by whole pixels, up to ``ratio`` of its side; border filled with 0. x: (N, C, H, W) float."""
    check_shape(x, "augment_translation: x", ("N", "C", "H", "W"), dtype="float")
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
    """Zero a square of ``ratio`` of the side at a random centre of each image. x: (N, C, H, W) float."""
    check_shape(x, "augment_cutout: x", ("N", "C", "H", "W"), dtype="float")
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
        self.cfg = cfg or AugmentConfig(p=1.0, ada_target=0.0)
        self.transforms = parse_policy(self.cfg.policy)
        if not 0.0 <= self.cfg.p <= 1.0:
            raise ValueError(f"augmentation probability p must be in [0, 1], got {self.cfg.p}")
        self.p = float(self.cfg.p)  # the probability in force; AdaptiveAugment moves it

    @property
    def enabled(self) -> bool:
        return bool(self.transforms) and self.p > 0

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        """x: (N, C, H, W) float -> augmented (N, C, H, W)."""
        check_shape(x, "DiffAugment: x", ("N", "C", "H", "W"), dtype="float")
        if not self.enabled:
            return x
        c, p = self.cfg, self.p
        for name in self.transforms:
            if name == "color":
                x = augment_colour(x, p)
            elif name == "translation":
                x = augment_translation(x, c.translation_ratio, p)
            else:
                x = augment_cutout(x, c.cutout_ratio, p)
        return x.contiguous()


class AdaptiveAugment:
    """StyleGAN2-ADA's controller of the augmentation probability.

    The trainer reports the mean sign of the discriminators' real logits every iteration
    (:meth:`observe`); every ``ada_interval`` iterations ``p`` moves by
    sign(r_t - ada_target) * images / ada_images, r_t the mean of the reports since the last move,
    clamped to [0, 1]. A discriminator that overfits the photos calls them real ever more surely
    (r_t -> 1) and gets more augmentation; one near chance (r_t ~ 0) gets less.
    """

    def __init__(self, augment: DiffAugment):
        self.augment = augment
        self.sign_sum, self.count = 0.0, 0

    @property
    def adaptive(self) -> bool:
        return self.augment.cfg.ada_target > 0 and bool(self.augment.transforms)

    def observe(self, sign_real: float) -> None:
        """sign_real: mean of sign(D(real logits)) over this iteration's real images, in [-1, 1]."""
        self.sign_sum += float(sign_real)
        self.count += 1

    def step(self, iteration: int, images_per_iteration: int) -> None:
        """Call once per iteration, after :meth:`observe`, with the iteration just finished (0-based)."""
        cfg = self.augment.cfg
        if not self.adaptive or (iteration + 1) % cfg.ada_interval or self.count == 0:
            return
        r_t = self.sign_sum / self.count
        move = (1.0 if r_t > cfg.ada_target else -1.0) * images_per_iteration * cfg.ada_interval / cfg.ada_images
        self.augment.p = min(max(self.augment.p + move, 0.0), 1.0)
        self.sign_sum, self.count = 0.0, 0

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {
            "augment_p": torch.tensor(self.augment.p, dtype=torch.float64),
            "augment_sign_sum": torch.tensor(self.sign_sum, dtype=torch.float64),
            "augment_count": torch.tensor(self.count, dtype=torch.int64),
        }

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        """Missing keys (a checkpoint written before the controller) keep the config's p."""
        if "augment_p" in state:
            self.augment.p = float(state["augment_p"])
            self.sign_sum = float(state["augment_sign_sum"])
            self.count = int(state["augment_count"])
