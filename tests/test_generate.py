"""``mesh2tex infer generate``: renders, a GLB with a baked texture that trimesh loads, a PLY with colours."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh
from PIL import Image

from mesh2tex.cli import main
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.models import load_generator
from mesh2tex.nn.batch import collate_shapes
from mesh2tex.texturing import latent


@pytest.fixture(scope="module")
def trained(tiny_gan):
    return tiny_gan


def test_generate_writes_renders_glb_and_ply(trained, tmp_path):
    out = tmp_path / "gen"
    code = main(
        [
            "infer",
            "generate",
            "--checkpoint",
            str(trained / "run" / "checkpoint.safetensors"),
            "--mesh",
            str(trained / "shapes" / "box0.npz"),
            "--out",
            str(out),
            "--seeds",
            "0,5",
            "--views",
            "3",
            "--resolution",
            "32",
            "--texture-size",
            "64",
            "--device",
            "cpu",
        ]
    )
    assert code == 0
    for seed in (0, 5):
        for v in range(3):
            assert Image.open(out / f"seed{seed}_view{v}.png").size == (32, 32)
    scene = trimesh.load(out / "seed0.glb")
    mesh = next(iter(scene.geometry.values())) if isinstance(scene, trimesh.Scene) else scene
    image = mesh.visual.material.baseColorTexture
    assert image is not None and image.size == (64, 64)
    assert mesh.visual.uv.shape == (len(mesh.vertices), 2)
    ply = trimesh.load(out / "seed0.ply")
    assert ply.visual.vertex_colors.shape[0] == len(ply.vertices)
    # Different seeds give different textures.
    assert not np.array_equal(
        np.asarray(Image.open(out / "seed0_view0.png")), np.asarray(Image.open(out / "seed5_view0.png"))
    )


def test_generate_embeds_the_texture_format_asked(trained, tmp_path):
    out = tmp_path / "gen"
    assert (
        main(
            [
                "infer",
                "generate",
                "--checkpoint",
                str(trained / "run" / "checkpoint.safetensors"),
                "--mesh",
                str(trained / "shapes" / "box0.npz"),
                "--out",
                str(out),
                "--seeds",
                "1",
                "--views",
                "1",
                "--resolution",
                "16",
                "--texture-size",
                "64",
                "--texture-format",
                "jpeg",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    mesh = next(iter(trimesh.load(out / "seed1.glb").geometry.values()))
    assert mesh.visual.material.baseColorTexture.format == "JPEG" and mesh.visual.material.baseColorTexture.size == (
        64,
        64,
    )


def test_a_mesh_prepared_on_the_fly_too_coarsely_is_one_warning(trained, tmp_path, capsys):
    from mesh2tex.synthetic.shapes import generate_shape

    chair = generate_shape("chair", np.random.default_rng(0))
    mesh = tmp_path / "chair.obj"
    trimesh.Trimesh(chair.vertices, chair.faces, process=False).export(mesh)
    assert (
        main(
            [
                "infer",
                "generate",
                "--checkpoint",
                str(trained / "run" / "checkpoint.safetensors"),
                "--mesh",
                str(mesh),
                "--faces",
                "96",
                "--out",
                str(tmp_path / "gen"),
                "--seeds",
                "0",
                "--views",
                "1",
                "--resolution",
                "16",
                "--texture-size",
                "16",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    warnings = [line for line in capsys.readouterr().err.splitlines() if "too coarse" in line]
    assert len(warnings) == 1 and warnings[0].startswith(
        f"mesh2tex: warning: {mesh}: 96 faces are too coarse for this shape"
    ), warnings


def test_baked_texture_matches_the_field(trained, tmp_path):
    """The GLB's texture, looked up at a triangle's centroid uv, is psi at that triangle's centroid."""
    out = tmp_path / "gen"
    ckpt = trained / "run" / "checkpoint.safetensors"
    assert (
        main(
            [
                "infer",
                "generate",
                "--checkpoint",
                str(ckpt),
                "--mesh",
                str(trained / "shapes" / "box1.npz"),
                "--out",
                str(out),
                "--seeds",
                "3",
                "--views",
                "1",
                "--resolution",
                "16",
                "--texture-size",
                "256",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    scene = trimesh.load(out / "seed3.glb")
    mesh = next(iter(scene.geometry.values())) if isinstance(scene, trimesh.Scene) else scene
    texture = np.asarray(mesh.visual.material.baseColorTexture.convert("RGB")).astype(np.float32)
    uv = np.asarray(mesh.visual.uv)
    faces = np.asarray(mesh.faces)
    centroid_uv = uv[faces].mean(1)
    cols = np.clip((centroid_uv[:, 0] * 256).astype(int), 0, 255)
    rows = np.clip(((1 - centroid_uv[:, 1]) * 256).astype(int), 0, 255)
    baked = texture[rows, cols]

    generator = load_generator(ckpt, torch.device("cpu")).network
    shape = PreparedShape.load(trained / "shapes" / "box1.npz")
    batch = collate_shapes([shape])
    with torch.no_grad():
        tex = generator.synthesize(batch, latent(generator, 3, torch.device("cpu")), noise_mode="none")
        t = batch.triangles().shape[0]
        psi = tex.colours(torch.arange(t), torch.full((t, 3), 1 / 3))
    expected = ((psi.clamp(-1, 1) + 1) * 127.5).numpy()
    assert len(faces) == t
    # The GLB keeps the triangles in order; texels near centroids agree up to texel discretisation.
    error = np.abs(baked - expected).mean()
    assert error < 4.0
    assert np.abs(baked - expected[::-1]).mean() > 3 * error  # a wrong triangle order would not match


def test_generate_reads_a_config_file_and_flags_override_it(trained, tmp_path, capsys):
    config = tmp_path / "generate.yaml"
    config.write_text("seeds: [3]\nviews: 2\nresolution: 16\ntexture_size: 32\ndevice: cpu\n")
    base = [
        "infer",
        "generate",
        "--checkpoint",
        str(trained / "run" / "checkpoint.safetensors"),
        "--mesh",
        str(trained / "shapes" / "box0.npz"),
        "--config",
        str(config),
    ]
    assert main(base + ["--out", str(tmp_path / "a")]) == 0
    assert sorted(p.name for p in (tmp_path / "a").glob("*.png")) == ["seed3_view0.png", "seed3_view1.png"]
    assert main(base + ["--out", str(tmp_path / "b"), "--views", "1", "--seeds", "4"]) == 0
    assert sorted(p.name for p in (tmp_path / "b").glob("*.png")) == ["seed4_view0.png"]
    config.write_text("views: 0\n")
    assert main(base + ["--out", str(tmp_path / "c")]) == 2
    assert "views 0: must be at least 1" in capsys.readouterr().err


def test_generate_prepares_a_raw_mesh_and_rejects_bad_input(trained, tmp_path, capsys):
    ckpt = str(trained / "run" / "checkpoint.safetensors")
    out = tmp_path / "raw"
    assert (
        main(
            [
                "infer",
                "generate",
                "--checkpoint",
                ckpt,
                "--mesh",
                str(trained / "slab.obj"),
                "--out",
                str(out),
                "--faces",
                "96",
                "--seeds",
                "1",
                "--views",
                "2",
                "--resolution",
                "16",
                "--texture-size",
                "32",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    assert (out / "seed1.glb").is_file() and (out / "seed1.ply").is_file()
    assert (
        main(
            [
                "infer",
                "generate",
                "--checkpoint",
                str(trained / "slab.obj"),
                "--mesh",
                str(trained / "slab.obj"),
                "--out",
                str(out),
            ]
        )
        == 2
    )
    assert "not a mesh2tex checkpoint" in capsys.readouterr().err
    assert (
        main(
            [
                "infer",
                "generate",
                "--checkpoint",
                ckpt,
                "--mesh",
                str(trained / "slab.obj"),
                "--out",
                str(out),
                "--seeds",
                "a,b",
            ]
        )
        == 2
    )
    assert "--seeds" in capsys.readouterr().err


def test_glb_carries_smooth_outward_normals(trained, tmp_path):
    """Viewers shade a GLB without NORMAL flat and faceted: the file has one unit normal per vertex,
    the same for vertices split on UV seams, pointing outwards."""
    import json
    import struct

    from mesh2tex.io.assets import smooth_vertex_normals

    out = tmp_path / "gen"
    assert (
        main(
            [
                "infer",
                "generate",
                "--checkpoint",
                str(trained / "run" / "checkpoint.safetensors"),
                "--mesh",
                str(trained / "shapes" / "box0.npz"),
                "--out",
                str(out),
                "--seeds",
                "0",
                "--views",
                "1",
                "--resolution",
                "16",
                "--texture-size",
                "32",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    data = (out / "seed0.glb").read_bytes()
    length = struct.unpack("<I", data[12:16])[0]
    gltf = json.loads(data[20 : 20 + length])
    assert "NORMAL" in gltf["meshes"][0]["primitives"][0]["attributes"]
    scene = trimesh.load(out / "seed0.glb", process=False)
    mesh = next(iter(scene.geometry.values()))
    vertices = np.asarray(mesh.vertices)
    normals = np.asarray(mesh.vertex_normals)  # as stored in the file (trimesh keeps NORMAL with process=False)
    assert np.allclose(normals, smooth_vertex_normals(vertices, np.asarray(mesh.faces)), atol=1e-3)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1, atol=1e-3)
    outward = np.einsum("ij,ij->i", normals, vertices - vertices.mean(0))
    assert (outward > 0).mean() > 0.95
    _, first, inverse = np.unique(np.round(vertices, 6), axis=0, return_index=True, return_inverse=True)
    assert np.allclose(normals, normals[first][inverse.reshape(-1)], atol=1e-6), "split vertices share their normal"
