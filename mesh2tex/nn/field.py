"""The neural field psi: colour at any point of a face from blended vertex features.

psi(p, b1 F_v1 + b2 F_v2 + b3 F_v3) = c, where (v1, v2, v3) is the triangle half of the quad face
in which the point p lies, b its barycentric coordinates and F_v the mean feature of the quad faces
incident to vertex v. Besides the blended feature, the MLP sees a local coordinate encoding of p and
a learnt auxiliary latent (one vector for the whole model). Layout of the MLP: two layers on
[feature, coordinates], two layers on the auxiliary latent, concatenated, four more layers, the last
one linear to RGB; LeakyReLU(0.2) in between.

Local coordinates (``coords``):
    "raw"         the barycentrics (b1, b2, b3) rescaled to [-1, 1]; depend on the vertex order of the
                  triangle, so they jump across edges.
    "sorted_cdf"  the barycentrics sorted descending (a >= b >= c), which makes them identical on both
                  sides of a shared edge, each then pushed through the CDF of its exact distribution
                  under uniform sampling of a triangle (triangular distributions Tri(1/3,1,1/2),
                  Tri(0,1/2,1/3), Tri(0,1/3,0)) and rescaled to [-1, 1], which balances their ranges.
"""

from __future__ import annotations

import torch
from torch import nn

from mesh2tex.checks import check_shape
from mesh2tex.nn.faceconv import FullyConnected, take_rows

COORDINATE_MODES = ("raw", "sorted_cdf")
# (left, right, mode) of the triangular distribution of the largest, middle and smallest barycentric.
_SORTED_BARY_DISTRIBUTIONS = ((1.0 / 3.0, 1.0, 0.5), (0.0, 0.5, 1.0 / 3.0), (0.0, 1.0 / 3.0, 0.0))


def triangular_cdf(x: torch.Tensor, left: float, right: float, mode: float) -> torch.Tensor:
    """CDF of Tri(left, right, mode) at x (any shape), clamped to [0, 1]."""
    x = x.clamp(left, right)
    rising = (x - left).square() / max((right - left) * (mode - left), 1e-12)
    falling = 1.0 - (right - x).square() / max((right - left) * (right - mode), 1e-12)
    return torch.where(x < mode, rising, falling).clamp(0.0, 1.0)


def sorted_cdf_coordinates(bary: torch.Tensor) -> torch.Tensor:
    """(P, 3) barycentrics -> (P, 3) in [-1, 1]: sorted descending, CDF-remapped, rescaled."""
    top = bary.max(dim=1).values
    low = bary.min(dim=1).values
    mid = 1.0 - top - low
    parts = [triangular_cdf(v, *dist) for v, dist in zip((top, mid, low), _SORTED_BARY_DISTRIBUTIONS)]
    return torch.stack(parts, dim=1) * 2.0 - 1.0


def local_coordinates(bary: torch.Tensor, mode: str) -> torch.Tensor:
    """(P, 3) barycentrics -> (P, 3) local coordinate encoding in [-1, 1] (see the module docstring)."""
    if mode == "raw":
        return bary * 2.0 - 1.0
    if mode == "sorted_cdf":
        return sorted_cdf_coordinates(bary)
    raise ValueError(f"unknown coordinate mode {mode!r}; expected one of {COORDINATE_MODES}")


def vertex_features(face_features: torch.Tensor, quads: torch.Tensor, num_vertices: int) -> torch.Tensor:
    """Mean feature of the quad faces incident to each vertex.

    face_features: (F, C) float, quads: (F, 4) int64 -> (V, C); a vertex used by no face gets zeros.
    """
    check_shape(
        quads,
        "vertex_features: quads",
        ("F", 4),
        sizes=check_shape(face_features, "vertex_features: face_features", ("F", "C"), dtype="float"),
        dtype="int",
    )
    index = quads.reshape(-1)
    summed = face_features.new_zeros(num_vertices, face_features.shape[1])
    summed = summed.index_add(0, index, face_features.repeat_interleave(4, dim=0))
    counts = torch.zeros(num_vertices, device=index.device, dtype=face_features.dtype).index_add_(
        0, index, torch.ones_like(index, dtype=face_features.dtype)
    )
    return summed / counts.clamp(min=1.0).unsqueeze(1)


def blend_vertex_features(
    vertex_feats: torch.Tensor, triangles: torch.Tensor, triangle_id: torch.Tensor, bary: torch.Tensor
) -> torch.Tensor:
    """b1 F_v1 + b2 F_v2 + b3 F_v3 at points. vertex_feats (V, C), triangles (T, 3), triangle_id (P,), bary (P, 3) ->
    (P, C)."""
    corners = take_rows(vertex_feats, triangles[triangle_id])  # (P, 3, C)
    return (corners * bary.unsqueeze(2).to(corners.dtype)).sum(1)


class NeuralField(nn.Module):
    """psi: (blended feature (P, C), barycentrics (P, 3)) -> colour (P, 3), nominally in [-1, 1].

    The output layer is linear (as StyleGAN's toRGB): values may leave [-1, 1] slightly during
    training; files clamp them. ``output_init`` scales that layer's initial weights: at 1 the fresh
    MLP maps every point to one saturated colour (its mean reaches +-1.9 per channel for some
    seeds), which a short run at the paper's small psi learning rate cannot undo; at 0.1 training
    starts from grey.
    """

    def __init__(
        self, feature_dim: int, hidden: int = 128, aux_dim: int = 512, coords: str = "raw", output_init: float = 1.0
    ):
        super().__init__()
        if coords not in COORDINATE_MODES:
            raise ValueError(f"unknown coordinate mode {coords!r}; expected one of {COORDINATE_MODES}")
        self.coords = coords
        self.aux_latent = nn.Parameter(torch.randn(aux_dim))
        self.feature_branch = nn.Sequential(
            FullyConnected(feature_dim + 3, hidden, activation="lrelu"),
            FullyConnected(hidden, hidden, activation="lrelu"),
        )
        self.aux_branch = nn.Sequential(
            FullyConnected(aux_dim, hidden, activation="lrelu"), FullyConnected(hidden, hidden, activation="lrelu")
        )
        self.head = nn.Sequential(
            FullyConnected(2 * hidden, hidden, activation="lrelu"),
            FullyConnected(hidden, hidden, activation="lrelu"),
            FullyConnected(hidden, hidden, activation="lrelu"),
            FullyConnected(hidden, 3),
        )
        with torch.no_grad():
            self.head[-1].weight.mul_(output_init)

    def forward(self, features: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
        """features: (P, C) blended vertex features, bary: (P, 3) float -> (P, 3) RGB."""
        points = check_shape(
            features, "NeuralField: features", ("P", self.feature_branch[0].weight.shape[1] - 3), dtype="float"
        )
        check_shape(bary, "NeuralField: bary", ("P", 3), sizes=points, dtype="float")
        coords = local_coordinates(bary, self.coords).to(features.dtype)
        local = self.feature_branch(torch.cat([features, coords], dim=1))
        aux = self.aux_branch(self.aux_latent.unsqueeze(0).to(features.dtype))  # (1, hidden), the same for every point
        return self.head[1:](self.head[0](local, shared=aux))  # the head's input is [local ‖ aux]
