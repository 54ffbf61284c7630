"""Quad hierarchies over varied inputs: faces per level, ratios, methods, warnings, ring fill and seconds per shape.

    python benchmarks/bench_prepare_shapes.py [--world DIR] [--chairs 24] [--cars 24] [--faces 6144] [--levels 5]
                                              [--only NAME...] [--json FILE]

Inputs: the synthetic world's chairs and cars (built with ``mesh2tex prepare synthetic`` under
``--world`` when missing; only their meshes are read) and meshes built here that are hard for a quad
remesher: thin parts, disconnected parts, holes and open sheets, non-manifold edges, a triangle soup,
intersecting parts, and a 100k+ triangle mesh. Each shape is prepared in this process on one core
(set ``OMP_NUM_THREADS=1``), one after the other. Per shape one line: wall and CPU seconds, faces per level, the
ratio of each level to the finer one, the method of each level, warnings and the share of filled
3x3 ring slots per level; then a summary (copied levels, level 0 against the request, ratios, time).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import trimesh

from mesh2tex.errors import InputError
from mesh2tex.geometry.mesh_io import load_mesh
from mesh2tex.geometry.prepare import prepare_shape


def _box(size, centre):
    return trimesh.creation.box(size).apply_translation(centre)


def built_shapes() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Hard inputs made here, each (V, 3) float and (T, 3) int."""
    rng = np.random.default_rng(0)
    out = {}
    # thin parts: a stool whose legs and rungs are 1 % of its diagonal thick
    parts = [_box((1.0, 0.04, 1.0), (0, 1.0, 0))]
    parts += [_box((0.022, 1.0, 0.022), (x, 0.5, z)) for x in (-0.45, 0.45) for z in (-0.45, 0.45)]
    parts += [_box((0.9, 0.022, 0.022), (0, 0.3, z)) for z in (-0.45, 0.45)]
    out["thin_stool"] = trimesh.util.concatenate(parts)
    # disconnected parts: twelve spheres and boxes scattered, not touching
    parts = []
    for k in range(12):
        centre = rng.uniform(-1.5, 1.5, 3)
        parts.append(
            trimesh.creation.icosphere(2, radius=rng.uniform(0.1, 0.3)).apply_translation(centre)
            if k % 2
            else _box(rng.uniform(0.1, 0.5, 3), centre)
        )
    out["scattered_parts"] = trimesh.util.concatenate(parts)
    # holes and open boundaries: an open tube, a sphere with a large opening, a single sheet
    tube = trimesh.creation.cylinder(0.3, 1.5, sections=48)
    keep = np.abs(tube.face_normals[:, 2]) < 0.5  # drop both caps
    out["open_tube"] = trimesh.Trimesh(tube.vertices, tube.faces[keep])
    sphere = trimesh.creation.icosphere(4)
    out["open_bowl"] = trimesh.Trimesh(sphere.vertices, sphere.faces[sphere.triangles_center[:, 1] < 0.4])
    xs, zs = np.meshgrid(np.linspace(-1, 1, 40), np.linspace(-1, 1, 40))
    grid = np.stack([xs.ravel(), 0.2 * np.sin(3 * xs.ravel()) * np.cos(2 * zs.ravel()), zs.ravel()], axis=1)
    cells = np.array(
        [[r * 40 + c, (r + 1) * 40 + c, r * 40 + c + 1] for r in range(39) for c in range(39)]
        + [[r * 40 + c + 1, (r + 1) * 40 + c, (r + 1) * 40 + c + 1] for r in range(39) for c in range(39)]
    )
    out["wavy_sheet"] = trimesh.Trimesh(grid, cells)
    # non-manifold edges: two boxes sharing one edge, and a fin on a third box's edge
    a, b = _box((1, 1, 1), (0, 0, 0)), _box((1, 1, 1), (1, 1, 0))
    c = _box((1, 1, 1), (3, 0, 0))
    fin_v = np.vstack([c.vertices, [[3.0, 1.5, 0.0]]])
    edge = c.faces[0][:2]
    fin = trimesh.Trimesh(fin_v, np.vstack([c.faces, [[edge[0], edge[1], len(c.vertices)]]]), process=False)
    out["non_manifold"] = trimesh.util.concatenate([a, b, fin])
    # a triangle soup: no vertex shared, some faces duplicated
    soup_source = trimesh.creation.torus(1.0, 0.3, major_sections=64, minor_sections=24)
    soup_v = soup_source.vertices[soup_source.faces].reshape(-1, 3)
    soup_f = np.arange(len(soup_v)).reshape(-1, 3)
    out["triangle_soup"] = trimesh.Trimesh(soup_v, np.vstack([soup_f, soup_f[:200]]), process=False)
    # intersecting parts, not merged: a car-like body with wheels pushed into it
    body = _box((2.0, 0.5, 0.9), (0, 0.45, 0))
    wheels = [
        trimesh.creation.cylinder(0.22, 0.2, sections=32).apply_translation((x, 0.22, z))
        for x in (-0.7, 0.7)
        for z in (-0.4, 0.4)
    ]
    out["intersecting_parts"] = trimesh.util.concatenate([body, _box((1.0, 0.4, 0.8), (-0.1, 0.85, 0))] + wheels)
    # 100k+ triangles: a bumpy sphere
    dense = trimesh.creation.icosphere(7)  # 327 680 triangles
    direction = dense.vertices / np.linalg.norm(dense.vertices, axis=1, keepdims=True)
    bumps = 1.0 + 0.08 * np.sin(7 * direction[:, 0]) * np.sin(5 * direction[:, 1]) * np.sin(6 * direction[:, 2])
    out["dense_327k"] = trimesh.Trimesh(dense.vertices * bumps[:, None], dense.faces)
    return {name: (np.asarray(m.vertices), np.asarray(m.faces)) for name, m in out.items()}


def world_meshes(world: Path, category: str, count: int) -> dict[str, Path]:
    """The ``count`` meshes of a synthetic world (built with the CLI when missing)."""
    folder = world / category
    if count <= 0:
        return {}
    if not (folder / "index.json").exists() or len(list((folder / "meshes").glob("*.obj"))) < count:
        subprocess.run(
            [
                sys.executable,
                "-m",
                "mesh2tex",
                "prepare",
                "synthetic",
                "--out",
                str(folder),
                "--category",
                category,
                "--shapes",
                str(count),
                "--views",
                "1",
                "--resolution",
                "32",
                "--texture-size",
                "64",
                "--query-views",
                "1",
            ],
            check=True,
            stdout=subprocess.DEVNULL,
        )
    return {p.stem: p for p in sorted((folder / "meshes").glob("*.obj"))[:count]}


def _cpu_seconds() -> float:
    """CPU time of this process and of its finished children (QuadriFlow runs in forked children)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def ring_fill(neighbors: np.ndarray) -> float:
    """Share of the 8 ring slots of a (F, 9) neighbourhood table that hold a face."""
    return float((neighbors[:, 1:] >= 0).mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--world", default="bench_world", help="folder of the synthetic chair and car worlds (built when missing)"
    )
    parser.add_argument("--chairs", type=int, default=24)
    parser.add_argument("--cars", type=int, default=24)
    parser.add_argument("--faces", type=int, default=6144)
    parser.add_argument("--levels", type=int, default=5)
    parser.add_argument("--only", nargs="*", default=None, help="prepare only these shape names")
    parser.add_argument("--json", default=None, help="write the per-shape records here")
    args = parser.parse_args()

    inputs: dict[str, object] = {}
    inputs.update(world_meshes(Path(args.world), "chair", args.chairs))
    inputs.update(world_meshes(Path(args.world), "car", args.cars))
    inputs.update(built_shapes())
    if args.only:
        inputs = {k: v for k, v in inputs.items() if k in set(args.only)}

    records = []
    for name, source in inputs.items():
        vertices, faces = load_mesh(source) if isinstance(source, Path) else source
        start, cpu_start = time.perf_counter(), _cpu_seconds()
        try:
            shape = prepare_shape(vertices, faces, face_count=args.faces, levels=args.levels, source=name)
        except InputError as error:
            records.append(
                {
                    "name": name,
                    "triangles": int(len(faces)),
                    "status": "failed",
                    "reason": str(error),
                    "seconds": round(time.perf_counter() - start, 2),
                }
            )
            print(f"{name:20s} FAILED {records[-1]['seconds']:6.2f} s  {error}", flush=True)
            continue
        seconds, cpu = time.perf_counter() - start, _cpu_seconds() - cpu_start
        levels = shape.metadata["levels"]
        record = {
            "name": name,
            "triangles": int(len(faces)),
            "status": "ok",
            "seconds": round(seconds, 2),
            "cpu_seconds": round(cpu, 2),
            "faces": shape.face_counts,
            "ratios": [l["ratio"] for l in levels[1:]],
            "methods": [l["method"] for l in levels],
            "warnings": shape.metadata["warnings"],
            "ring_fill": [round(ring_fill(n), 3) for n in shape.neighbors],
        }
        records.append(record)
        short = [
            m.split("(")[0].replace("quadriflow", "QF").replace("surface nets", "SN")
            + ("*" if m.startswith("quadriflow(input") else "")
            for m in record["methods"]
        ]
        print(
            f"{name:20s} {seconds:6.2f} s ({cpu:5.2f} s CPU)  faces {record['faces']}  ratios {record['ratios']}  "
            f"methods {short}  "
            f"ring {record['ring_fill']}  warnings {len(record['warnings'])}",
            flush=True,
        )

    ok = [r for r in records if r["status"] == "ok"]
    if ok:
        ratios = np.array([x for r in ok for x in r["ratios"]])
        level0 = np.array([r["faces"][0] / args.faces for r in ok])
        seconds = np.array([r["seconds"] for r in ok])
        cpu = np.array([r["cpu_seconds"] for r in ok])
        print(
            f"\n{len(ok)} of {len(records)} shapes ok; copied levels (ratio 1.0): {int((ratios <= 1.0).sum())}; "
            f"ratios {ratios.min():.2f}-{ratios.max():.2f}; level 0 / request {level0.min():.2f}-{level0.max():.2f}; "
            f"levels with a warning: {sum(len(r['warnings']) for r in ok)}"
        )
        print(
            f"seconds per shape: mean {seconds.mean():.1f}, median {np.median(seconds):.1f}, max {seconds.max():.1f} "
            "(target: at most 20); "
            f"CPU seconds (this process and QuadriFlow's child processes): mean {cpu.mean():.1f}, max {cpu.max():.1f}"
        )
    if args.json:
        Path(args.json).write_text(json.dumps(records, indent=1))


if __name__ == "__main__":
    main()
