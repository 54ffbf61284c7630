"""Rendering on a device against the CPU: rasterize + interpolate, forward and backward, in one process.

    python benchmarks/bench_render_device.py [--device cuda] [--repeats 10] [--threads 0]

A 12,288-triangle bumpy torus (``tests/test_render_raycast.py``) in 8 views at 256 and 512 pixels:
``rasterize`` (no gradients: it returns face ids and barycentrics), then ``interpolate`` of a
per-vertex colour with gradients, and the backward pass of the mean colour. Prints milliseconds per
call (minimum over the repeats, median in brackets) on the CPU and, where given and available, on
``--device``, their ratio, and how far the two devices' face ids and barycentrics agree.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from test_render_raycast import bumpy_torus  # noqa: E402

from mesh2tex.render import interpolate, orbit_camera, rasterize, transform_points  # noqa: E402

VIEWS = 8
SIZES = (256, 512)


def render_step(vertices: torch.Tensor, faces: torch.Tensor, colours: torch.Tensor, mvp: torch.Tensor, size: int):
    """One forward and backward pass: (raster, gradient of the mean interpolated colour w.r.t. the colours)."""
    colours = colours.detach().requires_grad_(True)
    raster = rasterize(transform_points(vertices, mvp), faces, (size, size))
    image = interpolate(colours, raster, faces)  # (B, H, W, 3)
    image.mean().backward()
    return raster, colours.grad


def timed(fn, repeats: int, device: str) -> tuple[float, float]:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        if device == "cuda":
            torch.cuda.synchronize()
        times.append(time.perf_counter() - start)
    return min(times) * 1e3, statistics.median(times) * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--device", default="cuda", help="the device set beside the CPU (cuda; skipped where unavailable)"
    )
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--threads", type=int, default=0, help="torch CPU threads (0: torch's default)")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    devices = ["cpu"] + ([args.device] if args.device != "cpu" and torch.cuda.is_available() else [])
    if len(devices) == 1 and args.device != "cpu":
        print(f"{args.device} is not available here: CPU figures only")
    mesh = bumpy_torus(96, 64)
    camera = orbit_camera(
        torch.tensor([30.0 + 45.0 * i for i in range(VIEWS)]), torch.tensor([20.0] * VIEWS), distance=3.6, fov=45.0
    )
    results = []
    for size in SIZES:
        outputs, row = {}, {"triangles": len(mesh.faces), "views": VIEWS, "size": size}
        for device in devices:
            vertices = torch.tensor(mesh.vertices, dtype=torch.float32, device=device)
            faces = torch.tensor(mesh.faces, device=device)
            colours = torch.rand(len(mesh.vertices), 3, generator=torch.Generator().manual_seed(0)).to(device)
            mvp = camera.mvp.to(device)

            def step():
                return render_step(vertices, faces, colours, mvp, size)

            outputs[device] = step()  # warm-up, and the result compared below
            row[f"{device}_ms"], row[f"{device}_median_ms"] = (round(t, 2) for t in timed(step, args.repeats, device))
        line = f"{VIEWS}x{size}  {len(mesh.faces)} tris  cpu {row['cpu_ms']:8.2f} ms ({row['cpu_median_ms']:8.2f})"
        if len(devices) == 2:
            device = devices[1]
            (cpu_raster, cpu_grad), (dev_raster, dev_grad) = outputs["cpu"], (tuple(t for t in outputs[device]))
            same = cpu_raster.face_id == dev_raster.face_id.cpu()
            row["speed_up"] = round(row["cpu_ms"] / row[f"{device}_ms"], 2)
            row["face_id_agreement"] = round(float(same.float().mean()), 6)
            row["max_bary_difference"] = float((cpu_raster.bary - dev_raster.bary.cpu())[same].abs().max())
            row["max_grad_difference"] = float((cpu_grad - dev_grad.cpu()).abs().max())
            line += (
                f"  {device} {row[f'{device}_ms']:7.2f} ms ({row[f'{device}_median_ms']:7.2f})  cpu / {device} "
                f"{row['speed_up']:6.2f}"
                f"  ids agree {row['face_id_agreement']:.4%}  max bary diff {row['max_bary_difference']:.2e}"
            )
        print(line, flush=True)
        results.append(row)
    print(json.dumps(results))


if __name__ == "__main__":
    main()
