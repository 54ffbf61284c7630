"""Speed of one step of ``infer synthesize`` by method: rendered views against the patches walked on the
surface, each walked patch used once or reused over several steps (``synthesis.patch_reuse``).

    python benchmarks/bench_synthesis_step.py [--mesh sphere|SHAPE.npz|MESH] [--steps 20] [--rounds 3]
        [--reuse 1 2 4 8] [--threads 1]

On the mesh (the cube-sphere by default; a new xatlas atlas), the checker exemplar and the defaults
of :class:`mesh2tex.texel_synthesis.SynthesisConfig` (a 512 x 512 texture, the ``patch`` loss), one
optimisation per setting, built first; then ``--rounds`` rounds in which each setting takes ``--steps``
steps in turn, so that a busy machine slows every setting alike. Prints seconds per step (the median
of the rounds) and the ratio to ``renders`` measured in the same process.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mesh2tex.geometry.primitives import load_surface  # noqa: E402
from mesh2tex.nn.cell_graph import build_cell_graph  # noqa: E402
from mesh2tex.render.bake import new_atlas  # noqa: E402
from mesh2tex.synthetic.exemplars import exemplar_image  # noqa: E402
from mesh2tex.texel_synthesis import SynthesisConfig, TexelSurface, TexelSynthesis, exemplar_tensor  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mesh", default="sphere")
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--reuse", type=int, nargs="+", default=[1, 2, 4, 8])
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    graph = build_cell_graph(*load_surface(args.mesh))  # its triangles
    positions, triangles = graph.positions.numpy(), graph.triangles.numpy()
    vertex_index, faces, uv = new_atlas(positions.astype(np.float64), triangles)
    surface = TexelSurface.from_arrays(positions[vertex_index], faces, uv)
    exemplar = exemplar_tensor(exemplar_image("checker", 128), 128)
    settings = {"renders": SynthesisConfig(method="renders")}
    settings.update({f"patches, reuse {r}": SynthesisConfig(method="patches", patch_reuse=r) for r in args.reuse})
    runs = {name: TexelSynthesis(cfg, surface, exemplar) for name, cfg in settings.items()}
    for synthesis in runs.values():
        synthesis.step()  # the first step walks every patch of a reused bank
    seconds: dict[str, list[float]] = {name: [] for name in runs}
    for _ in range(args.rounds):
        for name, synthesis in runs.items():
            start = time.perf_counter()
            for _ in range(args.steps):
                synthesis.step()
            seconds[name].append((time.perf_counter() - start) / args.steps)
    reference = statistics.median(seconds["renders"])
    print(f"{args.mesh}: {len(positions)} vertices, {len(triangles)} triangles; {args.threads} thread(s)")
    print("| setting | s per step | / renders |")
    print("| --- | ---: | ---: |")
    for name, values in seconds.items():
        median = statistics.median(values)
        print(f"| {name} | {median:.3f} | {median / reference:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
