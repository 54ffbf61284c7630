"""The varied world (``prepare synthetic --variety real``): every family makes closed, labelled, well-sized
shapes; swept tubes have the volume of their circle times their length; the default boxy world is
byte for byte what it was; a varied world says so in its index and is rebuilt from it."""

import hashlib
import json
import math

import numpy as np
import pytest
import trimesh

from mesh2tex.cli import main
from mesh2tex.synthetic.solids import PART_ID
from mesh2tex.synthetic.sweeps import arc_points, cushion, tube
from mesh2tex.synthetic.variety import FAMILIES, collapse_short_edges, family_shares, generate_varied_shape
from mesh2tex.synthetic.world import WorldSpec, make_shape

FAMILY_CASES = [(category, name) for category, families in FAMILIES.items() for name in families]


@pytest.mark.parametrize("category,family", FAMILY_CASES)
def test_every_family_makes_closed_labelled_shapes_of_a_sensible_size(category, family):
    parts = FAMILIES[category][family][2]
    for seed in range(2):
        shape = generate_varied_shape(category, np.random.default_rng([11, seed]), "real", family)
        assert shape.params["family"] == family
        assert set(parts) <= set(shape.part_names), f"{family} lacks {set(parts) - set(shape.part_names)}"
        assert np.isfinite(shape.vertices).all()
        mesh = trimesh.Trimesh(shape.vertices, shape.faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0 and mesh.body_count == 1
        extent = shape.vertices.max(axis=0) - shape.vertices.min(axis=0)
        assert np.linalg.norm(extent) == pytest.approx(1.0) and extent.min() > 0.1  # normalised, no flat sheet
        assert 100 < len(shape.faces) < 8000
        if category == "car":  # long along z, the headlights in front, on its wheels
            assert extent[2] > 1.5 * extent[0] and extent[2] > 1.5 * extent[1]
            front = shape.vertices[shape.faces[shape.face_parts == PART_ID["headlight"]].reshape(-1), 2].mean()
            assert front > 0.3
            wheels = shape.vertices[shape.faces[shape.face_parts == PART_ID["wheel"]].reshape(-1), 1]
            assert wheels.min() == pytest.approx(shape.vertices[:, 1].min(), abs=1e-6)
        else:  # the seat is above the floor and, with a back, the back rises behind it
            seat = shape.vertices[shape.faces[shape.face_parts == PART_ID["seat"]].reshape(-1)].mean(axis=0)
            assert seat[1] > shape.vertices[:, 1].min() + 0.1
            if "back" in shape.part_names:
                back = shape.vertices[shape.faces[shape.face_parts == PART_ID["back"]].reshape(-1)].mean(axis=0)
                assert back[2] < seat[2] and back[1] > seat[1]


def test_shares_sum_to_one_and_every_family_is_drawn():
    for category in FAMILIES:
        assert sum(family_shares(category).values()) == pytest.approx(1.0)
    drawn = {generate_varied_shape("car", np.random.default_rng([5, k]), "real").params["family"] for k in range(40)}
    assert drawn == set(FAMILIES["car"])


def test_a_swept_tube_and_a_cushion_have_the_volume_they_should():
    radius, bend = 0.02, 0.3
    quarter = tube(arc_points((0, 0, 0), bend, 0, 90, 40, "zy"), radius, segments=48)
    assert quarter.volume() == pytest.approx(math.pi * radius**2 * bend * math.pi / 2, rel=0.02)
    ring = tube(arc_points((0, 0, 0), bend, 0, 360, 81, "xz")[:-1], radius, segments=24, closed=True)
    assert ring.genus() == 1
    pad = cushion((0.5, 0.1, 0.4), (0, 0, 0), 8.0, 8.0, segments=64, layers=30)
    assert 0.85 * 0.02 < pad.volume() < 0.02  # nearly the box, its edges rounded off


def test_short_edges_collapse_and_a_closed_surface_stays_closed():
    mesh = trimesh.creation.icosphere(subdivisions=2)
    vertices = mesh.vertices.copy()
    a, b = mesh.edges_unique[0]
    vertices[b] = vertices[a] + 1e-7  # one edge far below the threshold
    parts = np.zeros(len(mesh.faces), dtype=np.int64)
    result = collapse_short_edges(vertices, mesh.faces, parts)
    assert result is not None
    v, f, p = result
    assert len(v) == len(vertices) - 1 and len(f) == len(mesh.faces) - 2 and len(p) == len(f)
    assert trimesh.Trimesh(v, f, process=False).is_watertight


def _digest(shape) -> str:
    data = b"".join(np.ascontiguousarray(a).tobytes() for a in (shape.vertices, shape.faces, shape.face_parts))
    return hashlib.sha256(data).hexdigest()[:16]


def test_the_default_world_is_unchanged():
    # Digests of the boxy world's first shapes for seed 0, recorded before the varied world existed.
    assert _digest(make_shape(WorldSpec(category="chair"), 0)) == "9fc5f6167bd6ecf9"
    assert _digest(make_shape(WorldSpec(category="car"), 0)) == "271f223ede01cc98"
    assert "variety" not in WorldSpec().to_dict()  # a boxy world's index.json keeps its old settings
    with pytest.raises(ValueError, match="variety"):
        WorldSpec(variety="curvy")


def test_a_varied_world_records_its_variety_and_is_rebuilt_from_its_index(tmp_path):
    from mesh2tex.evaluation.world import world_spec
    from mesh2tex.geometry.mesh_io import load_mesh

    out = tmp_path / "world"
    argv = [
        "prepare",
        "synthetic",
        "--out",
        str(out),
        "--category",
        "chair",
        "--shapes",
        "2",
        "--views",
        "1",
        "--query-views",
        "1",
        "--resolution",
        "32",
        "--texture-size",
        "64",
        "--variety",
        "real",
        "--seed",
        "3",
    ]
    assert main(argv) == 0
    index = json.loads((out / "index.json").read_text())
    assert index["settings"]["variety"] == "real" and index["complete"]
    assert all(record["design"]["family"] in FAMILIES["chair"] for record in index["shapes"])
    spec = world_spec(index)
    assert spec.variety == "real"
    vertices, faces = load_mesh(out / "meshes" / "chair_0000.obj")
    shape = make_shape(spec, 0)
    assert faces.shape == shape.faces.shape and np.allclose(vertices[faces], shape.vertices[shape.faces], atol=1e-6)
