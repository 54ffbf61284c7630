"""The options of ``mesh2tex train gan|pose|noc|mask|nca``, built without importing torch (``--help`` stays
fast; the defaults shown are read from the configs' source, see :mod:`mesh2tex.options`); each
command's ``run()`` and ``build_config()`` are in its own module."""

from __future__ import annotations

import argparse

from mesh2tex.options import DEVICES, SHIPPED_MODELS_HELP, ConfigOptions, add_checkpoint, add_out, add_overwrite

VIEW_CONFIG = "mesh2tex.nn.view_nets:ViewTrainConfig"


def gan(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--shapes", required=True, help="folder of prepared shapes (.npz from 'mesh2tex prepare shapes')"
    )
    parser.add_argument("--images", required=True, help="photo folder: images/*.png with masks/*.png, or RGBA *.png")
    add_out(parser, "run directory (config, checkpoint, metrics, samples)")
    config = ConfigOptions(parser, "mesh2tex.train.gan_config:TrainGanConfig", what="the training config")
    config.add(
        "--iters",
        type=int,
        help="training iterations (total, also when resuming): 20000 take about 2.5 h on a 2-core CPU, "
        "a few hundred show whether a setup learns",
    )
    config.add("--batch", type=int, help="shapes per iteration and process")
    config.add("--views", type=int, help="random views per shape")
    config.add("--resolution", type=int, help="render resolution (power of two)")
    config.add("--device", choices=DEVICES, help="where to train")
    config.add("--seed", type=int, help="random seed")
    add_resume(parser, "gan")


def add_resume(parser: argparse.ArgumentParser, kind: str, what: str = "the run") -> None:
    """``--resume`` (continue the run in --out) or ``--resume CHECKPOINT`` (start the run in --out from
    another run's training checkpoint of ``kind``), and ``--overwrite`` (start a new run in place of the one in
    --out)."""
    parser.add_argument(
        "--resume",
        nargs="?",
        const=True,
        default=False,
        metavar="CHECKPOINT",
        help=f"alone: continue {what} in --out from its last checkpoint; with a CHECKPOINT (another 'train {kind}' "
        "run's "
        f"checkpoint.safetensors, or its folder): start {what} in --out from that checkpoint's networks, optimizer "
        f"states and iteration, with --out's config (or --config and the flags)",
    )
    add_overwrite(
        parser,
        "start a new run in --out in place of the one there (its checkpoint, metrics and config are replaced); "
        "without it, a folder holding a run is refused unless --resume",
    )


def _view_network(parser: argparse.ArgumentParser, kind: str) -> None:
    parser.add_argument(
        "--shapes", required=True, help="folder of prepared shapes (.npz from 'mesh2tex prepare shapes')"
    )
    add_out(parser, "run directory (config, views cache, checkpoint, metrics)")
    config = ConfigOptions(parser, VIEW_CONFIG, what="the training config")
    config.add("--iters", type=int, help="optimisation steps (total, also when resuming)")
    config.add("--batch", type=int, help="views per step")
    config.add("--samples", type=int, key="data.samples", help="rendered training views (plus held-out ones)")
    config.add("--resolution", type=int, key="data.resolution", help="side of the rendered views")
    config.add("--category", choices=["chair", "car"], key="data.category", help="material library of the renders")
    config.add(
        "--variety",
        choices=["boxy", "real"],
        key="data.variety",
        help="which world's materials the renders take: the original library (boxy) or materials a photo would show "
        "(real)",
    )
    add_checkpoint(
        parser,
        f"a generator, a 'train gan' checkpoint (RUN/checkpoint.safetensors) {SHIPPED_MODELS_HELP}, that textures a "
        "share (the config's data.gan_share) of the rendered views (default: none, procedural materials only)",
        config=config,
        key="data.gan_checkpoint",
        alias="--gan",
    )
    config.add("--device", choices=DEVICES, help="where to train")
    config.add("--seed", type=int, help="random seed")
    add_resume(parser, kind, f"the {kind} run")


def pose(parser: argparse.ArgumentParser) -> None:
    _view_network(parser, "pose")


def noc(parser: argparse.ArgumentParser) -> None:
    _view_network(parser, "noc")


def mask(parser: argparse.ArgumentParser) -> None:
    _view_network(parser, "mask")


def nca(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--exemplar", required=True, help="the texture photo to grow (any image file)")
    add_out(parser, "run directory (config, checkpoint, metrics, samples)")
    config = ConfigOptions(parser, "mesh2tex.train.nca:TrainNCAConfig", what="the training config")
    config.add("--mesh", help="training mesh: sphere, sphere:N, a prepared shape .npz or a mesh file")
    config.add("--iters", type=int, help="training iterations (total, also when resuming)")
    config.add("--views", type=int, help="random views per state and iteration")
    config.add("--resolution", type=int, help="render resolution")
    config.add("--steps", metavar="MIN,MAX", key=("steps_min", "steps_max"), help="rollout length range")
    config.add("--pool", type=int, help="pool size")
    parser.add_argument("--parent", help="start from this trained nca checkpoint (its lineage: the two can be grafted)")
    config.add("--readout", choices=["linear", "lppn"], key="nca.readout", help="state-to-colour readout")
    parser.add_argument(
        "--vgg-weights",
        help="ImageNet VGG19 weights (default: $MESH2TEX_VGG_WEIGHTS, torch's cache, else random weights)",
    )
    config.add("--device", choices=DEVICES, help="where to train")
    config.add("--seed", type=int, help="random seed")
    add_resume(parser, "nca")
