"""Speed of one cellular-automaton step, and of its perception as a sparse matrix against the edge-list definition.

    python benchmarks/bench_nca_step.py [--subdivisions 32] [--steps 200] [--threads 1]

On a cube-sphere (32 subdivisions: 6,146 cells) with the default automaton (16 channels, order-1
harmonics, hidden 128) whose update is made non-zero: ms per step (inference, the whole update),
and ms per perception call for :func:`mesh2tex.nn.cell_graph.perceive` (the cached CSR operator) and
:func:`mesh2tex.nn.cell_graph.perceive_edges` (gather and scatter-add over the edge list), measured in the
same process; the ratio is edges / sparse.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mesh2tex.geometry.primitives import cube_sphere  # noqa: E402
from mesh2tex.nn.cell_graph import build_cell_graph, perceive, perceive_edges  # noqa: E402
from mesh2tex.nn.nca import MeshNCA  # noqa: E402


def per_call_ms(fn, repeats: int) -> float:
    fn()
    start = time.perf_counter()
    for _ in range(repeats):
        fn()
    return 1000 * (time.perf_counter() - start) / repeats


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--subdivisions", type=int, default=32)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    graph = build_cell_graph(*cube_sphere(args.subdivisions))
    model = MeshNCA()
    torch.nn.init.normal_(model.update[2].weight, std=0.01)
    state = torch.rand(1, graph.num_cells, model.cfg.channels) - 0.5
    with torch.no_grad():
        step = per_call_ms(lambda: model.step(state, graph), args.steps)
        sparse = per_call_ms(lambda: perceive(state, graph, 1, 4.0), args.steps)
        edges = per_call_ms(lambda: perceive_edges(state, graph, 1, 4.0), args.steps)
    print(f"{graph.num_cells} cells, {args.threads} thread(s)")
    print(f"step            {step:7.2f} ms")
    print(f"perceive sparse {sparse:7.2f} ms")
    print(f"perceive edges  {edges:7.2f} ms")
    print(f"ratio edges / sparse {edges / sparse:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
