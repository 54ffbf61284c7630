"""Transfer from one photo onto meshes the synthetic world did not make: the mask, the pose and the
texture, against the photo's ground truth and a flat colour.

    python benchmarks/outside_transfer.py --checkpoint chair [--pose-checkpoint P] [--noc-checkpoint N]
        [--category chair] [--poses 4] [--transfers 1] [--latent-iters 60] [--refine-iters 120]
        [--resolution 64] [--photo-size 256] [--out FILE.json] [--variants alpha room clutter far]
        [--first-photo 0] [--no-mask-refine] [--no-mirror] [--meshes NAME ...]
        [--light-start prior] [--no-light-fixed] [--light-ambient A] [--light-truth] [--car-cues]
        [--noc-halfturn] [--crease-halfturn] [--pose-halfturn-tie T] [--mask-passes zoom flip]

``--mask-passes`` names the mask network's looks at each photo (:data:`mesh2tex.transfer.mask.MASK_PASSES`; given
with no name, one look at the whole photo; default ``infer transfer``'s). ``--first-photo K`` skips each
mesh's first K photos (``--poses 4 --first-photo 2``: two fresh cameras per mesh, beside the default run's
two); ``--no-mask-refine`` keeps the picked mask estimate as it is
(``transfer.mask_refine: false``); ``--no-mirror`` leaves the photo unread across the mesh's mirror plane
(``transfer.w_mirror: 0``); the photo's light starts where its shading across the mesh's folds says and stays
there, as ``infer transfer`` does by default: ``--light-start prior`` starts it at the light prior's middle instead
(``transfer.light_start``) and ``--no-light-fixed`` optimises it with the texture (``transfer.light_fixed``); each
transfer's row gives the light found and its error against the photo's (:func:`light_error`); ``--light-truth``
holds the photo's own light, relative to the photo's camera, placed relative to the found one (an oracle row).
``--car-cues`` paints a car's glass and head and tail lights on guessed places (cars are otherwise painted by
height alone, body and wheels: ``height_parts``). ``--noc-halfturn`` judges each photo's true and found pose
against their half turns by the NOC network's map, ``--crease-halfturn`` the true pose against its half turn
by the mesh's creases (``halfturn.py``); ``--pose-halfturn-tie -1`` turns the search's crease check off.
``--meshes`` keeps only the named meshes (their indices, hence their materials and cameras, stay those of the
full run, so the rows compare).

The meshes: the hand-modelled chairs (or cars) of ``benchmarks/world_reference_shapes.py`` and, for
chairs, the stool of ``tests/user_assets.py``, each read as a user's file is (turned y-up, prepared
with the model's hierarchy). Each gets a material of the world's sampler (``sample_material``; parts
guessed by height as in ``outside_generation.py``) and is photographed ``--poses`` times at the
world's query cameras and lights (random azimuth, elevation in the world's range) at
``--photo-size`` px, two ways:

  alpha        a PNG whose alpha channel is the object's mask (the mask is given)
  room         a JPEG (quality 90) of the object in front of a wall over a plank floor, drawn by this
               script (:func:`room`); the mask is estimated as below
  far          a JPEG of the object at the same size at a random place in a room twice the photo's side
               (:func:`far_photo`): a quarter of the photo's area; its mask is estimated as over clutter
               (no transfer is scored on it)
  clutter      a JPEG (quality 90) of the object over a sharp crop of a photograph that neither the
               world nor the mask network's training uses (scikit-image's astronaut, chelsea,
               camera, coins, clock, page); the mask is estimated as ``infer transfer`` estimates
               it when none is given: by the mask network with GrabCut edges when there is one
               (``--mask-checkpoint``, or the shipped model's), else by GrabCut alone

Columns, per variant:

  mask IoU     the estimated mask against the true one (1 for alpha): as infer transfer makes it
               (:func:`mesh2tex.transfer.locate_object`: the estimate whose found pose's silhouette
               matches it best, then GrabCut from the mesh's outline at that pose unless
               ``--no-mask-refine``), and each estimate alone (GrabCut, the network, the network with
               GrabCut edges; room, clutter, far)
  pose error   the azimuth error (degrees, circular) of ``--pose auto`` (the pose network and the
               search ``infer transfer`` runs), median and share within 15 degrees, up to the mesh's
               own symmetries (a round stool with four legs looks the same turned by 90 degrees,
               and its material, laid by height, is the same too: every such pose is right);
               "network" is the pose network's own most likely bin (raw error)
  transfer     for the first ``--transfers`` photos of each mesh: the transfer (``infer transfer``'s
               stages at the given iteration counts, NOC guidance when a NOC network is given) and a
               flat texture of the photo's mean object colour, both rendered with the photo's camera
               and light at the photo's view ("seen") and turned 180 degrees ("unseen"), scored
               against what the photo shows (the photo file as read, at 128 px) and the true material
               rendered alike on the unseen side: low-pass PSNR (Gaussian sigma 3 px) on the pixels
               both cover. Oracle: the true material rendered at the photo's view, against the file
               (what 8-bit and JPEG rounding leave; unseen it is the reference itself).
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT))

SOURCE_LABELS = {
    "estimated (mask network, GrabCut edges)": "network_grabcut",
    "estimated (mask network)": "network",
    "estimated (GrabCut)": "grabcut",
}


def true_light(view):
    """The photo's light (``view.light``, a world direction, and ``view.ambient``) as a ``LightStart``: its
    azimuth relative to the photo's camera, so that a transfer at the found pose holds it where the photo shows it."""
    import math

    from mesh2tex.transfer.light import LightStart

    x, y, z = view.light
    offset = (math.degrees(math.atan2(x, z)) - view.azimuth + 180.0) % 360.0 - 180.0
    return LightStart(offset, math.degrees(math.asin(y)), view.ambient)


def light_angle(a, b) -> float:
    """Degrees between two lights (``LightStart``s) placed relative to the same camera, elevations clamped at 89
    as ``PhotoLight`` renders them. Shading is two-sided (it depends on |n . l|), so a light and its opposite are
    the same light."""
    import math

    from mesh2tex.render import orbit_direction

    a, b = (
        orbit_direction(torch.tensor([float(s.azimuth_offset)]), torch.tensor([min(float(s.elevation), 89.0)]))[0]
        for s in (a, b)
    )
    return round(math.degrees(math.acos(float((a @ b).abs().clamp(max=1.0)))), 1)


def light_error(found: dict, view) -> float:
    """Degrees between the learnt light (``PhotoLight.describe``: relative to the found camera) and the photo's
    (:func:`true_light`: relative to the true camera): the light as the photo shows it, so a pose found turned by
    one of the mesh's symmetries does not count against it."""
    from mesh2tex.transfer.light import LightStart

    return light_angle(LightStart(found["azimuth_offset"], found["elevation"], found["ambient"]), true_light(view))


def main() -> None:
    import cv2

    from mesh2tex.evaluation.compare import ScoreSettings, common_mask, render_for_comparison, score_views
    from mesh2tex.evaluation.surfaces import flat_surface, generator_surface, material_surface, photo_mean_colour
    from mesh2tex.geometry.symmetry import azimuth_symmetries
    from mesh2tex.io.images import save_png
    from mesh2tex.models import MODEL_FILES, is_model_name, load_generator, models_root
    from mesh2tex.nn.pose import azimuth_error, symmetric_azimuth_error
    from mesh2tex.render import RenderSettings

    def shipped_file(name: str, kind: str) -> str | None:
        path = models_root() / name / MODEL_FILES[kind]
        return str(path) if path.is_file() else None

    from halfturn import crease_halfturn, halfturn_errors, print_halfturn
    from outside_generation import height_parts, outside_meshes
    from outside_photos import backdrop, far_photo, room, write_jpeg

    from mesh2tex.nn.batch import collate_shapes
    from mesh2tex.nn.vgg import load_vgg19
    from mesh2tex.photos import estimate_mask
    from mesh2tex.synthetic.world import WorldSpec, sample_material, sample_views
    from mesh2tex.texturing import load_shape
    from mesh2tex.transfer import (
        TransferConfig,
        locate_object,
        photo_masks,
        predict_noc,
        transfer_texture,
        view_at_pose,
    )
    from mesh2tex.transfer.config import LIGHT_STARTS
    from mesh2tex.transfer.fit import check_fit
    from mesh2tex.transfer.mask import DEFAULT_MASK_PASSES, MASK_PASSES, network_probability, refine_with_grabcut

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--checkpoint", default="chair")
    parser.add_argument("--pose-checkpoint")
    parser.add_argument("--noc-checkpoint")
    parser.add_argument(
        "--mask-checkpoint", help="a 'train mask' checkpoint (default: the shipped model's, if it has one)"
    )
    parser.add_argument("--category", default="chair", choices=["chair", "car"])
    parser.add_argument(
        "--variety", default="real", choices=["boxy", "real"], help="the world whose materials and cameras are used"
    )
    parser.add_argument("--poses", type=int, default=4)
    parser.add_argument("--transfers", type=int, default=1)
    parser.add_argument("--latent-iters", type=int, default=60)
    parser.add_argument("--refine-iters", type=int, default=120)
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--photo-size", type=int, default=256)
    parser.add_argument("--images", help="a folder to keep the photos, masks and renders in")
    parser.add_argument("--out", help="write the per-photo rows here (JSON)")
    parser.add_argument(
        "--no-mask-refine", action="store_true", help="keep the picked estimate (no GrabCut from the mesh's outline)"
    )
    parser.add_argument(
        "--no-mirror", action="store_true", help="do not read the photo across the mesh's mirror plane (w_mirror 0)"
    )
    parser.add_argument(
        "--first-photo", type=int, default=0, help="skip the first photos of each mesh (a fresh set of cameras)"
    )
    parser.add_argument(
        "--light-start", default=TransferConfig.light_start, choices=LIGHT_STARTS, help="where the photo's light starts"
    )
    parser.add_argument(
        "--light-fixed",
        action=argparse.BooleanOptionalAction,
        default=TransferConfig.light_fixed,
        help="the light stays where it starts (--no-light-fixed: optimised with the texture)",
    )
    parser.add_argument(
        "--light-ambient",
        type=float,
        default=TransferConfig.light_ambient,
        help="the ambient share the light holds (negative: searched with its direction)",
    )
    parser.add_argument("--light-truth", action="store_true", help="hold the photo's own light (an oracle)")
    parser.add_argument(
        "--car-cues", action="store_true", help="cars: glass and head and tail lights on guessed places (height_parts)"
    )
    parser.add_argument(
        "--noc-halfturn", action="store_true", help="judge each pose and its half turn by the NOC network"
    )
    parser.add_argument(
        "--crease-halfturn", action="store_true", help="judge each true pose and its half turn by the mesh's creases"
    )
    parser.add_argument(
        "--pose-halfturn-tie",
        type=float,
        default=TransferConfig.pose_halfturn_tie,
        help="weigh the found pose's half turn by the creases within this IoU (negative: never)",
    )
    parser.add_argument(
        "--mask-passes",
        nargs="*",
        default=list(DEFAULT_MASK_PASSES),
        choices=MASK_PASSES,
        help="the mask network's passes over each photo (none given: one prediction of the whole photo)",
    )
    parser.add_argument("--meshes", nargs="+", help="only these meshes (names as the rows print them)")
    parser.add_argument(
        "--variants", nargs="+", default=["alpha", "room", "clutter"], choices=["alpha", "room", "clutter", "far"]
    )
    args = parser.parse_args()
    passes = tuple(args.mask_passes)
    device = torch.device("cpu")
    pose_checkpoint = args.pose_checkpoint or (args.checkpoint if is_model_name(args.checkpoint) else None)
    noc_checkpoint = args.noc_checkpoint or (args.checkpoint if is_model_name(args.checkpoint) else None)
    mask_checkpoint = args.mask_checkpoint
    if mask_checkpoint is None and is_model_name(args.checkpoint):
        mask_checkpoint = shipped_file(args.checkpoint, "mask")
    if pose_checkpoint is None:
        parser.error("--pose-checkpoint is needed with a checkpoint file")
    model = load_generator(args.checkpoint, device)
    generator, distance, fov = model.network, model.camera.distance, model.camera.fov
    cfg = TransferConfig(
        resolution=args.resolution,
        latent_iters=args.latent_iters,
        refine_iters=args.refine_iters,
        use_noc=noc_checkpoint is not None,
        mask_refine=not args.no_mask_refine,
        w_mirror=0.0 if args.no_mirror else TransferConfig.w_mirror,
        light_start=args.light_start,
        light_fixed=args.light_fixed,
        light_ambient=args.light_ambient,
        pose_halfturn_tie=args.pose_halfturn_tie,
    )
    vgg = load_vgg19(None, device=device)
    spec = WorldSpec(category=args.category, variety=args.variety)
    folder = Path(args.images) if args.images else Path(tempfile.mkdtemp(prefix="outside-transfer-"))
    folder.mkdir(parents=True, exist_ok=True)
    settings = ScoreSettings()
    rows = []
    for index, (name, path) in enumerate(outside_meshes(args.category, folder)):
        if args.meshes and name not in args.meshes:
            continue
        shape, _ = load_shape(path, generator, model.face_count(), output_mesh="prepared")
        vertices, faces = shape.vertices[0], shape.triangles(0)
        parts = height_parts(vertices, faces, args.category, args.car_cues)
        material = sample_material(spec, np.random.default_rng([7, index]))
        truth = material_surface(vertices, faces, parts, material)
        views = sample_views(spec, 1000 + index, args.poses, query=True)
        turns = azimuth_symmetries(vertices)
        for k, view in enumerate(views):
            if k < args.first_photo:
                continue
            photo_render = render_for_comparison(truth, [view], RenderSettings(args.photo_size, 2))
            rgb = photo_render.rgb[0].permute(1, 2, 0).numpy()
            true_mask = photo_render.mask[0, 0].numpy() > 0.5
            rng = np.random.default_rng([11, index, k])
            # The rendered photo's background is the view's own; re-composite over each backdrop.
            coverage = photo_render.mask[0, 0].numpy()[..., None]
            stem = f"{name}_{k}"
            photos = {"alpha": (folder / f"{stem}.png", rgb)}
            save_png(
                photos["alpha"][0],
                np.concatenate(
                    [(rgb * 255).round().astype(np.uint8), (true_mask * 255).astype(np.uint8)[..., None]], 2
                ),
            )
            for variant, backdrop_rgb in (
                ("room", room(args.photo_size, rng)),
                ("clutter", backdrop(index + k, args.photo_size, rng)),
            ):
                over = rgb * coverage + backdrop_rgb * (1 - coverage)
                photos[variant] = (folder / f"{stem}_{variant}.jpg", over)
                write_jpeg(photos[variant][0], over)
            truths = dict.fromkeys(photos, true_mask)
            if "far" in args.variants:
                over, truths["far"] = far_photo(rgb, coverage, np.random.default_rng([13, index, k]))
                photos["far"] = (folder / f"{stem}_far.jpg", over)
                write_jpeg(photos["far"][0], over)
            for variant, (file, over) in photos.items():
                if variant not in args.variants:
                    continue
                true_mask = truths[variant]
                row = {
                    "mesh": name,
                    "photo": k,
                    "variant": variant,
                    "azimuth": view.azimuth,
                    "elevation": view.elevation,
                }
                if variant != "alpha":
                    as_read = cv2.cvtColor(cv2.imread(str(file)), cv2.COLOR_BGR2RGB)
                    candidates = {"grabcut": estimate_mask(as_read)}
                    if mask_checkpoint:
                        probability = network_probability(mask_checkpoint, as_read, passes=passes)
                        candidates["network"] = probability >= 0.5
                        candidates["network_grabcut"] = refine_with_grabcut(as_read, probability)
                    for label, estimate in candidates.items():
                        row[f"iou_{label}"] = float((estimate & true_mask).sum() / max((estimate | true_mask).sum(), 1))
                else:
                    row["mask_iou"] = 1.0
                # As infer transfer does: the mesh's outline picks among the mask estimates, then (unless
                # --no-mask-refine) GrabCut from that outline makes the mask again and the pose is found again.
                masked = photo_masks(file, None, mask_checkpoint=mask_checkpoint, mask_passes=passes)
                started = time.perf_counter()
                located = locate_object(masked, shape, pose_checkpoint, None, distance, fov, cfg, device)
                photo, estimate = located.photo, located.estimate
                if variant != "alpha":
                    picked = next(
                        label for source, label in SOURCE_LABELS.items() if located.mask_source.startswith(source)
                    )
                    estimated, row["mask_picked"] = located.mask, picked
                    row["mask_iou"] = float((estimated & true_mask).sum() / max((estimated | true_mask).sum(), 1))
                row["pose_seconds"] = round(time.perf_counter() - started, 2)
                row["found"] = [estimate.azimuth, estimate.elevation]
                row["pose_error"] = symmetric_azimuth_error(estimate.azimuth, view.azimuth, turns)
                row["raw_pose_error"] = float(azimuth_error(estimate.azimuth, view.azimuth))
                row["symmetries"] = len(turns)
                row["network_error"] = (
                    float(azimuth_error(estimate.network[0], view.azimuth)) if estimate.network else None
                )
                if args.noc_halfturn and noc_checkpoint:
                    camera = (distance, fov, cfg, device)
                    row.update(halfturn_errors(noc_checkpoint, photo, shape, estimate, view.azimuth, *camera))
                if args.crease_halfturn:
                    row.update(crease_halfturn(photo, shape, view.azimuth, view.elevation, distance, fov, cfg))
                row["turned"], row["creases"] = estimate.turned, estimate.creases
                if k - args.first_photo < args.transfers and variant != "far":  # far: no framed reference
                    photo_noc = predict_noc(noc_checkpoint, photo, device) if noc_checkpoint else None
                    framed = view_at_pose(shape, estimate.azimuth, estimate.elevation, distance, fov, cfg)
                    torch.manual_seed(0)
                    candidate = copy.deepcopy(generator)
                    result = transfer_texture(
                        candidate,
                        shape,
                        photo,
                        framed,
                        photo_noc,
                        vgg,
                        cfg,
                        device,
                        show_progress=False,
                        generator_lit=model.lit,
                        known_light=true_light(view) if args.light_truth else None,
                    )
                    batch = collate_shapes([shape])
                    fit = check_fit(photo.image, photo.mask, result.render, framed.mask)
                    row["fit_poor"], row["fit_iou"] = fit.poor, fit.silhouette_iou
                    row["mirror"], row["transfer_seconds"] = result.mirror, round(sum(result.seconds.values()), 1)
                    if result.light is not None:
                        row["light"] = result.light
                        row["light_error"] = light_error(result.light, view)
                    with torch.no_grad():
                        texture = candidate.synthesize(batch.to(device), result.ws.to(device), noise_mode="none")
                    judged = [view, dataclasses.replace(view, azimuth=(view.azimuth + 180.0) % 360.0)]
                    side = 128
                    reference = render_for_comparison(truth, judged, RenderSettings(side, 2))
                    # At the photo's view the reference is the photo file as the transfer read it (8-bit, JPEG for
                    # the backdrop variant): the oracle row is then the truth against that file, finite.
                    as_read = cv2.cvtColor(cv2.imread(str(file)), cv2.COLOR_BGR2RGB)
                    as_read = cv2.resize(as_read, (side, side), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
                    reference_rgb = reference.rgb.clone()
                    reference_rgb[0] = torch.from_numpy(as_read).permute(2, 0, 1)
                    photo_mask = torch.from_numpy(true_mask if variant == "alpha" else estimated).float()
                    flat_colour = photo_mean_colour(torch.from_numpy(over).permute(2, 0, 1).float(), photo_mask)
                    methods = {
                        "oracle": reference,
                        "transfer": render_for_comparison(
                            generator_surface(generator, texture, batch), judged, RenderSettings(side, 2)
                        ),
                        "flat": render_for_comparison(
                            flat_surface(vertices, faces, flat_colour), judged, RenderSettings(side, 2)
                        ),
                    }
                    mask = common_mask(reference.mask, methods["flat"].mask)
                    for method, rendered in methods.items():
                        scores = score_views(rendered, reference_rgb, reference.parts, mask, settings)["lowpass_psnr"]
                        row[f"{method} seen"], row[f"{method} unseen"] = (
                            scores[0],
                            (scores[1] if method != "oracle" else None),
                        )
                    save_png(
                        folder / f"{stem}_{variant}_transfer.png",
                        (
                            torch.cat([reference.rgb, methods["transfer"].rgb], 3)
                            .permute(0, 2, 3, 1)
                            .reshape(-1, 2 * side, 3)
                            .numpy()
                            * 255
                        )
                        .round()
                        .astype(np.uint8),
                    )
                rows.append(row)
                print(json.dumps({k: (round(v, 2) if isinstance(v, float) else v) for k, v in row.items()}), flush=True)
    print(
        f"\n{len({r['mesh'] for r in rows})} {args.category} meshes from outside the world, {args.poses} photos each; "
        f"checkpoint {args.checkpoint}, pose {pose_checkpoint}, NOC {noc_checkpoint}"
    )
    for variant in [v for v in ("room", "clutter", "far") if v in args.variants]:
        chosen = [r for r in rows if r["variant"] == variant]
        print(
            f"mask IoU, {variant}: "
            + ", ".join(
                f"{k[4:]} {np.mean([r[k] for r in chosen]):.3f} (worst {np.min([r[k] for r in chosen]):.3f})"
                for k in chosen[0]
                if k.startswith("iou_")
            )
        )
    print(
        f"{'variant':12s} {'mask IoU':>9s} {'pose err median':>15s} {'<=15 deg':>8s} {'network median':>14s}"
        f" {'poor fit':>8s} {'transfer seen':>13s} {'flat seen':>9s} {'transfer unseen':>15s} {'flat unseen':>11s} "
        f"{'oracle seen':>11s}"
    )
    for variant in args.variants:
        chosen = [r for r in rows if r["variant"] == variant]
        judged = [r for r in chosen if "transfer seen" in r]

        def mean(key):
            return float(np.mean([r[key] for r in judged])) if judged else float("nan")

        print(
            f"{variant:12s} {np.mean([r['mask_iou'] for r in chosen]):9.3f} "
            f"{np.median([r['pose_error'] for r in chosen]):15.1f} "
            f"{np.mean([r['pose_error'] <= 15 for r in chosen]):8.2f} "
            f"{np.median([r['network_error'] for r in chosen]):14.1f} "
            f"{mean('fit_poor'):8.2f} {mean('transfer seen'):13.2f} {mean('flat seen'):9.2f} "
            f"{mean('transfer unseen'):15.2f} {mean('flat unseen'):11.2f} {mean('oracle seen'):11.2f}"
        )
    print_halfturn(rows, args.variants)
    if args.out:
        Path(args.out).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
