"""The ``unconditional`` protocol: the GAN's renders of the held-out shapes against the world's photos (set
metrics: KID, FID, SWD); run by :func:`mesh2tex.evaluation.protocols.run_protocols`."""

from __future__ import annotations

import time

import torch

from mesh2tex.evaluation.protocol_config import ProtocolInputs
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.io.images import images_to_uint8, save_png
from mesh2tex.metrics import to_unit
from mesh2tex.metrics.evaluate import evaluate_sets
from mesh2tex.nn.batch import collate_shapes
from mesh2tex.nn.render_texture import render_field_views
from mesh2tex.photos import list_images, load_set
from mesh2tex.render import orbit_camera
from mesh2tex.texturing import latent


@torch.no_grad()
def unconditional_renders(
    generator,
    shapes: list[PreparedShape],
    latents: int,
    views: int,
    resolution: int,
    distance: float,
    fov: float,
    elevations: tuple[float, float],
    seed: int,
    device: torch.device,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Renders [len(shapes) * latents * views, 3, R, R] in [0, 1] on white of random latents, and
    their object masks [same N, 1, R, R] (0/1).

    Views of one latent: azimuths evenly spaced (offset by the latent), elevations evenly across
    ``elevations`` (degrees); latent seeds ``seed * 1000 + k``.
    """
    renders, masks = [], []
    for s, shape in enumerate(shapes):
        batch = collate_shapes([shape]).to(device)
        encoded = generator.encoder(batch)
        for k in range(latents):
            ws = latent(generator, seed * 1000 + s * latents + k, device)
            azimuth = (torch.arange(views, dtype=torch.float32) + k / max(latents, 1)) * (360.0 / views)
            elevation = (
                torch.linspace(elevations[0], elevations[1], views)
                if views > 1
                else torch.tensor([sum(elevations) / 2])
            )
            mvp = orbit_camera(azimuth, elevation, distance=distance, fov=fov).mvp.to(device)
            out = render_field_views(
                generator,
                batch,
                ws,
                mvp,
                (resolution, resolution),
                torch.ones(views, 3, device=device),
                encoded=encoded,
                noise_mode="none",
            )
            renders.append(to_unit(out.images.float()).clamp(0, 1).cpu())
            masks.append(out.mask.float().cpu())
    return torch.cat(renders), torch.cat(masks)


def run_unconditional(run: ProtocolInputs) -> dict:
    """Protocol ``unconditional``: GAN renders on the held-out shapes against the world's photos."""
    generator, world, shapes, cfg, out = run.generator, run.world, run.shapes, run.cfg, run.out
    start = time.perf_counter()
    settings = world.index.get("settings", {})
    elevations = (float(settings.get("elevation_min", 5.0)), float(settings.get("elevation_max", 35.0)))
    held_out = [shapes[name] for name in world.query_shapes]
    renders, render_masks = unconditional_renders(
        generator,
        held_out,
        cfg.latents,
        cfg.views,
        cfg.resolution,
        run.distance,
        run.fov,
        elevations,
        cfg.seed,
        run.device,
    )
    photos, photo_masks = load_set(
        world.root / "images", "image", cfg.resolution, 1.0, masks=list_images(world.root / "masks", "mask")
    )
    result = evaluate_sets(renders, photos, run.extractor, cfg.evaluate_config(), render_masks, photo_masks)
    if out is not None:
        folder = out / "renders" / "unconditional"
        folder.mkdir(parents=True, exist_ok=True)
        for i, image in enumerate(renders[: cfg.views * cfg.latents]):
            save_png(folder / f"{world.query_shapes[0]}_{i:02d}.png", images_to_uint8(image, signed=False))
    return {
        "shapes": world.query_shapes,
        "reference": str(world.root / "images"),
        **result,
        "seconds": round(time.perf_counter() - start, 2),
    }
