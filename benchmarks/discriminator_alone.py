"""Can the discriminator tell a generator's renders from the photos when the generator stands still?

    python benchmarks/discriminator_alone.py --run RUN --shapes TRAIN_SHAPES --images PHOTOS [--steps 150]

A fresh discriminator of RUN's config is trained alone (Adam, RUN's rate and betas) against 48 fixed
renders of RUN's checkpoint (6 batches of 2 shapes x 4 views, random backgrounds, as training draws
them) and batches of 8 photos, without and with RUN's DiffAugment. Prints the logistic D loss every
30 steps (2 ln 2 = 1.386 is chance), and the logits of RUN's own discriminator on the same fakes and
a batch of photos. A loss well below chance here, while RUN's metrics.jsonl sits at chance, says the
discriminator could learn and the generator keeps pace with it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mesh2tex.train import runs  # noqa: E402
from mesh2tex.train.gan import GanTrainer, random_cameras  # noqa: E402
from mesh2tex.train.gan_config import TrainGanConfig  # noqa: E402

from mesh2tex.config import load_config  # noqa: E402
from mesh2tex.geometry.prepared import load_shapes  # noqa: E402
from mesh2tex.nn.batch import collate_shapes  # noqa: E402
from mesh2tex.nn.discriminator import Discriminator  # noqa: E402
from mesh2tex.nn.render_texture import render_field_views  # noqa: E402
from mesh2tex.photos import load_photo_collection  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--run", required=True, help="a train gan run directory (its config.yaml and checkpoint)")
    parser.add_argument("--shapes", required=True)
    parser.add_argument("--images", required=True)
    parser.add_argument("--steps", type=int, default=150)
    args = parser.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    cfg = load_config(TrainGanConfig, Path(args.run) / "config.yaml")
    cfg.device = "cpu"
    shapes, _ = load_shapes(args.shapes)
    cfg.generator.input_features = shapes[0].face_features.shape[1]
    run = runs.RunDirectory(args.run)
    trainer = GanTrainer(
        cfg,
        shapes,
        load_photo_collection(args.images, cfg.resolution),
        run,
        torch.device("cpu"),
        runs.Distributed("cpu"),
    )
    trainer.resume(run.checkpoint_path)
    fakes = []
    with torch.no_grad():
        for _ in range(6):
            batch = collate_shapes([shapes[i] for i in torch.randint(len(shapes), (2,)).tolist()])
            ws = trainer.generator.mapping(torch.randn(2, cfg.generator.z_dim))
            out = render_field_views(
                trainer.generator,
                batch,
                ws,
                random_cameras(8, cfg.camera, torch.device("cpu"))[0],
                (cfg.resolution, cfg.resolution),
                torch.rand(8, 3) * 2 - 1,
            )
            fakes.append(out.images)
        fakes = torch.cat(fakes)

        def logits(images):
            return " ".join(f"{v:+.2f}" for v in trainer.d_field(images).tolist())

        print(
            f"iteration {trainer.iteration}: its d_field's logits on fakes {logits(fakes[:8])}; on photos "
            f"{logits(trainer.draw_real(8))}"
        )
    for augment in (False, True):
        d = Discriminator(cfg.resolution, cfg.discriminator)
        opt = torch.optim.Adam(d.parameters(), lr=cfg.optim.lr_discriminator, betas=(cfg.optim.beta1, cfg.optim.beta2))
        view = trainer.loss.augment if augment else (lambda x: x)
        for step in range(1, args.steps + 1):
            fake, real = fakes[torch.randint(len(fakes), (8,))], trainer.draw_real(8)
            loss = F.softplus(d(view(fake))).mean() + F.softplus(-d(view(real))).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
            if step % 30 == 0:
                print(f"augment {augment!s:5}  step {step:4d}  D loss {loss.item():.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
