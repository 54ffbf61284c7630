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
import warnings
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import torch

from mesh2tex import transfer
from mesh2tex.errors import InputError
from mesh2tex.evaluation import backproject_photo, generator_surface, vertex_colour_surface
from mesh2tex.evaluation.cache import TransferCache
from mesh2tex.evaluation.paired import compare_to_full, flat_colour_targets, mean_scores, oracle_check
from mesh2tex.evaluation.protocol_config import ProtocolConfig, ProtocolInputs, cache_settings
from mesh2tex.evaluation.queries import QueryJudge, QuerySetup
from mesh2tex.evaluation.report import TRANSFER_PROTOCOLS, protocols_markdown
from mesh2tex.evaluation.unconditional import run_unconditional
from mesh2tex.evaluation.world import World, load_world, other_shape_name
from mesh2tex.geometry.prepared import PreparedShape, shape_paths
from mesh2tex.io.atomic import json_ready, write_json, write_text
from mesh2tex.io.checkpoint import checkpoint_digest
from mesh2tex.io.images import images_to_uint8, save_png
from mesh2tex.metrics import get_feature_extractor
from mesh2tex.models import load_generator, resolve_checkpoint
from mesh2tex.nn.vgg import load_vgg19
from mesh2tex.progress import progress_bar
from mesh2tex.runtime import select_device
from mesh2tex.texturing import mean_latent, shape_mismatch
from mesh2tex.transfer import ABLATIONS, check_style_sizes, fit_automaton


# -------------------------------------------------------------------------------------- transfers
def run_transfer_protocol(protocol: str, run: ProtocolInputs, step=None) -> dict:
    """One transfer protocol (``known_pose``, ``unknown_pose`` or ``other_shape``): the baselines of
    ``cfg.baselines`` and every ablation of ``cfg.ablations``, judged alike.

    Every method is a textured surface rendered by ``mesh2tex.evaluation.render_for_comparison`` at
    the photo's view and ``cfg.unseen_views`` views it does not show, with the photo's light and
    background (``cfg.lighting``), against what the world photographs there (the query photo, then
    the world's own renders). ``run``: what every protocol shares (:class:`ProtocolInputs`);
    ``step()`` is called as each method of each query is judged.

    Returns {"queries": [per-query setup], "methods": {name: {"query": mean scores, "per_query":
    [rows], "seconds": s}}}; scores are named "seen <metric>" and "unseen <metric>".
    """
    generator, world, shapes, targets, vgg, cfg = run.generator, run.world, run.shapes, run.targets, run.vgg, run.cfg
    device, out, log, cache = run.device, run.out, run.log, run.cache
    base = cfg.transfer_config(str(device))
    methods = {name: {"per_query": [], "seconds": 0.0} for name in (*cfg.baselines, *cfg.ablations)}
    setups = []
    for q, query in enumerate(world.queries):
        setup = QuerySetup(
            protocol,
            query,
            shapes,
            targets,
            base,
            cfg,
            run.pose_checkpoint,
            run.noc_checkpoint,
            run.distance,
            run.fov,
            device,
        )
        setups.append(setup.record)
        judge = QueryJudge(protocol, world, query, setup.target, setup.shape, cfg)
        setup.judge_pose(judge.turns)

        def keep(name: str, rendered, row: dict) -> None:
            row = {"query": query.name, **judge.score(rendered), **row}
            methods[name]["per_query"].append(row)
            methods[name]["seconds"] += row.get("seconds", 0.0)
            if out is not None:
                folder = out / "renders" / protocol / name
                folder.mkdir(parents=True, exist_ok=True)
                save_png(folder / f"{query.name}.png", _strip(rendered.rgb))
            log(
                f"{protocol} {q + 1}/{len(world.queries)} {query.name} -> {setup.target} {name}: "
                + ", ".join(
                    f"{k} {row[k]:.4g}"
                    for k in ("seen part_delta_e", "unseen part_delta_e", "seen lowpass_psnr")
                    if k in row
                )
                + (f" ({row['seconds']:.0f} s)" if "seconds" in row else "")
            )
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
            texture, row = _transferred(ablation, setup, generator, vgg, cfg, base, device, cache, run.generator_lit)
            # Stage 2 refines synthesis blocks only: psi is the original's, so the synthesis output is the whole result.
            keep(ablation, judge.render(generator_surface(generator, texture, setup.batch)), dict(row))
    for entry in methods.values():
        entry["query"] = mean_scores(entry["per_query"])
        entry["seconds"] = round(entry["seconds"], 2)
    return {"queries": setups, "methods": methods}


def _baseline(
    name: str, judge: QueryJudge, setup: QuerySetup, generator, vgg, cfg: ProtocolConfig, base, device
) -> tuple:
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
        fit = fit_automaton(
            setup.shape,
            setup.photo,
            setup.view,
            setup.photo_noc,
            vgg,
            base,
            base.automaton,
            device,
            show_progress=False,
        )
        return judge.render(vertex_colour_surface(judge.vertices, judge.triangles, fit.colours.cpu())), {
            "loss_last": fit.losses[-1]
        }
    # backprojection: the photo painted on from the pose the transfer used, framed as the transfer frames it
    try:
        surface = backproject_photo(
            judge.vertices,
            judge.triangles,
            judge.truth.photo[0],
            judge.truth.photo_mask[0, 0],
            setup.azimuth,
            setup.elevation,
            setup.distance,
            setup.fov,
            align="photo" if setup.protocol == "known_pose" else "silhouette",
            margin=base.margin,
        )
    except ValueError as error:
        raise InputError(f"{setup.query.image}: {error}") from None
    return judge.render(surface), {}


def _transferred(
    ablation: str, setup: QuerySetup, generator, vgg, cfg: ProtocolConfig, base, device, cache, generator_lit: bool
) -> tuple:
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
    result = transfer.transfer_texture(
        candidate,
        setup.shape,
        setup.photo,
        setup.view,
        setup.photo_noc if guided else None,
        vgg,
        tcfg,
        device,
        show_progress=False,
        generator_lit=generator_lit,
    )
    with torch.no_grad():
        texture = candidate.synthesize(setup.batch.to(device), result.ws.to(device), noise_mode="none")
    row = {
        "loss_last": {k: v[-1] for k, v in result.losses.items() if v},
        "seconds": round(sum(result.seconds.values()), 2),
        **({"light": result.light} if result.light is not None else {}),
        **({"mirror": result.mirror} if result.mirror is not None else {}),
    }
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


# ------------------------------------------------------------------------------------------- entry
def run_protocols(
    world_dir: str | Path,
    shapes_dir: str | Path,
    gan_checkpoint: str | Path,
    pose_checkpoint: str | Path | None,
    noc_checkpoint: str | Path | None,
    cfg: ProtocolConfig,
    out: Path | None = None,
    log=print,
    overwrite: bool = False,
) -> dict:
    """Run the protocols of ``cfg`` and return the result dict (also written as ``protocols.json`` /
    ``protocols.md`` when ``out`` is given, with the renders under ``out/renders``).

    With ``out``, every finished transfer is kept in ``out/transfers`` (:class:`TransferCache`), so
    re-running after an interruption resumes and a wider run reuses them; ``overwrite`` discards
    transfers made with other settings instead of refusing the run."""
    transfers = [p for p in cfg.protocols if p in TRANSFER_PROTOCOLS]
    _check_networks(cfg, transfers, pose_checkpoint, noc_checkpoint)
    started = time.perf_counter()
    checkpoints = {"gan": gan_checkpoint, "pose": pose_checkpoint, "noc": noc_checkpoint}
    run, notes = _load_inputs(world_dir, shapes_dir, checkpoints, cfg, bool(transfers), out, log, overwrite)
    world, extractor, vgg = run.world, run.extractor, run.vgg
    result = {
        "world": str(world_dir),
        "shapes": str(shapes_dir),
        "gan": str(gan_checkpoint),
        "pose_checkpoint": str(pose_checkpoint) if pose_checkpoint else None,
        "noc_checkpoint": str(noc_checkpoint) if noc_checkpoint else None,
        "features": extractor.description,
        "style_features": getattr(vgg, "source", None),
        "counts": {"queries": len(world.queries), "query_shapes": len(world.query_shapes)},
        "settings": asdict(cfg),
        "protocols": {},
        "comparison": {},
        "warnings": notes,
    }
    per_protocol = len(world.queries) * (len(cfg.baselines) + len(cfg.ablations))
    steps = sum(1 if protocol == "unconditional" else per_protocol for protocol in cfg.protocols)
    bar = progress_bar(total=steps, desc="protocols", unit="result")
    for protocol in cfg.protocols:
        t = time.perf_counter()
        if protocol == "unconditional":
            entry = run_unconditional(run)
            bar.update(1)
        else:
            entry = run_transfer_protocol(protocol, run, step=bar.update)
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


def _load_inputs(
    world_dir, shapes_dir, checkpoints: dict, cfg: ProtocolConfig, style: bool, out: Path | None, log, overwrite: bool
) -> tuple[ProtocolInputs, list[str]]:
    """Everything the protocols share, loaded once (the world, the GAN of ``checkpoints["gan"]``, the prepared
    shapes, the feature networks, the transfer cache when writing to ``out``), and the loaders' warnings."""
    device = select_device(cfg.device)
    world = load_world(world_dir, cfg.queries)
    model = load_generator(checkpoints["gan"], device)
    shapes, targets = _world_shapes(world, shapes_dir, "other_shape" in cfg.protocols, model.network)
    extractor, vgg, notes = _feature_networks(cfg, style, device)
    cache = None if out is None else _transfer_cache(out, world_dir, shapes_dir, checkpoints, cfg, model.lit, overwrite)
    run = ProtocolInputs(
        model.network,
        model.lit,
        model.camera.distance,
        model.camera.fov,
        world,
        shapes,
        targets,
        vgg,
        extractor,
        cfg,
        checkpoints["pose"],
        checkpoints["noc"],
        device,
        out,
        log,
        cache,
    )
    return run, notes


def _transfer_cache(
    out: Path, world_dir, shapes_dir, checkpoints: dict, cfg: ProtocolConfig, generator_lit: bool, overwrite: bool
) -> TransferCache:
    """The finished transfers kept in ``out``, fingerprinted by the settings that change a transfer and by
    the inputs (the world's and shapes' folders, the digests of the ``checkpoints`` {gan, pose, noc})."""
    out.mkdir(parents=True, exist_ok=True)
    inputs = {
        "world": str(Path(world_dir).resolve()),
        "shapes": str(Path(shapes_dir).resolve()),
        **{kind: _file_digest(path, kind) for kind, path in checkpoints.items()},
    }
    return TransferCache(out, {"settings": json_ready(cache_settings(cfg, generator_lit)), "inputs": inputs}, overwrite)


def _check_networks(cfg: ProtocolConfig, transfers: list[str], pose_checkpoint, noc_checkpoint) -> None:
    """InputError, before any work, when the transfer protocols asked for lack a network they need."""
    if transfers:
        check_style_sizes(cfg.transfer_config())
    if any(p != "known_pose" for p in transfers) and not pose_checkpoint:
        raise InputError(
            "the unknown_pose and other_shape protocols need --pose-checkpoint (from 'mesh2tex train pose')"
        )
    if (
        transfers
        and any(ABLATIONS[a].get("use_noc", True) and ABLATIONS[a].get("use_patches", True) for a in cfg.ablations)
        and not noc_checkpoint
    ):
        raise InputError("NOC-guided ablations (full, no_refine) need --noc-checkpoint (from 'mesh2tex train noc')")


def _world_shapes(
    world: World, shapes_dir: str | Path, other_shape: bool, generator
) -> tuple[dict[str, PreparedShape], dict[str, str]]:
    """The prepared shapes the protocols need (the queries' shapes and, for ``other_shape``, each one's
    other shape): ({name: shape}, {query shape: other shape}); InputError naming those not prepared."""
    paths = shape_paths(shapes_dir)
    needed, targets = set(world.query_shapes), {}
    if other_shape:
        targets = {name: other_shape_name(name, list(paths)) for name in world.query_shapes}
        needed |= set(targets.values())
    missing = sorted(needed - set(paths))
    if missing:
        raise InputError(
            f"{shapes_dir}: no prepared shape for {', '.join(missing)} (prepare the world's meshes with 'mesh2tex "
            "prepare shapes')"
        )
    return {name: load_prepared(paths[name], generator) for name in sorted(needed)}, targets


def _feature_networks(cfg: ProtocolConfig, style: bool, device: torch.device) -> tuple:
    """The KID/FID feature extractor and (``style``) the transfer's VGG19; their warnings printed once and
    returned, sorted: (extractor, vgg or None, notes)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        extractor = get_feature_extractor(
            cfg.evaluate.features, cfg.inception_weights or None, cfg.vgg_weights or None, device
        )
        vgg = load_vgg19(cfg.vgg_weights or None, device=device) if style else None
    notes = sorted({str(w.message) for w in caught})
    for note in notes:
        print(f"mesh2tex: warning: {note}", file=sys.stderr)
    return extractor, vgg, notes


def load_prepared(path: Path, generator) -> PreparedShape:
    """A prepared shape of the world (``SHAPES/<name>.npz``), checked against the generator (InputError naming the
    file)."""
    shape = PreparedShape.load(path)
    problem = shape_mismatch(shape, generator)
    if problem:
        raise InputError(f"{path}: has {problem}")
    return shape


def _file_digest(path: str | Path | None, kind: str) -> str | None:
    """:func:`mesh2tex.io.checkpoint.checkpoint_digest` of a path or a shipped model's ``kind`` file, None for None."""
    return None if path is None else checkpoint_digest(resolve_checkpoint(path, kind))
