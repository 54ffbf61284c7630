"""Test-wide settings."""

import torch

# The tests run many tiny tensor operations; one thread avoids thread start-up and, on a shared
# machine, the large slow-down of threads that wait for a busy core.
torch.set_num_threads(1)


import numpy as np  # noqa: E402
import pytest  # noqa: E402
import trimesh  # noqa: E402
import yaml  # noqa: E402
from PIL import Image  # noqa: E402

# The smallest automaton run the tests train: a 6-channel automaton on a coarse sphere (add its ``iters``).
TINY_NCA = {
    "batch": 1,
    "views": 1,
    "resolution": 32,
    "steps_min": 2,
    "steps_max": 3,
    "pool": 4,
    "seed_every": 2,
    "mesh": "sphere:3",
    "exemplar_size": 32,
    "vgg_depth": 1,
    "max_points": 64,
    "sample_every": 0,
    "checkpoint_every": 1,
    "log_every": 1,
    "nca": {"channels": 6, "hidden": 16},
}

# The smallest GAN config the tests train (every network a few channels wide).
TINY_GAN = {
    "sample_every": 0,
    "checkpoint_every": 0,
    "generator": {
        "z_dim": 16,
        "w_dim": 16,
        "mapping_layers": 2,
        "encoder_channels": [8, 8, 8],
        "synthesis_channels": [8, 8, 8],
        "field_hidden": 16,
        "aux_latent_dim": 8,
    },
    "discriminator": {"channel_base": 64, "channel_max": 16},
}


@pytest.fixture(scope="session")
def tiny_gan(tmp_path_factory):
    """A GAN checkpoint (``run/checkpoint.safetensors``) after 2 iterations on two prepared boxes
    (``shapes/box0.npz``, ``shapes/box1.npz``: real preparation, 96 quads, 3 levels), its photos,
    and a raw mesh ``slab.obj`` for on-the-fly preparation. Returns the folder."""
    from mesh2tex.cli import main
    from mesh2tex.geometry.prepare import prepare_shape

    root = tmp_path_factory.mktemp("tiny_gan")
    (root / "shapes").mkdir()
    for i, extents in enumerate([(1.0, 0.6, 0.4), (0.5, 1.0, 0.5)]):
        box = trimesh.creation.box(extents)
        prepare_shape(box.vertices, box.faces, face_count=96, levels=3, seed=0).save(root / "shapes" / f"box{i}.npz")
    photos = root / "photos"
    photos.mkdir()
    for i in range(4):
        rgba = np.zeros((16, 16, 4), np.uint8)
        rgba[4:12, 4:12] = (200, 40 * i, 30, 255)
        Image.fromarray(rgba).save(photos / f"{i}.png")
    (root / "tiny.yaml").write_text(yaml.safe_dump(TINY_GAN))
    code = main(
        [
            "train",
            "gan",
            "--shapes",
            str(root / "shapes"),
            "--images",
            str(photos),
            "--out",
            str(root / "run"),
            "--config",
            str(root / "tiny.yaml"),
            "--iters",
            "2",
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
    assert code == 0
    trimesh.creation.box((0.8, 0.8, 0.3)).export(root / "slab.obj")
    return root


def make_tiny_world(root, views: int, resolution: int, query_views: int) -> dict:
    """A 3-chair synthetic world (seed 3, one held-out shape) under ``root/world`` and its held-out
    shape and first training shape prepared (96 quads, 3 levels) under ``root/shapes``. Returns the
    world's index."""
    import json

    from mesh2tex.cli import main
    from mesh2tex.geometry.mesh_io import load_mesh
    from mesh2tex.geometry.prepare import prepare_shape

    world = root / "world"
    assert (
        main(
            [
                "prepare",
                "synthetic",
                "--out",
                str(world),
                "--shapes",
                "3",
                "--views",
                str(views),
                "--resolution",
                str(resolution),
                "--texture-size",
                "64",
                "--seed",
                "3",
                "--query-views",
                str(query_views),
            ]
        )
        == 0
    )
    index = json.loads((world / "index.json").read_text())
    shapes = root / "shapes"
    shapes.mkdir()
    for name in index["split"]["query_shapes"] + index["split"]["train_shapes"][:1]:
        vertices, faces = load_mesh(world / "meshes" / f"{name}.obj")
        prepare_shape(vertices, faces, face_count=96, levels=3, seed=0).save(shapes / f"{name}.npz")
    return index


@pytest.fixture(params=["compiled", "vectorised"])
def raster_path(request, monkeypatch):
    """Runs a test on both CPU paths of ``mesh2tex.render.rasterize``: the compiled loop
    (``mesh2tex.render.kernels``) and the vectorised passes (the CUDA path, and the fallback)."""
    if request.param == "vectorised":
        monkeypatch.setenv("MESH2TEX_RASTER_KERNEL", "torch")
    else:
        pytest.importorskip("numba")
    return request.param
