"""The options of ``mesh2tex evaluate``, built without importing torch (``--help`` stays fast; the
defaults shown are read from the configs' source, see :mod:`mesh2tex.options`); ``run()`` and
``build_config()`` are in :mod:`mesh2tex.evaluate.evaluate`."""

from __future__ import annotations

import argparse

from mesh2tex.options import (
    SHIPPED_MODELS_HELP,
    ConfigOptions,
    add_checkpoint,
    add_device,
    add_out,
    add_overwrite,
    add_print_config,
    config_default,
    renamed,
    static_value,
)

SETS_CONFIG = "mesh2tex.metrics.evaluate:EvaluateConfig"
PROTOCOL_CONFIG = "mesh2tex.evaluation.protocol_config:ProtocolConfig"
GENERATION_CONFIG = "mesh2tex.evaluation.generation:GenerationConfig"
BACKGROUNDS = ("black", "grey", "white")  # mesh2tex.evaluate.evaluate.BACKGROUNDS maps them to grey levels


def evaluate(parser: argparse.ArgumentParser) -> None:
    """Three modes, each with its config: sets (default) and pairs, ``--protocols``, ``--generation``;
    ``--config`` reads, and ``--print-config`` prints, the one of the mode asked for."""
    parser.add_argument(
        "--renders", help="folder of rendered images (PNG/JPEG; RGBA alpha is the mask); required unless --protocols"
    )
    parser.add_argument(
        "--images",
        help="folder of reference images (photos, or ground-truth renders with --pairs); required unless --protocols",
    )
    parser.add_argument("--masks", help="folder of masks named like the images (white = object)")
    parser.add_argument(
        "--pairs", action="store_true", help="paired metrics (PSNR, SSIM, histogram) between files of the same name"
    )
    add_out(
        parser,
        "output folder for metrics.json and metrics.md (protocols.* with --protocols, generation.* with --generation)",
    )
    config = parser.add_argument(
        "--config",
        "--protocol-config",
        metavar="YAML",
        help="YAML file with any fields of the config of the mode asked for: sets and pairs, --protocols or "
        "--generation (the flags given override it; --print-config shows its fields)",
    )
    renamed(config, "--protocol-config")
    add_print_config(parser)
    sets = ConfigOptions(parser, SETS_CONFIG, config_flag=None)
    parser.add_argument(
        "--resolution",
        type=int,
        help=(
            f"square side images are resized to (default: {config_default(SETS_CONFIG, 'resolution')}; with "
            f"--protocols {config_default(PROTOCOL_CONFIG, 'resolution')}; with --generation the GAN's training "
            "resolution)"
        ),
    )
    sets.add(
        "--features",
        choices=static_value("mesh2tex.metrics.features:EXTRACTOR_NAMES"),
        help="KID/FID features (auto: Inception if its weights are found, else randvgg)",
    )
    parser.add_argument(
        "--inception-weights",
        help="Inception-v3 weight file (pt_inception-2015-12-05 or torchvision's inception_v3_google)",
    )
    parser.add_argument(
        "--vgg-weights", help="VGG19 weight file (torchvision's vgg19-dcbb9e9d.pth), for --features vgg"
    )
    sets.add("--kid-subsets", type=int, help="KID subsets")
    sets.add("--kid-subset-size", type=int, help="KID subset size")
    sets.add("--background", choices=BACKGROUNDS, help="sets mode: colour for masked-out pixels")
    add_device(parser)
    sets.add("--seed", type=int, help="seed for KID subsets and SWD sampling")
    add_overwrite(parser, "replace metrics already in --out")
    _protocols(parser)
    _generation(parser)


def _generation(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("generation (--generation: a GAN against a synthetic world's ground truth)")
    group.add_argument(
        "--generation",
        action="store_true",
        help="the generation protocol: --checkpoint against --world's ground truth on the held-out shapes in --shapes",
    )
    generation = ConfigOptions(group, GENERATION_CONFIG, config_flag=None)
    generation.add("--latents", type=int, help="latents per shape for the diversity measures")
    generation.add(
        "--repeats",
        type=int,
        help="draws of the latents, oracle materials and fresh photo set, their distances averaged",
    )
    generation.add(
        "--truncation",
        type=float,
        help="truncation psi of the trained generator's latents, as 'infer generate' takes it (1: none)",
    )
    generation.add(
        "--gan-lighting",
        key="lighting",
        choices=["auto", "lit", "unlit"],
        help="the generator's rows: lit by each view's light, unlit, or auto (as the GAN was trained)",
    )
    generation.add(
        "--generator-render",
        choices=["photo", "direct"],
        help="the generator's rows rendered as the world's photos and the oracle are (photo), or by the GAN's own "
        "renderer straight at the metric's resolution (direct: how the figures before were measured)",
    )
    generation.add(
        "--split",
        choices=["held_out", "train"],
        help="the world's shapes measured: held_out (never trained on) or train (the GAN's own; --shapes then the "
        "prepared training shapes)",
    )


def _protocols(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("protocols (--protocols: the paper's synthetic evaluation)")
    group.add_argument("--protocols", action="store_true", help="run the evaluation protocols on a synthetic world")
    group.add_argument("--world", help="synthetic world folder (from 'mesh2tex prepare synthetic')")
    group.add_argument("--shapes", help="prepared shapes of the world's meshes (from 'mesh2tex prepare shapes')")
    add_checkpoint(
        group,
        "--protocols and --generation: the generator measured, a 'train gan' checkpoint (RUN/checkpoint.safetensors) "
        f"{SHIPPED_MODELS_HELP}, which also supplies the pose and NOC networks unless given",
        alias="--gan",
    )
    group.add_argument(
        "--pose-checkpoint", help="pose network checkpoint (from 'train pose'), or a shipped model's name"
    )
    group.add_argument("--noc-checkpoint", help="NOC network checkpoint (from 'train noc'), or a shipped model's name")
    config = ConfigOptions(group, PROTOCOL_CONFIG, config_flag=None, what="the protocol config")
    config.add("--latent-iters", key="transfer.latent_iters", type=int, help="transfer stage 1 iterations")
    config.add("--refine-iters", key="transfer.refine_iters", type=int, help="transfer stage 2 iterations")
    config.add("--queries", type=int, help="query photos used, the first K (0: all)")
    config.add("--only", key="protocols", help="comma-separated protocols to run")
    config.add("--ablations", help="comma-separated ablations of each transfer protocol")
    config.add(
        "--lighting", choices=("photo", "albedo"), help="judge every method with the photo's light or unlit, as albedo"
    )
    config.add("--unseen-views", type=int, help="views the photo does not show, judged apart")
    config.add("--baselines", help="comma-separated baselines beside the transfers")
