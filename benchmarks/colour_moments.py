"""How far a generator's colours are from the photos', and how much of its object SWD that explains.

    python benchmarks/colour_moments.py --world WORLD --shapes HELD_OUT_SHAPES CHECKPOINT... [--live-out DIR]
    [--threads 2]

Each CHECKPOINT is any GAN checkpoint (snapshot, shipped model, training checkpoint: its EMA
generator); ``RUN/checkpoint.safetensors@live`` takes a training checkpoint's live generator instead,
and with ``--live-out`` also writes it there as an inference snapshot (for
``benchmarks/learning_curve_gan.py --checkpoints``). For each, on the world's held-out shapes (8
views, a latent per view, the views' lights, as the generation protocol renders them) against one
draw of the protocol's fresh photo set, it prints the CIELAB mean lightness and chroma of the object
pixels, and the object SWD of the renders as they are and after their object colours are moved,
channel by channel in CIELAB, to the photo set's mean and standard deviation; the same for the oracle
(the world's own materials, as the protocol draws them) and the flat-colour baseline; and the
lightness and chroma of the training photos, which the GANs learnt from. The moved renders are a
diagnosis, not a generator: they take the reference's own moments.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch
from kornia.color import lab_to_rgb

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

# noqa: E402
from mesh2tex.evaluation.generation import read_world, sample_views
from mesh2tex.evaluation.generation_renders import (
    ORACLE_STREAM,
    draw_key,
    fresh_photo_set,
    generator_renders,
    material_draws,
)
from mesh2tex.geometry.prepared import PreparedShape  # noqa: E402
from mesh2tex.io.checkpoint import load_checkpoint  # noqa: E402
from mesh2tex.metrics.generation import object_set_swd, srgb_to_lab  # noqa: E402
from mesh2tex.models import load_generator, save_inference_checkpoint  # noqa: E402
from mesh2tex.models.store import GENERATOR  # noqa: E402
from mesh2tex.photos import list_images, load_set  # noqa: E402
from mesh2tex.render import composite_images  # noqa: E402


def object_lab(images: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
    """(B, 3, R, R) in [0, 1], masks (B, 1, R, R) -> CIELAB of the object pixels (3, P)."""
    return srgb_to_lab(images).permute(1, 0, 2, 3)[:, masks[:, 0] > 0.5]


def moved_to(
    images: torch.Tensor, masks: torch.Tensor, reference: torch.Tensor, reference_masks: torch.Tensor
) -> torch.Tensor:
    """``images`` with their object pixels' CIELAB mean and std moved, per channel, to the reference's."""
    lab = srgb_to_lab(images).permute(1, 0, 2, 3).clone()  # (3, B, R, R)
    inside = masks[:, 0] > 0.5
    x, y = lab[:, inside], object_lab(reference, reference_masks)
    lab[:, inside] = (x - x.mean(1, keepdim=True)) / x.std(1, keepdim=True).clamp(min=1e-6) * y.std(
        1, keepdim=True
    ) + y.mean(1, keepdim=True)
    return lab_to_rgb(lab.permute(1, 0, 2, 3)).clamp(0, 1) * masks + (1 - masks)


def load(spec: str, live_out: Path | None):
    """A checkpoint spec (PATH or PATH@live) -> (EMA or live generator, label)."""
    path, _, which = spec.partition("@")
    model = load_generator(path, torch.device("cpu"))
    generator, meta = model.network, model.meta
    if which != "live":
        return generator, f"{path} (EMA)"
    groups, _ = load_checkpoint(path, kind="gan")
    if GENERATOR not in groups:
        sys.exit(f"{path}: not a training checkpoint (it holds no live generator)")
    generator.load_state_dict(groups[GENERATOR])
    if live_out is not None:
        live_out.mkdir(parents=True, exist_ok=True)
        target = live_out / f"{Path(path).parent.name}_live_iter{int(meta['iteration']):07d}.safetensors"
        save_inference_checkpoint(
            target,
            "gan",
            groups[GENERATOR],
            {k: meta[k] for k in ("iteration", "config", "generator_config", "world_size") if k in meta},
        )
        print(f"wrote {target}")
    return generator, f"{path} (live)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--world", required=True)
    parser.add_argument("--shapes", required=True, help="the world's prepared held-out shapes")
    parser.add_argument("checkpoints", nargs="+")
    parser.add_argument("--live-out", type=Path)
    parser.add_argument("--views", type=int, default=8)
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    world = read_world(args.world)
    photos, photo_masks = fresh_photo_set(world, args.resolution, draw_key(args.seed, 0))
    shapes = {name: PreparedShape.load(Path(args.shapes) / f"{name}.npz") for name in world.held_out}
    lab = object_lab(photos, photo_masks)
    chroma = lambda lab_: lab_[1:].norm(dim=0).mean().item()  # noqa: E731
    print(f"{'generator':<70} {'L':>5} {'chroma':>6} {'object SWD':>10} {'moved':>7}")
    print(f"{'fresh photo set (reference)':<70} {lab[0].mean().item():5.1f} {chroma(lab):6.1f}")
    # The photos the GAN learnt from, read as the protocol reads them (on white, resized): not the reference.
    training, training_masks = load_set(
        world.root / "images", "image", args.resolution, 1.0, masks=list_images(world.root / "masks", "mask")
    )
    lab = object_lab(training, training_masks)
    print(f"{'training photos (what the GAN learnt from)':<70} {lab[0].mean().item():5.1f} {chroma(lab):6.1f}")
    views = {name: sample_views(world.spec, world.indices[name], args.views) for name in shapes}

    def report(label: str, images: torch.Tensor, masks: torch.Tensor, move: bool = True) -> None:
        lab = object_lab(images, masks)
        raw = object_set_swd(images, masks, photos, photo_masks, seed=args.seed)
        moved = "      -"
        if move:
            moved_images = moved_to(images, masks, photos, photo_masks)
            moved = f"{object_set_swd(moved_images, masks, photos, photo_masks, seed=args.seed):7.1f}"
        print(f"{label[-70:]:<70} {lab[0].mean().item():5.1f} {chroma(lab):6.1f} {raw:10.1f} {moved}", flush=True)

    # The oracle (the world's own materials, a fresh draw per view) and the flat-colour baseline, as the protocol
    # renders them.
    oracle = [
        material_draws(world, name, views[name], args.resolution, draw_key(args.seed, 0), ORACLE_STREAM, lit=True)
        for name in shapes
    ]
    oracle_images, oracle_masks = torch.cat([o[0] for o in oracle]), torch.cat([o[1] for o in oracle])
    report("oracle (the world's materials)", oracle_images, oracle_masks)
    photo_mean = lab_to_rgb(object_lab(photos, photo_masks).mean(1).reshape(1, 3, 1, 1)).clamp(0, 1)
    # one colour: no spread to move
    report(
        "flat colour (the photo set's mean, baseline)",
        composite_images(photo_mean.expand_as(oracle_images), oracle_masks, 1.0),
        oracle_masks,
        move=False,
    )
    for spec in args.checkpoints:
        generator, label = load(spec, args.live_out)
        latents = torch.Generator().manual_seed(args.seed)
        images, masks = [], []
        for name, shape in shapes.items():
            z = torch.randn(len(views[name]), generator.cfg.z_dim, generator=latents)
            with torch.no_grad():
                image, mask = generator_renders(
                    generator,
                    shape,
                    views[name],
                    args.resolution,
                    z,
                    torch.device("cpu"),
                    lit=True,
                    photo_render=world.spec.photo_render,
                )
            images.append(image)
            masks.append(mask)
        report(label, torch.cat(images), torch.cat(masks))


if __name__ == "__main__":
    main()
