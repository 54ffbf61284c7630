"""The bad-input suite: every case is one command a user could type with one bad input.

Each case asserts exit status 2, exactly one ``mesh2tex: error:`` line on stderr that names the bad
file or field, no traceback (an exception escaping ``main`` fails the test with one), and that the
files already in ``--out`` are unchanged and nothing was added there. docs/reliability.md lists the
cases; run them with ``pytest tests/test_bad_inputs.py``.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from bad_input_helpers import (
    Case,
    check_case,
    crafted_resume,
    evaluate,
    gan_config,
    generate,
    make_ctx,
    mesh2tex_header,
    nan_vertex_obj,
    nan_weights,
    pair_folders,
    png,
    resume_with_meta,
    safetensors,
    set_item,
    spoiled_shape,
    train_gan,
    transfer,
    truncated,
    write,
)
from conftest import TINY_GAN


@pytest.fixture(scope="module")
def ctx(tiny_gan, tmp_path_factory):
    return make_ctx(tiny_gan, tmp_path_factory.mktemp("bad_inputs"))


CASES = {
    # configs: types, ranges, encodings (train gan reads its config before any data)
    "config not UTF-8": lambda c, t: Case(
        train_gan(c, t, write(t / "latin1.yaml", "iters: 3 # caf\xe9\n".encode("latin-1"))), "latin1.yaml: not UTF-8"
    ),
    "config lr a non-numeric string": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", **{"optim.lr_field": "fast"})), "optim.lr_field"
    ),
    "config list element of the wrong type": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", **{"generator.encoder_channels": [8, "wide", 8]})),
        "generator.encoder_channels[1]",
    ),
    "config log_every 0": lambda c, t: Case(train_gan(c, t, gan_config(t / "c.yaml", log_every=0)), "log_every"),
    "config sample_shapes 0": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", sample_shapes=0)), "sample_shapes"
    ),
    "config checkpoint_every -3": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", checkpoint_every=-3)), "checkpoint_every"
    ),
    "config channel_base negative": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", **{"discriminator.channel_base": -64})), "discriminator: channel_base"
    ),
    "config channel_base too small for the resolution": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", **{"discriminator.channel_base": 8})),
        "channel_base 8 is too small for resolution 16",
    ),
    "config 100000 channels": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", **{"generator.synthesis_channels": [100000, 8, 8]})),
        "synthesis_channels",
    ),
    "config camera.distance a word": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", **{"camera.distance": "far"})), "camera.distance"
    ),
    "config camera.distance 0": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", **{"camera.distance": 0})), "distance must be positive"
    ),
    "config negative learning rate": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", **{"optim.lr_generator": -1e-4})), "lr_generator"
    ),
    "config a number beyond any float": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", ema_rampup=10**400)), "ema_rampup: expected a finite number"
    ),
    "config NaN": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", ema_rampup=math.nan)), "ema_rampup: expected a finite number"
    ),
    "config not a mapping below": lambda c, t: Case(
        train_gan(c, t, gan_config(t / "c.yaml", optim=[1, 2])), "'optim' must be a mapping"
    ),
    "transfer config turntable_frames 0": lambda c, t: Case(
        transfer(c, t, None, "--config", str(write(t / "t.yaml", "turntable_frames: 0\n"))), "t.yaml: turntable_frames"
    ),
    "train pose config distance range reversed": lambda c, t: Case(
        [
            "train",
            "pose",
            "--shapes",
            str(c["gan"] / "shapes"),
            "--out",
            str(t / "out"),
            "--device",
            "cpu",
            "--config",
            str(write(t / "p.yaml", "data: {distance_min: 3.0, distance_max: 1.0}\n")),
        ],
        "p.yaml.data: distance 3.0..1.0",
    ),
    # flags
    "generate --truncation nan": lambda c, t: Case(
        generate(c, t, None, None, "--truncation", "nan"), "truncation: expected a finite number"
    ),
    "generate --seeds beyond 64 bits": lambda c, t: Case(
        generate(c, t, None, None, "--seeds", "99999999999999999999"), "seeds[0]: 99999999999999999999 is out of range"
    ),
    "train gan --seed beyond 64 bits": lambda c, t: Case(
        train_gan(c, t, None, None, None, "--seed", "-99999999999999999999"),
        "seed: -99999999999999999999 is out of range",
    ),
    "generate --elevation inf in a config": lambda c, t: Case(
        generate(c, t, None, None, "--config", str(write(t / "g.yaml", "elevation: .inf\n"))), "g.yaml.elevation"
    ),
    "transfer --pose elevation 1000": lambda c, t: Case(transfer(c, t, None, "--pose", "30,1000"), "--pose"),
    # checkpoints
    "checkpoint header a JSON list": lambda c, t: Case(
        generate(c, t, safetensors(t / "list.safetensors", b"[1, 2, 3]")), "list.safetensors"
    ),
    "checkpoint header nested 100000 deep": lambda c, t: Case(
        generate(c, t, safetensors(t / "deep.safetensors", b"[" * 100000 + b"]" * 100000)), "deep.safetensors"
    ),
    "checkpoint metadata nested 100000 deep": lambda c, t: Case(
        generate(
            c,
            t,
            safetensors(
                t / "deep2.safetensors",
                json.dumps({"__metadata__": {"mesh2tex": "[" * 100000 + "]" * 100000}}).encode(),
            ),
        ),
        "deep2.safetensors",
    ),
    "checkpoint __metadata__ a string": lambda c, t: Case(
        generate(c, t, safetensors(t / "meta.safetensors", b'{"__metadata__": "mesh2tex"}')), "meta.safetensors"
    ),
    "checkpoint without meta": lambda c, t: Case(
        generate(c, t, mesh2tex_header(t / "nometa.safetensors", {"format": 1, "kind": "gan"})), "nometa.safetensors"
    ),
    "checkpoint meta without a generator config": lambda c, t: Case(
        generate(c, t, mesh2tex_header(t / "nogen.safetensors", {"format": 1, "kind": "gan", "meta": {}})),
        "nogen.safetensors",
    ),
    "checkpoint truncated": lambda c, t: Case(
        generate(c, t, truncated(t / "cut.safetensors", c["gan"] / "run" / "checkpoint.safetensors", 5000)),
        "cut.safetensors",
    ),
    "checkpoint asking for 100000 channels": lambda c, t: Case(
        generate(
            c,
            t,
            mesh2tex_header(
                t / "wide.safetensors",
                {
                    "format": 1,
                    "kind": "gan",
                    "meta": {"generator_config": {**TINY_GAN["generator"], "synthesis_channels": [100000, 8, 8]}},
                },
            ),
        ),
        "wide.safetensors",
    ),
    "checkpoint with NaN weights": lambda c, t: Case(
        generate(c, t, nan_weights(c, t / "nan.safetensors")), "nan.safetensors: the generator's colours"
    ),
    "resume from a checkpoint with a crafted header": lambda c, t: Case(
        crafted_resume(c, t), "out/checkpoint.safetensors"
    ),
    "resume with RNG states of another form": lambda c, t: Case(
        resume_with_meta(c, t, lambda m: m.update(rng=[{"torch": 7}])), "RNG states of another form"
    ),
    "resume with optimizer states missing": lambda c, t: Case(
        resume_with_meta(c, t, lambda m: m["optimizers"].pop("d")), "no 'd' mapping"
    ),
    # prepared shapes
    "shape truncated (BadZipFile)": lambda c, t: Case(
        generate(c, t, None, truncated(t / "cut.npz", c["gan"] / "shapes" / "box0.npz", 300)), "cut.npz"
    ),
    "shape quads out of range": lambda c, t: Case(
        generate(c, t, None, spoiled_shape(c, t / "quads.npz", lambda a: set_item(a, "quads_0", (0, 0), 10**6))),
        "quads_0 has indices outside",
    ),
    "shape neighbours out of range": lambda c, t: Case(
        generate(c, t, None, spoiled_shape(c, t / "nb.npz", lambda a: set_item(a, "neighbors_1", (2, 3), -7))),
        "neighbors_1",
    ),
    "shape pooling out of range": lambda c, t: Case(
        generate(c, t, None, spoiled_shape(c, t / "pool.npz", lambda a: set_item(a, "pool_0", 0, 999))), "pool_0"
    ),
    "shape metadata a list": lambda c, t: Case(
        generate(c, t, None, spoiled_shape(c, t / "listmeta.npz", lambda a: a.update(metadata=np.asarray("[1, 2]")))),
        "listmeta.npz",
    ),
    "shape NaN face features": lambda c, t: Case(
        generate(
            c, t, None, spoiled_shape(c, t / "nanfeat.npz", lambda a: set_item(a, "face_features", (0, 0), np.nan))
        ),
        "face_features holds NaN",
    ),
    "shape vertices as text": lambda c, t: Case(
        generate(
            c, t, None, spoiled_shape(c, t / "text.npz", lambda a: a.update(vertices_0=a["vertices_0"].astype(str)))
        ),
        "vertices_0",
    ),
    "shape in the training folder damaged": lambda c, t: Case(
        train_gan(
            c, t, None, spoiled_shape(c, t / "shapes" / "box9.npz", lambda a: set_item(a, "quads_1", (0, 0), -2)).parent
        ),
        "box9.npz",
    ),
    # meshes
    "mesh with a NaN vertex": lambda c, t: Case(
        generate(c, t, None, nan_vertex_obj(t / "nan.obj")), "nan.obj: 1 vertex(es) with non-finite"
    ),
    "mesh of random bytes": lambda c, t: Case(
        generate(c, t, None, write(t / "noise.stl", np.random.default_rng(0).bytes(3000))),
        "noise.stl: cannot be read as a mesh (not a valid .stl file)",
    ),
    "mesh of garbage text": lambda c, t: Case(
        generate(c, t, None, write(t / "junk.obj", b"garbage \x00\xff\xfe\nv 1 2\nf a b c\n")), "junk.obj"
    ),
    "mesh with a vertex at 1e300": lambda c, t: Case(
        generate(
            c,
            t,
            None,
            write(t / "huge.obj", "v 0 0 0\nv 1e300 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n"),
        ),
        "huge.obj: the mesh's coordinates are too large",
    ),
    "degenerate mesh prepared on the fly": lambda c, t: Case(
        transfer(c, t, None, "--mesh", str(write(t / "flat.obj", "v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n"))),
        "flat.obj: the mesh has a zero-size bounding box",
    ),
    # paths
    "--out a file (prepare shapes)": lambda c, t: Case(
        [
            "prepare",
            "shapes",
            "--input",
            str(nan_vertex_obj(t / "m.obj")),
            "--out",
            str(write(t / "out" / "a_file", "x")),
        ],
        "a_file: --out is a file",
    ),
    "--out a file (generate)": lambda c, t: Case(
        generate(c, t, None, None, "--out", str(write(t / "out" / "a_file", "x"))), "a_file: --out is a file"
    ),
    "prepare synthetic --shapes beyond reason": lambda c, t: Case(
        ["prepare", "synthetic", "--out", str(t / "out" / "w"), "--shapes", "99999999999999999999"],
        "--shapes must be at most",
    ),
    # images
    "photo 1x1": lambda c, t: Case(transfer(c, t, png(t / "tiny.png", (1, 1))), "tiny.png: the photo is 1x1"),
    "photo truncated": lambda c, t: Case(
        transfer(c, t, truncated(t / "cut.png", c["root"] / "query.png", 60)), "cut.png"
    ),
    "photo not an image": lambda c, t: Case(transfer(c, t, write(t / "fake.png", b"GIF89a not really")), "fake.png"),
    "training photo truncated": lambda c, t: Case(
        train_gan(c, t, None, None, truncated(t / "photos" / "0.png", c["gan"] / "photos" / "0.png", 50).parent),
        "0.png",
    ),
    "evaluate --pairs image truncated": lambda c, t: Case(
        evaluate(t, *pair_folders(t, truncated(t / "a.png", png(t / "src.png"), 40)), "--pairs"), "a.png"
    ),
    "evaluate --pairs mask of another size": lambda c, t: Case(
        evaluate(t, *pair_folders(t), "--pairs", "--masks", str(png(t / "m" / "a.png", (10, 10), "L").parent)),
        "m/a.png: mask size (10, 10)",
    ),
    "prepare images --input a file": lambda c, t: Case(
        ["prepare", "images", "--input", str(png(t / "p.png")), "--out", str(t / "out" / "p")], "p.png: is a file"
    ),
    "evaluate sets image not an image": lambda c, t: Case(
        evaluate(t, *pair_folders(t, write(t / "a.png", b"\x89PNG\r\n\x1a\n garbage"))), "a.png"
    ),
}


@pytest.mark.parametrize("name", list(CASES))
def test_bad_input_is_one_line_error_and_changes_nothing(name, ctx, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("MESH2TEX_PROGRESS", "0")
    case = CASES[name](ctx, tmp_path)
    check_case(case, tmp_path / "out", capsys)
