"""The bad-input suite: every case is one command a user could type with one bad input.

Each case asserts exit status 2, exactly one ``mesh2tex: error:`` line on stderr that names the bad
file or field, no traceback (an exception escaping ``main`` fails the test with one), and that the
files already in ``--out`` are unchanged and nothing was added there. docs/reliability.md lists the
cases; run them with ``pytest tests/test_bad_inputs.py``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
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


@pytest.fixture(scope="module")
def ctx(tiny_gan, tmp_path_factory):
    """Good inputs to spoil: the tiny GAN (its run, shapes, photos) and a photo for transfer."""
    root = tmp_path_factory.mktemp("bad_inputs")
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
    argv = ["train", "gan", "--shapes", str(shapes or ctx["gan"] / "shapes"), "--images", str(images or ctx["gan"] / "photos"),
            "--out", str(tmp / "out"), "--iters", "1", "--batch", "2", "--views", "2", "--resolution", "16", "--device", "cpu"]
    return argv + (["--config", str(config)] if config else []) + list(extra)


def generate(ctx, tmp, checkpoint=None, mesh=None, *extra):
    return ["infer", "generate", "--checkpoint", str(checkpoint or ctx["gan"] / "run" / "checkpoint.safetensors"),
            "--mesh", str(mesh or ctx["gan"] / "shapes" / "box0.npz"), "--out", str(tmp / "out"), "--seeds", "0",
            "--views", "1", "--resolution", "16", "--texture-size", "32", "--device", "cpu", *extra]


def transfer(ctx, tmp, image=None, *extra):
    return ["infer", "transfer", "--checkpoint", str(ctx["gan"] / "run" / "checkpoint.safetensors"),
            "--mesh", str(ctx["gan"] / "shapes" / "box0.npz"), "--image", str(image or ctx["root"] / "query.png"), "--pose", "30,20",
            "--no-noc", "--out", str(tmp / "out"), "--resolution", "64", "--latent-iters", "1", "--refine-iters", "0", "--device", "cpu",
            *extra]


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


CASES = {
    # configs: types, ranges, encodings (train gan reads its config before any data)
    "config not UTF-8": lambda c, t: Case(train_gan(c, t, write(t / "latin1.yaml", "iters: 3 # caf\xe9\n".encode("latin-1"))), "latin1.yaml: not UTF-8"),
    "config lr a non-numeric string": lambda c, t: Case(train_gan(c, t, gan_config(t / "c.yaml", **{"optim.lr_field": "fast"})), "optim.lr_field"),
    "config list element of the wrong type": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", **{"generator.encoder_channels": [8, "wide", 8]})), "generator.encoder_channels[1]"),
    "config log_every 0": lambda c, t: Case(train_gan(c, t, gan_config(t / "c.yaml", log_every=0)), "log_every"),
    "config sample_shapes 0": lambda c, t: Case(train_gan(c, t, gan_config(t / "c.yaml", sample_shapes=0)), "sample_shapes"),
    "config checkpoint_every -3": lambda c, t: Case(train_gan(c, t, gan_config(t / "c.yaml", checkpoint_every=-3)), "checkpoint_every"),
    "config channel_base negative": lambda c, t: Case(train_gan(c, t, gan_config(t / "c.yaml", **{"discriminator.channel_base": -64})),
                                                     "discriminator: channel_base"),
    "config channel_base too small for the resolution": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", **{"discriminator.channel_base": 8})), "channel_base 8 is too small for resolution 16"),
    "config 100000 channels": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", **{"generator.synthesis_channels": [100000, 8, 8]})), "synthesis_channels"),
    "config camera.distance a word": lambda c, t: Case(train_gan(c, t, gan_config(t / "c.yaml", **{"camera.distance": "far"})), "camera.distance"),
    "config camera.distance 0": lambda c, t: Case(train_gan(c, t, gan_config(t / "c.yaml", **{"camera.distance": 0})), "distance must be positive"),
    "config negative learning rate": lambda c, t: Case(train_gan(c, t, gan_config(t / "c.yaml", **{"optim.lr_generator": -1e-4})), "lr_generator"),
    "config a number beyond any float": lambda c, t: Case(train_gan(c, t, gan_config(t / "c.yaml", ema_rampup=10**400)),
                                                          "ema_rampup: expected a finite number"),
    "config NaN": lambda c, t: Case(train_gan(c, t, gan_config(t / "c.yaml", ema_rampup=math.nan)), "ema_rampup: expected a finite number"),
    "config not a mapping below": lambda c, t: Case(train_gan(c, t, gan_config(t / "c.yaml", optim=[1, 2])), "'optim' must be a mapping"),
    "transfer config turntable_frames 0": lambda c, t: Case(
        transfer(c, t, None, "--config", str(write(t / "t.yaml", "turntable_frames: 0\n"))), "t.yaml: turntable_frames"),
    "train pose config distance range reversed": lambda c, t: Case(
        ["train", "pose", "--shapes", str(c["gan"] / "shapes"), "--out", str(t / "out"), "--device", "cpu",
         "--config", str(write(t / "p.yaml", "data: {distance_min: 3.0, distance_max: 1.0}\n"))], "p.yaml.data: distance 3.0..1.0"),
    # flags
    "generate --truncation nan": lambda c, t: Case(generate(c, t, None, None, "--truncation", "nan"), "truncation: expected a finite number"),
    "generate --seeds beyond 64 bits": lambda c, t: Case(generate(c, t, None, None, "--seeds", "99999999999999999999"), "seeds[0]: 99999999999999999999 is out of range"),
    "train gan --seed beyond 64 bits": lambda c, t: Case(train_gan(c, t, None, None, None, "--seed", "-99999999999999999999"), "seed: -99999999999999999999 is out of range"),
    "generate --elevation inf in a config": lambda c, t: Case(
        generate(c, t, None, None, "--config", str(write(t / "g.yaml", "elevation: .inf\n"))), "g.yaml.elevation"),
    "transfer --pose elevation 1000": lambda c, t: Case(transfer(c, t, None, "--pose", "30,1000"), "--pose"),
    # checkpoints
    "checkpoint header a JSON list": lambda c, t: Case(generate(c, t, safetensors(t / "list.safetensors", b"[1, 2, 3]")), "list.safetensors"),
    "checkpoint header nested 100000 deep": lambda c, t: Case(
        generate(c, t, safetensors(t / "deep.safetensors", b"[" * 100000 + b"]" * 100000)), "deep.safetensors"),
    "checkpoint metadata nested 100000 deep": lambda c, t: Case(
        generate(c, t, safetensors(t / "deep2.safetensors", json.dumps({"__metadata__": {"mesh2tex": "[" * 100000 + "]" * 100000}}).encode())),
        "deep2.safetensors"),
    "checkpoint __metadata__ a string": lambda c, t: Case(
        generate(c, t, safetensors(t / "meta.safetensors", b'{"__metadata__": "mesh2tex"}')), "meta.safetensors"),
    "checkpoint without meta": lambda c, t: Case(generate(c, t, mesh2tex_header(t / "nometa.safetensors", {"format": 1, "kind": "gan"})),
                                                 "nometa.safetensors"),
    "checkpoint meta without a generator config": lambda c, t: Case(
        generate(c, t, mesh2tex_header(t / "nogen.safetensors", {"format": 1, "kind": "gan", "meta": {}})), "nogen.safetensors"),
    "checkpoint truncated": lambda c, t: Case(
        generate(c, t, truncated(t / "cut.safetensors", c["gan"] / "run" / "checkpoint.safetensors", 5000)), "cut.safetensors"),
    "checkpoint asking for 100000 channels": lambda c, t: Case(generate(c, t, mesh2tex_header(t / "wide.safetensors", {
        "format": 1, "kind": "gan", "meta": {"generator_config": {**TINY_GAN["generator"], "synthesis_channels": [100000, 8, 8]}}})),
        "wide.safetensors"),
    "checkpoint with NaN weights": lambda c, t: Case(generate(c, t, nan_weights(c, t / "nan.safetensors")), "nan.safetensors: the generator's colours"),
    "resume from a checkpoint with a crafted header": lambda c, t: Case(crafted_resume(c, t), "out/checkpoint.safetensors"),
    "resume with RNG states of another form": lambda c, t: Case(resume_with_meta(c, t, lambda m: m.update(rng=[{"torch": 7}])),
                                                                "RNG states of another form"),
    "resume with optimizer states missing": lambda c, t: Case(resume_with_meta(c, t, lambda m: m["optimizers"].pop("d")),
                                                              "no 'd' mapping"),
    # prepared shapes
    "shape truncated (BadZipFile)": lambda c, t: Case(generate(c, t, None, truncated(t / "cut.npz", c["gan"] / "shapes" / "box0.npz", 300)), "cut.npz"),
    "shape quads out of range": lambda c, t: Case(generate(c, t, None, spoiled_shape(c, t / "quads.npz", lambda a: set_item(a, "quads_0", (0, 0), 10**6))),
                                                  "quads_0 has indices outside"),
    "shape neighbours out of range": lambda c, t: Case(
        generate(c, t, None, spoiled_shape(c, t / "nb.npz", lambda a: set_item(a, "neighbors_1", (2, 3), -7))), "neighbors_1"),
    "shape pooling out of range": lambda c, t: Case(generate(c, t, None, spoiled_shape(c, t / "pool.npz", lambda a: set_item(a, "pool_0", 0, 999))),
                                                    "pool_0"),
    "shape metadata a list": lambda c, t: Case(
        generate(c, t, None, spoiled_shape(c, t / "listmeta.npz", lambda a: a.update(metadata=np.asarray("[1, 2]")))), "listmeta.npz"),
    "shape NaN face features": lambda c, t: Case(
        generate(c, t, None, spoiled_shape(c, t / "nanfeat.npz", lambda a: set_item(a, "face_features", (0, 0), np.nan))), "face_features holds NaN"),
    "shape vertices as text": lambda c, t: Case(
        generate(c, t, None, spoiled_shape(c, t / "text.npz", lambda a: a.update(vertices_0=a["vertices_0"].astype(str)))), "vertices_0"),
    "shape in the training folder damaged": lambda c, t: Case(
        train_gan(c, t, None, spoiled_shape(c, t / "shapes" / "box9.npz", lambda a: set_item(a, "quads_1", (0, 0), -2)).parent), "box9.npz"),
    # meshes
    "mesh with a NaN vertex": lambda c, t: Case(generate(c, t, None, nan_vertex_obj(t / "nan.obj")), "nan.obj: 1 vertex(es) with non-finite"),
    "mesh of random bytes": lambda c, t: Case(generate(c, t, None, write(t / "noise.stl", np.random.default_rng(0).bytes(3000))),
                                              "noise.stl: cannot be read as a mesh (not a valid .stl file)"),
    "mesh of garbage text": lambda c, t: Case(generate(c, t, None, write(t / "junk.obj", b"garbage \x00\xff\xfe\nv 1 2\nf a b c\n")), "junk.obj"),
    "mesh with a vertex at 1e300": lambda c, t: Case(generate(c, t, None, write(t / "huge.obj", "v 0 0 0\nv 1e300 0 0\nv 0 1 0\nv 0 0 1\n"
                                                                                "f 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")),
                                                     "huge.obj: the mesh's coordinates are too large"),
    "degenerate mesh prepared on the fly": lambda c, t: Case(transfer(c, t, None, "--mesh", str(write(t / "flat.obj", "v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n"))),
                                                             "flat.obj: the mesh has a zero-size bounding box"),
    # paths
    "--out a file (prepare shapes)": lambda c, t: Case(["prepare", "shapes", "--input", str(nan_vertex_obj(t / "m.obj")), "--out",
                                                       str(write(t / "out" / "a_file", "x"))], "a_file: --out is a file"),
    "--out a file (generate)": lambda c, t: Case(generate(c, t, None, None, "--out", str(write(t / "out" / "a_file", "x"))),
                                                 "a_file: --out is a file"),
    "prepare synthetic --shapes beyond reason": lambda c, t: Case(["prepare", "synthetic", "--out", str(t / "out" / "w"),
                                                                   "--shapes", "99999999999999999999"], "--shapes must be at most"),
    # images
    "photo 1x1": lambda c, t: Case(transfer(c, t, png(t / "tiny.png", (1, 1))), "tiny.png: the photo is 1x1"),
    "photo truncated": lambda c, t: Case(transfer(c, t, truncated(t / "cut.png", c["root"] / "query.png", 60)), "cut.png"),
    "photo not an image": lambda c, t: Case(transfer(c, t, write(t / "fake.png", b"GIF89a not really")), "fake.png"),
    "training photo truncated": lambda c, t: Case(
        train_gan(c, t, None, None, truncated(t / "photos" / "0.png", c["gan"] / "photos" / "0.png", 50).parent), "0.png"),
    "evaluate --pairs image truncated": lambda c, t: Case(
        evaluate(t, *pair_folders(t, truncated(t / "a.png", png(t / "src.png"), 40)), "--pairs"), "a.png"),
    "evaluate --pairs mask of another size": lambda c, t: Case(
        evaluate(t, *pair_folders(t), "--pairs", "--masks", str(png(t / "m" / "a.png", (10, 10), "L").parent)), "m/a.png: mask size (10, 10)"),
    "prepare images --input a file": lambda c, t: Case(["prepare", "images", "--input", str(png(t / "p.png")), "--out", str(t / "out" / "p")],
                                                       "p.png: is a file"),
    "evaluate sets image not an image": lambda c, t: Case(
        evaluate(t, *pair_folders(t, write(t / "a.png", b"\x89PNG\r\n\x1a\n garbage"))), "a.png"),
}


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()} if folder.exists() else {}


def check_case(case: Case, out: Path, capsys) -> str:
    """Run ``case``; assert the exit status, one error line naming the problem, and an untouched --out."""
    write(out / "mine.txt", "a file of the user's")
    before = _snapshot(out)
    capsys.readouterr()
    code = main(case.argv)
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if line.startswith("mesh2tex: error:")]
    assert code == case.code, err
    assert "Traceback" not in err
    assert len(errors) == 1, err
    assert case.names in errors[0], errors[0]
    assert _snapshot(out) == before, "--out changed"
    return errors[0]


@pytest.mark.parametrize("name", list(CASES))
def test_bad_input_is_one_line_error_and_changes_nothing(name, ctx, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("MESH2TEX_PROGRESS", "0")
    case = CASES[name](ctx, tmp_path)
    check_case(case, tmp_path / "out", capsys)


# ------------------------------------------------------------------------ cases that need a patch
def test_decompression_bombs_are_one_line_errors(ctx, tmp_path, capsys, monkeypatch):
    """PIL refuses images over twice MAX_IMAGE_PIXELS; a smaller limit stands in for a 1 GB bomb."""
    monkeypatch.setenv("MESH2TEX_PROGRESS", "0")
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 100)
    bomb = png(tmp_path / "bomb.png", (48, 48))
    check_case(Case(transfer(ctx, tmp_path / "t", bomb), "bomb.png: image too large"), tmp_path / "t" / "out", capsys)
    renders, images = pair_folders(tmp_path / "e")
    check_case(Case(evaluate(tmp_path / "e", renders, images, "--pairs"), "a.png: image too large"), tmp_path / "e" / "out", capsys)
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 10**8)
    photos = tmp_path / "photos"
    png(photos / "0.png", (24, 24), "RGBA")
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 100)
    check_case(Case(train_gan(ctx, tmp_path / "g", None, None, photos), "0.png: image too large"), tmp_path / "g" / "out", capsys)


def test_a_shape_that_would_inflate_beyond_the_cap_is_refused_before_reading(ctx, tmp_path, capsys, monkeypatch):
    from mesh2tex.geometry import prepared

    monkeypatch.setattr(prepared, "MAX_UNCOMPRESSED_BYTES", 1000)  # stands in for a 1 MB file inflating to 1.2 GB
    check_case(Case(generate(ctx, tmp_path), "box0.npz: not a valid prepared shape (ValueError: its arrays would take"), tmp_path / "out", capsys)


# ----------------------------------------------------------------------- data loss: the output guard
@pytest.mark.parametrize("command, existing", [("generate", "seed0.glb"), ("generate", "seed0_view0.png"),
                                               ("transfer", "comparison.png"), ("transfer", "textured.glb"), ("evaluate", "metrics.md")])
def test_files_already_in_out_are_kept_without_overwrite(command, existing, ctx, tmp_path, capsys):
    out = tmp_path / "out"
    write(out / existing, "the user's own file")
    argv = {"generate": lambda: generate(ctx, tmp_path), "transfer": lambda: transfer(ctx, tmp_path),
            "evaluate": lambda: evaluate(tmp_path, *pair_folders(tmp_path), "--pairs")}[command]()
    line = check_case(Case(argv, f"already holds {existing}"), out, capsys)
    assert "--overwrite" in line


def test_infer_nca_keeps_files_already_in_out(tmp_path, capsys):
    from test_train_nca import TINY_NCA

    from mesh2tex.synthetic.exemplars import exemplar_image

    Image.fromarray(exemplar_image("stripes", 48)).save(tmp_path / "stripes.png")
    write(tmp_path / "tiny.yaml", yaml.safe_dump({**TINY_NCA, "iters": 1}))
    assert main(["train", "nca", "--exemplar", str(tmp_path / "stripes.png"), "--out", str(tmp_path / "run"),
                 "--config", str(tmp_path / "tiny.yaml"), "--device", "cpu"]) == 0
    out = tmp_path / "out"
    write(out / "view_0.png", "the user's own file")
    check_case(Case(["infer", "nca", "--checkpoint", str(tmp_path / "run" / "model.safetensors"), "--mesh", "sphere:2", "--out", str(out),
                     "--steps", "2", "--views", "1", "--resolution", "32", "--texture-size", "32", "--frames", "0", "--device", "cpu"],
                    "already holds view_0.png"), out, capsys)


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


@pytest.mark.parametrize("change, names", [({"lr": -1.0}, "lr must be positive"), ({"camera": {"distance": 0}}, "distance must be positive"),
                                           ({"nca": {"channels": 100000}}, "channels must be at most"),
                                           ({"checkpoint_every": -3}, "checkpoint_every must be at least 0"),
                                           ({"steps_min": 5, "steps_max": 2}, "steps_max 2 is below steps_min 5"),
                                           ({"nca": {"readout": "mlp"}}, "readout must be one of")])
def test_train_nca_config_values_out_of_range_are_named(change, names, tmp_path, capsys):
    from mesh2tex.synthetic.exemplars import exemplar_image

    Image.fromarray(exemplar_image("stripes", 48)).save(tmp_path / "stripes.png")
    config = write(tmp_path / "bad.yaml", yaml.safe_dump(change))
    check_case(Case(["train", "nca", "--exemplar", str(tmp_path / "stripes.png"), "--out", str(tmp_path / "out"), "--config", str(config),
                     "--device", "cpu"], names), tmp_path / "out", capsys)
