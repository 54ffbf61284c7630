"""Training of the three image networks of texture transfer: the pose classifier, the NOC U-Net and
the mask U-Net.

``mesh2tex train pose``, ``train noc`` and ``train mask`` share everything but the network and its
loss (the mask network sees each view shrunk and placed over a fresh backdrop,
:func:`mesh2tex.synthetic.backdrops.place_over_backdrops`, drawn anew at every step):

1. **Data**: views of the prepared shapes, rendered once and cached in ``RUN/views.npz``. Each group
   of views (one shape, one texture) is textured either by a random material of the category's
   procedural library (:mod:`mesh2tex.synthetic.materials`) or, with ``--checkpoint NAME|PATH``
   (``data.gan_checkpoint``), for a ``data.gan_share`` of the groups, by the trained GAN from a
   random latent (its per-vertex colours of the finest level). Cameras, lights and backgrounds are
   drawn exactly as the synthetic photos are (:func:`mesh2tex.synthetic.world.sample_views`), and
   the ground truth (azimuth, elevation, NOC map, mask) comes from the rasterizer. Each view is
   cropped to the square around its object (``data.frame_margin``), exactly as ``infer transfer``
   crops a query photo, so the networks see the same framing in training and at query time. The last
   ``holdout`` share of the groups is never trained on and gives the validation figures in
   ``metrics.jsonl``. The cache is reused only when the data settings, seed and GAN checkpoint
   are those it was rendered with.
2. **Loop**: Adam, mini-batches drawn with the run's seed, checkpoints, resume, NaN guard and
   metrics with the conventions of :mod:`train.runs` (the same as ``train gan``).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import torch
from mesh2tex.train import runs

from mesh2tex.config import load_config
from mesh2tex.errors import UserError
from mesh2tex.geometry.prepared import PreparedShape, load_shapes
from mesh2tex.io.atomic import atomic_path
from mesh2tex.io.checkpoint import checkpoint_digest, read_checkpoint_meta
from mesh2tex.models import load_generator, resolve_checkpoint
from mesh2tex.models.store import VIEW_NET
from mesh2tex.nn.batch import collate_shapes
from mesh2tex.nn.mask import mask_iou, mask_loss
from mesh2tex.nn.noc import noc_error, noc_loss
from mesh2tex.nn.pose import pose_accuracy, pose_loss
from mesh2tex.nn.schedule import cosine_rate
from mesh2tex.nn.view_nets import VIEWS_NAME, ViewDataConfig, ViewTrainConfig, build_network
from mesh2tex.options import config_overrides
from mesh2tex.progress import progress_bar
from mesh2tex.render import crop_square, object_box
from mesh2tex.synthetic.backdrops import place_over_backdrops
from mesh2tex.synthetic.shapes import SyntheticShape
from mesh2tex.synthetic.world import WorldSpec, render_views, sample_material, sample_views, unit_to_uint8

# _GanTextures.vertex_colours shadows the name
from mesh2tex.texturing import (
    latent,
    shape_mismatch,
)
from mesh2tex.texturing import (
    vertex_colours as field_vertex_colours,
)

# --------------------------------------------------------------------------------------- data
_GAN_STREAM = 4  # random stream of a group (WorldSpec.rng) that picks GAN or material, and the latent seed


def render_view_dataset(shapes: list[PreparedShape], cfg: ViewDataConfig, seed: int) -> dict[str, np.ndarray]:
    """Render ``cfg.samples`` random views of ``shapes``, each group of ``cfg.views_per_material``
    textured by a random procedural material or (a ``cfg.gan_share`` of the groups, with a
    ``cfg.gan_checkpoint``) by the GAN from a random latent.

    Returns uint8 ``rgb`` (N, R, R, 3), ``mask`` (N, R, R) 0/255, ``noc`` (N, R, R, 3),
    ``gan_textured`` (N,) 0/1 and float32 ``azimuth``, ``elevation`` (N,) in degrees. Deterministic
    for ``seed``.
    """
    spec = WorldSpec(
        category=cfg.category,
        seed=seed,
        resolution=cfg.resolution,
        elevation_min=cfg.elevation_min,
        elevation_max=cfg.elevation_max,
        distance_min=cfg.distance_min,
        distance_max=cfg.distance_max,
        fov=cfg.fov,
        supersample=cfg.supersample,
        variety=cfg.variety,
    )
    meshes = [
        SyntheticShape(
            cfg.category,
            s.vertices[0].astype(np.float64),
            s.triangles(0),
            np.zeros(2 * s.face_counts[0], dtype=np.int64),
        )
        for s in shapes
    ]
    gan = _GanTextures(cfg.gan_checkpoint, shapes) if cfg.gan_checkpoint else None
    framed = cfg.frame_margin >= 0
    render = cfg.render_settings  # before framing
    groups = -(-cfg.samples // cfg.views_per_material)
    parts: dict[str, list[np.ndarray]] = {k: [] for k in ("rgb", "mask", "noc", "gan_textured", "azimuth", "elevation")}
    for group in progress_bar(range(groups), desc="render views"):
        views = sample_views(spec, group, cfg.views_per_material)
        index = group % len(meshes)
        choice = spec.rng(group, _GAN_STREAM)  # its own stream: the procedural groups do not depend on the GAN
        use_gan = gan is not None and choice.random() < cfg.gan_share
        if use_gan:
            colours = gan.vertex_colours(index, int(choice.integers(1 << 31)))
            rendered = render_views(meshes[index], None, views, render, vertex_colours=colours)
        else:
            material = sample_material(spec, spec.rng(group, 1))
            rendered = render_views(meshes[index], material, views, render)
        if framed:
            rendered = frame_views(rendered, cfg.frame_margin, cfg.resolution)
        for key in ("rgb", "mask", "noc"):
            parts[key].append(rendered[key])
        parts["gan_textured"].append(np.full(len(views), use_gan, dtype=np.uint8))
        parts["azimuth"].append(np.array([v.azimuth for v in views], dtype=np.float32))
        parts["elevation"].append(np.array([v.elevation for v in views], dtype=np.float32))
    return {k: np.concatenate(v)[: cfg.samples] for k, v in parts.items()}


def frame_views(rendered: dict[str, np.ndarray], margin: float, size: int) -> dict[str, np.ndarray]:
    """Crop rendered views to the square around each object, as a query photo is cropped.

    ``rendered``: uint8 ``rgb`` (B, S, S, 3), ``mask`` (B, S, S) 0/255, ``noc`` (B, S, S, 3) from
    :func:`mesh2tex.synthetic.world.render_views`. Returns the same keys at side ``size``. The square
    is :func:`mesh2tex.render.object_box` with ``margin``; outside the image it is white, like the
    photo crop of ``infer transfer``. NOC is averaged over object pixels only, so the background
    does not darken it at the silhouette.
    """
    out: dict[str, list[np.ndarray]] = {"rgb": [], "mask": [], "noc": []}
    for rgb, mask, noc in zip(rendered["rgb"], rendered["mask"], rendered["noc"]):
        covered = mask > 127
        box = object_box(covered, margin) if covered.any() else (0, 0, mask.shape[0])
        m = torch.from_numpy(covered)[None, None].float()
        image = crop_square(torch.from_numpy(rgb).permute(2, 0, 1)[None].float() / 255.0, box, size, fill=1.0)
        coverage = crop_square(m, box, size)
        noc_sum = crop_square(torch.from_numpy(noc).permute(2, 0, 1)[None].float() / 255.0 * m, box, size)
        keep = coverage >= 0.5
        noc_mean = noc_sum / coverage.clamp_min(1e-6) * keep
        out["rgb"].append(unit_to_uint8(image[0].permute(1, 2, 0)))
        out["mask"].append(keep[0, 0].numpy().astype(np.uint8) * 255)
        out["noc"].append(unit_to_uint8(noc_mean[0].permute(1, 2, 0)))
    return {k: np.stack(v) for k, v in out.items()}


class _GanTextures:
    """Per-vertex colours of prepared shapes textured by a trained GAN (CPU, EMA generator, no noise)."""

    def __init__(self, checkpoint: str, shapes: list[PreparedShape]):
        self.device = torch.device("cpu")
        self.generator = load_generator(checkpoint, self.device).network
        problem = shape_mismatch(shapes[0], self.generator)  # all shapes share levels and features (load_shapes)
        if problem:
            raise UserError(f"{checkpoint}: the prepared shapes have {problem}; prepare them with the GAN's settings")
        self.batches = [collate_shapes([s]) for s in shapes]
        for shape, batch in zip(shapes, self.batches):  # the colours index the rendered mesh's vertices
            if not torch.equal(batch.shape_triangles(0), torch.as_tensor(shape.triangles(0), dtype=torch.int64)):
                raise RuntimeError("the GAN's batch and the rendered mesh disagree on the finest triangles")
        self.encoded: dict[int, list[torch.Tensor]] = {}

    @torch.no_grad()
    def vertex_colours(self, index: int, latent_seed: int) -> np.ndarray:
        """(V, 3) float32 in [0, 1]: the texture of latent ``latent_seed`` at the finest vertices of shape
        ``index``, in the order of ``shapes[index].vertices[0]`` (= ``batch.shape_vertices(0)``)."""
        batch = self.batches[index]
        if index not in self.encoded:
            self.encoded[index] = self.generator.encoder(batch)
        ws = latent(self.generator, latent_seed, self.device)
        texture = self.generator.synthesize(batch, ws, encoded=self.encoded[index], noise_mode="none")
        return field_vertex_colours(self.generator, texture, batch).astype(np.float32) / 255.0


def data_fingerprint(cfg: ViewTrainConfig) -> str:
    """JSON of everything the rendered views depend on: the data config and the seed, with the GAN
    checkpoint's path replaced by a digest of its bytes (a moved checkpoint keeps the cache, a retrained one does
    not)."""
    data = dataclasses.asdict(cfg.data)
    if cfg.data.gan_checkpoint:
        data["gan_checkpoint"] = "sha256:" + checkpoint_digest(cfg.data.gan_checkpoint, "GAN checkpoint")
    return json.dumps({"data": data, "seed": cfg.seed}, sort_keys=True)


def load_or_render_views(
    run: runs.RunDirectory, shapes: list[PreparedShape], cfg: ViewTrainConfig
) -> dict[str, np.ndarray]:
    """The run's cached views if they were rendered with the same data settings (:func:`data_fingerprint`),
    or render them and cache them atomically."""
    path = run.root / VIEWS_NAME
    fingerprint = data_fingerprint(cfg)
    if path.is_file():
        with np.load(path, allow_pickle=False) as data:
            views = {k: data[k] for k in data.files}
        if "fingerprint" in views and str(views.pop("fingerprint")) == fingerprint:
            return views
    views = render_view_dataset(shapes, cfg.data, cfg.seed)
    with atomic_path(path, suffix=".npz") as tmp:
        np.savez(tmp, fingerprint=np.array(fingerprint), **views)
    return views


def views_to_tensors(views: dict[str, np.ndarray], index: np.ndarray, device: torch.device) -> dict[str, torch.Tensor]:
    """A mini-batch: ``image`` (B,3,R,R) in [-1,1], ``mask`` (B,1,R,R) {0,1}, ``noc`` (B,3,R,R) in [0,1], angles
    (B,)."""
    # contiguous(): a channels-last input trips a heap corruption in the CPU conv backward of small nets.
    rgb = torch.from_numpy(views["rgb"][index]).to(device).permute(0, 3, 1, 2).contiguous().float() / 127.5 - 1.0
    mask = (torch.from_numpy(views["mask"][index]).to(device) > 127).float()[:, None]
    noc = torch.from_numpy(views["noc"][index]).to(device).permute(0, 3, 1, 2).contiguous().float() / 255.0
    return {
        "image": rgb,
        "mask": mask,
        "noc": noc,
        "azimuth": torch.from_numpy(views["azimuth"][index]).to(device),
        "elevation": torch.from_numpy(views["elevation"][index]).to(device),
    }


# ------------------------------------------------------------------------------------ networks
def network_loss(kind: str, net: torch.nn.Module, batch: dict[str, torch.Tensor], cfg: ViewTrainConfig) -> torch.Tensor:
    if kind == "pose":
        azimuth_logits, elevation_logits = net(batch["image"])
        return pose_loss(azimuth_logits, elevation_logits, batch["azimuth"], batch["elevation"], cfg.bins)
    if kind == "mask":  # the backdrops come from torch's generator: a resumed run draws what it would have
        images, masks = place_over_backdrops(
            batch["image"],
            batch["mask"],
            np.random.default_rng(int(torch.randint(1 << 62, (1,)))),
            cfg.room_share,
            cfg.camouflage_share,
            cfg.distractor_share,
        )
        return mask_loss(net(images), masks)
    predicted = net(batch["image"], batch["mask"])
    return noc_loss(predicted, batch["noc"], batch["mask"])


@torch.no_grad()
def validate(
    kind: str,
    net: torch.nn.Module,
    views: dict[str, np.ndarray],
    index: np.ndarray,
    cfg: ViewTrainConfig,
    device: torch.device,
) -> dict[str, float]:
    """Validation figures on the held-out views: bin accuracies and azimuth error, NOC error, or mask IoU
    (the held-out views over the same backdrops at every validation)."""
    net.eval()
    out: dict[str, float] = {}
    chunks = [index[i : i + 64] for i in range(0, len(index), 64)]
    totals: dict[str, float] = {}
    backdrops = np.random.default_rng(20240)
    for chunk in chunks:
        batch = views_to_tensors(views, chunk, device)
        if kind == "pose":
            az, el = net(batch["image"])
            figures = pose_accuracy(az, el, batch["azimuth"], batch["elevation"], cfg.bins)
        elif kind == "mask":
            images, masks = place_over_backdrops(batch["image"], batch["mask"], backdrops, cfg.room_share)
            figures = {"mask_iou": mask_iou(net(images), masks)}
        else:
            figures = {"noc_error": noc_error(net(batch["image"], batch["mask"]), batch["noc"], batch["mask"])}
        for k, v in figures.items():
            totals[k] = totals.get(k, 0.0) + float(v) * len(chunk)
    for k, v in totals.items():
        out[f"val_{k}"] = round(v / max(len(index), 1), 5)
    net.train()
    return out


# ---------------------------------------------------------------------------------------- stage
def build_view_config(args) -> ViewTrainConfig:
    overrides = config_overrides(args)
    run_config = Path(args.out) / "config.yaml"
    source = (
        run_config if args.resume and not getattr(args, "overwrite", False) and run_config.is_file() else args.config
    )
    cfg = load_config(ViewTrainConfig, source, overrides)
    if cfg.iters < 1 or cfg.batch < 1 or cfg.data.samples < 2:
        raise UserError("--iters and --batch must be at least 1 and --samples at least 2")
    if cfg.data.resolution < 16:
        raise UserError(f"--resolution {cfg.data.resolution}: must be at least 16")
    if not 0.0 <= cfg.data.gan_share <= 1.0:
        raise UserError(f"data.gan_share {cfg.data.gan_share}: must be between 0 and 1")
    if cfg.data.gan_checkpoint:  # checked before the run directory is written
        # a shipped model's name, or a path
        cfg.data.gan_checkpoint = str(resolve_checkpoint(cfg.data.gan_checkpoint, "gan"))
        kind = read_checkpoint_meta(cfg.data.gan_checkpoint).get("kind")
        if kind != "gan":
            raise UserError(
                f"{cfg.data.gan_checkpoint}: this is a '{kind}' checkpoint, --checkpoint needs a 'gan' checkpoint"
            )
    return cfg


class ViewTrainer:
    """One pose, NOC or mask network trained on the rendered views (:func:`mesh2tex.train.runs.training_loop` drives
    it)."""

    def __init__(self, kind: str, cfg, views: dict, train_index: np.ndarray, device: torch.device):
        self.kind, self.cfg, self.views, self.train_index, self.device = kind, cfg, views, train_index, device
        self.net = build_network(kind, cfg).to(device)
        self.opt = torch.optim.Adam(self.net.parameters(), lr=cfg.lr)
        self.iteration = 0

    def resume(self, path: Path) -> None:
        _, meta = runs.load_training_state(path, self.kind, {VIEW_NET: self.net}, {"opt": self.opt}, self.device)
        self.iteration = int(meta["iteration"])
        runs.rng_from_state(meta["rng"][0])

    def step(self) -> dict[str, float]:
        cfg, index = self.cfg, self.train_index
        pick = index[torch.randint(len(index), (min(cfg.batch, len(index)),)).numpy()]
        loss = network_loss(self.kind, self.net, views_to_tensors(self.views, pick, self.device), cfg)
        runs.check_finite({"loss": loss}, self.iteration)
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        for group in self.opt.param_groups:
            group["lr"] = cosine_rate(cfg.lr, cfg.lr_end, self.iteration, cfg.iters)
        self.opt.step()
        self.iteration += 1
        return {"loss": round(float(loss.detach()), 6)}

    def save(self, path: Path) -> None:
        runs.save_training_state(
            path,
            self.kind,
            {VIEW_NET: self.net},
            {"opt": self.opt},
            {},
            {"iteration": self.iteration, "config": runs.dumps_config(self.cfg)},
            [runs.rng_to_state()],
        )


def run_view_training(args, kind: str) -> int:
    cfg = build_view_config(args)
    device = runs.select_device(cfg.device)
    run = runs.RunDirectory(args.out)
    source = runs.start_from(args.resume, run, kind, overwrite=args.overwrite)  # checked before anything is written
    shapes, _ = load_shapes(args.shapes)
    # another run's: loaded once before --out is written, so a misfit leaves it as it was
    if source is not None and source != run.checkpoint_path:
        probe = build_network(kind, cfg)
        runs.load_training_state(
            source,
            kind,
            {VIEW_NET: probe},
            {"opt": torch.optim.Adam(probe.parameters(), lr=cfg.lr)},
            torch.device("cpu"),
        )
    run.start(cfg, resume=source == run.checkpoint_path, overwrite=args.overwrite)
    runs.seed_everything(cfg.seed)
    views = load_or_render_views(run, shapes, cfg)

    count = len(views["rgb"])
    held = max(1, int(round(count * cfg.data.holdout)))
    train_index, val_index = np.arange(count - held), np.arange(count - held, count)
    trainer = ViewTrainer(kind, cfg, views, train_index, device)
    if source is not None:
        trainer.resume(source)
        run.metrics.truncate_after("iteration", trainer.iteration)
    net = trainer.net
    runs.training_loop(
        trainer,
        run,
        iters=cfg.iters,
        desc=f"train {kind}",
        device=device,
        log_every=cfg.log_every,
        checkpoint_every=cfg.checkpoint_every,
        advice="Lower --config lr and --resume",
        postfix=lambda logs: {"loss": f"{logs['loss']:.4f}"},
        measure=runs.Every(cfg.log_every, lambda: validate(kind, net, views, val_index, cfg, device), final="always"),
    )
    iteration = trainer.iteration
    final = validate(kind, net, views, val_index, cfg, device)
    print(
        f"trained {kind} network for {iteration} steps; held-out "
        + ", ".join(f"{k}={v}" for k, v in final.items())
        + f"; checkpoint {run.checkpoint_path}"
    )
    return 0
