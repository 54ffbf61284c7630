"""Every checked public function of mesh2tex.transfer and .geometry, as tests/test_shape_checks_library.py checks
the losses and metrics: a correct call works, a wrong argument fails at the call naming the function and the
argument."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from shape_check_cases import ANY, R, check_case, correct_inputs, stand_in_layers

from mesh2tex.geometry import clean, features, hierarchy, levelset, prepare, prepared, primitives, regions
from mesh2tex.nn.pose import PoseBins
from mesh2tex.transfer import automaton, fit, optimise, pose
from mesh2tex.transfer import mask as transfer_mask
from mesh2tex.transfer.photo import FramedView, Photo


@pytest.fixture(scope="module")
def w():
    """Small correct inputs that the cases below break one argument at a time."""
    return correct_inputs()


TRANSFER = {
    "check_fit render_mask": (
        lambda w: fit.check_fit(w.photo.image, w.photo.mask, w.photo.image, w.photo.mask),
        lambda w: fit.check_fit(w.photo.image, w.photo.mask, w.photo.image, w.masks[:1]),
        ValueError,
        r"check_fit: render_mask must have shape \[1, 1, R, R\] \(R = 64 from photo_image\)",
    ),
    "outline_agreement b": (
        lambda w: fit.outline_agreement(w.photo.mask > 0.5, w.view.mask > 0.5, 1),
        lambda w: fit.outline_agreement(w.photo.mask > 0.5, w.view.mask, 1),
        TypeError,
        r"outline_agreement: b must be a bool tensor, got float32",
    ),
    "network_probability rgb": (
        None,
        lambda w: transfer_mask.network_probability("none", np.zeros((8, 8), np.uint8)),
        ValueError,
        r"network_probability: rgb must have shape \[H, W, 3\], got \[8, 8\]",
    ),
    "refine_with_grabcut probability": (
        lambda w: transfer_mask.refine_with_grabcut(np.zeros((16, 16, 3), np.uint8), np.full((16, 16), 0.6)),
        lambda w: transfer_mask.refine_with_grabcut(np.zeros((16, 16, 3), np.uint8), np.zeros((8, 16))),
        ValueError,
        r"refine_with_grabcut: probability must have shape \[H, W\] \(H = 16 from rgb\)",
    ),
    "predict_pose photo": (
        None,
        lambda w: pose.predict_pose("none", w.photo.image, "cpu"),
        TypeError,
        r"predict_pose: photo must be a Photo, got Tensor",
    ),
    "pose_network_beliefs photo.mask": (
        None,
        lambda w: pose.pose_network_beliefs("none", Photo(w.photo.image, w.masks[:1]), "cpu"),
        ValueError,
        r"pose_network_beliefs: photo.mask must have shape \[1, 1, R, R\] \(R = 64",
    ),
    "silhouette_iou elevations": (
        None,
        lambda w: pose.silhouette_iou(None, w.photo.mask, torch.zeros(3), torch.zeros(2), 2.0, 40.0, 0.1),
        ValueError,
        r"silhouette_iou: elevations must have shape \[N\] \(N = 3 from azimuths\)",
    ),
    "search_pose beliefs.elevation": (
        None,
        lambda w: pose.search_pose(
            None, w.photo, pose.PoseBeliefs(PoseBins(), torch.ones(12), torch.ones(5, 1)), 2.0, 40.0, w.cfg
        ),
        ValueError,
        r"search_pose: beliefs.elevation must have shape \[E\]",
    ),
    "estimate_pose photo.mask": (
        None,
        lambda w: pose.estimate_pose("none", None, Photo(w.images[:1], w.photo.mask), 2.0, 40.0, w.cfg, "cpu"),
        ValueError,
        r"estimate_pose: photo.mask must have shape \[1, 1, R, R\] \(R = 32 from photo.image\)",
    ),
    "predict_noc photo.image": (
        None,
        lambda w: pose.predict_noc("none", Photo(w.photo.image.half().long(), w.photo.mask), "cpu"),
        TypeError,
        r"predict_noc: photo.image must be a floating-point tensor",
    ),
    "PhotoLoss photo_noc": (
        lambda w: optimise.PhotoLoss(w.photo, w.view, w.noc, stand_in_layers, w.cfg, "cpu"),
        lambda w: optimise.PhotoLoss(w.photo, w.view, w.noc[:32, :32], stand_in_layers, w.cfg, "cpu"),
        ValueError,
        r"PhotoLoss: photo_noc must have shape \[R, R, 3\] \(R = 64 from photo.image\), got \[32, 32, 3\]",
    ),
    "PhotoLoss view.noc": (
        None,
        lambda w: optimise.PhotoLoss(
            w.photo,
            FramedView(w.view.mvp, R, (0, 0, R), w.noc[..., :2], w.view.mask),
            None,
            stand_in_layers,
            w.cfg,
            "cpu",
        ),
        ValueError,
        r"PhotoLoss: view.noc must have shape \[R, R, 3\]",
    ),
    "PhotoLoss image": (
        lambda w: w.loss(w.photo.image, use_global=True),
        lambda w: w.loss(w.images[:1], use_global=True),
        ValueError,
        r"PhotoLoss: image must have shape \[1, 3, R, R\] \(R = 64 from photo.image\), got \[1, 3, 32",
    ),
    "transfer_texture view": (
        None,
        lambda w: optimise.transfer_texture(None, None, w.photo, w.photo, None, stand_in_layers, w.cfg, "cpu"),
        TypeError,
        r"transfer_texture: view must be a FramedView, got Photo",
    ),
    "unseen_anchors view.mvp": (
        None,
        lambda w: optimise.unseen_anchors(
            None, FramedView(torch.eye(4), R, (0, 0, R), w.noc, w.view.mask), None, None, w.cfg, "cpu", None, None
        ),
        ValueError,
        r"unseen_anchors: view.mvp must have shape \[1, 4, 4\], got \[4, 4\]",
    ),
    "fit_automaton photo_noc": (
        None,
        lambda w: automaton.fit_automaton(None, w.photo, w.view, w.noc.long(), None, w.cfg, None, "cpu"),
        TypeError,
        r"fit_automaton: photo_noc must be a floating-point tensor",
    ),
}

GEOMETRY = {
    "quads_to_triangles quads": (
        lambda w: prepared.quads_to_triangles(torch.as_tensor(w.quads)),
        lambda w: prepared.quads_to_triangles(w.triangles),
        ValueError,
        r"quads_to_triangles: quads must have shape \[F, 4\], got \[48, 3\]",
    ),
    "edge_neighbors quads": (
        lambda w: hierarchy.edge_neighbors(w.quads),
        lambda w: hierarchy.edge_neighbors(w.quads.ravel()),
        ValueError,
        r"edge_neighbors: quads must have shape \[F, 4\], got \[96\]",
    ),
    "face_neighborhoods vertices": (
        lambda w: hierarchy.face_neighborhoods(w.vertices, w.quads),
        lambda w: hierarchy.face_neighborhoods(w.vertices[:, :2], w.quads),
        ValueError,
        ANY,
    ),
    "face_centres quads": (
        lambda w: hierarchy.face_centres(w.vertices, w.quads),
        lambda w: hierarchy.face_centres(w.vertices, w.triangles),
        ValueError,
        ANY,
    ),
    "pooling_map coarse_quads": (
        lambda w: hierarchy.pooling_map(w.vertices, w.quads, w.vertices, w.quads[:6]),
        lambda w: hierarchy.pooling_map(w.vertices, w.quads, w.vertices, w.triangles),
        ValueError,
        r"pooling_map: coarse_quads must have shape \[F_c, 4\]",
    ),
    "orient_coherently vertices": (
        lambda w: hierarchy.orient_coherently(w.vertices, w.quads),
        lambda w: hierarchy.orient_coherently(w.vertices.tolist()[0], w.quads),
        ValueError,
        ANY,
    ),
    "quad_normals quads": (
        lambda w: features.quad_normals(w.vertices, w.quads),
        lambda w: features.quad_normals(w.vertices, w.quads[0]),
        ValueError,
        r"quad_normals: quads must have shape \[F, 4\], got \[4\]",
    ),
    "vertex_normals vertices": (
        lambda w: features.vertex_normals(w.vertices, w.quads),
        lambda w: features.vertex_normals(w.vertices[None], w.quads),
        ValueError,
        ANY,
    ),
    "fundamental_forms quads": (
        lambda w: features.fundamental_forms(w.vertices, w.quads),
        lambda w: features.fundamental_forms(w.vertices, w.triangles),
        ValueError,
        ANY,
    ),
    "face_features vertices": (
        lambda w: features.face_features(w.vertices, w.quads),
        lambda w: features.face_features(w.vertices.T, w.quads),
        ValueError,
        ANY,
    ),
    "noc_coordinates vertices": (
        lambda w: features.noc_coordinates(w.vertices / 4),
        lambda w: features.noc_coordinates(w.vertices[:, :2]),
        ValueError,
        ANY,
    ),
    "normalize vertices": (
        lambda w: clean.normalize(w.vertices),
        lambda w: clean.normalize(w.vertices.ravel()),
        ValueError,
        ANY,
    ),
    "mesh_set faces": (
        None,
        lambda w: clean.mesh_set(w.vertices, w.quads),
        ValueError,
        r"mesh_set: faces must have shape \[T, 3\]",
    ),
    "clean_mesh faces": (None, lambda w: clean.clean_mesh(w.vertices, w.quads), ValueError, ANY),
    "triangle_areas faces": (
        lambda w: clean.triangle_areas(w.vertices, w.triangles),
        lambda w: clean.triangle_areas(w.vertices, w.quads),
        ValueError,
        ANY,
    ),
    "decimate vertices": (
        lambda w: clean.decimate(w.vertices, w.triangles, 1000),
        lambda w: clean.decimate(w.vertices[:, :2], w.triangles, 1000),
        ValueError,
        ANY,
    ),
    "isotropic_remesh faces": (None, lambda w: clean.isotropic_remesh(w.vertices, w.quads, 0.1), ValueError, ANY),
    "prepare_shape faces": (
        None,
        lambda w: prepare.prepare_shape(w.vertices, w.quads),
        ValueError,
        r"prepare_shape: faces must have shape \[T, 3\], got \[24, 4\]",
    ),
    "surface_deviation quads": (
        lambda w: prepare.surface_deviation(w.vertices, w.triangles, w.vertices, w.quads, max_points=100),
        lambda w: prepare.surface_deviation(w.vertices, w.triangles, w.vertices, w.triangles),
        ValueError,
        ANY,
    ),
    "coarseness_check quad_vertices": (
        None,
        lambda w: prepare.coarseness_check(w.vertices, w.triangles, w.vertices[:, :2], w.quads, 24),
        ValueError,
        r"coarseness_check: quad_vertices must have shape \[V', 3\]",
    ),
    "subdivide_quads quads": (
        lambda w: primitives.subdivide_quads(w.vertices, w.quads),
        lambda w: primitives.subdivide_quads(w.vertices, w.triangles),
        ValueError,
        ANY,
    ),
    "unit_surface faces": (
        lambda w: primitives.unit_surface(w.vertices, w.triangles),
        lambda w: primitives.unit_surface(w.vertices, w.quads[:, :2]),
        ValueError,
        r"unit_surface: faces must have shape \[F, 4\] or \[F, 3\], got \[24, 2\]",
    ),
    "unit_transform vertices": (
        lambda w: primitives.unit_transform(w.vertices),
        lambda w: primitives.unit_transform(w.vertices[0]),
        ValueError,
        ANY,
    ),
    "mean_edge_length faces": (
        lambda w: primitives.mean_edge_length(w.vertices, w.quads),
        lambda w: primitives.mean_edge_length(w.vertices, w.quads.ravel()),
        ValueError,
        ANY,
    ),
    "expression_weights positions": (
        lambda w: regions.expression_weights("x > 0", w.vertices),
        lambda w: regions.expression_weights("x > 0", w.vertices[:, :2]),
        ValueError,
        r"expression_weights: positions must have shape \[V, 3\], got \[26, 2\]",
    ),
    "region_weights positions": (None, lambda w: regions.region_weights("x > 0", w.vertices[:, 0]), ValueError, ANY),
    "surface_samples faces": (
        lambda w: levelset.surface_samples(w.vertices, w.triangles, 0.5),
        lambda w: levelset.surface_samples(w.vertices, w.quads, 0.5),
        ValueError,
        ANY,
    ),
    "solid_field samples": (None, lambda w: levelset.solid_field(w.vertices[:, :2], 0.5, 0.1), ValueError, ANY),
    "make_well_composed inside": (
        lambda w: levelset.make_well_composed(np.zeros((4, 4, 4), bool)),
        lambda w: levelset.make_well_composed(np.zeros((4, 4), bool)),
        ValueError,
        r"make_well_composed: inside must have shape \[X, Y, Z\], got \[4, 4\]",
    ),
}

CASES = {**TRANSFER, **GEOMETRY}


@pytest.mark.parametrize("case", list(CASES))
def test_each_checked_function_passes_a_correct_call_and_names_a_wrong_argument(case, w):
    check_case(CASES, case, w)


def test_check_array_shape_reads_shapes_of_arrays_lists_and_tensors():
    from mesh2tex.checks import check_array_shape

    sizes = check_array_shape(np.zeros((5, 3)), "f: v", ("V", 3))
    assert sizes == {"V": (5, "v")}
    check_array_shape([[0, 1, 2, 3]], "f: q", ("F", 4))
    check_array_shape(torch.zeros(5, 2), "f: uv", ("V", 2), sizes=sizes)
    assert check_array_shape(None, "f: x", ("V", 3), optional=True) == {}
    with pytest.raises(ValueError, match=r"f: uv must have shape \[V, 2\] \(V = 5 from v\), got \[4, 2\]"):
        check_array_shape(np.zeros((4, 2)), "f: uv", ("V", 2), sizes=sizes)
