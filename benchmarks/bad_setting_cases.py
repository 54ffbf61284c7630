"""The bad-input benchmark's cases of bad checkpoints and configs, bad values and bad folders (:mod:`bad_input_cases`
holds its helpers and the bad mesh, shape and image files)."""

from __future__ import annotations

import os
import struct

from bad_input_cases import (
    evaluate,
    generate,
    infer_nca,
    pair_folders,
    png,
    prepare_images,
    prepare_shapes,
    safetensors_bytes,
    train_gan,
    train_nca,
    train_view,
    transfer,
    write,
)


def checkpoint_cases(add) -> None:
    """Bad checkpoints and configs."""
    ckpts = {
        "zero bytes": b"",
        "a header longer than the file": struct.pack("<Q", 10**6) + b"{}",
        "a header of 2^63 bytes": struct.pack("<Q", 2**63),
        "a JSON object, no length": b'{"a": 1}',
        "a header that is a string": safetensors_bytes(b'"hello"'),
        "a tensor past the end of the file": safetensors_bytes(
            {"w": {"dtype": "F32", "shape": [1000], "data_offsets": [0, 4000]}}
        ),
        "a tensor of an unknown dtype": safetensors_bytes(
            {"w": {"dtype": "Q7", "shape": [1], "data_offsets": [0, 4]}}, b"\x00" * 4
        ),
    }
    for name, data in ckpts.items():
        add(
            f"generate --checkpoint: {name}",
            "file",
            lambda fx, d: generate(fx, d, checkpoint=d / "c.safetensors"),
            lambda d, b=data: write(d / "c.safetensors", b),
        )
    add("generate --checkpoint: a PNG", "file", lambda fx, d: generate(fx, d, checkpoint=fx["query.png"]))
    add(
        "generate --checkpoint: a pose checkpoint",
        "file",
        lambda fx, d: generate(fx, d, checkpoint=fx["pose"] / "checkpoint.safetensors"),
    )
    add(
        "generate --checkpoint: an NCA model",
        "file",
        lambda fx, d: generate(fx, d, checkpoint=fx["nca"] / "model.safetensors"),
    )
    add(
        "infer nca --checkpoint: a GAN checkpoint",
        "file",
        lambda fx, d: infer_nca(fx, d, checkpoint=fx["gan"] / "checkpoint.safetensors"),
    )
    add(
        "transfer --noc-checkpoint: a GAN checkpoint",
        "file",
        lambda fx, d: transfer(fx, d, "--noc-checkpoint", str(fx["gan"] / "checkpoint.safetensors")),
    )
    add("train pose --resume: a GAN run", "file", lambda fx, d: train_view(fx, d, "pose", "--resume", str(fx["gan"])))
    add("train nca --resume: a pose run", "file", lambda fx, d: train_nca(fx, d, "--resume", str(fx["pose"])))
    configs = {
        "a YAML list": "- 1\n- 2\n",
        "a scalar": "42\n",
        "a tab-indented mapping": "iters: 3\n\tbatch: 2\n",
        "a python tag": "!!python/object/apply:os.system ['true']\n",
        "an unknown key": "iterations: 3\n",
        "sample_every a word": "sample_every: ten\n",
        "UTF-8 BOM then binary": b"\xef\xbb\xbf\x00\x01\x02\xff",
        "duplicate anchors": "a: &x 1\nb: &x 2\nc: *x\nd: *y\n",
        "a 5 MB comment": "#" + "x" * 5_000_000 + "\n",
        "1000 nested lists": "[" * 1000 + "]" * 1000 + "\n",
    }
    for name, text in configs.items():
        add(
            f"train gan --config: {name}",
            "file",
            lambda fx, d: train_gan(fx, d) + ["--config", str(d / "c.yaml")],
            lambda d, t=text: write(d / "c.yaml", t),
        )
    add(
        "infer generate --config: a folder",
        "file",
        lambda fx, d: generate(fx, d, "--config", str(d / "c.yaml")),
        lambda d: (d / "c.yaml").mkdir(),
    )
    add(
        "evaluate --world: index.json truncated",
        "file",
        lambda fx, d: [
            "evaluate",
            "--generation",
            "--world",
            str(d / "w"),
            "--shapes",
            str(fx["shapes"]),
            "--checkpoint",
            str(fx["gan"] / "checkpoint.safetensors"),
            "--out",
            str(d / "out"),
        ],
        lambda d: write(d / "w" / "index.json", '{"format": '),
    )


def value_cases(add) -> None:
    """Bad values of options and config fields."""
    values = [
        ("generate --elevation 95", lambda fx, d: generate(fx, d, "--elevation", "95")),
        ("generate --elevation -91", lambda fx, d: generate(fx, d, "--elevation", "-91")),
        ("generate --truncation -5", lambda fx, d: generate(fx, d, "--truncation", "-5")),
        ("generate --views 0", lambda fx, d: generate(fx, d, "--views", "0")),
        ("generate --resolution 7", lambda fx, d: generate(fx, d, "--resolution", "7")),
        ("generate --resolution 100000", lambda fx, d: generate(fx, d, "--resolution", "100000")),
        ("generate --texture-size 3", lambda fx, d: generate(fx, d, "--texture-size", "3")),
        ("generate --texture-size 50000", lambda fx, d: generate(fx, d, "--texture-size", "50000")),
        (
            "generate --seeds over 100000 in two ranges",
            lambda fx, d: generate(fx, d, "--seeds", "0-99999,100000-100005"),
        ),
        ("generate --seeds 1--3", lambda fx, d: generate(fx, d, "--seeds", "1--3")),
        ("generate --seeds 1.5", lambda fx, d: generate(fx, d, "--seeds", "1.5")),
        ("generate --faces 3", lambda fx, d: generate(fx, d, "--faces", "3", mesh=fx["box.obj"])),
        ("infer nca --mesh sphere:0", lambda fx, d: infer_nca(fx, d, "--mesh", "sphere:0")),
        ("infer nca --mesh sphere:-3", lambda fx, d: infer_nca(fx, d, "--mesh", "sphere:-3")),
        ("infer nca --mesh sphere:abc", lambda fx, d: infer_nca(fx, d, "--mesh", "sphere:abc")),
        ("infer nca --mesh cube:3", lambda fx, d: infer_nca(fx, d, "--mesh", "cube:3")),
        ("generate --device cuda:7", lambda fx, d: generate(fx, d, "--device", "cuda:7")),
        ("transfer --pose abc", lambda fx, d: transfer(fx, d, "--pose", "abc")),
        ("transfer --pose 30", lambda fx, d: transfer(fx, d, "--pose", "30")),
        ("transfer --pose 30,20,10", lambda fx, d: transfer(fx, d, "--pose", "30,20,10")),
        ("transfer --pose nan,20", lambda fx, d: transfer(fx, d, "--pose", "nan,20")),
        ("transfer --resolution 8", lambda fx, d: transfer(fx, d, "--resolution", "8")),
        ("transfer --latent-iters -1", lambda fx, d: transfer(fx, d, "--latent-iters", "-1")),
        ("transfer --refine-iters 10^12", lambda fx, d: transfer(fx, d, "--refine-iters", "1000000000000")),
        ("infer nca --steps 10^9", lambda fx, d: infer_nca(fx, d, "--steps", "1000000000")),
        ("train gan --iters -1", lambda fx, d: train_gan(fx, d, "--iters", "-1")),
        ("train gan --batch 0", lambda fx, d: train_gan(fx, d, "--batch", "0")),
        ("train gan --views 100000", lambda fx, d: train_gan(fx, d, "--views", "100000")),
        ("train gan --resolution 12", lambda fx, d: train_gan(fx, d, "--resolution", "12")),
        ("train pose --samples 0", lambda fx, d: train_view(fx, d, "pose", "--samples", "0")),
        ("train noc --batch 100000", lambda fx, d: train_view(fx, d, "noc", "--batch", "100000")),
        ("train nca --steps 5,3,1", lambda fx, d: train_nca(fx, d, "--steps", "5,3,1")),
        ("train nca --steps 0,0", lambda fx, d: train_nca(fx, d, "--steps", "0,0")),
        ("train nca --mesh sphere:100000", lambda fx, d: train_nca(fx, d, "--mesh", "sphere:100000")),
        (
            "infer nca --graft-mask 10**400",
            lambda fx, d: infer_nca(fx, d, "--graft", str(fx["nca"] / "model.safetensors"), "--graft-mask", "10**400"),
        ),
        (
            "infer nca --graft-mask 1/0",
            lambda fx, d: infer_nca(fx, d, "--graft", str(fx["nca"] / "model.safetensors"), "--graft-mask", "1/0"),
        ),
        ("infer nca --regrow a 5000-term sum", lambda fx, d: infer_nca(fx, d, "--regrow", "x" + "+x" * 5000)),
        ("infer nca --angle 1e308", lambda fx, d: infer_nca(fx, d, "--angle", "1e308")),
        ("infer nca --subdivide 50", lambda fx, d: infer_nca(fx, d, "--subdivide", "50")),
        ("prepare shapes --faces 3", lambda fx, d: prepare_shapes(fx, d, "--faces", "3", source=fx["box.obj"])),
        ("prepare shapes --levels 0", lambda fx, d: prepare_shapes(fx, d, "--levels", "0", source=fx["box.obj"])),
        (
            "prepare shapes --max-seconds -1",
            lambda fx, d: prepare_shapes(fx, d, "--max-seconds", "-1", source=fx["box.obj"]),
        ),
        ("prepare images --size 7", lambda fx, d: prepare_images(fx, d, "--size", "7", source=fx["photos"])),
        (
            "prepare synthetic --shapes 0",
            lambda fx, d: ["prepare", "synthetic", "--out", str(d / "out"), "--shapes", "0"],
        ),
        (
            "prepare synthetic --query-shapes 3 of 3",
            lambda fx, d: ["prepare", "synthetic", "--out", str(d / "out"), "--shapes", "3", "--query-shapes", "3"],
        ),
        (
            "prepare synthetic --elevation 50 10",
            lambda fx, d: ["prepare", "synthetic", "--out", str(d / "out"), "--elevation", "50", "10"],
        ),
        (
            "prepare synthetic --elevation 0 100",
            lambda fx, d: ["prepare", "synthetic", "--out", str(d / "out"), "--elevation", "0", "100"],
        ),
        ("evaluate --resolution 15", lambda fx, d: evaluate(fx, d, "--resolution", "15")),
        (
            "evaluate --generation --latents 1",
            lambda fx, d: [
                "evaluate",
                "--generation",
                "--world",
                str(fx["world"]),
                "--shapes",
                str(fx["shapes"]),
                "--checkpoint",
                str(fx["gan"] / "checkpoint.safetensors"),
                "--out",
                str(d / "out"),
                "--latents",
                "1",
            ],
        ),
    ]
    for name, argv in values:
        add(name, "value", argv, (lambda d: pair_folders(d)) if name.startswith("evaluate --resolution") else None)


def folder_cases(add) -> None:
    """Bad folders: missing, empty, mixed, or --out where it must not be."""
    add(
        "--out below a file",
        "folder",
        lambda fx, d: generate(fx, d) + ["--out", str(d / "f" / "sub")],
        lambda d: write(d / "f", "x"),
    )
    add(
        "--out a dangling link",
        "folder",
        lambda fx, d: generate(fx, d) + ["--out", str(d / "link")],
        lambda d: os.symlink(d / "nowhere", d / "link"),
    )
    add("--out a name of 300 characters", "folder", lambda fx, d: generate(fx, d) + ["--out", str(d / ("n" * 300))])
    add("--out /dev/null", "folder", lambda fx, d: generate(fx, d) + ["--out", "/dev/null"])
    add(
        "--out holds the user's seed0.glb",
        "folder",
        lambda fx, d: generate(fx, d),
        lambda d: write(d / "out" / "seed0.glb", "mine"),
        keep=("seed0.glb",),
    )
    add(
        "--out holds the user's report.json (transfer)",
        "folder",
        lambda fx, d: transfer(fx, d),
        lambda d: write(d / "out" / "report.json", "{}"),
        keep=("report.json",),
    )
    add(
        "--out holds the user's config.yaml (train pose)",
        "folder",
        lambda fx, d: train_view(fx, d, "pose"),
        lambda d: write(d / "out" / "config.yaml", "mine: 1\n"),
        keep=("config.yaml",),
    )
    add(
        "--out holds the user's config.yaml (train nca)",
        "folder",
        lambda fx, d: train_nca(fx, d),
        lambda d: write(d / "out" / "config.yaml", "mine: 1\n"),
        keep=("config.yaml",),
    )
    add(
        "--out holds the user's metrics.json (evaluate)",
        "folder",
        lambda fx, d: evaluate(fx, d),
        lambda d: (pair_folders(d), write(d / "out" / "metrics.json", "{}")),
        keep=("metrics.json",),
    )
    add(
        "--out holds the user's images/a.png (prepare images)",
        "folder",
        lambda fx, d: prepare_images(fx, d),
        lambda d: (png(d / "in" / "a.png"), png(d / "out" / "images" / "a.png", (8, 8))),
        keep=("images/a.png",),
    )
    add(
        "--out holds the user's view_0.png (infer nca)",
        "folder",
        lambda fx, d: infer_nca(fx, d),
        lambda d: png(d / "out" / "view_0.png"),
        keep=("view_0.png",),
    )
    add(
        "--out holds the user's index.json (synthetic)",
        "folder",
        lambda fx, d: ["prepare", "synthetic", "--out", str(d / "out"), "--shapes", "2"],
        lambda d: write(d / "out" / "index.json", '{"mine": 1}'),
        keep=("index.json",),
    )
    add(
        "--out is --shapes (train gan into its input)",
        "folder",
        lambda fx, d: train_gan(fx, d, shapes=d / "out"),
        lambda d: write(d / "out" / "a.npz", "x"),
    )
    add(
        "--images an empty folder",
        "folder",
        lambda fx, d: train_gan(fx, d, images=d / "p"),
        lambda d: (d / "p").mkdir(),
    )
    add(
        "--images only sub-folders",
        "folder",
        lambda fx, d: train_gan(fx, d, images=d / "p"),
        lambda d: png(d / "p" / "x" / "y" / "a.png"),
    )
    add(
        "--shapes an empty folder",
        "folder",
        lambda fx, d: train_view(fx, d, "noc", shapes=d / "s"),
        lambda d: (d / "s").mkdir(),
    )
    add("--shapes a mesh file", "folder", lambda fx, d: train_gan(fx, d, shapes=fx["box.obj"]))
    add(
        "prepare shapes --input an empty folder",
        "folder",
        lambda fx, d: prepare_shapes(fx, d),
        lambda d: (d / "in").mkdir(),
    )
    add(
        "prepare shapes --input only a dangling link",
        "folder",
        lambda fx, d: prepare_shapes(fx, d),
        lambda d: ((d / "in").mkdir(), os.symlink(d / "gone.obj", d / "in" / "a.obj")),
    )
    add(
        "prepare images --input holds no image",
        "folder",
        lambda fx, d: prepare_images(fx, d),
        lambda d: write(d / "in" / "a.txt", "x"),
    )
    add(
        "prepare images --masks a file",
        "folder",
        lambda fx, d: prepare_images(fx, d, "--masks", str(d / "m.png")),
        lambda d: (png(d / "in" / "a.png"), png(d / "m.png")),
    )
    add(
        "evaluate --renders an empty folder",
        "folder",
        lambda fx, d: evaluate(fx, d),
        lambda d: ((d / "r").mkdir(), png(d / "i" / "a.png")),
    )
    add(
        "evaluate --pairs no image of a render's name",
        "folder",
        lambda fx, d: evaluate(fx, d, "--pairs"),
        lambda d: (png(d / "r" / "a.png"), png(d / "i" / "b.png")),
    )
    add(
        "evaluate --generation --world not a world",
        "folder",
        lambda fx, d: [
            "evaluate",
            "--generation",
            "--world",
            str(fx["shapes"]),
            "--shapes",
            str(fx["shapes"]),
            "--checkpoint",
            str(fx["gan"] / "checkpoint.safetensors"),
            "--out",
            str(d / "out"),
        ],
    )
    add(
        "evaluate --generation --shapes lacks the world's shapes",
        "folder",
        lambda fx, d: [
            "evaluate",
            "--generation",
            "--world",
            str(fx["world"]),
            "--shapes",
            str(fx["shapes"]),
            "--checkpoint",
            str(fx["gan"] / "checkpoint.safetensors"),
            "--out",
            str(d / "out"),
        ],
    )
    add(
        "train gan --resume a run folder without a checkpoint",
        "folder",
        lambda fx, d: train_gan(fx, d, "--resume", str(d / "run")),
        lambda d: write(d / "run" / "config.yaml", "iters: 5\n"),
    )
    add(
        "train noc --resume and --overwrite",
        "folder",
        lambda fx, d: train_view(fx, d, "noc", "--resume", "--overwrite"),
    )
    add(
        "infer nca --out is the model file",
        "folder",
        lambda fx, d: infer_nca(fx, d) + ["--out", str(fx["nca"] / "model.safetensors")],
    )
