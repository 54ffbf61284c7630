"""Tangent direction fields (mesh2tex.geometry.direction_field): which way a pattern runs on the surface in
infer synthesize's charts and walked patches."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from mesh2tex.geometry.direction_field import field_turns, tangent_field
from mesh2tex.geometry.geodesic import SurfaceWalker


def slab_walker(extents=(2.0, 0.4, 2.0), subdivisions: int = 3) -> SurfaceWalker:
    """A box (a seat: wide, thin in y), its triangles split ``subdivisions`` times so the fields have room."""
    box = trimesh.creation.box(extents=extents)
    for _ in range(subdivisions):
        box = box.subdivide()
    return SurfaceWalker(np.asarray(box.vertices), np.asarray(box.faces))


@pytest.mark.parametrize("kind", ["up", "smooth"])
@pytest.mark.parametrize("mesh", ["slab", "sphere"])
def test_a_field_is_a_unit_tangent_on_every_face(kind, mesh):
    if mesh == "slab":
        walker = slab_walker()
    else:
        sphere = trimesh.creation.icosphere(3)
        walker = SurfaceWalker(np.asarray(sphere.vertices), np.asarray(sphere.faces))
    field = tangent_field(walker, kind)
    np.testing.assert_allclose(np.linalg.norm(field, axis=1), 1.0, atol=1e-9)
    assert np.abs((field * walker.normals).sum(1)).max() < 1e-9


def test_the_smooth_field_keeps_the_up_on_walls_and_folds_it_over_the_seat():
    """On the slab's sides both fields point up (the smooth one within 20 degrees, near the corners). On its
    top the up field falls back to x, a right angle away from the front's up folded over the front edge;
    the smooth field carries that fold on: near the front edge (z = +1, front facing +z) it runs back, -z,
    as a stripe running down the front would go on over the edge. It turns far less across edges than the
    up field."""
    walker = slab_walker()
    up, smooth = tangent_field(walker, "up"), tangent_field(walker, "smooth")
    normals, centres = walker.normals, walker.vertices.mean(1)
    side = np.abs(normals[:, 1]) < 0.5
    assert (smooth[side] @ [0.0, 1.0, 0.0]).min() > np.cos(np.radians(20))
    np.testing.assert_allclose(up[side], np.tile([0.0, 1.0, 0.0], (side.sum(), 1)), atol=1e-12)
    front_of_top = (normals[:, 1] > 0.99) & (centres[:, 2] > 0.85) & (np.abs(centres[:, 0]) < 0.3)
    assert front_of_top.sum() >= 2
    assert (smooth[front_of_top] @ [0.0, 0.0, -1.0]).min() > np.cos(np.radians(25))
    assert np.abs(up[front_of_top] @ [0.0, 0.0, -1.0]).max() < 1e-9  # the fallback x
    assert (field_turns(walker, smooth) > 30).sum() < (field_turns(walker, up) > 30).sum() / 3


def test_the_axis_chooses_which_way_the_field_runs():
    """--direction-axis x: on the slab's front (normal +z) the field is +x, on its top too (no fallback)."""
    walker = slab_walker()
    field = tangent_field(walker, "up", axis="x")
    front, top = walker.normals[:, 2] > 0.99, walker.normals[:, 1] > 0.99
    np.testing.assert_allclose(field[front | top], np.tile([1.0, 0.0, 0.0], ((front | top).sum(), 1)), atol=1e-12)
    smooth = tangent_field(walker, "smooth", axis="x")
    assert (smooth[front | top] @ [1.0, 0.0, 0.0]).min() > np.cos(np.radians(10))


def test_a_field_that_does_not_turn_has_no_turns_and_a_flip_is_half_a_turn():
    walker = slab_walker(subdivisions=1)
    top = np.flatnonzero(walker.normals[:, 1] > 0.99)
    field = tangent_field(walker, "up")  # x on the whole top: parallel there
    turns = field_turns(walker, field)
    from mesh2tex.geometry.direction_field import _interior_edges

    f, g, _ = _interior_edges(walker)
    on_top = np.isin(f, top) & np.isin(g, top)
    assert on_top.any() and turns[on_top].max() < 1e-6
    flipped = field.copy()
    flipped[top[0]] *= -1
    changed = field_turns(walker, flipped)[(f == top[0]) | (g == top[0])]
    assert np.all(changed[np.isin(np.r_[f, g][: len(f)][(f == top[0]) | (g == top[0])], top)] > 179)


def test_faces_wound_against_each_other_and_a_mesh_with_no_wall_still_get_a_field():
    """A plate facing up has no steep face to follow: the smooth field keeps the up field's fallback, x. A
    face wound the other way is not smoothed across but still gets a unit tangent."""
    plate = trimesh.creation.box(extents=(2.0, 2.0, 2.0)).subdivide()
    top = plate.face_normals[:, 1] > 0.99
    vertices, faces = np.asarray(plate.vertices), np.asarray(plate.faces)[top]
    faces[0] = faces[0][::-1]
    walker = SurfaceWalker(vertices, faces)
    field = tangent_field(walker, "smooth")
    np.testing.assert_allclose(np.abs(field @ [1.0, 0.0, 0.0]), 1.0, atol=1e-6)


def test_an_unknown_field_or_axis_is_refused_by_name():
    walker = slab_walker(subdivisions=0)
    with pytest.raises(ValueError, match="direction field"):
        tangent_field(walker, "sideways")
    with pytest.raises(ValueError, match="direction axis"):
        tangent_field(walker, "up", axis="w")


def test_the_command_lines_choices_are_the_fields_and_none():
    """DIRECTIONS is a literal so the CLI reads it without importing torch; it must follow FIELDS."""
    from mesh2tex.geometry.direction_field import FIELDS
    from mesh2tex.texel_synthesis import DIRECTIONS

    assert DIRECTIONS == (*FIELDS, "none")
