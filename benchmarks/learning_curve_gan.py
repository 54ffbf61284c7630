"""Learning curve of the texture GAN on the synthetic chairs: sliced Wasserstein distance over time.

    python benchmarks/learning_curve_gan.py --work /tmp/gan_curve [--minutes 30] [--eval-every 100]
                                            [--shapes 10] [--faces 1536] [--levels 4] [--resolution 64] [--threads 1]

Builds (once, under --work) a synthetic chair world and its prepared shapes, then trains with the
default hyperparameters at a CPU-sized scale (finest faces, levels, resolution as given; channel
lists cut to the number of levels) for --minutes of wall-clock time. Every --eval-every iterations
it renders 64 views of the training shapes with the EMA generator (random seeds and poses, white
background) and computes the SWD (x1000, Laplacian-pyramid patches, mesh2tex.metrics.swd) against
64 photos composited on white. Prints the curve and writes it to --work/curve.json. Iteration 0 is
the untrained generator: the figure to beat.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mesh2tex.cli import main as cli  # noqa: E402
from mesh2tex.config import load_config  # noqa: E402
from mesh2tex.metrics.swd import swd  # noqa: E402
from mesh2tex.nn.batch import collate_shapes  # noqa: E402
from mesh2tex.nn.render_texture import render_field_views  # noqa: E402
from mesh2tex.render import orbit_camera  # noqa: E402
from train import runs  # noqa: E402
from train.gan import GanTrainer, TrainGanConfig, composite_real, load_images, load_shapes  # noqa: E402


@torch.no_grad()
def evaluate(trainer: GanTrainer, real: torch.Tensor, count: int = 64, seed: int = 0) -> float:
    """SWD x1000 between ``count`` EMA renders (white background) and ``real`` (N, 3, R, R) in [-1, 1]."""
    g = torch.Generator().manual_seed(seed)
    cfg, res = trainer.cfg, trainer.cfg.resolution
    per_batch, images = 4, []
    for start in range(0, count, per_batch):
        index = torch.randint(len(trainer.shapes), (per_batch,), generator=g).tolist()
        batch = collate_shapes([trainer.shapes[i] for i in index]).to(trainer.device)
        z = torch.randn(per_batch, cfg.generator.z_dim, generator=g).to(trainer.device)
        az = torch.rand(per_batch, generator=g) * 360
        el = cfg.camera.elevation_min + torch.rand(per_batch, generator=g) * (cfg.camera.elevation_max - cfg.camera.elevation_min)
        mvp = orbit_camera(az, el, distance=cfg.camera.distance, fov=cfg.camera.fov).mvp.to(trainer.device)
        out = render_field_views(trainer.ema, batch, trainer.ema.mapping(z), mvp, (res, res), torch.ones(per_batch, 3, device=trainer.device), noise_mode="none")
        images.append(out.images.float().cpu())
    return swd(real, torch.cat(images)[:count])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--work", required=True)
    parser.add_argument("--minutes", type=float, default=30.0)
    parser.add_argument("--eval-every", type=int, default=100)
    parser.add_argument("--shapes", type=int, default=10)
    parser.add_argument("--faces", type=int, default=1536)
    parser.add_argument("--levels", type=int, default=4)
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads (1 is fastest on a shared, busy machine)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    work = Path(args.work)
    world, shapes_dir = work / "world", work / "shapes"
    if not (world / "index.json").is_file() or not list((world / "images").glob("*.png")):
        assert cli(["prepare", "synthetic", "--output", str(world), "--category", "chair", "--shapes", str(args.shapes),
                    "--views", "8", "--resolution", str(args.resolution)]) == 0
    if not list(shapes_dir.glob("*.npz")):
        assert cli(["prepare", "shapes", "--input", str(world / "meshes"), "--output", str(shapes_dir),
                    "--faces", str(args.faces), "--levels", str(args.levels), "--workers", "2"]) == 0
    shapes, _ = load_shapes(shapes_dir)
    photos = load_images(world, args.resolution)
    cfg = load_config(TrainGanConfig, None, {"resolution": args.resolution, "device": "cpu", "seed": args.seed, "iters": 10**9})
    cfg.generator.input_features = shapes[0].face_features.shape[1]
    cfg.generator.encoder_channels = cfg.generator.encoder_channels[: shapes[0].num_levels]
    cfg.generator.synthesis_channels = cfg.generator.synthesis_channels[: shapes[0].num_levels]
    cfg.ema_halflife_images = 500.0  # a short run: let the EMA follow within it
    real = composite_real(photos[:64], torch.ones(min(64, len(photos)), 3))
    trainer = GanTrainer(cfg, shapes, photos, runs.RunDirectory(work / "run"), runs.select_device("cpu"), runs.Distributed("cpu"))
    print(f"{len(shapes)} shapes ({shapes[0].face_counts} faces), {len(photos)} photos at {args.resolution}px, "
          f"{torch.get_num_threads()} threads")
    curve = [{"iteration": 0, "seconds": 0.0, "swd": evaluate(trainer, real)}]
    print(f"iteration {0:6d}  {0.0:8.1f} s  SWD {curve[0]['swd']:.1f} (untrained)")
    start = time.perf_counter()
    train_seconds = 0.0
    while time.perf_counter() - start < args.minutes * 60:
        t = time.perf_counter()
        for _ in range(args.eval_every):
            trainer.step()
        train_seconds += time.perf_counter() - t
        value = evaluate(trainer, real)
        curve.append({"iteration": trainer.iteration, "seconds": round(train_seconds, 1), "swd": value})
        print(f"iteration {trainer.iteration:6d}  {train_seconds:8.1f} s  SWD {value:.1f}", flush=True)
        (work / "curve.json").write_text(json.dumps(curve, indent=1))
    best = min(c["swd"] for c in curve[1:]) if len(curve) > 1 else float("nan")
    print(f"untrained SWD {curve[0]['swd']:.1f}; final {curve[-1]['swd']:.1f}; best {best:.1f}; "
          f"final / untrained = {curve[-1]['swd'] / curve[0]['swd']:.2f}")


if __name__ == "__main__":
    main()
