"""``mesh2tex infer synthesize``: the user's mesh back with a texture optimised through renders, on a
tiny mesh with tiny sizes (the figures of full-size runs are in docs/results/nca.md)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch
import trimesh
from PIL import Image
from user_assets import stool, write_obj

from mesh2tex.cli import main
from mesh2tex.io.assets import load_glb
from mesh2tex.render.bake import new_atlas
from mesh2tex.synthetic.exemplars import exemplar_image
from mesh2tex.texel_synthesis import SynthesisConfig, TexelSurface, TexelSynthesis, exemplar_tensor, view_cameras

TINY = ["--iters", "4", "--texture-size", "64", "--resolution", "48", "--views", "1", "--device", "cpu"]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("synthesize")
    Image.fromarray(exemplar_image("stripes", 48)).save(folder / "stripes.png")
    mesh = stool(sections=8)
    write_obj(folder / "stool.obj", mesh.vertices, mesh.faces)
    return folder


def command(inputs, out, exemplar=None) -> list[str]:
    exemplar = exemplar or inputs / "stripes.png"
    return ["infer", "synthesize", "--exemplar", str(exemplar), "--mesh", str(inputs / "stool.obj"), "--out", str(out)]


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("mesh2tex: error:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_the_glb_holds_the_users_mesh_with_a_texture_of_the_asked_size(inputs, tmp_path, monkeypatch):
    monkeypatch.setenv("MESH2TEX_PROGRESS", "0")
    out = tmp_path / "out"
    assert main([*command(inputs, out), *TINY]) == 0
    source = trimesh.load(inputs / "stool.obj", process=False)
    vertices, faces, uv, texture = load_glb(out / "textured.glb")
    assert len(faces) == len(source.faces)
    # the user's own positions (split on the atlas's seams only), and their triangles
    corners = source.vertices[source.faces].astype(np.float32).reshape(len(faces), -1)
    np.testing.assert_array_equal(np.sort(vertices[faces].reshape(len(faces), -1), axis=0), np.sort(corners, axis=0))
    assert texture.shape == (64, 64, 3) and texture.std() > 0 and uv.shape == (len(vertices), 2)
    ply = trimesh.load(out / "textured.ply", process=False)
    assert len(ply.vertices) == len(source.vertices) and np.array_equal(ply.faces, source.faces)
    assert np.asarray(Image.open(out / "texture.png")).shape == (64, 64, 3)
    report = json.loads((out / "report.json").read_text())
    assert report["config"]["synthesis"]["iters"] == 4 and report["output_mesh"]["uv"] == "new"
    assert np.isfinite(report["final_loss"]) and "swd" in report["structure"]
    assert (out / "view_0.png").is_file()


def test_files_already_in_out_are_kept_without_overwrite(inputs, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("MESH2TEX_PROGRESS", "0")
    out = tmp_path / "out"
    out.mkdir()
    (out / "texture.png").write_text("the user's own file")
    capsys.readouterr()
    assert main([*command(inputs, out), *TINY]) != 0
    line = one_error_line(capsys)
    assert "texture.png" in line and "--overwrite" in line
    assert (out / "texture.png").read_text() == "the user's own file"
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == ["texture.png"]


@pytest.mark.parametrize("bad", ["missing.png", "broken.png"])
def test_a_bad_exemplar_is_a_one_line_error(bad, inputs, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("MESH2TEX_PROGRESS", "0")
    (tmp_path / "broken.png").write_bytes(b"not an image at all")
    out = tmp_path / "out"
    capsys.readouterr()
    assert main([*command(inputs, out, exemplar=tmp_path / bad), *TINY]) != 0
    assert bad in one_error_line(capsys)
    assert not out.exists() or not [p for p in out.iterdir() if not p.name.startswith(".")]


def test_a_bad_mesh_is_a_one_line_error(inputs, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("MESH2TEX_PROGRESS", "0")
    capsys.readouterr()
    assert (
        main(
            [
                "infer",
                "synthesize",
                "--exemplar",
                str(inputs / "stripes.png"),
                "--mesh",
                str(tmp_path / "none.obj"),
                "--out",
                str(tmp_path / "out"),
                *TINY,
            ]
        )
        != 0
    )
    assert "none.obj" in one_error_line(capsys)


@pytest.mark.parametrize(
    "method,loss", [("renders", "ps"), ("surface", "ps"), ("renders", "patch"), ("patches", "patch")]
)
def test_the_loss_falls_over_a_short_run(method, loss):
    torch.manual_seed(0)
    ball = trimesh.creation.icosphere(subdivisions=2)
    vertex_index, faces, uv = new_atlas(ball.vertices, ball.faces)
    unit = ball.vertices / np.linalg.norm(ball.vertices, axis=1).max()
    surface = TexelSurface.from_arrays(unit[vertex_index], faces, uv)
    cfg = SynthesisConfig(
        iters=30,
        texture_size=64,
        levels=4,
        resolution=64,
        exemplar_size=48,
        lr=0.05,
        method=method,
        charts=4,
        loss=loss,
        max_points=256,
    )
    synthesis = TexelSynthesis(cfg, surface, exemplar_tensor(exemplar_image("stripes", 48), 48))
    before = synthesis.fixed_loss()
    for _ in range(cfg.iters):
        synthesis.step()
    after = synthesis.fixed_loss()
    assert after < 0.8 * before, (before, after)
    image = synthesis.texture()
    assert image.shape == (64, 64, 3) and float(image.abs().max()) <= 1.0


def test_the_surface_method_writes_the_same_outputs_and_names_itself(inputs, tmp_path, monkeypatch):
    monkeypatch.setenv("MESH2TEX_PROGRESS", "0")
    out = tmp_path / "out"
    assert main([*command(inputs, out), *TINY, "--method", "surface"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["config"]["synthesis"]["method"] == "surface" and "geodesic charts" in report["method"]
    assert (out / "textured.glb").is_file() and (out / "view_0.png").is_file()


def test_upright_views_keep_the_meshs_up_and_rolled_views_do_not():
    """direction field 'up': the y axis projects straight up the image in every view; 'none': it leans."""

    def screen_up(direction: str) -> torch.Tensor:
        mvp = view_cameras(SynthesisConfig(direction_field=direction), 16, torch.Generator().manual_seed(0))
        points = torch.tensor([[0.0, 0.0, 0.0, 1.0], [0.0, 0.1, 0.0, 1.0]])
        clip = points @ mvp.transpose(1, 2)  # (16, 2, 4)
        ndc = clip[..., :2] / clip[..., 3:]
        step = ndc[:, 1] - ndc[:, 0]
        return torch.atan2(step[:, 0], step[:, 1]).abs()  # angle from the image's up, radians

    assert float(screen_up("up").max()) < 1e-4
    assert float(screen_up("none").max()) > 0.5


def test_the_views_are_set_in_a_camera_section_as_the_automatons_and_old_keys_say_where_they_went():
    from mesh2tex.config import config_from_dict
    from mesh2tex.errors import InputError
    from mesh2tex.render.cameras import NCACameraConfig
    from mesh2tex.texel_synthesis import SynthesisConfig

    cfg = config_from_dict(SynthesisConfig, {"camera": {"distance": 2.5, "elevation_min": -30.0}})
    assert cfg.camera == NCACameraConfig(distance=2.5, elevation_min=-30.0)
    with pytest.raises(InputError, match="moved: distance -> camera.distance"):
        config_from_dict(SynthesisConfig, {"distance": 2.5})
    with pytest.raises(InputError, match="elevation_max"):
        config_from_dict(SynthesisConfig, {"camera": {"elevation_min": 10.0, "elevation_max": 0.0}})


def test_the_colour_term_weighs_what_the_loss_needs_unless_set():
    """The patch loss matches joint colours itself and the colour term would drown it: unset, its weight is 0;
    the other losses keep 100; a weight the user sets is the weight used, and a negative one is refused."""
    assert SynthesisConfig(loss="ps").palette_weight == 100.0
    assert SynthesisConfig(loss="patch").palette_weight == SynthesisConfig().palette_weight == 0.0
    assert SynthesisConfig(loss="patch", colour_weight=5.0).palette_weight == 5.0
    assert SynthesisConfig(loss="ps", colour_weight=0.0).palette_weight == 0.0
    with pytest.raises(ValueError, match="colour_weight"):
        SynthesisConfig(colour_weight=-1.0)


@pytest.mark.parametrize("key, value", [("method", "charts"), ("direction_field", "sideways")])
def test_an_unknown_method_or_direction_field_in_a_config_is_refused_by_name(key, value):
    """A config file is not limited by the command line's choices: a misspelt method must not fall back to renders."""
    from mesh2tex.config import config_from_dict
    from mesh2tex.errors import InputError

    with pytest.raises((ValueError, InputError), match=key):
        config_from_dict(SynthesisConfig, {key: value})


def test_walked_patches_read_a_flat_texture_as_the_patch_loss_reads_the_image():
    """On a flat square whose UVs are its positions, the patches method's finest patches of a texture are the
    texture's own patches, upright and flattened as the loss flattens an image's: horizontal stripes read
    through it are near the exemplar's patches, the same stripes turned a quarter are far."""
    from mesh2tex.losses.structure import patch_distance

    grid = np.linspace(-0.7, 0.7, 9)
    x, y = np.meshgrid(grid, grid)
    positions = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)  # the plane z = 0, facing +z, y up
    cells = np.arange(81).reshape(9, 9)
    a, b, c, d = cells[:-1, :-1].ravel(), cells[:-1, 1:].ravel(), cells[1:, 1:].ravel(), cells[1:, :-1].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    surface = TexelSurface.from_arrays(positions, faces, (positions[:, :2] + 0.7) / 1.4)
    rows = (torch.arange(64) // 4 % 2).float() * 2 - 1  # horizontal stripes 4 texels wide
    stripes = rows[None, :, None].expand(3, 64, 64).contiguous()
    # 106 px views put one exemplar pixel on about one texel of this square (no pooling: mip level 0)
    cfg = SynthesisConfig(texture_size=64, levels=2, resolution=106, exemplar_size=64, method="patches", max_points=512)
    synthesis = TexelSynthesis(cfg, surface, stripes[None])
    assert synthesis.mip == 0

    def distance(texture: torch.Tensor) -> float:
        sets = synthesis.surface_patch_sets(texture, torch.Generator().manual_seed(0))
        return float(patch_distance(sets[:1], synthesis.features.patch_sets()[:1]))

    assert distance(stripes) < 0.25 * distance(stripes.transpose(1, 2))

    strip = TexelSurface.from_arrays(positions * [1.0, 0.02, 1.0], faces, (positions[:, :2] + 0.7) / 1.4)
    narrow = TexelSynthesis(cfg, strip, stripes[None])  # 2 texels wide: no 5 x 5 patch fits at any octave
    assert [len(s) for s in narrow.surface_patch_sets(stripes, torch.Generator().manual_seed(0))] == [0, 0, 0, 0]
    assert narrow.fixed_loss() == 0.0 and math.isfinite(narrow.step()["loss"])


def test_the_patches_method_asks_for_the_patch_loss(inputs, tmp_path, capsys, monkeypatch):
    """Only the patch loss has patches to walk: another loss with --method patches is a one-line error, and the
    patch loss writes the same outputs as the other methods and names the method in the report."""
    monkeypatch.setenv("MESH2TEX_PROGRESS", "0")
    assert main([*command(inputs, tmp_path / "ps"), *TINY, "--method", "patches", "--loss", "ps"]) != 0
    assert "needs loss patch" in one_error_line(capsys)
    out = tmp_path / "out"
    assert main([*command(inputs, out), *TINY, "--method", "patches"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["config"]["synthesis"]["method"] == "patches" and "octave by octave" in report["method"]
    assert (out / "textured.glb").is_file() and (out / "view_0.png").is_file()


def test_the_smooth_field_and_another_axis_walk_the_patches_and_are_refused_with_renders(
    inputs, tmp_path, capsys, monkeypatch
):
    """--direction-field smooth and --direction-axis lay the walked patches (the report keeps both); the renders
    method's views are upright in the mesh's up, so either there is a one-line error naming the method."""
    monkeypatch.setenv("MESH2TEX_PROGRESS", "0")
    field = ["--direction-field", "smooth", "--direction-axis", "x"]
    assert main([*command(inputs, tmp_path / "renders"), *TINY, "--method", "renders", *field]) != 0
    assert "need method surface or patches" in one_error_line(capsys)
    out = tmp_path / "out"
    assert main([*command(inputs, out), *TINY, "--method", "patches", *field]) == 0
    synthesis = json.loads((out / "report.json").read_text())["config"]["synthesis"]
    assert (synthesis["direction_field"], synthesis["direction_axis"]) == ("smooth", "x")
    assert (out / "textured.glb").is_file()


def test_reused_patches_walk_a_share_afresh_and_keep_the_newest_of_the_last_draw():
    """``patch_reuse`` R: the first draw walks every patch; each later one walks count / R afresh, ahead of
    the newest of the previous draw's; R = 1 walks all afresh every time; a fixed measurement walks afresh
    and leaves the kept patches as they were."""
    from mesh2tex.texel_synthesis import SurfacePatches

    mesh = stool()
    positions = mesh.vertices / np.abs(mesh.vertices).max()
    vertex_index, faces, uv = new_atlas(positions, mesh.faces)
    surface = TexelSurface.from_arrays(positions[vertex_index], faces, uv)
    generator = torch.Generator().manual_seed(0)
    reused = SurfacePatches(surface, 0.02, 5, "up", reuse=4)
    first, _ = reused.draw(64, 0, generator)
    second, whole = reused.draw(64, 0, generator)
    assert second.shape == first.shape and len(whole) == 64
    assert torch.equal(second[16:], first[:48]) and not torch.equal(second[:16], first[:16])
    with reused.fresh():
        reused.draw(64, 0, generator)
    third, _ = reused.draw(64, 0, generator)
    assert torch.equal(third[16:], second[:48])
    plain = SurfacePatches(surface, 0.02, 5, "up")
    a, _ = plain.draw(64, 0, generator)
    b, _ = plain.draw(64, 0, generator)
    assert not torch.equal(a[16:], b[16:])


def test_the_method_follows_the_loss_unless_set():
    """Unset, the method is the loss's own: the patch loss walks its patches, the others render views; a
    method set is kept, and patches with another loss is refused by name."""
    assert SynthesisConfig().method == "patches"
    assert SynthesisConfig(loss="ps").method == "renders"
    assert SynthesisConfig(loss="patch", method="renders").method == "renders"
    with pytest.raises(ValueError, match="needs loss patch"):
        SynthesisConfig(loss="ps", method="patches")
