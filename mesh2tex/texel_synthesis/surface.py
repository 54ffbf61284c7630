"""The surface a texture lives on (:class:`TexelSurface`, a mesh and its UV atlas), and what the direct
method's loss sees when it looks at the surface itself, not at renders: geodesic
charts (the ``surface`` method) and the ``patch`` loss's patches walked out octave by octave (the
``patches`` method). Both read the texture through the atlas's UVs at points reached by geodesic
walks in tangent frames of a direction field (:mod:`mesh2tex.geometry.geodesic`), so neither has a
camera's foreshortening or hidden parts, and both cross the atlas's seams.

Conventions: a surface is a :class:`TexelSurface` (positions (V, 3) in the unit ball, faces (T, 3),
uv (V, 2) v up); UVs returned are (..., 2) float32, v up, for
:func:`mesh2tex.render.sample_texture`; a grid's row 0 is its top (the frame's u up), as an image's.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass

import numpy as np
import torch

from mesh2tex.geometry.direction_field import tangent_field
from mesh2tex.geometry.geodesic import SurfaceWalker, geodesic_charts
from mesh2tex.losses.ot_style import ExemplarFeatures, style_loss
from mesh2tex.losses.structure import PATCH_SIZE, patch_distance


@dataclass
class TexelSurface:
    """The mesh the texture lives on: positions (V, 3) float32 in the unit ball (y up), faces (T, 3)
    int64, uv (V, 2) float32 in [0, 1] (v up); a vertex is split where the atlas has a seam."""

    positions: torch.Tensor
    faces: torch.Tensor
    uv: torch.Tensor

    def __post_init__(self):
        if self.positions.dim() != 2 or self.positions.shape[1] != 3:
            raise ValueError(f"TexelSurface: positions must be (V, 3), got {tuple(self.positions.shape)}")
        if self.uv.shape != (self.positions.shape[0], 2):
            raise ValueError(
                f"TexelSurface: uv must be (V, 2) with V = {self.positions.shape[0]}, got {tuple(self.uv.shape)}"
            )
        if self.faces.dim() != 2 or self.faces.shape[1] != 3 or self.faces.shape[0] == 0:
            raise ValueError(f"TexelSurface: faces must be (T, 3) with T > 0, got {tuple(self.faces.shape)}")

    @classmethod
    def from_arrays(cls, positions, faces, uv) -> "TexelSurface":
        return cls(
            torch.tensor(np.asarray(positions), dtype=torch.float32),
            torch.tensor(np.asarray(faces), dtype=torch.long),
            torch.tensor(np.asarray(uv), dtype=torch.float32),
        )

    def texel_density(self) -> float:
        """Texels per unit length of the surface, per texel of texture side: sqrt(UV area / surface area)."""
        corners, uv = self.positions[self.faces].double(), self.uv[self.faces].double()
        area = torch.linalg.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]).norm(dim=1).sum() / 2
        e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
        uv_area = (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).abs().sum() / 2
        return float((uv_area / area.clamp_min(1e-12)).sqrt())


def grid_field(walker: SurfaceWalker, direction_field: str, axis: str = "y") -> np.ndarray | None:
    """The grids' direction: (T, 3) unit tangents per face for the ``up`` and ``smooth`` fields guided by
    ``axis`` (:func:`mesh2tex.geometry.direction_field.tangent_field`), None for ``none`` (rolled at random)."""
    return None if direction_field == "none" else tangent_field(walker, direction_field, axis)


def walk_grids(walker: SurfaceWalker, count: int, size: int, spacing: float, field: np.ndarray | None, rng):
    """``count`` square grids of ``size`` x ``size`` geodesic points ``spacing`` apart around centres uniform
    over the area, their u along ``field`` (T, 3) (:func:`grid_field`) or, where it is None, the mesh's up
    rolled by a random angle per grid: faces (count, size, size), barycentrics (count, size, size, 3) and
    valid (count, size, size) bool (False where a walk left the surface at a boundary or came back around
    a thin part)."""
    face, bary = walker.sample(count, rng)
    roll = rng.random(count) * 2 * math.pi if field is None else 0.0
    return geodesic_charts(walker, face, bary, walker.frames(face, roll, field), size, spacing)


class _SurfaceGrids:
    """Square grids of ``size`` x ``size`` geodesic points ``spacing`` apart (at the finest scale) around
    random centres of a surface, read through its atlas; direction_field: ``up`` (u = ``axis`` projected),
    ``smooth`` (the smooth field guided by ``axis``) or ``none`` (each grid rolled by a random angle)."""

    def __init__(self, surface: TexelSurface, spacing: float, size: int, direction_field: str, axis: str = "y"):
        self.walker = SurfaceWalker(surface.positions.cpu().numpy(), surface.faces.cpu().numpy())
        self.field = grid_field(self.walker, direction_field, axis)
        self.uv = surface.uv.cpu().double().numpy()[surface.faces.cpu().numpy()]  # (T, 3, 2)
        self.spacing, self.size = float(spacing), int(size)

    def grids(self, count: int, spacing: float, generator: torch.Generator):
        """``count`` grids of ``size`` x ``size`` points ``spacing`` apart at centres uniform over the area:
        UVs (count, size, size, 2) float32 (v up) and valid (count, size, size) bool (False where a walk
        left the surface at a boundary or came back around a thin part)."""
        rng = np.random.default_rng(int(torch.randint(2**62, (1,), generator=generator)))
        faces, barys, valid = walk_grids(self.walker, count, self.size, spacing, self.field, rng)
        uv = (self.uv[faces] * barys[..., None]).sum(-2)  # (count, size, size, 2)
        return torch.from_numpy(uv).float(), torch.from_numpy(valid)


class SurfaceCharts(_SurfaceGrids):
    """Random geodesic charts of a :class:`TexelSurface` (the ``surface`` method).

    spacing: the distance between a chart's neighbouring points on the surface (one exemplar pixel);
    size: a chart's side in points.
    """

    def draw(self, count: int, generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
        """``count`` charts at centres uniform over the area: UVs (count, G, G, 2) float32 (v up) and
        masks (count, 1, G, G) float32 (0 where a walk left the surface at a boundary)."""
        uv, valid = self.grids(count, self.spacing, generator)
        return uv, valid.float()[:, None]


class SurfacePatches(_SurfaceGrids):
    """The ``patch`` loss's patches walked out on the surface, octave by octave (the ``patches`` method).

    On an image the loss compares, per octave l, the ``size`` x ``size`` patches of the image pooled
    2^l times (:func:`mesh2tex.losses.structure.patch_sets`). Here octave l's patches are grids of
    ``size`` x ``size`` geodesic points ``spacing`` x 2^l apart at random centres, read from the texture
    pooled 2^l times more than the finest octave's: every patch is a texel neighbourhood sampled in its
    own tangent frame at its layer's scale, as the seed paper's surface-aware convolutions sample
    theirs layer by layer. A patch is small, so its grid stays near its tangent plane where a whole
    chart bends away from it; and no render or chart border cuts the patches near it away.
    """

    def __init__(
        self, surface: TexelSurface, spacing: float, size: int, direction_field: str, reuse: int = 1, axis: str = "y"
    ):
        super().__init__(surface, spacing, size, direction_field, axis)
        self.reuse = int(reuse)
        self._recent: dict[int, tuple[torch.Tensor, torch.Tensor]] = {}  # per octave: the last draw's patches

    def draw(self, count: int, level: int, generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
        """``count`` patches of octave ``level``: UVs (count, size, size, 2) float32 (v up) and whole
        (count,) bool (every point of the patch reached). With ``reuse`` R above 1 only count / R of them
        are walked afresh (all of them at the first draw); the rest are the newest of the previous draw's,
        so each patch serves R draws and the walks, most of a step's time, cost 1 / R."""
        recent = self._recent.get(level)
        fresh = count if recent is None else -(-count // self.reuse)
        uv, valid = self.grids(fresh, self.spacing * 2**level, generator)
        whole = valid.flatten(1).all(1)
        if recent is not None and fresh < count:
            uv, whole = torch.cat([uv, recent[0]])[:count], torch.cat([whole, recent[1]])[:count]
        self._recent[level] = uv, whole
        return uv, whole

    @contextlib.contextmanager
    def fresh(self):
        """Within it every draw walks all its patches afresh and the patches kept for reuse stay as they
        were (a fixed measurement does not disturb the optimisation's draws)."""
        recent, reuse = self._recent, self.reuse
        self._recent, self.reuse = {}, 1
        try:
            yield self
        finally:
            self._recent, self.reuse = recent, reuse


class VertexPatches:
    """The ``patch`` loss's patches walked out octave by octave (as :class:`SurfacePatches`) on a mesh whose
    colours live on its vertices: an automaton's cells (``train nca --method patches``).

    A point's colour is its triangle's three vertex colours weighted by its barycentrics (what the
    linear readout draws between cells). Octave l reads the colours pooled over a disc of the area of
    2^l x 2^l exemplar pixels around each vertex (straight-line distance; no pooling where the disc is
    smaller than the cells' spacing), as the exemplar's octave is its image pooled 2^l times. The walks
    depend on the mesh alone, so ``bank`` patches per octave are walked once here and every draw takes
    a random subset of them (a fresh walk per step would cost more than the automaton's own step).

    positions (V, 3) and faces (T, 3) of the cell mesh (triangles); spacing: one exemplar pixel in the
    mesh's units; levels: the exemplar's octaves.
    """

    def __init__(
        self,
        positions: np.ndarray,
        faces: np.ndarray,
        spacing: float,
        levels: int,
        size: int,
        bank: int,
        direction_field: str = "up",
        seed: int = 0,
    ):
        from scipy.spatial import cKDTree

        positions, faces = np.asarray(positions, dtype=np.float64), np.asarray(faces, dtype=np.int64)
        walker, rng = SurfaceWalker(positions, faces), np.random.default_rng(seed)
        field = grid_field(walker, direction_field)
        tree, count = cKDTree(positions), len(positions)
        self.size, self.corners, self.weights, self.pooling = int(size), [], [], []
        for level in range(levels):
            step = spacing * 2**level
            face, bary, valid = walk_grids(walker, bank, self.size, step, field, rng)
            whole = valid.reshape(bank, -1).all(1)
            shape = (int(whole.sum()), self.size**2, 3)
            self.corners.append(torch.from_numpy(faces[face[whole]].reshape(shape)))
            self.weights.append(torch.from_numpy(bary[whole].reshape(shape)).float())
            neighbours = tree.query_ball_point(positions, step / math.sqrt(math.pi))  # disc of area step^2
            rows = np.repeat(np.arange(count), [len(n) for n in neighbours])
            columns = np.concatenate([np.asarray(n, dtype=np.int64) for n in neighbours])
            if len(rows) == count:  # every disc holds its own vertex alone
                self.pooling.append(None)
                continue
            share = 1.0 / np.bincount(rows, minlength=count)[rows]
            indices = torch.from_numpy(np.stack([rows, columns]))
            self.pooling.append(
                torch.sparse_coo_tensor(indices, torch.from_numpy(share).float(), (count, count), check_invariants=True)
            )

    def whole_patches(self) -> list[int]:
        """Patches of the bank per octave that every walk reached."""
        return [len(c) for c in self.corners]

    def sets(self, colours: torch.Tensor, count: int, generator: torch.Generator) -> list[torch.Tensor]:
        """Per octave, ``count`` random patches of the bank (fewer if it holds fewer) read from ``colours``
        (V, 3), flattened as :func:`mesh2tex.losses.structure.patch_sets` flattens an image's (channel,
        row, column): (P_l, 3 size^2). Differentiable with respect to ``colours``."""
        sets = []
        for bank_corners, bank_weights, pooling in zip(self.corners, self.weights, self.pooling):
            pooled = colours if pooling is None else torch.sparse.mm(pooling.to(colours.device), colours)
            pick = torch.randperm(len(bank_corners), generator=generator)[:count]
            corners = bank_corners[pick].to(colours.device)
            weights = bank_weights[pick].to(colours.device, colours.dtype)
            points = (pooled[corners] * weights[..., None]).sum(-2)  # (P, size^2, 3)
            sets.append(points.transpose(1, 2).reshape(len(points), 3 * self.size**2))
        return sets


def walked_patch_terms(
    sets: list[torch.Tensor],
    exemplar: ExemplarFeatures,
    palette: ExemplarFeatures | None,
    max_points: int,
    generator: torch.Generator,
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """The loss terms of one draw of walked patches, (P_l, 3 PATCH_SIZE^2) per octave: the ``patch`` distance
    to the exemplar's sets, and with ``palette`` (the exemplar's pixels alone) the palette term, the sliced
    Wasserstein distance of the finest octave's pixels to the exemplar's (None when off or when fewer than 2
    patches were whole)."""
    style = patch_distance(sets, exemplar.patch_sets(), generator)
    if palette is None or len(sets[0]) < 2:
        return style, None
    pixels = sets[0].reshape(-1, 3, PATCH_SIZE, PATCH_SIZE).transpose(0, 1).reshape(1, 3, -1, PATCH_SIZE)
    return style, style_loss(None, pixels, torch.ones_like(pixels[:, :1]), palette, "sw", max_points, generator)


def chart_mosaic(images: torch.Tensor, masks: torch.Tensor, gutter: int = 4, background: float = 1.0):
    """The charts (N, 3, G, G) with masks (N, 1, G, G) side by side on a square grid, ``gutter`` masked
    pixels between them, as one image (1, 3, H, W) and mask (1, 1, H, W): the structure losses pool
    their statistics over every chart, and no filter whose support is on the object straddles two."""
    n, _, g, _ = images.shape
    columns = math.ceil(math.sqrt(n))
    rows = math.ceil(n / columns)
    cell = g + gutter
    canvas = images.new_full((3, rows * cell - gutter, columns * cell - gutter), background)
    cover = masks.new_zeros((1, rows * cell - gutter, columns * cell - gutter))
    for k in range(n):
        r, c = divmod(k, columns)
        canvas[:, r * cell : r * cell + g, c * cell : c * cell + g] = images[k]
        cover[:, r * cell : r * cell + g, c * cell : c * cell + g] = masks[k]
    return canvas[None], cover[None]


__all__ = [
    "SurfaceCharts",
    "SurfacePatches",
    "TexelSurface",
    "VertexPatches",
    "chart_mosaic",
    "walk_grids",
    "walked_patch_terms",
]
