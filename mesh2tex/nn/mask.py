"""The mask network: a U-Net that finds the object in a photo, for the photos that come without a mask.

GrabCut alone separates an object from a plain wall, but not from a busy one (a brick wall, a
table with things on it): it models the background by the photo's border colours only. This network
is trained on the world's renders placed at random sizes and positions over backdrops (sharp
photographs and drawn clutter, :mod:`mesh2tex.synthetic.backdrops`); GrabCut then refines its edges
(:mod:`mesh2tex.transfer.mask`). Same encoder-decoder as the NOC network
(:class:`mesh2tex.nn.noc.NocUNet`), RGB in, one logit per pixel out.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from mesh2tex.checks import check_shape
from mesh2tex.nn.noc import NocUNet


class MaskUNet(NocUNet):
    """U-Net from RGB to the object's logit.

    ``forward(images)``: images [B, 3, H, W] float RGB in [-1, 1], any H, W. Returns logits
    [B, 1, H, W] (object where > 0; ``torch.sigmoid`` gives the probability).
    """

    def __init__(self, width: int = 16, depth: int = 4):
        super().__init__(width=width, depth=depth, in_channels=3, out_channels=1)

    def forward(self, images: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        check_shape(images, "MaskUNet: images", ("B", 3, "H", "W"), dtype="float")
        return self.logits(images)


def mask_loss(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Binary cross-entropy plus soft Dice (the Dice term keeps thin parts, a small share of the pixels,
    from being given up): logits, target [B, 1, H, W], target in {0, 1}; scalar."""
    bce = F.binary_cross_entropy_with_logits(logits, target)
    probability = torch.sigmoid(logits)
    overlap = (probability * target).sum(dim=(1, 2, 3))
    dice = 1 - (2 * overlap + 1) / (probability.sum(dim=(1, 2, 3)) + target.sum(dim=(1, 2, 3)) + 1)
    return bce + dice.mean()


def mask_iou(logits: torch.Tensor, target: torch.Tensor) -> float:
    """Mean intersection over union of the thresholded prediction (logit > 0) and target [B, 1, H, W]."""
    predicted = logits > 0
    truth = target > 0.5
    union = (predicted | truth).sum(dim=(1, 2, 3)).float()
    inter = (predicted & truth).sum(dim=(1, 2, 3)).float()
    return float((inter / union.clamp_min(1.0)).mean())
