"""`mesh2tex prepare images` and image loading: masks from alpha, files or GrabCut; odd formats; bad files."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from mesh2tex.cli import main
from mesh2tex.errors import InputError
from mesh2tex.io.images import load_image, save_png


def photo_with_object(h=120, w=160, box=(30, 50, 90, 130)) -> tuple[np.ndarray, np.ndarray]:
    """A textured grey background with a saturated red object; returns the RGB image and its true mask."""
    rng = np.random.default_rng(0)
    rgb = (rng.normal(180, 8, size=(h, w, 3))).clip(0, 255).astype(np.uint8)
    mask = np.zeros((h, w), bool)
    top, left, bottom, right = box
    mask[top:bottom, left:right] = True
    rgb[mask] = (200, 30, 40)
    return rgb, mask


def iou(a, b):
    return (a & b).sum() / max(1, (a | b).sum())


def test_load_image_normalises_grayscale_16bit_palette_and_rgba(tmp_path):
    rgb, mask = photo_with_object()
    Image.fromarray(rgb).convert("L").save(tmp_path / "gray.png")
    Image.fromarray((rgb[..., 0].astype(np.uint16) * 257)).save(tmp_path / "deep.png")
    Image.fromarray(rgb).convert("P", palette=Image.Palette.ADAPTIVE, colors=16).save(tmp_path / "palette.gif")
    Image.fromarray(np.dstack([rgb, mask.astype(np.uint8) * 255])).save(tmp_path / "rgba.png")
    for name in ("gray.png", "deep.png", "palette.gif", "rgba.png"):
        image, alpha = load_image(tmp_path / name)
        assert image.shape == (120, 160, 3) and image.dtype == np.uint8, name
        assert (alpha is not None) == (name == "rgba.png"), name
    deep, _ = load_image(tmp_path / "deep.png")
    assert np.abs(deep[..., 0].astype(int) - rgb[..., 0]).max() <= 1, "16-bit scaled to 8-bit by its range"
    _, alpha = load_image(tmp_path / "rgba.png")
    assert np.array_equal(alpha >= 128, mask)


@pytest.mark.parametrize("content", [b"", b"\x89PNG\r\n\x1a\n broken", b"just text"])
def test_load_image_rejects_corrupt_files(tmp_path, content):
    path = tmp_path / "bad.png"
    path.write_bytes(content)
    with pytest.raises(InputError) as error:
        load_image(path)
    assert str(path) in str(error.value)


def test_prepare_images_masks_from_alpha_file_and_estimate(tmp_path, capsys):
    src, masks, out = tmp_path / "photos", tmp_path / "masks", tmp_path / "out"
    (src / "sub").mkdir(parents=True)
    masks.mkdir()
    rgb, mask = photo_with_object()
    Image.fromarray(np.dstack([rgb, mask.astype(np.uint8) * 255])).save(src / "with_alpha.png")
    Image.fromarray(rgb).save(src / "sub" / "with_file.jpg", quality=95)
    save_png(masks / "with_file.png", mask)
    Image.fromarray(rgb).save(src / "estimated.png")
    (src / "corrupt.jpg").write_bytes(b"\xff\xd8\xff not really a jpeg")
    # fully transparent
    Image.fromarray(np.dstack([rgb, np.zeros_like(mask, dtype=np.uint8)])).save(src / "invisible.png")

    code = main(["prepare", "images", "--input", str(src), "--out", str(out), "--size", "64", "--masks", str(masks)])
    assert code == 2, "corrupt and empty-mask inputs make the run fail, the rest still done"
    index = {entry["name"]: entry for entry in json.loads((out / "index.json").read_text())["images"]}
    assert index["with_alpha"]["mask"] == "alpha"
    assert index["sub_with_file"]["mask"].startswith("file")
    assert index["estimated"]["mask"].startswith("estimated")
    assert index["corrupt"]["status"] == "failed" and "corrupt.jpg" in index["corrupt"]["reason"]
    assert index["invisible"]["status"] == "failed" and "empty" in index["invisible"]["reason"]
    assert "corrupt.jpg" in capsys.readouterr().err

    # the object is a 60 x 80 box: the square crop with a 10 % margin holds it centred, 80 px -> 64 px * (1/1.2)
    expected = np.zeros((64, 64), bool)
    side = 80 * 1.2
    half_h, half_w = 60 / side * 32, 80 / side * 32
    expected[round(32 - half_h) : round(32 + half_h), round(32 - half_w) : round(32 + half_w)] = True
    for name in ("with_alpha", "sub_with_file", "estimated"):
        image = np.asarray(Image.open(out / "images" / f"{name}.png"))
        out_mask = np.asarray(Image.open(out / "masks" / f"{name}.png")) > 127
        assert image.shape == (64, 64, 3) and out_mask.shape == (64, 64)
        assert iou(out_mask, expected) > 0.85, name
        assert image[out_mask].mean(axis=0)[0] > 150 and image[out_mask].mean(axis=0)[1] < 80, (
            "the object is what is masked"
        )


def test_prepare_images_missing_folder_is_a_user_error(tmp_path, capsys):
    assert main(["prepare", "images", "--input", str(tmp_path / "none"), "--out", str(tmp_path / "out")]) == 2
    assert "none" in capsys.readouterr().err


def test_prepare_images_refuses_to_replace_its_outputs_without_overwrite(tmp_path, capsys):
    src, out = tmp_path / "photos", tmp_path / "out"
    src.mkdir()
    rgb, mask = photo_with_object()
    for name in ("a", "b"):
        Image.fromarray(np.dstack([rgb, mask.astype(np.uint8) * 255])).save(src / f"{name}.png")
    argv = ["prepare", "images", "--input", str(src), "--out", str(out), "--size", "32"]
    assert main(argv) == 0
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    capsys.readouterr()
    assert main(argv + ["--size", "16"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "already holds index.json" in err and "--overwrite" in err, err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before, "nothing replaced"
    (src / "b.png").unlink()  # the next set lacks b: --overwrite leaves the folder holding this set only
    assert main(argv + ["--size", "16", "--overwrite"]) == 0
    assert sorted(p.name for p in (out / "images").iterdir()) == ["a.png"]
    assert sorted(p.name for p in (out / "masks").iterdir()) == ["a.png"]
    assert np.asarray(Image.open(out / "images" / "a.png")).shape == (16, 16, 3)
