"""Quad hierarchies that really coarsen: strict ratios, closed manifold quads, no silent fallback, failures with a
reason."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

import mesh2tex.geometry.quadremesh as quadremesh
from mesh2tex.cli import main
from mesh2tex.errors import InputError
from mesh2tex.geometry.hierarchy import edge_neighbors, face_neighborhoods
from mesh2tex.geometry.levelset import SolidField, make_well_composed, solid_field, surface_net_quads, surface_samples
from mesh2tex.geometry.prepare import prepare_shape
from mesh2tex.synthetic.shapes import generate_shape


def thin_legged_stool() -> trimesh.Trimesh:
    """A seat on four legs and two rungs about 1 % of the diagonal thick, all separate boxes."""
    parts = [trimesh.creation.box((1.0, 0.04, 1.0)).apply_translation((0, 1.0, 0))]
    parts += [
        trimesh.creation.box((0.022, 1.0, 0.022)).apply_translation((x, 0.5, z))
        for x in (-0.45, 0.45)
        for z in (-0.45, 0.45)
    ]
    parts += [trimesh.creation.box((0.9, 0.022, 0.022)).apply_translation((0, 0.3, z)) for z in (-0.45, 0.45)]
    return trimesh.util.concatenate(parts)


def scattered_open_parts() -> trimesh.Trimesh:
    """Disconnected parts with open boundaries: an open tube, a bowl and a small sheet."""
    tube = trimesh.creation.cylinder(0.3, 1.5, sections=32)
    tube = trimesh.Trimesh(tube.vertices, tube.faces[np.abs(tube.face_normals[:, 2]) < 0.5])
    sphere = trimesh.creation.icosphere(3)
    bowl = trimesh.Trimesh(sphere.vertices, sphere.faces[sphere.triangles_center[:, 1] < 0.3]).apply_translation(
        (2.0, 0, 0)
    )
    sheet = trimesh.Trimesh(
        [[0, 0, 0], [0.8, 0, 0], [0.8, 0, 0.8], [0, 0, 0.8]], [[0, 2, 1], [0, 3, 2]]
    ).apply_translation((-1.5, 0.5, 0))
    return trimesh.util.concatenate([tube, bowl, sheet])


def check_level(vertices: np.ndarray, quads: np.ndarray, neighbors: np.ndarray) -> None:
    """A closed manifold pure-quad mesh whose neighbourhood table is consistent."""
    assert quads.ndim == 2 and quads.shape[1] == 4
    ordered = np.sort(quads, axis=1)
    assert (ordered[:, 1:] != ordered[:, :-1]).all(), "no quad repeats a vertex"
    edges = np.sort(np.stack([quads, np.roll(quads, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert (counts == 2).all(), "closed and edge-manifold: every edge on exactly two quads"
    assert (edge_neighbors(quads) >= 0).all()
    assert np.array_equal(neighbors, face_neighborhoods(vertices, quads))
    for face in range(len(quads)):
        ring = neighbors[face, 1:]
        for nb in ring[0::2]:
            assert face in neighbors[nb, 1::2], "edge neighbours are symmetric"
        for nb in ring[1::2][ring[1::2] >= 0]:
            assert len(set(quads[face]) & set(quads[nb])) == 1, "a corner neighbour shares exactly one vertex"


@pytest.fixture(scope="module")
def hierarchies():
    """Hard inputs prepared once as 1536, 384, 96, 24-quad hierarchies."""
    chair = generate_shape("chair", np.random.default_rng(3))
    car = generate_shape("car", np.random.default_rng(4))
    inputs = {
        "chair": (chair.vertices, chair.faces),
        "car": (car.vertices, car.faces),
        "stool": (thin_legged_stool().vertices, thin_legged_stool().faces),
        "open_parts": (scattered_open_parts().vertices, scattered_open_parts().faces),
    }
    return {
        name: prepare_shape(v, f, face_count=1536, levels=4, seed=0, source=name) for name, (v, f) in inputs.items()
    }


@pytest.mark.parametrize("name", ["chair", "car", "stool", "open_parts"])
def test_every_level_is_strictly_coarser_closed_and_pooled(hierarchies, name):
    shape = hierarchies[name]
    counts = shape.face_counts
    assert 0.7 * 1536 <= counts[0] <= 1.4 * 1536, counts
    for level in range(1, 4):
        assert 2.0 <= counts[level - 1] / counts[level] <= 8.0, counts
    for level in range(4):
        check_level(shape.vertices[level].astype(np.float64), shape.quads[level], shape.neighbors[level])
    for level in range(3):
        assert np.array_equal(np.unique(shape.pool[level]), np.arange(counts[level + 1])), (
            "every coarse face receives a fine face"
        )
    levels = shape.metadata["levels"]
    assert [l["faces"] for l in levels] == counts
    assert levels[0]["ratio"] is None and all(
        l["ratio"] == pytest.approx(counts[i] / counts[i + 1], abs=1e-3) for i, l in enumerate(levels[1:])
    )
    assert not any("copy" in l["method"] for l in levels)
    # a level made by a fallback says so
    for level in levels:
        assert bool(level["warnings"]) == level["method"].startswith("surface nets")


def test_coarse_levels_keep_every_part_of_the_shape(hierarchies):
    """Every foot of the stool's 1 %-thick legs has quads near it on every level, the coarsest included."""
    shape = hierarchies["stool"]
    transform = shape.metadata["transform"]
    feet = (np.array([[x, 0.0, z] for x in (-0.45, 0.45) for z in (-0.45, 0.45)]) - transform["center"]) * transform[
        "scale"
    ]
    for level in range(4):
        v = shape.vertices[level].astype(np.float64)
        edge = np.sqrt(1.0 / shape.face_counts[level])  # about a quad's edge on a surface of area ~1
        reach = np.linalg.norm(v[None, :, :] - feet[:, None, :], axis=2).min(axis=1)
        assert reach.max() < 0.05 + 1.5 * edge, (level, reach)


def test_surface_nets_close_an_open_sheet_into_a_manifold_quad_mesh():
    sheet = trimesh.creation.box((1.0, 1.0, 0.0001))  # nearly flat, two faces apart by a hair
    samples = surface_samples(sheet.vertices, sheet.faces[:2], 0.02)  # one side only: an open sheet
    v, q = surface_net_quads(solid_field(samples, spacing=0.1, offset=0.09))
    assert len(q) > 0
    edges = np.sort(np.stack([q, np.roll(q, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    assert (np.unique(edges, axis=0, return_counts=True)[1] == 2).all()
    normals = np.cross(v[q[:, 2]] - v[q[:, 0]], v[q[:, 3]] - v[q[:, 1]])
    assert np.einsum("ij,ij->i", normals, v[q].mean(axis=1)).sum() > 0, "oriented outwards"


def test_well_composed_repair_removes_edge_and_vertex_contacts():
    solid = np.zeros((6, 6, 6), dtype=bool)
    solid[2, 2, 2] = solid[3, 3, 2] = True  # two voxels touching along an edge only
    fixed = make_well_composed(solid)
    assert fixed[2, 2, 2] and fixed[3, 3, 2] and fixed.sum() == 3
    corner = np.zeros((6, 6, 6), dtype=bool)
    corner[2, 2, 2] = corner[3, 3, 3] = True  # touching at a vertex only
    fixed = make_well_composed(corner)
    assert fixed[2, 2, 2] and fixed[3, 3, 3] and fixed.sum() >= 4
    field = SolidField(phi=np.where(corner, -1.0, 1.0), origin=np.zeros(3), spacing=1.0, offset=0.0)
    v, q = surface_net_quads(field)
    edges = np.sort(np.stack([q, np.roll(q, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    assert (np.unique(edges, axis=0, return_counts=True)[1] == 2).all(), (
        "surface nets of the repaired solid are manifold"
    )


def test_samples_of_a_sliver_grow_with_its_area_not_its_length():
    sliver = np.array([[0.0, 0, 0], [1.0, 0, 0], [0.5, 0.01, 0]])
    points = surface_samples(sliver, np.array([[0, 1, 2]]), 0.01)
    assert len(points) < 1000
    spread = np.abs(points[:, 0][:, None] - np.linspace(0, 1, 101)[None, :]).min(axis=0)
    assert spread.max() <= 0.01, "no gap along the sliver"


def test_a_level_nothing_can_make_fails_the_shape_with_the_reasons(monkeypatch):
    box = trimesh.creation.box()

    def broken(*args, **kwargs):
        raise quadremesh.QuadRemeshError("QuadriFlow crashed (signal 11)")

    monkeypatch.setattr(quadremesh, "quadriflow", broken)
    monkeypatch.setattr(
        quadremesh, "surface_net_quads", lambda field: (np.zeros((0, 3)), np.zeros((0, 4), dtype=np.int64))
    )
    with pytest.raises(InputError) as error:
        prepare_shape(box.vertices, box.faces, face_count=96, levels=2)
    message = str(error.value)
    assert "level 0" in message and "signal 11" in message and "empty result" in message


def test_a_fallback_level_is_ok_with_a_warning_in_index_json(tmp_path, monkeypatch):
    real = quadremesh.quadriflow

    def coarse_fails(vertices, faces, target, seed=0, **kwargs):
        if target < 200:
            raise quadremesh.QuadRemeshError("QuadriFlow internal error: test")
        return real(vertices, faces, target, seed, **kwargs)

    monkeypatch.setattr(quadremesh, "quadriflow", coarse_fails)
    trimesh.creation.icosphere(3).export(tmp_path / "ball.ply")
    out = tmp_path / "out"
    assert (
        main(
            [
                "prepare",
                "shapes",
                "--input",
                str(tmp_path / "ball.ply"),
                "--out",
                str(out),
                "--faces",
                "384",
                "--levels",
                "2",
            ]
        )
        == 0
    )
    entry = json.loads((out / "index.json").read_text())["shapes"][0]
    assert entry["status"] == "ok"
    assert entry["levels"][1]["method"].startswith("surface nets") and entry["levels"][1]["ratio"] >= 2.0
    assert entry["warnings"] and entry["warnings"][0].startswith("level 1:")
    assert entry["levels"][0]["method"].startswith("quadriflow(input")
