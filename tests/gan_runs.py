"""A tiny ``train gan`` set-up shared by the GAN training tests: its config, data, command and metrics."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import yaml
from conftest import TINY_GAN
from PIL import Image
from test_faceconv import cube_shape

from mesh2tex.cli import main

TINY = {
    **TINY_GAN,
    "log_every": 1,
    "checkpoint_every": 2,
    "sample_shapes": 2,
    "loss": {"r1_interval": 2, "pl_interval": 2},
    "camera": {"distance": 1.6},
}


def train_args(data, out, *extra, batch: int = 2, config=None) -> list[str]:
    """The words after ``mesh2tex`` of a ``train gan`` run on the tiny set in ``data`` into ``out`` (with
    ``config`` in place of the tiny set's own)."""
    tiny = ["--batch", str(batch), *"--views 2 --resolution 16 --device cpu".split()]
    return [
        "train",
        "gan",
        "--shapes",
        str(data / "shapes"),
        "--images",
        str(data / "photos"),
        "--out",
        str(out),
        "--config",
        str(config or data / "tiny.yaml"),
        *tiny,
        *extra,
    ]


def train(data, out, *extra):
    return main(train_args(data, out, *extra))


def metrics(out):
    return [json.loads(line) for line in (Path(out) / "metrics.jsonl").read_text().splitlines()]


def make_tiny_data(root: Path) -> Path:
    """Three prepared cubes, six photos with masks and the tiny config (``tiny.yaml``) under ``root``."""
    shapes = root / "shapes"
    shapes.mkdir()
    for i in range(3):
        cube_shape(3, seed=i).save(shapes / f"cube{i}.npz")
    rng = np.random.default_rng(0)
    (root / "photos" / "images").mkdir(parents=True)
    (root / "photos" / "masks").mkdir()
    for i in range(6):
        img = np.zeros((24, 24, 3), np.uint8) + rng.integers(0, 255, 3, dtype=np.uint8)
        mask = np.zeros((24, 24), np.uint8)
        mask[5:19, 6:18] = 255
        Image.fromarray(img).save(root / "photos" / "images" / f"{i:03d}.png")
        Image.fromarray(mask).save(root / "photos" / "masks" / f"{i:03d}.png")
    config = root / "tiny.yaml"
    config.write_text(yaml.safe_dump(TINY))
    return root
