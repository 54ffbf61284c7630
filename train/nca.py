"""``mesh2tex train nca``: grow a texture from one exemplar image with a mesh cellular automaton.

    mesh2tex train nca --exemplar IMG --out RUN [--mesh sphere|sphere:N|SHAPE.npz|MESH] [--iters N]
                       [--views K] [--resolution R] [--steps MIN,MAX] [--pool P] [--parent CKPT]
                       [--readout linear|lppn] [--vgg-weights PATH] [--config YAML] [--device]
                       [--seed S] [--resume [CHECKPOINT]]

Each iteration: ``batch`` states drawn from a pool (every ``seed_every`` iterations the first is
replaced by a fresh seed), a rollout of a random number of steps in [MIN, MAX] with gradients
through every step, K random views of each state through the rasterizer, the style loss against
the exemplar (:mod:`mesh2tex.losses.ot_style`) plus an overflow penalty on states and colours,
per-parameter gradient normalisation, Adam; the final states go back into the pool. The model of
the automaton is :mod:`mesh2tex.nn.nca`. ``--parent`` starts from a trained model (same lineage:
the two can be grafted) and records its digest.
"""

from __future__ import annotations

import sys
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from mesh2tex.train import runs

from mesh2tex.config import check_fields, config_from_dict, load_config
from mesh2tex.errors import UserError
from mesh2tex.geometry.primitives import load_surface, mean_edge_length
from mesh2tex.io.checkpoint import checkpoint_digest, load_checkpoint, save_checkpoint
from mesh2tex.io.images import colours_to_uint8, images_to_uint8, load_image, save_png
from mesh2tex.losses.ot_style import STYLE_LOSSES, ExemplarFeatures, needs_vgg, style_loss
from mesh2tex.losses.structure import PATCH_SIZE
from mesh2tex.nn.cell_graph import CellGraph, build_cell_graph
from mesh2tex.nn.nca import MeshNCA, NCAConfig, overflow_penalty
from mesh2tex.nn.render_texture import render_states
from mesh2tex.nn.vgg import load_vgg19
from mesh2tex.options import config_overrides
from mesh2tex.render import orbit_camera
from mesh2tex.render.cameras import NCACameraConfig, turntable_angles
from mesh2tex.synthetic.world import contact_sheet
from mesh2tex.texel_synthesis import VertexPatches, pixels_per_unit, walked_patch_terms

KIND = "nca"
METHODS = ("renders", "patches")  # how the loss sees the colours: rendered views, or patches walked on the mesh
PATCH_BANK = 8  # the patches method walks this many steps' patches once (VertexPatches), then draws from them
VIEW_START = 30.0  # azimuth of the first sample view: off the cube-sphere's face centres
MODEL_NAME = "model.safetensors"  # the trained automaton alone, what infer nca reads


@dataclass
class TrainNCAConfig:
    seed: int = 0
    iters: int = 1500  # training iterations
    # states per iteration (1 state and 1 view: 3x the Adam steps of 2 x 2 in the same time; docs/results/nca.md)
    batch: int = 1
    views: int = 1  # random views per state
    resolution: int = 128  # render resolution
    steps_min: int = 15  # rollout length per iteration: uniform in [steps_min, steps_max]
    steps_max: int = 25
    pool: int = 256  # states kept between iterations
    seed_every: int = 4  # every this many iterations a fresh seed replaces the batch's first state
    mesh: str = "sphere"  # the training mesh (see load_surface; "sphere": 32 subdivisions, 6,146 cells)
    exemplar_size: int = 128  # the exemplar is centre-cropped to a square and resized to this
    # "ot" (relaxed optimal transport + moments), "gram", "sw" (sliced Wasserstein), "ps" (oriented-band
    # statistics) or "patch" (sliced Wasserstein on raw multi-scale patches)
    style_loss: str = "ot"
    # how the loss sees the automaton's colours: renders (random rendered views) or patches (the patch loss's
    # patches walked on the training mesh octave by octave, as infer synthesize --method patches; patch only)
    method: str = "renders"
    vgg_depth: int = 4  # VGG19 style layers used (relu1_2 ... relu4_4; 0: RGB only); unused by ps and patch
    max_points: int = 1024  # feature positions per set in the OT and sw losses; patches per octave in patch
    overflow_weight: float = 10.0  # weight of the overflow penalty
    # weight of the sliced Wasserstein distance of the rendered pixels' RGB to the exemplar's (the joint
    # palette), added to the style loss; 0: off (ot and gram match colour moments of their own)
    colour_weight: float = 0.0
    lr: float = 1e-3  # Adam learning rate
    lr_milestones: list[float] = field(default_factory=lambda: [0.5, 0.8])  # fractions of iters where the rate drops
    lr_gamma: float = 0.3  # the drop
    device: str = "auto"
    log_every: int = 10
    sample_every: int = 100  # iterations between sample sheets (0: only at the end)
    checkpoint_every: int = 100  # iterations between checkpoints (0: only at the end)
    nca: NCAConfig = field(default_factory=NCAConfig)
    camera: NCACameraConfig = field(default_factory=NCACameraConfig)

    def __post_init__(self):
        check_fields(
            self,
            at_least={
                "iters": 1,
                "batch": 1,
                "views": 1,
                "resolution": 32,
                "steps_min": 1,
                "steps_max": 1,
                "pool": 1,
                "seed_every": 1,
                "exemplar_size": 32,
                "max_points": 1,
                "log_every": 1,
                "sample_every": 0,
                "checkpoint_every": 0,
                "overflow_weight": 0,
                "colour_weight": 0,
            },
            between={
                "vgg_depth": (0, 5),
                "lr_gamma": (0.0, 1.0),
                "lr_milestones": (0.0, 1.0),
                "resolution": (32, 4096),
                "exemplar_size": (32, 4096),
                "steps_max": (1, 10_000),
                "pool": (1, 100_000),
            },
            positive=("lr",),
        )
        if self.steps_max < self.steps_min:
            raise ValueError(f"steps_max {self.steps_max} is below steps_min {self.steps_min}")
        if self.batch > self.pool:
            raise ValueError(f"batch {self.batch} is larger than the pool {self.pool}")
        if self.style_loss not in STYLE_LOSSES:
            raise ValueError(f"style_loss must be one of {STYLE_LOSSES}, got {self.style_loss!r}")
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        if self.method == "patches" and self.style_loss != "patch":
            raise ValueError(
                f"method patches walks the patch loss's patches: it needs style_loss patch, got {self.style_loss!r}"
            )


def parse_steps(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    parts = text.split(",")
    try:
        low, high = (int(parts[0]), int(parts[-1])) if len(parts) in (1, 2) else (0, -1)
    except ValueError:
        low, high = 0, -1
    if not 1 <= low <= high:
        raise UserError(f"--steps {text}: expected MIN,MAX with 1 <= MIN <= MAX (or one number)")
    return low, high


def build_config(args) -> TrainNCAConfig:
    steps = parse_steps(args.steps)
    overrides = config_overrides(
        args, computed={"steps_min": steps[0] if steps else None, "steps_max": steps[1] if steps else None}
    )
    run_config = Path(args.out) / "config.yaml"
    if args.resume and not getattr(args, "overwrite", False) and run_config.is_file():
        if args.config:
            print(f"mesh2tex: note: resuming uses {run_config}; --config {args.config} is ignored", file=sys.stderr)
        return load_config(TrainNCAConfig, run_config, overrides)
    return load_config(TrainNCAConfig, args.config, overrides)


# ------------------------------------------------------------------------------------------ data
def load_exemplar(path: str | Path, size: int) -> torch.Tensor:
    """(1, 3, size, size) in [-1, 1]: the image's centred square, area-resized."""
    import torch.nn.functional as F

    rgb, _ = load_image(path)  # (H, W, 3) uint8; a bad file is a UserError naming it
    h, w = rgb.shape[:2]
    if min(h, w) < 8:
        raise UserError(f"{path}: a {w}x{h} image is too small to be an exemplar")
    side = min(h, w)
    top, left = (h - side) // 2, (w - side) // 2
    square = (
        torch.from_numpy(np.array(rgb[top : top + side, left : left + side])).permute(2, 0, 1)[None].float() / 127.5 - 1
    )
    return (
        F.interpolate(square, size=(size, size), mode="area")
        if side >= size
        else F.interpolate(square, size=(size, size), mode="bilinear", align_corners=False)
    )


def random_cameras(cfg: TrainNCAConfig, count: int, generator: torch.Generator) -> torch.Tensor:
    """(count, 4, 4) mvp of random orbit views of the unit ball."""
    azimuth = torch.rand(count, generator=generator) * 360.0
    elevation = cfg.camera.elevation_min + torch.rand(count, generator=generator) * (
        cfg.camera.elevation_max - cfg.camera.elevation_min
    )
    return orbit_camera(azimuth, elevation, distance=cfg.camera.distance, fov=cfg.camera.fov).mvp


def fixed_cameras(cfg: TrainNCAConfig, count: int = 4, elevation: float = 20.0) -> torch.Tensor:
    """(count, 4, 4) mvp of evenly spaced views around the mesh, for samples and reports."""
    return orbit_camera(
        *turntable_angles(count, elevation, start=VIEW_START), distance=cfg.camera.distance, fov=cfg.camera.fov
    ).mvp


# --------------------------------------------------------------------------------------- trainer
class NCATrainer:
    """The loop of ``train nca`` (see the module docstring)."""

    def __init__(
        self,
        cfg: TrainNCAConfig,
        exemplar: torch.Tensor,
        graph: CellGraph,
        run: runs.RunDirectory,
        device: torch.device,
        vgg,
        parent: dict | None = None,
        cell_spacing: float = 0.0,
    ):
        self.cfg, self.run, self.device, self.vgg = cfg, run, device, vgg
        self.graph = graph.to(device)
        depth = cfg.vgg_depth if needs_vgg(cfg.style_loss) else 0
        self.exemplar = ExemplarFeatures.compute(vgg, exemplar.to(device), depth)
        self.palette = ExemplarFeatures.compute(None, exemplar.to(device), 0) if cfg.colour_weight else None
        # here, not earlier: loading VGG may or may not draw random numbers (it is cached)
        runs.seed_everything(cfg.seed)
        self.model = MeshNCA(cfg.nca).to(device)
        self.parent_record = None if parent is None else {"path": parent["path"], "digest": parent["digest"]}
        # Models of one lineage (a parent and every model trained from it) can be grafted.
        self.lineage = parent["lineage"] if parent is not None else uuid.uuid4().hex
        if parent is not None:
            self.model.load_state_dict(parent["state"])
        self.optimizer = torch.optim.Adam(self.model.parameters(), lr=cfg.lr)
        self.cell_spacing = cell_spacing
        self.generator = torch.Generator().manual_seed(cfg.seed)
        self.pool = self.model.seed_state(cfg.pool, self.graph.num_cells, device, generator=self.generator)
        self.patches = None
        if cfg.method == "patches":
            spacing = 1 / pixels_per_unit(cfg.resolution, cfg.camera.distance, cfg.camera.fov)  # one exemplar pixel
            self.patches = VertexPatches(
                graph.positions.cpu().numpy(),
                graph.triangles.cpu().numpy(),
                spacing,
                len(self.exemplar.patch_sets()),
                PATCH_SIZE,
                PATCH_BANK * cfg.max_points,
                seed=cfg.seed,
            )
        self.iteration = 0

    def learning_rate(self, iteration: int) -> float:
        drops = sum(iteration >= m * self.cfg.iters for m in self.cfg.lr_milestones)
        return self.cfg.lr * self.cfg.lr_gamma**drops

    def step(self) -> dict[str, float]:
        cfg = self.cfg
        for group in self.optimizer.param_groups:
            group["lr"] = self.learning_rate(self.iteration)
        index = torch.randperm(cfg.pool, generator=self.generator)[: cfg.batch].to(self.device)
        state = self.pool[index].clone()
        if self.iteration % cfg.seed_every == 0:
            state[:1] = self.model.seed_state(1, self.graph.num_cells, self.device, generator=self.generator)
        steps = int(torch.randint(cfg.steps_min, cfg.steps_max + 1, (1,), generator=self.generator))
        state = self.model.rollout(state, self.graph, steps)
        rgb = self.model.vertex_colours(state)  # (B, V, 3): the overflow penalty's, and what walked patches read
        style, colour = self.losses(state, rgb)
        overflow = overflow_penalty(state, rgb)
        loss = style + cfg.colour_weight * colour + cfg.overflow_weight * overflow
        # before any update
        runs.check_finite(
            {"loss": loss, "loss_style": style, "loss_colour": colour, "loss_overflow": overflow}, self.iteration
        )
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        with torch.no_grad():  # per-parameter gradient normalisation (as texture NCAs train)
            for p in self.model.parameters():
                if p.grad is not None:
                    p.grad /= p.grad.norm() + 1e-8
        self.optimizer.step()
        self.pool[index] = state.detach()
        self.iteration += 1
        logs = {
            "loss": float(loss.detach()),
            "loss_style": float(style.detach()),
            "loss_overflow": float(overflow.detach()),
            **({"loss_colour": float(colour.detach())} if self.palette is not None else {}),
            "steps": steps,
            "lr": self.learning_rate(self.iteration - 1),
        }
        return {k: round(v, 6) for k, v in logs.items()}

    def losses(self, state: torch.Tensor, rgb: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The style loss and the palette term (0 when off) of the states (B, V, C), whose cells' colours are
        ``rgb`` (B, V, 3), as ``method`` sees them."""
        cfg = self.cfg
        colour = torch.zeros((), device=self.device)
        if self.patches is not None:
            styles, colours = [], []
            for cells in rgb:  # (V, 3) per state
                sets = self.patches.sets(cells, cfg.max_points, self.generator)
                style, palette = walked_patch_terms(sets, self.exemplar, self.palette, cfg.max_points, self.generator)
                styles.append(style)
                colours += [] if palette is None else [palette]
            return torch.stack(styles).mean(), torch.stack(colours).mean() if colours else colour
        mvp = random_cameras(cfg, cfg.batch * cfg.views, self.generator).to(self.device)
        views = render_states(self.model, state, self.graph, mvp, cfg.resolution)
        style = style_loss(
            self.vgg, views.images, views.mask, self.exemplar, cfg.style_loss, cfg.max_points, self.generator
        )
        if self.palette is not None:  # drawn only when on, so that the random stream is otherwise unchanged
            colour = style_loss(None, views.images, views.mask, self.palette, "sw", cfg.max_points, self.generator)
        return style, colour

    # -------------------------------------------------------------------------------- state I/O
    def meta(self) -> dict:
        return {
            "iteration": self.iteration,
            "config": runs.dumps_config(self.cfg),
            "nca": runs.dumps_config(self.cfg.nca),
            "cell_spacing": self.cell_spacing,
            "vgg": self.vgg.source,
            "parent": self.parent_record,
            "lineage": self.lineage,
            "generator_state": self.generator.get_state().tolist(),
        }

    def exemplar_uint8(self) -> torch.Tensor:
        """(3, H, W) uint8: the exemplar as the model saw it, kept in every checkpoint."""
        return torch.from_numpy(colours_to_uint8(self.exemplar.image[0]))

    def save(self, path: Path) -> None:
        runs.save_training_state(
            path,
            KIND,
            {"model": self.model},
            {"adam": self.optimizer},
            {"pool": {"states": self.pool.cpu()}, "exemplar": {"image": self.exemplar_uint8()}},
            self.meta(),
            [runs.rng_to_state()],
        )

    def resume(self, path: Path) -> None:
        """Load the training state of ``path``: the run's own checkpoint, or another run's to start from."""
        groups, meta = runs.load_training_state(
            path, KIND, {"model": self.model}, {"adam": self.optimizer}, self.device
        )
        pool = groups["pool"]["states"]
        if pool.shape != self.pool.shape:
            raise UserError(
                f"{path}: its pool is {tuple(pool.shape)}, this config and mesh need {tuple(self.pool.shape)}"
            )
        self.pool = pool.to(self.device)
        self.iteration = int(meta["iteration"])
        self.parent_record = meta.get("parent")
        self.lineage = meta.get("lineage", self.lineage)
        self.generator.set_state(torch.tensor(meta["generator_state"], dtype=torch.uint8))
        runs.rng_from_state(meta["rng"][0])
        if path == self.run.checkpoint_path:
            self.run.metrics.truncate_after("iteration", self.iteration)

    @torch.no_grad()
    def write_samples(self) -> None:
        """samples/iter_NNNNNN.png: the exemplar beside 4 views of a state grown from the seed for steps_max * 2
        steps."""
        generator = torch.Generator(device=self.device).manual_seed(self.cfg.seed + 1)
        state = self.model.seed_state(1, self.graph.num_cells, self.device)
        for _ in range(self.cfg.steps_max * 2):
            state = self.model.step(state, self.graph, generator=generator)
        views = render_states(
            self.model, state, self.graph, fixed_cameras(self.cfg).to(self.device), self.cfg.resolution, background=1.0
        )
        size = self.cfg.resolution
        exemplar = torch.nn.functional.interpolate(
            self.exemplar.image, size=(size, size), mode="bilinear", align_corners=False
        )
        tiles = list(images_to_uint8(torch.cat([exemplar, views.images])))
        save_png(self.run.samples_dir / f"iter_{self.iteration:06d}.png", contact_sheet(tiles, len(tiles)))

    def train(self) -> None:
        cfg = self.cfg
        advice = (
            f"Lower lr in {self.run.config_path} and --resume (the rate is read from the run's config at every step)"
        )
        runs.training_loop(
            self,
            self.run,
            iters=cfg.iters,
            desc="train nca",
            device=self.device,
            log_every=cfg.log_every,
            checkpoint_every=cfg.checkpoint_every,
            advice=advice,
            postfix=lambda logs: {"style": f"{logs['loss_style']:.3f}"},
            periodic=[runs.Every(cfg.sample_every, self.write_samples, final="never")],
        )
        self.save_model(self.run.root / MODEL_NAME)
        self.write_samples()

    def save_model(self, path: Path) -> None:
        """The inference part: weights, exemplar and metadata (no pool, optimizer or RNG), about 100 kB."""
        meta = {k: v for k, v in self.meta().items() if k != "generator_state"}
        save_checkpoint(
            path,
            {
                "model": {k: v.detach().cpu() for k, v in self.model.state_dict().items()},
                "exemplar": {"image": self.exemplar_uint8()},
            },
            kind=KIND,
            meta=meta,
        )


def load_parent(path: str) -> tuple[NCAConfig, dict]:
    """A parent checkpoint's automaton config and {state, path, digest, lineage}."""
    groups, meta = load_checkpoint(path, kind=KIND)
    if "model" not in groups:
        raise UserError(f"{path}: the checkpoint holds no automaton weights")
    parent_cfg = config_from_dict(NCAConfig, meta.get("nca", {}), where=f"{path} nca")
    digest = checkpoint_digest(path, "parent checkpoint")
    return parent_cfg, {
        "state": groups["model"],
        "path": str(path),
        "digest": digest,
        "lineage": meta.get("lineage") or digest,
    }


def run(args) -> int:
    cfg = build_config(args)
    device = runs.select_device(cfg.device)
    run_dir = runs.RunDirectory(args.out)
    source = runs.start_from(args.resume, run_dir, KIND, overwrite=args.overwrite)  # checked before anything is written
    exemplar = load_exemplar(args.exemplar, cfg.exemplar_size)
    parent = None
    if args.parent and source is None:
        # A child takes its parent's automaton (sizes, perception, readout): that is what makes the two graftable.
        cfg.nca, parent = load_parent(args.parent)
    vertices, faces = load_surface(cfg.mesh)
    graph = build_cell_graph(vertices, faces, cfg.nca.neighbourhood)
    # ps and patch need no network: no warning that its weights are missing (its source is still recorded)
    vgg = load_vgg19(args.vgg_weights, device=device, warn=needs_vgg(cfg.style_loss))
    trainer = NCATrainer(
        cfg, exemplar, graph, run_dir, device, vgg, parent=parent, cell_spacing=mean_edge_length(vertices, faces)
    )
    if source is not None:
        trainer.resume(source)  # before config.yaml is written: a checkpoint that does not fit leaves --out as it was
    run_dir.start(cfg, resume=source == run_dir.checkpoint_path, overwrite=args.overwrite)
    trainer.train()
    print(f"trained {trainer.iteration} iterations on {graph.num_cells} cells; checkpoint {run_dir.checkpoint_path}")
    return 0
