"""``mesh2tex train gan``: train the mesh-field texture GAN on prepared shapes and a folder of photos.

    mesh2tex train gan --shapes DIR --images DIR --out RUN [--config YAML] [--iters N] [--batch B]
                       [--views K] [--resolution R] [--device auto|cpu|cuda] [--seed S] [--resume [CHECKPOINT]]

Each iteration: B shapes, K random views each (azimuth uniform, elevation in a range, camera
jitter), one rasterization of the finest level shared by the phases; G main (+ path-length reg
every 4, on half the shapes), D main (+ R1 every 16) through :class:`mesh2tex.losses.GanLoss`; an EMA of the generator.
Several processes: ``torchrun --nproc_per_node N -m mesh2tex train gan ...`` (gloo on CPU, nccl on
CUDA); each process renders its own B shapes and gradients are averaged.
"""

from __future__ import annotations

import contextlib
import sys
from pathlib import Path

import numpy as np
import torch
from mesh2tex.train import runs
from mesh2tex.train.gan_config import TrainGanConfig

from mesh2tex.config import load_config
from mesh2tex.errors import UserError
from mesh2tex.geometry.prepared import PreparedShape, load_shapes
from mesh2tex.io.images import images_to_uint8, save_png
from mesh2tex.losses.augment import AdaptiveAugment, DiffAugment
from mesh2tex.losses.gan import GanLoss, GanScene
from mesh2tex.metrics.generation import mean_pairwise_delta_e, object_set_swd
from mesh2tex.models import save_inference_checkpoint, shape_hierarchy
from mesh2tex.models.store import D_FIELD, D_PROXY, GAN_LOSS, GENERATOR, GENERATOR_CONFIG, GENERATOR_EMA, HIERARCHY
from mesh2tex.nn.batch import collate_shapes
from mesh2tex.nn.discriminator import Discriminator
from mesh2tex.nn.generator import TextureGenerator
from mesh2tex.nn.render_texture import rasterize_batch, render_field_views
from mesh2tex.options import config_overrides
from mesh2tex.photos import load_photo_collection
from mesh2tex.render import CameraConfig, composite_images, orbit_camera, random_lights, turntable_angles

KIND = "gan"


def composite_real(images: torch.Tensor, background: torch.Tensor) -> torch.Tensor:
    """uint8 (N, 4, R, R) photos over solid (N, 3) backgrounds in [-1, 1] -> float (N, 3, R, R) in [-1, 1]."""
    rgb = images[:, :3].float() / 127.5 - 1.0
    alpha = images[:, 3:].float() / 255.0
    return composite_images(rgb, alpha, background)


def random_cameras(n: int, cfg: CameraConfig, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """Random orbit views (azimuth uniform, elevation in range, jitter): (n, 4, 4) MVP matrices on
    ``device`` and the (n,) azimuths in degrees (CPU)."""
    azimuth = torch.rand(n) * 360.0 + torch.randn(n) * cfg.jitter_degrees
    elevation = (
        cfg.elevation_min
        + torch.rand(n) * (cfg.elevation_max - cfg.elevation_min)
        + torch.randn(n) * cfg.jitter_degrees
    )
    distance = cfg.distance * (1.0 + torch.randn(n) * cfg.distance_jitter)
    return orbit_camera(azimuth, elevation.clamp(-89.0, 89.0), distance=distance, fov=cfg.fov).mvp.to(device), azimuth


# ---------------------------------------------------------------------------------------- trainer
class GanTrainer:
    """Everything one process of a run holds; :meth:`train` is the loop."""

    def __init__(
        self,
        cfg: TrainGanConfig,
        shapes: list[PreparedShape],
        images: torch.Tensor,
        run: runs.RunDirectory,
        device: torch.device,
        distributed: runs.Distributed,
    ):
        self.cfg, self.shapes, self.images, self.run, self.device, self.dist = (
            cfg,
            shapes,
            images,
            run,
            device,
            distributed,
        )
        self.latest: dict[str, float] = {}  # the last value of every logged scalar, lazy terms included
        levels = shapes[0].num_levels
        gcfg = cfg.generator
        if len(gcfg.synthesis_channels) != levels or len(gcfg.encoder_channels) != levels:
            raise UserError(
                "generator.synthesis_channels and generator.encoder_channels need one entry per level: the shapes "
                f"have {levels} levels"
            )
        runs.seed_everything(cfg.seed)  # identical initial weights on every process
        self.generator = TextureGenerator(gcfg).to(device)
        self.d_field = Discriminator(cfg.resolution, cfg.discriminator).to(device)
        self.d_proxy = Discriminator(cfg.resolution, cfg.discriminator).to(device)
        for module in (self.generator, self.d_field, self.d_proxy):
            distributed.broadcast_module(module)
        self.ema = runs.make_ema(self.generator)
        o = cfg.optim
        groups = self.generator.parameter_groups()
        self.opt_g = torch.optim.Adam(
            [
                {"params": groups["encoder"], "lr": o.lr_encoder},
                {"params": groups["generator"], "lr": o.lr_generator},
                {"params": groups["field"], "lr": o.lr_field},
            ],
            betas=(o.beta1, o.beta2),
            eps=1e-8,
        )
        self.opt_d = torch.optim.Adam(
            list(self.d_field.parameters()) + list(self.d_proxy.parameters()),
            lr=o.lr_discriminator,
            betas=(o.beta1, o.beta2),
            eps=1e-8,
        )
        use_amp = cfg.mixed_precision and device.type == "cuda"
        autocast = (lambda: torch.autocast("cuda", dtype=torch.bfloat16)) if use_amp else contextlib.nullcontext
        try:
            augment = DiffAugment(cfg.augment)
        except ValueError as error:
            raise UserError(f"augment: {error}") from None
        self.loss = GanLoss(cfg.loss, self.generator, self.d_field, self.d_proxy, autocast=autocast, augment=augment)
        self.ada = AdaptiveAugment(augment)
        if cfg.loss.colour_weight > 0:  # the training photos' colour moments (the metric's held-out photos excluded)
            photos = images[: -cfg.metric_photos] if cfg.metric_every else images
            self.loss.set_colour_target(photos[:, :3].float() / 127.5 - 1.0, photos[:, 3:].float() / 255.0)
        self.images_per_step = cfg.batch * cfg.views * distributed.world_size
        self.held_out, self.best = (
            None,
            None,
        )  # the metric's photos; {"iteration", "swd", "diversity"} of RUN/best.safetensors
        if cfg.metric_every:  # run() checks that some photos are left to train on
            self.images, self.held_out = images[: -cfg.metric_photos], images[-cfg.metric_photos :]
        self.iteration = 0
        self.sample_batch = collate_shapes(shapes[: cfg.sample_shapes]).to(device)
        self.sample_z = torch.randn(
            self.sample_batch.num_shapes, gcfg.z_dim, generator=torch.Generator().manual_seed(cfg.seed + 12345)
        ).to(device)
        runs.seed_everything(cfg.seed + 1000003 * distributed.rank)  # each process draws its own data

    # ----------------------------------------------------------------------------- checkpoints
    def modules(self) -> dict:
        return {GENERATOR: self.generator, GENERATOR_EMA: self.ema, D_FIELD: self.d_field, D_PROXY: self.d_proxy}

    def model_meta(self) -> dict:
        """What every checkpoint of the run says of the model: iteration, configs, processes, and the
        hierarchy its shapes were prepared with (a raw mesh is prepared the same way at inference)."""
        return {
            "iteration": self.iteration,
            "config": runs.dumps_config(self.cfg),
            "world_size": self.dist.world_size,
            GENERATOR_CONFIG: runs.dumps_config(self.cfg.generator),
            HIERARCHY: shape_hierarchy(self.shapes),
        }

    def save(self, path: Path) -> None:
        """Collective: every process contributes its RNG state; the main process writes."""
        rng_states = self.dist.gather_objects(runs.rng_to_state())
        if self.dist.is_main:
            meta = {**self.model_meta(), "best": self.best, "latest": self.latest}
            runs.save_training_state(
                path,
                KIND,
                self.modules(),
                {"g": self.opt_g, "d": self.opt_d},
                {GAN_LOSS: {**self.loss.state_dict(), **self.ada.state_dict()}},
                meta,
                rng_states,
            )
        self.dist.barrier()

    def resume(self, path: Path) -> None:
        """Load the training state of ``path``: the run's own checkpoint (continuing it), or another
        run's (this run starts from its networks, optimizers, loss and augmentation state and iteration)."""
        optimizers = {"g": self.opt_g, "d": self.opt_d}
        groups, meta = runs.load_training_state(path, KIND, self.modules(), optimizers, self.device)
        # The run's config.yaml rules, not the checkpoint; annealed as at the checkpoint's last step.
        changed = runs.apply_learning_rates(
            optimizers, self.cfg.optim.learning_rates(max(int(meta["iteration"]) - 1, 0))
        )
        if changed and self.dist.is_main:
            print(
                f"mesh2tex: note: resuming with the learning rates of {self.run.config_path}: {', '.join(changed)}",
                file=sys.stderr,
            )
        if GAN_LOSS not in groups:
            raise UserError(f"{path}: checkpoint has no '{GAN_LOSS}' state")
        self.loss.load_state_dict(groups[GAN_LOSS])
        self.ada.load_state_dict(groups[GAN_LOSS])
        self.iteration = int(meta["iteration"])
        own = path == self.run.checkpoint_path
        self.best = meta.get("best") if own else None  # another run's best is not in this one's folder
        # the lazy terms' last values, logged until they run again: the resumed lines read as the uninterrupted
        self.latest = dict(meta.get("latest", {})) if own else {}
        states = meta["rng"]
        if len(states) == self.dist.world_size:
            runs.rng_from_state(states[self.dist.rank])
        else:  # another number of processes: fresh, distinct streams per process
            print(
                f"mesh2tex: note: the checkpoint was written by {len(states)} process(es), this run has "
                f"{self.dist.world_size}; random streams restart",
                file=sys.stderr,
            )
            runs.seed_everything(self.cfg.seed + 7919 * self.iteration + 1000003 * self.dist.rank)
        if self.dist.is_main and own:
            self.run.metrics.truncate_after("iteration", self.iteration)

    # ---------------------------------------------------------------------------------- steps
    def draw_real(self, n: int) -> torch.Tensor:
        index = torch.randint(len(self.images), (n,))
        background = torch.rand(n, 3) * 2 - 1
        return composite_real(self.images[index], background).to(self.device)

    def draw_scene(self) -> GanScene:
        """This iteration's scene: ``batch`` random shapes, ``views`` jittered cameras each, random
        backgrounds and (with the light prior) lights, rasterized once for every phase."""
        cfg = self.cfg
        n = cfg.batch * cfg.views
        shapes = [self.shapes[i] for i in torch.randint(len(self.shapes), (cfg.batch,)).tolist()]
        batch = collate_shapes(shapes).to(self.device)
        mvp, azimuth = random_cameras(n, cfg.camera, self.device)
        lights = random_lights(azimuth, cfg.lighting).to(self.device) if cfg.lighting.enabled else None
        render = cfg.render_settings  # fakes rasterized at its raster side, box-filtered down to the photos' resolution
        samples = rasterize_batch(batch, mvp, (render.raster_side, render.raster_side))
        background = (torch.rand(n, 3) * 2 - 1).to(self.device)
        return GanScene(shapes, batch, mvp, samples, background, lights, render)

    def step(self) -> dict[str, float]:
        """One iteration of all due phases; returns the logged scalars. Raises NonFiniteLoss before any
        optimizer step of an iteration whose losses are not finite."""
        cfg = self.cfg
        scene = self.draw_scene()
        real = self.draw_real(cfg.batch * cfg.views)
        z_g = torch.randn(cfg.batch, cfg.generator.z_dim, device=self.device)
        z_d = torch.randn(cfg.batch, cfg.generator.z_dim, device=self.device)
        g = self.generator
        if cfg.optim.lr_decay_start:
            runs.apply_learning_rates({"g": self.opt_g, "d": self.opt_d}, cfg.optim.learning_rates(self.iteration))

        logs: dict[str, torch.Tensor] = {}
        phases = self.loss.phases(self.iteration)
        diversity_gain = self.loss.diversity_gain(self.iteration)
        g_params = list(g.parameters())
        d_params = list(self.d_field.parameters()) + list(self.d_proxy.parameters())
        for group, params, opt in (("G", g_params, self.opt_g), ("D", d_params, self.opt_d)):
            opt.zero_grad(set_to_none=True)
            self.generator.requires_grad_(group == "G")
            self.d_field.requires_grad_(group == "D")
            self.d_proxy.requires_grad_(group == "D")
            for phase, gain in phases:
                if phase.startswith(group):
                    logs.update(
                        self.loss.accumulate_gradients(
                            phase, scene, z_g if group == "G" else z_d, real, gain, diversity_gain
                        )
                    )
            bad = None
            try:
                runs.check_finite(logs, self.iteration)
            except runs.NonFiniteLoss as error:
                bad = str(error)
            if self.dist.any(bad is not None, self.device):
                raise runs.NonFiniteLoss(bad or f"a non-finite loss on another process at iteration {self.iteration}")
            self.dist.average_gradients(params)
            for p in params:
                if p.grad is not None:
                    torch.nan_to_num_(p.grad, nan=0.0, posinf=1e5, neginf=-1e5)
            opt.step()
            if group == "G":
                beta = runs.ema_beta(
                    self.iteration * self.images_per_step, self.images_per_step, cfg.ema_halflife_images, cfg.ema_rampup
                )
                runs.ema_update(self.ema, self.generator, beta)
        for module in (self.generator, self.d_field, self.d_proxy):
            module.requires_grad_(True)
        signs = [float(v) for k, v in logs.items() if k.startswith("sign_real_")]
        if self.ada.adaptive and signs:
            self.ada.observe(self.dist.mean(sum(signs) / len(signs), self.device))  # every process keeps the same p
        self.ada.step(self.iteration, self.images_per_step)
        logs["augment_p"] = self.ada.augment.p
        self.iteration += 1
        self.latest.update(
            runs.scalars(logs)
        )  # the lazy terms (path length, R1, mode seeking) keep their last value between runs
        return dict(self.latest)

    def write_snapshot(self) -> Path:
        """RUN/snapshots/iterNNNNNNN.safetensors: the EMA generator now, float16, loadable like a shipped model."""
        path = self.run.root / "snapshots" / f"iter{self.iteration:07d}.safetensors"
        path.parent.mkdir(exist_ok=True)
        meta = self.model_meta()
        save_inference_checkpoint(path, KIND, self.ema.state_dict(), meta)
        if self.cfg.keep_snapshots:
            for old in sorted(path.parent.glob("iter*.safetensors"))[: -self.cfg.keep_snapshots]:
                old.unlink()
        return path

    def keep_checkpoint(self) -> Path:
        """Collective: RUN/checkpoints/iterNNNNNNN.safetensors, the whole training state now (as the run's
        checkpoint), for other runs to start from with ``--resume``."""
        path = self.run.root / "checkpoints" / f"iter{self.iteration:07d}.safetensors"
        if self.dist.is_main:
            path.parent.mkdir(exist_ok=True)
        self.save(path)
        return path

    def turntable(self, k: int) -> tuple[torch.Tensor, torch.Tensor]:
        """k azimuths around each sample shape: (num_shapes * k, 4, 4) cameras on the device and their
        (num_shapes * k,) azimuths in degrees (CPU)."""
        azimuth, elevation = turntable_angles(k)
        n = self.sample_batch.num_shapes
        azimuth, elevation = azimuth.repeat(n), elevation.repeat(n)
        mvp = orbit_camera(azimuth, elevation, distance=self.cfg.camera.distance, fov=self.cfg.camera.fov).mvp.to(
            self.device
        )
        return mvp, azimuth

    @torch.no_grad()
    def measure(self) -> dict[str, float]:
        """The run's own metric, drawing no random numbers of the run: SWD x 1000 (lower is better) between
        the objects of EMA renders (the sample shapes, 4 azimuths, 2 fixed latents, no noise, under fixed
        lights of the run's light prior when it has one) and of
        the held-out photos, and diversity (higher is better), the mean Delta E between the two
        latents' renders of each shape and view."""
        b, k, res = self.sample_batch, 4, self.cfg.resolution
        mvp, azimuth = self.turntable(k)
        z = torch.randn(
            2, b.num_shapes, self.cfg.generator.z_dim, generator=torch.Generator().manual_seed(self.cfg.seed + 54321)
        )
        lights = None
        if self.cfg.lighting.enabled:  # lit like the photos, with lights fixed for the whole run
            lights = random_lights(azimuth, self.cfg.lighting, torch.Generator().manual_seed(self.cfg.seed + 54322)).to(
                self.device
            )
        renders = []
        for latent in z.to(self.device):
            out = render_field_views(
                self.ema,
                b,
                self.ema.mapping(latent),
                mvp,
                (res, res),
                torch.zeros(len(mvp), 3, device=self.device),
                noise_mode="none",
                lights=lights,
            )
            renders.append(((out.images.float() + 1) / 2).clamp(0, 1).cpu())
        mask = out.mask.float().cpu()
        photos = self.held_out.float()
        swd = object_set_swd(
            torch.cat(renders),
            mask.repeat(2, 1, 1, 1),
            photos[:, :3] / 255,
            (photos[:, 3:] > 127).float(),
            seed=self.cfg.seed,
        )
        pairs = []
        for view in range(len(mvp)):
            with contextlib.suppress(ValueError):  # a view without object pixels
                pairs.append(mean_pairwise_delta_e(torch.stack([r[view] for r in renders]), mask[view]))
        return {
            "metric_swd": round(swd, 4),
            "metric_diversity": round(sum(pairs) / len(pairs), 4) if pairs else float("nan"),
        }

    def keep_if_best(self, metric: dict[str, float]) -> bool:
        """RUN/best.safetensors: the EMA generator (float16, like a snapshot) at the lowest SWD so far."""
        swd = metric["metric_swd"]
        if not np.isfinite(swd) or (self.best is not None and swd >= self.best["swd"]):
            return False
        self.best = {"iteration": self.iteration, "swd": swd, "diversity": metric["metric_diversity"]}
        meta = {**self.model_meta(), "metric": self.best}
        save_inference_checkpoint(self.run.root / "best.safetensors", KIND, self.ema.state_dict(), meta)
        return True

    @torch.no_grad()
    def write_samples(self) -> Path:
        """Grid of EMA renders: one row per sample shape, one column per view (white background)."""
        k = 4
        b = self.sample_batch
        mvp, _ = self.turntable(k)
        ws = self.ema.mapping(self.sample_z)
        res = self.cfg.resolution
        out = render_field_views(
            self.ema, b, ws, mvp, (res, res), torch.ones(b.num_shapes * k, 3, device=self.device), noise_mode="none"
        )
        tiles = images_to_uint8(out.images).reshape(b.num_shapes, k, res, res, 3)
        grid = tiles.transpose(0, 2, 1, 3, 4).reshape(b.num_shapes * res, k * res, 3)
        path = self.run.samples_dir / f"iter{self.iteration:07d}.png"
        save_png(path, grid)
        return path

    def train(self) -> None:
        cfg, main = self.cfg, self.dist.is_main
        advice = (
            f"Lower the optim.lr_* learning rates (or raise loss.r1_gamma) in {self.run.config_path} and re-run "
            "with --resume"
        )
        runs.training_loop(
            self,
            self.run,
            iters=cfg.iters,
            desc="train gan",
            device=self.device,
            log_every=cfg.log_every,
            checkpoint_every=cfg.checkpoint_every,
            advice=advice,
            main=main,
            postfix=lambda logs: {
                k: f"{v:.3f}" for k, v in logs.items() if k.startswith(("loss_g_field", "loss_d_field"))
            },
            measure=runs.Every(cfg.metric_every, self.measure_and_keep, final="always"),
            periodic=[
                runs.Every(cfg.snapshot_every, self.write_snapshot),
                runs.At(cfg.keep_checkpoints, self.keep_checkpoint, main_only=False),
                runs.Every(cfg.sample_every, self.write_samples, final="never"),
            ],
            extra={"world_size": self.dist.world_size},
            stop_together=lambda requested: self.dist.any(requested, self.device),
        )
        if main:
            self.write_samples()

    def measure_and_keep(self) -> dict:
        """The run's metric (:meth:`measure`) and whether it is the best so far (``best``; best.safetensors kept)."""
        metric = self.measure()
        return {**metric, "best": self.keep_if_best(metric)}


def build_config(args) -> TrainGanConfig:
    overrides = config_overrides(args)
    run_config = Path(args.out) / "config.yaml"
    if args.resume and not getattr(args, "overwrite", False) and run_config.is_file():
        if args.config:
            print(f"mesh2tex: note: resuming uses {run_config}; --config {args.config} is ignored", file=sys.stderr)
        cfg = load_config(TrainGanConfig, run_config, overrides)
    else:
        cfg = load_config(TrainGanConfig, args.config, overrides)
    return cfg


def run(args) -> int:
    cfg = build_config(args)
    distributed = runs.Distributed(cfg.device)
    try:
        device = runs.select_device(cfg.device)
        run_dir = runs.RunDirectory(args.out)
        source = runs.start_from(
            args.resume, run_dir, KIND, note=distributed.is_main, overwrite=args.overwrite
        )  # checked before the data is read
        shapes, _ = load_shapes(args.shapes)
        images = load_photo_collection(args.images, cfg.resolution)
        if cfg.metric_every and len(images) <= cfg.metric_photos:
            raise UserError(
                f"metric_photos {cfg.metric_photos}: the photo collection has {len(images)} photos, the metric holds "
                f"out fewer than that (or set metric_every: 0)"
            )
        features = shapes[0].face_features.shape[1]
        if cfg.generator.input_features not in (0, features):
            raise UserError(
                f"generator.input_features is {cfg.generator.input_features} but the shapes in {args.shapes} have "
                f"{features} face features"
            )
        cfg.generator.input_features = features
        if distributed.is_main and source is None:
            run_dir.start(cfg, resume=False, overwrite=args.overwrite)
        distributed.barrier()
        trainer = GanTrainer(cfg, shapes, images, run_dir, device, distributed)
        if source is not None:
            trainer.resume(
                source
            )  # before config.yaml is written: a checkpoint that cannot be loaded leaves --out as it was
            if distributed.is_main:
                run_dir.start(cfg, resume=source == run_dir.checkpoint_path, overwrite=args.overwrite)
            distributed.barrier()
        trainer.train()
        if distributed.is_main:
            print(f"trained {trainer.iteration} iterations; checkpoint {run_dir.checkpoint_path}")
    finally:
        distributed.close()
    return 0
