"""``mesh2tex evaluate``: metrics between a folder of renders and a folder of images.

Two modes:

* sets (default): the renders against an image collection, unpaired. KID and FID on the features
  of a named extractor (standard Inception-v3 from a local weight file, else clearly named
  substitutes, see :mod:`mesh2tex.metrics.features`), the sliced Wasserstein distance on
  Laplacian-pyramid patches, and the total-variation distance between the sets' pooled colour
  histograms. Images are centre-cropped to squares and resized to ``--resolution``.
* pairs (``--pairs``): each render against the image of the same file stem, for renders whose
  geometry and pose match exactly: masked PSNR, masked SSIM, colour-histogram distance, per pair and
  averaged. Pairs must have the same size.

Masks: the alpha channel of an RGBA file, and/or a file of the same stem in ``--masks DIR``
(white = object). In sets mode masked pixels' background is replaced by ``--background`` (renders
and images alike) so that backgrounds do not dominate the comparison; in pairs mode the metrics are
computed over the mask (the ``--masks`` file, else the intersection of the alpha channels).

The library entry points :func:`mesh2tex.metrics.evaluate.evaluate_sets` and
:func:`mesh2tex.metrics.evaluate.evaluate_pairs` take tensors and return plain dicts (the folders are
read by :mod:`mesh2tex.photos`); the command writes ``OUT/metrics.json`` and ``OUT/metrics.md``.

Each mode reads its config (``--config YAML``, printed by ``--print-config``): the sets and pairs
modes :class:`mesh2tex.metrics.evaluate.EvaluateConfig`, ``--protocols`` the protocol config,
``--generation`` the generation config. Long steps show a progress bar on a terminal.

``--generation`` measures a texture GAN against a synthetic world's ground truth (trained, untrained
and oracle rows, the gap closed, diversity across latents) given as ``--checkpoint NAME|PATH``: see
:mod:`mesh2tex.evaluation.generation`.

``--protocols`` runs the paper's evaluation protocols on a synthetic world instead (unconditional
generation; transfer with known pose, unknown pose, to another shape; each with the ablations of
Table 8): see :mod:`mesh2tex.evaluation.protocols`.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import asdict

from mesh2tex.evaluate.options import GENERATION_CONFIG, PROTOCOL_CONFIG, SETS_CONFIG

from mesh2tex.config import load_config
from mesh2tex.errors import UserError
from mesh2tex.evaluation.generation import GenerationConfig, run_generation_protocol
from mesh2tex.evaluation.protocol_config import ProtocolConfig
from mesh2tex.evaluation.protocols import run_protocols
from mesh2tex.evaluation.report import generation_markdown, protocols_markdown
from mesh2tex.io.atomic import json_ready, write_json, write_text
from mesh2tex.io.outputs import guard_outputs
from mesh2tex.metrics import get_feature_extractor
from mesh2tex.metrics.evaluate import EvaluateConfig, evaluate_pairs, evaluate_sets, load_pairs, markdown_table
from mesh2tex.models import is_model_name, resolve_checkpoint
from mesh2tex.options import config_overrides
from mesh2tex.photos import list_images, load_set
from mesh2tex.progress import progress_bar, write_line
from mesh2tex.runtime import select_device

BACKGROUNDS = {"white": 1.0, "black": 0.0, "grey": 0.5}


# ----------------------------------------------------------------------------------------------
# Command line (the options are in evaluate/options.py)


def generation_config(args: argparse.Namespace) -> GenerationConfig:
    """``--config``, then its own flags, then --resolution and the flags it shares with the sets mode."""
    return load_config(
        GenerationConfig,
        args.config,
        config_overrides(
            args,
            GENERATION_CONFIG,
            computed={"resolution": args.resolution, "features": args.features, "seed": args.seed},
        ),
    )


def sets_config(args: argparse.Namespace) -> EvaluateConfig:
    """``--config``, then the flags given."""
    return load_config(
        EvaluateConfig, args.config, config_overrides(args, SETS_CONFIG, computed={"resolution": args.resolution})
    )


def _split(text: str | None) -> list[str] | None:
    return None if text is None else [t.strip() for t in text.split(",") if t.strip()]


def protocol_config(args: argparse.Namespace) -> ProtocolConfig:
    """The protocol config: its defaults, then ``--config``, then the flags given."""
    return load_config(
        ProtocolConfig,
        args.config,
        config_overrides(
            args,
            PROTOCOL_CONFIG,
            computed={
                "protocols": _split(args.only),
                "ablations": _split(args.ablations),
                "baselines": _split(args.baselines),
                # the options evaluate's other modes share
                "resolution": args.resolution,
                "evaluate.features": args.features,
                "evaluate.kid_subsets": args.kid_subsets,
                "seed": args.seed,
                "device": None if args.device == "auto" else args.device,
                "vgg_weights": args.vgg_weights,
                "inception_weights": args.inception_weights,
            },
        ),
    )


def run_protocols_command(args: argparse.Namespace) -> int:
    """``mesh2tex evaluate --protocols ...``: writes OUT/protocols.json, OUT/protocols.md and OUT/renders/."""
    for flag in ("world", "shapes", "checkpoint"):
        if not getattr(args, flag):
            raise UserError(f"--protocols needs --{flag}")
    cfg = protocol_config(args)
    # finished transfers are a cache (TransferCache)
    out = guard_outputs(args.out, ["protocols.json", "protocols.md"], args.overwrite)
    pose, noc = args.pose_checkpoint, args.noc_checkpoint
    if is_model_name(args.checkpoint):  # a shipped model brings its own pose and NOC networks, as in 'infer transfer'
        pose, noc = pose or args.checkpoint, noc or args.checkpoint
    result = run_protocols(
        args.world, args.shapes, args.checkpoint, pose, noc, cfg, out, log=write_line, overwrite=args.overwrite
    )
    print(protocols_markdown(result), end="")
    print(f"wrote {out / 'protocols.json'} and {out / 'protocols.md'} ({result['seconds']:.0f} s)")
    return 0


def build_config(args: argparse.Namespace):
    """The config of the mode asked for: ``--generation``, ``--protocols``, else sets and pairs;
    ``--config`` is a YAML file of that mode's config."""
    if getattr(args, "generation", False):
        return generation_config(args)
    if getattr(args, "protocols", False):
        return protocol_config(args)
    return sets_config(args)


def run_generation_command(args: argparse.Namespace) -> int:
    """``mesh2tex evaluate --generation``: OUT/generation.json, OUT/generation.md, OUT/generation_samples.png."""
    for flag in ("world", "shapes", "checkpoint"):
        if not getattr(args, flag):
            raise UserError(f"--generation needs --{flag}")
    cfg = generation_config(args)
    if cfg.latents < 2:
        raise UserError(f"--latents {cfg.latents}: diversity needs at least 2")
    out = guard_outputs(args.out, ["generation.json", "generation.md", "generation_samples.png"], args.overwrite)
    resolve_checkpoint(args.checkpoint, "gan")  # an unknown model name is refused before the feature network is built
    device = select_device(args.device)
    extractor = (
        get_feature_extractor(cfg.features, args.inception_weights, args.vgg_weights, device) if cfg.kid_fid else None
    )
    out.mkdir(parents=True, exist_ok=True)
    result = run_generation_protocol(
        args.world,
        args.shapes,
        args.checkpoint,
        cfg,
        device,
        extractor,
        out / "generation_samples.png",
        log=lambda line: write_line(line, sys.stderr),
    )
    write_json(out / "generation.json", json_ready(result))
    text = generation_markdown(result)
    write_text(out / "generation.md", text)
    print(text, end="")
    print(
        f"wrote {out / 'generation.json'}, {out / 'generation.md'} and {out / 'generation_samples.png'} "
        f"({result['seconds']:.0f} s)"
    )
    return 0


def run(args: argparse.Namespace) -> int:
    if getattr(args, "generation", False):
        return run_generation_command(args)
    if getattr(args, "protocols", False):
        return run_protocols_command(args)
    if not args.renders or not args.images:
        raise UserError(
            "evaluate needs --renders and --images (or --protocols or --generation with --world, --shapes and "
            "--checkpoint)"
        )
    config = sets_config(args)
    if config.resolution < 16:
        raise UserError(f"--resolution {config.resolution}: must be at least 16")
    out = guard_outputs(args.out, ["metrics.json", "metrics.md"], args.overwrite)
    targets = [out / "metrics.json", out / "metrics.md"]
    masks = list_images(args.masks, "mask") if args.masks else None
    start = time.perf_counter()
    steps = (
        ["read the pairs", "paired metrics"]
        if args.pairs
        else ["read the renders", "read the images", "feature network", "set metrics"]
    )
    with progress_bar(total=len(steps), desc="evaluate", unit="step") as bar:

        def step(done: str) -> None:
            bar.update(1)
            bar.set_postfix_str(done)

        if args.pairs:
            renders, images, pair_masks, names = load_pairs(args.renders, args.images, masks)
            step(steps[0])
            result = evaluate_pairs(renders, images, pair_masks, names, config)
            step(steps[1])
            mode = "pairs"
        else:
            background = BACKGROUNDS[config.background]
            renders, render_masks = load_set(args.renders, "render", config.resolution, background)
            step(steps[0])
            images, image_masks = load_set(args.images, "image", config.resolution, background, masks)
            step(steps[1])
            extractor = get_feature_extractor(
                config.features, args.inception_weights, args.vgg_weights, select_device(args.device)
            )
            step(steps[2])
            result = evaluate_sets(renders, images, extractor, config, render_masks, image_masks)
            step(steps[3])
            mode = "sets"
    result = {
        "mode": mode,
        "renders": str(args.renders),
        "images": str(args.images),
        "masks": args.masks,
        **result,
        "seconds": round(time.perf_counter() - start, 2),
        "settings": asdict(config),
    }
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "metrics.json", json_ready(result))
    header = (
        f"# mesh2tex evaluate ({mode})\n\nrenders: `{args.renders}`, images: `{args.images}`"
        + (f", masks: `{args.masks}`" if args.masks else "")
        + f"; counts: {result['counts']}\n\n"
    )
    if "features" in result:
        header += f"KID/FID features: {result['features']}\n\n"
    write_text(out / "metrics.md", header + markdown_table(result))
    print(markdown_table(result), end="")
    print(f"wrote {targets[0]} and {targets[1]}")
    return 0
