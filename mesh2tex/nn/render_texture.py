"""Rendering generated textures: the one function that training, ``infer generate`` and texture
transfer use to turn (generator, shapes, ws, cameras) into images, and its counterpart for the
cell states of a mesh cellular automaton (:func:`render_states`).

Each shape of the batch is seen by K cameras: views ``s*K .. s*K+K-1`` belong to shape ``s``. The
finest level is rasterized; psi is evaluated only at covered pixels (one flat list of points over all
views), and the proxy path colours each covered pixel with its quad's per-face colour.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import torch

from mesh2tex.checks import check_shape, check_type
from mesh2tex.nn.batch import MeshBatch
from mesh2tex.nn.cell_graph import CellGraph
from mesh2tex.nn.faceconv import take_rows
from mesh2tex.nn.generator import FaceTexture, TextureGenerator
from mesh2tex.nn.nca import MeshNCA
from mesh2tex.render import Lights, quad_normals, rasterize, shade_colours, transform_points


@dataclass
class SurfaceSamples:
    """Covered pixels of N rendered views: where psi is evaluated.

    triangle_id (N, H, W) int64  batch triangle index (``MeshBatch.triangles()``), -1 on background
    bary        (N, H, W, 3)     perspective-correct barycentrics
    """

    triangle_id: torch.Tensor
    bary: torch.Tensor

    @property
    def mask(self) -> torch.Tensor:
        """(N, H, W) bool."""
        return self.triangle_id >= 0


@dataclass
class RenderedViews:
    """images (N, 3, H, W) psi renders over the background, in [-1, 1] nominally;
    proxy (N, 3, H, W) per-face colour renders (None unless asked); mask (N, 1, H, W) float 0/1."""

    images: torch.Tensor
    proxy: torch.Tensor | None
    mask: torch.Tensor


def rasterize_batch(batch: MeshBatch, mvp: torch.Tensor, resolution: tuple[int, int]) -> SurfaceSamples:
    """Rasterize the finest level of every shape of ``batch`` with K = N / num_shapes views each.

    mvp: (N, 4, 4) float32, N a multiple of ``batch.num_shapes``.
    """
    k = _views_per_item("rasterize_batch", batch, mvp)
    ids, barys = [], []
    for s in range(batch.num_shapes):
        pos = transform_points(batch.shape_vertices(s), mvp[s * k : (s + 1) * k])
        raster = rasterize(pos, batch.shape_triangles(s), resolution)
        first = 2 * batch.face_ranges[s][0]
        ids.append(torch.where(raster.face_id >= 0, raster.face_id + first, raster.face_id))
        barys.append(raster.bary)
    return SurfaceSamples(torch.cat(ids), torch.cat(barys))


def _views_per_item(
    function: str, batch: MeshBatch, mvp: torch.Tensor, items: int | None = None, what: str = "shapes"
) -> int:
    """K = N / B for ``mvp`` (N, 4, 4) float over B = ``items`` (default: the batch's shapes), checked."""
    if items is None:
        items = check_type(batch, f"{function}: batch", MeshBatch).num_shapes
    check_shape(mvp, f"{function}: mvp", (None, 4, 4), dtype="float")
    if mvp.shape[0] % items:
        raise ValueError(
            f"{function}: mvp holds {mvp.shape[0]} cameras, which cannot be split evenly over {items} {what}"
        )
    return mvp.shape[0] // items


def paint_pixels(background: torch.Tensor, flat_index: torch.Tensor, colours: torch.Tensor) -> torch.Tensor:
    """background (N, 3, H, W); colours (P, 3) at flat pixel indices into N*H*W -> (N, 3, H, W)."""
    n, _, h, w = background.shape
    flat = background.permute(0, 2, 3, 1).reshape(-1, 3).to(colours.dtype)
    flat = flat.index_put((flat_index,), colours)
    # contiguous(): channels-last inputs to the CPU conv backward of small networks can corrupt the heap.
    return flat.reshape(n, h, w, 3).permute(0, 3, 1, 2).contiguous()


def render_field_views(
    generator: TextureGenerator,
    batch: MeshBatch,
    ws: torch.Tensor,
    mvp: torch.Tensor,
    resolution: tuple[int, int],
    background: torch.Tensor,
    proxy: bool = False,
    texture: FaceTexture | None = None,
    encoded: list[torch.Tensor] | None = None,
    noise_mode: str = "random",
    samples: SurfaceSamples | None = None,
    lights: Lights | None = None,
) -> RenderedViews:
    """Render the texture that ``generator`` makes for ``batch`` from ``ws`` (B, num_ws, w_dim) or (B, w_dim).

    ``ws`` may be None when ``texture`` is given.
    mvp: (N, 4, 4) camera matrices (``orbit_camera(...).mvp``), K = N / B views per shape;
    background: (N, 3) solid colours or (N, 3, H, W) images in [-1, 1];
    proxy: also render the per-face colours; texture / encoded / samples: reuse what was computed;
    lights: one light per view (N) to shade the colours with (Lambert, flat quad normals), None: unlit.
    Differentiable with respect to ws and every generator parameter.
    """
    h, w = int(resolution[0]), int(resolution[1])
    _views_per_item("render_field_views", batch, mvp)
    views = {"N": (mvp.shape[0], "mvp")}
    check_shape(background, "render_field_views: background", ("N", 3), ("N", 3, h, w), sizes=views, dtype="float")
    if texture is None and ws is None:
        raise ValueError("render_field_views: ws is needed when no texture is given")
    if samples is not None:
        check_shape(samples.triangle_id, "render_field_views: samples.triangle_id", ("N", h, w), sizes=views)
    if lights is not None:
        check_shape(lights.direction, "render_field_views: lights.direction", ("N", 3), sizes=views)
        check_shape(lights.ambient, "render_field_views: lights.ambient", ("N",), sizes=views)
    texture = (
        generator.synthesize(batch, ws, encoded=encoded, noise_mode=noise_mode)
        if texture is None
        else texture.bound(generator, batch)
    )
    if samples is None:
        samples = rasterize_batch(batch, mvp, (h, w))
    background, flat_index, triangle_id, bary = _covered_pixels(samples.triangle_id, samples.bary, background)
    shade = _pixel_lighting(batch, triangle_id, flat_index, lights, h * w)
    images = paint_pixels(background, flat_index, shade(texture.colours(triangle_id, bary)))
    proxy_images = paint_pixels(background, flat_index, shade(_quad_colours(texture, triangle_id))) if proxy else None
    return RenderedViews(images=images, proxy=proxy_images, mask=samples.mask.unsqueeze(1).to(images.dtype))


def render_proxy_views(
    texture: FaceTexture,
    batch: MeshBatch,
    samples: SurfaceSamples,
    background: torch.Tensor,
    lights: Lights | None = None,
) -> torch.Tensor:
    """The proxy path alone: each covered pixel of ``samples`` (N views) takes its quad's per-face colour
    ``texture.face_rgb``, shaded by ``lights`` like :func:`render_field_views`; no psi evaluated.

    background: (N, 3) or (N, 3, H, W) in [-1, 1] -> (N, 3, H, W).
    """
    n, h, w = samples.triangle_id.shape
    check_shape(background, "render_proxy_views: background", (n, 3), (n, 3, h, w), dtype="float")
    background, flat_index, triangle_id, _ = _covered_pixels(samples.triangle_id, samples.bary, background)
    shade = _pixel_lighting(batch, triangle_id, flat_index, lights, h * w)
    return paint_pixels(background, flat_index, shade(_quad_colours(texture, triangle_id)))


def _quad_colours(texture: FaceTexture, triangle_id: torch.Tensor) -> torch.Tensor:
    """The proxy colour of each covered pixel: triangle_id (P,) int64 -> (P, 3), its quad's
    ``texture.face_rgb`` row (quad q is split into triangles 2q and 2q + 1)."""
    return take_rows(texture.face_rgb, triangle_id // 2)


def _covered_pixels(triangle_id: torch.Tensor, bary: torch.Tensor, background: torch.Tensor):
    """The covered pixels of N views: triangle_id (N, H, W) int64 (-1 on background), bary (N, H, W, 3) and
    background () grey, (N, 3) colours or (N, 3, H, W) -> (background (N, 3, H, W), flat pixel indices (P,),
    triangle ids (P,), barycentrics (P, 3))."""
    n, h, w = triangle_id.shape
    if background.dim() == 0:
        background = background.expand(n, 3)
    if background.dim() == 2:
        background = background[:, :, None, None].expand(n, 3, h, w)
    flat_index = (triangle_id >= 0).reshape(-1).nonzero().squeeze(1)
    return background, flat_index, triangle_id.reshape(-1)[flat_index], bary.reshape(-1, 3)[flat_index]


def _pixel_lighting(
    batch: MeshBatch, triangle_id: torch.Tensor, flat_index: torch.Tensor, lights: Lights | None, pixels_per_view: int
) -> Callable[[torch.Tensor], torch.Tensor]:
    """shade(colours (P, 3)) for the covered pixels: Lambert under each pixel's view's light with flat quad
    normals, gathered once and shared by every colour shaded at these pixels; unlit: the identity."""
    if lights is None:
        return lambda colours: colours
    view = flat_index // pixels_per_view
    normals = quad_normals(batch.vertices, batch.quads)[triangle_id // 2]
    direction, ambient = lights.direction[view], lights.ambient[view]
    return lambda colours: shade_colours(
        colours, normals.to(colours.dtype), direction.to(colours.dtype), ambient.to(colours.dtype)
    )


@dataclass
class StateViews:
    """images (N, 3, H, W) renders of cell states over the background, RGB in about [-1, 1];
    mask (N, 1, H, W) float 0/1."""

    images: torch.Tensor
    mask: torch.Tensor


def render_states(
    model: MeshNCA,
    state: torch.Tensor,
    graph: CellGraph,
    mvp: torch.Tensor,
    resolution: int,
    background: float | torch.Tensor = 0.0,
    graft: tuple[MeshNCA, torch.Tensor] | None = None,
) -> StateViews:
    """Render B states of one mesh with K = N / B cameras each (views s*K .. s*K+K-1 show state s).

    state (B, V, C) float, V = ``graph.num_cells``; mvp (N, 4, 4); background a float, (N, 3) colours
    or (N, 3, H, W) images in [-1, 1]; graft: a grafted growth's (other model, alpha (V,)), whose
    readouts are blended as :meth:`MeshNCA.colours` does. The readout is evaluated only at covered pixels.
    Differentiable with respect to the states and the readout's parameters.
    """
    check_type(graph, "render_states: graph", CellGraph)
    check_shape(state, "render_states: state", (None, graph.num_cells, None), dtype="float")
    _views_per_item("render_states", None, mvp, state.shape[0], "states")
    n, b = mvp.shape[0], state.shape[0]
    h = w = int(resolution)
    raster = rasterize(transform_points(graph.positions, mvp), graph.triangles, (h, w))
    # A float stays exact until paint_pixels gives the background the readout's dtype.
    background = torch.as_tensor(
        background, dtype=None if torch.is_tensor(background) else torch.float64, device=state.device
    )
    background, flat_index, triangle_id, bary = _covered_pixels(raster.face_id, raster.bary, background)
    sample = flat_index // (h * w) // (n // b)
    colours = model.colours(state, graph.triangles, triangle_id, bary, sample, graft=graft)
    images = paint_pixels(background, flat_index, colours)
    return StateViews(images=images, mask=(raster.face_id >= 0).unsqueeze(1).to(images.dtype))
