"""Seconds per shape of `prepare_shape` on the default hierarchy (6144 .. 24 faces) and parallel throughput.

    python benchmarks/bench_prepare_shapes.py [--faces 6144] [--levels 5] [--workers 2]

Shapes are built here: a sphere, a torus, a box and a chair made of six boxes. Prints per shape the
seconds on one core (serial, one process) and the method of each level, then the shapes per minute
of `--workers` processes against the serial run of the same shapes.
"""

from __future__ import annotations

import argparse
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import trimesh

from mesh2tex.geometry.prepare import prepare_shape


def shapes() -> dict[str, trimesh.Trimesh]:
    chair = [trimesh.creation.box((1, 0.1, 1)).apply_translation((0, 0.5, 0)),
             trimesh.creation.box((1, 1, 0.1)).apply_translation((0, 1.0, -0.45))]
    chair += [trimesh.creation.box((0.1, 0.5, 0.1)).apply_translation((x, 0.22, z)) for x in (-0.45, 0.45) for z in (-0.45, 0.45)]
    return {
        "sphere": trimesh.creation.icosphere(5),
        "torus": trimesh.creation.torus(1.0, 0.35, major_sections=96, minor_sections=32),
        "box": trimesh.creation.box((1.0, 0.6, 0.4)),
        "chair": trimesh.util.concatenate(chair),
    }


def _time_one(name: str, faces: int, levels: int) -> tuple[str, float, list[int], list[str]]:
    mesh = shapes()[name]
    start = time.perf_counter()
    shape = prepare_shape(mesh.vertices, mesh.faces, face_count=faces, levels=levels)
    return name, time.perf_counter() - start, shape.face_counts, [level["method"] for level in shape.metadata["levels"]]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--faces", type=int, default=6144)
    parser.add_argument("--levels", type=int, default=5)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    names = list(shapes())

    serial_start = time.perf_counter()
    seconds = []
    for name in names:
        _, s, counts, methods = _time_one(name, args.faces, args.levels)
        seconds.append(s)
        print(f"{name:8s} {s:6.2f} s  faces {counts}  methods {methods}")
    serial = time.perf_counter() - serial_start
    print(f"serial: mean {np.mean(seconds):.2f} s per shape, max {np.max(seconds):.2f} s (target: at most 20 s)")

    start = time.perf_counter()
    # spawn, not fork: a forked child of a process that already ran pymeshlab's OpenMP code hangs in libgomp
    with ProcessPoolExecutor(max_workers=args.workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        list(pool.map(_time_one, names, [args.faces] * len(names), [args.levels] * len(names)))
    parallel = time.perf_counter() - start
    print(f"parallel ({args.workers} workers): {len(names) / parallel * 60:.1f} shapes/min "
          f"vs serial {len(names) / serial * 60:.1f} shapes/min (speed-up x{serial / parallel:.2f})")


if __name__ == "__main__":
    main()
