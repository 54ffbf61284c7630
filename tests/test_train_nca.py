"""``train nca`` and ``infer nca`` end to end on a tiny sphere: files, resume, lineage, grafting, errors."""

import json

import numpy as np
import pytest
import torch
import trimesh
import yaml
from conftest import TINY_NCA
from PIL import Image

from mesh2tex.cli import main
from mesh2tex.io.checkpoint import checkpoint_digest, load_checkpoint
from mesh2tex.synthetic.exemplars import exemplar_image

TINY_NCA_RUN = {**TINY_NCA, "iters": 4}


@pytest.fixture(scope="module")
def nca_files(tmp_path_factory):
    root = tmp_path_factory.mktemp("nca")
    Image.fromarray(exemplar_image("stripes", 48)).save(root / "stripes.png")
    Image.fromarray(exemplar_image("checker", 48)).save(root / "checker.png")
    (root / "tiny.yaml").write_text(yaml.safe_dump(TINY_NCA_RUN))
    return root


@pytest.fixture(scope="module")
def straight(nca_files):
    """A run of the tiny config trained without a stop, in nca_files/straight: the model the other tests
    graft, infer and compare against (trained here, so any test can run alone or first)."""
    out = nca_files / "straight"
    assert train(nca_files, out) == 0
    return out


def train(root, out, *extra):
    return main(
        [
            "train",
            "nca",
            "--exemplar",
            str(root / "stripes.png"),
            "--out",
            str(out),
            "--config",
            str(root / "tiny.yaml"),
            "--device",
            "cpu",
            *extra,
        ]
    )


def test_an_interrupted_run_resumes_exactly(nca_files, straight, monkeypatch):
    import mesh2tex.train.nca as stage

    step = stage.NCATrainer.step

    def interrupted(self):
        if self.iteration == 2:
            raise KeyboardInterrupt
        return step(self)

    monkeypatch.setattr(stage.NCATrainer, "step", interrupted)
    assert train(nca_files, nca_files / "split") != 0
    monkeypatch.setattr(stage.NCATrainer, "step", step)
    assert load_checkpoint(nca_files / "split" / "checkpoint.safetensors", kind="nca")[1]["iteration"] == 2
    assert train(nca_files, nca_files / "split", "--resume") == 0
    a, meta_a = load_checkpoint(straight / "checkpoint.safetensors", kind="nca")
    b, meta_b = load_checkpoint(nca_files / "split" / "checkpoint.safetensors", kind="nca")
    assert meta_a["iteration"] == meta_b["iteration"] == 4
    for name in a["model"]:
        assert torch.allclose(a["model"][name], b["model"][name], atol=1e-6), name
    assert torch.allclose(a["pool"]["states"], b["pool"]["states"], atol=1e-6)
    assert (straight / "model.safetensors").stat().st_size < 200_000
    lines = [json.loads(l) for l in (straight / "metrics.jsonl").read_text().splitlines()]
    assert [l["iteration"] for l in lines] == [1, 2, 3, 4]


def test_a_second_run_into_the_same_folder_is_refused(nca_files, straight, capsys):
    assert train(nca_files, straight) != 0
    assert "--resume" in capsys.readouterr().err


def test_child_keeps_the_lineage_and_infer_grafts_it(nca_files, straight, capsys):
    parent = straight / "model.safetensors"
    assert (
        main(
            [
                "train",
                "nca",
                "--exemplar",
                str(nca_files / "checker.png"),
                "--out",
                str(nca_files / "child"),
                "--config",
                str(nca_files / "tiny.yaml"),
                "--parent",
                str(parent),
                "--iters",
                "2",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    _, parent_meta = load_checkpoint(parent, kind="nca")
    _, child_meta = load_checkpoint(nca_files / "child" / "model.safetensors", kind="nca")
    assert child_meta["lineage"] == parent_meta["lineage"]
    assert child_meta["parent"]["digest"] == checkpoint_digest(parent)
    out = nca_files / "graft"
    assert (
        main(
            [
                "infer",
                "nca",
                "--checkpoint",
                str(parent),
                "--graft",
                str(nca_files / "child" / "model.safetensors"),
                "--mesh",
                "sphere:4",
                "--out",
                str(out),
                "--steps",
                "6",
                "--views",
                "2",
                "--resolution",
                "32",
                "--texture-size",
                "64",
                "--texture-format",
                "webp",
                "--frames",
                "3",
                "--regrow",
                "y > 0.5",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    report = json.loads((out / "report.json").read_text())
    assert report["lineage"] is None and report["cells"] == 6 * 16 + 2
    for name in ("textured.glb", "textured.ply", "growth.gif", "state.safetensors", "view_0.png", "view_1.png"):
        assert (out / name).is_file(), name
    with Image.open(out / "growth.gif") as gif:
        assert gif.n_frames == 6  # 3 of the growth, 3 of the regrowth
    glb = next(iter(trimesh.load(out / "textured.glb").geometry.values()))
    assert glb.visual.material.baseColorTexture.format == "WEBP"
    state, _ = load_checkpoint(out / "state.safetensors")
    assert state["cells"]["state"].shape == (6 * 16 + 2, 6)
    assert np.isfinite(report["style_loss"])


def test_infer_refuses_to_replace_outputs_and_names_bad_input(nca_files, straight, capsys):
    model = str(straight / "model.safetensors")
    out = nca_files / "once"
    args = [
        "infer",
        "nca",
        "--checkpoint",
        model,
        "--mesh",
        "sphere:2",
        "--out",
        str(out),
        "--steps",
        "2",
        "--views",
        "1",
        "--resolution",
        "32",
        "--texture-size",
        "32",
        "--frames",
        "0",
        "--device",
        "cpu",
    ]
    assert main(args) == 0
    assert main(args) != 0
    assert "--overwrite" in capsys.readouterr().err
    assert main(args + ["--overwrite"]) == 0
    bad = nca_files / "bad.safetensors"
    bad.write_bytes(b"not a checkpoint")
    assert main(["infer", "nca", "--checkpoint", str(bad), "--out", str(nca_files / "x"), "--device", "cpu"]) != 0
    err = capsys.readouterr().err
    assert "bad.safetensors" in err and "Traceback" not in err
    assert (
        main(
            args[:-2]
            + ["--graft", model, "--graft-mask", "import os", "--out", str(nca_files / "y"), "--device", "cpu"]
        )
        != 0
    )
    assert "graft mask" in capsys.readouterr().err


def test_a_run_starts_from_another_runs_checkpoint(nca_files, capsys):
    """``--resume PATH`` into a new --out reaches the state of the source run continued in place; a snapshot-like
    inference model is refused."""
    source, other = nca_files / "from_source", nca_files / "from_other"
    assert train(nca_files, source, "--iters", "2") == 0
    capsys.readouterr()
    assert train(nca_files, other, "--iters", "4", "--resume", str(source / "checkpoint.safetensors")) == 0
    assert f"{other} starts from" in capsys.readouterr().err
    assert train(nca_files, source, "--iters", "4", "--resume") == 0
    a, meta_a = load_checkpoint(source / "checkpoint.safetensors", kind="nca")
    b, meta_b = load_checkpoint(other / "checkpoint.safetensors", kind="nca")
    assert meta_a["iteration"] == meta_b["iteration"] == 4 and meta_a["lineage"] == meta_b["lineage"]
    for name in a["model"]:
        torch.testing.assert_close(a["model"][name], b["model"][name], rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(a["pool"]["states"], b["pool"]["states"], rtol=1e-5, atol=1e-6)
    capsys.readouterr()
    assert train(nca_files, nca_files / "from_model", "--resume", str(source / "model.safetensors")) == 2
    assert "not a training checkpoint" in capsys.readouterr().err
    assert not (nca_files / "from_model").exists()


def test_infer_matches_the_training_cell_spacing_and_old_models_run_as_is(nca_files, straight, capsys):
    """A coarse mesh is split until its edges come nearest the training sphere's (sphere:1 against sphere:3:
    2.4x, one split leaves 1.2x, two 0.6x); a model saved without the training spacing still loads and
    runs on the mesh as it is."""
    from mesh2tex.io.checkpoint import save_checkpoint

    model = straight / "model.safetensors"
    groups, meta = load_checkpoint(model, kind="nca")
    assert meta["cell_spacing"] > 0
    old = nca_files / "old_model.safetensors"
    save_checkpoint(old, groups, kind="nca", meta={k: v for k, v in meta.items() if k != "cell_spacing"})
    common = [
        "--mesh",
        "sphere:1",
        "--steps",
        "2",
        "--views",
        "1",
        "--resolution",
        "32",
        "--texture-size",
        "32",
        "--frames",
        "0",
        "--device",
        "cpu",
    ]
    capsys.readouterr()
    for checkpoint, extra, cells, splits in (
        (model, [], 6 * 4 + 2, 1),
        (model, ["--subdivide", "0"], 8, 0),
        (old, [], 8, 0),
    ):
        out = nca_files / f"density_{checkpoint.stem}_{len(extra)}"
        assert main(["infer", "nca", "--checkpoint", str(checkpoint), "--out", str(out), *common, *extra]) == 0
        report = json.loads((out / "report.json").read_text())
        assert (report["cells"], report["subdivisions"]) == (cells, splits)
        line = capsys.readouterr().out
        assert line.startswith(f"{cells} cells (")
        assert ("records no training cell spacing" in line) == (checkpoint == old)


def test_infer_nca_hands_back_the_users_mesh(nca_files, straight, tmp_path):
    """Grown on a z-up STL stool (scaled by 40), the automaton's texture comes back on the stool itself:
    its vertices and triangles, the GLB's node standing it up, the PLY in the file's own frame."""
    from user_assets import user_files

    from mesh2tex.geometry.mesh_io import load_user_mesh
    from mesh2tex.io.assets import Z_UP_NODE_ROTATION, load_glb

    stl = user_files(tmp_path / "meshes")["stl"]
    out = tmp_path / "grown"
    assert (
        main(
            [
                "infer",
                "nca",
                "--checkpoint",
                str(straight / "model.safetensors"),
                "--mesh",
                str(stl),
                "--out",
                str(out),
                "--steps",
                "2",
                "--views",
                "1",
                "--resolution",
                "32",
                "--texture-size",
                "64",
                "--frames",
                "0",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    source = load_user_mesh(stl)
    vertices, faces, _, texture = load_glb(out / "textured.glb")
    assert len(faces) == len(source.faces) and set(map(tuple, vertices)) <= set(
        map(tuple, source.vertices.astype(np.float32))
    )
    assert texture.std() > 0
    ply = trimesh.load(out / "textured.ply", process=False)
    np.testing.assert_allclose(ply.vertices, source.vertices, rtol=1e-6)
    assert json.loads((out / "report.json").read_text())["output_mesh"]["up"] == "z"
    header = (out / "textured.glb").read_bytes()
    assert (
        json.loads(header[20 : 20 + int.from_bytes(header[12:16], "little")])["nodes"][0]["rotation"]
        == Z_UP_NODE_ROTATION
    )


def test_the_palette_term_is_added_to_the_loss_and_logged(nca_files, straight):
    """``colour_weight`` adds the sliced Wasserstein distance of the renders' pixels to the exemplar's;
    at 0 (the default) the log has no such term."""
    (nca_files / "colour.yaml").write_text(yaml.safe_dump({**TINY_NCA_RUN, "colour_weight": 2.0}))
    out = nca_files / "colour"
    assert train(nca_files, out, "--config", str(nca_files / "colour.yaml")) == 0
    lines = [json.loads(l) for l in (out / "metrics.jsonl").read_text().splitlines()]
    overflow_weight = TINY_NCA_RUN.get("overflow_weight", 10.0)
    for line in lines:
        assert line["loss_colour"] > 0
        expected = line["loss_style"] + 2.0 * line["loss_colour"] + overflow_weight * line["loss_overflow"]
        assert line["loss"] == pytest.approx(expected, rel=1e-4, abs=1e-5)
    plain = [json.loads(l) for l in (straight / "metrics.jsonl").read_text().splitlines()]
    assert all("loss_colour" not in line for line in plain)


def test_walked_patches_read_the_cells_colours_as_the_patch_loss_reads_an_image():
    """On a flat square with a vertex every exemplar pixel, the finest walked patches of vertex colours are the
    colours' own patches, upright and flattened as the loss flattens an image's: horizontal stripes are near
    the exemplar's patches, the same stripes turned a quarter far; a uniform colour stays uniform at every
    octave, and the coarser octaves pool the stripes towards their mean."""
    from mesh2tex.losses.structure import PATCH_SIZE, exemplar_patch_sets, patch_distance
    from mesh2tex.texel_synthesis import VertexPatches

    side = 48
    grid = np.arange(side) - (side - 1) / 2
    x, y = np.meshgrid(grid, -grid)  # row 0 at the top, y up
    positions = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1) / side  # one pixel: 1 / side
    cells = np.arange(side * side).reshape(side, side)
    a, b, c, d = cells[:-1, :-1].ravel(), cells[:-1, 1:].ravel(), cells[1:, 1:].ravel(), cells[1:, :-1].ravel()
    faces = np.concatenate([np.stack([a, c, b], 1), np.stack([a, d, c], 1)])  # facing +z
    patches = VertexPatches(positions, faces, 1 / side, levels=3, size=PATCH_SIZE, bank=256)
    assert min(patches.whole_patches()) > 0 and patches.pooling[0] is None
    rows = torch.from_numpy(np.arange(side) // 3 % 2).float() * 2 - 1  # horizontal stripes 3 pixels wide
    image = rows[None, None, :, None].expand(1, 3, side, side)
    exemplar = exemplar_patch_sets(image)
    turned = image.transpose(2, 3)

    def distance(picture: torch.Tensor) -> float:
        colours = picture[0].permute(1, 2, 0).reshape(-1, 3)  # the vertices in row-major order
        sets = patches.sets(colours, 128, torch.Generator().manual_seed(0))
        return float(patch_distance(sets[:1], exemplar[:1], torch.Generator().manual_seed(1)))

    assert distance(image) < 0.25 * distance(turned)
    uniform = patches.sets(torch.full((side * side, 3), 0.3), 64, torch.Generator().manual_seed(0))
    assert all(torch.allclose(s, torch.full_like(s, 0.3)) for s in uniform)
    stripes = patches.sets(image[0].permute(1, 2, 0).reshape(-1, 3), 64, torch.Generator().manual_seed(0))
    assert stripes[2].abs().mean() < 0.8 * stripes[0].abs().mean()


def test_the_patches_method_trains_with_the_patch_loss_only(nca_files, capsys):
    """``method: patches`` walks the patch loss's patches on the training mesh: with the patch loss (and the
    palette term) it trains and logs both terms; with another loss it is a one-line error naming the field."""
    (nca_files / "walked.yaml").write_text(
        yaml.safe_dump({**TINY_NCA_RUN, "style_loss": "patch", "method": "patches", "colour_weight": 1.0})
    )
    out = nca_files / "walked"
    assert train(nca_files, out, "--config", str(nca_files / "walked.yaml")) == 0
    lines = [json.loads(l) for l in (out / "metrics.jsonl").read_text().splitlines()]
    assert lines and all(np.isfinite(line["loss_style"]) and line["loss_colour"] >= 0 for line in lines)
    assert (out / "model.safetensors").is_file()
    (nca_files / "walked_ot.yaml").write_text(yaml.safe_dump({**TINY_NCA_RUN, "method": "patches"}))
    assert train(nca_files, nca_files / "walked_ot", "--config", str(nca_files / "walked_ot.yaml")) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "needs style_loss patch" in err[0]
