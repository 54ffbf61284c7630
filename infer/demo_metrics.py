"""The demo's transfer judged beside the ground truth and the simple baselines (the report's transfer table)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from mesh2tex.errors import UserError
from mesh2tex.evaluation import (
    ScoreSettings,
    backproject_photo,
    common_mask,
    flat_surface,
    generator_surface,
    other_views,
    photo_mean_colour,
    render_for_comparison,
    score_views,
    seen_and_unseen,
    textured_surface,
)
from mesh2tex.evaluation.world import load_query_truth, reference_renders
from mesh2tex.io.assets import load_glb
from mesh2tex.io.images import images_to_uint8, save_png
from mesh2tex.models import load_generator
from mesh2tex.nn.batch import collate_shapes
from mesh2tex.render import RenderSettings
from mesh2tex.texturing import load_shape, mean_latent

from .demo_report import TRANSFER_METHODS


def pick_query(world: Path, index: int) -> dict:
    """The sidecar of the ``index``-th query photo of the world (sorted by name)."""
    sidecars = sorted((world / "queries").glob("*.json"))
    if not sidecars:
        raise UserError(f"{world / 'queries'}: no query photos")
    return json.loads(sidecars[index % len(sidecars)].read_text())


# ------------------------------------------------------------------------------------------- metrics


def render_glb_at_pose(glb: Path, views: list, settings: RenderSettings):
    """A textured GLB (as the pipeline writes it) rendered by ``mesh2tex.evaluation.render_for_comparison``
    at ``views`` (``mesh2tex.synthetic.world.PhotoSetup``) with ``settings``: a ``ComparisonRender`` (rgb [B,3,S,S] in
    [0,1], mask, parts)."""
    try:
        vertices, faces, uv, image = load_glb(glb)
    except ValueError as error:
        raise UserError(str(error)) from None
    return render_for_comparison(textured_surface(vertices, faces, uv, image), views, settings)


@torch.no_grad()
def transfer_metrics(
    world: Path,
    transfer: Path,
    query: dict,
    resolution: int,
    lighting: str = "photo",
    unseen_views: int = 4,
    lowpass_sigma: float = 3.0,
) -> dict:
    """The transferred GLB beside the ground truth and the simple baselines, all judged alike.

    Every method is a textured surface rendered by one function (``mesh2tex.evaluation``) with the
    query photo's camera, light and background, at the photo's view ("seen") and ``unseen_views``
    views it does not show, against what the world photographs there (the photo, then the world's own
    renders), on the pixels both the world's shape and the transferred mesh cover: the ground truth
    (``textured/`` GLB, the oracle), the transfer's GLB, the photo's mean colour, the generator's mean
    texture and the photo back-projected from the pose the transfer used. ``resolution`` is the side
    of the transfer's crops; the comparison runs at the photo's own resolution. Writes
    ``transfer/comparison_views.png`` (a row per method, reference first).

    Returns {method: {"seen <metric>": value, "unseen <metric>": mean}, "settings": {...}}.
    """
    index = json.loads((world / "index.json").read_text())
    report = json.loads((transfer / "report.json").read_text())
    try:
        truth = load_query_truth(world, index, query)
        vertices, faces, _, _ = load_glb(transfer / "textured.glb")
    except ValueError as error:
        raise UserError(str(error)) from None
    views = [truth.view] + other_views(truth.view, [360.0 * k / (unseen_views + 1) for k in range(1, unseen_views + 1)])
    settings = truth.render_settings(lighting)

    def render(surface):
        return render_for_comparison(surface, views, settings)

    reference = reference_renders(truth, views, lighting)
    renders = {
        "oracle": render(truth.truth.oracle),
        "transfer": render_glb_at_pose(transfer / "textured.glb", views, settings),
        "flat_colour": render(flat_surface(vertices, faces, photo_mean_colour(truth.photo[0], truth.photo_mask[0]))),
    }
    renders["mean_texture"] = render(_mean_texture(report))
    renders["backprojection"] = render(_backprojection(transfer, report, truth, vertices, faces))
    pose = report["pose"]
    mask = common_mask(reference.mask, renders["transfer"].mask)
    scoring = ScoreSettings(lowpass_sigma=lowpass_sigma)
    result = {
        name: {
            k: round(v, 5)
            for k, v in seen_and_unseen(score_views(rendered, reference.rgb, reference.parts, mask, scoring)).items()
        }
        for name, rendered in renders.items()
    }
    rows = [reference.rgb] + [renders[name].rgb for name in TRANSFER_METHODS]
    tiles = [np.concatenate(list(images_to_uint8(row, signed=False)), axis=1) for row in rows]
    save_png(transfer / "comparison_views.png", np.concatenate(tiles, axis=0))
    save_png(transfer / "render_at_true_pose.png", tiles[2][:, : settings.resolution])
    result["settings"] = {
        "lighting": lighting,
        "views": [[round(v.azimuth, 2), round(v.elevation, 2)] for v in views],
        "lowpass_sigma_px": lowpass_sigma,
        "resolution": settings.resolution,
        "pose_used": [pose["azimuth"], pose["elevation"]],
    }
    return result


def _mean_texture(report: dict):
    """The transfer's generator's mean texture (w_avg) on the mesh the transfer prepared, as a surface."""
    model = load_generator(report["checkpoint"], torch.device("cpu"))
    generator = model.network
    faces = model.face_count(report["settings"].get("faces", 0))
    shape, _ = load_shape(report["mesh"], generator, faces, report["settings"].get("seed", 0), output_mesh="prepared")
    batch = collate_shapes([shape])
    return generator_surface(generator, generator.synthesize(batch, mean_latent(generator), noise_mode="none"), batch)


def _backprojection(transfer: Path, report: dict, truth, vertices: np.ndarray, faces: np.ndarray):
    """The query photo back-projected onto the transferred mesh from the pose the transfer used, as a surface."""
    pose = report["pose"]
    try:
        return backproject_photo(
            vertices,
            faces,
            truth.photo[0],
            truth.photo_mask[0, 0],
            pose["azimuth"],
            pose["elevation"],
            pose["distance"],
            pose["fov"],
            margin=report["settings"]["margin"],
        )
    except ValueError as error:
        raise UserError(f"{transfer / 'report.json'}: {error}") from None
