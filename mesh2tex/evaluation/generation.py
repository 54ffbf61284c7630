"""The generation protocol: a texture GAN measured against the synthetic world's ground truth.

    mesh2tex evaluate --generation --world WORLD --shapes SHAPES --checkpoint NAME|PATH --out DIR

On the world's held-out shapes (those of its queries, never seen in training), with the same
cameras, the same white background and the same image pipeline for every row (rendered as the
world renders its photos, at its resolution, supersampled, and read as the photo set is read;
``generator_render: direct`` renders the generator rows by the GAN's own renderer straight at the
metric's resolution instead, as the figures before were):

    trained       the checkpoint's EMA generator, one random latent per view
    untrained     a freshly initialised generator of the same configuration (the floor)
    oracle        for every view a fresh draw of the world's own material sampler on the held-out
                  shape, rendered as the world renders its photos (at the world's resolution, their
                  lighting, resized as the photo set is read): what a perfect generator produces
                  (one texture draw per view, like the generator's latents)
    oracle, unlit the same draws without lighting (what an albedo-only generator could reach)
    ground truth  each held-out shape's own material, lit: one texture per shape. With few held-out
                  shapes its colours cover the distribution less well than a draw per view: it is
                  shown, the gap is measured to the oracle
    training materials  the training shapes' own materials, one per view in turn, on the held-out
                  shapes: what a generator that reproduced its training textures exactly would paint
    flat colour   a simple baseline: the photo set's mean object colour on every pixel of the
                  generator's silhouettes (what a model that learnt one average colour would score)
    mean texture  the trained generator's mean texture (``w_avg`` in every style input, lit as the
                  trained row): what the GAN paints without a latent; a trained row no better than
                  it has not learnt to use its latent

each against a **fresh photo set** (:func:`fresh_photo_set`: the training shapes at their photos'
cameras and lights, a new material of the world's sampler on every photo): the **object SWD**
(x1000: patches of object pixels only, pooled per set, :func:`mesh2tex.metrics.generation.object_set_swd`),
the whole-image SWD, KID and FID on named features, the pooled colour-histogram distance; and the
**gap closed**: the share of the untrained-to-oracle gap in log object SWD that the trained
generator closes (also reported on the colour histogram, and for the training-materials row). Not
the training photos themselves: they show only as many materials as training shapes (24 on the
chair and car worlds), and a generator that copies those beat the oracle's fresh draws there (a
trained car GAN did, 81.5 against 144.2), so the figure measured copying, not closeness to the
world's textures; the object SWD to the training photos stays as a last column
(``object_swd_vs_photos``, ``gap_closed_vs_photos``) to read earlier figures. ``oracle_loses`` lists
the columns some row beats the oracle on: those do not rank textures. The whole-image SWD is
usually one: it is dominated by the white background and the silhouettes, in which the held-out
shapes differ from the reference's training shapes.

**Diversity**: per held-out shape, ``latents`` latents at one pose: the spread of their mean object
colours (Lab) and their mean pairwise per-pixel Delta E (:mod:`mesh2tex.metrics.generation`); the
references are the spread of the mean object colours of the photo set's shapes (each shape's photos
averaged), and, on the same held-out shape and pose, ``latents`` draws of the world's own material
sampler. A generator that ignores its latent scores 0.

**Lighting.** A generator trained with ``lighting.enabled`` (the default since the light prior was
added) learnt albedo under random lights: its rows (trained, untrained, diversity) are rendered
under each view's own light, as the oracle and the photos are, and its diversity reference (the
material sampler) is lit too. A generator trained unlit (older runs, ``lighting.enabled: false``)
baked its own shading into its colours: its rows are rendered unlit, as it was trained, against the
lit oracle. ``lighting`` lit/unlit forces one way (to compare models trained either way on one
footing); ``generator_lit`` in the result says which was used. The diversity pose keeps a
photo-like light: the first view's light turned with the camera to the pose's azimuth.

**Training shapes.** ``split: train`` (``--split train``, with --shapes the prepared training
shapes) measures the same rows on the shapes the GAN trained on, at their own photos' cameras.
Beside the held-out figures it shows how much of what the generator learnt is tied to the shapes
it saw: the generalisation gap.

**Truncation.** ``truncation`` (``--truncation``) maps the trained row's latents with that psi, as
``infer generate --truncation`` does (every latent pulled towards ``w_avg``; 0 paints the mean
texture): it measures the trade between distance and diversity a user can choose. The untrained row
keeps psi 1.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from mesh2tex.config import check_fields
from mesh2tex.errors import InputError
from mesh2tex.evaluation.generation_renders import (
    DIVERSITY_STREAM,
    LATENT_STREAM,
    ORACLE_STREAM,
    draw_key,
    fresh_photo_set,
    generator_renders,
    ground_truth_renders,
    material_draws,
    photo_set_spread,
    pose_view,
    seeded_generator,
    training_material_renders,
)
from mesh2tex.evaluation.report import GENERATION_ROWS, SPLITS
from mesh2tex.evaluation.summary import generation_summary
from mesh2tex.evaluation.world import WorldData, read_world
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.io.images import colours_to_uint8, save_png
from mesh2tex.metrics import get_feature_extractor
from mesh2tex.metrics.evaluate import EvaluateConfig, evaluate_sets
from mesh2tex.metrics.generation import colour_spread, mean_object_lab, mean_pairwise_delta_e, object_set_swd
from mesh2tex.models import load_generator
from mesh2tex.nn.generator import TextureGenerator
from mesh2tex.photos import list_images, load_set
from mesh2tex.progress import progress_bar
from mesh2tex.render import RenderSettings, composite_images
from mesh2tex.synthetic.world import sample_views
from mesh2tex.texturing import mean_latent, shape_mismatch

LIGHTING_MODES = ("auto", "lit", "unlit")
GENERATOR_RENDERS = ("photo", "direct")
DRAWN_ROWS = ("trained", "untrained", "oracle", "oracle_unlit")  # the rows drawn anew in every repeat


@dataclass
class GenerationConfig:
    views: int = 8  # photo-like views of each shape for the set metrics (one latent each)
    latents: int = 16  # latents per shape for the diversity measures
    resolution: int = 0  # render and photo side (0: the GAN's training resolution)
    azimuth: float = 35.0  # the one pose of the diversity renders, degrees
    elevation: float = 20.0
    features: str = "auto"  # KID/FID features (see mesh2tex.metrics.features)
    kid_fid: bool = True  # compute KID and FID (the feature network is most of the cost)
    max_shapes: int = 0  # shapes of the split used, the first K (0: all)
    seed: int = 0  # latents, untrained weights, material draws, SWD sampling
    repeats: int = 4  # draws of the set rows' latents, oracle materials and fresh photo set; their distances averaged
    lighting: str = "auto"  # the generator's rows: auto (lit when it was trained under the light prior), lit or unlit
    # the shapes measured: held_out (never trained on) or train (beside held_out: the generalisation gap)
    split: str = "held_out"
    # truncation psi of the trained generator's latents, as 'infer generate --truncation' (1: none)
    truncation: float = 1.0
    # The generator rows' renders: "photo" as the world renders its photos and the oracle (supersampled at the world's
    # resolution, read as the photo set is), or "direct", the GAN's own renderer at the metric's resolution (the
    # figures before)
    generator_render: str = "photo"

    def __post_init__(self):
        if self.repeats < 1:
            raise ValueError(f"repeats must be at least 1, got {self.repeats}")
        check_fields(self, between={"truncation": (0.0, 1.0)})
        if self.lighting not in LIGHTING_MODES:
            raise ValueError(f"lighting must be one of {', '.join(LIGHTING_MODES)}, got {self.lighting!r}")
        if self.generator_render not in GENERATOR_RENDERS:
            raise ValueError(
                f"generator_render must be one of {', '.join(GENERATOR_RENDERS)}, got {self.generator_render!r}"
            )
        if self.split not in SPLITS:
            raise ValueError(f"split must be one of {', '.join(SPLITS)}, got {self.split!r}")

    def photo_render(self, world: WorldData) -> RenderSettings | None:
        """:func:`generator_renders`' ``photo_render`` for the generator rows: the world's photos' render
        settings, or None with ``generator_render: direct``."""
        return world.spec.photo_render if self.generator_render == "photo" else None


def run_generation_protocol(
    world_dir: str | Path,
    shapes_dir: str | Path,
    checkpoint: str | Path,
    cfg: GenerationConfig,
    device: torch.device | None = None,
    extractor=None,
    samples_path: Path | None = None,
    log=print,
) -> dict:
    """Every row of the module docstring and the diversity measures; returns a JSON-ready dict.

    ``samples_path``: also write a samples grid there (rows latents, columns views; the first held-out
    shape, trained generator, with the oracle's views as the last row).
    """
    start = time.perf_counter()
    device = device or torch.device("cpu")
    world = read_world(world_dir)
    model = load_generator(checkpoint, device)
    trained = model.network
    if not cfg.resolution and model.resolution is None:
        raise InputError(
            f"{checkpoint}: the checkpoint does not say the resolution it was trained at; give --resolution"
        )
    torch.manual_seed(cfg.seed)
    untrained = TextureGenerator(trained.cfg).to(device).eval().requires_grad_(False)
    names = world.held_out if cfg.split == "held_out" else world.train
    names = names[: cfg.max_shapes] if cfg.max_shapes > 0 else names
    run = _ProtocolRun(
        world,
        cfg,
        device,
        trained,
        untrained,
        _prepared_shapes(world, names, shapes_dir, cfg, trained),
        resolution=cfg.resolution or model.resolution,
        lit=model.lit if cfg.lighting == "auto" else cfg.lighting == "lit",
    )
    bar = progress_bar(total=len(names) + cfg.repeats, desc="generation protocol", unit="step")
    fixed, diversity = run.fixed_rows_and_diversity(
        lambda name: (log(f"generation protocol: {name} done ({time.perf_counter() - start:.0f} s)"), bar.update(1))
    )
    if cfg.kid_fid:
        extractor = extractor or get_feature_extractor(cfg.features, device=device)
    per_repeat = []  # {row: metrics} of every repeat
    for repeat in range(cfg.repeats):
        per_repeat.append(run.measure_draw(repeat, fixed, extractor))
        log(f"generation protocol: draw {repeat + 1} of {cfg.repeats} measured ({time.perf_counter() - start:.0f} s)")
        bar.update(1)
    bar.close()
    result = {
        "world": str(world.root),
        "checkpoint": str(checkpoint),
        "split": cfg.split,
        "shapes": names,
        "resolution": run.resolution,
        "iteration": model.iteration or 0,
        **generation_summary(per_repeat, diversity, photo_set_spread(world, *run.photos, run.photo_names)),
        "generator_lit": run.lit,
        "settings": dataclasses.asdict(cfg),
        "seconds": round(time.perf_counter() - start, 1),
    }
    if samples_path is not None:
        write_samples_grid(
            samples_path, trained, run.shapes[names[0]], world, names[0], run.resolution, cfg, device, lit=run.lit
        )
    return result


def _prepared_shapes(
    world: WorldData, names: list[str], shapes_dir: str | Path, cfg: GenerationConfig, generator
) -> dict:
    """{name: PreparedShape} of the measured shapes, each checked against the generator (InputError naming the file)."""
    shapes = {}
    for name in names:
        path = Path(shapes_dir) / f"{name}.npz"
        if not path.is_file():
            raise InputError(
                f"{path}: the {SPLITS[cfg.split]} shape {name} is not prepared; run 'mesh2tex prepare shapes' on "
                f"{world.root / 'meshes' / (name + '.obj')}"
            )
        shape = PreparedShape.load(path)
        problem = shape_mismatch(shape, generator)
        if problem:
            raise InputError(f"{path}: {problem}")
        shapes[name] = shape
    return shapes


class _ProtocolRun:
    """One run of the protocol: the world, the generators, the shapes and their views, and the photo set.
    Its steps draw random numbers in the order the protocol has always drawn them (figures stay reproducible)."""

    def __init__(
        self,
        world: WorldData,
        cfg: GenerationConfig,
        device,
        trained,
        untrained,
        shapes: dict,
        resolution: int,
        lit: bool,
    ):
        self.world, self.cfg, self.device, self.trained, self.shapes = world, cfg, device, trained, shapes
        self.resolution, self.lit, self.photo_render = resolution, lit, cfg.photo_render(world)
        self.photos = load_set(
            world.root / "images", "image", resolution, 1.0, masks=list_images(world.root / "masks", "mask")
        )
        self.photo_names = list(list_images(world.root / "images", "image"))
        photos, photo_masks = self.photos
        self.photo_mean = (photos * photo_masks).sum(dim=(0, 2, 3)) / (photo_masks.sum() * 1.0).clamp_min(
            1.0
        )  # (3,) mean object colour
        self.views_of = {
            name: sample_views(world.spec, world.indices[name], cfg.views) for name in shapes
        }  # fresh for held-out shapes
        self.generator_rows = (
            ("trained", trained, cfg.truncation),
            ("untrained", untrained, 1.0),
        )  # (row, generator, truncation psi)

    def renders(self, generator, name: str, views, z, psi: float = 1.0, ws=None):
        return generator_renders(
            generator,
            self.shapes[name],
            views,
            self.resolution,
            z,
            self.device,
            self.lit,
            truncation=psi,
            photo_render=self.photo_render,
            **({} if ws is None else {"ws": ws}),
        )

    def fixed_rows_and_diversity(self, done) -> tuple[dict, dict]:
        """The rows that draw nothing (rendered once) and the diversity measures, shape by shape (``done(name)`` after
        each)."""
        cfg, world, trained = self.cfg, self.world, self.trained
        fixed = {row: ([], []) for row in GENERATION_ROWS if row not in DRAWN_ROWS}
        diversity = {row: {"spread": [], "pairwise": []} for row in ("trained", "untrained", "reference_materials")}
        z_div_gen = seeded_generator((cfg.seed,), DIVERSITY_STREAM)
        for position, name in enumerate(self.shapes):
            views = self.views_of[name]
            images, masks = self.renders(trained, name, views, None, ws=mean_latent(trained).expand(len(views), -1, -1))
            rendered = {
                "mean_texture": (images, masks),
                "flat_colour": (
                    composite_images(self.photo_mean.reshape(1, 3, 1, 1).expand_as(images), masks, 1.0),
                    masks,
                ),
                "ground_truth": ground_truth_renders(world, name, views, self.resolution, lit=True),
                "training_materials": training_material_renders(
                    world, name, views, self.resolution, first=position * len(views)
                ),
            }
            for row, (images, masks) in rendered.items():
                fixed[row][0].append(images)
                fixed[row][1].append(masks)
            # Diversity: many latents at one pose.
            pose = pose_view(
                views[0], cfg.azimuth, cfg.elevation, (world.spec.distance_min + world.spec.distance_max) / 2
            )
            z_div = torch.randn(cfg.latents, trained.cfg.z_dim, generator=z_div_gen)
            draws = [
                (row, self.renders(generator, name, [pose] * cfg.latents, z_div, psi))
                for row, generator, psi in self.generator_rows
            ]
            draws.append(
                (
                    "reference_materials",
                    material_draws(world, name, [pose] * cfg.latents, self.resolution, cfg.seed, lit=self.lit),
                )
            )
            for row, (images, masks) in draws:
                diversity[row]["spread"].append(colour_spread(mean_object_lab(images, masks)))
                diversity[row]["pairwise"].append(mean_pairwise_delta_e(images, masks))
            done(name)
        return {row: (torch.cat(images), torch.cat(masks)) for row, (images, masks) in fixed.items()}, diversity

    def measure_draw(self, repeat: int, fixed: dict, extractor) -> dict:
        """{row: metrics} of one draw of the latents, the oracle's materials and the fresh photo set."""
        cfg, world = self.cfg, self.world
        key = draw_key(cfg.seed, repeat)
        drawn = {row: ([], []) for row in DRAWN_ROWS}
        z_gen = seeded_generator(key, LATENT_STREAM)
        for name, views in self.views_of.items():
            z = torch.randn(cfg.views, self.trained.cfg.z_dim, generator=z_gen)
            renders = [
                (row, self.renders(generator, name, views, z, psi)) for row, generator, psi in self.generator_rows
            ]
            renders += [
                (row, material_draws(world, name, views, self.resolution, key, ORACLE_STREAM, oracle_lit))
                for row, oracle_lit in (("oracle", True), ("oracle_unlit", False))
            ]
            for row, (images, masks) in renders:
                drawn[row][0].append(images)
                drawn[row][1].append(masks)
        sets = {**fixed, **{row: (torch.cat(images), torch.cat(masks)) for row, (images, masks) in drawn.items()}}
        reference, reference_masks = fresh_photo_set(world, self.resolution, key)
        kid_fid = (
            cfg.kid_fid and repeat == 0
        )  # KID and FID (the feature network, most of the cost) on the first draw only
        reference_features = extractor(reference * 2 - 1) if kid_fid else None  # once for every row
        eval_cfg = EvaluateConfig(resolution=self.resolution, features=cfg.features, seed=cfg.seed + repeat)
        photos, photo_masks = self.photos
        rows = {}
        for row in GENERATION_ROWS:
            images, masks = sets[row]
            metrics = evaluate_sets(
                images,
                reference,
                extractor,
                eval_cfg,
                masks,
                reference_masks,
                kid_fid=kid_fid,
                image_features=reference_features,
            )["metrics"]
            metrics["swd"] = float(
                np.mean([v for k, v in metrics.items() if k.startswith("swd_") and k.endswith("px")])
            )
            metrics["object_swd"] = object_set_swd(images, masks, reference, reference_masks, seed=eval_cfg.seed)
            # Against the training photos, as this protocol measured before the fresh photo set: for
            # comparison with earlier figures only (the oracle can lose there).
            metrics["object_swd_vs_photos"] = object_set_swd(images, masks, photos, photo_masks, seed=eval_cfg.seed)
            rows[row] = metrics
        return rows


@torch.no_grad()
def write_samples_grid(
    path: Path,
    generator: TextureGenerator,
    shape: PreparedShape,
    world: WorldData,
    name: str,
    resolution: int,
    cfg: GenerationConfig,
    device: torch.device,
    latents: int = 4,
    views: int = 4,
    lit: bool = False,
) -> None:
    """PNG grid: rows latents (seeds ``cfg.seed*1000 + row``), columns azimuths evenly spaced; the last row the shape's
    ground truth (lit)."""
    base = sample_views(world.spec, world.indices[name], 1)[0]
    ring = [
        pose_view(base, float(a), cfg.elevation, (world.spec.distance_min + world.spec.distance_max) / 2)
        for a in (np.arange(views) * 360.0 / views + cfg.azimuth)
    ]
    rows = []
    for k in range(latents):
        z = torch.randn(1, generator.cfg.z_dim, generator=torch.Generator().manual_seed(cfg.seed * 1000 + k)).repeat(
            views, 1
        )
        rows.append(
            generator_renders(
                generator,
                shape,
                ring,
                resolution,
                z,
                device,
                lit,
                truncation=cfg.truncation,
                photo_render=cfg.photo_render(world),
            )[0]
        )
    rows.append(ground_truth_renders(world, name, ring, resolution, lit=True)[0])
    grid = torch.stack(rows)  # (rows, views, 3, R, R)
    grid = grid.permute(0, 3, 1, 4, 2).reshape(len(rows) * resolution, views * resolution, 3)
    save_png(path, colours_to_uint8(grid, signed=False))
