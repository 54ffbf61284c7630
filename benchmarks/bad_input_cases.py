"""The cases of ``benchmarks/bad_inputs.py``: each a command line (built on the fixtures it makes once)
and what it must do with a bad file, value or folder, with the helpers that write the damaged files."""

from __future__ import annotations

import json
import os
import struct
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

BOX_OBJ = (
    "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
    "f 1 2 3 4\nf 5 8 7 6\nf 1 5 6 2\nf 2 6 7 3\nf 3 7 8 4\nf 4 8 5 1\n"
)


@dataclass
class Case:
    name: str
    kind: str  # "file", "value" or "folder"
    argv: Callable[[dict, Path], list[str]]  # (fixtures, case folder) -> arguments; the case's --out is folder/"out"
    setup: Callable[[Path], None] | None = None  # makes the bad input in the case folder
    accept: str | None = None  # an awkward input that is accepted: the warning or note text that must be printed
    keep: tuple[str, ...] = ()  # files the case puts in out/ at names the command writes (they must be kept)


def write(path: Path, data: bytes | str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    (path.write_bytes if isinstance(data, bytes) else path.write_text)(data)
    return path


def png(path: Path, size=(32, 32), mode="RGB", value=128) -> Path:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.new(mode, size, value).save(path)
    return path


# The fixed flags of each command, written as one string each: small and fast settings on the CPU.
GENERATE_FLAGS = "--seeds 0 --views 1 --resolution 16 --texture-size 32 --device cpu".split()
TRANSFER_FLAGS = "--pose 30,20 --no-noc --resolution 64 --latent-iters 1 --refine-iters 0 --device cpu".split()
TRAIN_GAN_FLAGS = "--iters 1 --batch 2 --views 2 --resolution 16 --device cpu".split()
TRAIN_VIEW_FLAGS = "--iters 1 --samples 8 --resolution 32 --batch 4 --device cpu".split()
INFER_NCA_FLAGS = "--views 1 --resolution 32 --texture-size 32 --frames 0 --device cpu".split()


def generate(fx, d, *extra, mesh=None, checkpoint=None):
    checkpoint = checkpoint or fx["gan"] / "checkpoint.safetensors"
    mesh = mesh or fx["shapes"] / "box0.npz"
    return [
        "infer",
        "generate",
        "--checkpoint",
        str(checkpoint),
        "--mesh",
        str(mesh),
        "--out",
        str(d / "out"),
        *GENERATE_FLAGS,
        *extra,
    ]


def transfer(fx, d, *extra, image=None, mesh=None, checkpoint=None):
    checkpoint = checkpoint or fx["gan"] / "checkpoint.safetensors"
    mesh, image = mesh or fx["shapes"] / "box0.npz", image or fx["query.png"]
    return [
        "infer",
        "transfer",
        "--checkpoint",
        str(checkpoint),
        "--mesh",
        str(mesh),
        "--image",
        str(image),
        "--out",
        str(d / "out"),
        *TRANSFER_FLAGS,
        *extra,
    ]


def train_gan(fx, d, *extra, shapes=None, images=None):
    shapes, images, config = shapes or fx["shapes"], images or fx["photos"], fx["gan"].parent / "gan.yaml"
    return [
        "train",
        "gan",
        "--shapes",
        str(shapes),
        "--images",
        str(images),
        "--out",
        str(d / "out"),
        "--config",
        str(config),
        *TRAIN_GAN_FLAGS,
        *extra,
    ]


def train_view(fx, d, kind, *extra, shapes=None):
    return ["train", kind, "--shapes", str(shapes or fx["shapes"]), "--out", str(d / "out"), *TRAIN_VIEW_FLAGS, *extra]


def train_nca(fx, d, *extra, exemplar=None):
    exemplar, config = exemplar or fx["exemplar.png"], fx["nca"].parent / "nca.yaml"
    return [
        "train",
        "nca",
        "--exemplar",
        str(exemplar),
        "--out",
        str(d / "out"),
        "--config",
        str(config),
        "--device",
        "cpu",
        *extra,
    ]


def infer_nca(fx, d, *extra, checkpoint=None):
    checkpoint = checkpoint or fx["nca"] / "model.safetensors"
    return ["infer", "nca", "--checkpoint", str(checkpoint), "--out", str(d / "out"), *INFER_NCA_FLAGS, *extra]


def evaluate(fx, d, *extra, renders=None, images=None):
    return [
        "evaluate",
        "--renders",
        str(renders or d / "r"),
        "--images",
        str(images or d / "i"),
        "--out",
        str(d / "out"),
        *extra,
    ]


def prepare_shapes(fx, d, *extra, source=None):
    return [
        "prepare",
        "shapes",
        "--input",
        str(source or d / "in"),
        "--out",
        str(d / "out"),
        "--faces",
        "96",
        "--levels",
        "2",
        *extra,
    ]


def prepare_images(fx, d, *extra, source=None):
    return ["prepare", "images", "--input", str(source or d / "in"), "--out", str(d / "out"), "--size", "16", *extra]


def pair_folders(d: Path, render_size=(32, 32), image_size=(32, 32)) -> None:
    png(d / "r" / "a.png", render_size)
    png(d / "i" / "a.png", image_size)


def safetensors_bytes(header: dict | bytes, payload: bytes = b"") -> bytes:
    raw = header if isinstance(header, bytes) else json.dumps(header).encode()
    return struct.pack("<Q", len(raw)) + raw + payload


def npz(path: Path, **arrays) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **arrays)
    return path


def fifo(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    os.mkfifo(path)
    return path


def cases() -> list[Case]:
    """Every case, in the order the report lists them."""
    from bad_setting_cases import (  # this folder; it imports the helpers above
        checkpoint_cases,
        folder_cases,
        value_cases,
    )

    c: list[Case] = []

    def add(name, kind, argv, setup=None, accept=None, keep=()):
        c.append(Case(name, kind, argv, setup, accept, keep))

    for section in (mesh_cases, shape_cases, image_cases, checkpoint_cases, value_cases, folder_cases):
        section(add)
    return c


def mesh_cases(add) -> None:
    """Bad mesh files given to ``infer generate --mesh``."""
    meshes = {
        "obj empty": ("m.obj", b""),
        "obj vertices only": ("m.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"),
        "obj face index past the end": ("m.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n"),
        "obj negative index past the start": ("m.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -9\n"),
        "obj coordinates words": ("m.obj", "v a b c\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
        "obj one face of two vertices": ("m.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n"),
        "obj all vertices one point": ("m.obj", "v 1 1 1\nv 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\nf 1 3 4\n"),
        "obj UTF-16": ("m.obj", BOX_OBJ.encode("utf-16")),
        "obj NUL bytes": ("m.obj", b"\x00" * 4096),
        "ply header only": ("m.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n"),
        "ply claims a billion vertices": (
            "m.ply",
            "ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\nproperty float x\n"
            "property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n",
        ),
        "ply random bytes": ("m.ply", bytes(np.random.default_rng(1).integers(0, 256, 3000, dtype=np.uint8))),
        "off wrong counts": ("m.off", "OFF\n8 6 0\n0 0 0\n1 0 0\n"),
        "glb random bytes": ("m.glb", b"glTF" + bytes(np.random.default_rng(2).integers(0, 256, 500, dtype=np.uint8))),
        "gltf JSON of something else": ("m.gltf", '{"hello": "world"}'),
        "stl ascii with no facets": ("m.stl", "solid empty\nendsolid empty\n"),
        "stl binary with a huge count": ("m.stl", b"\x00" * 80 + struct.pack("<I", 10**9) + b"\x00" * 50),
        "unknown suffix": ("m.xyz", "1 2 3\n"),
    }
    awkward = {"obj UTF-16": "input mesh, 12 triangles"}  # read as it is meant: the box, all 12 triangles
    for name, (file, data) in meshes.items():
        add(
            f"generate --mesh: {name}",
            "file",
            lambda fx, d, f=file: generate(fx, d, mesh=d / f),
            lambda d, f=file, b=data: write(d / f, b),
            accept=awkward.get(name),
        )
    add(
        "generate --mesh: a folder named .obj",
        "file",
        lambda fx, d: generate(fx, d, mesh=d / "m.obj"),
        lambda d: (d / "m.obj").mkdir(),
    )
    add(
        "generate --mesh: a FIFO named .obj",
        "file",
        lambda fx, d: generate(fx, d, mesh=d / "m.obj"),
        lambda d: fifo(d / "m.obj"),
    )
    add(
        "generate --mesh: a dangling link",
        "file",
        lambda fx, d: generate(fx, d, mesh=d / "m.obj"),
        lambda d: os.symlink(d / "gone.obj", d / "m.obj"),
    )
    add(
        "transfer --mesh: obj vertices only",
        "file",
        lambda fx, d: transfer(fx, d, mesh=d / "m.obj"),
        lambda d: write(d / "m.obj", "v 0 0 0\n"),
    )
    add(
        "infer nca --mesh: obj face index past the end",
        "file",
        lambda fx, d: infer_nca(fx, d, "--mesh", str(d / "m.obj")),
        lambda d: write(d / "m.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n"),
    )
    add(
        "prepare shapes: every input bad",
        "file",
        lambda fx, d: prepare_shapes(fx, d),
        lambda d: (write(d / "in" / "a.obj", ""), write(d / "in" / "b.obj", "v 1 1 1\nf 1 1 1\n")),
    )


def shape_cases(add) -> None:
    """Bad prepared shapes."""
    add(
        "generate --mesh: npz without the hierarchy",
        "file",
        lambda fx, d: generate(fx, d, mesh=d / "s.npz"),
        lambda d: npz(d / "s.npz", a=np.zeros(3)),
    )
    add(
        "generate --mesh: npz holding a pickled object",
        "file",
        lambda fx, d: generate(fx, d, mesh=d / "s.npz"),
        lambda d: np.savez(d / "s.npz", vertices_0=np.array([{"a": 1}], dtype=object)),
    )
    add(
        "generate --mesh: a zip that is not npz",
        "file",
        lambda fx, d: generate(fx, d, mesh=d / "s.npz"),
        lambda d: zipfile.ZipFile(d / "s.npz", "w").writestr("readme.txt", "hello"),
    )
    add(
        "generate --mesh: npz of zero bytes",
        "file",
        lambda fx, d: generate(fx, d, mesh=d / "s.npz"),
        lambda d: write(d / "s.npz", b""),
    )
    add(
        "train gan --shapes: a folder of text named .npz",
        "folder",
        lambda fx, d: train_gan(fx, d, shapes=d / "shapes"),
        lambda d: write(d / "shapes" / "a.npz", "not a zip"),
    )


def image_cases(add) -> None:
    """Bad image files."""
    images = {
        "text named .png": ("q.png", "hello"),
        "PNG signature only": ("q.png", b"\x89PNG\r\n\x1a\n"),
        "JPEG cut after its header": ("q.jpg", b"\xff\xd8\xff\xe0\x00\x10JFIF\x00\x01\x01\x00\x00\x01\x00\x01\x00\x00"),
        "GIF header only": ("q.gif", b"GIF89a"),
        "BMP of zero size": ("q.bmp", b"BM" + b"\x00" * 52),
    }
    for name, (file, data) in images.items():
        add(
            f"transfer --image: {name}",
            "file",
            lambda fx, d, f=file: transfer(fx, d, image=d / f),
            lambda d, f=file, b=data: write(d / f, b),
        )
    add(
        "transfer --image: 3x200 strip",
        "file",
        lambda fx, d: transfer(fx, d, image=d / "q.png"),
        lambda d: png(d / "q.png", (3, 200)),
    )
    add(
        "transfer --image: a PNG declaring 60000x60000",
        "file",
        lambda fx, d: transfer(fx, d, image=d / "q.png"),
        lambda d: write(d / "q.png", big_png_header()),
    )
    add(
        "transfer --image: a folder",
        "file",
        lambda fx, d: transfer(fx, d, image=d / "q.png"),
        lambda d: (d / "q.png").mkdir(),
    )
    add(
        "transfer --image: a FIFO",
        "file",
        lambda fx, d: transfer(fx, d, image=d / "q.png"),
        lambda d: fifo(d / "q.png"),
    )
    add(
        "transfer --image: fully transparent",
        "file",
        lambda fx, d: transfer(fx, d, image=d / "q.png"),
        lambda d: png(d / "q.png", (32, 32), "RGBA", (0, 0, 0, 0)),
    )
    add(
        "transfer --mask: all black",
        "file",
        lambda fx, d: transfer(fx, d, "--mask", str(d / "m.png")),
        lambda d: png(d / "m.png", (48, 48), "L", 0),
    )
    add(
        "transfer --mask: another size",
        "file",
        lambda fx, d: transfer(fx, d, "--mask", str(d / "m.png")),
        lambda d: png(d / "m.png", (20, 20), "L", 255),
    )
    add(
        "train gan --images: a 1x1 photo among them",
        "file",
        lambda fx, d: train_gan(fx, d, images=d / "p"),
        lambda d: (png(d / "p" / "a.png"), png(d / "p" / "b.png", (1, 1))),
    )
    add(
        "train gan --images: all fully transparent",
        "file",
        lambda fx, d: train_gan(fx, d, images=d / "p"),
        lambda d: [png(d / "p" / f"{k}.png", (16, 16), "RGBA", (0, 0, 0, 0)) for k in range(3)],
    )
    add(
        "train gan --images: a float TIFF depth map",
        "file",
        lambda fx, d: train_gan(fx, d, images=d / "p"),
        lambda d: float_tiff(d / "p"),
    )
    add(
        "train gan --images: a mask file holding a photo",
        "file",
        lambda fx, d: train_gan(fx, d, images=d / "p"),
        lambda d: (colour_png(d / "p" / "images" / "a.png"), colour_png(d / "p" / "masks" / "a.png")),
    )
    add(
        "train gan --images: masks/ lacks one",
        "file",
        lambda fx, d: train_gan(fx, d, images=d / "p"),
        lambda d: (
            png(d / "p" / "images" / "a.png"),
            png(d / "p" / "images" / "b.png"),
            png(d / "p" / "masks" / "a.png", mode="L", value=255),
        ),
    )
    add(
        "train nca --exemplar: a text file",
        "file",
        lambda fx, d: train_nca(fx, d, exemplar=d / "e.png"),
        lambda d: write(d / "e.png", "no"),
    )
    add(
        "train nca --exemplar: 2x2 pixels",
        "file",
        lambda fx, d: train_nca(fx, d, exemplar=d / "e.png"),
        lambda d: png(d / "e.png", (2, 2)),
    )
    add(
        "evaluate: a 1x1 image among the set",
        "file",
        lambda fx, d: evaluate(fx, d),
        lambda d: (
            png(d / "r" / "a.png"),
            png(d / "r" / "b.png"),
            png(d / "i" / "a.png"),
            png(d / "i" / "b.png", (1, 1)),
        ),
    )
    add(
        "evaluate --pairs: render and image of other sizes",
        "file",
        lambda fx, d: evaluate(fx, d, "--pairs"),
        lambda d: pair_folders(d, (32, 32), (40, 40)),
    )
    add(
        "evaluate --pairs: an empty mask",
        "file",
        lambda fx, d: evaluate(fx, d, "--pairs", "--masks", str(d / "m")),
        lambda d: (pair_folders(d), png(d / "m" / "a.png", (32, 32), "L", 0)),
    )
    add(
        "prepare images: a 1-bit image",
        "file",
        lambda fx, d: prepare_images(fx, d),
        lambda d: png(d / "in" / "a.png", (32, 32), "1", 1),
    )


def big_png_header() -> bytes:
    """A PNG whose header declares 60000 x 60000 pixels (3.6 G) with almost no data."""
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", 60000, 60000, 8, 2, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(b"\x00" * 100))
        + chunk(b"IEND", b"")
    )


def float_tiff(folder: Path) -> None:
    from PIL import Image

    folder.mkdir(parents=True, exist_ok=True)
    png(folder / "a.png")
    Image.fromarray(np.ones((16, 16), np.float32)).save(folder / "b.tif")
    (folder / "b.tif").rename(folder / "b.png")  # a float image under a photo's name


def colour_png(path: Path) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    rgb = np.zeros((16, 16, 3), np.uint8)
    rgb[..., 0] = np.arange(16)[None] * 16
    rgb[..., 2] = 200
    Image.fromarray(rgb).save(path)


# -------------------------------------------------------------------------------------------- runs
