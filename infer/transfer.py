"""``mesh2tex infer transfer``: texture a mesh after one photo (Mesh2Tex section 3.3).

    mesh2tex infer transfer --checkpoint GAN --mesh MESH --image IMG [--mask M] [--pose auto|AZ,EL]
                            [--pose-checkpoint P] [--noc-checkpoint N] --out DIR [--texture-size 1024]
                            [--no-noc] [--no-patches] [--no-refine] [--no-pose-search] [--automaton [--automaton-iters
                            300]]
                            [--config YAML] [--overwrite]

Steps:
1. The photo: mask from its alpha channel, from ``--mask``, or estimated (the mask network with
   GrabCut edges, the network alone, GrabCut alone; with ``--pose auto`` the silhouette search
   picks the estimate its found pose matches best; then GrabCut from the mesh's outline at the pose
   makes it again and the pose is found again: :func:`mesh2tex.transfer.locate_object`); a square
   crop around the object, resized to ``resolution``.
2. The pose: given as ``--pose AZ,EL`` (degrees, the orbit-camera convention), or ``--pose auto``
   (the default, needs ``--pose-checkpoint``): the pose network's bin probabilities, then a search
   for the pose whose silhouette best matches the photo's mask (``--no-pose-search``: the network's
   bin centres, as the paper).
3. Correspondences: the NOC network predicts the photo's NOC map; the mesh's NOC map is rendered at
   the pose. Renders are cropped around the object the same way as the photo, so both images show
   the object at the same scale.
4. Stage 1 optimises the latent ``w`` (all style inputs of the synthesis network) with
   ``w_glob * L_glob + w_patch * L_patch`` (Equation 2) plus ``w_colour * L_colour`` (the low-pass
   colour loss at the pose, not in the paper); stage 2 unfreezes the last two synthesis blocks and
   optimises their weights with ``L_patch + w_colour * L_colour``. Adam, lr 0.05 then 0.01 (the
   paper: 0.01 and the style losses alone). A generator trained lit is rendered under the photo's light
   (``light``), so the texture stays albedo: the light of the prior that best explains the photo's shading
   across the mesh's folds at the pose (``light_start: search``; ``prior``: the prior's middle), held there
   (``light_fixed``; false: optimised with the texture). When the mesh is mirror-symmetric (a chair's
   or a car's left and right, ``mesh2tex.geometry.symmetry.mirror_axis``), both stages also hold the
   render at the mirrored pose to the photo flipped left to right (``w_mirror``, 0 turns it off): the
   side the photo shows paints the other.
5. Outputs in ``DIR``: ``textured.glb`` (the user's own mesh, in its own frame and units, with psi
   baked into its UVs or a new atlas: ``--up``, ``--uv``, ``--output-mesh`` as in ``infer generate``),
   ``textured.ply`` (the same mesh with vertex colours),
   ``comparison.png`` (photo | render at the pose | photo NOC | rendered NOC), ``turntable_XX.png`` and
   ``turntable.gif`` (lit by the photo's light, turning with the camera, when the renders were lit),
   ``report.json`` (pose, the photo's light, losses per stage, seconds per stage, settings, the fit at the pose).

``--automaton``: instead of step 4's optimisation of the GAN's texture, a mesh automaton is grown on the
mesh and fitted to the photo with the same losses (:mod:`mesh2tex.transfer.automaton`; no GAN in the
result: the checkpoint gives the camera and the shape's preparation). Its renders are unlit, so its
colours carry the photo's shading, as back-projection's do; the same files are written.

Ablations of the paper's Table 8: ``--no-noc`` (patch pairs without NOC guidance), ``--no-patches``
(global loss only; stage 2 then also uses the global loss), ``--no-refine`` (stage 1 only).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from mesh2tex.config import load_config
from mesh2tex.errors import UserError, note, warning
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.io.atomic import atomic_path, write_json
from mesh2tex.io.images import colours_to_uint8, images_to_uint8, save_png
from mesh2tex.io.outputs import guard_outputs
from mesh2tex.models import is_model_name, load_generator, model_has
from mesh2tex.nn.batch import collate_shapes
from mesh2tex.nn.generator import TextureGenerator
from mesh2tex.nn.render_texture import render_field_views, render_states
from mesh2tex.nn.vgg import load_vgg19
from mesh2tex.options import config_overrides
from mesh2tex.render import Lights, composite, composite_images, orbit_camera, orbit_direction, turntable_angles
from mesh2tex.render.bake import BakeTarget
from mesh2tex.runtime import select_device
from mesh2tex.texturing import load_shape, write_automaton_mesh, write_textured_mesh
from mesh2tex.transfer import (
    AutomatonFit,
    FramedView,
    Photo,
    PoseEstimate,
    TransferConfig,
    TransferResult,
    check_style_sizes,
    fit_automaton,
    locate_object,
    photo_masks,
    predict_noc,
    transfer_texture,
    view_at_pose,
)
from mesh2tex.transfer.fit import check_fit


# -------------------------------------------------------------------------------------- the pose
def parse_pose(text: str) -> tuple[float, float] | None:
    """'auto' -> None; 'AZ,EL' -> degrees."""
    if text == "auto":
        return None
    try:
        azimuth, elevation = (float(v) for v in text.split(","))
    except ValueError:
        raise UserError(f"--pose {text!r}: give 'auto' or 'AZIMUTH,ELEVATION' in degrees, e.g. 30,20") from None
    if not (math.isfinite(azimuth) and -90.0 <= elevation <= 90.0):
        raise UserError(f"--pose {text!r}: the azimuth must be a finite angle and the elevation in [-90, 90] degrees")
    return azimuth, elevation


# ------------------------------------------------------------------------------------------ outputs
def to_uint8_image(image: torch.Tensor) -> np.ndarray:
    """(1,3,H,W) or (3,H,W) in [-1,1] -> (H,W,3) uint8."""
    return images_to_uint8(image.reshape(-1, *image.shape[-3:])[0])


def noc_to_uint8(noc: torch.Tensor, mask: torch.Tensor) -> np.ndarray:
    """(H,W,3) NOC in [0,1] and a (…,H,W) mask -> (H,W,3) uint8, white background."""
    m = mask.reshape(noc.shape[:2] + (1,)).cpu()
    return colours_to_uint8(composite(noc.cpu().clamp(0, 1)[None], m[None], 1.0)[0], signed=False)


def save_comparison(
    out: Path, photo: Photo, render: torch.Tensor, view: FramedView, photo_noc: torch.Tensor | None
) -> None:
    """comparison.png: photo | render at the pose (1,3,R,R) | photo NOC (when predicted) | rendered NOC, on white."""
    white_photo = composite_images(photo.image, photo.mask, 1.0)
    white_render = composite_images(render, view.mask, 1.0)
    panels = [to_uint8_image(white_photo), to_uint8_image(white_render)]
    if photo_noc is not None:
        panels.append(noc_to_uint8(photo_noc, photo.mask))
    panels.append(noc_to_uint8(view.noc, view.mask))
    save_png(out / "comparison.png", np.concatenate(panels, axis=1))


def save_turntable(out: Path, images: torch.Tensor) -> None:
    """turntable_XX.png and turntable.gif from (K,3,H,W) images in [-1, 1]."""
    frames = []
    for i in range(images.shape[0]):
        frame = to_uint8_image(images[i])
        save_png(out / f"turntable_{i:02d}.png", frame)
        frames.append(Image.fromarray(frame))
    with atomic_path(out / "turntable.gif") as tmp:
        frames[0].save(tmp, format="GIF", save_all=True, append_images=frames[1:], duration=120, loop=0)


@torch.no_grad()
def write_outputs(
    out: Path,
    generator: TextureGenerator,
    shape: PreparedShape,
    result: TransferResult,
    photo: Photo,
    view: FramedView,
    photo_noc: torch.Tensor | None,
    distance: float,
    fov: float,
    elevation: float,
    cfg: TransferConfig,
    device: torch.device,
    target: BakeTarget | None = None,
) -> tuple[dict[str, str], dict]:
    """textured.glb/.ply (the user's mesh ``target``, or the prepared shape when None), comparison.png,
    turntable frames and GIF; returns ({what: file name}, what the report says of the mesh written)."""
    batch = collate_shapes([shape]).to(device)
    texture = generator.synthesize(batch, result.ws.to(device), noise_mode="none")
    written = write_textured_mesh(
        out / "textured.glb",
        out / "textured.ply",
        generator,
        texture,
        batch,
        cfg.texture_size,
        cfg.texture_format,
        target,
    )
    save_comparison(out, photo, result.render, view, photo_noc)

    k = cfg.turntable_frames
    azimuths, elevations = turntable_angles(k, elevation)
    mvp = orbit_camera(azimuths, elevations, distance=distance, fov=fov).mvp.to(device)
    lights = None
    if (
        result.light is not None
    ):  # an albedo texture: the turntable keeps the photo's light where it was relative to the camera
        found = result.light
        direction = orbit_direction(azimuths + found["azimuth_offset"], torch.full((k,), found["elevation"]))
        lights = Lights(direction, torch.full((k,), found["ambient"])).to(device)
    size = cfg.resolution * 2
    views = render_field_views(
        generator,
        batch,
        result.ws.to(device),
        mvp,
        (size, size),
        torch.ones(k, 3, device=device),
        texture=texture,
        noise_mode="none",
        lights=lights,
    )
    save_turntable(out, views.images)
    return OUTPUT_FILES, written


OUTPUT_FILES = {
    "glb": "textured.glb",
    "ply": "textured.ply",
    "comparison": "comparison.png",
    "turntable": "turntable.gif",
}


@torch.no_grad()
def write_automaton_outputs(
    out: Path,
    fit: AutomatonFit,
    photo: Photo,
    view: FramedView,
    photo_noc: torch.Tensor | None,
    distance: float,
    fov: float,
    elevation: float,
    cfg: TransferConfig,
    device: torch.device,
    target: BakeTarget | None = None,
) -> tuple[dict[str, str], dict]:
    """The same files for an automaton fitted to the photo (``--automaton``); its turntable is unlit."""
    written = write_automaton_mesh(
        out / "textured.glb",
        out / "textured.ply",
        fit.model,
        fit.state,
        fit.graph,
        cfg.texture_size,
        cfg.texture_format,
        target=target,
    )
    save_comparison(out, photo, fit.render, view, photo_noc)
    azimuths, elevations = turntable_angles(cfg.turntable_frames, elevation)
    mvp = orbit_camera(azimuths, elevations, distance=distance, fov=fov).mvp.to(device)
    save_turntable(out, render_states(fit.model, fit.state, fit.graph, mvp, cfg.resolution * 2, background=1.0).images)
    return OUTPUT_FILES, written


def output_names(cfg: TransferConfig) -> list[str]:
    """The files the command writes into --out."""
    return [
        "textured.glb",
        "textured.ply",
        "comparison.png",
        "turntable.gif",
        "photo_crop.png",
        "render_at_pose.png",
        "report.json",
    ] + [f"turntable_{i:02d}.png" for i in range(cfg.turntable_frames)]


# -------------------------------------------------------------------------------------------- stage
def build_config(args) -> TransferConfig:
    overrides = config_overrides(
        args,
        computed={  # the ablation switches turn a field off
            "use_noc": False if args.no_noc else None,
            "use_patches": False if args.no_patches else None,
            "refine": False if args.no_refine else None,
            "pose_search": False if args.no_pose_search else None,
        },
    )
    cfg = load_config(TransferConfig, args.config, overrides)
    check_style_sizes(cfg)
    return cfg


def checked_networks(args, cfg: TransferConfig) -> tuple[float, float] | None:
    """The options that name networks, checked before anything is loaded: the pose given (or None: auto),
    and a shipped model's own pose, NOC and (when it has one) mask networks filled in where none is given."""
    pose = parse_pose(args.pose)
    if is_model_name(args.checkpoint):
        args.pose_checkpoint = args.pose_checkpoint or args.checkpoint
        args.noc_checkpoint = args.noc_checkpoint or args.checkpoint
        if not args.mask_checkpoint and model_has(args.checkpoint, "mask"):
            args.mask_checkpoint = args.checkpoint
    if pose is None and not args.pose_checkpoint:
        raise UserError(
            "--pose auto needs --pose-checkpoint (from 'mesh2tex train pose'), or give --pose AZIMUTH,ELEVATION"
        )
    if cfg.use_noc and cfg.use_patches and not args.noc_checkpoint:
        raise UserError("NOC-guided patches need --noc-checkpoint (from 'mesh2tex train noc'); or pass --no-noc")
    return pose


def pose_record(estimate: PoseEstimate, source: str, distance: float, fov: float) -> dict:
    """report.json's ``pose``: the pose used, where it came from, and the network's and the search's figures."""
    searched = estimate.silhouette_iou is not None
    return {
        "azimuth": estimate.azimuth,
        "elevation": estimate.elevation,
        "source": source,
        "distance": distance,
        "fov": fov,
        **(
            {
                "network": list(estimate.network),
                "silhouette_iou": estimate.silhouette_iou,
                "network_silhouette_iou": estimate.network_silhouette_iou,
                # the crease agreement at the pose the silhouettes found and at its half turn (None: not weighed)
                "creases": list(estimate.creases) if estimate.creases else None,
                "turned": estimate.turned,
            }
            if searched
            else {}
        ),
    }


def _fit_texture(
    automaton: bool,
    model,
    shape,
    photo,
    view,
    photo_noc,
    vgg,
    cfg: TransferConfig,
    device: torch.device,
    seconds: dict[str, float],
) -> tuple:
    """The photo's texture on ``shape``: an automaton fitted to it (``automaton``) or the generator's
    transfer; its stages' seconds added to ``seconds``. (the fit or transfer result, {stage: loss curve},
    the photo's light as used or None, the render at the photo's pose (1, 3, R, R))."""
    if automaton:
        fit = fit_automaton(shape, photo, view, photo_noc, vgg, cfg, cfg.automaton, device)
        seconds["automaton"] = fit.seconds
        return fit, {"automaton": fit.losses}, None, fit.render
    result = transfer_texture(model.network, shape, photo, view, photo_noc, vgg, cfg, device, generator_lit=model.lit)
    seconds.update({f"stage_{k}": v for k, v in result.seconds.items()})
    return result, result.losses, result.light, result.render


def _loss_record(curve: list[float]) -> dict:
    """A stage's loss in the report: its first and last values (None when it ran no step) and the curve."""
    return {"first": curve[0] if curve else None, "last": curve[-1] if curve else None, "curve": curve}


def run(args) -> int:
    cfg = build_config(args)
    out = guard_outputs(args.out, output_names(cfg), args.overwrite)
    pose = checked_networks(args, cfg)
    device = select_device(cfg.device)
    torch.manual_seed(cfg.seed)
    started = time.perf_counter()
    seconds: dict[str, float] = {}

    model = load_generator(args.checkpoint, device)
    generator, distance, fov = model.network, model.camera.distance, model.camera.fov
    faces = model.face_count(cfg.faces)
    shape, target = load_shape(
        args.mesh, generator, faces, cfg.seed, up=args.up, uv=args.uv, output_mesh=args.output_mesh
    )
    masked = photo_masks(args.image, args.mask, mask_checkpoint=args.mask_checkpoint)
    seconds["load"] = round(time.perf_counter() - started, 2)

    t = time.perf_counter()
    located = locate_object(masked, shape, args.pose_checkpoint, pose, distance, fov, cfg, device)
    photo, mask_source, estimate = located.photo, located.mask_source, located.estimate
    azimuth, elevation, pose_source = estimate.azimuth, estimate.elevation, estimate.source
    photo_noc = predict_noc(args.noc_checkpoint, photo, device) if args.noc_checkpoint else None
    view = view_at_pose(shape, azimuth, elevation, distance, fov, cfg)
    seconds["pose_and_noc"] = round(time.perf_counter() - t, 2)

    vgg = load_vgg19(cfg.vgg_weights or None, device=device)
    fitted, losses, light, render = _fit_texture(
        args.automaton, model, shape, photo, view, photo_noc, vgg, cfg, device, seconds
    )

    # Judged at the found pose before anything is written: a poor fit is said, and recorded.
    fit_check = check_fit(photo.image, photo.mask, render, view.mask)
    for problem in fit_check.problems:
        warning(f"{args.image}: {problem}")

    t = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    if args.automaton:
        files, written = write_automaton_outputs(
            out, fitted, photo, view, photo_noc, distance, fov, elevation, cfg, device, target
        )
    else:
        files, written = write_outputs(
            out, generator, shape, fitted, photo, view, photo_noc, distance, fov, elevation, cfg, device, target
        )
    if written.get("uv_note"):
        note(f"{args.mesh}: a new UV atlas, as {written['uv_note']}")
    save_png(out / "photo_crop.png", to_uint8_image(photo.image))
    save_png(out / "render_at_pose.png", to_uint8_image(render))
    seconds["outputs"] = round(time.perf_counter() - t, 2)
    seconds["total"] = round(time.perf_counter() - started, 2)
    report = {
        "image": str(args.image),
        "mesh": str(args.mesh),
        "checkpoint": str(args.checkpoint),
        "mask_source": mask_source,
        "pose": pose_record(estimate, pose_source, distance, fov),
        "fit": fit_check.as_dict(),
        "noc_guidance": bool(cfg.use_noc and cfg.use_patches),
        "method": f"automaton fitted to the photo ({cfg.automaton.iters} iterations)" if args.automaton else "transfer",
        "light": light,  # the photo's light as learnt (degrees from the camera, ambient share), None: unlit renders
        # where that light started: the photo's shading across the mesh's folds (pairs > 0) or the prior's middle
        "light_start": getattr(fitted, "light_start", None),
        # the mirror plane the photo was also read across (the axis normal to it), None: not (no plane, or w_mirror 0)
        "mirror": getattr(fitted, "mirror", None),
        "losses": {stage: _loss_record(curve) for stage, curve in losses.items()},
        "seconds": seconds,
        "vgg": {"source": vgg.source, "pretrained": vgg.pretrained},
        "settings": asdict(cfg),
        "files": {**files, "photo_crop": "photo_crop.png", "render_at_pose": "render_at_pose.png"},
        "output_mesh": written,
    }
    write_json(out / "report.json", report)
    print(
        f"textured {args.mesh} after {args.image}: pose az {azimuth:.0f} el {elevation:.0f} ({pose_source}); "
        f"{seconds['total']:.0f} s; {out / 'textured.glb'}, {out / 'report.json'}"
    )
    return 0
