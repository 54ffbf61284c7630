"""Seconds per SWD call with numpy's row sort (the library's) against torch.sort, in one process.

    python benchmarks/bench_swd.py [--images 64] [--size 64] [--repeats 3] [--threads 2]

Two random image sets of ``--images`` images at ``--size`` px go through
:func:`mesh2tex.metrics.swd.swd_per_level` (128 patches per image, 512 projections, 4 repeats, as
every table uses), once with :func:`mesh2tex.metrics.swd.sorted_rows` as it is and once with
``torch.sort`` in its place, in alternation. Prints the seconds of each, their ratio, and whether
the two gave the same figures (they must: sorting is exact).
"""

from __future__ import annotations

import argparse
import importlib
import time
from unittest import mock

import torch

swd = importlib.import_module("mesh2tex.metrics.swd")  # the module: the package exports a function of this name


def torch_sorted_rows(values: torch.Tensor) -> torch.Tensor:
    return torch.sort(values.contiguous(), dim=1).values


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", type=int, default=64)
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    generator = torch.Generator().manual_seed(0)
    images_a = torch.rand(args.images, 3, args.size, args.size, generator=generator)
    images_b = torch.rand(args.images, 3, args.size, args.size, generator=generator) ** 2
    seconds = {"numpy sort": [], "torch.sort": []}
    figures = {}
    for _ in range(args.repeats):
        for name in seconds:
            with mock.patch.object(swd, "sorted_rows", torch_sorted_rows if name == "torch.sort" else swd.sorted_rows):
                start = time.perf_counter()
                figures[name] = swd.swd_per_level(images_a, images_b)
                seconds[name].append(time.perf_counter() - start)
    best = {name: min(values) for name, values in seconds.items()}
    print(
        f"{args.images} + {args.images} images at {args.size} px, {torch.get_num_threads()} torch threads, best of "
        f"{args.repeats}"
    )
    for name, value in best.items():
        print(f"  {name:10s} {value:.3f} s per swd_per_level call")
    print(f"speed-up torch.sort / numpy sort: {best['torch.sort'] / best['numpy sort']:.2f}")
    print(f"same figures: {figures['numpy sort'] == figures['torch.sort']} (swd {figures['numpy sort']['swd']:.4f})")


if __name__ == "__main__":
    main()
