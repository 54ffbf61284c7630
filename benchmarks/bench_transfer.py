"""Seconds per stage of texture transfer (``infer transfer``) at the default configuration.

    python benchmarks/bench_transfer.py [--resolution 128] [--latent-iters 100] [--refine-iters 300]
                                        [--patch-size 32] [--patch-scales 2] [--unlit]
                                        [--faces 6144] [--device auto|cpu|cuda] [--threads N] [--previous REV]

A procedural chair is prepared (quad hierarchy of --faces faces), a generator of the default
architecture is built (untrained: its weights do not change the cost), and a query photo of
another chair is rendered with its ground-truth NOC map. Then the two optimisation stages run
exactly as in ``infer transfer`` (global + NOC-guided patch style losses with VGG19, then the last
two synthesis blocks with the patch loss, and the low-pass colour loss in both). The generator
counts as trained under the light prior (the default of ``train gan``), so the photo's light is
learnt as in a default transfer; ``--unlit`` renders unlit instead. Prints seconds per stage, per
iteration, and the total against the 300 s target. ``--previous REV`` also runs the transfer of
git revision REV (its ``mesh2tex``, the same generator weights, photo and settings that it knows)
after today's, in the same process, and prints the ratio of the totals.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from previous import Revision  # noqa: E402  (this folder)

from mesh2tex.geometry.prepare import prepare_shape  # noqa: E402
from mesh2tex.nn.generator import GeneratorConfig, TextureGenerator  # noqa: E402
from mesh2tex.nn.vgg import load_vgg19  # noqa: E402
from mesh2tex.render import CameraConfig, RenderSettings  # noqa: E402
from mesh2tex.runtime import select_device  # noqa: E402
from mesh2tex.synthetic.world import WorldSpec, make_material, make_shape, render_views, sample_views  # noqa: E402
from mesh2tex.transfer import Photo, TransferConfig, transfer_texture, view_at_pose  # noqa: E402

TARGET_SECONDS = 300.0


GAN_CAMERA = CameraConfig()  # the camera an untrained or default GAN renders with


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--latent-iters", type=int, default=100)
    parser.add_argument("--refine-iters", type=int, default=300)
    parser.add_argument("--faces", type=int, default=6144)
    parser.add_argument(
        "--patch-size", type=int, default=TransferConfig.patch_size, help="the paper's: 64 (with --patch-scales 3)"
    )
    parser.add_argument("--patch-scales", type=int, default=TransferConfig.patch_scales)
    parser.add_argument("--device", default="auto")
    parser.add_argument("--threads", type=int, default=0, help="torch CPU threads (0: torch's default)")
    parser.add_argument("--unlit", action="store_true", help="a generator trained unlit: no light is learnt")
    parser.add_argument("--previous", metavar="REV", help="also time the transfer of this git revision, same process")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    device = select_device(args.device)
    spec = WorldSpec(category="chair", seed=0, resolution=args.resolution)

    start = time.perf_counter()
    target = make_shape(spec, 0)
    shape = prepare_shape(target.vertices, target.faces, face_count=args.faces, levels=5, seed=0, source="chair 0")
    print(f"prepared the mesh: {shape.face_counts} quads ({time.perf_counter() - start:.1f} s)")
    query_view = sample_views(spec, 1, 1, query=True)[0]
    query = render_views(make_shape(spec, 1), make_material(spec, 1), [query_view], RenderSettings(args.resolution, 2))
    image = torch.from_numpy(query["rgb"]).permute(0, 3, 1, 2).contiguous().float() / 127.5 - 1
    mask = torch.from_numpy(query["mask"] > 127)[:, None].float()
    photo = Photo(image=image, mask=mask)
    photo_noc = torch.from_numpy(query["noc"][0]).float() / 255

    cfg = TransferConfig(
        resolution=args.resolution,
        latent_iters=args.latent_iters,
        refine_iters=args.refine_iters,
        patch_size=args.patch_size,
        patch_scales=args.patch_scales,
    )
    generator = TextureGenerator(GeneratorConfig(input_features=shape.face_features.shape[1])).eval()
    view = view_at_pose(shape, query_view.azimuth, query_view.elevation, GAN_CAMERA.distance, GAN_CAMERA.fov, cfg)
    vgg = load_vgg19(None, device=device, warn=False)
    weights = {k: v.clone() for k, v in generator.state_dict().items()}  # stage 2 changes the generator
    result = transfer_texture(
        generator, shape, photo, view, photo_noc, vgg, cfg, device, show_progress=False, generator_lit=not args.unlit
    )

    total = sum(result.seconds.values())
    print(
        f"device {device}, torch threads {torch.get_num_threads()}, resolution {args.resolution}, "
        f"{shape.face_counts[0]} finest quads, {cfg.patches} patches of {cfg.patch_size} px at {cfg.patch_levels} "
        f"scales, VGG19 {'ImageNet' if vgg.pretrained else 'random-weight'} (same cost)"
    )
    for stage, seconds in result.seconds.items():
        iters = len(result.losses[stage])
        print(f"  stage {stage:7s}: {iters:4d} iterations, {seconds:7.1f} s, {seconds / max(iters, 1):.3f} s/iteration")
    print(f"  total: {total:.1f} s; target {TARGET_SECONDS:.0f} s; ratio {total / TARGET_SECONDS:.2f}")
    print(f"  loss latent {result.losses['latent'][0]:.4g} -> {result.losses['latent'][-1]:.4g}")
    if args.previous:
        seconds = time_previous(args.previous, args, shape, photo, view, photo_noc, weights, device)
        print(f"revision {args.previous}: total {seconds:.1f} s; today / previous {total / seconds:.2f}")


def time_previous(revision: str, args, shape, photo, view, photo_noc, weights: dict, device) -> float:
    """Seconds of the transfer of git ``revision`` on the same inputs (its own TransferConfig with the
    same flags, a generator of its own code with today's initial weights)."""
    old = Revision(revision)
    with old.active():
        config = old.module("mesh2tex.transfer.config").TransferConfig
        generator_module = old.module("mesh2tex.nn.generator")
        cfg = config(
            resolution=args.resolution,
            latent_iters=args.latent_iters,
            refine_iters=args.refine_iters,
            patch_size=args.patch_size,
            patch_scales=args.patch_scales,
        )
        generator = generator_module.TextureGenerator(
            generator_module.GeneratorConfig(input_features=shape.face_features.shape[1])
        ).eval()
        generator.load_state_dict(weights)
        vgg = old.module("mesh2tex.nn.vgg").load_vgg19(None, device=device, warn=False)
        # The revision's own classes: its checks compare types, and today's Photo is not its Photo.
        photo_module = old.module("mesh2tex.transfer.photo")
        photo, view = as_revision_type(photo, photo_module.Photo), as_revision_type(view, photo_module.FramedView)
        result = old.module("mesh2tex.transfer.optimise").transfer_texture(
            generator, shape, photo, view, photo_noc, vgg, cfg, device, show_progress=False
        )
    return sum(result.seconds.values())


def as_revision_type(value, kind):
    """``value`` (a dataclass of today's code) rebuilt as the revision's dataclass ``kind`` of the fields it knows."""
    import dataclasses

    return kind(**{f.name: getattr(value, f.name) for f in dataclasses.fields(kind) if hasattr(value, f.name)})


if __name__ == "__main__":
    main()
