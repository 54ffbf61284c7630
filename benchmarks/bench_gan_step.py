"""Seconds per training iteration and peak memory of ``train gan`` at its default configuration.

    python benchmarks/bench_gan_step.py [--iters 8] [--device auto|cpu|cuda] [--faces 6144]
                                        [--batch 2] [--views 4] [--resolution 128] [--config YAML] [--threads N]

Two procedural chairs are prepared (quad hierarchy of --faces faces), the trainer is built with the
default config (or --config) and a random photo set, one warm-up iteration runs, then --iters timed
iterations. Iterations with the lazy regularisers (path length every 4, R1 every 16) are slower;
the script prints the mean over main-only iterations, over iterations with the path-length term,
the amortised mean of the schedule, and its ratio to the 2 s target.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mesh2tex.config import load_config  # noqa: E402
from mesh2tex.geometry.prepare import prepare_shape  # noqa: E402
from mesh2tex.synthetic.shapes import generate_shape  # noqa: E402
from train import runs  # noqa: E402
from train.gan import GanTrainer, TrainGanConfig  # noqa: E402

TARGET_SECONDS = 2.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--iters", type=int, default=8)
    parser.add_argument("--device", default="auto")
    parser.add_argument("--faces", type=int, default=6144)
    parser.add_argument("--batch", type=int, default=2)
    parser.add_argument("--views", type=int, default=4)
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--config")
    parser.add_argument("--threads", type=int, default=0, help="torch CPU threads (0: torch's default)")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)

    t0 = time.perf_counter()
    shapes = []
    for i in range(2):
        mesh = generate_shape("chair", np.random.default_rng(i))
        shapes.append(prepare_shape(mesh.vertices, mesh.faces, face_count=args.faces, levels=5, seed=0))
    print(f"prepared 2 chairs in {time.perf_counter() - t0:.1f} s; finest faces {[s.face_counts[0] for s in shapes]}")

    cfg = load_config(TrainGanConfig, args.config, {"batch": args.batch, "views": args.views, "resolution": args.resolution,
                                                     "device": args.device, "iters": 10**9})
    cfg.generator.input_features = shapes[0].face_features.shape[1]
    device = runs.select_device(cfg.device)
    rng = np.random.default_rng(0)
    images = torch.from_numpy(rng.integers(0, 256, (32, 4, cfg.resolution, cfg.resolution), dtype=np.uint8))
    with tempfile.TemporaryDirectory() as tmp:
        trainer = GanTrainer(cfg, shapes, images, runs.RunDirectory(tmp), device, runs.Distributed("cpu"))
        params = sum(p.numel() for p in trainer.generator.parameters())
        dparams = sum(p.numel() for p in trainer.d_field.parameters())
        print(f"device {device}, threads {torch.get_num_threads()}, generator {params / 1e6:.2f} M parameters, each discriminator {dparams / 1e6:.2f} M")
        trainer.step()  # warm-up (iteration 0 runs every regulariser)
        main_only, with_pl = [], []
        for _ in range(args.iters):
            due = {phase for phase, _ in trainer.loss.phases(trainer.iteration)}
            if device.type == "cuda":
                torch.cuda.synchronize()
            start = time.perf_counter()
            trainer.step()
            if device.type == "cuda":
                torch.cuda.synchronize()
            seconds = time.perf_counter() - start
            (with_pl if "Greg" in due else main_only).append(seconds)
        peak = runs.peak_memory_gb(device)
    lc = cfg.loss
    m = statistics.mean(main_only) if main_only else float("nan")
    p = statistics.mean(with_pl) if with_pl else m
    amortised = m + (p - m) / lc.pl_interval
    print(f"seconds per iteration: main phases {m:.3f} (n={len(main_only)}), with path-length reg {p:.3f} (n={len(with_pl)}), "
          f"amortised {amortised:.3f}")
    print(f"peak memory {peak:.2f} GB ({'CUDA allocator' if device.type == 'cuda' else 'process RSS'})")
    print(f"ratio to the {TARGET_SECONDS:.0f} s target: {amortised / TARGET_SECONDS:.2f}")


if __name__ == "__main__":
    main()
