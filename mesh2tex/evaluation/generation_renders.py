"""The renders the generation protocol compares (:mod:`mesh2tex.evaluation.generation`), all alike.

The world's ground truth, fresh draws of its material sampler (the oracle and the fresh photo set, each
from its own seeded stream so one never shifts another), and a generator's textures, each rendered as
the world's photos are (lit, supersampled, composited on white) and read back as a photo would be: RGB
(N, 3, R, R) in [0, 1] and masks (N, 1, R, R).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import torch

from mesh2tex.evaluation.compare import render_for_comparison
from mesh2tex.evaluation.surfaces import generator_surface
from mesh2tex.evaluation.world import WorldData
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.metrics.generation import colour_spread, mean_object_lab
from mesh2tex.nn.batch import collate_shapes
from mesh2tex.nn.generator import TextureGenerator
from mesh2tex.nn.render_texture import render_field_views
from mesh2tex.photos import square_resize
from mesh2tex.render import Lights, RenderSettings, composite_images, orbit_camera
from mesh2tex.synthetic.world import make_material, make_shape, render_views, sample_material, sample_views

REFERENCE_STREAM = 7919  # seeds the material draws of the diversity reference apart from the world's own
ORACLE_STREAM = 7927  # seeds the oracle's material draws
FRESH_PHOTOS_STREAM = 7933  # seeds the materials of the fresh photo set, the distances' reference
LATENT_STREAM = 7937  # seeds the latents of the set rows
DIVERSITY_STREAM = 7949  # seeds the latents of the diversity renders


def draw_key(seed: int, repeat: int) -> tuple[int, ...]:
    """The entropy of repeat ``repeat``'s draws: ``(seed,)`` for the first, ``(seed, repeat)`` after."""
    return (seed,) if repeat == 0 else (seed, repeat)


def seeded_generator(key: tuple[int, ...], stream: int) -> torch.Generator:
    """A torch generator for one stream of draws, seeded from ``key`` and ``stream`` (never colliding
    with another key's or stream's)."""
    return torch.Generator().manual_seed(int(np.random.default_rng([*key, stream]).integers(1 << 62)))


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
    return (
        torch.stack([square_resize(image, resolution) for image in images]),
        torch.stack([(square_resize(mask, resolution) > 0.5).float() for mask in masks]),
    )


def ground_truth_renders(
    world: WorldData, name: str, views, resolution: int, lit: bool = True
) -> tuple[torch.Tensor, torch.Tensor]:
    """The shape's own ground-truth material at ``views`` (world PhotoSetup records), rendered as the
    world's photos are (:func:`as_photos`); ``lit`` False renders the albedo (ambient 1).
    -> images (B, 3, R, R) in [0, 1], masks (B, 1, R, R)."""
    index = world.indices[name]
    out = render_views(
        make_shape(world.spec, index), make_material(world.spec, index), views, photo_render_settings(world, lit)
    )
    return as_photos(out, resolution)


def photo_render_settings(world: WorldData, lit: bool) -> RenderSettings:
    """How the world renders its photos, lit by each view's light or (``lit`` False) unlit."""
    return dataclasses.replace(world.spec.photo_render, lighting="photo" if lit else "albedo")


def material_renders(
    world: WorldData, name: str, views, materials, resolution: int, lit: bool = True
) -> tuple[torch.Tensor, torch.Tensor]:
    """Shape ``name`` at each of ``views`` with the matching one of ``materials`` (world Material
    functions of surface point, normal and part label: any shape of the category takes any of them),
    rendered as the world's photos are (:func:`as_photos`; unlit unless ``lit``).
    -> images (B, 3, R, R) in [0, 1], masks (B, 1, R, R)."""
    shape = make_shape(world.spec, world.indices[name])
    images, masks = [], []
    for view, material in zip(views, materials, strict=True):
        out = render_views(shape, material, [view], photo_render_settings(world, lit))
        image, mask = as_photos(out, resolution)
        images.append(image)
        masks.append(mask)
    return torch.cat(images), torch.cat(masks)


def material_draws(
    world: WorldData,
    name: str,
    views,
    resolution: int,
    seed: int | tuple[int, ...],
    stream: int = REFERENCE_STREAM,
    lit: bool = False,
) -> tuple[torch.Tensor, torch.Tensor]:
    """A fresh material of the world's sampler for each of ``views`` on shape ``name`` (see
    :func:`material_renders`; unlit unless ``lit``), drawn from ``seed`` (or a :func:`draw_key`) and
    ``stream``. -> images (B, 3, R, R) in [0, 1], masks (B, 1, R, R)."""
    index = world.indices[name]
    key = seed if isinstance(seed, tuple) else (seed,)
    shape = (
        make_shape(world.spec, index) if world.spec.variety == "real" else None
    )  # the varied world's materials fit the shape's size
    materials = [
        sample_material(world.spec, np.random.default_rng([*key, stream, index, k]), shape) for k in range(len(views))
    ]
    return material_renders(world, name, views, materials, resolution, lit)


def training_material_renders(
    world: WorldData, name: str, views, resolution: int, first: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Shape ``name`` at ``views`` (lit) with the training shapes' own materials, one per view, taken
    in turn from the ``first``-th (modulo their count): what a generator that reproduced its training
    textures exactly, one per latent, would paint. -> images (B, 3, R, R) in [0, 1], masks (B, 1, R, R)."""
    train = world.train
    materials = [make_material(world.spec, world.indices[train[(first + k) % len(train)]]) for k in range(len(views))]
    return material_renders(world, name, views, materials, resolution)


def fresh_photo_set(
    world: WorldData, resolution: int, seed: int | tuple[int, ...]
) -> tuple[torch.Tensor, torch.Tensor]:
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
        image, mask = material_draws(world, name, views, resolution, seed, FRESH_PHOTOS_STREAM, lit=True)
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
    return dataclasses.replace(
        view, azimuth=azimuth, elevation=elevation, distance=distance, light=tuple(round(v, 6) for v in light)
    )


def view_lights(views) -> Lights:
    """The lights of world PhotoSetup records: directions (B, 3) and ambient shares (B,)."""
    return Lights(
        torch.tensor([v.light for v in views], dtype=torch.float32),
        torch.tensor([v.ambient for v in views], dtype=torch.float32),
    )


def generator_renders(
    generator: TextureGenerator,
    shape: PreparedShape,
    views,
    resolution: int,
    z: torch.Tensor | None,
    device: torch.device,
    lit: bool = False,
    ws: torch.Tensor | None = None,
    truncation: float = 1.0,
    photo_render: RenderSettings | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
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
    camera = orbit_camera(
        torch.tensor([v.azimuth for v in views]),
        torch.tensor([v.elevation for v in views]),
        distance=torch.tensor([v.distance for v in views]),
        fov=torch.tensor([v.fov for v in views]),
    )
    out = render_field_views(
        generator,
        batch,
        ws,
        camera.mvp.to(device),
        (resolution, resolution),
        torch.ones(b, 3, device=device),
        noise_mode="none",
        lights=view_lights(views).to(device) if lit else None,
    )
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
