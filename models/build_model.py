"""Rebuild a shipped model from nothing: world, shapes, GAN, pose, NOC and mask networks, export, evaluation, card.

    python models/build_model.py --category chair|car --work WORK [--gan-iters N] [--out mesh2tex/models/chair]
                                 [--variety boxy|real] [--seed 0] [--pose-iters 1500] [--noc-iters 400] [--mask-iters
                                 N] [--device auto]
                                 [--pick FROM,EVERY]
                                 [--from-gan CKPT] [--views-gan CKPT] [--keep-mask]

The mask network learns from the world alone, so it trains in a process of its own beside the GAN, the pick
and the view networks (half the cores each; its output in WORK/mask.log). Every stage resumes (re-run the same
command after an interruption): the world and the shapes are
skipped when present, the GAN, pose and NOC runs continue with --resume. ``--gan-iters`` is the total
(default: the category's recipe in ``RECIPES``), so a larger value continues a finished run.
``--from-gan`` takes the GAN (and the iteration count in its metadata) from an existing run instead
of training one: the run must have been trained with this script's settings (``GAN_CONFIG``,
``RECIPES``, WORLD, SHAPES below) for the card to be true; a recipe's pick then chooses among that
run's snapshots up to the checkpoint's iteration. ``--keep-mask`` keeps the mask network already in
``--out`` (it learns from the world alone) with its card record, instead of training one again.

The model folder gets generator.safetensors, pose.safetensors, noc.safetensors, mask.safetensors (float16 inference
checkpoints, :mod:`mesh2tex.models`), card.json (settings, commands, iterations, hardware, wall
time, the generation protocol's figures) and build_log.md (the same for people; the model card,
card.md, is written by hand from it). ``--variety real`` builds the world of real families of chairs
and cars (``prepare synthetic --variety``); ``--seed`` the GAN's training seed.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import sys
import time
from pathlib import Path

import torch
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mesh2tex.cli import main as cli  # noqa: E402
from mesh2tex.evaluation.generation import GenerationConfig, run_generation_protocol  # noqa: E402
from mesh2tex.evaluation.report import generation_markdown  # noqa: E402
from mesh2tex.io.checkpoint import read_checkpoint_meta  # noqa: E402
from mesh2tex.models import MODEL_FILES, export_inference_checkpoint  # noqa: E402
from models.stages import (  # noqa: E402
    cli_flags,
    command_line,
    finish_mask_training,
    gan_run_dir,
    run,
    split_threads,
    start_mask_training,
    training_seconds,
)

WORLD = {"shapes": 32, "views": 8, "query_shapes": 8, "query_views": 2, "seed": 0, "resolution": 128}
SHAPES = {"faces": 1536, "levels": 4, "seed": 0}
GAN = {"resolution": 64, "views": 4, "seed": 0}
GAN_CONFIG = {
    "sample_every": 250,
    "checkpoint_every": 250,
    "snapshot_every": 250,
    "log_every": 10,
    "generator": {"encoder_channels": [32, 48, 64, 64], "synthesis_channels": [32, 48, 64, 64]},
    "discriminator": {"channel_base": 1024},
    "optim": {"lr_field": 0.0012},
}
# What differs between the shipped models. world_shapes: the world's shape count (WORLD["shapes"]
# when absent; the held-out count stays WORLD["query_shapes"]). gan: top-level training settings
# (supersample: the fakes rendered at twice the resolution and box-filtered, as the photos are).
# loss.diversity_start: the mode-seeking term from that iteration on. The pose and NOC networks learn
# from views half textured by the GAN's snapshot at views_gan_iteration. variety: the world's shapes
# and materials (prepare synthetic --variety; boxy when absent). pick (or --pick FROM,EVERY): the
# exported generator is the snapshot, every EVERY iterations from FROM to gan_iters, that closes the
# most of the gap on a validation world no table reports (VALIDATION), among those whose latents still
# paint different chairs (PICK_MIN_SPREAD), not the last one. mask: the mask network's settings beyond
# MASK's (config.room_share: the share of its training views standing in a drawn room); mask_iters: its
# steps (MASK_ITERS when absent; --mask-iters overrides).
VARIED_WORLD_RECIPE = {
    "gan_iters": 6000,
    "world_shapes": 64,
    "variety": "real",
    # the rates annealed from 4,000: a run keeps what it holds when the mode-seeking term has settled
    "gan": {"supersample": 2, "optim": {"lr_field": 0.0012, "lr_decay_start": 4000}},
    "loss": {"diversity_start": 3500},
    "views_gan_iteration": 2500,
    "pick": {"from": 4000, "every": 500},
}
RECIPES = {
    # chairs are photographed in rooms: on the outside chairs' photos in a room the mask's IoU rose from 0.76
    # to 0.87 and over clutter from 0.69 to 0.76 (docs/results/transfer.md, "A mask network that has seen rooms");
    # at 128 px with the rate settling by a cosine the thin legs and rods come out sharper (same page, "The mask
    # network at 128 px, its rate settling"; 56 photos each way): over clutter 0.75 -> 0.78 and poses within 15
    # degrees 35 -> 38; in a room 0.89 -> 0.90 and 46 -> 51; with rounded things drawn behind the chair in 0.3 of
    # the scenes (same page, "Other things behind the object") the masks over clutter 0.78 -> 0.82 as used, two seeds
    "chair": {
        **VARIED_WORLD_RECIPE,
        "mask": {"resolution": 128, "config": {"room_share": 0.3, "lr_end": 0.05, "distractor_share": 0.3}},
        "mask_iters": 6000,
    },
    # the chair's recipe on the varied car world (docs/results/gan.md, "The same recipe on the varied car world")
    "car": VARIED_WORLD_RECIPE,
}


# The validation world of a recipe's pick: the same kind of world from another seed, its held-out
# shapes measured by a smaller generation protocol (one draw).
VALIDATION = {"shapes": 24, "views": 4, "query_shapes": 8, "query_views": 1, "seed": 1, "resolution": 128}
VALIDATION_PROTOCOL = {"views": 4, "latents": 8, "kid_fid": False, "repeats": 1}
# A snapshot is picked only if its samples vary: the colour spread of its latents (the same protocol)
# at least this share of the photo set's. Without it the pick can take a generator whose every
# latent paints the same chair (docs/results/gan.md, "Seed 0 branched at 3,500").
PICK_MIN_SPREAD = 0.5


def recipe_world(recipe: dict) -> dict:
    """The `prepare synthetic` settings of a recipe: WORLD with the recipe's shape count (and variety)."""
    world = {**WORLD, "shapes": recipe.get("world_shapes", WORLD["shapes"])}
    return {**world, "variety": recipe["variety"]} if recipe.get("variety", "boxy") != "boxy" else world


def prepare_world(folder: Path, category: str, settings: dict, variety: str, commands: list[str]) -> None:
    """`prepare synthetic` into ``folder`` with ``settings`` (WORLD's keys); skipped when present with them."""
    keys = ("shapes", "views", "query_shapes", "query_views", "seed", "resolution")
    world = cli_flags(out=folder, category=category, **{key: settings[key] for key in keys}, variety=variety)
    run(["prepare", "synthetic", *world], commands)


def prepare_split(world: Path, part: str, folder: Path, commands: list[str]) -> None:
    """Prepare the world's ``part`` shapes (train or query) into ``folder`` with the recipe's hierarchy."""
    split = json.loads((world / "index.json").read_text())["split"]
    names = split["train_shapes"] if part == "train" else split["query_shapes"]
    inputs = [str(world / "meshes" / f"{n}.obj") for n in names]
    argv = ["prepare", "shapes", "--input", *inputs, *cli_flags(out=folder, **SHAPES, workers=2)]
    print(f"\n== mesh2tex {' '.join(argv[:2])} ... ({part})", flush=True)
    commands.append(command_line(argv))
    cli(argv)  # a shape that cannot be remeshed fails alone (exit 2); the others are prepared


def pick_snapshot(
    work: Path, category: str, variety: str, gan_run: Path, gan_iters: int, pick: dict, commands: list[str]
) -> tuple[Path, dict[int, dict]]:
    """The snapshot of ``gan_run`` that closes the most of the gap on the validation world among those
    whose colour spread is at least :data:`PICK_MIN_SPREAD` of the photo set's (all of them, with a
    warning, when none is), and every snapshot's figures ({iteration: {"gap": gap closed, "spread":
    colour spread vs the photo set}}). Figures are kept in WORK/validation/pick.json with the run they
    measured and reused for that run only (a work folder copied for another seed measures its own;
    delete the file to measure again)."""
    folder = work / "validation"
    prepare_world(folder / "world", category, VALIDATION, variety, commands)
    prepare_split(folder / "world", "query", folder / "shapes", commands)
    record = folder / "pick.json"
    kept = json.loads(record.read_text()) if record.is_file() else {}
    run_id = str(gan_run.resolve())
    figures = {int(k): v for k, v in kept.get("figures", {}).items()} if kept.get("gan_run") == run_id else {}
    figures = {it: f for it, f in figures.items() if isinstance(f, dict)}  # a record without the spread: measured again
    for iteration in range(pick["from"], gan_iters + 1, pick["every"]):
        snapshot = gan_run / "snapshots" / f"iter{iteration:07d}.safetensors"
        if iteration in figures or not snapshot.is_file():
            continue
        print(f"\n== validation: the snapshot at iteration {iteration}", flush=True)
        result = run_generation_protocol(
            folder / "world", folder / "shapes", snapshot, GenerationConfig(**VALIDATION_PROTOCOL)
        )
        figures[iteration] = {
            "gap": round(float(result["gap_closed"]), 4),
            "spread": round(float(result["diversity"]["trained_spread_vs_photo_set"]), 4),
        }
        record.write_text(json.dumps({"gan_run": run_id, "figures": figures}, indent=1))
    if not figures:
        sys.exit(
            f"build_model: no snapshot of {gan_run} between iterations {pick['from']} and {gan_iters} to pick from"
        )
    if not any(f["spread"] >= PICK_MIN_SPREAD for f in figures.values()):
        print(
            f"build_model: warning: no snapshot's colour spread reaches {PICK_MIN_SPREAD} of the photo set's; "
            "picking by the gap alone",
            flush=True,
        )
    best = best_snapshot(figures)
    print(
        f"\n== picked the snapshot at iteration {best} (validation gap closed {figures[best]['gap']}, "
        f"spread {figures[best]['spread']}; " + pick_figures(figures) + ")",
        flush=True,
    )
    return gan_run / "snapshots" / f"iter{best:07d}.safetensors", figures


def best_snapshot(figures: dict[int, dict], min_spread: float = PICK_MIN_SPREAD) -> int:
    """The pick's rule: the iteration of the best validation gap among the snapshots whose colour spread is
    at least ``min_spread`` of the photo set's, or among all of them when none is."""
    varied = [it for it, f in figures.items() if f["spread"] >= min_spread]
    return max(varied or figures, key=lambda it: figures[it]["gap"])


def pick_figures(figures: dict[int, dict]) -> str:
    """``iteration: gap / spread`` of each measured snapshot, in order, for the log and the build log."""
    return ", ".join(f"{it}: {f['gap']} / {f['spread']}" for it, f in sorted(figures.items()))


def network_training(
    work: Path, kind: str, config: Path, iters: int, settings: dict, args: argparse.Namespace, **extra
) -> list[str]:
    """The ``train pose|noc|mask`` command of a build: on WORK's training shapes into WORK/<kind>, with
    ``settings`` (VIEWS or MASK: samples, resolution, batch, seed), the build's category, variety and
    device, and ``extra`` flags (the views' GAN checkpoint); resumed."""
    flags = cli_flags(
        shapes=work / "shapes" / "train",
        out=work / kind,
        config=config,
        iters=iters,
        samples=settings["samples"],
        resolution=settings["resolution"],
        batch=settings["batch"],
        category=args.category,
        variety=args.variety,
        seed=settings["seed"],
        **extra,
        device=args.device,
    )
    return ["train", kind, *flags, "--resume"]


def keep_mask_record(out: Path, mask_iters: int, mask: dict) -> dict:
    """The card's record of the mask network already in ``out`` (``--keep-mask``): its ``mask_training``
    entry, checked to be of the recipe's mask settings ``mask`` (:func:`recipe_mask`) and iteration count."""
    card = json.loads((out / "card.json").read_text()) if (out / "card.json").is_file() else {}
    same = card.get("mask") == mask and card.get("mask_iterations") == mask_iters
    if not (out / MODEL_FILES["mask"]).is_file() or not same:
        raise SystemExit(
            f"build_model: --keep-mask needs {out} to hold a mask network of the recipe's settings "
            f"at {mask_iters} steps"
        )
    return {"mask_training": card.get("mask_training", {})}


def recipe_mask(recipe: dict) -> dict:
    """The mask network's training settings of a recipe: MASK with the recipe's ``mask`` on top (its
    ``config`` merged into MASK's, its other keys, such as ``resolution``, in place of MASK's)."""
    extra = recipe.get("mask", {})
    top = {key: value for key, value in extra.items() if key != "config"}
    return {**MASK, **top, "config": {**MASK["config"], **extra.get("config", {})}}


def recipe_gan_config(recipe: dict) -> dict:
    """The `train gan --config` contents of a recipe: GAN_CONFIG with its top-level settings and loss."""
    config = {**GAN_CONFIG, **recipe["gan"]}
    return {**config, "loss": recipe["loss"]} if recipe["loss"] else config


VIEWS = {
    "samples": 1536,
    "resolution": 64,
    "batch": 32,
    "seed": 0,
    "config": {"width": 16, "log_every": 25, "checkpoint_every": 100},
}
# The mask network sees whole photos, not object crops: finer views, each placed over a fresh backdrop at every step.
MASK_ITERS = 4000
MASK = {
    "samples": 2048,
    "resolution": 96,
    "batch": 8,
    "seed": 0,
    "config": {"width": 12, "lr": 0.001, "log_every": 50, "checkpoint_every": 250},
}


def train_gan_and_views(
    args: argparse.Namespace, recipe: dict, gan_config: dict, gan_settings: dict, work: Path, commands: list[str]
) -> tuple[Path, dict[int, dict], dict | None, Path]:
    """The build's GAN (trained, or ``--from-gan``'s), the recipe's pick among its snapshots, and the pose
    and NOC networks on views it textures: (the GAN checkpoint to export, the pick's figures per
    iteration, the pick's settings, the views' GAN checkpoint)."""
    world = work / "world"
    if args.from_gan:
        gan_ckpt = Path(args.from_gan)
        run_dir = gan_run_dir(gan_ckpt)
        it = read_checkpoint_meta(gan_ckpt)["meta"]["iteration"]
        commands.append(
            f"mesh2tex train gan --shapes {work / 'shapes' / 'train'} --images {world} --out {run_dir} "
            f"--config {run_dir / 'config.yaml'} --resolution {GAN['resolution']} --views {GAN['views']} "
            f"--seed {gan_settings['seed']}  # stopped at iteration {it}; {gan_ckpt.name} taken from it"
        )
    else:
        gan_yaml = work / "gan.yaml"
        gan_yaml.write_text(yaml.safe_dump(gan_config, sort_keys=False))
        training = cli_flags(
            shapes=work / "shapes" / "train",
            images=world,
            out=work / "gan",
            config=gan_yaml,
            iters=args.gan_iters,
            resolution=GAN["resolution"],
            views=GAN["views"],
            seed=gan_settings["seed"],
            device=args.device,
        )
        run(["train", "gan", *training, "--resume"], commands)
        gan_ckpt = work / "gan" / "checkpoint.safetensors"
    picked: dict[int, dict] = {}
    pick = recipe.get("pick")
    if args.pick:
        start_at, every = (int(v) for v in args.pick.split(","))
        pick = {"from": start_at, "every": every}
    if pick:  # among the snapshots of the run trained here, or of --from-gan's run up to its iteration
        last = read_checkpoint_meta(gan_ckpt)["meta"]["iteration"] if args.from_gan else args.gan_iters
        gan_ckpt, picked = pick_snapshot(work, args.category, args.variety, gan_run_dir(gan_ckpt), last, pick, commands)
    snapshot = gan_run_dir(gan_ckpt) / "snapshots" / f"iter{recipe['views_gan_iteration']:07d}.safetensors"
    if not args.views_gan and snapshot.is_file():  # else the GAN itself (a run shorter than the recipe's iteration)
        args.views_gan = str(snapshot)
    views_yaml = work / "views.yaml"
    views_yaml.write_text(yaml.safe_dump(VIEWS["config"]))
    views_gan = Path(args.views_gan) if args.views_gan else gan_ckpt
    for kind, iters in (("pose", args.pose_iters), ("noc", args.noc_iters)):
        run(network_training(work, kind, views_yaml, iters, VIEWS, args, checkpoint=views_gan), commands)
    return gan_ckpt, picked, pick, views_gan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--category", choices=["chair", "car"], required=True)
    parser.add_argument("--work", required=True, help="folder for the world, shapes and runs (kept, resumable)")
    parser.add_argument("--out", help="model folder (default mesh2tex/models/<category>)")
    parser.add_argument("--gan-iters", type=int, help="GAN iterations in all (default: the category's recipe)")
    parser.add_argument(
        "--variety",
        choices=["boxy", "real"],
        help="the world's shapes (prepare synthetic --variety; default: the recipe's)",
    )
    parser.add_argument("--seed", type=int, default=GAN["seed"], help="the GAN's training seed")
    parser.add_argument("--pose-iters", type=int, default=1500)
    parser.add_argument("--noc-iters", type=int, default=400)
    parser.add_argument("--mask-iters", type=int, help="the mask network's steps (default: the recipe's)")
    parser.add_argument(
        "--pick",
        metavar="FROM,EVERY",
        help="export the snapshot (every EVERY iterations from FROM) that the "
        "validation world ranks first, not the last one (default: the recipe's pick, if any)",
    )
    parser.add_argument("--device", default="auto")
    parser.add_argument(
        "--keep-mask",
        action="store_true",
        help="keep --out's mask network and its card record (it learns from the world alone, not from the GAN)",
    )
    parser.add_argument("--from-gan", help="use this GAN checkpoint instead of training one")
    parser.add_argument("--note", default="", help="a line for the card (e.g. how busy the machine was)")
    parser.add_argument(
        "--views-gan",
        help="the GAN that textures half of the pose and NOC training views "
        "(default: the model's own run, its snapshot at the recipe's views_gan_iteration)",
    )
    args = parser.parse_args()
    # `kill PID` stops the build as Ctrl-C does, through the finally below that stops the mask's process too
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    recipe = RECIPES[args.category]
    args.variety = args.variety or recipe.get("variety", "boxy")
    gan_config = recipe_gan_config(recipe)
    world_settings = {**recipe_world(recipe), "variety": args.variety}
    if args.variety == "boxy":
        world_settings.pop("variety")
    gan_settings = {**GAN, "seed": args.seed}
    if args.gan_iters is None:
        args.gan_iters = recipe["gan_iters"]
    work = Path(args.work)
    out = Path(args.out) if args.out else ROOT / "mesh2tex" / "models" / args.category
    out.mkdir(parents=True, exist_ok=True)
    mask_settings = recipe_mask(recipe)
    if args.mask_iters is None:
        args.mask_iters = recipe.get("mask_iters", MASK_ITERS)
    kept_mask = keep_mask_record(out, args.mask_iters, mask_settings) if args.keep_mask else {}  # before any training
    commands: list[str] = []
    start = time.perf_counter()
    world = work / "world"
    prepare_world(world, args.category, world_settings, args.variety, commands)
    for part in ("train", "query"):
        prepare_split(world, part, work / "shapes" / part, commands)
    mask_yaml = work / "mask.yaml"
    mask_yaml.write_text(yaml.safe_dump(mask_settings["config"]))
    own_threads, mask_threads = split_threads()
    threads_before, masking = torch.get_num_threads(), None
    if not kept_mask:
        mask_argv = network_training(work, "mask", mask_yaml, args.mask_iters, mask_settings, args)
        masking = start_mask_training(mask_argv, work / "mask.log", mask_threads, commands)
        if own_threads:  # the stages below run in this process (mesh2tex.cli.main leaves torch's threads alone)
            torch.set_num_threads(own_threads)
    try:
        gan_ckpt, picked, pick, views_gan = train_gan_and_views(args, recipe, gan_config, gan_settings, work, commands)
        if masking is not None:
            finish_mask_training(masking, work / "mask.log")
    finally:
        if masking is not None and masking.poll() is None:  # the build stopped: stop the mask's training too
            masking.terminate()  # it saves its checkpoint, as on Ctrl-C, and the same command resumes it
            masking.wait()
        torch.set_num_threads(threads_before)
    export_inference_checkpoint(gan_ckpt, "gan", out / MODEL_FILES["gan"])
    for kind in ("pose", "noc") if kept_mask else ("pose", "noc", "mask"):
        export_inference_checkpoint(work / kind / "checkpoint.safetensors", kind, out / MODEL_FILES[kind])
    gan_meta = read_checkpoint_meta(gan_ckpt)["meta"]
    print("\n== generation protocol on the held-out shapes", flush=True)
    result = run_generation_protocol(
        world,
        work / "shapes" / "query",
        out / MODEL_FILES["gan"],
        GenerationConfig(views=8, latents=16, kid_fid=False),
        samples_path=out / "samples.png",
    )
    size_mb = sum((out / f).stat().st_size for f in MODEL_FILES.values()) / 1e6
    card = {
        "name": args.category,
        "category": args.category,
        "world": world_settings,
        "shapes": SHAPES,
        "gan": {**gan_settings, "config": gan_config},
        "views": VIEWS,
        "gan_iterations": int(gan_meta["iteration"]),
        "gan_trained_iterations": args.gan_iters,
        **(
            {
                "pick": {
                    **pick,
                    "validation_world": VALIDATION,
                    "protocol": VALIDATION_PROTOCOL,
                    "min_spread": PICK_MIN_SPREAD,
                    "figures": picked,
                }
            }
            if picked
            else {}
        ),
        "pose_iterations": args.pose_iters,
        "noc_iterations": args.noc_iters,
        "mask": mask_settings,
        "mask_iterations": args.mask_iters,
        **kept_mask,
        "views_gan_iteration": int(read_checkpoint_meta(views_gan)["meta"]["iteration"]),
        "commands": commands,
        "gan_training_seconds": training_seconds(
            gan_run_dir(gan_ckpt), args.gan_iters if picked else int(gan_meta["iteration"])
        ),
        "hardware": f"{platform.machine()}, {os.cpu_count()} CPU cores, {platform.system()}; device {args.device}",
        "note": args.note,
        "build_seconds_this_invocation": round(time.perf_counter() - start, 1),
        "size_mb": round(size_mb, 2),
        "generation": result,
    }
    (out / "card.json").write_text(json.dumps(card, indent=1, default=float))
    rebuild = (
        f"python models/build_model.py --category {args.category} --work WORK"
        + ("" if args.gan_iters == recipe["gan_iters"] else f" --gan-iters {args.gan_iters}")
        + (f" --variety {args.variety}" if args.variety != recipe.get("variety", "boxy") else "")
        + (f" --seed {args.seed}" if args.seed != GAN["seed"] else "")
        + (f" --pick {args.pick}" if args.pick else "")
    )
    (out / "build_log.md").write_text(
        f"# Shipped model `{args.category}` ({args.category})\n\n"
        f"Texture GAN (EMA generator), pose, NOC and mask networks trained on the synthetic {args.category} world "
        f"({world_settings['shapes'] - world_settings['query_shapes']} training shapes, {world_settings['views']} "
        "photos each at "
        f"{world_settings['resolution']} px; {world_settings['query_shapes']} held-out shapes for the figures below). "
        f"Float16, {size_mb:.1f} MB in all.\n\n"
        f"- GAN: {card['gan_iterations']} iterations at {GAN['resolution']} px, {GAN['views']} views per shape, batch "
        "2, "
        + (
            f"the snapshot picked of {args.gan_iters} by the validation world's gap closed among those whose colour "
            f"spread reaches {PICK_MIN_SPREAD} of the photo set's (iteration: gap / spread; "
            + pick_figures(picked)
            + "), "
            if picked
            else ""
        )
        + (f"{card['gan_training_seconds'] / 3600:.2f} h of training; " if card["gan_training_seconds"] else "")
        + f"pose: {args.pose_iters} steps, NOC: {args.noc_iters} steps, on views half textured by the GAN at iteration "
        f"{card['views_gan_iteration']} and half by the world's procedural materials; mask: {args.mask_iters} steps on "
        f"{mask_settings['resolution']} px views placed over backdrops"
        + (f" ({rooms:.0%} of them in drawn rooms)" if (rooms := mask_settings["config"].get("room_share")) else "")
        + "\n"
        f"- Hardware of this build: {card['hardware']}" + (f"; {args.note}" if args.note else "") + "\n"
        f"- Rebuild from nothing: `{rebuild}`\n\n## Commands\n\n```\n"
        + "\n".join(commands)
        + "\n```\n\n## Figures (generation protocol)\n\n"
        + generation_markdown(result)
        + "\n![samples](samples.png)\n"
    )
    print(generation_markdown(result))
    print(f"wrote {out} ({size_mb:.1f} MB)")


if __name__ == "__main__":
    main()
