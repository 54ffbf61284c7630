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

BOX_OBJ = ("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
           "f 1 2 3 4\nf 5 8 7 6\nf 1 5 6 2\nf 2 6 7 3\nf 3 7 8 4\nf 4 8 5 1\n")


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


def generate(fx, d, *extra, mesh=None, checkpoint=None):
    return ["infer", "generate", "--checkpoint", str(checkpoint or fx["gan"] / "checkpoint.safetensors"), "--mesh", str(mesh or fx["shapes"] / "box0.npz"),
            "--out", str(d / "out"), "--seeds", "0", "--views", "1", "--resolution", "16", "--texture-size", "32", "--device", "cpu", *extra]


def transfer(fx, d, *extra, image=None, mesh=None, checkpoint=None):
    return ["infer", "transfer", "--checkpoint", str(checkpoint or fx["gan"] / "checkpoint.safetensors"), "--mesh", str(mesh or fx["shapes"] / "box0.npz"),
            "--image", str(image or fx["query.png"]), "--pose", "30,20", "--no-noc", "--out", str(d / "out"), "--resolution", "64",
            "--latent-iters", "1", "--refine-iters", "0", "--device", "cpu", *extra]


def train_gan(fx, d, *extra, shapes=None, images=None):
    return ["train", "gan", "--shapes", str(shapes or fx["shapes"]), "--images", str(images or fx["photos"]), "--out", str(d / "out"),
            "--config", str(fx["gan"].parent / "gan.yaml"), "--iters", "1", "--batch", "2", "--views", "2", "--resolution", "16", "--device", "cpu", *extra]


def train_view(fx, d, kind, *extra, shapes=None):
    return ["train", kind, "--shapes", str(shapes or fx["shapes"]), "--out", str(d / "out"), "--iters", "1", "--samples", "8",
            "--resolution", "32", "--batch", "4", "--device", "cpu", *extra]


def train_nca(fx, d, *extra, exemplar=None):
    return ["train", "nca", "--exemplar", str(exemplar or fx["exemplar.png"]), "--out", str(d / "out"), "--config",
            str(fx["nca"].parent / "nca.yaml"), "--device", "cpu", *extra]


def infer_nca(fx, d, *extra, checkpoint=None):
    return ["infer", "nca", "--checkpoint", str(checkpoint or fx["nca"] / "model.safetensors"), "--out", str(d / "out"), "--views", "1",
            "--resolution", "32", "--texture-size", "32", "--frames", "0", "--device", "cpu", *extra]


def evaluate(fx, d, *extra, renders=None, images=None):
    return ["evaluate", "--renders", str(renders or d / "r"), "--images", str(images or d / "i"), "--out", str(d / "out"), *extra]


def prepare_shapes(fx, d, *extra, source=None):
    return ["prepare", "shapes", "--input", str(source or d / "in"), "--out", str(d / "out"), "--faces", "96", "--levels", "2", *extra]


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
    c: list[Case] = []

    def add(name, kind, argv, setup=None, accept=None, keep=()):
        c.append(Case(name, kind, argv, setup, accept, keep))

    # ------------------------------------------------------------------ bad files: meshes
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
        "ply claims a billion vertices": ("m.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\nproperty float x\n"
                                                   "property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"),
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
        add(f"generate --mesh: {name}", "file", lambda fx, d, f=file: generate(fx, d, mesh=d / f), lambda d, f=file, b=data: write(d / f, b),
            accept=awkward.get(name))
    add("generate --mesh: a folder named .obj", "file", lambda fx, d: generate(fx, d, mesh=d / "m.obj"), lambda d: (d / "m.obj").mkdir())
    add("generate --mesh: a FIFO named .obj", "file", lambda fx, d: generate(fx, d, mesh=d / "m.obj"), lambda d: fifo(d / "m.obj"))
    add("generate --mesh: a dangling link", "file", lambda fx, d: generate(fx, d, mesh=d / "m.obj"), lambda d: os.symlink(d / "gone.obj", d / "m.obj"))
    add("transfer --mesh: obj vertices only", "file", lambda fx, d: transfer(fx, d, mesh=d / "m.obj"), lambda d: write(d / "m.obj", "v 0 0 0\n"))
    add("infer nca --mesh: obj face index past the end", "file", lambda fx, d: infer_nca(fx, d, "--mesh", str(d / "m.obj")),
        lambda d: write(d / "m.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n"))
    add("prepare shapes: every input bad", "file", lambda fx, d: prepare_shapes(fx, d),
        lambda d: (write(d / "in" / "a.obj", ""), write(d / "in" / "b.obj", "v 1 1 1\nf 1 1 1\n")))

    # ------------------------------------------------------------------ bad files: prepared shapes
    add("generate --mesh: npz without the hierarchy", "file", lambda fx, d: generate(fx, d, mesh=d / "s.npz"), lambda d: npz(d / "s.npz", a=np.zeros(3)))
    add("generate --mesh: npz holding a pickled object", "file", lambda fx, d: generate(fx, d, mesh=d / "s.npz"),
        lambda d: np.savez(d / "s.npz", vertices_0=np.array([{"a": 1}], dtype=object)))
    add("generate --mesh: a zip that is not npz", "file", lambda fx, d: generate(fx, d, mesh=d / "s.npz"),
        lambda d: zipfile.ZipFile(d / "s.npz", "w").writestr("readme.txt", "hello"))
    add("generate --mesh: npz of zero bytes", "file", lambda fx, d: generate(fx, d, mesh=d / "s.npz"), lambda d: write(d / "s.npz", b""))
    add("train gan --shapes: a folder of text named .npz", "folder", lambda fx, d: train_gan(fx, d, shapes=d / "shapes"),
        lambda d: write(d / "shapes" / "a.npz", "not a zip"))

    # ------------------------------------------------------------------ bad files: images
    images = {
        "text named .png": ("q.png", "hello"),
        "PNG signature only": ("q.png", b"\x89PNG\r\n\x1a\n"),
        "JPEG cut after its header": ("q.jpg", b"\xff\xd8\xff\xe0\x00\x10JFIF\x00\x01\x01\x00\x00\x01\x00\x01\x00\x00"),
        "GIF header only": ("q.gif", b"GIF89a"),
        "BMP of zero size": ("q.bmp", b"BM" + b"\x00" * 52),
    }
    for name, (file, data) in images.items():
        add(f"transfer --image: {name}", "file", lambda fx, d, f=file: transfer(fx, d, image=d / f), lambda d, f=file, b=data: write(d / f, b))
    add("transfer --image: 3x200 strip", "file", lambda fx, d: transfer(fx, d, image=d / "q.png"), lambda d: png(d / "q.png", (3, 200)))
    add("transfer --image: a PNG declaring 60000x60000", "file", lambda fx, d: transfer(fx, d, image=d / "q.png"), lambda d: write(d / "q.png", big_png_header()))
    add("transfer --image: a folder", "file", lambda fx, d: transfer(fx, d, image=d / "q.png"), lambda d: (d / "q.png").mkdir())
    add("transfer --image: a FIFO", "file", lambda fx, d: transfer(fx, d, image=d / "q.png"), lambda d: fifo(d / "q.png"))
    add("transfer --image: fully transparent", "file", lambda fx, d: transfer(fx, d, image=d / "q.png"), lambda d: png(d / "q.png", (32, 32), "RGBA", (0, 0, 0, 0)))
    add("transfer --mask: all black", "file", lambda fx, d: transfer(fx, d, "--mask", str(d / "m.png")), lambda d: png(d / "m.png", (48, 48), "L", 0))
    add("transfer --mask: another size", "file", lambda fx, d: transfer(fx, d, "--mask", str(d / "m.png")), lambda d: png(d / "m.png", (20, 20), "L", 255))
    add("train gan --images: a 1x1 photo among them", "file", lambda fx, d: train_gan(fx, d, images=d / "p"),
        lambda d: (png(d / "p" / "a.png"), png(d / "p" / "b.png", (1, 1))))
    add("train gan --images: all fully transparent", "file", lambda fx, d: train_gan(fx, d, images=d / "p"),
        lambda d: [png(d / "p" / f"{k}.png", (16, 16), "RGBA", (0, 0, 0, 0)) for k in range(3)])
    add("train gan --images: a float TIFF depth map", "file", lambda fx, d: train_gan(fx, d, images=d / "p"), lambda d: float_tiff(d / "p"))
    add("train gan --images: a mask file holding a photo", "file", lambda fx, d: train_gan(fx, d, images=d / "p"),
        lambda d: (colour_png(d / "p" / "images" / "a.png"), colour_png(d / "p" / "masks" / "a.png")))
    add("train gan --images: masks/ lacks one", "file", lambda fx, d: train_gan(fx, d, images=d / "p"),
        lambda d: (png(d / "p" / "images" / "a.png"), png(d / "p" / "images" / "b.png"), png(d / "p" / "masks" / "a.png", mode="L", value=255)))
    add("train nca --exemplar: a text file", "file", lambda fx, d: train_nca(fx, d, exemplar=d / "e.png"), lambda d: write(d / "e.png", "no"))
    add("train nca --exemplar: 2x2 pixels", "file", lambda fx, d: train_nca(fx, d, exemplar=d / "e.png"), lambda d: png(d / "e.png", (2, 2)))
    add("evaluate: a 1x1 image among the set", "file", lambda fx, d: evaluate(fx, d),
        lambda d: (png(d / "r" / "a.png"), png(d / "r" / "b.png"), png(d / "i" / "a.png"), png(d / "i" / "b.png", (1, 1))))
    add("evaluate --pairs: render and image of other sizes", "file", lambda fx, d: evaluate(fx, d, "--pairs"), lambda d: pair_folders(d, (32, 32), (40, 40)))
    add("evaluate --pairs: an empty mask", "file", lambda fx, d: evaluate(fx, d, "--pairs", "--masks", str(d / "m")),
        lambda d: (pair_folders(d), png(d / "m" / "a.png", (32, 32), "L", 0)))
    add("prepare images: a 1-bit image", "file", lambda fx, d: prepare_images(fx, d), lambda d: png(d / "in" / "a.png", (32, 32), "1", 1))

    # ------------------------------------------------------------------ bad files: checkpoints and configs
    ckpts = {
        "zero bytes": b"",
        "a header longer than the file": struct.pack("<Q", 10**6) + b"{}",
        "a header of 2^63 bytes": struct.pack("<Q", 2**63),
        "a JSON object, no length": b'{"a": 1}',
        "a header that is a string": safetensors_bytes(b'"hello"'),
        "a tensor past the end of the file": safetensors_bytes({"w": {"dtype": "F32", "shape": [1000], "data_offsets": [0, 4000]}}),
        "a tensor of an unknown dtype": safetensors_bytes({"w": {"dtype": "Q7", "shape": [1], "data_offsets": [0, 4]}}, b"\x00" * 4),
    }
    for name, data in ckpts.items():
        add(f"generate --checkpoint: {name}", "file", lambda fx, d: generate(fx, d, checkpoint=d / "c.safetensors"), lambda d, b=data: write(d / "c.safetensors", b))
    add("generate --checkpoint: a PNG", "file", lambda fx, d: generate(fx, d, checkpoint=fx["query.png"]))
    add("generate --checkpoint: a pose checkpoint", "file", lambda fx, d: generate(fx, d, checkpoint=fx["pose"] / "checkpoint.safetensors"))
    add("generate --checkpoint: an NCA model", "file", lambda fx, d: generate(fx, d, checkpoint=fx["nca"] / "model.safetensors"))
    add("infer nca --checkpoint: a GAN checkpoint", "file", lambda fx, d: infer_nca(fx, d, checkpoint=fx["gan"] / "checkpoint.safetensors"))
    add("transfer --noc-checkpoint: a GAN checkpoint", "file", lambda fx, d: transfer(fx, d, "--noc-checkpoint", str(fx["gan"] / "checkpoint.safetensors")))
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
        add(f"train gan --config: {name}", "file", lambda fx, d: train_gan(fx, d) + ["--config", str(d / "c.yaml")],
            lambda d, t=text: write(d / "c.yaml", t))
    add("infer generate --config: a folder", "file", lambda fx, d: generate(fx, d, "--config", str(d / "c.yaml")), lambda d: (d / "c.yaml").mkdir())
    add("evaluate --world: index.json truncated", "file",
        lambda fx, d: ["evaluate", "--generation", "--world", str(d / "w"), "--shapes", str(fx["shapes"]), "--checkpoint",
                       str(fx["gan"] / "checkpoint.safetensors"), "--out", str(d / "out")],
        lambda d: write(d / "w" / "index.json", '{"format": '))

    # ------------------------------------------------------------------ bad values
    values = [
        ("generate --elevation 95", lambda fx, d: generate(fx, d, "--elevation", "95")),
        ("generate --elevation -91", lambda fx, d: generate(fx, d, "--elevation", "-91")),
        ("generate --truncation -5", lambda fx, d: generate(fx, d, "--truncation", "-5")),
        ("generate --views 0", lambda fx, d: generate(fx, d, "--views", "0")),
        ("generate --resolution 7", lambda fx, d: generate(fx, d, "--resolution", "7")),
        ("generate --resolution 100000", lambda fx, d: generate(fx, d, "--resolution", "100000")),
        ("generate --texture-size 3", lambda fx, d: generate(fx, d, "--texture-size", "3")),
        ("generate --texture-size 50000", lambda fx, d: generate(fx, d, "--texture-size", "50000")),
        ("generate --seeds over 100000 in two ranges", lambda fx, d: generate(fx, d, "--seeds", "0-99999,100000-100005")),
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
        ("infer nca --graft-mask 10**400", lambda fx, d: infer_nca(fx, d, "--graft", str(fx["nca"] / "model.safetensors"), "--graft-mask", "10**400")),
        ("infer nca --graft-mask 1/0", lambda fx, d: infer_nca(fx, d, "--graft", str(fx["nca"] / "model.safetensors"), "--graft-mask", "1/0")),
        ("infer nca --regrow a 5000-term sum", lambda fx, d: infer_nca(fx, d, "--regrow", "x" + "+x" * 5000)),
        ("infer nca --angle 1e308", lambda fx, d: infer_nca(fx, d, "--angle", "1e308")),
        ("infer nca --subdivide 50", lambda fx, d: infer_nca(fx, d, "--subdivide", "50")),
        ("prepare shapes --faces 3", lambda fx, d: prepare_shapes(fx, d, "--faces", "3", source=fx["box.obj"])),
        ("prepare shapes --levels 0", lambda fx, d: prepare_shapes(fx, d, "--levels", "0", source=fx["box.obj"])),
        ("prepare shapes --max-seconds -1", lambda fx, d: prepare_shapes(fx, d, "--max-seconds", "-1", source=fx["box.obj"])),
        ("prepare images --size 7", lambda fx, d: prepare_images(fx, d, "--size", "7", source=fx["photos"])),
        ("prepare synthetic --shapes 0", lambda fx, d: ["prepare", "synthetic", "--out", str(d / "out"), "--shapes", "0"]),
        ("prepare synthetic --query-shapes 3 of 3", lambda fx, d: ["prepare", "synthetic", "--out", str(d / "out"), "--shapes", "3", "--query-shapes", "3"]),
        ("prepare synthetic --elevation 50 10", lambda fx, d: ["prepare", "synthetic", "--out", str(d / "out"), "--elevation", "50", "10"]),
        ("prepare synthetic --elevation 0 100", lambda fx, d: ["prepare", "synthetic", "--out", str(d / "out"), "--elevation", "0", "100"]),
        ("evaluate --resolution 15", lambda fx, d: evaluate(fx, d, "--resolution", "15")),
        ("evaluate --generation --latents 1", lambda fx, d: ["evaluate", "--generation", "--world", str(fx["world"]), "--shapes", str(fx["shapes"]),
                                                             "--checkpoint", str(fx["gan"] / "checkpoint.safetensors"), "--out", str(d / "out"), "--latents", "1"]),
    ]
    for name, argv in values:
        add(name, "value", argv, (lambda d: pair_folders(d)) if name.startswith("evaluate --resolution") else None)

    # ------------------------------------------------------------------ bad folders
    add("--out below a file", "folder", lambda fx, d: generate(fx, d) + ["--out", str(d / "f" / "sub")], lambda d: write(d / "f", "x"))
    add("--out a dangling link", "folder", lambda fx, d: generate(fx, d) + ["--out", str(d / "link")], lambda d: os.symlink(d / "nowhere", d / "link"))
    add("--out a name of 300 characters", "folder", lambda fx, d: generate(fx, d) + ["--out", str(d / ("n" * 300))])
    add("--out /dev/null", "folder", lambda fx, d: generate(fx, d) + ["--out", "/dev/null"])
    add("--out holds the user's seed0.glb", "folder", lambda fx, d: generate(fx, d), lambda d: write(d / "out" / "seed0.glb", "mine"), keep=("seed0.glb",))
    add("--out holds the user's report.json (transfer)", "folder", lambda fx, d: transfer(fx, d), lambda d: write(d / "out" / "report.json", "{}"), keep=("report.json",))
    add("--out holds the user's config.yaml (train pose)", "folder", lambda fx, d: train_view(fx, d, "pose"), lambda d: write(d / "out" / "config.yaml", "mine: 1\n"),
        keep=("config.yaml",))
    add("--out holds the user's config.yaml (train nca)", "folder", lambda fx, d: train_nca(fx, d), lambda d: write(d / "out" / "config.yaml", "mine: 1\n"),
        keep=("config.yaml",))
    add("--out holds the user's metrics.json (evaluate)", "folder", lambda fx, d: evaluate(fx, d),
        lambda d: (pair_folders(d), write(d / "out" / "metrics.json", "{}")), keep=("metrics.json",))
    add("--out holds the user's images/a.png (prepare images)", "folder", lambda fx, d: prepare_images(fx, d),
        lambda d: (png(d / "in" / "a.png"), png(d / "out" / "images" / "a.png", (8, 8))), keep=("images/a.png",))
    add("--out holds the user's view_0.png (infer nca)", "folder", lambda fx, d: infer_nca(fx, d), lambda d: png(d / "out" / "view_0.png"), keep=("view_0.png",))
    add("--out holds the user's index.json (synthetic)", "folder", lambda fx, d: ["prepare", "synthetic", "--out", str(d / "out"), "--shapes", "2"],
        lambda d: write(d / "out" / "index.json", '{"mine": 1}'), keep=("index.json",))
    add("--out is --shapes (train gan into its input)", "folder", lambda fx, d: train_gan(fx, d, shapes=d / "out"),
        lambda d: write(d / "out" / "a.npz", "x"))
    add("--images an empty folder", "folder", lambda fx, d: train_gan(fx, d, images=d / "p"), lambda d: (d / "p").mkdir())
    add("--images only sub-folders", "folder", lambda fx, d: train_gan(fx, d, images=d / "p"), lambda d: png(d / "p" / "x" / "y" / "a.png"))
    add("--shapes an empty folder", "folder", lambda fx, d: train_view(fx, d, "noc", shapes=d / "s"), lambda d: (d / "s").mkdir())
    add("--shapes a mesh file", "folder", lambda fx, d: train_gan(fx, d, shapes=fx["box.obj"]))
    add("prepare shapes --input an empty folder", "folder", lambda fx, d: prepare_shapes(fx, d), lambda d: (d / "in").mkdir())
    add("prepare shapes --input only a dangling link", "folder", lambda fx, d: prepare_shapes(fx, d),
        lambda d: ((d / "in").mkdir(), os.symlink(d / "gone.obj", d / "in" / "a.obj")))
    add("prepare images --input holds no image", "folder", lambda fx, d: prepare_images(fx, d), lambda d: write(d / "in" / "a.txt", "x"))
    add("prepare images --masks a file", "folder", lambda fx, d: prepare_images(fx, d, "--masks", str(d / "m.png")),
        lambda d: (png(d / "in" / "a.png"), png(d / "m.png")))
    add("evaluate --renders an empty folder", "folder", lambda fx, d: evaluate(fx, d), lambda d: ((d / "r").mkdir(), png(d / "i" / "a.png")))
    add("evaluate --pairs no image of a render's name", "folder", lambda fx, d: evaluate(fx, d, "--pairs"),
        lambda d: (png(d / "r" / "a.png"), png(d / "i" / "b.png")))
    add("evaluate --generation --world not a world", "folder",
        lambda fx, d: ["evaluate", "--generation", "--world", str(fx["shapes"]), "--shapes", str(fx["shapes"]), "--checkpoint",
                       str(fx["gan"] / "checkpoint.safetensors"), "--out", str(d / "out")])
    add("evaluate --generation --shapes lacks the world's shapes", "folder",
        lambda fx, d: ["evaluate", "--generation", "--world", str(fx["world"]), "--shapes", str(fx["shapes"]), "--checkpoint",
                       str(fx["gan"] / "checkpoint.safetensors"), "--out", str(d / "out")])
    add("train gan --resume a run folder without a checkpoint", "folder", lambda fx, d: train_gan(fx, d, "--resume", str(d / "run")),
        lambda d: write(d / "run" / "config.yaml", "iters: 5\n"))
    add("train noc --resume and --overwrite", "folder", lambda fx, d: train_view(fx, d, "noc", "--resume", "--overwrite"))
    add("infer nca --out is the model file", "folder", lambda fx, d: infer_nca(fx, d) + ["--out", str(fx["nca"] / "model.safetensors")])
    return c


def big_png_header() -> bytes:
    """A PNG whose header declares 60000 x 60000 pixels (3.6 G) with almost no data."""
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 60000, 60000, 8, 2, 0, 0, 0)) + chunk(b"IDAT", zlib.compress(b"\x00" * 100)) + chunk(b"IEND", b"")


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
