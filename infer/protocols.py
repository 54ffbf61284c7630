"""The evaluation protocols of the Mesh2Tex paper, run on a synthetic world and trained checkpoints.

    mesh2tex evaluate --protocols --world WORLD --shapes SHAPES --gan GAN --pose-checkpoint P
                      --noc-checkpoint N --out DIR [--latent-iters N] [--refine-iters N] [--queries K]

A world from ``mesh2tex prepare synthetic`` holds photos of training shapes (``images/``, ``masks/``)
and held-out query photos (``queries/``) whose JSON sidecars give the true pose and source shape.
``SHAPES`` holds the prepared shapes (``<name>.npz``, from ``mesh2tex prepare shapes``) of the query
shapes and of any other shape used as a transfer target.

Protocols (names as in ``protocols.json``):

``unconditional`` (paper Table 1)
    The GAN's textures for random latents on the held-out query shapes, ``views`` orbit views each
    (elevations across the world's range), on white, against the world's photos (object on white):
    KID/FID on named features, SWD, pooled colour-histogram distance.
``known_pose`` (Tables 2-3): exact geometry, known pose
    Each query photo textures its own shape, seen at the sidecar's pose, distance and field of view.
``unknown_pose`` (Tables 4-5, 8): exact geometry, unknown pose
    As ``known_pose``, but the pose comes from the pose network and the distance and field of view
    from the GAN's camera, as ``infer transfer --pose auto`` does.
``other_shape`` (Tables 6-7): transfer to another shape of the category
    The query photo textures a different shape (the next prepared shape by name), at the pose the
    pose network predicts.

Each transfer protocol runs every ablation of Table 8 on the same queries with the same seeds:
``full``, ``no_noc`` (patch pairs without NOC guidance), ``no_patches`` (global style loss only) and
``no_refine`` (latent only, "w/o surface features"), and beside them the simple baselines
(:data:`BASELINES`): the ground-truth texture itself (``oracle``, the world's ``textured/`` GLB),
the photo's mean colour everywhere (``flat_colour``), the generator's mean texture (``mean_texture``,
``w_avg``, no optimisation) and the photo back-projected onto the mesh from the pose the transfer
used (``backprojection``).

Every method is judged alike (:mod:`mesh2tex.evaluation`): a textured surface rendered by one
function with the photo's camera, light and background (``lighting: albedo`` renders all unlit), at
the photo's view ("seen") and ``unseen_views`` views the photo does not show (the same camera
turned about the vertical axis), against what the world photographs there (the query photo, then
the world's own renders of the query shape). Scores per query and view side
(``mesh2tex.evaluation.METRICS``): per-part CIELAB colour error (parts by the world's labels),
low-pass PSNR (Gaussian blur of ``lowpass_sigma`` px), SWD on object patches, and PSNR / SSIM on
the object mask. Exact geometry (``known_pose``, ``unknown_pose``) is scored on the pixels both the
world's shape and the prepared one cover; ``other_shape`` (the texture on another shape, seen
through the query's cameras) has per-part colour error (parts matched by label) and SWD only, and
its oracle is the query shape's own material on the other shape. The oracle must win every column
(``oracle_check``); the full method is compared with every other method query by query (wins and
Wilcoxon signed-rank p-values).

The paper measures CLIP similarity and LPIPS, which need downloaded weights; the metrics above need
none (KID/FID of the unconditional protocol use Inception only when its weights are on disk, else
features named for what they are).
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import shutil
import sys
import time
import warnings
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import torch

from mesh2tex.errors import UserError
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.io.atomic import write_json, write_text
from mesh2tex.io.images import save_png
from mesh2tex.metrics import to_unit

PROTOCOLS = ("unconditional", "known_pose", "unknown_pose", "other_shape")
TRANSFER_PROTOCOLS = PROTOCOLS[1:]
# Ablation name -> the TransferConfig fields it changes (paper Table 8).
ABLATIONS = {
    "full": {},
    "no_noc": {"use_noc": False},
    "no_patches": {"use_patches": False},
    "no_refine": {"refine": False},
}
# The simple methods beside every transfer (none optimises anything): the ground truth itself, the
# photo's mean colour everywhere, the generator's mean texture (w_avg), and the photo back-projected.
BASELINES = ("oracle", "flat_colour", "mean_texture", "backprojection")
LOWER_IS_BETTER = ("kid", "fid", "swd", "color_hist_tv")
HIGHER_IS_BETTER = ("psnr_masked", "ssim_masked")


@dataclass
class ProtocolConfig:
    protocols: list[str] = field(default_factory=lambda: list(PROTOCOLS))  # which protocols to run
    ablations: list[str] = field(default_factory=lambda: list(ABLATIONS))  # which ablations of each transfer protocol
    queries: int = 0  # query photos used (first K in the world's order; 0: all)
    resolution: int = 64  # side of the photo crops, renders and set-metric images
    latent_iters: int = 100  # transfer stage 1 iterations (paper: 100)
    refine_iters: int = 300  # transfer stage 2 iterations (paper: 300)
    patch_size: int = 32  # style patch side at ``resolution`` (paper: 64 px patches in larger crops)
    scales: int = 2  # style-loss pyramid levels (paper: 3; 2 keeps a 16 px coarsest level for 32 px patches)
    patch_scales: int = 0  # pyramid levels of the patch loss alone (0: ``scales``)
    pose_search: bool = True  # unknown_pose, other_shape: silhouette search around the pose network's answer (as infer transfer)
    baselines: list[str] = field(default_factory=lambda: list(BASELINES))  # simple methods judged beside the transfers
    lighting: str = "photo"  # render every method with the photo's light ('photo') or unlit, as albedo ('albedo')
    unseen_views: int = 4  # views the photo does not show, evenly spaced in azimuth after the photo's
    lowpass_sigma: float = 3.0  # Gaussian blur of the low-pass PSNR, in pixels of the world's photos
    latents: int = 4  # unconditional: random latents per held-out shape
    views: int = 6  # unconditional: orbit views per latent (paper: 6)
    features: str = "auto"  # KID/FID features: auto, inception, tvinception, vgg or randvgg
    kid_subsets: int = 100  # KID random subsets
    seed: int = 0  # seed of the transfers, the unconditional latents and the set metrics
    device: str = "auto"  # auto, cpu or cuda
    vgg_weights: str = ""  # VGG19 ImageNet weights for the style losses ('' looks in $TORCH_HOME)
    inception_weights: str = ""  # Inception-v3 weights for KID/FID ('' looks in $TORCH_HOME)


@dataclass
class Query:
    """One held-out query photo of the world and its ground truth."""

    name: str  # file stem, e.g. chair_0004_00
    image: Path
    mask: Path
    shape: str  # the world shape it shows
    azimuth: float
    elevation: float
    distance: float
    fov: float
    record: dict = field(default_factory=dict)  # the sidecar (camera, light, background, files)


@dataclass
class World:
    root: Path
    index: dict
    queries: list[Query]
    query_shapes: list[str]


# ------------------------------------------------------------------------------------------- inputs
def load_world(root: str | Path, max_queries: int = 0) -> World:
    """The world's index and its query photos (first ``max_queries``; 0: all) with their sidecar poses."""
    root = Path(root)
    index_path = root / "index.json"
    if not index_path.is_file():
        raise UserError(f"{root}: not a synthetic world (no index.json; make one with 'mesh2tex prepare synthetic')")
    try:
        index = json.loads(index_path.read_text())
    except json.JSONDecodeError as error:
        raise UserError(f"{index_path}: not valid JSON ({error.msg})") from None
    if index.get("format") != "mesh2tex-synthetic-world":
        raise UserError(f"{index_path}: not a mesh2tex synthetic world index (format {index.get('format')!r})")
    if not index.get("complete", False):
        raise UserError(f"{root}: the world is incomplete; finish it with 'mesh2tex prepare synthetic' (it resumes)")
    entries = index.get("queries") or []
    if not entries:
        raise UserError(f"{index_path}: the world has no query photos (prepare it with --query-views above 0)")
    queries = []
    for entry in entries:
        sidecar = root / entry["sidecar"] if "sidecar" in entry else None
        truth = json.loads(sidecar.read_text()) if sidecar is not None and sidecar.is_file() else entry
        image, mask = root / entry["image"], root / entry["mask"]
        for path in (image, mask):
            if not path.is_file():
                raise UserError(f"{path}: query file missing (listed in {index_path})")
        queries.append(Query(name=image.stem, image=image, mask=mask, shape=truth["shape"],
                             azimuth=float(truth["azimuth"]), elevation=float(truth["elevation"]),
                             distance=float(truth["distance"]), fov=float(truth["fov"]), record=truth))
    if max_queries > 0:
        queries = queries[:max_queries]
    query_shapes = list(dict.fromkeys(q.shape for q in queries))
    return World(root=root, index=index, queries=queries, query_shapes=query_shapes)


def shape_paths(folder: str | Path) -> dict[str, Path]:
    """{name: path} of the prepared shapes (.npz) in ``folder``, sorted by name."""
    folder = Path(folder)
    if not folder.is_dir():
        raise UserError(f"{folder}: prepared-shape folder not found (make it with 'mesh2tex prepare shapes')")
    found = {p.stem: p for p in sorted(folder.glob("*.npz"))}
    if not found:
        raise UserError(f"{folder}: no prepared shapes (.npz)")
    return found


def other_shape_name(name: str, available: list[str]) -> str:
    """The transfer target for a query of shape ``name``: the next available shape by name (cyclic), never ``name``."""
    others = sorted(set(available) - {name})
    if not others:
        raise UserError(f"transfer to another shape needs a second prepared shape besides {name}")
    later = [n for n in others if n > name]
    return later[0] if later else others[0]


def on_white(images: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
    """images [N,3,H,W] in [0,1], masks [N,1,H,W] {0,1} -> the object on white."""
    return images * masks + (1.0 - masks)


# ---------------------------------------------------------------------------------- unconditional
@torch.no_grad()
def unconditional_renders(generator, shapes: list[PreparedShape], latents: int, views: int, resolution: int,
                          distance: float, fov: float, elevations: tuple[float, float], seed: int,
                          device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """Renders [len(shapes) * latents * views, 3, R, R] in [0, 1] on white of random latents, and
    their object masks [same N, 1, R, R] (0/1).

    Views of one latent: azimuths evenly spaced (offset by the latent), elevations evenly across
    ``elevations`` (degrees); latent seeds ``seed * 1000 + k``.
    """
    from infer.generate import latent
    from mesh2tex.nn.batch import collate_shapes
    from mesh2tex.nn.render_texture import render_field_views
    from mesh2tex.render import orbit_camera

    renders, masks = [], []
    for s, shape in enumerate(shapes):
        batch = collate_shapes([shape]).to(device)
        encoded = generator.encoder(batch)
        for k in range(latents):
            ws = latent(generator, seed * 1000 + s * latents + k, device)
            azimuth = (torch.arange(views, dtype=torch.float32) + k / max(latents, 1)) * (360.0 / views)
            elevation = torch.linspace(elevations[0], elevations[1], views) if views > 1 else torch.tensor([sum(elevations) / 2])
            mvp = orbit_camera(azimuth, elevation, distance=distance, fov=fov).mvp.to(device)
            out = render_field_views(generator, batch, ws, mvp, (resolution, resolution), torch.ones(views, 3, device=device),
                                     encoded=encoded, noise_mode="none")
            renders.append(to_unit(out.images.float()).clamp(0, 1).cpu())
            masks.append(out.mask.float().cpu())
    return torch.cat(renders), torch.cat(masks)


def run_unconditional(generator, world: World, shapes: dict[str, PreparedShape], cfg: ProtocolConfig, extractor,
                      eval_cfg, distance: float, fov: float, device: torch.device, out: Path | None) -> dict:
    """Protocol ``unconditional``: GAN renders on the held-out shapes against the world's photos."""
    from infer.evaluate import evaluate_sets, list_images, load_set

    start = time.perf_counter()
    settings = world.index.get("settings", {})
    elevations = (float(settings.get("elevation_min", 5.0)), float(settings.get("elevation_max", 35.0)))
    held_out = [shapes[name] for name in world.query_shapes]
    renders, render_masks = unconditional_renders(generator, held_out, cfg.latents, cfg.views, cfg.resolution, distance, fov,
                                                  elevations, cfg.seed, device)
    photos, photo_masks = load_set(world.root / "images", "image", cfg.resolution, 1.0, masks=list_images(world.root / "masks", "mask"))
    result = evaluate_sets(renders, photos, extractor, eval_cfg, render_masks, photo_masks)
    if out is not None:
        folder = out / "renders" / "unconditional"
        folder.mkdir(parents=True, exist_ok=True)
        for i, image in enumerate(renders[: cfg.views * cfg.latents]):
            save_png(folder / f"{world.query_shapes[0]}_{i:02d}.png", _uint8(image))
    return {"shapes": world.query_shapes, "reference": str(world.root / "images"), **result,
            "seconds": round(time.perf_counter() - start, 2)}


# -------------------------------------------------------------------------------------- transfers
@torch.no_grad()
def photo_frame_view(shape: PreparedShape, query: Query, resolution: int, margin: float):
    """The query's true camera, framed like its photo crop: an ``infer.transfer.View`` whose render,
    cropped with the photo's own box, is pixel-aligned with the cropped photo (exact geometry).

    Its ``mask`` (1,1,R,R) is where the shape covers the crop; its ``noc`` is left empty.
    """
    from infer.transfer import View
    from mesh2tex.io.images import load_mask
    from mesh2tex.render import crop_mask, object_box, orbit_camera, rasterize, transform_points

    photo_mask = np.asarray(load_mask(query.mask), dtype=bool)
    side = photo_mask.shape[0]
    if photo_mask.shape[1] != side:
        raise UserError(f"{query.mask}: query photos must be square to be framed like renders, got {photo_mask.shape[1]}x{side}")
    box = object_box(photo_mask, margin)
    camera = orbit_camera(torch.tensor([query.azimuth]), torch.tensor([query.elevation]), distance=query.distance, fov=query.fov)
    vertices = torch.as_tensor(shape.vertices[0], dtype=torch.float32)
    raster = rasterize(transform_points(vertices, camera.mvp), torch.as_tensor(shape.triangles(0)), (side, side))
    mask = crop_mask(raster.face_id[0] >= 0, box, resolution)
    return View(mvp=camera.mvp, render_size=side, box=box, noc=torch.zeros(resolution, resolution, 3), mask=mask)


@torch.no_grad()
def render_at_view(generator, shape: PreparedShape, ws: torch.Tensor, view, resolution: int, device: torch.device) -> torch.Tensor:
    """The texture of ``ws`` on ``shape`` seen at ``view`` (infer.transfer.View), cropped by its box: [1,3,R,R] in [-1,1]."""
    from mesh2tex.render import crop_square
    from mesh2tex.nn.batch import collate_shapes
    from mesh2tex.nn.render_texture import render_field_views

    batch = collate_shapes([shape]).to(device)
    size = (view.render_size, view.render_size)
    full = render_field_views(generator, batch, ws.to(device), view.mvp.to(device), size, torch.zeros(1, 3, device=device),
                              noise_mode="none").images
    return crop_square(full.float(), view.box, resolution).cpu()


def run_transfer_protocol(protocol: str, generator, world: World, shapes: dict[str, PreparedShape], targets: dict[str, str],
                          vgg, cfg: ProtocolConfig,
                          pose_checkpoint: str | Path | None, noc_checkpoint: str | Path | None,
                          distance: float, fov: float, device: torch.device, out: Path | None, log=print,
                          cache: "TransferCache | None" = None) -> dict:
    """One transfer protocol (``known_pose``, ``unknown_pose`` or ``other_shape``): the baselines of
    ``cfg.baselines`` and every ablation of ``cfg.ablations``, judged alike.

    Every method is a textured surface rendered by ``mesh2tex.evaluation.render_for_comparison`` at
    the photo's view and ``cfg.unseen_views`` views it does not show, with the photo's light and
    background (``cfg.lighting``), against what the world photographs there (the query photo, then
    the world's own renders). ``shapes``: the prepared shapes by name; ``targets``: query shape ->
    the shape ``other_shape`` textures; ``cache``: finished transfers are stored there and reused.

    Returns {"queries": [per-query setup], "methods": {name: {"query": mean scores, "per_query":
    [rows], "seconds": s}}}; scores are named "seen <metric>" and "unseen <metric>".
    """
    from infer.transfer import TransferConfig, estimate_pose, load_photo, predict_noc, transfer_texture, view_at_pose
    from mesh2tex.evaluation import (ComparisonRender, ScoreSettings, backproject_photo, common_mask, flat_surface,
                                     generator_surface, other_views, photo_mean_colour, render_for_comparison, score_views,
                                     seen_and_unseen)
    from mesh2tex.evaluation.world import load_query_truth, load_shape_truth, reference_renders
    from mesh2tex.nn.batch import collate_shapes
    from mesh2tex.nn.pose import azimuth_error

    base = TransferConfig(resolution=cfg.resolution, latent_iters=cfg.latent_iters, refine_iters=cfg.refine_iters,
                          patch_size=cfg.patch_size, scales=cfg.scales, patch_scales=cfg.patch_scales, seed=cfg.seed,
                          pose_search=cfg.pose_search, device=str(device), vgg_weights=cfg.vgg_weights)
    exact = protocol in ("known_pose", "unknown_pose")
    settings = ScoreSettings(lowpass_sigma=cfg.lowpass_sigma, seed=cfg.seed)
    offsets = [360.0 * k / (cfg.unseen_views + 1) for k in range(1, cfg.unseen_views + 1)]
    methods = {name: {"per_query": [], "seconds": 0.0} for name in (*cfg.baselines, *cfg.ablations)}
    setups = []
    for q, query in enumerate(world.queries):
        photo, _ = load_photo(query.image, query.mask, base)
        photo_noc = predict_noc(noc_checkpoint, photo, device) if noc_checkpoint else None
        target = query.shape if exact else targets[query.shape]
        shape = shapes[target]
        network_pose = None
        if protocol == "known_pose":
            azimuth, elevation, dist, view_fov = query.azimuth, query.elevation, query.distance, query.fov
        else:
            estimate = estimate_pose(pose_checkpoint, shape, photo, distance, fov, base, device)
            azimuth, elevation, network_pose = estimate.azimuth, estimate.elevation, estimate.network
            dist, view_fov = distance, fov
        view = view_at_pose(shape, azimuth, elevation, dist, view_fov, base)
        setups.append({"query": query.name, "shape": target, "azimuth": round(azimuth, 3), "elevation": round(elevation, 3),
                       "true_azimuth": query.azimuth, "true_elevation": query.elevation,
                       "azimuth_error": round(float(azimuth_error(azimuth, query.azimuth)), 3),
                       "elevation_error": round(abs(elevation - query.elevation), 3)})
        if network_pose is not None and cfg.pose_search:
            setups[-1]["network_azimuth_error"] = round(float(azimuth_error(network_pose[0], query.azimuth)), 3)

        # The ground truth, and one render function for every method.
        try:
            truth = load_query_truth(world.root, world.index, query.record)
            target_truth = truth.truth if exact else load_shape_truth(world.root, world.index, target)
        except ValueError as error:
            raise UserError(str(error)) from None
        views = [truth.view] + other_views(truth.view, offsets)
        size = truth.resolution

        def render(surface):
            return render_for_comparison(surface, views, size, lighting=cfg.lighting)

        reference = reference_renders(truth, views, cfg.lighting)
        oracle = render(truth.truth.oracle if exact else truth.truth.material_on(target_truth))
        vertices, triangles = shape.vertices[0], shape.triangles(0)
        batch = collate_shapes([shape])
        flat = render(flat_surface(vertices, triangles, photo_mean_colour(truth.photo[0], truth.photo_mask[0])))
        # Exact geometry: every method on the pixels both the world's shape and the prepared one cover, with
        # the world's part labels. Another shape: each image on its own object pixels, parts by label.
        mask = common_mask(reference.mask, flat.mask) if exact else common_mask(flat.mask, oracle.mask)

        def score(rendered) -> dict:
            if exact:
                scores = score_views(rendered, reference.rgb, reference.parts, mask, settings)
            else:
                scores = score_views(ComparisonRender(rendered.rgb, mask, oracle.parts), reference.rgb, reference.parts, mask,
                                     settings, reference_mask=reference.mask)
            return {k: round(v, 5) for k, v in seen_and_unseen(scores).items()}

        def keep(name: str, rendered, row: dict) -> None:
            row = {"query": query.name, **score(rendered), **row}
            methods[name]["per_query"].append(row)
            methods[name]["seconds"] += row.get("seconds", 0.0)
            if out is not None:
                folder = out / "renders" / protocol / name
                folder.mkdir(parents=True, exist_ok=True)
                save_png(folder / f"{query.name}.png", _strip(rendered.rgb))
            log(f"{protocol} {q + 1}/{len(world.queries)} {query.name} -> {target} {name}: "
                + ", ".join(f"{k} {row[k]:.4g}" for k in ("seen part_delta_e", "unseen part_delta_e", "seen lowpass_psnr") if k in row)
                + (f" ({row['seconds']:.0f} s)" if "seconds" in row else ""))

        if out is not None:
            (out / "renders" / protocol).mkdir(parents=True, exist_ok=True)
            save_png(out / "renders" / protocol / f"{query.name}_reference.png", _strip(reference.rgb))
        for name in cfg.baselines:
            start = time.perf_counter()
            if name == "oracle":
                rendered = oracle
            elif name == "flat_colour":
                rendered = flat
            elif name == "mean_texture":
                with torch.no_grad():
                    ws = generator.mapping.w_avg.reshape(1, 1, -1).expand(1, generator.num_ws, -1).to(device)
                    features = generator.synthesize(batch.to(device), ws, noise_mode="none").field_features
                rendered = render(generator_surface(generator, features, batch))
            else:  # backprojection: the photo painted on from the pose the transfer used, framed as the transfer frames it
                try:
                    surface = backproject_photo(vertices, triangles, truth.photo[0], truth.photo_mask[0, 0], azimuth, elevation,
                                                dist, view_fov, align="photo" if protocol == "known_pose" else "silhouette",
                                                margin=base.margin)
                except ValueError as error:
                    raise UserError(f"{query.image}: {error}") from None
                rendered = render(surface)
            keep(name, rendered, {"seconds": round(time.perf_counter() - start, 2)})

        for ablation in cfg.ablations:
            tcfg = replace(base, **ABLATIONS[ablation])
            guided = tcfg.use_noc and tcfg.use_patches
            if guided and photo_noc is None:
                raise UserError(f"ablation {ablation} uses NOC-guided patches: give --noc-checkpoint")
            cached = cache.load(protocol, ablation, query.name) if cache is not None else None
            if cached is not None:  # made by an earlier run into this folder with the same settings
                features, row = cached
            else:
                torch.manual_seed(cfg.seed)
                candidate = copy.deepcopy(generator)  # stage 2 changes the generator's weights
                result = transfer_texture(candidate, shape, photo, view, photo_noc if guided else None, vgg, tcfg, device,
                                          show_progress=False)
                with torch.no_grad():
                    features = candidate.synthesize(batch.to(device), result.ws.to(device), noise_mode="none").field_features.cpu()
                row = {"loss_last": {k: v[-1] for k, v in result.losses.items() if v}, "seconds": round(sum(result.seconds.values()), 2)}
                if cache is not None:
                    cache.save(protocol, ablation, query.name, features, row)
            # Stage 2 refines synthesis blocks only: psi is the original's, so the face features are the whole result.
            keep(ablation, render(generator_surface(generator, features, batch)), dict(row))
    for entry in methods.values():
        entry["query"] = mean_scores(entry["per_query"])
        entry["seconds"] = round(entry["seconds"], 2)
    return {"queries": setups, "methods": methods}


def mean_scores(rows: list[dict]) -> dict[str, float]:
    """Mean over the rows (queries) of every score column ('seen ...', 'unseen ...'), NaNs skipped."""
    columns = [k for k in (rows[0] if rows else {}) if k.startswith(("seen ", "unseen "))]
    means = {}
    for column in columns:
        values = [r[column] for r in rows if column in r and isinstance(r[column], (int, float)) and not math.isnan(r[column])]
        if values:
            means[column] = sum(values) / len(values)
    return means


def _strip(images: torch.Tensor) -> np.ndarray:
    """[B, 3, R, R] in [0, 1] -> one (R, B*R + 2*(B-1), 3) uint8 image, the views side by side."""
    tiles = [_uint8(image) for image in images]
    gap = np.full((tiles[0].shape[0], 2, 3), 255, dtype=np.uint8)
    return np.concatenate([t for tile in tiles for t in (tile, gap)][:-1], axis=1)


# ------------------------------------------------------------------------------------------ resume
class TransferCache:
    """Finished transfers of protocol runs into one folder: an interrupted run resumes where it stopped,
    and a run with more queries or ablations redoes none of the transfers already made.

    ``DIR/transfers/<protocol>/<ablation>/<query>.npz`` holds the result of one transfer, the
    generator's face features [F_0, C] (float32; with the unchanged psi they are the whole texture, so
    the evaluation can be redone with other metrics, views or lighting without redoing the transfer),
    and its row (JSON: last losses, seconds); ``DIR/transfers/settings.json`` what they were made
    with: every setting that changes a transfer (not the choice of protocols, ablations or number of
    queries) and the digests of the checkpoints. Transfers made with other settings are never mixed
    in: the run is refused, or with ``--overwrite`` they are discarded. Because each transfer is its
    own file, a long run can be split across processes into the same folder (``--ablations full``
    in one, ``--ablations no_noc`` in another...); one more run with every ablation then only builds
    the tables.
    """

    def __init__(self, out: Path, fingerprint: dict, overwrite: bool = False):
        self.root = out / "transfers"
        settings = self.root / "settings.json"
        if settings.is_file() and json.loads(settings.read_text()) != fingerprint:
            if not overwrite:
                raise UserError(f"{out}: holds transfers made with other settings or checkpoints ({settings}); "
                                "use the same settings to reuse them, or pass --overwrite to discard them")
            shutil.rmtree(self.root)
        if not settings.is_file():
            write_json(settings, fingerprint)

    def _path(self, protocol: str, ablation: str, query: str) -> Path:
        return self.root / protocol / ablation / f"{query}.npz"

    def load(self, protocol: str, ablation: str, query: str) -> tuple[torch.Tensor, dict] | None:
        """(face features [F_0, C], row) of a finished transfer, or None (also for a file of an older
        layout, which kept only a render: that transfer is made again)."""
        path = self._path(protocol, ablation, query)
        if not path.is_file():
            return None
        with np.load(path, allow_pickle=False) as data:
            if "field_features" not in data:
                return None
            return torch.from_numpy(data["field_features"]), json.loads(str(data["row"]))

    def save(self, protocol: str, ablation: str, query: str, field_features: torch.Tensor, row: dict) -> None:
        from mesh2tex.io.atomic import atomic_path

        with atomic_path(self._path(protocol, ablation, query)) as tmp:
            np.savez(tmp, field_features=field_features.detach().float().cpu().numpy(), row=np.array(json.dumps(row)))


# ------------------------------------------------------------------------------------- comparison
def metric_direction(name: str) -> int:
    """+1 if higher is better, -1 if lower is better, 0 for values that are not scores (spreads, levels).

    Transfer columns are named '<seen|unseen> <metric>' (``mesh2tex.evaluation.METRICS``); the
    unconditional protocol's set metrics by their own names (kid_*, fid_*, swd, color_hist_tv)."""
    from mesh2tex.evaluation import METRICS

    if name.endswith("_std") or (name.startswith("swd_") and name.endswith("px")):
        return 0
    last = name.split(" ")[-1]
    if " " in name and last in METRICS:
        return METRICS[last]
    if name in HIGHER_IS_BETTER:
        return 1
    base = name.split("_")[0]
    return -1 if base in ("kid", "fid", "swd") or name == "color_hist_tv" else 0


def scored_metrics(entry: dict) -> dict[str, float]:
    """{column: mean value} of one method's scores that rank methods (finite values only)."""
    return {name: float(value) for name, value in entry.get("query", {}).items()
            if metric_direction(name) != 0 and isinstance(value, (int, float)) and math.isfinite(value)}


def compare_to_full(methods: dict) -> dict:
    """For every other method (ablation or baseline): per column whether the full method's mean is
    better, the count of wins, and the paired view of the same queries (``query_wins``: [full better,
    queries]; ``query_tests``: mean difference, Wilcoxon p)."""
    if "full" not in methods:
        return {}
    full = scored_metrics(methods["full"])
    full_rows = methods["full"].get("per_query", [])
    comparison = {}
    for name, entry in methods.items():
        if name == "full":
            continue
        other = scored_metrics(entry)
        other_rows = entry.get("per_query", [])
        margin = {m: (full[m] - other[m]) * metric_direction(m) for m in full if m in other}
        comparison[name] = {"full_better": {m: d > 0 for m, d in margin.items()}, "wins": sum(d > 0 for d in margin.values()),
                            "ties": sum(d == 0 for d in margin.values()), "metrics": len(margin),
                            "query_wins": paired_query_wins(full_rows, other_rows), "query_tests": paired_query_tests(full_rows, other_rows)}
    return comparison


def paired_query_differences(full_rows: list[dict], other_rows: list[dict]) -> dict[str, list[float]]:
    """Per score column, the differences full - other over the queries both ran, signed so that a
    positive value means the full method is better (for lower-is-better columns: other - full)."""
    others = {row["query"]: row for row in other_rows}
    differences: dict[str, list[float]] = {}
    for row in full_rows:
        other = others.get(row["query"])
        if other is None:
            continue
        for metric, value in row.items():
            direction = metric_direction(metric) if isinstance(value, (int, float)) else 0
            if direction and metric in other and math.isfinite(value) and math.isfinite(other[metric]):
                differences.setdefault(metric, []).append((value - other[metric]) * direction)
    return differences


def paired_query_wins(full_rows: list[dict], other_rows: list[dict]) -> dict[str, list[int]]:
    """Per metric, [queries where the full method is strictly better, queries compared]: the paired view
    of the same queries, less sensitive than a mean to one query's large margin."""
    return {metric: [sum(d > 0 for d in values), len(values)]
            for metric, values in paired_query_differences(full_rows, other_rows).items()}


def paired_query_tests(full_rows: list[dict], other_rows: list[dict]) -> dict[str, dict]:
    """Per metric: the mean paired difference (positive: the full method is better) and the two-sided
    p-value of the Wilcoxon signed-rank test of the differences (exact for small, untied samples).

    The p-value says how often differences at least this one-sided would arise if neither method were
    better on such queries: with 6 queries it cannot go below 0.031, so a table of 6 queries can
    show a trend but not settle a comparison. ``p_wilcoxon`` is None when every difference is 0 or
    fewer than 2 queries were compared.
    """
    from scipy.stats import wilcoxon

    tests = {}
    for metric, values in paired_query_differences(full_rows, other_rows).items():
        p_value = None
        if len(values) >= 2 and any(v != 0 for v in values):
            p_value = float(wilcoxon(values).pvalue)
        tests[metric] = {"mean_difference": sum(values) / len(values), "p_wilcoxon": p_value, "pairs": len(values)}
    return tests


def oracle_check(methods: dict) -> list[str]:
    """The columns where the ground truth (``oracle``) does not score at least as well as every other
    method: each one is a broken metric or comparison. Empty when it wins everywhere."""
    if "oracle" not in methods:
        return []
    oracle = scored_metrics(methods["oracle"])
    lost = []
    for column, value in oracle.items():
        others = [scored_metrics(e).get(column) for n, e in methods.items() if n != "oracle"]
        others = [v for v in others if v is not None]
        if others and any((v - value) * metric_direction(column) > 0 for v in others):
            lost.append(column)
    return lost


def flat_colour_targets(methods: dict, method: str = "full") -> dict:
    """How ``method`` does against the flat mean colour, query by query (the issue's targets): the
    ratio of mean per-part ΔE (seen and unseen), the share of queries with a lower ΔE, and the share
    with a higher low-pass PSNR (seen)."""
    if method not in methods or "flat_colour" not in methods:
        return {}
    mine, flat = methods[method], methods["flat_colour"]
    wins = paired_query_wins(mine["per_query"], flat["per_query"])
    out = {}
    for side in ("seen", "unseen"):
        column = f"{side} part_delta_e"
        if column in mine["query"] and column in flat["query"] and flat["query"][column] > 0:
            out[f"{side} part_delta_e ratio"] = mine["query"][column] / flat["query"][column]
            if column in wins:
                out[f"{side} part_delta_e below"] = wins[column]
    if "seen lowpass_psnr" in wins:
        out["seen lowpass_psnr above"] = wins["seen lowpass_psnr"]
    return out


# ----------------------------------------------------------------------------------------- report
METHOD_TITLES = {"oracle": "ground-truth texture (oracle)", "flat_colour": "flat mean colour of the photo",
                 "mean_texture": "generator's mean texture (w_avg)", "backprojection": "photo back-projection",
                 **{"full": "full method", "no_noc": "w/o NOC", "no_patches": "w/o patches",
                    "no_refine": "w/o surface features (no refine)"}}
ABLATION_TITLES = {k: METHOD_TITLES[k] for k in ABLATIONS}


def _paired_note(test: dict | None) -> str:
    """' (mean +0.47, p 0.69)': the paired difference (positive: full better) and its Wilcoxon p-value."""
    if not test:
        return ""
    p_value = test.get("p_wilcoxon")
    return f" (mean {test['mean_difference']:+.3g}" + ("" if p_value is None else f", p {p_value:.2g}") + ")"


def _fmt(value, name: str) -> str:
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        return "-" if value is None else str(value)
    if name.startswith("kid"):
        return f"{value * 100:.3g}"  # x1e2, as the paper's tables
    return f"{value:.4g}"


def _column_title(column: str) -> str:
    from mesh2tex.evaluation import METRIC_TITLES

    side, _, metric = column.partition(" ")
    arrow = " ↑" if metric_direction(column) > 0 else " ↓"
    return f"{side} {METRIC_TITLES.get(metric, metric)}{arrow}"


def transfer_table(methods: dict, order: list[str]) -> list[str]:
    """Markdown rows of one transfer protocol: a row per method, seen columns then unseen columns; the
    best value among the methods other than the oracle in bold."""
    from mesh2tex.evaluation import METRICS

    present = set().union(*(m["query"] for m in methods.values()))
    columns = [f"{side} {metric}" for side in ("seen", "unseen") for metric in METRICS if f"{side} {metric}" in present]
    best = {}
    for column in columns:
        values = [scored_metrics(e).get(column) for n, e in methods.items() if n != "oracle"]
        values = [v for v in values if v is not None]
        if values:
            best[column] = max(values) if metric_direction(column) > 0 else min(values)
    lines = ["| method | " + " | ".join(_column_title(c) for c in columns) + " | seconds |",
             "| --- |" + " --- |" * (len(columns) + 1)]
    for name in order:
        if name not in methods:
            continue
        scores = methods[name]["query"]
        cells = []
        for column in columns:
            text = _fmt(scores.get(column), column)
            cells.append(f"**{text}**" if name != "oracle" and scores.get(column) is not None and scores.get(column) == best.get(column) else text)
        lines.append(f"| {METHOD_TITLES.get(name, name)} | " + " | ".join(cells) + f" | {methods[name]['seconds']:.0f} |")
    return lines


def protocols_markdown(result: dict) -> str:
    """The results as markdown: one table per protocol (rows: the oracle, the baselines, the ablations
    of the paper's Table 8 and the full method), then the paired comparisons with the full method."""
    lines = ["# mesh2tex evaluate --protocols", ""]
    s = result["settings"]
    lines.append(f"World `{result['world']}`, GAN `{result['gan']}`; {result['counts']['queries']} queries; "
                 f"transfer {s['latent_iters']} + {s['refine_iters']} iterations at {s['resolution']} px, "
                 f"style scales {s.get('scales', '?')}, patches {s['patch_size']} px at {s.get('patch_scales') or s.get('scales', '?')} "
                 f"scales. KID is shown x1e2. KID/FID features: {result['features']}.")
    lines.append("")
    if "unconditional" in result["protocols"]:
        entry = result["protocols"]["unconditional"]
        metrics = {k: v for k, v in entry["metrics"].items() if metric_direction(k) != 0}
        lines += ["## unconditional generation (held-out shapes vs the world's photos)", "",
                  "| " + " | ".join(metrics) + " |", "|" + " --- |" * len(metrics),
                  "| " + " | ".join(_fmt(v, k) for k, v in metrics.items()) + " |", ""]
    titles = {"known_pose": "exact geometry, known pose", "unknown_pose": "exact geometry, unknown pose (pose network)",
              "other_shape": "transfer to another shape of the category"}
    for protocol in TRANSFER_PROTOCOLS:
        if protocol not in result["protocols"]:
            continue
        entry = result["protocols"][protocol]
        methods = entry["methods"]
        lines += [f"## {titles[protocol]} (`{protocol}`)", "",
                  f"Every method rendered alike (`mesh2tex.evaluation.render_for_comparison`, lighting `{s.get('lighting', 'photo')}`) "
                  f"at the photo's view (seen) and {s.get('unseen_views', 4)} views it does not show (unseen, mean), "
                  "against what the world photographs there; "
                  + ("scored on the object pixels both the world's shape and the prepared one cover. "
                     if protocol != "other_shape" else "each image on its own object pixels, parts matched by label. ")
                  + f"Low-pass PSNR after a Gaussian blur of σ = {s.get('lowpass_sigma', 3.0):g} px; object SWD x1e3. "
                  "Bold: the best method other than the oracle.", ""]
        order = ["oracle", "flat_colour", "mean_texture", "backprojection", "no_noc", "no_patches", "no_refine", "full"]
        lines += transfer_table(methods, order)
        lost = oracle_check(methods)
        lines += ["", "The oracle wins every column." if not lost else
                  f"**The oracle does not win: {', '.join(lost)}** (a broken metric or comparison)."]
        errors = [q["azimuth_error"] for q in entry["queries"]]
        if protocol != "known_pose" and errors:
            searched = [q["network_azimuth_error"] for q in entry["queries"] if "network_azimuth_error" in q]
            how = "Pose network + silhouette search" if searched else "Pose network"
            lines += ["", f"{how}: mean azimuth error {sum(errors) / len(errors):.1f} deg, "
                          f"mean elevation error {sum(q['elevation_error'] for q in entry['queries']) / len(errors):.1f} deg"
                          + (f" (the network's bins alone: mean azimuth error {sum(searched) / len(searched):.1f} deg)." if searched else ".")]
        targets = flat_colour_targets(methods)
        if targets:
            parts = []
            for side in ("seen", "unseen"):
                if f"{side} part_delta_e ratio" in targets:
                    below = targets.get(f"{side} part_delta_e below")
                    parts.append(f"{side} per-part ΔE {targets[f'{side} part_delta_e ratio']:.2f} of the flat colour's"
                                 + (f", lower on {below[0]} of {below[1]} queries" if below else ""))
            if "seen lowpass_psnr above" in targets:
                w, n = targets["seen lowpass_psnr above"]
                parts.append(f"seen low-pass PSNR higher on {w} of {n}")
            lines += ["", "Full method against the flat colour: " + "; ".join(parts) + "."]
        for name, c in result["comparison"].get(protocol, {}).items():
            if name == "oracle":
                continue
            lost = [m for m, better in c["full_better"].items() if not better]
            lines.append("")
            lines.append(f"Full method better than {METHOD_TITLES.get(name, name)} on {c['wins']} of {c['metrics']} columns"
                         + (f", {c['ties']} tied" if c["ties"] else "")
                         + (f" (not better on: {', '.join(lost)})." if lost else ".")
                         + ("" if not c.get("query_wins") else " Per query, full better on "
                            + ", ".join(f"{m} in {w} of {n}" + _paired_note(c.get("query_tests", {}).get(m))
                                        for m, (w, n) in c["query_wins"].items()) + "."))
        lines.append("")
    return "\n".join(lines) + "\n"


def _uint8(image01: torch.Tensor):
    """[3,H,W] in [0,1] -> (H,W,3) uint8."""
    return (image01.clamp(0, 1) * 255).round().to(torch.uint8).permute(1, 2, 0).cpu().numpy()


# ------------------------------------------------------------------------------------------- entry
def run_protocols(world_dir: str | Path, shapes_dir: str | Path, gan_checkpoint: str | Path,
                  pose_checkpoint: str | Path | None, noc_checkpoint: str | Path | None, cfg: ProtocolConfig,
                  out: Path | None = None, log=print, overwrite: bool = False) -> dict:
    """Run the protocols of ``cfg`` and return the result dict (also written as ``protocols.json`` /
    ``protocols.md`` when ``out`` is given, with the renders under ``out/renders``).

    With ``out``, every finished transfer is kept in ``out/transfers`` (:class:`TransferCache`), so
    re-running after an interruption resumes and a wider run reuses them; ``overwrite`` discards
    transfers made with other settings instead of refusing the run."""
    from infer.evaluate import EvaluateConfig, _json_value
    from infer.generate import load_generator, load_shape
    from mesh2tex.metrics import get_feature_extractor
    from mesh2tex.nn.vgg import load_vgg19
    from train.runs import select_device

    from mesh2tex.evaluation import LIGHTING

    unknown = ([p for p in cfg.protocols if p not in PROTOCOLS] + [a for a in cfg.ablations if a not in ABLATIONS]
               + [b for b in cfg.baselines if b not in BASELINES])
    if unknown:
        raise UserError(f"unknown protocol, ablation or baseline {', '.join(unknown)}; protocols: {', '.join(PROTOCOLS)}; "
                        f"ablations: {', '.join(ABLATIONS)}; baselines: {', '.join(BASELINES)}")
    if cfg.lighting not in LIGHTING:
        raise UserError(f"lighting {cfg.lighting!r}: must be one of {', '.join(LIGHTING)}")
    if not 0 <= cfg.unseen_views <= 35 or cfg.lowpass_sigma < 0:
        raise UserError(f"unseen_views {cfg.unseen_views}, lowpass_sigma {cfg.lowpass_sigma}: need 0-35 unseen views and a sigma >= 0")
    if cfg.resolution < 32:
        raise UserError(f"--resolution {cfg.resolution}: must be at least 32")
    if cfg.latent_iters < 0 or cfg.refine_iters < 0:
        raise UserError("--latent-iters and --refine-iters must not be negative")
    transfers = [p for p in cfg.protocols if p in TRANSFER_PROTOCOLS]
    if transfers:
        from infer.transfer import TransferConfig, check_style_sizes

        check_style_sizes(TransferConfig(resolution=cfg.resolution, patch_size=cfg.patch_size, scales=cfg.scales,
                                         patch_scales=cfg.patch_scales))
    if any(p != "known_pose" for p in transfers) and not pose_checkpoint:
        raise UserError("the unknown_pose and other_shape protocols need --pose-checkpoint (from 'mesh2tex train pose')")
    if transfers and any(ABLATIONS[a].get("use_noc", True) and ABLATIONS[a].get("use_patches", True) for a in cfg.ablations) \
            and not noc_checkpoint:
        raise UserError("NOC-guided ablations (full, no_refine) need --noc-checkpoint (from 'mesh2tex train noc')")
    device = select_device(cfg.device)
    started = time.perf_counter()
    world = load_world(world_dir, cfg.queries)
    generator, meta = load_generator(gan_checkpoint, device)
    camera = meta.get("config", {}).get("camera", {})
    distance, fov = float(camera.get("distance", 1.7)), float(camera.get("fov", 40.0))
    paths = shape_paths(shapes_dir)
    needed, targets = set(world.query_shapes), {}
    if "other_shape" in cfg.protocols:
        targets = {name: other_shape_name(name, list(paths)) for name in world.query_shapes}
        needed |= set(targets.values())
    missing = sorted(needed - set(paths))
    if missing:
        raise UserError(f"{shapes_dir}: no prepared shape for {', '.join(missing)} (prepare the world's meshes with 'mesh2tex prepare shapes')")
    shapes = {name: load_shape(paths[name], generator, 0, cfg.seed) for name in sorted(needed)}
    eval_cfg = EvaluateConfig(resolution=cfg.resolution, features=cfg.features, kid_subsets=cfg.kid_subsets, seed=cfg.seed)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        extractor = get_feature_extractor(cfg.features, cfg.inception_weights or None, cfg.vgg_weights or None, device)
        vgg = load_vgg19(cfg.vgg_weights or None, device=device) if transfers else None
    notes = sorted({str(w.message) for w in caught})
    for note in notes:
        print(f"mesh2tex: warning: {note}", file=sys.stderr)
    cache = None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        inputs = {"world": str(Path(world_dir).resolve()), "shapes": str(Path(shapes_dir).resolve()),
                  "gan": _file_digest(gan_checkpoint), "pose": _file_digest(pose_checkpoint), "noc": _file_digest(noc_checkpoint)}
        # Which transfers run, and how they are judged, not how each one runs: a cached transfer is re-judged.
        selection = ("protocols", "ablations", "queries", "baselines", "lighting", "unseen_views", "lowpass_sigma")
        settings = {k: v for k, v in asdict(cfg).items() if k not in selection}
        # Settings that do what the runs before these fields did are left out: their folders still match.
        for key, default in (("patch_scales", 0), ("pose_search", False)):
            if settings[key] == default:
                del settings[key]
        cache = TransferCache(out, {"settings": _json_safe(settings), "inputs": inputs}, overwrite)
    result = {"world": str(world_dir), "shapes": str(shapes_dir), "gan": str(gan_checkpoint),
              "pose_checkpoint": str(pose_checkpoint) if pose_checkpoint else None,
              "noc_checkpoint": str(noc_checkpoint) if noc_checkpoint else None,
              "features": extractor.description, "style_features": getattr(vgg, "source", None),
              "counts": {"queries": len(world.queries), "query_shapes": len(world.query_shapes)},
              "settings": asdict(cfg), "protocols": {}, "comparison": {}, "warnings": notes}
    for protocol in cfg.protocols:
        t = time.perf_counter()
        if protocol == "unconditional":
            entry = run_unconditional(generator, world, shapes, cfg, extractor, eval_cfg, distance, fov, device, out)
        else:
            entry = run_transfer_protocol(protocol, generator, world, shapes, targets, vgg, cfg, pose_checkpoint,
                                          noc_checkpoint, distance, fov, device, out, log, cache)
            result["comparison"][protocol] = compare_to_full(entry["methods"])
            entry["oracle_loses"] = oracle_check(entry["methods"])
            entry["against_flat_colour"] = flat_colour_targets(entry["methods"])
        entry["seconds"] = round(time.perf_counter() - t, 2)
        result["protocols"][protocol] = entry
        log(f"{protocol}: done in {entry['seconds']:.0f} s")
    result["seconds"] = round(time.perf_counter() - started, 2)
    if out is not None:
        write_json(out / "protocols.json", _json_value(result))
        write_text(out / "protocols.md", protocols_markdown(result))
    return result


def _file_digest(path: str | Path | None) -> str | None:
    """SHA-256 prefix of a file's bytes (None for None): the identity of a checkpoint, wherever it lies."""
    import hashlib

    if path is None:
        return None
    if not Path(path).is_file():
        raise UserError(f"{path}: checkpoint not found")
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def _json_safe(value):
    return json.loads(json.dumps(value))


def add_protocol_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``mesh2tex evaluate --protocols`` (added to the evaluate command's parser)."""
    group = parser.add_argument_group("protocols (--protocols: the paper's synthetic evaluation)")
    group.add_argument("--protocols", action="store_true", help="run the evaluation protocols on a synthetic world")
    group.add_argument("--world", help="synthetic world folder (from 'mesh2tex prepare synthetic')")
    group.add_argument("--shapes", help="prepared shapes of the world's meshes (from 'mesh2tex prepare shapes')")
    group.add_argument("--gan", help="GAN checkpoint (RUN/checkpoint.safetensors from 'train gan')")
    group.add_argument("--pose-checkpoint", help="pose network checkpoint (from 'train pose')")
    group.add_argument("--noc-checkpoint", help="NOC network checkpoint (from 'train noc')")
    group.add_argument("--latent-iters", type=int, help="transfer stage 1 iterations (default 100)")
    group.add_argument("--refine-iters", type=int, help="transfer stage 2 iterations (default 300)")
    group.add_argument("--queries", type=int, help="query photos used, the first K (default all)")
    group.add_argument("--only", help=f"comma-separated protocols to run (default all: {','.join(PROTOCOLS)})")
    group.add_argument("--ablations", help=f"comma-separated ablations (default all: {','.join(ABLATIONS)})")
    group.add_argument("--lighting", choices=("photo", "albedo"),
                       help="judge every method with the photo's light (default) or unlit, as albedo")
    group.add_argument("--unseen-views", type=int, help="views the photo does not show, judged apart (default 4)")
    group.add_argument("--baselines", help=f"comma-separated baselines beside the transfers (default all: {','.join(BASELINES)})")
    group.add_argument("--protocol-config", help="YAML file with any fields of the protocol config")


def _split(text: str | None) -> list[str] | None:
    return None if text is None else [t.strip() for t in text.split(",") if t.strip()]


def run_protocols_command(args: argparse.Namespace) -> int:
    """``mesh2tex evaluate --protocols ...``: writes OUT/protocols.json, OUT/protocols.md and OUT/renders/."""
    from mesh2tex.config import load_config

    for flag in ("world", "shapes", "gan"):
        if not getattr(args, flag):
            raise UserError(f"--protocols needs --{flag}")
    cfg = load_config(ProtocolConfig, args.protocol_config, {
        "latent_iters": args.latent_iters, "refine_iters": args.refine_iters, "queries": args.queries,
        "protocols": _split(args.only), "ablations": _split(args.ablations), "resolution": args.resolution,
        "lighting": getattr(args, "lighting", None), "unseen_views": getattr(args, "unseen_views", None),
        "baselines": _split(getattr(args, "baselines", None)),
        "features": args.features, "kid_subsets": args.kid_subsets, "seed": args.seed,
        "device": None if args.device == "auto" else args.device, "vgg_weights": args.vgg_weights,
        "inception_weights": args.inception_weights})
    out = Path(args.out)
    if (out / "protocols.json").exists() and not args.overwrite:
        raise UserError(f"{out}: already holds protocol results (protocols.json); pass --overwrite to replace them")
    result = run_protocols(args.world, args.shapes, args.gan, args.pose_checkpoint, args.noc_checkpoint, cfg, out,
                           log=lambda line: print(line, flush=True), overwrite=args.overwrite)
    print(protocols_markdown(result), end="")
    print(f"wrote {out / 'protocols.json'} and {out / 'protocols.md'} ({result['seconds']:.0f} s)")
    return 0
