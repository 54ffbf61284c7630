"""Bad inputs beyond the table of tests/test_bad_inputs.py: decompression bombs, shapes that would inflate past the cap,
files already in --out kept or replaced, 16-bit PNGs, half-written files of an old version, out-of-range config
values."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from bad_input_helpers import (
    Case,
    check_case,
    evaluate,
    generate,
    make_ctx,
    pair_folders,
    png,
    train_gan,
    transfer,
    write,
)
from PIL import Image

from mesh2tex.cli import main


@pytest.fixture(scope="module")
def ctx(tiny_gan, tmp_path_factory):
    return make_ctx(tiny_gan, tmp_path_factory.mktemp("bad_inputs"))


# ------------------------------------------------------------------------ cases that need a patch
def test_decompression_bombs_are_one_line_errors(ctx, tmp_path, capsys, monkeypatch):
    """PIL refuses images over twice MAX_IMAGE_PIXELS; a smaller limit stands in for a 1 GB bomb."""
    monkeypatch.setenv("MESH2TEX_PROGRESS", "0")
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 100)
    bomb = png(tmp_path / "bomb.png", (48, 48))
    check_case(Case(transfer(ctx, tmp_path / "t", bomb), "bomb.png: image too large"), tmp_path / "t" / "out", capsys)
    renders, images = pair_folders(tmp_path / "e")
    check_case(
        Case(evaluate(tmp_path / "e", renders, images, "--pairs"), "a.png: image too large"),
        tmp_path / "e" / "out",
        capsys,
    )
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 10**8)
    photos = tmp_path / "photos"
    png(photos / "0.png", (24, 24), "RGBA")
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 100)
    check_case(
        Case(train_gan(ctx, tmp_path / "g", None, None, photos), "0.png: image too large"),
        tmp_path / "g" / "out",
        capsys,
    )


def test_a_shape_that_would_inflate_beyond_the_cap_is_refused_before_reading(ctx, tmp_path, capsys, monkeypatch):
    from mesh2tex.geometry import prepared

    monkeypatch.setattr(prepared, "MAX_UNCOMPRESSED_BYTES", 1000)  # stands in for a 1 MB file inflating to 1.2 GB
    check_case(
        Case(generate(ctx, tmp_path), "box0.npz: not a valid prepared shape (ValueError: its arrays would take"),
        tmp_path / "out",
        capsys,
    )


# ----------------------------------------------------------------------- data loss: the output guard
@pytest.mark.parametrize(
    "command, existing",
    [
        ("generate", "seed0.glb"),
        ("generate", "seed0_view0.png"),
        ("transfer", "comparison.png"),
        ("transfer", "textured.glb"),
        ("evaluate", "metrics.md"),
    ],
)
def test_files_already_in_out_are_kept_without_overwrite(command, existing, ctx, tmp_path, capsys):
    out = tmp_path / "out"
    write(out / existing, "the user's own file")
    argv = {
        "generate": lambda: generate(ctx, tmp_path),
        "transfer": lambda: transfer(ctx, tmp_path),
        "evaluate": lambda: evaluate(tmp_path, *pair_folders(tmp_path), "--pairs"),
    }[command]()
    line = check_case(Case(argv, f"already holds {existing}"), out, capsys)
    assert "--overwrite" in line


def test_infer_nca_keeps_files_already_in_out(tmp_path, capsys):
    from conftest import TINY_NCA

    from mesh2tex.synthetic.exemplars import exemplar_image

    Image.fromarray(exemplar_image("stripes", 48)).save(tmp_path / "stripes.png")
    write(tmp_path / "tiny.yaml", yaml.safe_dump({**TINY_NCA, "iters": 1}))
    assert (
        main(
            [
                "train",
                "nca",
                "--exemplar",
                str(tmp_path / "stripes.png"),
                "--out",
                str(tmp_path / "run"),
                "--config",
                str(tmp_path / "tiny.yaml"),
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    out = tmp_path / "out"
    write(out / "view_0.png", "the user's own file")
    check_case(
        Case(
            [
                "infer",
                "nca",
                "--checkpoint",
                str(tmp_path / "run" / "model.safetensors"),
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
            ],
            "already holds view_0.png",
        ),
        out,
        capsys,
    )


def test_overwrite_replaces_them(ctx, tmp_path):
    out = tmp_path / "out"
    write(out / "seed0.glb", "the user's own file")
    assert main(generate(ctx, tmp_path, None, None, "--overwrite")) == 0
    assert (out / "seed0.glb").read_bytes()[:4] == b"glTF"


# ------------------------------------------------------------------------------- silently wrong
def test_sixteen_bit_pngs_are_read_to_their_full_range(tmp_path, capsys):
    """evaluate --pairs: a 16-bit PNG against its own 8-bit copy is (nearly) identical, also when it is dark."""
    rng = np.random.default_rng(0)
    for name, top in (("bright", 65535), ("dark", 255)):
        gray16 = (rng.random((32, 32)) * top).astype(np.uint16)
        (tmp_path / "r").mkdir(exist_ok=True)
        (tmp_path / "i").mkdir(exist_ok=True)
        Image.fromarray(gray16).save(tmp_path / "r" / f"{name}.png")
        gray8 = np.round(gray16 / 65535.0 * 255).astype(np.uint8)
        Image.fromarray(np.repeat(gray8[..., None], 3, axis=2)).save(tmp_path / "i" / f"{name}.png")
    assert main(evaluate(tmp_path, tmp_path / "r", tmp_path / "i", "--pairs")) == 0
    result = json.loads((tmp_path / "out" / "metrics.json").read_text())
    for pair in result["per_pair"]:
        assert pair["psnr_masked"] == "inf" or pair["psnr_masked"] > 45, pair


def test_old_half_written_files_are_not_taken_for_shapes(ctx, tmp_path):
    """A leftover of a killed writer (the hidden temp names of old versions, or the partial folder) is not a shape."""
    from mesh2tex.geometry.prepared import shape_paths
    from mesh2tex.io.atomic import PARTIAL_DIR, _owner, atomic_path

    folder = tmp_path / "shapes"
    write(folder / "box0.npz", (ctx["gan"] / "shapes" / "box0.npz").read_bytes())
    write(folder / ".box1.x1y2.partial.npz", b"PK\x03\x04 half")
    write(folder / PARTIAL_DIR / "999999999.abc" / "box2.npz", b"PK\x03\x04 half")  # a dead process's (an older name)
    host = _owner().split("@", 1)[1]
    write(folder / PARTIAL_DIR / f"999999998@{host}.abc" / "box3.npz", b"PK\x03\x04 half")  # a dead process's
    write(folder / PARTIAL_DIR / "999999997@another-machine.abc" / "box4.npz", b"PK\x03\x04 half")  # not ours to judge
    assert list(shape_paths(folder)) == ["box0"]
    with atomic_path(folder / "note.json") as tmp:  # the next write into the folder removes the dead one's leftovers
        assert tmp.parent.parent.name == PARTIAL_DIR and tmp.name == "note.json"
        tmp.write_text("{}")
    assert [p.name for p in (folder / PARTIAL_DIR).iterdir()] == ["999999997@another-machine.abc"]


@pytest.mark.parametrize(
    "change, names",
    [
        ({"lr": -1.0}, "lr must be positive"),
        ({"camera": {"distance": 0}}, "distance must be positive"),
        ({"nca": {"channels": 100000}}, "channels must be at most"),
        ({"checkpoint_every": -3}, "checkpoint_every must be at least 0"),
        ({"steps_min": 5, "steps_max": 2}, "steps_max 2 is below steps_min 5"),
        ({"nca": {"readout": "mlp"}}, "readout must be one of"),
    ],
)
def test_train_nca_config_values_out_of_range_are_named(change, names, tmp_path, capsys):
    from mesh2tex.synthetic.exemplars import exemplar_image

    Image.fromarray(exemplar_image("stripes", 48)).save(tmp_path / "stripes.png")
    config = write(tmp_path / "bad.yaml", yaml.safe_dump(change))
    check_case(
        Case(
            [
                "train",
                "nca",
                "--exemplar",
                str(tmp_path / "stripes.png"),
                "--out",
                str(tmp_path / "out"),
                "--config",
                str(config),
                "--device",
                "cpu",
            ],
            names,
        ),
        tmp_path / "out",
        capsys,
    )
