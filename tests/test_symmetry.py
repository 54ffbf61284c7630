"""The turns that leave a shape as it was, and the pose error counted up to them: a bench without a back
photographed from behind is the same photo, so a pose found half a turn off on it is no error."""

import numpy as np
import pytest
import trimesh

from mesh2tex.geometry.symmetry import azimuth_symmetries, mirror_axis, mirrored_azimuth
from mesh2tex.nn.pose import symmetric_azimuth_error


def box_mesh(*specs) -> trimesh.Trimesh:
    """Axis-aligned boxes, each (extents, centre), y up, as one mesh; subdivided so that every part has
    as many vertices as its size asks."""
    meshes = []
    for extents, centre in specs:
        box = trimesh.creation.box(extents=extents)
        box.apply_translation(centre)
        meshes.append(box.subdivide().subdivide())
    return trimesh.util.concatenate(meshes)


def boxes(*specs) -> np.ndarray:
    """The vertices of :func:`box_mesh`."""
    return np.asarray(box_mesh(*specs).vertices)


def legs(width: float, depth: float) -> list:
    return [((0.04, 0.45, 0.04), (x, 0.225, z)) for x in (-width / 2, width / 2) for z in (-depth / 2, depth / 2)]


SEAT = ((0.45, 0.05, 0.45), (0.0, 0.47, 0.0))


def test_a_square_stool_looks_the_same_every_quarter_turn():
    assert azimuth_symmetries(boxes(SEAT, *legs(0.4, 0.4))) == [0.0, 90.0, 180.0, 270.0]


def test_a_backless_bench_looks_the_same_half_a_turn_round_and_a_chair_with_a_back_never():
    bench = boxes(((1.4, 0.05, 0.35), (0.0, 0.47, 0.0)), *legs(1.3, 0.3))
    assert azimuth_symmetries(bench) == [0.0, 180.0]
    chair = boxes(SEAT, *legs(0.4, 0.4), ((0.45, 0.5, 0.04), (0.0, 0.75, -0.2)))
    assert azimuth_symmetries(chair) == [0.0]


def test_the_turns_are_about_the_shapes_own_axis_wherever_the_file_puts_it():
    stool = boxes(SEAT, *legs(0.4, 0.4))
    assert azimuth_symmetries(stool + np.array([3.0, 1.0, -2.0])) == [0.0, 90.0, 180.0, 270.0]
    # three legs splayed past a round seat: the bounding box's centre is off the axis, the vertices' mean on it
    assert azimuth_symmetries(three_legged_stool()) == [0.0, 120.0, 240.0]


def three_legged_stool() -> np.ndarray:
    parts = [trimesh.creation.cylinder(radius=0.2, height=0.05, sections=72)]
    parts[0].apply_translation((0.0, 0.0, 0.47))
    for angle in np.radians([90.0, 210.0, 330.0]):
        leg = trimesh.creation.cylinder(radius=0.02, height=0.45, sections=12)
        leg.apply_translation((0.3 * np.cos(angle), 0.3 * np.sin(angle), 0.225))  # splayed past the seat
        parts.append(leg.subdivide())
    return np.asarray(trimesh.util.concatenate(parts).vertices)[:, [0, 2, 1]]  # z up -> y up


def test_a_round_shape_looks_the_same_at_every_azimuth():
    cylinder = np.asarray(trimesh.creation.cylinder(radius=0.3, height=0.5, sections=72).vertices)[:, [0, 2, 1]]
    assert len(azimuth_symmetries(cylinder, step=5.0)) == 72


def test_the_symmetric_error_is_the_smallest_error_to_any_equivalent_pose():
    assert symmetric_azimuth_error(182.0, 0.0, [0.0, 180.0]) == pytest.approx(2.0)
    assert symmetric_azimuth_error(182.0, 0.0, [0.0]) == pytest.approx(178.0)
    assert symmetric_azimuth_error(355.0, 95.0, [0.0, 90.0, 180.0, 270.0]) == pytest.approx(10.0)


def test_a_shape_of_one_point_keeps_the_plain_error():
    assert azimuth_symmetries(np.ones((5, 3))) == [0.0]


def test_vertices_of_the_wrong_shape_are_refused_by_name():
    with pytest.raises(ValueError, match="azimuth_symmetries: vertices"):
        azimuth_symmetries(np.zeros((10, 2)))


def test_a_chair_mirrors_across_the_plane_between_its_left_and_right_and_a_one_armed_chair_across_none():
    back = ((0.45, 0.5, 0.04), (0.0, 0.75, -0.2))
    chair = box_mesh(SEAT, *legs(0.4, 0.4), back)
    v, f = np.asarray(chair.vertices), np.asarray(chair.faces)
    assert mirror_axis(v, f) == 0
    assert mirror_axis(v[:, [2, 1, 0]], f) == 2  # turned a quarter: the plane is normal to z
    assert mirror_axis(v + np.array([3.0, 1.0, -2.0]), f) == 0  # wherever the file puts it
    one_arm = box_mesh(SEAT, *legs(0.4, 0.4), back, ((0.04, 0.25, 0.4), (0.22, 0.6, 0.0)))
    assert mirror_axis(np.asarray(one_arm.vertices), np.asarray(one_arm.faces)) is None
    # a symmetric surface meshed finer on one side: its vertices do not mirror, its surface does
    slab = trimesh.creation.box(extents=(1.0, 0.6, 0.4))
    for _ in range(3):
        slab = slab.subdivide(face_index=np.flatnonzero(slab.triangles_center[:, 0] > 0))
    assert len(slab.vertices) > 50 and (slab.vertices[:, 0] > 0.01).sum() > 5 * (slab.vertices[:, 0] < -0.01).sum()
    assert mirror_axis(np.asarray(slab.vertices), np.asarray(slab.faces)) in (0, 2)


def test_the_mirrored_camera_sits_where_the_plane_reflects_it():
    import torch

    from mesh2tex.render import orbit_direction

    for axis in (0, 2):
        for azimuth in (10.0, 75.0, 200.0, 330.0):
            eye = orbit_direction(torch.tensor([azimuth]), torch.tensor([20.0]))[0]
            reflected = eye.clone()
            reflected[axis] *= -1.0
            mirrored = orbit_direction(torch.tensor([mirrored_azimuth(azimuth, axis)]), torch.tensor([20.0]))[0]
            assert torch.allclose(mirrored, reflected, atol=1e-6)
    with pytest.raises(ValueError, match="axis 1"):
        mirrored_azimuth(10.0, 1)
