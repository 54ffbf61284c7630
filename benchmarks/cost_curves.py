"""Cost curves: seconds and peak memory of every stage against its size, and the exponent of each on a log-log scale.

    python benchmarks/cost_curves.py [--case NAME ...] [--threads 2] [--quick] [--json PATH] [--plot PNG]
                                     [--limit 900]

Each size runs in a fresh child process (this script with ``--child``), so that its peak resident
memory is its own and no case's caches help another. The child builds its inputs, then resets the
kernel's peak-RSS mark (``/proc/self/clear_refs``) and measures: ``peak MB`` is the peak resident
memory of the measured part (this process, or a process it forked, whichever is larger), ``added MB``
that peak less the resident memory just before it (the memory the work itself adds), ``cores`` the
CPU seconds of the measured part over its wall seconds (fewer than the threads asked for: serial
work, or a busy machine). Cases:

  prepare        ``prepare shapes`` (``data_prep.shapes.prepare_one``: load, prepare, save) of chair 0 of
                 the synthetic world subdivided to about 10k, 100k and 1M triangles, at the default
                 6144 quads and 5 levels
  gan_step       one ``train gan`` iteration, main phases (``benchmarks/bench_gan_step.py``'s trainer,
                 batch 2): over 1.5k / 6k / 24k quads (128 px, 4 views), 64 / 128 / 256 px (6k quads)
                 and 4 / 8 views; the mean of the timed iterations after one warm-up iteration that
                 runs every lazy regulariser (so the peak is the training's, regularisers included);
                 then the FLOPs of a main-only and a path-length iteration (``flop_account``)
  generate_bake  the shipped chair model's texture baked onto a user's mesh (``bench_bake.timed_bake``):
                 the user bake (map + colours + write) over the mesh's triangles (10k / 100k / 1M at
                 1024^2 texels) and over texels (512^2 / 1024^2 / 2048^2 at 100k triangles)
  transfer       ``benchmarks/bench_transfer.py`` at 64 / 128 / 256 px, a few iterations per stage:
                 seconds per iteration over both stages (latent and refine)
  nca_step       ``benchmarks/bench_nca_step.py`` over cells (cube-sphere subdivisions 16 to 128):
                 seconds per automaton step
  rasterize      ``mesh2tex.render.rasterize``, one view of a bumpy blob (``bench_bake.blob_mesh``):
                 over triangles (10k / 100k / 1M at 512 px) and pixels (128 to 1024 px at 100k)

``--quick`` runs the two smallest sizes of each sweep (a smoke test). A child that runs past
``--limit`` seconds is stopped and the larger sizes of its sweep are skipped. For each sweep a
table (size, seconds, peak MB, added MB, cores) and the exponents fitted by least squares on log-log
(time; added memory), each with a one-line verdict, and the exponent of the CPU seconds (seconds x
cores), which a busy machine distorts less than the wall clock.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))  # bench_gan_step, bench_bake, ... are imported, not copied
from cost_children import CHILDREN, MARK, child_main  # noqa: E402  (this folder)


@dataclass
class Sweep:
    """One swept quantity of a case: the parameters of each size, and what the size counts."""

    name: str  # e.g. "quads", "pixels"
    points: list[dict]
    unit: str = ""  # what "size" counts, for the verdict (default: name)
    results: list[dict] = field(default_factory=list)


def sweeps(quick: bool) -> dict[str, list[Sweep]]:
    """Every case's sweeps; with ``quick`` the two smallest sizes of each."""
    gan = lambda faces=6144, resolution=128, views=4: {"faces": faces, "resolution": resolution, "views": views}
    out = {
        "prepare": [Sweep("triangles", [{"triangles": t} for t in (10_000, 100_000, 1_000_000)])],
        "gan_step": [
            Sweep("quads", [gan(faces=f) for f in (1536, 6144, 24576)]),
            Sweep("pixels", [gan(resolution=r) for r in (64, 128, 256)], "pixels per view"),
            Sweep("views", [gan(views=v) for v in (4, 8)]),
        ],
        "generate_bake": [
            Sweep("triangles", [{"triangles": t, "size": 1024} for t in (10_000, 100_000, 1_000_000)]),
            Sweep("texels", [{"triangles": 100_000, "size": s} for s in (512, 1024, 2048)]),
        ],
        "transfer": [Sweep("pixels", [{"resolution": r} for r in (64, 128, 256)], "pixels per view")],
        "nca_step": [Sweep("cells", [{"subdivisions": s} for s in (16, 32, 64, 128)])],
        "rasterize": [
            Sweep("triangles", [{"triangles": t, "size": 512} for t in (10_000, 100_000, 1_000_000)]),
            Sweep("pixels", [{"triangles": 100_000, "size": s} for s in (128, 256, 512, 1024)]),
        ],
    }
    if quick:
        for case in out.values():
            for sweep in case:
                sweep.points = sweep.points[:2]
    return out


# ---------------------------------------------------------------------------------------- fitting
def fit_exponent(sizes, values) -> float:
    """Least-squares slope of log(values) against log(sizes): the p of values ~ c * sizes^p (nan under two points)."""
    x, y = np.log(np.asarray(sizes, dtype=float)), np.log(np.asarray(values, dtype=float))
    keep = np.isfinite(x) & np.isfinite(y)
    if keep.sum() < 2 or np.ptp(x[keep]) == 0:
        return float("nan")
    return float(np.polyfit(x[keep], y[keep], 1)[0])


def verdict(exponent: float, unit: str) -> str:
    """One line naming the growth, e.g. "linear in faces: exponent 1.02"."""
    if not np.isfinite(exponent):
        return f"not fitted in {unit}: fewer than two sizes"
    kinds = [
        (0.2, "flat (nearly constant)"),
        (0.8, "sublinear"),
        (1.2, "linear"),
        (1.8, "superlinear"),
        (2.2, "quadratic"),
    ]
    kind = next((name for bound, name in kinds if exponent < bound), "worse than quadratic")
    return f"{kind} in {unit}: exponent {exponent:.2f}"


def table(case: str, sweep: Sweep) -> str:
    """The sweep's rows (size, seconds, peak MB, added MB, cores) and its fitted exponents with their verdicts."""
    lines = [
        f"{case} over {sweep.name}",
        f"  {'size':>10s} {'seconds':>9s} {'peak MB':>8s} {'added MB':>9s} {'cores':>5s}  params",
    ]
    for r in sweep.results:
        if r.get("status") != "ok":
            lines.append(f"  {'-':>10s} {'-':>9s} {'-':>8s} {'-':>9s} {'-':>5s}  {r['params']}  {r.get('status')}")
            continue
        lines.append(
            f"  {r['size']:10,d} {r['seconds']:9.4f} {r['peak_mb']:8.0f} {r['added_mb']:9.0f} "
            f"{r.get('cores', float('nan')):5.2f}  {r['params']}"
        )
    fit = fit_sweep(sweep)
    lines.append(
        f"  time:   {fit['time_verdict']} (CPU seconds, seconds x cores: exponent {fit['cpu_time_exponent']:.2f})"
    )
    lines.append(
        f"  memory: {fit['memory_verdict']} (added MB; the whole peak: exponent {fit['peak_memory_exponent']:.2f})"
    )
    return "\n".join(lines)


def fit_sweep(sweep: Sweep) -> dict:
    """The exponents of a sweep's measured sizes: time, added memory (floored at 1 MB) and peak memory, with
    verdicts."""
    ok = [r for r in sweep.results if r.get("status") == "ok"]
    sizes, unit = [r["size"] for r in ok], sweep.unit or sweep.name
    time_exp = fit_exponent(sizes, [r["seconds"] for r in ok])
    memory_exp = fit_exponent(sizes, [max(r["added_mb"], 1.0) for r in ok])
    return {
        "time_exponent": time_exp,
        "added_memory_exponent": memory_exp,
        "cpu_time_exponent": fit_exponent(sizes, [r["seconds"] * r["cores"] for r in ok]),
        "peak_memory_exponent": fit_exponent(sizes, [r["peak_mb"] for r in ok]),
        "time_verdict": verdict(time_exp, unit),
        "memory_verdict": verdict(memory_exp, unit),
    }


# ---------------------------------------------------------------------------------- child side
# --------------------------------------------------------------------------------- parent side
def run_child(case: str, params: dict, threads: int, limit: float) -> dict:
    """One size in a fresh process (under ``timeout``): the child's result, its wall seconds and whole-process peak."""
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), MKL_NUM_THREADS=str(threads))
    command = [
        "timeout",
        "--signal=KILL",
        str(int(limit)),
        sys.executable,
        str(Path(__file__).resolve()),
        "--child",
        case,
        "--params",
        json.dumps(params),
        "--threads",
        str(threads),
    ]
    start = time.perf_counter()
    with tempfile.TemporaryFile("w+") as errors:
        process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=errors, text=True, cwd=ROOT, env=env)
        out = process.stdout.read()
        _, status, usage = os.wait4(process.pid, 0)  # this child's own rusage, not every child's so far
        process.returncode = os.waitstatus_to_exitcode(status)
        errors.seek(0)
        tail = errors.read()[-2000:]
    wall = time.perf_counter() - start
    lines = [line[len(MARK) :] for line in out.splitlines() if line.startswith(MARK)]
    if process.returncode != 0 or not lines:
        status_text = (
            f"timed out after {limit:.0f} s"
            if process.returncode in (124, 137, -9)
            else f"failed (exit {process.returncode})"
        )
        print(f"    {case} {params}: {status_text}\n{tail}", flush=True)
        return {"params": params, "status": status_text, "wall_s": wall}
    result = json.loads(lines[-1])
    result.update(params=params, wall_s=wall, process_peak_mb=usage.ru_maxrss / 1024)
    return result


def measure(cases: dict[str, list[Sweep]], threads: int, limit: float) -> None:
    """Run every size of every sweep (a configuration shared by sweeps runs once); stop a sweep after a failure."""
    done: dict[str, dict] = {}
    for case, case_sweeps in cases.items():
        for sweep in case_sweeps:
            for params in sweep.points:
                key = json.dumps([case, params], sort_keys=True)
                if key not in done:
                    print(f"  {case} {params} ...", flush=True)
                    done[key] = run_child(case, params, threads, limit)
                result = dict(done[key])
                if isinstance(result.get("size"), dict):
                    result["size"] = result["size"][sweep.name]
                sweep.results.append(result)
                if result.get("status", "").startswith("timed out"):
                    break  # the larger sizes would run longer still
            print(table(case, sweep), flush=True)


def summarise(cases: dict[str, list[Sweep]]) -> dict:
    """All figures as plain data, with each sweep's exponents."""
    out = {}
    for case, case_sweeps in cases.items():
        out[case] = []
        for sweep in case_sweeps:
            out[case].append(
                {"sweep": sweep.name, "unit": sweep.unit or sweep.name, "results": sweep.results} | fit_sweep(sweep)
            )
    return out


def plot(summary: dict, path: str, panel: int = 360) -> None:
    """Log-log curves, one panel per case: each sweep's seconds (filled dots) and added MB (hollow squares)
    relative to its smallest size, with reference slopes 1 and 2 in grey; PIL only."""
    from PIL import Image, ImageDraw, ImageFont

    colours = [(31, 119, 180), (214, 39, 40), (44, 160, 44), (148, 103, 189)]
    font = ImageFont.load_default(size=12)
    cols, rows = 3, (len(summary) + 2) // 3
    image = Image.new("RGB", (cols * panel, rows * panel), "white")
    draw = ImageDraw.Draw(image)
    span = 3.0  # decades shown on each axis: 10^0 .. 10^3 of the smallest size's figure
    for k, (case, case_sweeps) in enumerate(summary.items()):
        x0, y0 = (k % cols) * panel + 50, (k // cols) * panel + 30
        w, h = panel - 70, panel - 120
        to_xy = lambda x, y: (x0 + w * x / span, y0 + h - h * (y + 0.5) / (span + 0.5))
        draw.rectangle([x0, y0, x0 + w, y0 + h], outline="black")
        for slope in (1, 2):
            draw.line([to_xy(0, 0), to_xy(span / slope, span)], fill=(200, 200, 200), width=1)
            draw.text(to_xy(2.2 / slope + 0.08, 2.2), f"slope {slope}", fill=(150, 150, 150), font=font)
        for d in range(int(span) + 1):
            draw.text((to_xy(d, 0)[0] - 8, y0 + h + 4), f"1e{d}", fill="black", font=font)
            draw.text((x0 - 34, to_xy(0, d)[1] - 6), f"1e{d}", fill="black", font=font)
        draw.text((x0, y0 - 22), case, fill="black", font=font)
        for j, sweep in enumerate(case_sweeps):
            ok = [r for r in sweep["results"] if r.get("status") == "ok"]
            if len(ok) < 2:
                continue
            colour = colours[j % len(colours)]
            xs = np.log10(np.array([r["size"] for r in ok]) / ok[0]["size"])
            for values, filled in (([r["seconds"] for r in ok], True), ([max(r["added_mb"], 1.0) for r in ok], False)):
                points = [to_xy(x, y) for x, y in zip(xs, np.log10(np.array(values) / values[0]))]
                draw.line(points, fill=colour, width=2 if filled else 1)
                for px, py in points:
                    shape = draw.ellipse if filled else draw.rectangle
                    shape([px - 3, py - 3, px + 3, py + 3], fill=colour if filled else None, outline=colour)
            draw.text(
                (x0, y0 + h + 34 + 14 * j),
                f"{sweep['unit']}: time {sweep['time_exponent']:.2f}, mem {sweep['added_memory_exponent']:.2f}",
                fill=colour,
                font=font,
            )
        draw.text((x0, y0 + h + 18), "x: size / smallest; y: value / smallest", fill=(90, 90, 90), font=font)
    image.save(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--case", action="append", choices=list(CHILDREN), help="a case to run (repeatable; default: all)"
    )
    parser.add_argument("--threads", type=int, default=2, help="torch (and OpenMP) threads of each child")
    parser.add_argument("--quick", action="store_true", help="the two smallest sizes of each sweep")
    parser.add_argument("--json", help="write every figure here")
    parser.add_argument("--plot", help="write the log-log curves here (PNG)")
    parser.add_argument("--limit", type=float, default=900.0, help="seconds a child may run before it is stopped")
    parser.add_argument("--child", choices=list(CHILDREN), help=argparse.SUPPRESS)
    parser.add_argument("--params", default="{}", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child_main(args.child, json.loads(args.params), args.threads)
        return
    cases = {name: s for name, s in sweeps(args.quick).items() if not args.case or name in args.case}
    load_before, start = os.getloadavg(), time.perf_counter()
    print(
        f"{args.threads} thread(s) per child; load average {load_before[0]:.2f} on {os.cpu_count()} cores", flush=True
    )
    measure(cases, args.threads, args.limit)
    wall, load_after = time.perf_counter() - start, os.getloadavg()
    summary = summarise(cases)
    print(f"\nsweep wall time {wall:.0f} s; load average before {load_before[0]:.2f}, after {load_after[0]:.2f}")
    print(f"{'case':14s} {'sweep':16s} {'time exp':>8s} {'mem exp':>8s}  verdict (time)")
    for case, rows in summary.items():
        for row in rows:
            print(
                f"{case:14s} {row['unit']:16s} {row['time_exponent']:8.2f} {row['added_memory_exponent']:8.2f}  "
                f"{row['time_verdict']}"
            )
    if args.json:
        Path(args.json).write_text(
            json.dumps(
                {
                    "threads": args.threads,
                    "quick": args.quick,
                    "wall_s": wall,
                    "load_before": load_before,
                    "load_after": load_after,
                    "cases": summary,
                },
                indent=1,
                default=float,
            )
        )
    if args.plot:
        plot(summary, args.plot)


if __name__ == "__main__":
    main()
