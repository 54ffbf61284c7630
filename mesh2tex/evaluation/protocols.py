"""The evaluation protocols of the Mesh2Tex paper, run on a synthetic world and trained checkpoints.

    mesh2tex evaluate --protocols --world WORLD --shapes SHAPES --checkpoint NAME|PATH --pose-checkpoint P
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
used (``backprojection``). When asked for (``--baselines ...,automaton``), a mesh automaton fitted to
the photo at that pose with the transfer's losses and no GAN (``automaton``,
:mod:`mesh2tex.transfer.automaton`).

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

import copy
import sys
import time
import typing
import warnings
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

import numpy as np
import torch

from mesh2tex import transfer
from mesh2tex.errors import InputError
from mesh2tex.evaluation import LIGHTING, backproject_photo, generator_surface, vertex_colour_surface
from mesh2tex.evaluation.cache import TransferCache
from mesh2tex.evaluation.queries import QueryJudge, QuerySetup
from mesh2tex.evaluation.paired import compare_to_full, flat_colour_targets, mean_scores, oracle_check
from mesh2tex.evaluation.report import BASELINES, EXTRA_METHODS, PROTOCOLS, TRANSFER_PROTOCOLS, protocols_markdown
from mesh2tex.evaluation.world import World, load_world, other_shape_name
from mesh2tex.geometry.prepared import PreparedShape, shape_paths
from mesh2tex.io.atomic import json_ready, write_json, write_text
from mesh2tex.io.checkpoint import checkpoint_digest
from mesh2tex.photos import list_images, load_set
from mesh2tex.io.images import images_to_uint8, save_png
from mesh2tex.models import load_generator, resolve_checkpoint
from mesh2tex.metrics import get_feature_extractor, to_unit
from mesh2tex.metrics.evaluate import EvaluateConfig, evaluate_sets
from mesh2tex.nn.batch import collate_shapes
from mesh2tex.nn.render_texture import render_field_views
from mesh2tex.nn.vgg import load_vgg19
from mesh2tex.progress import progress_bar
from mesh2tex.render import orbit_camera
from mesh2tex.runtime import select_device
from mesh2tex.texturing import latent, mean_latent, shape_mismatch
from mesh2tex.transfer import ABLATIONS, TransferConfig, check_style_sizes, fit_automaton


# TransferConfig fields every transfer takes from the protocol's own fields of the same name, and those the ablations set.
SHARED = ("resolution", "seed", "device", "vgg_weights")
ABLATED = ("use_noc", "use_patches", "refine")
# TransferConfig and EvaluateConfig fields that were ProtocolConfig's own before it nested them.
FORMER_FIELDS = ("latent_iters", "refine_iters", "patch_size", "scales", "patch_scales", "pose_search")
FORMER_EVALUATE_FIELDS = ("features", "kid_subsets")


# TransferConfig fields that change no transfer (the automaton baseline's fit, the GLB's image format): left out of the
# transfer cache's fingerprint, so that setting them reuses the cached transfers.
NOT_TRANSFER = ("automaton", "texture_format")


@dataclass
class ProtocolConfig:
    protocols: list[str] = field(default_factory=lambda: list(PROTOCOLS))  # which protocols to run
    ablations: list[str] = field(default_factory=lambda: list(ABLATIONS))  # which ablations of each transfer protocol
    queries: int = 0  # query photos used (first K in the world's order; 0: all)
    resolution: int = 64  # side of the photo crops, renders and set-metric images
    baselines: list[str] = field(default_factory=lambda: list(BASELINES))  # simple methods judged beside the transfers
    lighting: str = "photo"  # render every method with the photo's light ('photo') or unlit, as albedo ('albedo')
    unseen_views: int = 4  # views the photo does not show, evenly spaced in azimuth after the photo's
    lowpass_sigma: float = 3.0  # Gaussian blur of the low-pass PSNR, in pixels of the world's photos
    latents: int = 4  # unconditional: random latents per held-out shape
    views: int = 6  # unconditional: orbit views per latent (paper: 6)
    seed: int = 0  # seed of the transfers, the unconditional latents and the set metrics
    device: str = "auto"  # auto, cpu or cuda
    vgg_weights: str = ""  # VGG19 ImageNet weights for the style losses ('' looks in $TORCH_HOME)
    inception_weights: str = ""  # Inception-v3 weights for KID/FID ('' looks in $TORCH_HOME)
    # Every transfer's settings, which the ablations change; its resolution, seed, device and vgg_weights are the fields
    # above. 2 style scales, the patch loss's the same: 32 px patches keep a 16 px coarsest level (paper: 3 scales, 64 px
    # patches in larger crops).
    transfer: TransferConfig = field(default_factory=lambda: TransferConfig(resolution=64, scales=2, patch_scales=0))
    # The unconditional protocol's set metrics (KID/FID features, KID subsets, SWD sampling); its resolution and seed are
    # the fields above.
    evaluate: EvaluateConfig = field(default_factory=lambda: EvaluateConfig(resolution=64))
    # The ``automaton`` method (when --baselines asks for it) is fitted with the transfer's losses and settings and its
    # ``transfer.automaton`` section.

    # Keys of older protocol configs that now live under ``transfer`` (named by the unknown-key error).
    MOVED_KEYS: typing.ClassVar[dict[str, str]] = ({name: f"transfer.{name}" for name in FORMER_FIELDS}
                                                   | {name: f"evaluate.{name}" for name in FORMER_EVALUATE_FIELDS}
                                                   | {"automaton": "transfer.automaton"})

    def __post_init__(self):
        unknown = ([p for p in self.protocols if p not in PROTOCOLS] + [a for a in self.ablations if a not in ABLATIONS]
                   + [b for b in self.baselines if b not in (*BASELINES, *EXTRA_METHODS)])
        if unknown:
            raise InputError(f"unknown protocol, ablation or baseline {', '.join(unknown)}; protocols: {', '.join(PROTOCOLS)}; "
                            f"ablations: {', '.join(ABLATIONS)}; baselines: {', '.join((*BASELINES, *EXTRA_METHODS))}")
        if self.lighting not in LIGHTING:
            raise InputError(f"lighting {self.lighting!r}: must be one of {', '.join(LIGHTING)}")
        if not 0 <= self.unseen_views <= 35 or self.lowpass_sigma < 0:
            raise InputError(f"unseen_views {self.unseen_views}, lowpass_sigma {self.lowpass_sigma}: need 0-35 unseen views and a sigma >= 0")
        if self.resolution < 32:
            raise InputError(f"--resolution {self.resolution}: must be at least 32")
        self.transfer = self._shared_into("transfer", SHARED)
        ablated = [name for name in ABLATED if getattr(self.transfer, name) != getattr(self._default("transfer"), name)]
        if ablated:
            raise InputError(f"transfer: {', '.join(ablated)} cannot be set there: choose an ablation (--ablations)")
        self.evaluate = self._shared_into("evaluate", ("resolution", "seed"))

    def _default(self, name: str):
        return next(f for f in fields(self) if f.name == name).default_factory()

    def _shared_into(self, name: str, shared: tuple[str, ...]):
        """The nested config ``name`` with the protocol's own values of ``shared``; a value set there that differs is refused
        (one left at the nested config's default cannot be told from one not set, and takes the protocol's). The copy
        remembers the values it was given (``_from_protocol``), so that ``dataclasses.replace`` of a shared field on a
        built config, which hands the same nested config to the new one, takes the new value instead of refusing it."""
        nested, default = getattr(self, name), self._default(name)
        given = getattr(nested, "_from_protocol", {})
        wrong = [key for key in shared
                 if getattr(nested, key) not in (getattr(self, key), getattr(default, key)) and getattr(nested, key) != given.get(key)]
        if wrong:
            raise InputError(f"{name}: {', '.join(wrong)} cannot be set there: set the protocol's own {', '.join(wrong)}")
        resolved = replace(nested, **{key: getattr(self, key) for key in shared})
        resolved._from_protocol = {key: getattr(self, key) for key in shared}
        return resolved

    def transfer_config(self, device: str = "auto") -> TransferConfig:
        """The settings of every transfer (the ablations change them further), on ``device``."""
        return replace(self.transfer, device=device)

    def evaluate_config(self) -> EvaluateConfig:
        """The settings of the unconditional protocol's set metrics."""
        return self.evaluate


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
            save_png(folder / f"{world.query_shapes[0]}_{i:02d}.png", images_to_uint8(image, signed=False))
    return {"shapes": world.query_shapes, "reference": str(world.root / "images"), **result,
            "seconds": round(time.perf_counter() - start, 2)}


# -------------------------------------------------------------------------------------- transfers
def run_transfer_protocol(protocol: str, generator, world: World, shapes: dict[str, PreparedShape], targets: dict[str, str],
                          vgg, cfg: ProtocolConfig,
                          pose_checkpoint: str | Path | None, noc_checkpoint: str | Path | None,
                          distance: float, fov: float, device: torch.device, out: Path | None, log=print,
                          cache: "TransferCache | None" = None, generator_lit: bool = False, step=None) -> dict:
    """One transfer protocol (``known_pose``, ``unknown_pose`` or ``other_shape``): the baselines of
    ``cfg.baselines`` and every ablation of ``cfg.ablations``, judged alike.

    Every method is a textured surface rendered by ``mesh2tex.evaluation.render_for_comparison`` at
    the photo's view and ``cfg.unseen_views`` views it does not show, with the photo's light and
    background (``cfg.lighting``), against what the world photographs there (the query photo, then
    the world's own renders). ``shapes``: the prepared shapes by name; ``targets``: query shape ->
    the shape ``other_shape`` textures; ``cache``: finished transfers are stored there and reused;
    ``generator_lit``: the GAN was trained under the light prior (see ``TransferConfig.light``).

    Returns {"queries": [per-query setup], "methods": {name: {"query": mean scores, "per_query":
    [rows], "seconds": s}}}; scores are named "seen <metric>" and "unseen <metric>".
    """
    base = cfg.transfer_config(str(device))
    methods = {name: {"per_query": [], "seconds": 0.0} for name in (*cfg.baselines, *cfg.ablations)}
    setups = []
    for q, query in enumerate(world.queries):
        setup = QuerySetup(protocol, query, shapes, targets, base, cfg, pose_checkpoint, noc_checkpoint, distance, fov, device)
        setups.append(setup.record)
        judge = QueryJudge(protocol, world, query, setup.target, setup.shape, cfg)

        def keep(name: str, rendered, row: dict) -> None:
            row = {"query": query.name, **judge.score(rendered), **row}
            methods[name]["per_query"].append(row)
            methods[name]["seconds"] += row.get("seconds", 0.0)
            if out is not None:
                folder = out / "renders" / protocol / name
                folder.mkdir(parents=True, exist_ok=True)
                save_png(folder / f"{query.name}.png", _strip(rendered.rgb))
            log(f"{protocol} {q + 1}/{len(world.queries)} {query.name} -> {setup.target} {name}: "
                + ", ".join(f"{k} {row[k]:.4g}" for k in ("seen part_delta_e", "unseen part_delta_e", "seen lowpass_psnr") if k in row)
                + (f" ({row['seconds']:.0f} s)" if "seconds" in row else ""))
            if step is not None:  # one method of one query judged
                step()

        if out is not None:
            (out / "renders" / protocol).mkdir(parents=True, exist_ok=True)
            save_png(out / "renders" / protocol / f"{query.name}_reference.png", _strip(judge.reference.rgb))
        for name in cfg.baselines:
            start = time.perf_counter()
            rendered, row = _baseline(name, judge, setup, generator, vgg, cfg, base, device)
            keep(name, rendered, {"seconds": round(time.perf_counter() - start, 2), **row})
        for ablation in cfg.ablations:
            texture, row = _transferred(ablation, setup, generator, vgg, cfg, base, device, cache, generator_lit)
            # Stage 2 refines synthesis blocks only: psi is the original's, so the synthesis output is the whole result.
            keep(ablation, judge.render(generator_surface(generator, texture, setup.batch)), dict(row))
    for entry in methods.values():
        entry["query"] = mean_scores(entry["per_query"])
        entry["seconds"] = round(entry["seconds"], 2)
    return {"queries": setups, "methods": methods}


def _baseline(name: str, judge: QueryJudge, setup: QuerySetup, generator, vgg, cfg: ProtocolConfig, base, device) -> tuple:
    """(the render, extra row fields) of the simple method ``name`` (:data:`BASELINES`, or ``automaton``)."""
    if name == "oracle":
        return judge.oracle, {}
    if name == "flat_colour":
        return judge.flat, {}
    if name == "mean_texture":
        with torch.no_grad():
            texture = generator.synthesize(setup.batch.to(device), mean_latent(generator).to(device), noise_mode="none")
        return judge.render(generator_surface(generator, texture, setup.batch)), {}
    if name == "automaton":  # fitted at the pose the transfer uses, with its losses
        if base.use_noc and base.use_patches and setup.photo_noc is None:
            raise InputError("the automaton uses NOC-guided patches: give --noc-checkpoint")
        fit = fit_automaton(setup.shape, setup.photo, setup.view, setup.photo_noc, vgg, base, base.automaton, device, show_progress=False)
        return judge.render(vertex_colour_surface(judge.vertices, judge.triangles, fit.colours.cpu())), {"loss_last": fit.losses[-1]}
    # backprojection: the photo painted on from the pose the transfer used, framed as the transfer frames it
    try:
        surface = backproject_photo(judge.vertices, judge.triangles, judge.truth.photo[0], judge.truth.photo_mask[0, 0], setup.azimuth,
                                    setup.elevation, setup.distance, setup.fov,
                                    align="photo" if setup.protocol == "known_pose" else "silhouette", margin=base.margin)
    except ValueError as error:
        raise InputError(f"{setup.query.image}: {error}") from None
    return judge.render(surface), {}


def _transferred(ablation: str, setup: QuerySetup, generator, vgg, cfg: ProtocolConfig, base, device, cache, generator_lit: bool) -> tuple:
    """(the synthesis output, row) of the transfer under ``ablation``: from ``cache`` when an earlier run made it."""
    tcfg = replace(base, **ABLATIONS[ablation])
    guided = tcfg.use_noc and tcfg.use_patches
    if guided and setup.photo_noc is None:
        raise InputError(f"ablation {ablation} uses NOC-guided patches: give --noc-checkpoint")
    cached = cache.load(setup.protocol, ablation, setup.query.name) if cache is not None else None
    if cached is not None:  # made by an earlier run into this folder with the same settings
        return cached
    torch.manual_seed(cfg.seed)
    candidate = copy.deepcopy(generator)  # stage 2 changes the generator's weights
    result = transfer.transfer_texture(candidate, setup.shape, setup.photo, setup.view, setup.photo_noc if guided else None, vgg, tcfg,
                                       device, show_progress=False, generator_lit=generator_lit)
    with torch.no_grad():
        texture = candidate.synthesize(setup.batch.to(device), result.ws.to(device), noise_mode="none")
    row = {"loss_last": {k: v[-1] for k, v in result.losses.items() if v}, "seconds": round(sum(result.seconds.values()), 2),
           **({"light": result.light} if result.light is not None else {})}
    if cache is not None:
        cache.save(setup.protocol, ablation, setup.query.name, texture, row)
    return texture, row


def _strip(images: torch.Tensor) -> np.ndarray:
    """[B, 3, R, R] in [0, 1] -> one (R, B*R + 2*(B-1), 3) uint8 image, the views side by side."""
    tiles = [images_to_uint8(image, signed=False) for image in images]
    gap = np.full((tiles[0].shape[0], 2, 3), 255, dtype=np.uint8)
    return np.concatenate([t for tile in tiles for t in (tile, gap)][:-1], axis=1)


# ------------------------------------------------------------------------------------------ resume
# The fingerprint keeps the layout it had when FORMER_FIELDS were fields of ProtocolConfig itself and ``transfer``
# held only the other fields a config set, so that the folders of those runs still match.


def cache_settings(cfg: ProtocolConfig, generator_lit: bool) -> dict:
    """The settings a :class:`TransferCache` is made with: every setting of ``cfg`` that changes a transfer, not
    which transfers run or how they are judged (protocols, ablations, queries, baselines, lighting, unseen_views,
    lowpass_sigma: a cached transfer is re-judged), with every transfer's resolved settings (``transfer_config``,
    so that a changed TransferConfig default never reuses old transfers) and whether the GAN was trained lit."""
    transfer = asdict(cfg.transfer)
    own = {name: transfer[name] for name in FORMER_FIELDS}
    # Settings that do what the runs before these fields did are left out: their folders still match.
    if own["patch_scales"] == 0:
        del own["patch_scales"]
    if not own["pose_search"]:
        del own["pose_search"]
    judged = ("protocols", "ablations", "queries", "baselines", "lighting", "unseen_views", "lowpass_sigma")
    # The automaton's fit is not cached (a method beside the transfers, not a transfer).
    settings = {"resolution": cfg.resolution, **own, **{name: getattr(cfg.evaluate, name) for name in FORMER_EVALUATE_FIELDS},
                **{k: v for k, v in asdict(cfg).items() if k not in (*judged, "resolution", "transfer", "evaluate")}}
    defaults = asdict(TransferConfig())
    further = {k: v for k, v in transfer.items()
               if k not in (*FORMER_FIELDS, *SHARED, *ABLATED, *NOT_TRANSFER) and v != defaults[k]}
    if further:
        settings["transfer"] = further
    settings["transfer_config"] = {k: v for k, v in asdict(cfg.transfer_config()).items() if k not in ("device", *NOT_TRANSFER)}
    settings["generator_lit"] = generator_lit
    return settings


# ------------------------------------------------------------------------------------------- entry
def run_protocols(world_dir: str | Path, shapes_dir: str | Path, gan_checkpoint: str | Path,
                  pose_checkpoint: str | Path | None, noc_checkpoint: str | Path | None, cfg: ProtocolConfig,
                  out: Path | None = None, log=print, overwrite: bool = False) -> dict:
    """Run the protocols of ``cfg`` and return the result dict (also written as ``protocols.json`` /
    ``protocols.md`` when ``out`` is given, with the renders under ``out/renders``).

    With ``out``, every finished transfer is kept in ``out/transfers`` (:class:`TransferCache`), so
    re-running after an interruption resumes and a wider run reuses them; ``overwrite`` discards
    transfers made with other settings instead of refusing the run."""
    transfers = [p for p in cfg.protocols if p in TRANSFER_PROTOCOLS]
    if transfers:
        check_style_sizes(cfg.transfer_config())
    if any(p != "known_pose" for p in transfers) and not pose_checkpoint:
        raise InputError("the unknown_pose and other_shape protocols need --pose-checkpoint (from 'mesh2tex train pose')")
    if transfers and any(ABLATIONS[a].get("use_noc", True) and ABLATIONS[a].get("use_patches", True) for a in cfg.ablations) \
            and not noc_checkpoint:
        raise InputError("NOC-guided ablations (full, no_refine) need --noc-checkpoint (from 'mesh2tex train noc')")
    device = select_device(cfg.device)
    started = time.perf_counter()
    world = load_world(world_dir, cfg.queries)
    model = load_generator(gan_checkpoint, device)
    generator, distance, fov = model.network, model.camera.distance, model.camera.fov
    paths = shape_paths(shapes_dir)
    needed, targets = set(world.query_shapes), {}
    if "other_shape" in cfg.protocols:
        targets = {name: other_shape_name(name, list(paths)) for name in world.query_shapes}
        needed |= set(targets.values())
    missing = sorted(needed - set(paths))
    if missing:
        raise InputError(f"{shapes_dir}: no prepared shape for {', '.join(missing)} (prepare the world's meshes with 'mesh2tex prepare shapes')")
    shapes = {name: load_prepared(paths[name], generator) for name in sorted(needed)}
    eval_cfg = cfg.evaluate_config()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        extractor = get_feature_extractor(cfg.evaluate.features, cfg.inception_weights or None, cfg.vgg_weights or None, device)
        vgg = load_vgg19(cfg.vgg_weights or None, device=device) if transfers else None
    notes = sorted({str(w.message) for w in caught})
    for note in notes:
        print(f"mesh2tex: warning: {note}", file=sys.stderr)
    cache = None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        inputs = {"world": str(Path(world_dir).resolve()), "shapes": str(Path(shapes_dir).resolve()),
                  "gan": _file_digest(gan_checkpoint, "gan"), "pose": _file_digest(pose_checkpoint, "pose"),
                  "noc": _file_digest(noc_checkpoint, "noc")}
        cache = TransferCache(out, {"settings": json_ready(cache_settings(cfg, model.lit)), "inputs": inputs}, overwrite)
    result = {"world": str(world_dir), "shapes": str(shapes_dir), "gan": str(gan_checkpoint),
              "pose_checkpoint": str(pose_checkpoint) if pose_checkpoint else None,
              "noc_checkpoint": str(noc_checkpoint) if noc_checkpoint else None,
              "features": extractor.description, "style_features": getattr(vgg, "source", None),
              "counts": {"queries": len(world.queries), "query_shapes": len(world.query_shapes)},
              "settings": asdict(cfg), "protocols": {}, "comparison": {}, "warnings": notes}
    steps = sum(1 if protocol == "unconditional" else len(world.queries) * (len(cfg.baselines) + len(cfg.ablations))
                for protocol in cfg.protocols)
    bar = progress_bar(total=steps, desc="protocols", unit="result")
    for protocol in cfg.protocols:
        t = time.perf_counter()
        if protocol == "unconditional":
            entry = run_unconditional(generator, world, shapes, cfg, extractor, eval_cfg, distance, fov, device, out)
            bar.update(1)
        else:
            entry = run_transfer_protocol(protocol, generator, world, shapes, targets, vgg, cfg, pose_checkpoint,
                                          noc_checkpoint, distance, fov, device, out, log, cache, generator_lit=model.lit,
                                          step=bar.update)
            result["comparison"][protocol] = compare_to_full(entry["methods"])
            entry["oracle_loses"] = oracle_check(entry["methods"])
            entry["against_flat_colour"] = flat_colour_targets(entry["methods"])
        entry["seconds"] = round(time.perf_counter() - t, 2)
        result["protocols"][protocol] = entry
        log(f"{protocol}: done in {entry['seconds']:.0f} s")
    bar.close()
    result["seconds"] = round(time.perf_counter() - started, 2)
    if out is not None:
        write_json(out / "protocols.json", json_ready(result))
        write_text(out / "protocols.md", protocols_markdown(result))
    return result


def load_prepared(path: Path, generator) -> PreparedShape:
    """A prepared shape of the world (``SHAPES/<name>.npz``), checked against the generator (InputError naming the file)."""
    shape = PreparedShape.load(path)
    problem = shape_mismatch(shape, generator)
    if problem:
        raise InputError(f"{path}: has {problem}")
    return shape


def _file_digest(path: str | Path | None, kind: str) -> str | None:
    """:func:`mesh2tex.io.checkpoint.checkpoint_digest` of a path or a shipped model's ``kind`` file, None for None."""
    return None if path is None else checkpoint_digest(resolve_checkpoint(path, kind))
