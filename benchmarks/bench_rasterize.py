"""Speed of mesh2tex.render.rasterize against first-hit ray casting with Embree, side by side.

Cases (both methods produce face ids and barycentrics for the same pixel centres):
  single  256x256, one view of a 49,152-triangle mesh
  batch   8 views at 128x128 of a 12,288-triangle mesh in one call
  memory  peak memory of a 1024x1024 render of a 98,304-triangle mesh (in a fresh subprocess)

    python benchmarks/bench_rasterize.py [--threads 1] [--repeats 20] [--device cpu|cuda]

Embree (trimesh + embreex) runs on the CPU; its scene is built once before timing, so only the
ray casts and barycentrics are timed. Times are the minimum over the repeats (median in brackets);
the ratio is ours / Embree (below 1.0: ours is faster).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch
import trimesh
from trimesh.ray.ray_pyembree import RayMeshIntersector

from mesh2tex.render import orbit_camera, rasterize, transform_points

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_render_raycast import bumpy_torus, pixel_rays  # noqa: E402  the same meshes and rays


def embree_cast(intersector, mesh, origins, directions):
    """First hits with barycentrics, the way trimesh users get them."""
    faces, rays, hits = intersector.intersects_id(origins, directions, multiple_hits=False,
                                                  return_locations=True)
    bary = trimesh.triangles.points_to_barycentric(mesh.triangles[faces], hits)
    face_id = np.full(len(origins), -1, dtype=np.int64)
    face_id[rays] = faces
    return face_id, bary


def timed(fn, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times), float(np.median(times))


def compare(name, mesh, azimuths, elevations, resolution, repeats, device):
    camera = orbit_camera(torch.tensor(azimuths), torch.tensor(elevations), distance=2.8, fov=45.0)
    vertices = torch.tensor(mesh.vertices, dtype=torch.float32, device=device)
    faces = torch.tensor(mesh.faces, device=device)
    mvp = camera.mvp.to(device)

    def ours():
        raster = rasterize(transform_points(vertices, mvp), faces, resolution)
        if device == "cuda":
            torch.cuda.synchronize()
        return raster

    rays = [pixel_rays(orbit_camera(a, e, distance=2.8, fov=45.0), resolution)
            for a, e in zip(azimuths, elevations)]
    origins = np.concatenate([o for o, _ in rays])
    directions = np.concatenate([d for _, d in rays])
    intersector = RayMeshIntersector(mesh)
    embree_cast(intersector, mesh, origins[:16], directions[:16])  # builds the scene

    def embree():
        return embree_cast(intersector, mesh, origins, directions)

    ours(), embree()  # warm-up
    agree = (ours().face_id.reshape(-1).cpu().numpy() == embree()[0]).mean()
    t_ours, t_embree = [], []
    for _ in range(2):  # interleave so both see the same machine load
        t_ours.append(timed(ours, repeats))
        t_embree.append(timed(embree, repeats))
    best_ours = min(t_ours)
    best_embree = min(t_embree)
    result = {
        "case": name, "triangles": len(mesh.faces), "views": len(azimuths),
        "resolution": list(resolution), "device": device, "threads": torch.get_num_threads(),
        "ours_ms": round(best_ours[0] * 1e3, 2), "ours_median_ms": round(best_ours[1] * 1e3, 2),
        "embree_ms": round(best_embree[0] * 1e3, 2), "embree_median_ms": round(best_embree[1] * 1e3, 2),
        "ratio": round(best_ours[0] / best_embree[0], 3), "face_id_agreement": round(float(agree), 5),
    }
    print(f"{name:6s} {len(mesh.faces):6d} tris {len(azimuths)} x {resolution[0]}x{resolution[1]}  "
          f"ours {result['ours_ms']:7.2f} ms ({result['ours_median_ms']:.2f})  "
          f"embree {result['embree_ms']:7.2f} ms ({result['embree_median_ms']:.2f})  "
          f"ratio {result['ratio']:.3f}  ids agree {agree:.4%}")
    return result


def memory_case(device):
    """Peak memory of one 1024x1024 render of a 98,304-triangle mesh (run in a fresh process)."""
    mesh = bumpy_torus(384, 128)
    camera = orbit_camera(30.0, 30.0, distance=2.8, fov=45.0)
    vertices = torch.tensor(mesh.vertices, dtype=torch.float32, device=device)
    faces = torch.tensor(mesh.faces, device=device)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    if device == "cuda":
        torch.cuda.reset_peak_memory_stats()
    start = time.perf_counter()
    raster = rasterize(transform_points(vertices, camera.mvp.to(device)), faces, (1024, 1024))
    if device == "cuda":
        torch.cuda.synchronize()
    seconds = time.perf_counter() - start
    peak = (torch.cuda.max_memory_allocated() / 2**20 if device == "cuda"
            else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 - before)
    covered = float((raster.face_id >= 0).float().mean())
    print(json.dumps({"case": "memory", "triangles": len(mesh.faces), "resolution": [1024, 1024],
                      "device": device, "peak_extra_mib": round(peak, 1), "seconds": round(seconds, 3),
                      "covered": round(covered, 3)}))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--threads", type=int, default=0, help="torch CPU threads (0: torch's default)")
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    parser.add_argument("--case", default="all", choices=["all", "single", "batch", "memory"])
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    if args.case == "memory":
        memory_case(args.device)
        return
    results = []
    if args.case in ("all", "single"):
        results.append(compare("single", bumpy_torus(192, 128), [30.0], [35.0], (256, 256),
                               args.repeats, args.device))
    if args.case in ("all", "batch"):
        azimuths = [float(a) for a in range(0, 360, 45)]
        elevations = [20.0, -10.0, 35.0, 5.0, 50.0, -25.0, 15.0, 30.0]
        results.append(compare("batch", bumpy_torus(96, 64), azimuths, elevations, (128, 128),
                               args.repeats, args.device))
    if args.case == "all":
        command = [sys.executable, __file__, "--case", "memory", "--device", args.device]
        if args.threads:
            command += ["--threads", str(args.threads)]
        subprocess.run(command, check=True)
    print(json.dumps(results))


if __name__ == "__main__":
    main()
