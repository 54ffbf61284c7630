"""What every texture mesh2tex makes has in common: bound to the triangles of one surface, it gives
the colour at any point of them (:class:`SurfaceTexture`). Renderers, bakers and writers take such an
object, so a new kind of texture needs no new plumbing.

The kinds: a generator's field on a batch of shapes (:class:`mesh2tex.nn.generator.FaceTexture`,
returned by ``TextureGenerator.synthesize``), an automaton's cell states on its cell mesh
(:class:`mesh2tex.nn.nca.AutomatonTexture`), and a UV image on a mesh (:class:`UVTexture`).
Colours are RGB in [-1, 1] (the networks' range; files hold [0, 1] or uint8, see
:func:`mesh2tex.io.images.colours_to_uint8`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import torch

from mesh2tex.checks import check_shape

from .interpolate import sample_texture


class SurfaceTexture(Protocol):
    """A texture bound to one surface's triangles."""

    def colours(self, triangle_id: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
        """triangle_id (P,) int64 indices of the surface's triangles, bary (P, 3) float barycentrics
        -> RGB (P, 3) in [-1, 1] (nominally: a network's colours may stray a little)."""
        ...


COLOUR_CHUNK = 262_144  # surface points read at once by a baker: bounds a field's activations (about 1 GB at this size)


def read_colours(
    texture: SurfaceTexture, triangle_id: torch.Tensor, bary: torch.Tensor, device=None, chunk: int = COLOUR_CHUNK
) -> torch.Tensor:
    """``texture.colours`` at P surface points, ``chunk`` at a time on ``device`` (default: the points'):
    triangle_id (P,) int, bary (P, 3) float -> (P, 3) float32 on the CPU, RGB in [-1, 1]. A 2048^2 bake
    asks for millions of points; a network's field holds activations for all it is given at once."""
    sizes = check_shape(triangle_id, "read_colours: triangle_id", ("P",), dtype="int")
    check_shape(bary, "read_colours: bary", ("P", 3), sizes=sizes, dtype="float")
    device = triangle_id.device if device is None else device
    out = [
        texture.colours(triangle_id[start : start + chunk].to(device), bary[start : start + chunk].to(device))
        .float()
        .cpu()
        for start in range(0, len(triangle_id), chunk)
    ]
    return torch.cat(out) if out else torch.zeros(0, 3)


@dataclass
class UVTexture:
    """A UV image on a triangle mesh: ``uv`` (T, 3, 2) per-corner texture coordinates (u right, v up)
    of the mesh's T triangles, ``image`` (1, 3, H, W) float in [-1, 1]; bilinear lookups."""

    uv: torch.Tensor
    image: torch.Tensor

    def __post_init__(self):
        check_shape(self.uv, "UVTexture: uv", (None, 3, 2), dtype="float")
        check_shape(self.image, "UVTexture: image", (1, 3, None, None), dtype="float")

    def colours(self, triangle_id: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
        sizes = check_shape(triangle_id, "UVTexture.colours: triangle_id", ("P",), dtype="int")
        check_shape(bary, "UVTexture.colours: bary", ("P", 3), sizes=sizes, dtype="float")
        corners = self.uv[triangle_id]  # (P, 3, 2)
        uv = (corners * bary.to(corners.dtype)[..., None]).sum(1)  # (P, 2)
        return sample_texture(self.image, uv.reshape(1, 1, -1, 2)).reshape(-1, 3)
