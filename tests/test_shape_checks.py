"""Every checked public function of mesh2tex.render and mesh2tex.nn: a correct call still works, and a
wrong rank, size or dtype fails at the call with a message that names the function and the argument
(ValueError for a shape, TypeError for a non-tensor or a wrong dtype), not deep inside."""

from __future__ import annotations

import dataclasses
import re
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from test_faceconv import cube_shape
from test_nca import grid_mesh
from test_render import cube

from mesh2tex import render
from mesh2tex.nn.batch import collate_shapes
from mesh2tex.nn.cell_graph import build_cell_graph
from mesh2tex.nn.discriminator import Discriminator, DiscriminatorConfig
from mesh2tex.nn.faceconv import FaceResNetBlock, gather_neighborhood
from mesh2tex.nn.field import NeuralField, vertex_features
from mesh2tex.nn.generator import GeneratorConfig, MappingNetwork, TextureGenerator
from mesh2tex.nn.nca import ConditionedNCA, MeshNCA, NCAConfig
from mesh2tex.nn.noc import NocUNet
from mesh2tex.nn.pose import PoseNet
from mesh2tex.nn.render_texture import rasterize_batch, render_field_views, render_states
from mesh2tex.render.uv import bake_surface_colours


@pytest.fixture(scope="module")
def w():
    """Small correct inputs that the cases below break one argument at a time."""
    torch.manual_seed(0)
    v, tri = cube()
    mvp = render.orbit_camera(torch.tensor([20.0, 80.0]), torch.tensor([25.0, 25.0]), distance=3.0).mvp
    raster = render.rasterize(render.transform_points(v, mvp), tri, (8, 8))  # B = 2
    cfg = GeneratorConfig(
        z_dim=16,
        w_dim=16,
        mapping_layers=2,
        input_features=4,
        encoder_channels=[8] * 3,
        synthesis_channels=[8] * 3,
        field_hidden=16,
        aux_latent_dim=8,
    )
    gen = TextureGenerator(cfg)
    batch = collate_shapes([cube_shape(3, seed=0), cube_shape(3, seed=1)])
    ws = torch.randn(2, gen.num_ws, 16)
    vertices, quads = grid_mesh(4)
    graph = build_cell_graph(vertices, quads)
    nca = MeshNCA(NCAConfig(channels=4, hidden=8))
    conditioned = ConditionedNCA(channels=4, hidden=8, steps=1, condition=2, w_dim=16, geometry_dim=3)
    return SimpleNamespace(
        v=v,
        tri=tri,
        mvp=mvp,
        raster=raster,
        gen=gen,
        batch=batch,
        ws=ws,
        graph=graph,
        nca=nca,
        state=torch.zeros(2, graph.num_cells, 4),
        conditioned=conditioned,
        images=torch.rand(2, 3, 8, 8),
        masks=torch.ones(2, 1, 8, 8),
    )


def _flat_quad():
    uv = torch.tensor([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    return uv, torch.tensor([[0, 1, 2], [0, 2, 3]])


# name: (a correct call, the same call with one argument wrong, the error, a regex its message must match)
CASES = {
    "rasterize pos dtype": (
        lambda w: render.rasterize(render.transform_points(w.v, w.mvp), w.tri, (8, 8)),
        lambda w: render.rasterize(torch.zeros(2, 8, 4, dtype=torch.long), w.tri, (8, 8)),
        TypeError,
        r"rasterize: pos must be a floating-point tensor, got int64",
    ),
    "rasterize tri dtype": (
        lambda w: render.rasterize(torch.rand(8, 4), w.tri, (8, 8)),
        lambda w: render.rasterize(torch.rand(8, 4), w.tri.float(), (8, 8)),
        TypeError,
        r"rasterize: tri must be an integer tensor",
    ),
    "rasterize resolution": (
        lambda w: render.rasterize(torch.rand(8, 4), w.tri, [8, 8]),
        lambda w: render.rasterize(torch.rand(8, 4), w.tri, 8),
        ValueError,
        r"rasterize: resolution must be \(H, W\), got 8",
    ),
    "interpolate attr batch": (
        lambda w: render.interpolate(torch.rand(1, 8, 2), w.raster, w.tri),
        lambda w: render.interpolate(torch.rand(3, 8, 2), w.raster, w.tri),
        ValueError,
        r"interpolate: attr must have shape \[V, C\] or \[1, V, C\] or \[B, V, C\] \(B = 2 from raster\), got \[3, 8, "
        r"2\]",
    ),
    "interpolate raster type": (
        lambda w: render.interpolate(torch.rand(8, 2), w.raster, w.tri),
        lambda w: render.interpolate(torch.rand(8, 2), w.raster.face_id, w.tri),
        TypeError,
        r"interpolate: raster must be a Raster, got Tensor",
    ),
    "interpolate tri": (
        lambda w: render.interpolate(torch.rand(8, 2), w.raster, w.tri.int()),
        lambda w: render.interpolate(torch.rand(8, 2), w.raster, w.tri[:, :2]),
        ValueError,
        r"interpolate: tri must have shape \[T, 3\], got \[12, 2\]",
    ),
    "face_attribute attr": (
        lambda w: render.face_attribute(torch.rand(2, 12, 3), w.raster),
        lambda w: render.face_attribute(torch.rand(12), w.raster),
        ValueError,
        r"face_attribute: attr must have shape \[T, C\]",
    ),
    "sample_texture image batch": (
        lambda w: render.sample_texture(torch.rand(1, 3, 4, 4), torch.rand(2, 8, 8, 2)),
        lambda w: render.sample_texture(torch.rand(3, 3, 4, 4), torch.rand(2, 8, 8, 2)),
        ValueError,
        r"sample_texture: image must have shape .*\[B, C, Ht, Wt\] \(B = 2 from uv\), got \[3, 3, 4, 4\]",
    ),
    "transform_points vertices": (
        lambda w: render.transform_points(w.v[None].expand(2, 8, 3), w.mvp),
        lambda w: render.transform_points(torch.rand(8, 4), w.mvp),
        ValueError,
        r"transform_points: vertices must have shape \[V, 3\] or \[B, V, 3\], got \[8, 4\]",
    ),
    "transform_points mvp batch": (
        lambda w: render.transform_points(w.v[None].expand(2, 8, 3), w.mvp[:1]),
        lambda w: render.transform_points(torch.rand(2, 8, 3), torch.rand(3, 4, 4)),
        ValueError,
        r"transform_points: mvp must have shape .*\[B, 4, 4\] \(B = 2 from vertices\), got \[3, 4, 4\]",
    ),
    "orbit_camera batch": (
        lambda w: render.orbit_camera(torch.rand(3), torch.rand(1), distance=torch.rand(3) + 2),
        lambda w: render.orbit_camera(torch.rand(3), torch.rand(2)),
        ValueError,
        r"orbit_camera: elevation must have shape \[\] or \[1\] or \[B\] \(B = 3 from azimuth\), got \[2\]",
    ),
    "orbit_camera rank": (
        lambda w: render.orbit_camera(torch.rand(()), 20.0),
        lambda w: render.orbit_camera(torch.rand(3, 2), 20.0),
        ValueError,
        r"orbit_camera: azimuth must have shape",
    ),
    "orbit_direction": (
        lambda w: render.orbit_direction(torch.rand(3), torch.rand(3)),
        lambda w: render.orbit_direction(torch.rand(3), torch.rand(4)),
        ValueError,
        r"orbit_direction: elevation must have shape \[B\] \(B = 3 from azimuth\), got \[4\]",
    ),
    "render_normals vertices": (
        lambda w: render.render_normals(w.v, w.tri, w.raster, smooth=False),
        lambda w: render.render_normals(w.v[:, :2], w.tri, w.raster),
        ValueError,
        r"render_normals: vertices must have shape \[V, 3\]",
    ),
    "render_noc noc": (
        lambda w: render.render_noc(w.v + 0.5, w.raster, w.tri),
        lambda w: render.render_noc((w.v + 0.5)[None].expand(3, 8, 3), w.raster, w.tri),
        ValueError,
        r"render_noc: noc must have shape .*\(B = 2 from raster\)",
    ),
    "render_mask raster": (
        lambda w: render.render_mask(w.raster),
        lambda w: render.render_mask(w.raster.face_id),
        TypeError,
        r"render_mask: raster must be a Raster",
    ),
    "face_normals tri": (
        lambda w: render.face_normals(w.v, w.tri),
        lambda w: render.face_normals(w.v, w.tri[:, [0, 1, 2, 2]]),
        ValueError,
        r"face_normals: tri must have shape \[T, 3\], got \[12, 4\]",
    ),
    "vertex_normals vertices": (
        lambda w: render.vertex_normals(w.v, w.tri),
        lambda w: render.vertex_normals(w.v.long(), w.tri),
        TypeError,
        r"vertex_normals: vertices must be a floating-point tensor",
    ),
    "quad_normals quads": (
        lambda w: render.quad_normals(w.v, torch.tensor([[0, 1, 3, 2]])),
        lambda w: render.quad_normals(w.v, w.tri),
        ValueError,
        r"quad_normals: quads must have shape \[F, 4\], got \[12, 3\]",
    ),
    "shade_lambert normals": (
        lambda w: render.shade_lambert(torch.rand(2, 4, 4, 3), torch.rand(2, 4, 4, 3), [0.0, 0.0, 1.0]),
        lambda w: render.shade_lambert(torch.rand(2, 4, 4, 3), torch.rand(2, 4, 5, 3), [0.0, 0.0, 1.0]),
        ValueError,
        r"shade_lambert: normals must have shape \[B, H, W, 3\] \(W = 4 from albedo\), got \[2, 4, 5, 3\]",
    ),
    "shade_lambert light_dir": (
        lambda w: render.shade_lambert(
            torch.rand(2, 4, 4, 3), torch.rand(2, 4, 4, 3), torch.rand(2, 3), torch.rand(2, 1, 1, 1)
        ),
        lambda w: render.shade_lambert(torch.rand(2, 4, 4, 3), torch.rand(2, 4, 4, 3), [0.0, 1.0]),
        ValueError,
        r"shade_lambert: light_dir must have shape \[3\] or \[1, 3\] or \[B, 3\], got \[2\]",
    ),
    "shade_colours ambient": (
        lambda w: render.shade_colours(torch.rand(5, 3), torch.rand(5, 3), torch.rand(5, 3), torch.rand(5)),
        lambda w: render.shade_colours(torch.rand(5, 3), torch.rand(5, 3), torch.rand(5, 3), torch.rand(4)),
        ValueError,
        r"shade_colours: ambient must have shape \[P\] \(P = 5 from colours\), got \[4\]",
    ),
    "random_lights azimuth": (
        lambda w: render.random_lights(torch.zeros(4), render.LightConfig()),
        lambda w: render.random_lights(torch.zeros(4, 1), render.LightConfig()),
        ValueError,
        r"random_lights: camera_azimuth must have shape \[N\], got \[4, 1\]",
    ),
    "composite mask": (
        lambda w: render.composite(torch.rand(2, 4, 4, 3), torch.ones(2, 4, 4, 1, dtype=torch.bool), 1.0),
        lambda w: render.composite(torch.rand(2, 4, 4, 3), torch.ones(2, 4, 4, 3), 1.0),
        ValueError,
        r"composite: mask must have shape \[B, H, W, 1\]",
    ),
    "composite background": (
        lambda w: render.composite(torch.rand(2, 4, 4, 3), torch.ones(2, 4, 4, 1), torch.rand(4, 4, 3)),
        lambda w: render.composite(torch.rand(2, 4, 4, 3), torch.ones(2, 4, 4, 1), torch.rand(5, 5, 3)),
        ValueError,
        r"composite: background must have shape",
    ),
    "composite_images masks": (
        lambda w: render.composite_images(w.images, w.masks, torch.rand(2, 3)),
        lambda w: render.composite_images(w.images, w.masks.expand(2, 3, 8, 8), 1.0),
        ValueError,
        r"composite_images: masks must have shape \[N, 1, H, W\]",
    ),
    "composite_images background": (
        lambda w: render.composite_images(w.images, w.masks, torch.rand(1, 3, 1, 1)),
        lambda w: render.composite_images(w.images, w.masks, torch.rand(3, 3)),
        ValueError,
        r"composite_images: background must have shape \[N, C\] \(N = 2 from images\), got \[3, 3\]",
    ),
    "crop_square images": (
        lambda w: render.crop_square(w.images, (1, 1, 4), 4),
        lambda w: render.crop_square(w.images[0], (1, 1, 4), 4),
        ValueError,
        r"crop_square: images must have shape \[\*, \*, H, W\], got \[3, 8, 8\]",
    ),
    "crop_square box": (
        lambda w: render.crop_square(w.images, [1, 1, 4], 4),
        lambda w: render.crop_square(w.images, (1, 4), 4),
        ValueError,
        r"crop_square: box must be \(top, left, side\)",
    ),
    "crop_mask mask": (
        lambda w: render.crop_mask(np.ones((8, 8), bool), (0, 0, 8), 4),
        lambda w: render.crop_mask(torch.ones(2, 8, 8), (0, 0, 8), 4),
        ValueError,
        r"crop_mask: mask must have shape \[H, W\]",
    ),
    "object_box empty": (
        lambda w: render.object_box(np.eye(8, dtype=bool), 0.1),
        lambda w: render.object_box(np.zeros((8, 8), bool), 0.1),
        ValueError,
        r"object_box: the object mask is empty",
    ),
    "uv_rasterize uv": (
        lambda w: render.uv_rasterize(*_flat_quad(), (4, 4)),
        lambda w: render.uv_rasterize(torch.rand(4, 3), _flat_quad()[1], (4, 4)),
        ValueError,
        r"uv_rasterize: uv must have shape \[V, 2\], got \[4, 3\]",
    ),
    "dilate_texture mask": (
        lambda w: render.dilate_texture(torch.rand(3, 8, 8), torch.ones(1, 8, 8), 1),
        lambda w: render.dilate_texture(torch.rand(3, 8, 8), torch.ones(8, 7), 1),
        ValueError,
        r"dilate_texture: mask must have shape \[H, W\] \(W = 8 from image\)",
    ),
    "bake_surface_colours triangles": (
        None,
        lambda w: bake_surface_colours(w.v, w.tri.float(), None, 8),
        TypeError,
        r"bake_surface_colours: triangles must be an integer tensor",
    ),
    # mesh2tex.nn
    "FaceResNetBlock x": (
        lambda w: FaceResNetBlock(4, 6)(torch.rand(5, 4), torch.full((5, 9), -1)),
        lambda w: FaceResNetBlock(4, 6)(torch.rand(5, 3), torch.full((5, 9), -1)),
        ValueError,
        r"FaceResNetBlock: x must have shape \[\*, 4\], got \[5, 3\]",
    ),
    "gather_neighborhood neighbors": (
        lambda w: gather_neighborhood(torch.rand(5, 2), torch.full((5, 9), -1)),
        lambda w: gather_neighborhood(torch.rand(5, 2), torch.full((5, 9), -1.0)),
        TypeError,
        r"gather_neighborhood: neighbors must be an integer tensor",
    ),
    "MappingNetwork z": (
        lambda w: MappingNetwork(16, 16, 3, layers=2)(torch.randn(2, 16)),
        lambda w: MappingNetwork(16, 16, 3, layers=2)(torch.randn(2, 8)),
        ValueError,
        r"MappingNetwork: z must have shape \[\*, 16\], got \[2, 8\]",
    ),
    "TextureGenerator z": (
        lambda w: w.gen(w.batch, torch.randn(2, 16)),
        lambda w: w.gen(w.batch, torch.randn(3, 16)),
        ValueError,
        r"TextureGenerator: z must have shape \[B, 16\] \(B = 2 from batch\), got \[3, 16\]",
    ),
    "TextureGenerator.synthesize ws": (
        lambda w: w.gen.synthesize(w.batch, w.ws[:, 0], noise_mode="none"),
        lambda w: w.gen.synthesize(w.batch, w.ws[:1]),
        ValueError,
        r"TextureGenerator.synthesize: ws must have shape \[B, 9, 16\] \(B = 2 from batch\) or \[B, 16\], got \[1, 9, "
        r"16\]",
    ),
    "TextureGenerator.synthesize batch": (
        None,
        lambda w: w.gen.synthesize(dataclasses.replace(w.batch, face_features=w.batch.face_features[:, :3]), w.ws),
        ValueError,
        r"TextureGenerator.synthesize: batch.face_features must have shape \[\*, 4\]",
    ),
    "render_field_views mvp": (
        lambda w: render_field_views(w.gen, w.batch, w.ws, w.mvp, (8, 8), torch.zeros(2, 3)),
        lambda w: render_field_views(w.gen, w.batch, w.ws, w.mvp[:1], (8, 8), torch.zeros(1, 3)),
        ValueError,
        r"render_field_views: mvp holds 1 cameras, which cannot be split evenly over 2 shapes",
    ),
    "render_field_views background": (
        lambda w: render_field_views(w.gen, w.batch, w.ws, w.mvp, (8, 8), torch.zeros(2, 3, 8, 8)),
        lambda w: render_field_views(w.gen, w.batch, w.ws, w.mvp, (8, 8), torch.zeros(2, 3, 16, 16)),
        ValueError,
        r"render_field_views: background must have shape \[N, 3\] or \[N, 3, 8, 8\], got \[2, 3, 16, 16\]",
    ),
    "rasterize_batch mvp": (
        lambda w: rasterize_batch(w.batch, w.mvp, (8, 8)),
        lambda w: rasterize_batch(w.batch, w.mvp[0], (8, 8)),
        ValueError,
        r"rasterize_batch: mvp must have shape \[\*, 4, 4\], got \[4, 4\]",
    ),
    "FaceTexture.colours bary": (
        lambda w: w.gen.synthesize(w.batch, w.ws).colours(torch.arange(3), torch.rand(3, 3)),
        lambda w: w.gen.synthesize(w.batch, w.ws).colours(torch.arange(3), torch.rand(4, 3)),
        ValueError,
        r"FaceTexture.colours: bary must have shape \[P, 3\] \(P = 3 from triangle_id\), got \[4, 3\]",
    ),
    "NeuralField features": (
        lambda w: NeuralField(6, hidden=8, aux_dim=4)(torch.rand(5, 6), torch.rand(5, 3)),
        lambda w: NeuralField(6, hidden=8, aux_dim=4)(torch.rand(5, 7), torch.rand(5, 3)),
        ValueError,
        r"NeuralField: features must have shape \[P, 6\], got \[5, 7\]",
    ),
    "vertex_features quads": (
        lambda w: vertex_features(torch.rand(2, 3), torch.tensor([[0, 1, 2, 3], [1, 2, 3, 4]]), 5),
        lambda w: vertex_features(torch.rand(2, 3), torch.tensor([[0, 1, 2], [1, 2, 3]]), 5),
        ValueError,
        r"vertex_features: quads must have shape \[F, 4\]",
    ),
    "Discriminator images": (
        lambda w: Discriminator(8, DiscriminatorConfig(channel_base=64, channel_max=8))(torch.rand(2, 3, 8, 8)),
        lambda w: Discriminator(8, DiscriminatorConfig(channel_base=64, channel_max=8))(torch.rand(2, 3, 16, 16)),
        ValueError,
        r"Discriminator: images must have shape \[\*, 3, 8, 8\], got \[2, 3, 16, 16\]",
    ),
    "PoseNet images": (
        lambda w: PoseNet(width=4, feature_dim=8, hidden=8)(torch.rand(2, 3, 32, 32)),
        lambda w: PoseNet(width=4, feature_dim=8, hidden=8)(torch.rand(2, 4, 32, 32)),
        ValueError,
        r"PoseNet: images must have shape \[\*, 3, \*, \*\], got \[2, 4, 32, 32\]",
    ),
    "NocUNet masks": (
        lambda w: NocUNet(width=4, depth=2)(w.images, w.masks),
        lambda w: NocUNet(width=4, depth=2)(w.images, w.masks[:1]),
        ValueError,
        r"NocUNet: masks must have shape \[B, 1, H, W\] \(B = 2 from images\), got \[1, 1, 8, 8\]",
    ),
    "MeshNCA.step state": (
        lambda w: w.nca.step(w.state, w.graph),
        lambda w: w.nca.step(w.state[:, :5], w.graph),
        ValueError,
        r"MeshNCA.step: state must have shape \[\*, 16, 4\], got \[2, 5, 4\]",
    ),
    "MeshNCA.step graft": (
        lambda w: w.nca.step(w.state, w.graph, graft=(w.nca, torch.rand(16))),
        lambda w: w.nca.step(w.state, w.graph, graft=(w.nca, torch.rand(15))),
        ValueError,
        r"MeshNCA.step: graft alpha must have shape \[16\], got \[15\]",
    ),
    "MeshNCA.delta angle": (
        lambda w: w.nca.delta(w.state, w.graph, angle=torch.rand(16)),
        lambda w: w.nca.delta(w.state, w.graph, angle=torch.rand(3)),
        ValueError,
        r"MeshNCA.delta: angle must have shape \[\] or \[16\], got \[3\]",
    ),
    "MeshNCA.colours bary": (
        lambda w: w.nca.colours(
            w.state, w.graph.triangles, torch.arange(3), torch.rand(3, 3), torch.zeros(3, dtype=torch.long)
        ),
        lambda w: w.nca.colours(w.state, w.graph.triangles, torch.arange(3), torch.rand(3, 2)),
        ValueError,
        r"MeshNCA.colours: bary must have shape \[P, 3\], got \[3, 2\]",
    ),
    "MeshNCA.vertex_colours state": (
        lambda w: w.nca.vertex_colours(w.state),
        lambda w: w.nca.vertex_colours(w.state[0]),
        ValueError,
        r"MeshNCA.vertex_colours: state must have shape \[\*, \*, 4\], got \[16, 4\]",
    ),
    "render_states state": (
        lambda w: render_states(w.nca, w.state, w.graph, w.mvp, 8),
        lambda w: render_states(w.nca, w.state[:, :3], w.graph, w.mvp, 8),
        ValueError,
        r"render_states: state must have shape \[\*, 16, \*\], got \[2, 3, 4\]",
    ),
    "render_states mvp": (
        None,
        lambda w: render_states(w.nca, w.state, w.graph, torch.cat([w.mvp, w.mvp[:1]]), 8),
        ValueError,
        r"render_states: mvp holds 3 cameras, which cannot be split evenly over 2 states",
    ),
    "ConditionedNCA w": (
        lambda w: w.conditioned(w.batch, torch.rand(2, 16), torch.rand(w.batch.quads.shape[0], 3)),
        lambda w: w.conditioned(w.batch, torch.rand(1, 16), torch.rand(w.batch.quads.shape[0], 3)),
        ValueError,
        r"ConditionedNCA: w must have shape \[2, 16\], got \[1, 16\]",
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_wrong_argument_is_named_at_the_call(case, w):
    good, bad, error, message = CASES[case]
    if good is not None:
        good(w)
    with pytest.raises(error) as caught:
        bad(w)
    function = case.split(" ")[0]
    assert str(caught.value).startswith(function), str(caught.value)
    assert re.search(message, str(caught.value)), str(caught.value)


def test_check_shape_dtype_families():
    from mesh2tex.checks import check_shape, check_type

    check_shape(torch.zeros(2, dtype=torch.float16), "f: x", ("N",), dtype="float")
    check_shape(torch.zeros(2, dtype=torch.int32), "f: i", ("N",), dtype="int")
    with pytest.raises(TypeError, match="f: i must be an integer tensor, got bool"):
        check_shape(torch.zeros(2, dtype=torch.bool), "f: i", ("N",), dtype="int")
    with pytest.raises(TypeError, match="f: raster must be a Raster, got dict"):
        check_type({}, "f: raster", render.Raster)
