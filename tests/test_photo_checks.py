"""A photo set is checked once when training or evaluation reads it (mesh2tex/photos.py).

Every file is read and checked before the command starts its work: a file too small, of a kind that
is no photo, with a mask that is missing, of another size, coloured or empty, or whose object
vanishes at the training resolution, is named on a line of its own, and the command stops with one
error line counting them; ``--out`` is left as it was.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from mesh2tex.cli import main
from mesh2tex.errors import InputError
from mesh2tex.photos import read_photo_set, read_set_photo, refuse_rejected


def photo(path, size=(32, 32), alpha=None):
    """An RGB photo with a gradient (an RGBA one when ``alpha`` (H, W) uint8 is given)."""
    w, h = size
    rgb = np.zeros((h, w, 3), np.uint8)
    rgb[..., 0] = np.linspace(0, 255, w, dtype=np.uint8)[None]
    rgb[..., 1] = 90
    image = Image.fromarray(rgb if alpha is None else np.dstack([rgb, alpha]))
    path.parent.mkdir(parents=True, exist_ok=True)
    image.save(path)
    return path


def centre_alpha(size=32):
    alpha = np.zeros((size, size), np.uint8)
    alpha[size // 4 : 3 * size // 4, size // 4 : 3 * size // 4] = 255
    return alpha


@pytest.mark.parametrize(
    "make, expected",
    [
        (
            lambda d: photo(d / "tiny.png", (1, 1)),
            "tiny.png: the photo is 1x1 pixels; a photo of a set needs at least 8x8",
        ),
        (lambda d: photo(d / "strip.png", (300, 4)), "strip.png: the photo is 300x4 pixels"),
        (
            lambda d: photo(d / "clear.png", alpha=np.zeros((32, 32), np.uint8)),
            "clear.png: the mask is empty (no object pixel in the alpha channel)",
        ),
        (
            lambda d: Image.new("1", (32, 32), 1).save(d / "bits.png") or d / "bits.png",
            "bits.png: a 1-bit black-and-white image (a mask?), not a photo",
        ),
        (
            lambda d: Image.fromarray(np.ones((32, 32), np.float32)).save(d / "depth.tif") or d / "depth.tif",
            "depth.tif: a 32-bit float image",
        ),
        (lambda d: (d / "empty.png").write_bytes(b"") or d / "empty.png", "empty.png: empty file"),
    ],
)
def test_a_bad_photo_is_refused_naming_the_file(make, expected, tmp_path):
    path = make(tmp_path)
    with pytest.raises(InputError) as caught:
        read_set_photo(path)
    assert expected in str(caught.value) and str(tmp_path) in str(caught.value)


def test_a_bad_mask_file_is_refused_naming_it(tmp_path):
    image = photo(tmp_path / "a.png")
    with pytest.raises(InputError, match="masks/a.png: mask missing for a.png"):
        read_set_photo(image, tmp_path / "masks" / "a.png")
    Image.new("L", (16, 16), 255).save((tmp_path / "masks").mkdir() or tmp_path / "masks" / "a.png")
    with pytest.raises(InputError, match="masks/a.png: mask is 16x16, the photo a.png 32x32"):
        read_set_photo(image, tmp_path / "masks" / "a.png")
    photo(tmp_path / "masks" / "a.png")  # the photo put among the masks by mistake
    with pytest.raises(InputError, match=r"masks/a.png: not a mask: \d+% of its pixels are coloured"):
        read_set_photo(image, tmp_path / "masks" / "a.png")
    Image.new("L", (32, 32), 0).save(tmp_path / "masks" / "a.png")
    with pytest.raises(InputError, match=r"masks/a.png: the mask is empty \(no object pixel\)"):
        read_set_photo(image, tmp_path / "masks" / "a.png")


def test_good_photos_pass_with_their_masks_and_16_bit_gray_keeps_its_level(tmp_path):
    rgb, alpha = read_set_photo(photo(tmp_path / "a.png", alpha=centre_alpha()))
    assert rgb.shape == (32, 32, 3) and alpha.shape == (32, 32) and (alpha >= 128).sum() == 256
    rgb, alpha = read_set_photo(photo(tmp_path / "b.png"))
    assert alpha is None, "no mask: the whole photo is the object"
    Image.fromarray(np.full((16, 16), 32768, np.uint16)).save(tmp_path / "gray16.png")
    rgb, _ = read_set_photo(tmp_path / "gray16.png")
    assert abs(int(rgb[0, 0, 0]) - 128) <= 1, "a 16-bit photo is scaled, not clipped to white"


def test_the_whole_set_is_read_and_every_bad_file_named(tmp_path, capsys):
    items = [
        (photo(tmp_path / "good.png"), None),
        (photo(tmp_path / "tiny.png", (2, 2)), None),
        (photo(tmp_path / "clear.png", alpha=np.zeros((32, 32), np.uint8)), None),
    ]
    kept, rejected = read_photo_set(items)
    assert len(kept) == 1 and len(rejected) == 2 and "tiny.png" in rejected[0] and "clear.png" in rejected[1]
    with pytest.raises(InputError, match=r"2 of 3 photos cannot be used \(each named above\), the first: .*tiny.png"):
        refuse_rejected(rejected, 3, tmp_path)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 2 and all(line.startswith("mesh2tex: warning: rejected: ") for line in lines)
    with pytest.raises(InputError, match=r"1 of 3 photos cannot be used: .*tiny.png"):
        refuse_rejected(rejected[:1], 3, tmp_path)
    assert capsys.readouterr().err == "", "one rejected file: the error line alone names it"
    refuse_rejected([], 3, tmp_path)


def test_train_gan_stops_on_a_set_with_bad_photos_naming_each(tiny_gan, tmp_path, capsys):
    photos = tmp_path / "photos"
    for k in range(3):
        photo(photos / f"{k}.png", alpha=centre_alpha())
    photo(photos / "tiny.png", (1, 1))
    speck = np.zeros((64, 64), np.uint8)
    speck[10, 10] = 255  # one pixel of object: nothing of it is left at 16x16
    photo(photos / "speck.png", (64, 64), alpha=speck)
    out = tmp_path / "run"
    code = main(
        [
            "train",
            "gan",
            "--shapes",
            str(tiny_gan / "shapes"),
            "--images",
            str(photos),
            "--out",
            str(out),
            "--iters",
            "1",
            "--batch",
            "2",
            "--views",
            "2",
            "--resolution",
            "16",
            "--device",
            "cpu",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.startswith("mesh2tex: ")]
    assert len(lines) == 3 and "speck.png: the object covers no pixel once resized to 16x16" in lines[0], lines
    assert "tiny.png: the photo is 1x1 pixels" in lines[1]
    assert lines[2].startswith("mesh2tex: error: ") and "2 of 5 photos cannot be used" in lines[2]
    assert not out.exists(), "nothing written"


def test_evaluate_stops_on_a_bad_image_of_a_set(tmp_path, capsys):
    renders, images = tmp_path / "renders", tmp_path / "images"
    for k in range(3):
        photo(renders / f"{k}.png")
        photo(images / f"{k}.png")
    photo(images / "1.png", (1, 1))
    out = tmp_path / "out"
    assert main(["evaluate", "--renders", str(renders), "--images", str(images), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "1 of 3 images cannot be used" in err and "1.png: the photo is 1x1" in err, err
    assert not out.exists()


def test_prepare_images_fails_a_tiny_photo_and_prepares_the_rest(tmp_path, capsys):
    src, out = tmp_path / "src", tmp_path / "out"
    photo(src / "a.png", alpha=centre_alpha())
    photo(src / "tiny.png", (1, 1))
    assert main(["prepare", "images", "--input", str(src), "--out", str(out), "--size", "16"]) == 2
    records = {r["name"]: r for r in json.loads((out / "index.json").read_text())["images"]}
    assert (
        records["a"]["status"] == "ok" and records["tiny"]["status"] == "failed" and "1x1" in records["tiny"]["reason"]
    )
    assert "tiny.png: the photo is 1x1" in capsys.readouterr().err
    assert not (out / "images" / "tiny.png").exists()
