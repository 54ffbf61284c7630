"""The child side of ``benchmarks/cost_curves.py``: one size of one case, measured in a fresh process (time, CPU
time, resident memory) and printed as one marked JSON line; ``cost_curves.py --child CASE`` runs it."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import re
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))  # bench_gan_step, bench_bake, ... are imported, not copied
from resident_memory import reset_peak_rss, status_mib  # noqa: E402  (this folder)

MARK = "COST_RESULT "


def _cpu_seconds() -> float:
    """CPU seconds of this process's threads and of its finished children."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


class Measured:
    """A measured section: resident MB before it, its peak (this process or a forked one), and the cores it got
    (CPU seconds over wall seconds: below the threads asked for when the machine is busy or the work is serial)."""

    def __enter__(self):
        import gc

        gc.collect()
        self.before_mb = reset_peak_rss()  # the peak mark restarts from the resident size now
        self.children_before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        self.start, self.cpu_start = time.perf_counter(), _cpu_seconds()
        return self

    def __exit__(self, *exc):
        children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss  # forked workers (QuadriFlow), kB
        forked = children / 1024 if children > self.children_before else 0.0  # a new, higher peak: one of the section's
        self.peak_mb = max(status_mib("VmHWM"), forked)
        self.cores = (_cpu_seconds() - self.cpu_start) / max(time.perf_counter() - self.start, 1e-9)
        return False


def run_quietly(main, argv: list[str]) -> str:
    """Run a benchmark's ``main`` with ``argv`` as its command line; its standard output as text."""
    buffer, saved = io.StringIO(), sys.argv
    sys.argv = argv
    try:
        with contextlib.redirect_stdout(buffer):
            main()
    finally:
        sys.argv = saved
    return buffer.getvalue()


def child_prepare(p: dict, threads: int) -> dict:
    """Seconds of ``prepare shapes`` on one mesh file (load, prepare at 6144 quads and 5 levels, save the .npz)."""
    from bench_bake import chair_mesh

    from data_prep.shapes import prepare_one

    with tempfile.TemporaryDirectory() as tmp:
        mesh = chair_mesh(p["triangles"])
        triangles = len(mesh.faces)
        mesh.export(f"{tmp}/chair.ply")
        del mesh
        with Measured() as memory:
            start = time.perf_counter()
            record = prepare_one(f"{tmp}/chair.ply", f"{tmp}/chair.npz", faces=6144, levels=5, seed=0)
            seconds = time.perf_counter() - start
    return {
        "seconds": seconds,
        "size": triangles,
        "memory": memory,
        "status": record["status"],
        "parts": {"face_counts": record["face_counts"], "reason": record["reason"]},
    }


def child_gan_step(p: dict, threads: int, iters: int = 3) -> dict:
    """Mean seconds of ``iters`` main-phase ``train gan`` iterations after one warm-up (bench_gan_step's trainer, 2
    chairs)."""
    import bench_gan_step as gan

    from mesh2tex.geometry.prepare import prepare_shape
    from mesh2tex.synthetic.shapes import generate_shape

    shapes = [
        prepare_shape(m.vertices, m.faces, face_count=p["faces"], levels=5, seed=0)
        for m in (generate_shape("chair", np.random.default_rng(i)) for i in range(2))
    ]
    version = gan.Version("current")
    args = argparse.Namespace(batch=2, views=p["views"], resolution=p["resolution"], device="cpu")
    with tempfile.TemporaryDirectory() as tmp:
        trainer = version.trainer(args, shapes, tmp)
        with Measured() as memory:
            version.step(trainer)  # warm-up: iteration 0 runs every lazy regulariser
            times = []
            for _ in range(iters):
                greg = any(phase == "Greg" for phase, _ in trainer.loss.phases(trainer.iteration))
                times.append((version.step(trainer)[0], greg))
        main_s = gan.summary(times, trainer.cfg.loss.pl_interval)[0]
        flops = counted_flops(gan, version, trainer, main_s)
    quads = int(np.mean([s.face_counts[0] for s in shapes]))
    size = {"quads": quads, "pixels": p["resolution"] ** 2, "views": p["views"]}
    count = lambda *modules: sum(t.numel() for m in modules for t in m.parameters())
    return {
        "seconds": main_s,
        "size": size,
        "memory": memory,
        "status": "ok",
        "parts": {
            "finest quads": quads,
            "GFLOP main phases": flops[False] / 1e9,
            "GFLOP with path length": flops[True] / 1e9,
            "generator parameters": count(trainer.generator),
            "discriminator parameters": count(trainer.d_field, trainer.d_proxy),
        },
    }


def counted_flops(gan, version, trainer, seconds: float) -> dict[bool, float]:
    """FLOPs (matmuls and convolutions, forward and backward: ``FlopCounterMode``) of the next main-only iteration
    and the next one with the path-length term, {has path length: FLOPs}, as ``bench_gan_step.flop_account`` prints
    them."""
    text = run_quietly(lambda: gan.flop_account(version, trainer, {False: seconds, True: seconds}), sys.argv)
    found = {
        label: float(re.search(label + r": ([\d.]+) GFLOP", text)[1]) * 1e9
        for label in ("main phases only", "with path-length reg")
    }
    return {False: found["main phases only"], True: found["with path-length reg"]}


def child_generate_bake(p: dict, threads: int) -> dict:
    """Seconds of the user bake (map + colours + write) of the shipped chair's texture onto a chair mesh of
    ``triangles`` at ``size``^2 texels (``bench_bake.timed_bake``, which also generates the texture)."""
    from bench_bake import timed_bake

    with Measured() as memory:
        result = timed_bake(p["triangles"], p["size"])
    seconds = result["seconds"]
    return {
        "seconds": seconds["user bake (map + colours + write)"],
        "memory": memory,
        "status": "ok",
        "size": {"triangles": result["triangles"], "texels": result["texels"]},
        "parts": seconds,
    }


def child_transfer(p: dict, threads: int, iters: int = 8) -> dict:
    """Seconds per transfer iteration over both stages (``bench_transfer.py`` with ``iters`` iterations each)."""
    import bench_transfer

    argv = [
        "bench_transfer.py",
        "--resolution",
        str(p["resolution"]),
        "--latent-iters",
        str(iters),
        "--refine-iters",
        str(iters),
        "--threads",
        str(threads),
        "--device",
        "cpu",
    ]
    with Measured() as memory:
        text = run_quietly(bench_transfer.main, argv)
    stages = {
        m[1]: (int(m[2]), float(m[3])) for m in re.finditer(r"stage (\w+)\s*:\s*(\d+) iterations,\s*([\d.]+) s", text)
    }
    total_iters, total_s = sum(n for n, _ in stages.values()), sum(s for _, s in stages.values())
    return {
        "seconds": total_s / total_iters,
        "size": p["resolution"] ** 2,
        "memory": memory,
        "status": "ok",
        "parts": {f"{k} s/iteration": s / n for k, (n, s) in stages.items()},
    }


def child_nca_step(p: dict, threads: int, steps: int = 50) -> dict:
    """Seconds per automaton step (inference) on a cube-sphere of ``subdivisions`` (``bench_nca_step.py``)."""
    import bench_nca_step

    argv = [
        "bench_nca_step.py",
        "--subdivisions",
        str(p["subdivisions"]),
        "--steps",
        str(steps),
        "--threads",
        str(threads),
    ]
    with Measured() as memory:
        text = run_quietly(bench_nca_step.main, argv)
    cells = int(re.search(r"(\d+) cells", text)[1])
    number = lambda label: float(re.search(label + r"\s+([\d.]+) ms", text)[1]) / 1000
    return {
        "seconds": number("step"),
        "size": cells,
        "memory": memory,
        "status": "ok",
        "parts": {"perceive sparse s": number("perceive sparse"), "perceive edges s": number("perceive edges")},
    }


def child_rasterize(p: dict, threads: int, repeats: int = 5) -> dict:
    """Seconds of one ``rasterize`` call (minimum of ``repeats`` after a warm-up): one view of a bumpy blob of
    ``triangles`` at ``size`` px."""
    import torch
    from bench_bake import blob_mesh

    from mesh2tex.render import orbit_camera, rasterize, transform_points

    mesh = blob_mesh(p["triangles"])
    vertices = torch.tensor(np.asarray(mesh.vertices), dtype=torch.float32)
    faces = torch.tensor(np.asarray(mesh.faces), dtype=torch.int64)
    pos = transform_points(vertices, orbit_camera(30.0, 25.0, distance=3.2, fov=45.0).mvp)
    rasterize(pos, faces, (p["size"], p["size"]))  # warm-up: numba's compiled loop is read from its cache
    times = []
    with Measured() as memory:
        for _ in range(repeats):
            start = time.perf_counter()
            raster = rasterize(pos, faces, (p["size"], p["size"]))
            times.append(time.perf_counter() - start)
    covered = float((raster.face_id >= 0).float().mean())
    return {
        "seconds": min(times),
        "size": {"triangles": len(faces), "pixels": p["size"] ** 2},
        "memory": memory,
        "status": "ok",
        "parts": {"covered": covered, "median s": float(np.median(times))},
    }


CHILDREN = {
    "prepare": child_prepare,
    "gan_step": child_gan_step,
    "generate_bake": child_generate_bake,
    "transfer": child_transfer,
    "nca_step": child_nca_step,
    "rasterize": child_rasterize,
}


def child_main(case: str, params: dict, threads: int) -> None:
    """Measure one size of one case and print the result as one marked JSON line."""
    import torch

    torch.set_num_threads(threads)
    result = CHILDREN[case](params, threads)
    memory = result.pop("memory")
    result.update(
        peak_mb=memory.peak_mb,
        added_mb=memory.peak_mb - memory.before_mb,
        before_mb=memory.before_mb,
        cores=memory.cores,
    )
    print(MARK + json.dumps(result), flush=True)
