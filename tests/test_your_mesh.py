"""The user's mesh in, the user's mesh out: the inferring commands hand back the mesh they were given
(its vertex positions, faces, frame and units), with UVs (its own when usable) and a baked texture."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial import cKDTree
from user_assets import Y_UP_TO_Z_UP, stool, user_files, with_planar_uvs, write_obj

from mesh2tex.cli import main
from mesh2tex.geometry.clean import normalize
from mesh2tex.geometry.mesh_io import UserMesh, choose_up, load_user_mesh
from mesh2tex.io.assets import Z_UP_NODE_ROTATION, load_glb
from mesh2tex.render import interpolate
from mesh2tex.render.bake import BakeTarget, MeshBaker, fill_empty_texels, mesh_atlas
from mesh2tex.render.uv import uv_atlas_problem, uv_rasterize

GENERATE = ["--seeds", "0", "--views", "1", "--resolution", "32", "--texture-size", "128", "--device", "cpu"]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return user_files(tmp_path_factory.mktemp("user"))


def rows(array) -> set[tuple]:
    return set(map(tuple, np.asarray(array, dtype=np.float32)))


def glb_node_rotation(path) -> list | None:
    data = path.read_bytes()
    length = int.from_bytes(data[12:16], "little")
    return json.loads(data[20 : 20 + length])["nodes"][0].get("rotation")


@pytest.mark.parametrize("kind", ["obj", "ply", "off", "glb", "stl"])
def test_generate_hands_back_the_users_mesh(files, kind, tmp_path, capsys):
    """Every output vertex is an input vertex (float32), every input vertex is in the output, the
    triangles are the input's, and the GLB has UVs and a texture; the PLY is the input mesh itself."""
    path = files[kind]
    source = load_user_mesh(path)
    out = tmp_path / "gen"
    assert main(["infer", "generate", "--checkpoint", "chair", "--mesh", str(path), "--out", str(out), *GENERATE]) == 0
    vertices, faces, uv, texture = load_glb(out / "seed0.glb")
    assert rows(vertices) <= rows(source.vertices) and rows(source.vertices) <= rows(vertices)
    assert len(faces) == len(source.faces)
    np.testing.assert_array_equal(
        np.sort(vertices[faces].reshape(len(faces), -1), axis=0),
        np.sort(source.vertices[source.faces].astype(np.float32).reshape(len(faces), -1), axis=0),
    )
    assert uv.shape == (len(vertices), 2) and texture.shape == (128, 128, 3) and texture.std() > 0
    ply = trimesh.load(out / "seed0.ply", process=False)
    np.testing.assert_array_equal(ply.faces, source.faces)
    np.testing.assert_allclose(ply.vertices, source.vertices, rtol=1e-6, atol=1e-6)
    err = capsys.readouterr().err
    assert f"{source.up}-up" in err  # the up axis chosen is said, with its reason
    assert glb_node_rotation(out / "seed0.glb") == (Z_UP_NODE_ROTATION if kind == "stl" else None)


def test_a_z_up_mesh_is_prepared_standing(files, tmp_path):
    """The z-up STL (scaled by 40) and the y-up OBJ of the same stool give the same prepared shape: the
    file's up axis is undone before preparing, and the scale does not matter."""
    from mesh2tex.geometry.prepare import prepare_user_mesh

    z_up = prepare_user_mesh(load_user_mesh(files["stl"]), face_count=96, levels=2)
    y_up = prepare_user_mesh(load_user_mesh(files["ply"]), face_count=96, levels=2)
    assert z_up.metadata["up"] == "z" and y_up.metadata["up"] == "y"
    np.testing.assert_allclose(np.ptp(z_up.vertices[0], axis=0), np.ptp(y_up.vertices[0], axis=0), atol=0.02)
    assert np.ptp(z_up.vertices[0][:, 1]) > np.ptp(z_up.vertices[0][:, 2])  # standing: y (height) is its tallest extent


def test_the_up_rule():
    assert choose_up("a.glb")[0] == "y" and choose_up("a.gltf", "z")[0] == "y"  # glTF is y-up by definition
    assert choose_up("a.stl")[0] == "z" and choose_up("a.STL", "y")[0] == "y"
    assert [choose_up(f"a.{s}")[0] for s in ("obj", "ply", "off")] == ["y", "y", "y"]
    assert "--up y" in choose_up("a.stl")[1]


def test_usable_uvs_are_kept_and_overlapping_ones_replaced(tmp_path, capsys):
    mesh = with_planar_uvs(stool())
    good = write_obj(tmp_path / "good.obj", mesh.vertices, mesh.faces, mesh.visual.uv)
    out = tmp_path / "keep"
    assert main(["infer", "generate", "--checkpoint", "chair", "--mesh", str(good), "--out", str(out), *GENERATE]) == 0
    vertices, faces, uv, _ = load_glb(out / "seed0.glb")
    source = load_user_mesh(good)
    assert len(vertices) == len(source.vertices)
    np.testing.assert_allclose(uv, source.uv, atol=1e-6)  # the file's own UVs, per vertex
    assert "new UV atlas" not in capsys.readouterr().err

    mirrored = with_planar_uvs(stool(), mirrored=True)
    bad = write_obj(tmp_path / "mirrored.obj", mirrored.vertices, mirrored.faces, mirrored.visual.uv)
    out = tmp_path / "new"
    assert main(["infer", "generate", "--checkpoint", "chair", "--mesh", str(bad), "--out", str(out), *GENERATE]) == 0
    err = capsys.readouterr().err
    assert "new UV atlas" in err and "overlap" in err
    _, faces, uv, _ = load_glb(out / "seed0.glb")
    assert uv_atlas_problem(uv, faces) == ""
    out = tmp_path / "forced"
    assert (
        main(
            [
                "infer",
                "generate",
                "--checkpoint",
                "chair",
                "--mesh",
                str(bad),
                "--out",
                str(out),
                "--uv",
                "keep",
                *GENERATE,
            ]
        )
        == 0
    )
    np.testing.assert_allclose(load_glb(out / "seed0.glb")[2], load_user_mesh(bad).uv, atol=1e-6)


def test_the_uv_check_names_what_is_wrong():
    mesh = stool()
    assert uv_atlas_problem(with_planar_uvs(mesh).visual.uv, with_planar_uvs(mesh).faces) == ""
    mirrored = with_planar_uvs(mesh, mirrored=True)
    assert "overlap" in uv_atlas_problem(mirrored.visual.uv, mirrored.faces)
    assert "leave [0, 1]" in uv_atlas_problem(mirrored.visual.uv * 2, mirrored.faces)
    assert "no area" in uv_atlas_problem(np.zeros((len(mesh.vertices), 2)), mesh.faces)


def test_ngons_unused_vertices_and_the_prepared_output(tmp_path):
    """A quad is fanned into two triangles; vertices no face uses are kept (a PLY: the OBJ reader drops
    them, they hold no surface); --output-mesh prepared still writes the normalised working copy."""
    mesh = stool()
    path = tmp_path / "quads.obj"
    count = len(mesh.vertices)
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in mesh.vertices]
    lines += ["v 0.3 0 0.3", "v 0.4 0 0.3", "v 0.4 0 0.4", "v 0.3 0 0.4"]  # a floor tile, written as one quad
    lines += [f"f {x} {y} {z}" for x, y, z in mesh.faces + 1] + [f"f {count + 1} {count + 4} {count + 3} {count + 2}"]
    path.write_text("\n".join(lines) + "\n")
    out = tmp_path / "gen"
    assert main(["infer", "generate", "--checkpoint", "chair", "--mesh", str(path), "--out", str(out), *GENERATE]) == 0
    assert len(load_glb(out / "seed0.glb")[1]) == len(mesh.faces) + 2

    loose = tmp_path / "loose.ply"
    trimesh.Trimesh(np.concatenate([mesh.vertices, [[5, 5, 5], [6, 6, 6]]]), mesh.faces, process=False).export(loose)
    assert (
        main(
            [
                "infer",
                "generate",
                "--checkpoint",
                "chair",
                "--mesh",
                str(loose),
                "--out",
                str(tmp_path / "loose"),
                *GENERATE,
            ]
        )
        == 0
    )
    assert rows([[5, 5, 5], [6, 6, 6]]) <= rows(load_glb(tmp_path / "loose" / "seed0.glb")[0])

    out = tmp_path / "prepared"
    assert (
        main(
            [
                "infer",
                "generate",
                "--checkpoint",
                "chair",
                "--mesh",
                str(path),
                "--out",
                str(out),
                "--output-mesh",
                "prepared",
                *GENERATE,
            ]
        )
        == 0
    )
    vertices = load_glb(out / "seed0.glb")[0]
    assert abs(np.linalg.norm(np.ptp(vertices, axis=0)) - 1) < 0.05  # the normalised frame: diagonal 1


def test_a_raw_mesh_is_prepared_as_the_model_learnt(files, tmp_path, capsys):
    """Without --faces the shipped chair's own hierarchy is used (no note); another --faces says the texture's scale
    changes."""
    common = ["infer", "generate", "--checkpoint", "chair", "--mesh", str(files["ply"]), *GENERATE]
    assert main([*common, "--out", str(tmp_path / "a")]) == 0
    assert "learnt on" not in capsys.readouterr().err
    assert main([*common, "--out", str(tmp_path / "b"), "--faces", "6144"]) == 0
    assert "learnt on 1536-quad hierarchies" in capsys.readouterr().err


def test_the_bake_reads_the_surface_texture_at_each_texels_point():
    """A texture that is a function of position, living on a remeshed copy of the surface, baked onto the
    user's (z-up, scaled) mesh: each texel shows that function at its own point of the user's mesh, up
    to the distance between the two surfaces."""
    mesh = stool()
    z_up = trimesh.Trimesh(mesh.vertices @ Y_UP_TO_Z_UP.T * 40.0, mesh.faces, process=False)
    user = UserMesh("stool.stl", np.asarray(z_up.vertices), np.asarray(z_up.faces), None, None, "z", "")
    working, transform = normalize(user.working_vertices())
    surface = trimesh.Trimesh(
        working, mesh.faces, process=False
    ).subdivide()  # the working surface: another triangulation

    def colour(points: torch.Tensor) -> torch.Tensor:
        return torch.sin(8 * points)

    class PositionTexture:  # a SurfaceTexture: a function of the surface point
        def colours(self, triangle: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
            corners = torch.from_numpy(surface.vertices[surface.faces[triangle.numpy()]]).float()
            return colour((corners * bary[:, :, None]).sum(1))

    baker = MeshBaker(BakeTarget(user, transform), surface.vertices, surface.faces, 128)
    baked = baker.bake(PositionTexture())
    assert baked.atlas.source == "new" and baked.coverage.mean() > 0.3
    # the expected colour at each covered texel: the function at the texel's own point of the user's mesh
    raster = uv_rasterize(torch.from_numpy(baked.uv).float(), torch.from_numpy(baked.faces), (128, 128))
    points = interpolate(
        torch.from_numpy(transform.apply(user.to_working_frame(baked.vertices))).float()[None],
        raster,
        torch.from_numpy(baked.faces),
    )[0]
    expected = ((colour(points) + 1) * 127.5).numpy()[baked.coverage]
    error = np.abs(baked.texture[baked.coverage].astype(float) - expected)
    assert np.median(error) < 2 and np.quantile(error, 0.99) < 12
    used = np.unique(user.faces)
    # the two surfaces coincide: every vertex of a face lies on the working one
    assert baked.surface_distance[used].max() < 1e-6


def test_empty_texels_take_the_nearest_covered_colour():
    colours = np.zeros((4, 4, 3), dtype=np.float32)
    covered = np.zeros((4, 4), dtype=bool)
    colours[0, 0], covered[0, 0] = 1.0, True
    colours[3, 3], covered[3, 3] = -1.0, True
    filled = fill_empty_texels(colours, covered)
    assert filled[0, 1, 0] == 1.0 and filled[3, 2, 0] == -1.0 and filled[1, 1, 0] == 1.0


def test_keep_without_uvs_is_refused():
    mesh = stool()
    with pytest.raises(ValueError, match="has no UV coordinates"):
        mesh_atlas(UserMesh("m.ply", mesh.vertices, mesh.faces, None, None), "keep")


def test_a_scene_of_several_nodes_and_an_obj_of_several_materials(tmp_path):
    """A glTF scene's nodes are flattened with their transforms into one mesh in the scene's frame; an OBJ
    whose faces use two materials is read whole. The textured output keeps every triangle of both."""
    mesh = stool()
    seat, rest = mesh.faces[: len(mesh.faces) // 3], mesh.faces[len(mesh.faces) // 3 :]
    scene = trimesh.Scene()
    shift = trimesh.transformations.translation_matrix([0.0, 0.1, 0.0])
    scene.add_geometry(trimesh.Trimesh(mesh.vertices, seat, process=False), node_name="seat", transform=shift)
    scene.add_geometry(trimesh.Trimesh(mesh.vertices, rest, process=False), node_name="rest", transform=shift)
    scene.export(tmp_path / "scene.glb")
    read = load_user_mesh(tmp_path / "scene.glb")
    assert len(read.faces) == len(mesh.faces)
    corners = np.sort(read.vertices[read.faces].reshape(len(read.faces), -1), axis=0)
    np.testing.assert_allclose(
        corners, np.sort((mesh.vertices + [0.0, 0.1, 0.0])[mesh.faces].reshape(len(mesh.faces), -1), axis=0), atol=1e-6
    )
    out = tmp_path / "gen"
    assert (
        main(
            [
                "infer",
                "generate",
                "--checkpoint",
                "chair",
                "--mesh",
                str(tmp_path / "scene.glb"),
                "--out",
                str(out),
                *GENERATE,
            ]
        )
        == 0
    )
    assert len(load_glb(out / "seed0.glb")[1]) == len(mesh.faces)

    (tmp_path / "two.mtl").write_text("newmtl wood\nKd 0.5 0.3 0.1\nnewmtl cloth\nKd 0.2 0.2 0.8\n")
    lines = ["mtllib two.mtl"] + [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in mesh.vertices]
    lines += (
        ["usemtl cloth"]
        + [f"f {a} {b} {c}" for a, b, c in seat + 1]
        + ["usemtl wood"]
        + [f"f {a} {b} {c}" for a, b, c in rest + 1]
    )
    (tmp_path / "two.obj").write_text("\n".join(lines) + "\n")
    read = load_user_mesh(tmp_path / "two.obj")
    assert len(read.faces) == len(mesh.faces)
    assert cKDTree(mesh.vertices).query(read.vertices)[0].max() < 1e-6  # every vertex read is one of the file's


def test_uv_keep_on_a_mesh_without_uvs_is_one_line(files, tmp_path, capsys):
    out = tmp_path / "keep"
    assert (
        main(
            [
                "infer",
                "generate",
                "--checkpoint",
                "chair",
                "--mesh",
                str(files["ply"]),
                "--out",
                str(out),
                "--uv",
                "keep",
                *GENERATE,
            ]
        )
        == 2
    )
    errors = [line for line in capsys.readouterr().err.splitlines() if line.startswith("mesh2tex: error:")]
    assert len(errors) == 1 and "has no UV coordinates" in errors[0] and not out.exists()
