"""Peak memory and time of baking a generated texture onto the prepared shape (``infer generate
--output-mesh prepared``'s bake, :func:`mesh2tex.texturing.bake_texture`).

    python benchmarks/bake_memory.py [--size 2048] [--checkpoint chair]

One world chair (``mesh2tex.synthetic``, seed 0) is prepared at the model's hierarchy, a texture is
generated from a random latent, and it is baked at ``--size``; the process's peak resident memory
before and after the bake is printed (run each size in a fresh process: the peak only grows).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mesh2tex.geometry.prepare import prepare_shape  # noqa: E402
from mesh2tex.models import load_generator  # noqa: E402
from mesh2tex.nn.batch import collate_shapes  # noqa: E402
from mesh2tex.runtime import peak_memory_gb  # noqa: E402
from mesh2tex.synthetic.shapes import generate_shape  # noqa: E402
from mesh2tex.texturing import bake_texture  # noqa: E402


def peak_mb() -> float:
    return peak_memory_gb(torch.device("cpu")) * 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=2048)
    parser.add_argument("--checkpoint", default="chair")
    args = parser.parse_args()
    model = load_generator(args.checkpoint, torch.device("cpu"))
    generator = model.network
    mesh = generate_shape("chair", np.random.default_rng(0))
    shape = prepare_shape(mesh.vertices, mesh.faces, face_count=model.face_count(0), levels=4, seed=0)
    batch = collate_shapes([shape])
    with torch.no_grad():
        texture = generator.synthesize(batch, generator.mapping(torch.randn(1, generator.cfg.z_dim)), noise_mode="none")
        before = peak_mb()
        start = time.perf_counter()
        bake_texture(generator, texture, batch, args.size)
    print(
        f"bake at {args.size}^2: {time.perf_counter() - start:.1f} s, peak RSS {peak_mb():.0f} MB ({before:.0f} MB "
        "before the bake)"
    )


if __name__ == "__main__":
    main()
