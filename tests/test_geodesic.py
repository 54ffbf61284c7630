"""Geodesic walks and charts (mesh2tex.geometry.geodesic): what the surface method of infer synthesize
relies on to see the surface as it is."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from mesh2tex.geometry.geodesic import SurfaceWalker, geodesic_charts, weld_positions
from mesh2tex.geometry.hierarchy import polygon_edge_neighbors


def box_walker(split: bool = False) -> SurfaceWalker:
    """The cube [-1, 1]^3, its vertices shared or (``split``) copied per triangle, as an atlas's seams split them."""
    box = trimesh.creation.box(extents=(2, 2, 2))
    vertices, faces = np.asarray(box.vertices), np.asarray(box.faces)
    if split:
        vertices, faces = vertices[faces.reshape(-1)], np.arange(faces.size).reshape(-1, 3)
    return SurfaceWalker(vertices, faces, min_chord=0.0)


def start_on(walker: SurfaceWalker, point) -> tuple[np.ndarray, np.ndarray]:
    """The face holding ``point`` and its barycentrics there."""
    for face in range(len(walker.faces)):
        corners = walker.vertices[face]
        if abs((np.asarray(point) - corners[0]) @ walker.normals[face]) > 1e-9:
            continue
        bary = np.linalg.lstsq(np.vstack([corners.T, np.ones(3)]), np.r_[point, 1.0], rcond=None)[0]
        if (bary >= -1e-12).all():
            return np.array([face]), bary[None]
    raise AssertionError(f"no face holds {point}")


@pytest.mark.parametrize("split", [False, True])
def test_a_walk_over_a_cube_unfolds_across_its_edges(split):
    """From (0.3, 1, 0.2) on the top, +z for 3: 0.8 to the front edge, 2 down the front, 0.2 back along
    the bottom; and a diagonal walk over a corner edge lands where the unfolded net says. Split vertices
    (an atlas's seams) change nothing."""
    walker = box_walker(split)
    face, bary = start_on(walker, (0.3, 1.0, 0.2))
    for step, expected in [((0, 0, 3.0), (0.3, -1.0, 0.8)), ((1.2, 0, 1.6), (1.0, 0.2, 0.5))]:
        end_face, end_bary, valid = walker.walk(face, bary, np.array([step]))
        assert valid.all()
        np.testing.assert_allclose(walker.point(end_face, end_bary)[0], expected, atol=1e-9)


def test_walks_on_a_sphere_follow_great_circles():
    """On a fine sphere, the end of a walk of length L is L away along the great circle (within 0.5%)."""
    sphere = trimesh.creation.icosphere(5)
    walker = SurfaceWalker(sphere.vertices, sphere.faces)
    rng = np.random.default_rng(0)
    face, bary = walker.sample(500, rng)
    frames = walker.frames(face, rng.random(500) * 2 * np.pi)
    length = 0.05 + rng.random(500) * 1.2
    end_face, end_bary, valid = walker.walk(face, bary, frames[:, 0] * length[:, None])
    assert valid.all()
    start, end = walker.point(face, bary), walker.point(end_face, end_bary)
    cosine = (start * end).sum(1) / np.linalg.norm(start, axis=1) / np.linalg.norm(end, axis=1)
    ratio = np.arccos(np.clip(cosine, -1, 1)) / length
    assert np.abs(ratio - 1).max() < 0.005


def test_a_walk_off_a_boundary_or_around_a_thin_tube_is_invalid():
    """An open square: a walk off its edge is invalid, one inside it valid. A thin tube: a walk half way
    around it (its end near its start) is invalid, a short one valid."""
    plane = trimesh.creation.box(extents=(2, 2, 2))
    top = plane.faces[plane.face_normals[:, 1] > 0.5]
    walker = SurfaceWalker(plane.vertices, top)
    face, bary = start_on(walker, (0.0, 1.0, 0.0))
    _, _, valid = walker.walk(np.repeat(face, 2), np.repeat(bary, 2, 0), np.array([[0.5, 0, 0], [1.5, 0, 0]]))
    assert valid.tolist() == [True, False]

    tube = trimesh.creation.cylinder(radius=0.05, height=2.0, sections=32)
    walker = SurfaceWalker(tube.vertices, tube.faces)
    side = np.flatnonzero(np.abs(walker.normals[:, 2]) < 0.1)[:1]
    bary = np.full((1, 3), 1 / 3)
    frames = walker.frames(side)  # u along the tube's axis is not the mesh's up here; r goes around or along
    around = frames[:, 0] if abs(frames[0, 0, 2]) < 0.5 else frames[:, 1]
    _, _, valid = walker.walk(np.repeat(side, 2), np.repeat(bary, 2, 0), np.vstack([around * 0.03, around * 0.16]))
    assert valid.tolist() == [True, False]


def test_frames_point_up_the_mesh_and_face_outwards():
    """On a box's sides u is +y and (r, u, n) right-handed; on its top (up along the normal) u falls back to
    a horizontal direction; a roll turns the frame about the normal."""
    walker = box_walker()
    faces = np.arange(len(walker.faces))
    frames = walker.frames(faces)
    r, u, n = frames[:, 0], frames[:, 1], walker.normals
    side = np.abs(n[:, 1]) < 0.5
    np.testing.assert_allclose(u[side], np.tile([0.0, 1.0, 0.0], (side.sum(), 1)), atol=1e-12)
    np.testing.assert_allclose(np.cross(r, u), n, atol=1e-12)
    assert np.abs((u * n).sum(1)).max() < 1e-12
    rolled = walker.frames(faces, np.pi / 2)
    np.testing.assert_allclose(rolled[:, 0], u, atol=1e-12)


def test_edge_neighbours_pair_manifold_edges_and_leave_others():
    """Two triangles sharing an edge see each other across it (the walker's columns: the edge opposite each
    corner); a third on the same edge makes it non-manifold."""
    corners = np.array([[0, 1, 2], [2, 1, 3]])
    assert polygon_edge_neighbors(corners).tolist() == [[-1, 1, -1], [0, -1, -1]]  # edges (v_i, v_i+1)
    walker = SurfaceWalker(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]), corners)
    assert walker.neighbours.tolist() == [[1, -1, -1], [-1, -1, 0]]
    assert (polygon_edge_neighbors(np.vstack([corners, [[1, 2, 4]]])) == -1).all()
    assert weld_positions(np.array([[0.0, 0, 0], [1, 0, 0], [0, 0, 0]])).tolist() == [0, 1, 0]


def test_a_chart_of_horizontal_bands_on_an_upright_side_has_constant_rows():
    """A chart on a box's side with direction up: its rows run level, so a pattern banded in y is constant
    along every row and changes down the columns."""
    walker = box_walker()
    face, bary = start_on(walker, (0.1, 0.0, 1.0))
    faces, barys, valid = geodesic_charts(walker, face, bary, walker.frames(face), 16, 0.05)
    assert valid.all()
    points = (walker.vertices[faces] * barys[..., None]).sum(-2)[0]  # (16, 16, 3)
    # level to rounding: rows here lie on the bands' edges (y = 3/8), where floor(8 y) alone would flip
    np.testing.assert_allclose(points[..., 1], points[:, :1, 1].repeat(16, axis=1), atol=1e-9)
    bands = np.floor(points[:, 0, 1] * 8 + 1e-6)
    assert len(np.unique(bands)) > 4
    assert points[0, 0, 1] > points[-1, 0, 1]  # row 0 is the top


def test_a_mesh_without_area_has_no_points_to_sample():
    flat = SurfaceWalker(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="no triangle of non-zero area"):
        flat.sample(4, np.random.default_rng(0))
