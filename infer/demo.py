"""``mesh2tex demo [--out DIR]``: the whole pipeline on the embedded synthetic chair world.

Stages (each one resumes: re-running the command after an interruption continues where it stopped):

1. ``world/``       ``prepare synthetic``: procedural chairs, textured ground truth, photos, queries
2. ``shapes/``      ``prepare shapes``: quad hierarchies of the training shapes (``train/``) and of
                    the held-out query shapes (``query/``)
3. ``gan/``         ``train gan`` on the training shapes and the photos
4. ``pose/ noc/``   ``train pose`` and ``train noc`` on one set of rendered views of the training
                    shapes (half textured by the GAN of step 3, half by procedural materials)
5. ``transfer/``    ``infer transfer``: a held-out mesh textured after a held-out query photo, pose
                    and NOC predicted by the networks
6. ``metrics.json`` the transferred asset (the GLB itself, rendered at the query's true pose)
                    against the query photo; the generation protocol (trained, untrained and
                    ground-truth rows on the held-out shapes, gap closed, diversity across latents)
7. ``report.html``  everything above on one page

The defaults are a CPU budget (about 17 minutes on 2 cores), far below the paper's training
(50k iterations on two GPUs): the figures show the pipeline working, not the method's ceiling.
``--config YAML`` changes any field of :class:`DemoConfig`.
"""

from __future__ import annotations

import json
import shutil
import time
import typing
from dataclasses import asdict, dataclass, field
from pathlib import Path

import yaml

from mesh2tex.cli import main as cli_main
from mesh2tex.config import check_fields, load_config, save_config
from mesh2tex.errors import UserError
from mesh2tex.evaluation.generation import GenerationConfig, run_generation_protocol
from mesh2tex.io.assets import check_texture_format
from mesh2tex.io.atomic import atomic_path, write_json, write_text
from mesh2tex.io.outputs import guard_outputs, remove_outputs
from mesh2tex.nn.view_nets import VIEWS_NAME
from mesh2tex.options import config_overrides
from mesh2tex.progress import JsonLines
from mesh2tex.runtime import select_device

from .demo_metrics import pick_query, transfer_metrics
from .demo_report import write_report


@dataclass
class DemoGanConfig:
    iters: int = 1200  # GAN iterations (the demo world's learning curves in docs/results/gan.md)
    resolution: int = 64  # GAN render resolution
    views: int = 4  # views per shape and GAN iteration
    channels: list[int] = field(
        default_factory=lambda: [32, 48, 64, 64]
    )  # encoder and synthesis widths, finest first: one per level
    discriminator_base: int = 1024  # discriminator width: min(base / resolution, 128) channels (library default 2048)
    lr_field: float = 0.0012  # psi's learning rate (library default and paper 1e-4, over 50k iterations)
    tiny_networks: bool = False  # networks a few channels wide (the --quick smoke test)

    def __post_init__(self):
        check_fields(
            self,
            at_least={"iters": 0, "resolution": 8, "views": 1, "channels": 1, "discriminator_base": 1},
            positive=("lr_field",),
        )


@dataclass
class DemoViewNetsConfig:
    samples: int = 1536  # rendered views for the pose and NOC networks (rendered once, shared by both)
    resolution: int = 64  # their input size
    # the pose network's channel width (as good as 16 on held-out queries, 8 worse; docs/results/demo.md)
    width: int = 12
    # the NOC network's (12 or 16: a sixth lower NOC error on queries, no better transfer, 2-3.5x the time)
    noc_width: int = 8
    pose_iters: int = 1500  # pose network steps (1000 read the held-out queries worse; docs/results/demo.md)
    noc_iters: int = 400  # NOC network steps

    def __post_init__(self):
        check_fields(
            self, at_least={"samples": 1, "resolution": 8, "width": 1, "noc_width": 1, "pose_iters": 0, "noc_iters": 0}
        )


@dataclass
class DemoTransferConfig:
    query: int = 0  # which query photo of the world to texture (index into the sorted queries, modulo their number)
    resolution: int = 64  # side of the transfer renders
    latent_iters: int = 60  # stage 1 iterations (paper: 100)
    refine_iters: int = 120  # stage 2 iterations (paper: 300)
    texture_size: int = 512  # baked UV texture of the GLB
    texture_format: str = "png"  # how the GLB embeds it: png (lossless), jpeg or webp (lossy, smaller)

    def __post_init__(self):
        check_fields(self, at_least={"resolution": 16, "latent_iters": 0, "refine_iters": 0, "texture_size": 16})
        check_texture_format(self.texture_format)


@dataclass
class DemoGenerationConfig:
    views: int = 8  # views per held-out shape of the GAN renders compared with the photos (generation protocol)
    latents: int = 8  # latents per held-out shape for the diversity measures

    def __post_init__(self):
        check_fields(self, at_least={"views": 1, "latents": 2})


# The flat names of the settings a demo folder recorded (demo_config.yaml) before they were nested: such a folder
# still resumes.
FORMER_NAMES = {
    "gan_iters": "gan.iters",
    "gan_resolution": "gan.resolution",
    "gan_views": "gan.views",
    "gan_channels": "gan.channels",
    "gan_discriminator_base": "gan.discriminator_base",
    "gan_lr_field": "gan.lr_field",
    "tiny_networks": "gan.tiny_networks",
    "view_samples": "view_nets.samples",
    "view_resolution": "view_nets.resolution",
    "view_width": "view_nets.width",
    "pose_iters": "view_nets.pose_iters",
    "noc_iters": "view_nets.noc_iters",
    "query": "transfer.query",
    "transfer_resolution": "transfer.resolution",
    "latent_iters": "transfer.latent_iters",
    "refine_iters": "transfer.refine_iters",
    "texture_size": "transfer.texture_size",
    "texture_format": "transfer.texture_format",
    "eval_views": "generation.views",
    "eval_latents": "generation.latents",
}


@dataclass
class DemoConfig:
    seed: int = 0  # master seed of every stage
    shapes: int = 12  # procedural chairs (a quarter held out for queries)
    views: int = 8  # photos per training chair
    photo_resolution: int = 128  # side of the photos and queries
    faces: int = 1536  # finest quad count of the prepared shapes (the library default is 6144)
    levels: int = 4  # levels of the quad hierarchy
    workers: int = 2  # processes of 'prepare shapes'
    gan: DemoGanConfig = field(default_factory=DemoGanConfig)  # 'train gan'
    view_nets: DemoViewNetsConfig = field(default_factory=DemoViewNetsConfig)  # 'train pose' and 'train noc'
    transfer: DemoTransferConfig = field(default_factory=DemoTransferConfig)  # 'infer transfer'
    generation: DemoGenerationConfig = field(
        default_factory=DemoGenerationConfig
    )  # the generation protocol of the report

    # a --config of the flat layout is told where each key went
    MOVED_KEYS: typing.ClassVar[dict[str, str]] = FORMER_NAMES

    def __post_init__(self):
        if len(self.gan.channels) != self.levels:
            raise ValueError(
                f"gan.channels has {len(self.gan.channels)} entries, the demo's hierarchy has {self.levels} levels"
            )


QUICK = {  # a smoke-test budget: every stage runs, nothing learns much
    "shapes": 4,
    "views": 2,
    "photo_resolution": 64,
    "faces": 96,
    "levels": 3,
    "workers": 1,
    "gan.iters": 2,
    "gan.resolution": 32,
    "gan.views": 1,
    "gan.channels": [8, 8, 8],
    "gan.tiny_networks": True,
    "view_nets.samples": 16,
    "view_nets.resolution": 32,
    "view_nets.width": 4,
    "view_nets.pose_iters": 2,
    "view_nets.noc_iters": 2,
    "transfer.latent_iters": 3,
    "transfer.refine_iters": 2,
    "transfer.texture_size": 64,
    "generation.views": 2,
    "generation.latents": 2,
}


def _stage(name: str, argv: list[str], log: JsonLines) -> float:
    """Run one CLI stage in-process; a failure stops the demo with the stage's name."""
    print(f"\n== demo: {name}: mesh2tex {' '.join(argv)}", flush=True)
    start = time.perf_counter()
    code = cli_main(argv)
    seconds = round(time.perf_counter() - start, 1)
    log.write({"stage": name, "exit_code": code, "seconds": seconds})
    if code != 0:
        raise UserError(f"demo stage '{name}' failed (exit code {code}); fix the cause above and re-run to resume")
    return seconds


def _gan_config(cfg: DemoConfig) -> dict:
    channels = list(cfg.gan.channels)
    gan = {
        "sample_every": 0,
        "checkpoint_every": 50,
        "log_every": 10,
        "generator": {"encoder_channels": channels, "synthesis_channels": channels},
        "discriminator": {"channel_base": cfg.gan.discriminator_base},
        "optim": {"lr_field": cfg.gan.lr_field},
    }
    if cfg.gan.tiny_networks:
        gan["generator"].update(
            {"z_dim": 16, "w_dim": 16, "mapping_layers": 2, "field_hidden": 16, "aux_latent_dim": 8}
        )
        gan["discriminator"] = {"channel_base": 64, "channel_max": 16}
    return gan


def run_pipeline(out: Path, cfg: DemoConfig, device: str = "auto") -> dict:
    """Run (or resume) every stage into ``out``, the training and transfer stages on ``device`` (auto, cpu or
    cuda); returns {stage: seconds of this run}."""
    out.mkdir(parents=True, exist_ok=True)
    log = JsonLines(out / "demo_log.jsonl")
    seconds: dict[str, float] = {}
    world = _prepare_stages(out, cfg, log, seconds)
    _training_stages(out, world, cfg, device, log, seconds)
    _transfer_stage(out, world, cfg, device, log, seconds)
    return seconds


def _prepare_stages(out: Path, cfg: DemoConfig, log: JsonLines, seconds: dict[str, float]) -> Path:
    """The world, then its training and query shapes prepared; the world's folder."""
    world = out / "world"
    seconds["prepare synthetic"] = _stage(
        "prepare synthetic",
        [
            "prepare",
            "synthetic",
            "--out",
            str(world),
            "--category",
            "chair",
            "--shapes",
            str(cfg.shapes),
            "--views",
            str(cfg.views),
            "--resolution",
            str(cfg.photo_resolution),
            "--seed",
            str(cfg.seed),
        ],
        log,
    )
    split = json.loads((world / "index.json").read_text())["split"]
    for part, names in (("train", split["train_shapes"]), ("query", split["query_shapes"])):
        meshes = [str(world / "meshes" / f"{n}.obj") for n in names]
        seconds[f"prepare shapes ({part})"] = _stage(
            f"prepare shapes ({part})",
            [
                "prepare",
                "shapes",
                "--input",
                *meshes,
                "--out",
                str(out / "shapes" / part),
                "--faces",
                str(cfg.faces),
                "--levels",
                str(cfg.levels),
                "--workers",
                str(cfg.workers),
                "--seed",
                str(cfg.seed),
            ],
            log,
        )
    return world


def _training_stages(
    out: Path, world: Path, cfg: DemoConfig, device: str, log: JsonLines, seconds: dict[str, float]
) -> None:
    """The GAN, then the pose and NOC networks (sharing one set of rendered views)."""
    gan_yaml = out / "gan_config.yaml"
    write_text(gan_yaml, yaml.safe_dump(_gan_config(cfg), sort_keys=False))
    seconds["train gan"] = _stage(
        "train gan",
        [
            "train",
            "gan",
            "--shapes",
            str(out / "shapes" / "train"),
            "--images",
            str(world),
            "--out",
            str(out / "gan"),
            "--config",
            str(gan_yaml),
            "--iters",
            str(cfg.gan.iters),
            "--resolution",
            str(cfg.gan.resolution),
            "--views",
            str(cfg.gan.views),
            "--seed",
            str(cfg.seed),
            "--device",
            device,
            "--resume",
        ],
        log,
    )
    nets = cfg.view_nets
    for kind, iters, width in (("pose", nets.pose_iters, nets.width), ("noc", nets.noc_iters, nets.noc_width)):
        views_yaml = out / f"{kind}_config.yaml"
        write_text(views_yaml, yaml.safe_dump({"width": width, "log_every": 25, "checkpoint_every": 100}))
        share_views(out / "pose" / VIEWS_NAME, out / kind / VIEWS_NAME)
        seconds[f"train {kind}"] = _stage(
            f"train {kind}",
            [
                "train",
                kind,
                "--shapes",
                str(out / "shapes" / "train"),
                "--out",
                str(out / kind),
                "--config",
                str(views_yaml),
                "--iters",
                str(iters),
                "--samples",
                str(nets.samples),
                "--resolution",
                str(nets.resolution),
                "--batch",
                "32",
                "--seed",
                str(cfg.seed),
                "--device",
                device,
                "--checkpoint",
                str(out / "gan" / "checkpoint.safetensors"),
                "--resume",
            ],
            log,
        )


def _transfer_stage(
    out: Path, world: Path, cfg: DemoConfig, device: str, log: JsonLines, seconds: dict[str, float]
) -> None:
    """The transfer from the demo's query photo, unless a finished one is in ``out/transfer``."""
    query = pick_query(world, cfg.transfer.query)
    transfer = out / "transfer"
    if not (transfer / "report.json").is_file():
        seconds["infer transfer"] = _stage(
            "infer transfer",
            [
                "infer",
                "transfer",
                "--checkpoint",
                str(out / "gan" / "checkpoint.safetensors"),
                "--mesh",
                str(out / "shapes" / "query" / f"{query['shape']}.npz"),
                "--image",
                str(world / query["image"]),
                "--mask",
                str(world / query["mask"]),
                "--pose",
                "auto",
                "--pose-checkpoint",
                str(out / "pose" / "checkpoint.safetensors"),
                "--noc-checkpoint",
                str(out / "noc" / "checkpoint.safetensors"),
                "--out",
                str(transfer),
                "--resolution",
                str(cfg.transfer.resolution),
                "--latent-iters",
                str(cfg.transfer.latent_iters),
                "--refine-iters",
                str(cfg.transfer.refine_iters),
                "--texture-size",
                str(cfg.transfer.texture_size),
                "--texture-format",
                cfg.transfer.texture_format,
                "--seed",
                str(cfg.seed),
                "--device",
                device,
                "--overwrite",
            ],
            log,
        )


def share_views(source: Path, target: Path) -> None:
    """Let the NOC run start from the pose run's rendered views: both use the same data settings, so
    'train noc' accepts the cache (it checks the settings fingerprint) instead of rendering again."""
    if source != target and source.is_file() and not target.exists():
        with atomic_path(target) as tmp:
            shutil.copyfile(source, tmp)


def generation_metrics(out: Path, cfg: DemoConfig, device: str = "auto") -> dict:
    """The generation protocol (:mod:`mesh2tex.evaluation.generation`) on the world's held-out shapes: trained,
    untrained and oracle rows against a fresh photo set, the gap closed and the diversity across latents;
    writes the samples grid ``gan/generation_samples.png`` (rows latents, columns views, last row the
    ground truth)."""
    gen_cfg = GenerationConfig(views=cfg.generation.views, latents=cfg.generation.latents, kid_fid=False, seed=cfg.seed)
    return run_generation_protocol(
        out / "world",
        out / "shapes" / "query",
        out / "gan" / "checkpoint.safetensors",
        gen_cfg,
        select_device(device),
        samples_path=out / "gan" / "generation_samples.png",
        log=lambda line: None,
    )


def build_config(args) -> DemoConfig:
    """The demo config: its defaults, then --config, then --quick's budget, --seed and --texture-format."""
    return load_config(DemoConfig, args.config, {**(QUICK if args.quick else {}), **config_overrides(args)})


def saved_config(path: Path) -> DemoConfig:
    """The settings a demo folder recorded (``demo_config.yaml``), also of the flat layout before they were nested."""
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    if not isinstance(data, dict):
        raise UserError(f"{path}: not a demo's settings; choose another --out")
    return load_config(DemoConfig, None, {FORMER_NAMES.get(key, key): value for key, value in data.items()})


# What a demo writes into --out: --overwrite removes these (and nothing else) before it starts again.
DEMO_OUTPUTS = (
    "world",
    "shapes",
    "gan",
    "pose",
    "noc",
    "transfer",
    "report.html",
    "metrics.json",
    "demo_log.jsonl",
    "demo_config.yaml",
    "gan_config.yaml",
    "pose_config.yaml",
    "noc_config.yaml",
)


def run(args) -> int:
    out = Path(args.out)
    saved = out / "demo_config.yaml"
    cfg = build_config(args)
    select_device(args.device)  # --device cuda without a GPU is refused before any stage runs
    if not saved.is_file():  # a new demo: files of the user's under its names are kept without --overwrite
        guard_outputs(out, DEMO_OUTPUTS, args.overwrite)
    if args.overwrite:
        remove_outputs(out, DEMO_OUTPUTS)
    if saved.is_file() and saved_config(saved) != cfg:
        raise UserError(
            f"{out}: holds a demo run with other settings ({saved}); resume it with the same options, "
            "start again with --overwrite, or choose another --out"
        )
    out.mkdir(parents=True, exist_ok=True)
    save_config(cfg, saved)
    start = time.perf_counter()
    run_pipeline(out, cfg, args.device)
    # Seconds per stage summed over every run of the demo in this folder (an interrupted stage counts twice).
    seconds: dict[str, float] = {}
    for record in JsonLines(out / "demo_log.jsonl").read():
        seconds[record["stage"]] = round(seconds.get(record["stage"], 0.0) + record["seconds"], 1)
    query = pick_query(out / "world", cfg.transfer.query)
    t = time.perf_counter()
    metrics = {
        "transfer": transfer_metrics(out / "world", out / "transfer", query, cfg.transfer.resolution),
        "generation": generation_metrics(out, cfg, args.device),
    }
    seconds["metrics"] = round(time.perf_counter() - t, 1)
    seconds["demo total (this run)"] = round(time.perf_counter() - start, 1)
    write_json(out / "metrics.json", {"query": query, **metrics, "seconds": seconds, "config": asdict(cfg)})
    report = write_report(out, cfg, seconds, query, metrics)
    print(f"\ndemo finished in {seconds['demo total (this run)']:.0f} s: open {report}")
    return 0
