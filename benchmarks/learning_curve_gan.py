"""Learning curve of a texture GAN run: the generation protocol at each kept generator.

    python benchmarks/learning_curve_gan.py --run RUN --world WORLD --shapes HELD_OUT_SHAPES
        [--checkpoints FILE...] [--views 8] [--latents 8] [--max-shapes 0] [--json curve.json] [--threads 1]
        [--split held_out|train] [--seed 0] [--truncation 1.0] [--generator-render photo|direct]

RUN is a ``mesh2tex train gan`` run directory; its generators are ``RUN/snapshots/*.safetensors``
(``snapshot_every`` in the training config) unless ``--checkpoints`` names files (any GAN
checkpoints: snapshots, training checkpoints, shipped models). Each one goes through the
generation protocol of ``mesh2tex evaluate --generation`` (:mod:`mesh2tex.evaluation.generation`) on the world's
held-out shapes (or, with ``--split train`` and --shapes the prepared training shapes, on the
shapes the GAN trained on), without KID/FID: the gap closed on log object SWD (0 untrained, 1 the ground
truth) against the protocol's fresh photo set, the same on the colour histogram, the gap closed
against the training photos (``gap_photos``: the protocol's reference before the fresh photo set,
for comparison with earlier curves), and the colour diversity across latents against the photo set's. Wall time is read
from RUN/metrics.jsonl (seconds since the run's first record, resumed runs included). Prints one line per generator and
writes the curve to --json."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

# noqa: E402
from mesh2tex.evaluation.generation import (
    GENERATOR_RENDERS,
    LIGHTING_MODES,
    SPLITS,
    GenerationConfig,
    run_generation_protocol,
)
from mesh2tex.io.checkpoint import read_checkpoint_meta  # noqa: E402


def wall_seconds(run: Path) -> dict[int, float]:
    """iteration -> seconds since the first metrics record of ``run`` (training time, pauses between resumes
    removed)."""
    path = run / "metrics.jsonl"
    if not path.is_file():
        return {}
    records = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    out, elapsed, last = {}, 0.0, None
    for record in records:
        if last is not None:
            gap = record["time"] - last["time"]
            rate = record.get("iters_per_second") or 0
            expected = (record["iteration"] - last["iteration"]) / rate if rate else gap
            elapsed += min(gap, 3 * expected + 60)  # a pause between a stop and a --resume does not count
        out[int(record["iteration"])] = elapsed
        last = record
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--run", required=True)
    parser.add_argument("--world", required=True)
    parser.add_argument("--shapes", required=True, help="prepared held-out shapes of the world")
    parser.add_argument("--checkpoints", nargs="*")
    parser.add_argument("--views", type=int, default=8)
    parser.add_argument("--latents", type=int, default=8)
    parser.add_argument("--max-shapes", type=int, default=0)
    parser.add_argument("--json")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument(
        "--seed",
        type=int,
        default=0,
        help="the protocol's seed: latents, untrained weights, material draws, SWD sampling",
    )
    parser.add_argument(
        "--truncation",
        type=float,
        default=1.0,
        help="truncation psi of the generators' latents (evaluate --generation's option)",
    )
    parser.add_argument(
        "--gan-lighting",
        choices=LIGHTING_MODES,
        default="auto",
        help="the generator's rows lit, unlit, or as the run was trained (evaluate --generation's option)",
    )
    parser.add_argument(
        "--generator-render",
        choices=list(GENERATOR_RENDERS),
        default="photo",
        help="the generator's rows rendered as the oracle is (photo), or by the GAN's own renderer (direct; evaluate "
        "--generation's option)",
    )
    parser.add_argument(
        "--split",
        choices=list(SPLITS),
        default="held_out",
        help="the world's shapes measured: held_out, or train (--shapes the prepared training shapes; evaluate "
        "--generation's option)",
    )
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    run = Path(args.run)
    paths = (
        [Path(p) for p in args.checkpoints] if args.checkpoints else sorted((run / "snapshots").glob("*.safetensors"))
    )
    if not paths:
        sys.exit(
            f"{run / 'snapshots'}: no generators to evaluate (set snapshot_every in the training config, or pass "
            "--checkpoints)"
        )
    paths.sort(key=lambda p: read_checkpoint_meta(p)["meta"]["iteration"])
    seconds = wall_seconds(run)
    cfg = GenerationConfig(
        views=args.views,
        latents=args.latents,
        kid_fid=False,
        max_shapes=args.max_shapes,
        lighting=args.gan_lighting,
        split=args.split,
        seed=args.seed,
        truncation=args.truncation,
        generator_render=args.generator_render,
    )
    curve = []
    print(
        f"{'iteration':>9} {'hours':>6} {'objSWD':>7} {'oracle':>7} {'untrained':>9} {'gap':>5} {'gap_hist':>8} "
        f"{'gap_photos':>10} {'div/photos':>10} {'pair/materials':>14}"
    )
    for path in paths:
        r = run_generation_protocol(args.world, args.shapes, path, cfg, log=lambda line: None)
        d, rows = r["diversity"], r["rows"]
        point = {
            "checkpoint": str(path),
            "iteration": r["iteration"],
            "seconds": seconds.get(r["iteration"]),
            "object_swd": rows["trained"]["object_swd"],
            "oracle_object_swd": rows["oracle"]["object_swd"],
            "untrained_object_swd": rows["untrained"]["object_swd"],
            "gap_closed": r["gap_closed"],
            "gap_closed_histogram": r["gap_closed_histogram"],
            "gap_closed_vs_photos": r["gap_closed_vs_photos"],
            "gap_closed_training_materials": r["gap_closed_training_materials"],
            "spread_vs_photo_set": d["trained_spread_vs_photo_set"],
            "pairwise_vs_materials": d["trained_pairwise_vs_materials"],
        }
        curve.append(point)
        hours = f"{point['seconds'] / 3600:6.2f}" if point["seconds"] is not None else "     ?"
        print(
            f"{point['iteration']:9d} {hours} {point['object_swd']:7.1f} {point['oracle_object_swd']:7.1f} "
            f"{point['untrained_object_swd']:9.1f} {point['gap_closed']:5.2f} {point['gap_closed_histogram']:8.2f} "
            f"{point['gap_closed_vs_photos']:10.2f} "
            f"{point['spread_vs_photo_set']:10.2f} {point['pairwise_vs_materials']:14.2f}",
            flush=True,
        )
        if args.json:
            Path(args.json).write_text(json.dumps(curve, indent=1))


if __name__ == "__main__":
    main()
