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
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from mesh2tex.config import check_fields
from mesh2tex.errors import InputError
from mesh2tex.evaluation.compare import render_for_comparison
from mesh2tex.evaluation.report import GENERATION_ROWS, SPLITS
from mesh2tex.evaluation.summary import generation_summary
from mesh2tex.evaluation.surfaces import generator_surface
from mesh2tex.evaluation.world import WorldData, read_world
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.photos import list_images, load_set, square_resize
from mesh2tex.io.images import colours_to_uint8, save_png
from mesh2tex.models import load_generator
from mesh2tex.metrics import get_feature_extractor
from mesh2tex.metrics.evaluate import EvaluateConfig, evaluate_sets
from mesh2tex.metrics.generation import colour_spread, mean_object_lab, mean_pairwise_delta_e, object_set_swd
from mesh2tex.nn.batch import collate_shapes
from mesh2tex.nn.generator import TextureGenerator
from mesh2tex.nn.render_texture import render_field_views
from mesh2tex.progress import progress_bar
from mesh2tex.render import Lights, RenderSettings, composite_images, orbit_camera
from mesh2tex.synthetic.world import make_material, make_shape, render_views, sample_material, sample_views
from mesh2tex.texturing import mean_latent, shape_mismatch

LIGHTING_MODES = ("auto", "lit", "unlit")
GENERATOR_RENDERS = ("photo", "direct")
_REFERENCE_STREAM = 7919  # seeds the material draws of the diversity reference apart from the world's own
_ORACLE_STREAM = 7927  # seeds the oracle's material draws
_FRESH_PHOTOS_STREAM = 7933  # seeds the materials of the fresh photo set, the distances' reference
_LATENT_STREAM = 7937  # seeds the latents of the set rows
_DIVERSITY_STREAM = 7949  # seeds the latents of the diversity renders
DRAWN_ROWS = ("trained", "untrained", "oracle", "oracle_unlit")  # the rows drawn anew in every repeat


def draw_key(seed: int, repeat: int) -> tuple[int, ...]:
    """The entropy of repeat ``repeat``'s draws: ``(seed,)`` for the first, ``(seed, repeat)`` after."""
    return (seed,) if repeat == 0 else (seed, repeat)


def seeded_generator(key: tuple[int, ...], stream: int) -> torch.Generator:
    """A torch generator for one stream of draws, seeded from ``key`` and ``stream`` (never colliding
    with another key's or stream's)."""
    return torch.Generator().manual_seed(int(np.random.default_rng([*key, stream]).integers(1 << 62)))


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
    split: str = "held_out"  # the shapes measured: held_out (never trained on) or train (beside held_out: the generalisation gap)
    truncation: float = 1.0  # truncation psi of the trained generator's latents, as 'infer generate --truncation' (1: none)
    # The generator rows' renders: "photo" as the world renders its photos and the oracle (supersampled at the world's
    # resolution, read as the photo set is), or "direct", the GAN's own renderer at the metric's resolution (the figures before)
    generator_render: str = "photo"

    def __post_init__(self):
        if self.repeats < 1:
            raise ValueError(f"repeats must be at least 1, got {self.repeats}")
        check_fields(self, between={"truncation": (0.0, 1.0)})
        if self.lighting not in LIGHTING_MODES:
            raise ValueError(f"lighting must be one of {', '.join(LIGHTING_MODES)}, got {self.lighting!r}")
        if self.generator_render not in GENERATOR_RENDERS:
            raise ValueError(f"generator_render must be one of {', '.join(GENERATOR_RENDERS)}, got {self.generator_render!r}")
        if self.split not in SPLITS:
            raise ValueError(f"split must be one of {', '.join(SPLITS)}, got {self.split!r}")

    def photo_render(self, world: WorldData) -> RenderSettings | None:
        """:func:`generator_renders`' ``photo_render`` for the generator rows: the world's photos' render
        settings, or None with ``generator_render: direct``."""
        return world.spec.photo_render if self.generator_render == "photo" else None


def on_white(rgb_uint8: np.ndarray, mask_uint8: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    """(B, R, R, 3) uint8 over any background, (B, R, R) 0/255 -> on white (B, 3, R, R) [0, 1], masks (B, 1, R, R)."""
    rgb = torch.from_numpy(rgb_uint8).float().permute(0, 3, 1, 2) / 255.0
    mask = torch.from_numpy(mask_uint8 > 127).float().unsqueeze(1)
    return composite_images(rgb, mask, 1.0), mask


def as_photos(out: dict[str, np.ndarray], resolution: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``render_views`` output at the world's photo resolution, read as the photo set is read
    (:func:`mesh2tex.photos.load_set`: composited on white, then resized to ``resolution``)
    -> images (B, 3, R, R) in [0, 1], masks (B, 1, R, R).

    Rendering straight at ``resolution`` is another image pipeline: the world's own materials on its
    training shapes, rendered at 64 px instead of 128 px and resized, lay 52 object-SWD units from
    the identical photos instead of 10 (car world), a handicap the oracle rows do not deserve."""
    return read_as_photos(*on_white(out["rgb"], out["mask"]), resolution)


def read_as_photos(images: torch.Tensor, masks: torch.Tensor, resolution: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Renders on white at the world's photo resolution, images (B, 3, S, S) in [0, 1] and masks (B, 1, S, S),
    resized to ``resolution`` as the photo set is read -> (B, 3, R, R), (B, 1, R, R)."""
    if images.shape[-1] == resolution:
        return images, masks
    return (torch.stack([square_resize(image, resolution) for image in images]),
            torch.stack([(square_resize(mask, resolution) > 0.5).float() for mask in masks]))


def ground_truth_renders(world: WorldData, name: str, views, resolution: int, lit: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """The shape's own ground-truth material at ``views`` (world PhotoSetup records), rendered as the
    world's photos are (:func:`as_photos`); ``lit`` False renders the albedo (ambient 1).
    -> images (B, 3, R, R) in [0, 1], masks (B, 1, R, R)."""
    index = world.indices[name]
    out = render_views(make_shape(world.spec, index), make_material(world.spec, index), views, _photo_render(world, lit))
    return as_photos(out, resolution)


def _photo_render(world: WorldData, lit: bool) -> RenderSettings:
    """How the world renders its photos, lit by each view's light or (``lit`` False) unlit."""
    return dataclasses.replace(world.spec.photo_render, lighting="photo" if lit else "albedo")


def material_renders(world: WorldData, name: str, views, materials, resolution: int, lit: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """Shape ``name`` at each of ``views`` with the matching one of ``materials`` (world Material
    functions of surface point, normal and part label: any shape of the category takes any of them),
    rendered as the world's photos are (:func:`as_photos`; unlit unless ``lit``).
    -> images (B, 3, R, R) in [0, 1], masks (B, 1, R, R)."""
    shape = make_shape(world.spec, world.indices[name])
    images, masks = [], []
    for view, material in zip(views, materials, strict=True):
        out = render_views(shape, material, [view], _photo_render(world, lit))
        image, mask = as_photos(out, resolution)
        images.append(image)
        masks.append(mask)
    return torch.cat(images), torch.cat(masks)


def material_draws(world: WorldData, name: str, views, resolution: int, seed: int | tuple[int, ...], stream: int = _REFERENCE_STREAM,
                   lit: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
    """A fresh material of the world's sampler for each of ``views`` on shape ``name`` (see
    :func:`material_renders`; unlit unless ``lit``), drawn from ``seed`` (or a :func:`draw_key`) and
    ``stream``. -> images (B, 3, R, R) in [0, 1], masks (B, 1, R, R)."""
    index = world.indices[name]
    key = seed if isinstance(seed, tuple) else (seed,)
    shape = make_shape(world.spec, index) if world.spec.variety == "real" else None  # the varied world's materials fit the shape's size
    materials = [sample_material(world.spec, np.random.default_rng([*key, stream, index, k]), shape) for k in range(len(views))]
    return material_renders(world, name, views, materials, resolution, lit)


def training_material_renders(world: WorldData, name: str, views, resolution: int, first: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Shape ``name`` at ``views`` (lit) with the training shapes' own materials, one per view, taken
    in turn from the ``first``-th (modulo their count): what a generator that reproduced its training
    textures exactly, one per latent, would paint. -> images (B, 3, R, R) in [0, 1], masks (B, 1, R, R)."""
    train = world.train
    materials = [make_material(world.spec, world.indices[train[(first + k) % len(train)]]) for k in range(len(views))]
    return material_renders(world, name, views, materials, resolution)


def fresh_photo_set(world: WorldData, resolution: int, seed: int | tuple[int, ...]) -> tuple[torch.Tensor, torch.Tensor]:
    """The reference of every distance: the world's photo set drawn again with new materials.

    Every training shape at its own photos' cameras, lights and ambient shares, each photo with a
    fresh material of the world's sampler (one per photo), read as the photo set is. The photo set
    itself is one sample of a few materials (24 shapes, 24 materials on the chair and car worlds):
    measured against it, a generator that reproduces those materials beats fresh draws of the
    world's own sampler (the oracle), which says nothing about how close it is to the world's
    textures. -> images (N, 3, R, R) in [0, 1], masks (N, 1, R, R), N = training shapes x photos each."""
    images, masks = [], []
    for name in world.train:
        views = sample_views(world.spec, world.indices[name], world.spec.views)
        image, mask = material_draws(world, name, views, resolution, seed, _FRESH_PHOTOS_STREAM, lit=True)
        images.append(image)
        masks.append(mask)
    return torch.cat(images), torch.cat(masks)


@torch.no_grad()
def pose_view(view, azimuth: float, elevation: float, distance: float):
    """``view`` (a world PhotoSetup record) moved to another camera; its light turns about the vertical axis
    with the camera, so that it stays where the world's photos have it (beside and above the camera)."""
    turn = math.radians(azimuth - view.azimuth)
    x, y, z = view.light
    light = (x * math.cos(turn) + z * math.sin(turn), y, -x * math.sin(turn) + z * math.cos(turn))
    return dataclasses.replace(view, azimuth=azimuth, elevation=elevation, distance=distance, light=tuple(round(v, 6) for v in light))


def view_lights(views) -> Lights:
    """The lights of world PhotoSetup records: directions (B, 3) and ambient shares (B,)."""
    return Lights(torch.tensor([v.light for v in views], dtype=torch.float32), torch.tensor([v.ambient for v in views], dtype=torch.float32))


def generator_renders(generator: TextureGenerator, shape: PreparedShape, views, resolution: int, z: torch.Tensor | None,
                      device: torch.device, lit: bool = False, ws: torch.Tensor | None = None,
                      truncation: float = 1.0, photo_render: RenderSettings | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """One latent per view: z (B, z_dim) mapped with ``truncation`` psi, or style inputs ``ws``
    (B, num_ws, w_dim) instead; ``views`` B world PhotoSetup records (their cameras, and with ``lit``
    their lights) -> images (B, 3, R, R) in [0, 1] on white, masks (B, 1, R, R).

    ``photo_render`` (the world's ``WorldSpec.photo_render``): the texture rendered as the world renders
    its photos and as the oracle is (:func:`mesh2tex.evaluation.render_for_comparison` with these settings,
    supersampled and box-filtered, Lambert with flat face normals, unlit unless ``lit``), then read as
    the photo set is (on white, resized to R). None: the GAN's own
    renderer straight at R, as it trains (no antialiasing): another image pipeline than the oracle's,
    which costs the generator rows distance that is not the texture's (``docs/results/gan.md``, *One
    pipeline for every row*)."""
    b = len(views)
    ws = generator.mapping(z.to(device), truncation_psi=truncation) if ws is None else ws.to(device)
    if photo_render is not None:
        photo_render = dataclasses.replace(photo_render, lighting="photo" if lit else "albedo")
        batch = collate_shapes([shape]).to(device)
        encoded = generator.encoder(batch)  # the geometry's encoding: the same for every view's latent
        images, masks = [], []
        for view, w in zip(views, ws, strict=True):
            texture = generator.synthesize(batch, w[None], encoded=encoded, noise_mode="none")
            out = render_for_comparison(generator_surface(generator, texture, batch), [view], photo_render)
            images.append(composite_images(out.rgb, out.mask, 1.0))
            masks.append(out.mask)
        return read_as_photos(torch.cat(images).cpu(), torch.cat(masks).cpu(), resolution)
    batch = collate_shapes([shape] * b).to(device)
    camera = orbit_camera(torch.tensor([v.azimuth for v in views]), torch.tensor([v.elevation for v in views]),
                          distance=torch.tensor([v.distance for v in views]), fov=torch.tensor([v.fov for v in views]))
    out = render_field_views(generator, batch, ws, camera.mvp.to(device), (resolution, resolution),
                             torch.ones(b, 3, device=device), noise_mode="none", lights=view_lights(views).to(device) if lit else None)
    return ((out.images.float() + 1) / 2).clamp(0, 1).cpu(), out.mask.float().cpu()


def photo_set_spread(world: WorldData, photos: torch.Tensor, masks: torch.Tensor, names: list[str]) -> float:
    """Spread of the mean object colours of the photo set's shapes: each shape's photos averaged. NaN
    for a world of one training shape: a spread across shapes needs two (the report says so)."""
    lab = mean_object_lab(photos, masks)
    by_shape: dict[str, list[torch.Tensor]] = {}
    for stem, colour in zip(names, lab):
        by_shape.setdefault(stem.rsplit("_", 1)[0], []).append(colour)
    if len(by_shape) < 2:
        return float("nan")
    return colour_spread(torch.stack([torch.stack(c).mean(0) for c in by_shape.values()]))


def run_generation_protocol(world_dir: str | Path, shapes_dir: str | Path, checkpoint: str | Path, cfg: GenerationConfig,
                            device: torch.device | None = None, extractor=None, samples_path: Path | None = None,
                            log=print) -> dict:
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
        raise InputError(f"{checkpoint}: the checkpoint does not say the resolution it was trained at; give --resolution")
    torch.manual_seed(cfg.seed)
    untrained = TextureGenerator(trained.cfg).to(device).eval().requires_grad_(False)
    names = world.held_out if cfg.split == "held_out" else world.train
    names = names[: cfg.max_shapes] if cfg.max_shapes > 0 else names
    run = _ProtocolRun(world, cfg, device, trained, untrained, _prepared_shapes(world, names, shapes_dir, cfg, trained),
                       resolution=cfg.resolution or model.resolution, lit=model.lit if cfg.lighting == "auto" else cfg.lighting == "lit")
    bar = progress_bar(total=len(names) + cfg.repeats, desc="generation protocol", unit="step")
    fixed, diversity = run.fixed_rows_and_diversity(lambda name: (log(f"generation protocol: {name} done "
                                                                      f"({time.perf_counter() - start:.0f} s)"), bar.update(1)))
    if cfg.kid_fid:
        extractor = extractor or get_feature_extractor(cfg.features, device=device)
    per_repeat = []  # {row: metrics} of every repeat
    for repeat in range(cfg.repeats):
        per_repeat.append(run.measure_draw(repeat, fixed, extractor))
        log(f"generation protocol: draw {repeat + 1} of {cfg.repeats} measured ({time.perf_counter() - start:.0f} s)")
        bar.update(1)
    bar.close()
    result = {"world": str(world.root), "checkpoint": str(checkpoint), "split": cfg.split, "shapes": names, "resolution": run.resolution,
              "iteration": model.iteration or 0, **generation_summary(per_repeat, diversity, photo_set_spread(world, *run.photos, run.photo_names)),
              "generator_lit": run.lit, "settings": dataclasses.asdict(cfg), "seconds": round(time.perf_counter() - start, 1)}
    if samples_path is not None:
        write_samples_grid(samples_path, trained, run.shapes[names[0]], world, names[0], run.resolution, cfg, device, lit=run.lit)
    return result


def _prepared_shapes(world: WorldData, names: list[str], shapes_dir: str | Path, cfg: GenerationConfig, generator) -> dict:
    """{name: PreparedShape} of the measured shapes, each checked against the generator (InputError naming the file)."""
    shapes = {}
    for name in names:
        path = Path(shapes_dir) / f"{name}.npz"
        if not path.is_file():
            raise InputError(f"{path}: the {SPLITS[cfg.split]} shape {name} is not prepared; run 'mesh2tex prepare shapes' on "
                             f"{world.root / 'meshes' / (name + '.obj')}")
        shape = PreparedShape.load(path)
        problem = shape_mismatch(shape, generator)
        if problem:
            raise InputError(f"{path}: {problem}")
        shapes[name] = shape
    return shapes


class _ProtocolRun:
    """One run of the protocol: the world, the generators, the shapes and their views, and the photo set.
    Its steps draw random numbers in the order the protocol has always drawn them (figures stay reproducible)."""

    def __init__(self, world: WorldData, cfg: GenerationConfig, device, trained, untrained, shapes: dict, resolution: int, lit: bool):
        self.world, self.cfg, self.device, self.trained, self.shapes = world, cfg, device, trained, shapes
        self.resolution, self.lit, self.photo_render = resolution, lit, cfg.photo_render(world)
        self.photos = load_set(world.root / "images", "image", resolution, 1.0, masks=list_images(world.root / "masks", "mask"))
        self.photo_names = list(list_images(world.root / "images", "image"))
        photos, photo_masks = self.photos
        self.photo_mean = (photos * photo_masks).sum(dim=(0, 2, 3)) / (photo_masks.sum() * 1.0).clamp_min(1.0)  # (3,) mean object colour
        self.views_of = {name: sample_views(world.spec, world.indices[name], cfg.views) for name in shapes}  # fresh for held-out shapes
        self.generator_rows = (("trained", trained, cfg.truncation), ("untrained", untrained, 1.0))  # (row, generator, truncation psi)

    def renders(self, generator, name: str, views, z, psi: float = 1.0, ws=None):
        return generator_renders(generator, self.shapes[name], views, self.resolution, z, self.device, self.lit, truncation=psi,
                                 photo_render=self.photo_render, **({} if ws is None else {"ws": ws}))

    def fixed_rows_and_diversity(self, done) -> tuple[dict, dict]:
        """The rows that draw nothing (rendered once) and the diversity measures, shape by shape (``done(name)`` after each)."""
        cfg, world, trained = self.cfg, self.world, self.trained
        fixed = {row: ([], []) for row in GENERATION_ROWS if row not in DRAWN_ROWS}
        diversity = {row: {"spread": [], "pairwise": []} for row in ("trained", "untrained", "reference_materials")}
        z_div_gen = seeded_generator((cfg.seed,), _DIVERSITY_STREAM)
        for position, name in enumerate(self.shapes):
            views = self.views_of[name]
            images, masks = self.renders(trained, name, views, None, ws=mean_latent(trained).expand(len(views), -1, -1))
            rendered = {"mean_texture": (images, masks),
                        "flat_colour": (composite_images(self.photo_mean.reshape(1, 3, 1, 1).expand_as(images), masks, 1.0), masks),
                        "ground_truth": ground_truth_renders(world, name, views, self.resolution, lit=True),
                        "training_materials": training_material_renders(world, name, views, self.resolution, first=position * len(views))}
            for row, (images, masks) in rendered.items():
                fixed[row][0].append(images)
                fixed[row][1].append(masks)
            # Diversity: many latents at one pose.
            pose = pose_view(views[0], cfg.azimuth, cfg.elevation, (world.spec.distance_min + world.spec.distance_max) / 2)
            z_div = torch.randn(cfg.latents, trained.cfg.z_dim, generator=z_div_gen)
            draws = [(row, self.renders(generator, name, [pose] * cfg.latents, z_div, psi)) for row, generator, psi in self.generator_rows]
            draws.append(("reference_materials", material_draws(world, name, [pose] * cfg.latents, self.resolution, cfg.seed, lit=self.lit)))
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
        z_gen = seeded_generator(key, _LATENT_STREAM)
        for name, views in self.views_of.items():
            z = torch.randn(cfg.views, self.trained.cfg.z_dim, generator=z_gen)
            renders = [(row, self.renders(generator, name, views, z, psi)) for row, generator, psi in self.generator_rows]
            renders += [(row, material_draws(world, name, views, self.resolution, key, _ORACLE_STREAM, oracle_lit))
                        for row, oracle_lit in (("oracle", True), ("oracle_unlit", False))]
            for row, (images, masks) in renders:
                drawn[row][0].append(images)
                drawn[row][1].append(masks)
        sets = {**fixed, **{row: (torch.cat(images), torch.cat(masks)) for row, (images, masks) in drawn.items()}}
        reference, reference_masks = fresh_photo_set(world, self.resolution, key)
        kid_fid = cfg.kid_fid and repeat == 0  # KID and FID (the feature network, most of the cost) on the first draw only
        reference_features = extractor(reference * 2 - 1) if kid_fid else None  # once for every row
        eval_cfg = EvaluateConfig(resolution=self.resolution, features=cfg.features, seed=cfg.seed + repeat)
        photos, photo_masks = self.photos
        rows = {}
        for row in GENERATION_ROWS:
            images, masks = sets[row]
            metrics = evaluate_sets(images, reference, extractor, eval_cfg, masks, reference_masks, kid_fid=kid_fid,
                                    image_features=reference_features)["metrics"]
            metrics["swd"] = float(np.mean([v for k, v in metrics.items() if k.startswith("swd_") and k.endswith("px")]))
            metrics["object_swd"] = object_set_swd(images, masks, reference, reference_masks, seed=eval_cfg.seed)
            # Against the training photos, as this protocol measured before the fresh photo set: for
            # comparison with earlier figures only (the oracle can lose there).
            metrics["object_swd_vs_photos"] = object_set_swd(images, masks, photos, photo_masks, seed=eval_cfg.seed)
            rows[row] = metrics
        return rows


@torch.no_grad()
def write_samples_grid(path: Path, generator: TextureGenerator, shape: PreparedShape, world: WorldData, name: str,
                       resolution: int, cfg: GenerationConfig, device: torch.device, latents: int = 4, views: int = 4, lit: bool = False) -> None:
    """PNG grid: rows latents (seeds ``cfg.seed*1000 + row``), columns azimuths evenly spaced; the last row the shape's ground truth (lit)."""
    base = sample_views(world.spec, world.indices[name], 1)[0]
    ring = [pose_view(base, float(a), cfg.elevation, (world.spec.distance_min + world.spec.distance_max) / 2)
            for a in (np.arange(views) * 360.0 / views + cfg.azimuth)]
    rows = []
    for k in range(latents):
        z = torch.randn(1, generator.cfg.z_dim, generator=torch.Generator().manual_seed(cfg.seed * 1000 + k)).repeat(views, 1)
        rows.append(generator_renders(generator, shape, ring, resolution, z, device, lit, truncation=cfg.truncation,
                                      photo_render=cfg.photo_render(world))[0])
    rows.append(ground_truth_renders(world, name, ring, resolution, lit=True)[0])
    grid = torch.stack(rows)  # (rows, views, 3, R, R)
    grid = grid.permute(0, 3, 1, 4, 2).reshape(len(rows) * resolution, views * resolution, 3)
    save_png(path, colours_to_uint8(grid, signed=False))
