"""How well a transfer's result fits its photo at the pose it was found at, checked before the files
are written: the outline's overlap and the colours against a flat texture of the photo's mean."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F

from mesh2tex.checks import check_shape
from mesh2tex.metrics.appearance import lowpass_psnr

# Below these the result is reported as a poor fit (one warning line; the files are still written).
# The outline is compared with a pixel of tolerance: a thin leg one pixel off halves a plain IoU. On
# photos of 7 chairs from outside the world at 64 px (benchmarks/outside_transfer.py), poses found
# within 10 degrees scored 0.925-1.0 and poses turned 90 degrees 0.32-0.90 (a round stool, the same
# turned, aside).
MIN_OUTLINE_AGREEMENT = 0.9
OUTLINE_TOLERANCE_PX = 1
MIN_GAIN_OVER_FLAT_DB = 0.0  # a texture that matches the photo worse than its mean colour has failed


@dataclass
class FitCheck:
    """The result at the found pose against the photo.

    silhouette_iou: the mesh's outline (cropped like the photo) against the photo's object mask;
    outline_agreement: the same with :data:`OUTLINE_TOLERANCE_PX` of tolerance (the F-score of the
    mask pixels within that distance of the other mask); lowpass_psnr, flat_lowpass_psnr: dB over the pixels both cover
    (Gaussian sigma 3 px) for the result's render and for the photo's mean colour; ``problems``: why the fit is poor
    (empty: good)."""

    silhouette_iou: float
    outline_agreement: float
    lowpass_psnr: float
    flat_lowpass_psnr: float
    problems: list[str]

    @property
    def poor(self) -> bool:
        return bool(self.problems)

    def as_dict(self) -> dict:
        return {**asdict(self), "poor": self.poor}


@torch.no_grad()
def check_fit(
    photo_image: torch.Tensor, photo_mask: torch.Tensor, render: torch.Tensor, render_mask: torch.Tensor
) -> FitCheck:
    """Judge a transfer's render at its pose against the photo.

    photo_image, render: (1,3,R,R) in [-1,1]; photo_mask, render_mask: (1,1,R,R) {0,1}, the same crop.
    """
    sizes = check_shape(photo_image, "check_fit: photo_image", (1, 3, "R", "R"), dtype="float")
    check_shape(photo_mask, "check_fit: photo_mask", (1, 1, "R", "R"), sizes=sizes)
    check_shape(render, "check_fit: render", (1, 3, "R", "R"), sizes=sizes, dtype="float")
    check_shape(render_mask, "check_fit: render_mask", (1, 1, "R", "R"), sizes=sizes)
    photo_in = photo_mask.float().cpu() > 0.5
    render_in = render_mask.float().cpu() > 0.5
    union = float((photo_in | render_in).sum())
    iou = float((photo_in & render_in).sum()) / max(union, 1.0)
    agreement = outline_agreement(photo_in, render_in, OUTLINE_TOLERANCE_PX)
    both = (photo_in & render_in).float()
    problems = []
    if both.sum() < 16:
        return FitCheck(
            round(iou, 4),
            round(agreement, 4),
            float("nan"),
            float("nan"),
            ["the mesh and the photo's object barely overlap at the pose used"],
        )
    photo01 = (photo_image.float().cpu() + 1) / 2
    render01 = (render.float().cpu() + 1) / 2
    mean = (photo01 * both).sum(dim=(2, 3), keepdim=True) / both.sum()
    flat = mean.expand_as(photo01)
    result_db = float(lowpass_psnr(render01, photo01, both)[0])
    flat_db = float(lowpass_psnr(flat, photo01, both)[0])
    if agreement < MIN_OUTLINE_AGREEMENT:
        problems.append(
            f"the mesh's outline at the pose used agrees with the photo's object by {agreement:.2f} "
            f"(IoU {iou:.2f}): the pose or the mask may be wrong (give --pose AZ,EL or --mask FILE)"
        )
    if result_db - flat_db < MIN_GAIN_OVER_FLAT_DB:
        problems.append(
            f"the result matches the photo less than a flat colour of its mean ({result_db:.1f} dB against "
            f"{flat_db:.1f} dB low-pass PSNR at the pose used)"
        )
    return FitCheck(round(iou, 4), round(agreement, 4), round(result_db, 3), round(flat_db, 3), problems)


def outline_agreement(a: torch.Tensor, b: torch.Tensor, tolerance: int) -> float:
    """F-score of two masks (1,1,R,R) bool, each pixel counted as matched when the other mask lies within
    ``tolerance`` pixels (a square neighbourhood): 1 for outlines that agree up to the tolerance."""
    sizes = check_shape(a, "outline_agreement: a", (1, 1, "R", "R"), dtype="bool")
    check_shape(b, "outline_agreement: b", (1, 1, "R", "R"), sizes=sizes, dtype="bool")
    size = 2 * tolerance + 1

    def grown(mask: torch.Tensor) -> torch.Tensor:
        return F.max_pool2d(mask.float(), size, stride=1, padding=tolerance) > 0.5

    precision = float((a & grown(b)).sum()) / max(float(a.sum()), 1.0)
    recall = float((b & grown(a)).sum()) / max(float(b.sum()), 1.0)
    return 2 * precision * recall / max(precision + recall, 1e-9)
