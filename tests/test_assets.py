"""Textured assets open elsewhere: GLB with its texture in trimesh, PLY with its colours, OBJ stays closed."""

import json
import struct

import numpy as np
import pytest
import trimesh

from mesh2tex.io.assets import TEXTURE_FORMATS, glb_bytes, load_glb, save_glb, save_obj, save_ply


def _quad():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uv = vertices[:, :2].copy()  # v up: vertices 2 and 3 sit at the top of the image
    texture = np.zeros((8, 16, 3), dtype=np.uint8)
    texture[:4] = (255, 0, 0)  # top half red
    texture[4:] = (0, 0, 255)  # bottom half blue
    return vertices, faces, uv, texture


def _only_geometry(loaded):
    if isinstance(loaded, trimesh.Scene):
        (geometry,) = loaded.geometry.values()
        return geometry
    return loaded


def test_glb_loads_in_trimesh_with_its_texture_and_uv_orientation(tmp_path):
    vertices, faces, uv, texture = _quad()
    path = tmp_path / "quad.glb"
    save_glb(path, vertices, faces, uv, texture)
    mesh = _only_geometry(trimesh.load(path))
    assert isinstance(mesh.visual, trimesh.visual.TextureVisuals)
    image = np.asarray(mesh.visual.material.baseColorTexture.convert("RGB"))
    assert image.shape == texture.shape and np.array_equal(image, texture)
    np.testing.assert_allclose(mesh.vertices, vertices, atol=1e-6)
    np.testing.assert_allclose(mesh.visual.uv, uv, atol=1e-6)
    # trimesh samples the texture at each vertex's uv: the top vertices get the top (red) rows.
    colours = mesh.visual.to_color().vertex_colors[:, :3]
    assert np.array_equal(colours[2], [255, 0, 0]) and np.array_equal(colours[0], [0, 0, 255])


def test_glb_structure_is_aligned_and_declares_bounds():
    vertices, faces, uv, texture = _quad()
    data = glb_bytes(vertices, faces, uv, texture, vertex_normals=np.tile([0.0, 0.0, 2.0], (4, 1)))
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    json_length, json_type = struct.unpack_from("<I4s", data, 12)
    assert json_type == b"JSON" and json_length % 4 == 0
    document = json.loads(data[20 : 20 + json_length])
    bin_length, bin_type = struct.unpack_from("<I4s", data, 20 + json_length)
    assert bin_type == b"BIN\x00" and bin_length % 4 == 0
    assert all(view["byteOffset"] % 4 == 0 for view in document["bufferViews"])
    position = document["accessors"][document["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
    assert position["min"] == [0, 0, 0] and position["max"] == [1, 1, 0]
    assert document["images"][0]["mimeType"] == "image/png"


def _glb_document(data: bytes) -> dict:
    (json_length,) = struct.unpack_from("<I", data, 12)
    return json.loads(data[20 : 20 + json_length])


def _noisy_texture(size: int = 128, noise: float = 24.0) -> np.ndarray:
    """A colour gradient with per-texel noise: lossless PNG cannot squeeze it, lossy formats can."""
    ramp = np.linspace(0, 1, size)
    smooth = np.stack(
        [np.add.outer(ramp, ramp) * 100, np.outer(ramp, 1 - ramp) * 600, np.tile(ramp * 200, (size, 1))], axis=2
    )
    noisy = smooth + np.random.default_rng(0).normal(0, noise, smooth.shape)
    return np.clip(noisy + 28, 0, 255).astype(np.uint8)


@pytest.mark.parametrize(
    "texture_format, mime_type", [("png", "image/png"), ("jpeg", "image/jpeg"), ("webp", "image/webp")]
)
def test_glb_embeds_its_texture_in_the_format_asked(tmp_path, texture_format, mime_type):
    vertices, faces, uv, _ = _quad()
    texture = _noisy_texture(noise=4.0)
    path = tmp_path / f"quad_{texture_format}.glb"
    save_glb(path, vertices, faces, uv, texture, texture_format=texture_format)
    document = _glb_document(path.read_bytes())
    assert document["images"] == [{"bufferView": 3, "mimeType": mime_type}]
    # glTF core knows PNG and JPEG only: WebP comes through its extension, declared required
    if texture_format == "webp":
        assert document["extensionsUsed"] == document["extensionsRequired"] == ["EXT_texture_webp"]
        assert document["textures"][0]["extensions"] == {"EXT_texture_webp": {"source": 0}}
    else:
        assert "extensionsRequired" not in document and document["textures"][0]["source"] == 0
    mesh = _only_geometry(trimesh.load(path))  # trimesh finds the texture in every format
    assert mesh.visual.material.baseColorTexture.format == texture_format.upper()
    _, _, loaded_uv, image = load_glb(path)
    np.testing.assert_allclose(loaded_uv, uv, atol=1e-6)
    error = np.abs(image.astype(float) - texture).mean()
    assert error == 0 if texture_format == "png" else error < 4.0  # lossy, but the same picture


def test_lossy_texture_formats_make_smaller_glbs_on_a_noisy_texture():
    vertices, faces, uv, _ = _quad()
    texture = _noisy_texture(256)
    size = {f: len(glb_bytes(vertices, faces, uv, texture, texture_format=f)) for f in TEXTURE_FORMATS}
    assert size["jpeg"] < size["png"] / 2 and size["webp"] < size["png"] / 2, size


def test_glb_refuses_an_unknown_texture_format():
    vertices, faces, uv, texture = _quad()
    with pytest.raises(ValueError, match="texture_format 'gif'"):
        glb_bytes(vertices, faces, uv, texture, texture_format="gif")


def test_glb_rejects_mismatched_inputs(tmp_path):
    vertices, faces, uv, texture = _quad()
    with pytest.raises(ValueError, match="one uv per vertex"):
        save_glb(tmp_path / "bad.glb", vertices, faces, uv[:3], texture)
    with pytest.raises(ValueError, match="faces index"):
        save_glb(tmp_path / "bad.glb", vertices, faces + 10, uv, texture)
    assert not (tmp_path / "bad.glb").exists()


def test_ply_round_trips_vertex_colours(tmp_path):
    vertices, faces, _, _ = _quad()
    colours = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [9, 8, 7]], dtype=np.uint8)
    path = tmp_path / "quad.ply"
    save_ply(path, vertices, faces, colours)
    mesh = trimesh.load(path, process=False)
    assert np.array_equal(mesh.faces, faces)
    assert np.array_equal(mesh.visual.vertex_colors[:, :3], colours)


def test_obj_with_part_groups_stays_watertight(tmp_path):
    box = trimesh.creation.box()
    groups = ["top" if c[2] > 0.4 else "rest" for c in box.triangles_center]
    order = np.argsort(groups, kind="stable")
    path = tmp_path / "box.obj"
    save_obj(path, box.vertices, box.faces[order], [groups[i] for i in order])
    assert "g top" in path.read_text()
    loaded = trimesh.load(path)
    assert loaded.is_watertight and len(loaded.faces) == 12
