"""How a set of views is rendered: one frozen record, checked once, passed whole.

A render's settings used to travel as loose arguments (a resolution here, a supersampling factor
there, a lighting string elsewhere) with each receiver trusting, or checking again, what it got.
:class:`RenderSettings` (PyTorch3D's ``RasterizationSettings`` is the model) holds them together and
refuses bad values when it is made, so every function that takes one can rely on it. Commands keep
their flat config fields (``resolution``, ``supersample``) and make one of these from them.

Backgrounds are not a setting: each view brings its own (a synthetic photo's backdrop, the GAN's
random colours), so they travel with the views.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from mesh2tex.limits import MAX_RESOLUTION

LIGHTING = ("photo", "albedo")  # Lambert-shaded with each view's light and ambient share, or the unlit albedo
MAX_SUPERSAMPLE = 8  # 64 sub-pixels per pixel: beyond it the box filter gains nothing a photo would show


@dataclass(frozen=True)
class RenderSettings:
    """The images a render hands back and how they are made.

    Attributes:
        resolution: side of the square images handed back, pixels (1 to ``MAX_RESOLUTION``).
        supersample: the mesh is rasterized at ``resolution * supersample`` and each block of
            ``supersample`` x ``supersample`` sub-pixels averaged (a box filter, the antialiasing of the
            synthetic world's photos); 1: one sample per pixel.
        lighting: "photo" (Lambert with each view's light) or "albedo" (unlit).
    """

    resolution: int
    supersample: int = 1
    lighting: str = "photo"

    def __post_init__(self):
        for name, value, top in (
            ("resolution", self.resolution, MAX_RESOLUTION),
            ("supersample", self.supersample, MAX_SUPERSAMPLE),
        ):
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= top:
                raise ValueError(f"render settings: {name} must be a whole number from 1 to {top}, got {value!r}")
        if self.raster_side > MAX_RESOLUTION * 2:
            raise ValueError(
                f"render settings: resolution {self.resolution} x supersample {self.supersample} rasterizes "
                f"{self.raster_side} px a side, more than {MAX_RESOLUTION * 2}"
            )
        if self.lighting not in LIGHTING:
            raise ValueError(f"render settings: lighting must be one of {', '.join(LIGHTING)}, got {self.lighting!r}")

    @property
    def raster_side(self) -> int:
        """Side of the rasterized image, pixels: ``resolution * supersample``."""
        return self.resolution * self.supersample

    @property
    def lit(self) -> bool:
        return self.lighting == "photo"

    def down(self, images: torch.Tensor) -> torch.Tensor:
        """(N, C, S, S) at ``raster_side`` -> (N, C, R, R) at ``resolution`` by the box filter."""
        return images if self.supersample == 1 else F.avg_pool2d(images, self.supersample)

    def down_channels_last(self, images: torch.Tensor) -> torch.Tensor:
        """(N, S, S, C) at ``raster_side`` -> (N, R, R, C) at ``resolution`` by the box filter."""
        return images if self.supersample == 1 else self.down(images.permute(0, 3, 1, 2)).permute(0, 2, 3, 1)
