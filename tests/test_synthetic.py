"""The synthetic world: shapes are closed and look like their category, materials are sane, the dataset is
consistent."""

import json

import numpy as np
import pytest
import torch
import trimesh
from PIL import Image

from mesh2tex.cli import main
from mesh2tex.render import face_normals
from mesh2tex.synthetic.materials import PART_NAMES, PhotoPattern, random_material
from mesh2tex.synthetic.shapes import generate_shape
from mesh2tex.synthetic.solids import PART_ID

SEEDS = range(8)


def _shapes(category):
    return [generate_shape(category, np.random.default_rng([7, seed])) for seed in SEEDS]


def _part_centre(shape, part):
    faces = shape.faces[shape.face_parts == PART_ID[part]]
    return shape.vertices[faces.reshape(-1)].mean(axis=0)


@pytest.mark.parametrize("category", ["chair", "car"])
def test_shapes_are_watertight_single_pieces_in_the_normalised_frame(category):
    for shape in _shapes(category):
        mesh = trimesh.Trimesh(shape.vertices, shape.faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
        assert mesh.body_count == 1  # one piece, as quad remeshing wants
        low, high = shape.vertices.min(axis=0), shape.vertices.max(axis=0)
        np.testing.assert_allclose((low + high) / 2, 0, atol=1e-9)
        assert np.linalg.norm(high - low) == pytest.approx(1.0)
        assert 100 < len(shape.faces) < 6000
        assert len(shape.face_parts) == len(shape.faces)


def test_chairs_are_tall_with_the_back_behind_the_seat():
    for shape in _shapes("chair"):
        extent = shape.vertices.max(axis=0) - shape.vertices.min(axis=0)
        assert extent[1] > extent[0] and extent[1] > extent[2]  # taller than wide and deep
        assert {"seat", "back", "leg"} <= set(shape.part_names)
        seat, back = _part_centre(shape, "seat"), _part_centre(shape, "back")
        assert back[2] < seat[2] and back[1] > seat[1]  # the front faces +z; the back rises behind


def test_cars_are_long_low_and_face_forward_on_their_wheels():
    for shape in _shapes("car"):
        extent = shape.vertices.max(axis=0) - shape.vertices.min(axis=0)
        assert extent[2] > 1.5 * extent[0] and extent[2] > 1.5 * extent[1]  # length along z
        assert {"body", "cabin", "wheel", "hub", "headlight", "taillight"} <= set(shape.part_names)
        assert _part_centre(shape, "headlight")[2] > 0 > _part_centre(shape, "taillight")[2]
        wheel_faces = shape.faces[shape.face_parts == PART_ID["wheel"]]
        assert shape.vertices[wheel_faces.reshape(-1), 1].min() == pytest.approx(shape.vertices[:, 1].min(), abs=1e-6)


def test_shapes_vary_between_seeds_and_repeat_for_a_seed():
    chairs, cars = _shapes("chair"), _shapes("car")
    assert len({c.params["legs"] for c in chairs}) >= 2
    assert len({c.params["back"] for c in chairs}) >= 2
    assert {c.params["arms"] == "none" for c in chairs} == {True, False}
    assert len({c.params["style"] for c in cars}) >= 3
    extents = np.array([c.vertices.max(axis=0) - c.vertices.min(axis=0) for c in chairs])
    assert extents.std(axis=0).min() > 0.01  # proportions differ, not just the topology
    again = generate_shape("chair", np.random.default_rng([7, 3]))
    assert np.array_equal(again.vertices, chairs[3].vertices) and np.array_equal(again.faces, chairs[3].faces)
    assert np.array_equal(again.face_parts, chairs[3].face_parts)


def test_materials_are_deterministic_in_range_and_part_wise():
    shape = generate_shape("car", np.random.default_rng(1))
    normals = face_normals(torch.as_tensor(shape.vertices), torch.as_tensor(shape.faces)).numpy()
    points = shape.vertices[shape.faces].mean(axis=1)
    colours = random_material("car", np.random.default_rng(5))(points, normals, shape.face_parts)
    again = random_material("car", np.random.default_rng(5))(points, normals, shape.face_parts)
    assert colours.shape == (len(points), 3) and colours.min() >= 0 and colours.max() <= 1
    assert np.array_equal(colours, again)
    tyres = colours[shape.face_parts == PART_ID["wheel"]].mean(axis=0)
    lights = colours[shape.face_parts == PART_ID["headlight"]].mean(axis=0)
    assert tyres.max() < 0.3 < lights.min()  # dark tyres, bright headlights
    described = random_material("chair", np.random.default_rng(2)).describe()
    json.dumps(described)
    assert set(described["parts"]) <= set(PART_NAMES)


def test_photographic_textures_come_from_bundled_images():
    rng = np.random.default_rng(0)
    points = rng.uniform(-0.5, 0.5, (500, 3))
    normals = rng.normal(size=(500, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    for name in ("brick", "grass", "gravel"):
        rgb = PhotoPattern(name, (0.1, 0.1, 0.1), (0.9, 0.8, 0.7), 0.4)(points, normals)
        assert rgb.std() > 0.05 and 0 <= rgb.min() and rgb.max() <= 1


# ----------------------------------------------------------------------------------------------
# The dataset


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    output = tmp_path_factory.mktemp("world") / "chairs"
    argv = [
        "prepare",
        "synthetic",
        "--out",
        str(output),
        "--category",
        "chair",
        "--shapes",
        "4",
        "--views",
        "3",
        "--resolution",
        "48",
        "--texture-size",
        "128",
        "--seed",
        "3",
    ]
    assert main(argv) == 0
    return output, argv


def test_world_layout_and_split(world):
    output, _ = world
    index = json.loads((output / "index.json").read_text())
    assert index["complete"] is True
    train, held_out = index["split"]["train_shapes"], index["split"]["query_shapes"]
    assert len(train) == 3 and len(held_out) == 1 and not set(train) & set(held_out)
    assert {s["name"] for s in index["shapes"]} == set(train) | set(held_out)
    assert len(index["images"]) == 3 * 3 and {r["shape"] for r in index["images"]} == set(train)
    assert len(index["queries"]) == 2 and {r["shape"] for r in index["queries"]} == set(held_out)
    for shape in index["shapes"]:
        mesh = trimesh.load(output / shape["mesh"])
        assert mesh.is_watertight
        textured = trimesh.load(output / shape["textured"])
        (geometry,) = textured.geometry.values()
        assert geometry.visual.material.baseColorTexture.size == (128, 128)
    for record in index["images"]:
        image = np.asarray(Image.open(output / record["image"]))
        mask = np.asarray(Image.open(output / record["mask"]))
        assert image.shape == (48, 48, 3) and mask.shape == (48, 48)
        assert set(np.unique(mask)) <= {0, 255} and 0.03 < (mask > 0).mean() < 0.9
        assert index["settings"]["elevation_min"] <= record["elevation"] <= index["settings"]["elevation_max"]
    assert (output / "preview.png").exists()


def test_query_sidecars_match_their_noc_maps(world):
    """Every NOC pixel, decoded to a surface point and projected with the sidecar's camera, lands on itself."""
    from mesh2tex.render import orbit_camera, transform_points

    output, _ = world
    index = json.loads((output / "index.json").read_text())
    for record in index["queries"]:
        sidecar = json.loads((output / record["sidecar"]).read_text())
        assert sidecar["shape"] == record["shape"] and sidecar["shape"] in index["split"]["query_shapes"]
        assert (output / sidecar["mesh"]).exists() and (output / sidecar["textured"]).exists()
        mask = np.asarray(Image.open(output / sidecar["mask"])) > 0
        noc = np.asarray(Image.open(output / sidecar["noc"])).astype(np.float64) / 255
        assert mask.any() and (noc[~mask] == 0).all()
        rows, cols = np.nonzero(mask)
        points = torch.tensor(noc[rows, cols] - 0.5, dtype=torch.float32)
        camera = orbit_camera(
            sidecar["azimuth"], sidecar["elevation"], distance=sidecar["distance"], fov=sidecar["fov"]
        )
        clip = transform_points(points, camera.mvp)[0]
        ndc = (clip[:, :2] / clip[:, 3:]).numpy()
        size = sidecar["resolution"]
        col = (ndc[:, 0] + 1) / 2 * size - 0.5
        row = (1 - ndc[:, 1]) / 2 * size - 0.5
        error = np.hypot(col - cols, row - rows)
        assert np.median(error) < 0.5 and np.percentile(error, 95) < 1.5


def test_rerun_skips_finished_items_and_rejects_other_settings(world, capsys):
    output, argv = world
    before = {p: p.stat().st_mtime_ns for p in (output / "images").iterdir()}
    assert main(argv) == 0
    assert {p: p.stat().st_mtime_ns for p in (output / "images").iterdir()} == before
    last_run = [json.loads(line) for line in (output / "log.jsonl").read_text().splitlines()][-4:]
    assert all(record["wrote"] == [] for record in last_run)
    assert main(argv[:-1] + ["4"]) == 2  # another seed into the same folder
    assert "other settings (seed)" in capsys.readouterr().err


def test_world_is_deterministic_for_a_seed(world, tmp_path):
    output, argv = world
    other = tmp_path / "again"
    argv = list(argv)
    argv[argv.index("--out") + 1] = str(other)
    argv[argv.index("--shapes") + 1] = "2"  # fewer shapes: shape 0 must not change
    argv[argv.index("--views") + 1] = "3"
    assert main(argv) == 0
    first = sorted((output / "images").glob("chair_0000_*.png"))
    assert first and all((other / "images" / p.name).read_bytes() == p.read_bytes() for p in first)
    assert (other / "meshes/chair_0000.obj").read_bytes() == (output / "meshes/chair_0000.obj").read_bytes()


# ----------------------------------------------------------------------------------------------
# Rendering with per-vertex colours


def test_vertex_colours_render_like_a_solid_material_and_change_only_the_object():
    from mesh2tex.render import RenderSettings
    from mesh2tex.synthetic.materials import Material, Solid
    from mesh2tex.synthetic.world import WorldSpec, render_views, sample_views

    shape = generate_shape("chair", np.random.default_rng([7, 0]))
    views = sample_views(WorldSpec(), 0, 3)
    red, blue = (0.8, 0.4, 0.2), (0.1, 0.3, 0.9)
    by_vertex = {
        c: render_views(shape, None, views, RenderSettings(32), vertex_colours=np.tile(c, (len(shape.vertices), 1)))
        for c in (red, blue)
    }
    by_material = render_views(shape, Material(default=Solid(red)), views, RenderSettings(32))
    # A constant per-vertex colour is the solid material of that colour (same shading and background).
    assert np.abs(by_vertex[red]["rgb"].astype(int) - by_material["rgb"]).max() <= 1
    for key in ("mask", "noc"):
        assert np.array_equal(by_vertex[red][key], by_material[key]) and np.array_equal(
            by_vertex[red][key], by_vertex[blue][key]
        )
    on = by_vertex[red]["mask"] > 127
    assert on.any() and np.array_equal(by_vertex[red]["rgb"][~on], by_vertex[blue]["rgb"][~on]), (
        "the background does not change"
    )
    lit = by_vertex[red]["rgb"][on].astype(float)
    lit = lit[lit[:, 0] > 60]
    assert np.allclose(lit[:, 1] / lit[:, 0], 0.5, atol=0.03) and np.allclose(lit[:, 2] / lit[:, 0], 0.25, atol=0.03), (
        "the albedo is uniform: only the shading scales it"
    )
    with pytest.raises(ValueError, match="material or vertex_colours"):
        render_views(shape, None, views, RenderSettings(32))
    with pytest.raises(ValueError, match="one per vertex"):
        render_views(shape, None, views, RenderSettings(32), vertex_colours=np.zeros((3, 3)))
