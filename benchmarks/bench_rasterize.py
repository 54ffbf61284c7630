"""Speed of mesh2tex.render.rasterize against first-hit ray casting with Embree, side by side, on meshes
of different character.

Meshes (each centred, bbox diagonal 1, seen from distance 1.6 with a 45 degree field of view):
  torus   the bumpy torus of tests/test_render_raycast.py: 49,152 triangles of nearly equal size
  table   a box with finely rounded edges on round legs: a few huge triangles beside 48k tiny ones
  scan    a noisy, irregular blob like a 3D scan: 103,680 triangles, most under a pixel
  chair   shape 0 of the synthetic world's chairs (mesh2tex.synthetic): panels, rods, bevels
  car     shape 0 of the synthetic world's cars
Cases: one view at 256 and 512 pixels, eight views at 128 and sixteen at 256 (the paper's two
batches of eight) in one call. ``--cameras axis`` looks along the axes instead (azimuths 0, 90,
180, 270, elevations 0 and 90): symmetric views that put many pixel centres exactly on edges,
where coverage is decided by the exact edge test.

    python benchmarks/bench_rasterize.py [--threads 1] [--repeats 10] [--meshes torus,table]
        [--previous REV] [--busy 1] [--device cpu|cuda] [--case memory] [--cameras axis] [--clock cpu]

Embree (trimesh + embreex, one thread) builds its scene before timing, so only the ray casts and
barycentrics are timed. Ours and Embree are timed in alternation, twice, so both see the same load;
times are the minimum over the repeats (median in brackets); the ratio is ours / Embree (below 1.0:
ours is faster). ``--clock cpu`` times with this process's CPU time instead of the wall clock: on a
machine shared with other jobs it leaves out the time spent descheduled. ``--previous REV`` also
times the rasterizer of git revision REV (its mesh2tex package, extracted by
``benchmarks/previous.py``) in the same process. ``--busy N`` runs N CPU-bound processes (``while
True: pass``) during the measurements. The load average is printed before and after.
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
import torch
import trimesh
from trimesh.ray.ray_pyembree import RayMeshIntersector

from mesh2tex.render import orbit_camera, rasterize, transform_points

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from previous import Revision  # noqa: E402  (this folder)
from resident_memory import reset_peak_rss, status_mib  # noqa: E402  (this folder)
from test_rasterize_reference import bevelled_table, normalised, scan_sphere  # noqa: E402  the same meshes
from test_render_raycast import bumpy_torus, pixel_rays  # noqa: E402

# 16x256: the paper's two batches of 8 views at 256 px in one call
CASES = {"1x256": (1, 256), "1x512": (1, 512), "8x128": (8, 128), "16x256": (16, 256)}
CAMERAS = {  # (azimuths, elevations) of up to sixteen views, degrees; the first eight as before
    "orbit": (
        [30.0 + 45.0 * i for i in range(8)] + [52.5 + 45.0 * i for i in range(8)],
        [25.0, -10.0, 35.0, 5.0, 50.0, -25.0, 15.0, 30.0] + [-5.0, 20.0, 40.0, -15.0, 10.0, 45.0, -30.0, 0.0],
    ),
    "axis": ([0.0, 90.0, 180.0, 270.0, 0.0, 90.0, 180.0, 270.0] * 2, [0.0, 0.0, 0.0, 0.0, 90.0, 90.0, 0.0, 0.0] * 2),
}
CLOCKS = {"wall": time.perf_counter, "cpu": time.process_time}


def world_shape(category: str) -> trimesh.Trimesh:
    from mesh2tex.synthetic.world import WorldSpec, make_shape

    shape = make_shape(WorldSpec(category=category), 0)
    return normalised(shape.vertices, shape.faces)


MESHES = {
    "torus": lambda: normalised(bumpy_torus().vertices, bumpy_torus().faces),
    "table": bevelled_table,
    "scan": scan_sphere,
    "chair": lambda: world_shape("chair"),
    "car": lambda: world_shape("car"),
}


def previous_rasterize(revision: str):
    """``rasterize`` of the mesh2tex package at a git revision (its binning and all)."""
    old = Revision(revision)
    rasterize = old.module("mesh2tex.render.rasterize").rasterize
    rasterize.revision = old  # keeps the extracted files while the function lives
    return rasterize


def embree_cast(intersector, mesh, origins, directions):
    """First hits with barycentrics, the way trimesh users get them."""
    faces, rays, hits = intersector.intersects_id(origins, directions, multiple_hits=False, return_locations=True)
    bary = trimesh.triangles.points_to_barycentric(mesh.triangles[faces], hits)
    face_id = np.full(len(origins), -1, dtype=np.int64)
    face_id[rays] = faces
    return face_id, bary


def timed(fn, repeats, clock=time.perf_counter):
    times = []
    for _ in range(repeats):
        start = clock()
        fn()
        times.append(clock() - start)
    return min(times), float(np.median(times))


def compare(name, mesh, case, repeats, device, previous=None, cameras="orbit", clock="wall"):
    views, size = CASES[case]
    azimuths, elevations = (angles[:views] for angles in CAMERAS[cameras])
    camera = orbit_camera(torch.tensor(azimuths), torch.tensor(elevations), distance=1.6, fov=45.0)
    vertices = torch.tensor(mesh.vertices, dtype=torch.float32, device=device)
    faces = torch.tensor(mesh.faces, device=device)
    pos = transform_points(vertices, camera.mvp.to(device))

    def run(fn):
        def call():
            raster = fn(pos, faces, (size, size))
            if device == "cuda":
                torch.cuda.synchronize()
            return raster

        return call

    ours = run(rasterize)
    rays = [pixel_rays(orbit_camera(a, e, distance=1.6, fov=45.0), (size, size)) for a, e in zip(azimuths, elevations)]
    origins = np.concatenate([o for o, _ in rays])
    directions = np.concatenate([d for _, d in rays])
    intersector = RayMeshIntersector(mesh)
    embree_cast(intersector, mesh, origins[:16], directions[:16])  # builds the scene

    def embree():
        return embree_cast(intersector, mesh, origins, directions)

    contenders = {"ours": ours, "embree": embree} | ({"previous": run(previous)} if previous else {})
    for fn in contenders.values():
        fn()  # warm-up
    agree = (ours().face_id.reshape(-1).cpu().numpy() == embree()[0]).mean()
    times = {key: [] for key in contenders}
    for _ in range(2):  # alternate so that all see the same machine load
        for key, fn in contenders.items():
            times[key].append(timed(fn, repeats, CLOCKS[clock]))
    best = {key: min(value) for key, value in times.items()}
    result = {
        "mesh": name,
        "triangles": len(mesh.faces),
        "case": case,
        "device": device,
        "threads": torch.get_num_threads(),
        "cameras": cameras,
        "clock": clock,
        "face_id_agreement": round(float(agree), 5),
        "ratio": round(best["ours"][0] / best["embree"][0], 3),
    }
    for key, (low, median) in best.items():
        result[f"{key}_ms"], result[f"{key}_median_ms"] = round(low * 1e3, 2), round(median * 1e3, 2)
    line = (
        f"{name:6s} {len(mesh.faces):6d} tris  {case:5s}  ours {result['ours_ms']:7.2f} ms "
        f"({result['ours_median_ms']:7.2f})  embree {result['embree_ms']:7.2f} ms ({result['embree_median_ms']:7.2f})  "
        f"ratio {result['ratio']:5.2f}"
    )
    if previous:
        line += f"  previous {result['previous_ms']:7.2f} ms ({result['previous_median_ms']:7.2f})"
    print(line + f"  ids agree {agree:.3%}", flush=True)
    return result


def memory_case(device):
    """Peak memory of one 1024x1024 render of a 98,304-triangle mesh (run in a fresh process)."""
    mesh = bumpy_torus(384, 128)
    camera = orbit_camera(30.0, 30.0, distance=2.8, fov=45.0)
    vertices = torch.tensor(mesh.vertices, dtype=torch.float32, device=device)
    faces = torch.tensor(mesh.faces, device=device)
    pos = transform_points(vertices, camera.mvp.to(device))
    before = reset_peak_rss()
    if device == "cuda":
        torch.cuda.reset_peak_memory_stats()
    start = time.perf_counter()
    raster = rasterize(pos, faces, (1024, 1024))
    if device == "cuda":
        torch.cuda.synchronize()
    seconds = time.perf_counter() - start
    peak = torch.cuda.max_memory_allocated() / 2**20 if device == "cuda" else status_mib("VmHWM") - before
    covered = float((raster.face_id >= 0).float().mean())
    print(
        json.dumps(
            {
                "case": "memory",
                "triangles": len(mesh.faces),
                "resolution": [1024, 1024],
                "device": device,
                "peak_extra_mib": round(peak, 1),
                "seconds": round(seconds, 3),
                "covered": round(covered, 3),
            }
        )
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--threads", type=int, default=0, help="torch CPU threads (0: torch's default)")
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    parser.add_argument("--meshes", default=",".join(MESHES), help="comma-separated subset of " + ",".join(MESHES))
    parser.add_argument("--cases", default=",".join(CASES), help="comma-separated subset of " + ",".join(CASES))
    parser.add_argument("--previous", default="", help="also time the rasterizer of this git revision")
    parser.add_argument("--busy", type=int, default=0, help="CPU-bound processes to run meanwhile")
    parser.add_argument("--case", default="all", choices=["all", "speed", "memory"])
    parser.add_argument("--cameras", default="orbit", choices=list(CAMERAS), help="orbit views, or along the axes")
    parser.add_argument("--clock", default="wall", choices=list(CLOCKS), help="wall time, or this process's CPU time")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    if args.case == "memory":
        memory_case(args.device)
        return
    previous = previous_rasterize(args.previous) if args.previous else None
    meshes = {name: MESHES[name]() for name in args.meshes.split(",")}
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy)]
    try:
        time.sleep(1.0 if spinners else 0.0)
        print(
            f"torch threads {torch.get_num_threads()}, {args.busy} busy processes, "
            f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores",
            flush=True,
        )
        results = [
            compare(name, mesh, case, args.repeats, args.device, previous, args.cameras, args.clock)
            for name, mesh in meshes.items()
            for case in args.cases.split(",")
        ]
        print(f"load average after: {os.getloadavg()[0]:.2f}")
    finally:
        for process in spinners:
            process.kill()
            process.wait()
    if args.case == "all":
        command = [sys.executable, __file__, "--case", "memory", "--device", args.device]
        if args.threads:
            command += ["--threads", str(args.threads)]
        subprocess.run(command, check=True)
    print(json.dumps(results))


if __name__ == "__main__":
    main()
