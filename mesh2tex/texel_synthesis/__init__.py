"""Texture synthesis from one exemplar image, with the texels themselves as the parameters.

The user's mesh keeps its own UV atlas (or gets a new xatlas one, :func:`mesh2tex.render.bake.mesh_atlas`);
its UV texture is optimised directly, no network, so that renders of the textured mesh from random
views match the exemplar's structure under a weight-free structure loss
(:func:`mesh2tex.losses.ot_style.style_loss`: ``ps``, ``patch``, ``sw`` or ``ot``). Each step::

    texture  = sum over levels k of upsample(P_k)             P_k (3, S / 2^k, S / 2^k), level 0 finest
    seen     = avg_pool(texture, 2^m)                          m: the mip level whose texels match render pixels
    views    = render(mesh, seen, K random orbit cameras)      (K, 3, R, R) in [-1, 1], masks (K, 1, R, R)
    loss     = style_loss(views, masks, exemplar)              the structure loss (``patch`` by default)
             + colour_weight * SW(RGB pixels of views, of the exemplar) + overflow      Adam on every P_k

The colour term is the sliced Wasserstein distance of the object's RGB pixels (``style_loss`` kind
``sw`` without VGG layers): ``ps`` matches each channel's quantiles but not which values go together,
and without it the texture keeps off-palette speckles (green and cyan among red and cream stripes);
on the stripes exemplar (400 steps, the same rates) it took the judge's patch distance from 576 to 232.
The ``patch`` loss matches whole RGB patches, joint colours included, and the colour term drowns it:
at any weight from 1 up it paints the palette's blotches where without it a checker has corners. Its
weight is therefore the loss's own unless set (:data:`COLOUR_WEIGHTS`: 100 for ``ps``, ``sw`` and
``ot``; 0 for ``patch``).

**Three ways to see the surface** (``method``). ``renders``: the surface is seen through random
*rendered views*, and the structure loss judges them as 2D images. It inherits the camera's
orientation: the structure losses are orientation-sensitive (the ``ps`` filters are oriented, random
VGG filters are not rotation-invariant), so a pattern's direction on the surface follows the
cameras' up. With ``direction="up"`` every view is upright (roll zero, up = the mesh's up, y in the
working frame), so stripes keep one global direction on the surface, across the atlas's seams; with
``"none"`` every view is rolled by a random angle, and each region settles on an orientation of its
own. A render foreshortens what it sees at a grazing angle and never sees what other parts hide.

``surface``: the surface is seen through *geodesic charts*, as the paper (surface-aware texture
synthesis with pre-trained 2D CNNs, Kovacs et al. 2024) samples its convolutions' neighbourhoods by
the exponential map on a tangent direction field. Each step draws ``charts`` centres uniformly over
the surface's area; around each, a ``chart_size`` square grid of points one exemplar pixel apart is
walked out along geodesics in the centre's tangent frame (:mod:`mesh2tex.geometry.geodesic`; the
frame's up is the direction field's, :mod:`mesh2tex.geometry.direction_field`: the ``direction_axis``
projected on the tangent plane for ``direction_field="up"``, the smooth field it guides for ``"smooth"``,
a random roll for ``"none"``), and the texture read at those points is a chart: an image of the surface as it is, with
no foreshortening, across the atlas's seams, hidden parts included. The charts, side by side with
masked gutters (:func:`chart_mosaic`), are one image for the structure loss. What differs from the
paper: its network convolves every texel's own neighbourhood layer by layer (pooling by voxels);
here the 2D loss runs on charts, whole local images, so a chart's grid is exact at its centre and
follows the geodesics radially, as a photo of a curved patch would not.

``patches`` (the ``patch`` loss only): the loss's own patches are walked out on the surface, octave by
octave, as the paper's layers sample their neighbourhoods: octave l's ``size`` x ``size`` patches
(:data:`mesh2tex.losses.structure.PATCH_SIZE`) are grids of geodesic points 2^l exemplar pixels apart
around ``max_points`` random centres, read from the texture pooled 2^l times more
(:class:`mesh2tex.texel_synthesis.surface.SurfacePatches`), and each octave's set is compared with
the exemplar's by the same sliced Wasserstein distance
(:func:`mesh2tex.losses.structure.patch_distance`). No chart is bent around a curved surface and no
chart border or render silhouette cuts patches away: a patch is dropped only where a walk leaves an
open mesh or wraps around a thin part.

**Scale.** The exemplar's pixels are matched to render pixels: an exemplar pixel covers one pixel of a
``resolution``-px view of the whole mesh (the unit ball seen from ``distance`` with ``fov``), as in
``train nca``. The texels are pooled to the mip level nearest that pixel size before rendering
(:func:`mip_level`), so that every texel receives a gradient (bilinear lookups of a finer texture
would read four texels per pixel and leave the rest untouched); the finer levels of the pyramid then
carry only what the pooled renders see.

Conventions: colours in [-1, 1] inside; positions in the unit ball, y up; UVs v up (the convention of
:func:`mesh2tex.render.texture`); the texture image row 0 is its top (v = 1).
"""

from __future__ import annotations

import math
import typing
from dataclasses import dataclass, field

import numpy as np
import torch
import torch.nn.functional as F

from mesh2tex.config import check_fields
from mesh2tex.geometry.direction_field import AXES
from mesh2tex.losses.ot_style import STYLE_LOSSES, ExemplarFeatures, needs_vgg, style_loss
from mesh2tex.losses.structure import PATCH_SIZE
from mesh2tex.nn.schedule import cosine_rate
from mesh2tex.photos import square_resize
from mesh2tex.render import interpolate, orbit_camera, rasterize, sample_texture, transform_points, uv_rasterize
from mesh2tex.render.cameras import NCACameraConfig
from mesh2tex.texel_synthesis.surface import (
    SurfaceCharts,
    SurfacePatches,
    TexelSurface,
    VertexPatches,
    chart_mosaic,
    walked_patch_terms,
)

# --direction-field: the axis projected (up), the smooth field it guides (smooth; charts and patches only), or
# randomly rolled views and grids (none); mesh2tex.geometry.direction_field
DIRECTIONS = ("up", "smooth", "none")  # FIELDS and none (a literal: the CLI reads it without importing)
# how the loss sees the surface: rendered views, geodesic charts, or the patch loss's patches walked octave by octave
METHODS = ("renders", "surface", "patches")
# The losses of mesh2tex.losses.ot_style.STYLE_LOSSES that see a pattern, each with the colour term's weight
# when the config leaves it unset (the module docstring says why).
COLOUR_WEIGHTS = {"ps": 100.0, "patch": 0.0, "sw": 100.0, "ot": 100.0}
SYNTHESIS_LOSSES = tuple(COLOUR_WEIGHTS)


@dataclass
class SynthesisConfig:
    iters: int = 400  # Adam steps
    texture_size: int = 512  # side of the UV texture (the finest level of the pyramid)
    levels: int = 6  # pyramid levels (level k has side texture_size / 2^k)
    views: int = 2  # random views rendered per step
    resolution: int = 128  # render resolution: an exemplar pixel shows at one render pixel
    exemplar_size: int = 128  # the exemplar's centred square is resized to this
    # structure loss: patch (raw multi-scale patches; draws stripes and corners that ps leaves as blotches,
    # docs/results/nca.md), ps (oriented-band statistics), sw, ot
    loss: str = "patch"
    vgg_depth: int = 4  # VGG19 layers of the sw and ot losses (0: RGB only)
    max_points: int = 1024  # feature positions per set in the sw and ot losses; patches per octave in patch
    lr: float = 0.05  # Adam learning rate of every level, at the start
    lr_end: float = 0.1  # the rate at the last step, as a fraction of lr (a cosine in between): the texels settle
    # weight of the sliced Wasserstein distance of the RGB pixels (the joint palette); unset: the loss's own
    # (COLOUR_WEIGHTS: 100, or 0 for patch)
    colour_weight: float | None = None
    overflow_weight: float = 10.0  # weight of the penalty on colours outside [-1, 1]
    # up: views or charts upright (stripes keep the direction axis); smooth: charts and patches along the smooth
    # field the axis guides (no jump where the surface looks along the axis); none: rolled at random
    direction_field: str = "up"
    direction_axis: str = "y"  # the axis that guides the field: y (the mesh's up), x or z of its working frame
    # renders: random rendered views; surface: geodesic charts of the surface itself; patches: the patch loss's
    # patches walked on it. Unset: the loss's own (patches for patch, which draws more of a checker's corners
    # there at the same cost; renders for the others, which have no patches to walk)
    method: str | None = None
    # surface method: charts per step and a chart's side in exemplar pixels; a chart holds a few of a
    # pattern's periods (measured with patch; ps was measured at 16 charts of 32)
    charts: int = 4
    chart_size: int = 64
    # patches method: each walked patch serves this many steps (the newest 1 / patch_reuse walked afresh each
    # step; the walks are most of a step's time); 1: every patch fresh. 4 costs what a renders step does and
    # draws the same structure (docs/results/nca.md)
    patch_reuse: int = 4
    # the random views around the mesh in the unit ball, as train nca's
    camera: NCACameraConfig = field(default_factory=NCACameraConfig)
    seed: int = 0  # seed of the views, the loss's random projections and the initial noise

    # Keys of configs written before the cameras became a section (named by the unknown-key error).
    MOVED_KEYS: typing.ClassVar[dict[str, str]] = {
        name: f"camera.{name}" for name in ("distance", "fov", "elevation_min", "elevation_max")
    }

    def __post_init__(self):
        check_fields(
            self,
            at_least={
                "iters": 1,
                "texture_size": 16,
                "levels": 1,
                "views": 1,
                "resolution": 32,
                "exemplar_size": 16,
                "max_points": 2,
                "overflow_weight": 0,
                "charts": 1,
                "chart_size": 16,
                "patch_reuse": 1,
            },
            between={
                "vgg_depth": (0, 5),
                "texture_size": (16, 8192),
                "resolution": (32, 4096),
                "exemplar_size": (16, 4096),
                "levels": (1, 12),
                "lr_end": (0.0, 1.0),
            },
            positive=("lr", "lr_end"),
        )
        if self.loss not in SYNTHESIS_LOSSES or self.loss not in STYLE_LOSSES:
            raise ValueError(f"loss must be one of {', '.join(SYNTHESIS_LOSSES)}, got {self.loss!r}")
        if self.colour_weight is not None and not self.colour_weight >= 0:
            raise ValueError(f"colour_weight must be at least 0, got {self.colour_weight}")
        if self.method is None:
            self.method = "patches" if self.loss == "patch" else "renders"
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        if self.method == "patches" and self.loss != "patch":
            raise ValueError(f"method patches walks the patch loss's patches: it needs loss patch, got {self.loss!r}")
        if self.direction_field not in DIRECTIONS:
            raise ValueError(f"direction_field must be one of {', '.join(DIRECTIONS)}, got {self.direction_field!r}")
        if self.direction_axis not in AXES:
            raise ValueError(f"direction_axis must be one of {', '.join(AXES)}, got {self.direction_axis!r}")
        if self.method == "renders" and (self.direction_field == "smooth" or self.direction_axis != "y"):
            raise ValueError(
                "the renders method's views are upright in the mesh's up: direction_field smooth and "
                "direction_axis x or z need method surface or patches"
            )

    @property
    def palette_weight(self) -> float:
        """The colour term's weight: ``colour_weight``, or the loss's own (:data:`COLOUR_WEIGHTS`) when unset."""
        return COLOUR_WEIGHTS[self.loss] if self.colour_weight is None else float(self.colour_weight)


def pixels_per_unit(resolution: int, distance: float, fov: float) -> float:
    """Render pixels per unit length at the origin, seen from ``distance`` with a vertical ``fov`` (degrees)."""
    return resolution / (2 * distance * math.tan(math.radians(fov) / 2))


def mip_level(surface: TexelSurface, cfg: SynthesisConfig) -> int:
    """The pooling level m whose texels come nearest to one render pixel (log2 of texels per pixel,
    rounded; 0 when the texture is coarser than the renders), at most levels - 1."""
    per_pixel = (
        cfg.texture_size
        * surface.texel_density()
        / pixels_per_unit(cfg.resolution, cfg.camera.distance, cfg.camera.fov)
    )
    return int(min(max(round(math.log2(max(per_pixel, 1e-9))), 0), cfg.levels - 1))


def exemplar_tensor(rgb: np.ndarray, size: int) -> torch.Tensor:
    """(H, W, 3) uint8 image -> (1, 3, size, size) float32 in [-1, 1]: its centred square, resized with
    antialiasing, as every photo set is framed (:func:`mesh2tex.photos.square_resize`)."""
    # A copy: an image read from a file can be a read-only array, which torch.from_numpy warns of.
    square = square_resize(torch.tensor(np.asarray(rgb)).float().permute(2, 0, 1), size)
    return (square[None] / 127.5 - 1).clamp(-1, 1)


def view_cameras(cfg: SynthesisConfig, count: int, generator: torch.Generator) -> torch.Tensor:
    """(count, 4, 4) mvp of random orbit views of the unit ball: upright for ``direction_field`` up, else each
    rolled about its view axis by a random angle (a rotation of the clip-space x and y)."""
    azimuth = torch.rand(count, generator=generator) * 360.0
    camera = cfg.camera
    elevation = camera.elevation_min + torch.rand(count, generator=generator) * (
        camera.elevation_max - camera.elevation_min
    )
    mvp = orbit_camera(azimuth, elevation, distance=camera.distance, fov=camera.fov).mvp
    if cfg.direction_field == "none":
        angle = torch.rand(count, generator=generator) * (2 * math.pi)
        roll = torch.eye(4).repeat(count, 1, 1)
        roll[:, 0, 0], roll[:, 0, 1], roll[:, 1, 0], roll[:, 1, 1] = angle.cos(), -angle.sin(), angle.sin(), angle.cos()
        mvp = roll @ mvp
    return mvp


def render_texture(
    surface: TexelSurface, image: torch.Tensor, mvp: torch.Tensor, resolution: int, background: float = 1.0
) -> tuple[torch.Tensor, torch.Tensor]:
    """The mesh with texture ``image`` (3, H, W) in [-1, 1] (row 0 at v = 1) seen by ``mvp`` (N, 4, 4).

    Returns images (N, 3, R, R) in [-1, 1] (``background`` off the object) and masks (N, 1, R, R)
    float; differentiable with respect to ``image``.
    """
    raster = rasterize(transform_points(surface.positions, mvp), surface.faces, (resolution, resolution))
    covered = (raster.face_id >= 0)[..., None]
    colours = sample_texture(image, interpolate(surface.uv, raster, surface.faces))  # (N, R, R, 3)
    images = torch.where(covered, colours, torch.full_like(colours, background))
    return images.permute(0, 3, 1, 2), covered.permute(0, 3, 1, 2).to(images.dtype)


class TexelPyramid(torch.nn.Module):
    """A texture as a Laplacian-style pyramid of parameters whose upsampled levels add up.

    A single texel grid learns its low frequencies slowly: a step moves each texel by about the
    learning rate, and a colour balance or band layout spanning the atlas has to be assembled texel by
    texel. A coarse level moves a whole region in one step, so the large-scale layout converges in a
    few dozen steps while the finer levels add detail.

    Level 0 is (3, S, S) and the finest; level k is (3, S / 2^k, S / 2^k). ``mean`` (3,) starts the
    coarsest level; ``noise`` the finest (a small random start breaks the symmetry of a flat colour).
    """

    def __init__(
        self, size: int, levels: int, mean: torch.Tensor, noise: float = 0.05, generator: torch.Generator | None = None
    ):
        super().__init__()
        sides = [max(size >> k, 1) for k in range(levels)]
        self.size = int(size)
        self.levels = torch.nn.ParameterList([torch.nn.Parameter(torch.zeros(1, 3, s, s)) for s in sides])
        with torch.no_grad():
            self.levels[-1].copy_(mean.reshape(1, 3, 1, 1).expand_as(self.levels[-1]))
            self.levels[0].add_(noise * torch.randn(self.levels[0].shape, generator=generator))

    def forward(self) -> torch.Tensor:
        """(3, S, S): the sum of every level, each upsampled bilinearly to S."""
        total = self.levels[0]
        for level in self.levels[1:]:
            total = total + F.interpolate(level, size=(self.size, self.size), mode="bilinear", align_corners=False)
        return total[0]


def texture_coverage(surface: TexelSurface, size: int) -> torch.Tensor:
    """(size, size) bool: the texels whose centre a triangle of the atlas covers."""
    return uv_rasterize(surface.uv, surface.faces, (size, size)).face_id[0] >= 0


class TexelSynthesis:
    """The optimisation (module docstring): :meth:`step` once per iteration, then :meth:`texture`.

    surface: the mesh and its atlas; exemplar (1, 3, h, w) in [-1, 1]; vgg: the feature network of
    the ``sw`` and ``ot`` losses (None for ``ps``).
    """

    def __init__(
        self,
        cfg: SynthesisConfig,
        surface: TexelSurface,
        exemplar: torch.Tensor,
        vgg=None,
        device: torch.device | str = "cpu",
    ):
        if exemplar.dim() != 4 or exemplar.shape[:2] != (1, 3):
            raise ValueError(f"TexelSynthesis: exemplar must be (1, 3, h, w), got {tuple(exemplar.shape)}")
        if needs_vgg(cfg.loss) and vgg is None:
            raise ValueError(f"TexelSynthesis: the {cfg.loss} loss needs a VGG network")
        self.cfg, self.device = cfg, torch.device(device)
        self.surface = TexelSurface(*(t.to(self.device) for t in (surface.positions, surface.faces, surface.uv)))
        self.vgg = vgg
        depth = cfg.vgg_depth if needs_vgg(cfg.loss) else 0
        self.features = ExemplarFeatures.compute(vgg, exemplar.to(self.device), depth)
        self.palette = ExemplarFeatures.compute(None, exemplar.to(self.device), 0)  # the pixels alone
        self.generator = torch.Generator().manual_seed(cfg.seed)
        mean = exemplar.mean((0, 2, 3))
        self.pyramid = TexelPyramid(cfg.texture_size, cfg.levels, mean, generator=self.generator).to(self.device)
        self.optimizer = torch.optim.Adam(self.pyramid.parameters(), lr=cfg.lr)
        self.mip = mip_level(surface, cfg)
        self.charts = self.patches = None
        spacing = 1 / pixels_per_unit(cfg.resolution, cfg.camera.distance, cfg.camera.fov)  # one exemplar pixel
        if cfg.method == "surface":
            self.charts = SurfaceCharts(surface, spacing, cfg.chart_size, cfg.direction_field, cfg.direction_axis)
        elif cfg.method == "patches":
            self.patches = SurfacePatches(
                surface, spacing, PATCH_SIZE, cfg.direction_field, cfg.patch_reuse, cfg.direction_axis
            )
        self.iteration = 0

    def seen(self, image: torch.Tensor | None = None) -> torch.Tensor:
        """(3, S / 2^m, S / 2^m): the texture pooled to the mip level the renders read; colours
        clamped to [-1, 1] on the way forward, the gradient passed through as it is."""
        image = self.pyramid() if image is None else image
        pooled = F.avg_pool2d(image[None], 2**self.mip)[0] if self.mip else image
        return pooled + (pooled.clamp(-1, 1) - pooled).detach()

    def views_of(self, image: torch.Tensor, count: int, generator: torch.Generator):
        """What the loss compares with the exemplar: ``count`` random views of ``image`` (3, S, S) (the
        renders method), or ``count`` geodesic charts side by side (the surface method). Returns (images
        (N, 3, H, W) in [-1, 1], masks (N, 1, H, W)) for the structure loss and the same for the colour term."""
        seen = self.seen(image)
        if self.charts is None:
            mvp = view_cameras(self.cfg, count, generator).to(self.device)
            views = render_texture(self.surface, seen, mvp, self.cfg.resolution)
            return views, views
        uv, masks = self.charts.draw(count, generator)
        uv, masks = uv.to(self.device), masks.to(self.device)
        colours = sample_texture(seen, uv).permute(0, 3, 1, 2)  # (N, 3, G, G)
        charts = torch.where(masks > 0.5, colours, torch.ones_like(colours)), masks
        return chart_mosaic(*charts), charts

    def surface_patch_sets(self, image: torch.Tensor, generator: torch.Generator) -> list[torch.Tensor]:
        """The patches method's point sets of ``image`` (3, S, S): per octave l of the exemplar's, up to
        ``max_points`` patches (P_l, 3 PATCH_SIZE^2) walked out on the surface 2^l exemplar pixels apart and
        read from the texture pooled 2^l times more, flattened as :func:`patch_sets` flattens an image's."""
        seen, sets = self.seen(image), []
        for level in range(len(self.features.patch_sets())):
            pooled = F.avg_pool2d(seen[None], 2**level)[0] if level else seen
            uv, whole = self.patches.draw(self.cfg.max_points, level, generator)
            uv = uv[whole].to(self.device)  # (P, s, s, 2)
            # read as one image of P * s rows: a batch of P would expand the texture, and its gradient, P times
            colours = sample_texture(pooled, uv.reshape(1, -1, *uv.shape[2:])).reshape(*uv.shape[:3], 3)
            sets.append(colours.permute(0, 3, 1, 2).reshape(len(colours), 3 * PATCH_SIZE**2))  # may be empty
        return sets

    def loss_of(self, image: torch.Tensor, count: int, generator: torch.Generator) -> torch.Tensor:
        """The style loss of ``count`` views or charts of ``image`` (3, S, S) (or, for the patches method,
        a step's patches) against the exemplar."""
        cfg = self.cfg
        if self.patches is not None:
            sets = self.surface_patch_sets(image, generator)
            palette_features = self.palette if cfg.palette_weight else None
            loss, palette = walked_patch_terms(sets, self.features, palette_features, cfg.max_points, generator)
            return loss if palette is None else loss + cfg.palette_weight * palette
        (images, masks), (pixels, pixel_masks) = self.views_of(image, count, generator)
        loss = style_loss(self.vgg, images, masks, self.features, cfg.loss, cfg.max_points, generator)
        if cfg.palette_weight:
            palette = style_loss(None, pixels, pixel_masks, self.palette, "sw", cfg.max_points, generator)
            loss = loss + cfg.palette_weight * palette
        return loss

    def per_step(self) -> int:
        """Views (renders method), charts (surface method) or patches per octave (patches method) drawn per step."""
        if self.patches is not None:
            return self.cfg.max_points
        return self.cfg.views if self.charts is None else self.cfg.charts

    def learning_rate(self, iteration: int) -> float:
        """lr at ``iteration``: a cosine from ``lr`` down to ``lr * lr_end`` at the last step."""
        return cosine_rate(self.cfg.lr, self.cfg.lr_end, iteration, self.cfg.iters)

    def step(self) -> dict[str, float]:
        """One Adam step on random views; returns its losses (style, overflow)."""
        image = self.pyramid()
        style = self.loss_of(image, self.per_step(), self.generator)
        overflow = F.relu(image.abs() - 1).square().mean()
        loss = style + self.cfg.overflow_weight * overflow
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        for group in self.optimizer.param_groups:
            group["lr"] = self.learning_rate(self.iteration)
        self.optimizer.step()
        self.iteration += 1
        values = {"loss": float(style.detach()), "overflow": float(overflow.detach())}
        if not all(math.isfinite(v) for v in values.values()):
            raise FloatingPointError(f"texel synthesis: non-finite loss at step {self.iteration}: {values}")
        return values

    @torch.no_grad()
    def fixed_loss(self, views: int = 4, seed: int = 1) -> float:
        """The style loss over ``views`` views (or a step's charts) and projections drawn from
        ``seed`` (the same at every call): comparable before and after the optimisation."""
        generator = torch.Generator().manual_seed(seed)
        count = views if self.charts is None and self.patches is None else self.per_step()
        if self.patches is None:
            return float(self.loss_of(self.pyramid(), count, generator))
        with self.patches.fresh():
            return float(self.loss_of(self.pyramid(), count, generator))

    @torch.no_grad()
    def texture(self) -> torch.Tensor:
        """(S, S, 3) float32 in [-1, 1] on the CPU: the pyramid summed, pooled to the mip level the renders
        read and upsampled back (what the views saw, at the asked size), texels no render could read
        (farther from the atlas's charts than a pooled texel) filled from the nearest one that could."""
        from mesh2tex.render.bake import fill_empty_texels

        size = self.cfg.texture_size
        image = self.seen()
        if self.mip:
            image = F.interpolate(image[None], size=(size, size), mode="bilinear", align_corners=False)[0]
        covered = texture_coverage(self.surface, size)[None, None].float()
        reach = 2 * 2**self.mip + 1
        readable = F.max_pool2d(covered, reach, stride=1, padding=reach // 2)[0, 0] > 0
        colours = image.permute(1, 2, 0).cpu().numpy()
        return torch.from_numpy(fill_empty_texels(colours, readable.cpu().numpy()))


def vertex_texture_colours(image: torch.Tensor, uv: np.ndarray, vertex_index: np.ndarray, count: int) -> torch.Tensor:
    """(count, 3) colours in [-1, 1] of a mesh's own vertices: the texture ``image`` (S, S, 3) read at each
    atlas vertex's ``uv`` (V', 2) and averaged over the atlas vertices (``vertex_index`` (V',) into the
    mesh's) that split the same vertex; a vertex no face uses reads uv (0, 0)."""
    grid = torch.tensor(np.asarray(uv), dtype=torch.float32)[None, None]  # (1, 1, V', 2)
    sampled = sample_texture(image.permute(2, 0, 1).float(), grid)[0, 0]  # (V', 3)
    index = torch.tensor(np.asarray(vertex_index), dtype=torch.long)
    summed = torch.zeros(count, 3).index_add_(0, index, sampled)
    return summed / torch.zeros(count).index_add_(0, index, torch.ones(len(index))).clamp_min(1)[:, None]


__all__ = [
    "DIRECTIONS",
    "METHODS",
    "COLOUR_WEIGHTS",
    "SYNTHESIS_LOSSES",
    "SurfaceCharts",
    "SurfacePatches",
    "SynthesisConfig",
    "TexelPyramid",
    "TexelSurface",
    "TexelSynthesis",
    "VertexPatches",
    "chart_mosaic",
    "exemplar_tensor",
    "mip_level",
    "pixels_per_unit",
    "render_texture",
    "texture_coverage",
    "vertex_texture_colours",
    "view_cameras",
    "walked_patch_terms",
]
