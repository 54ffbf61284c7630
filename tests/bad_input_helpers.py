"""The bad-input suite's helpers: a case, the good inputs it spoils, the spoilers and the check every case runs
(tests/test_bad_inputs.py, tests/test_bad_input_files.py)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
import yaml
from conftest import TINY_GAN
from PIL import Image

from mesh2tex.cli import main


@dataclass
class Case:
    argv: list[str]
    names: str  # the error line must contain this (the file or the field)
    code: int = 2


def make_ctx(tiny_gan: Path, root: Path) -> dict:
    """Good inputs to spoil: the tiny GAN (its run, shapes, photos) and a photo for transfer, under ``root``."""
    photo = np.zeros((48, 48, 4), np.uint8)
    photo[10:40, 14:34] = (200, 120, 40, 255)
    Image.fromarray(photo).save(root / "query.png")
    return {"gan": tiny_gan, "root": root}


# ------------------------------------------------------------------------------------ spoilers
def write(path: Path, data: bytes | str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    (path.write_bytes if isinstance(data, bytes) else path.write_text)(data)
    return path


def gan_config(path: Path, **changes) -> Path:
    """The tiny GAN config with ``changes`` (dotted keys) applied."""
    cfg = json.loads(json.dumps(TINY_GAN))
    for key, value in changes.items():
        node = cfg
        *parents, leaf = key.split(".")
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value
    return write(path, yaml.safe_dump(cfg))


def safetensors(path: Path, header: bytes) -> Path:
    """A file with the safetensors layout (8-byte length, JSON header) and ``header``."""
    return write(path, len(header).to_bytes(8, "little") + header)


def mesh2tex_header(path: Path, header) -> Path:
    return safetensors(path, json.dumps({"__metadata__": {"mesh2tex": json.dumps(header)}}).encode())


def spoiled_shape(ctx, path: Path, change) -> Path:
    """box0.npz with ``change(arrays)`` applied (arrays: a dict of numpy arrays)."""
    with np.load(ctx["gan"] / "shapes" / "box0.npz", allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    change(arrays)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **arrays)
    return path


def set_item(arrays, key, index, value):
    arrays[key] = arrays[key].copy()
    arrays[key][index] = value


def nan_vertex_obj(path: Path) -> Path:
    box = trimesh.creation.box()
    lines = [f"v {x} {y} {z}" for x, y, z in box.vertices]
    lines[3] = "v nan 0 0"
    return write(path, "\n".join(lines + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in box.faces]) + "\n")


def png(path: Path, size=(24, 24), mode="RGB") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.new(mode, size, 128).save(path)
    return path


def truncated(path: Path, source: Path, keep: int = 100) -> Path:
    return write(path, source.read_bytes()[:keep])


# ------------------------------------------------------------------------------------ commands
def train_gan(ctx, tmp, config=None, shapes=None, images=None, *extra):
    argv = [
        "train",
        "gan",
        "--shapes",
        str(shapes or ctx["gan"] / "shapes"),
        "--images",
        str(images or ctx["gan"] / "photos"),
        "--out",
        str(tmp / "out"),
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
    return argv + (["--config", str(config)] if config else []) + list(extra)


def generate(ctx, tmp, checkpoint=None, mesh=None, *extra):
    return [
        "infer",
        "generate",
        "--checkpoint",
        str(checkpoint or ctx["gan"] / "run" / "checkpoint.safetensors"),
        "--mesh",
        str(mesh or ctx["gan"] / "shapes" / "box0.npz"),
        "--out",
        str(tmp / "out"),
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
        *extra,
    ]


def transfer(ctx, tmp, image=None, *extra):
    return [
        "infer",
        "transfer",
        "--checkpoint",
        str(ctx["gan"] / "run" / "checkpoint.safetensors"),
        "--mesh",
        str(ctx["gan"] / "shapes" / "box0.npz"),
        "--image",
        str(image or ctx["root"] / "query.png"),
        "--pose",
        "30,20",
        "--no-noc",
        "--out",
        str(tmp / "out"),
        "--resolution",
        "64",
        "--latent-iters",
        "1",
        "--refine-iters",
        "0",
        "--device",
        "cpu",
        *extra,
    ]


def evaluate(tmp, renders, images, *extra):
    return ["evaluate", "--renders", str(renders), "--images", str(images), "--out", str(tmp / "out"), *extra]


def crafted_resume(ctx, tmp):
    """A run folder whose checkpoint's header is not a mesh2tex one, resumed."""
    write(tmp / "out" / "config.yaml", (ctx["gan"] / "run" / "config.yaml").read_text())
    safetensors(tmp / "out" / "checkpoint.safetensors", b'{"__metadata__": ["x"]}')
    return train_gan(ctx, tmp, None, None, None, "--resume")


def resume_with_meta(ctx, tmp, change):
    """The tiny GAN's run copied with ``change(meta)`` applied to its checkpoint's metadata, resumed."""
    from mesh2tex.io.checkpoint import load_checkpoint, save_checkpoint

    groups, meta = load_checkpoint(ctx["gan"] / "run" / "checkpoint.safetensors", kind="gan")
    change(meta)
    save_checkpoint(tmp / "out" / "checkpoint.safetensors", groups, "gan", meta)
    write(tmp / "out" / "config.yaml", (ctx["gan"] / "run" / "config.yaml").read_text())
    return train_gan(ctx, tmp, None, None, None, "--resume", "--iters", "3")


def nan_weights(ctx, path: Path) -> Path:
    """The tiny GAN's checkpoint with a NaN in the EMA generator's weights."""
    from mesh2tex.io.checkpoint import load_checkpoint, save_checkpoint

    groups, meta = load_checkpoint(ctx["gan"] / "run" / "checkpoint.safetensors", kind="gan")
    for name, tensor in groups["generator_ema"].items():
        if tensor.is_floating_point() and "weight" in name:
            tensor.view(-1)[0] = float("nan")
    save_checkpoint(path, groups, "gan", meta)
    return path


def pair_folders(tmp, bad_image: Path | None = None):
    renders, images = png(tmp / "r" / "a.png").parent, png(tmp / "i" / "a.png").parent
    if bad_image is not None:
        (images / "a.png").unlink()
        bad_image.rename(images / bad_image.name)
    return renders, images


def snapshot(folder: Path) -> dict[str, bytes]:
    return (
        {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}
        if folder.exists()
        else {}
    )


def check_case(case: Case, out: Path, capsys) -> str:
    """Run ``case``; assert the exit status, one error line naming the problem, and an untouched --out."""
    write(out / "mine.txt", "a file of the user's")
    before = snapshot(out)
    capsys.readouterr()
    code = main(case.argv)
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if line.startswith("mesh2tex: error:")]
    assert code == case.code, err
    assert "Traceback" not in err
    assert len(errors) == 1, err
    assert case.names in errors[0], errors[0]
    assert snapshot(out) == before, "--out changed"
    return errors[0]
