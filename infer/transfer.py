"""``mesh2tex infer transfer``: texture a mesh after one photo (Mesh2Tex section 3.3).

    mesh2tex infer transfer --checkpoint GAN --mesh MESH --image IMG [--mask M] [--pose auto|AZ,EL]
                            [--pose-checkpoint P] [--noc-checkpoint N] --out DIR
                            [--no-noc] [--no-patches] [--no-refine] [--no-pose-search] [--config YAML] [--overwrite]

Steps:
1. The photo: mask from its alpha channel, from ``--mask``, or estimated (GrabCut); a square crop
   around the object, resized to ``resolution``.
2. The pose: given as ``--pose AZ,EL`` (degrees, the orbit-camera convention), or ``--pose auto``
   (the default, needs ``--pose-checkpoint``): the pose network's bin probabilities, then a search
   for the pose whose silhouette best matches the photo's mask (``--no-pose-search``: the network's
   bin centres, as the paper).
3. Correspondences: the NOC network predicts the photo's NOC map; the mesh's NOC map is rendered at
   the pose. Renders are cropped around the object the same way as the photo, so both images show
   the object at the same scale.
4. Stage 1 optimises the latent ``w`` (all style inputs of the synthesis network) with
   ``w_glob * L_glob + w_patch * L_patch`` (Equation 2); stage 2 unfreezes the last two synthesis
   blocks and optimises their weights with ``L_patch`` only. Adam, lr 1e-2 (paper values).
5. Outputs in ``DIR``: ``textured.glb`` (UV texture baked from psi), ``textured.ply`` (vertex colours),
   ``comparison.png`` (photo | render at the pose | photo NOC | rendered NOC), ``turntable_XX.png`` and
   ``turntable.gif``, ``report.json`` (pose, losses per stage, seconds per stage, settings).

Ablations of the paper's Table 8: ``--no-noc`` (patch pairs without NOC guidance), ``--no-patches``
(global loss only; stage 2 then also uses the global loss), ``--no-refine`` (stage 1 only).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from mesh2tex.config import load_config
from mesh2tex.errors import UserError
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.io.atomic import write_json
from mesh2tex.io.images import load_image, load_mask, save_png
from mesh2tex.losses.style import global_style_loss, patch_style_loss, sample_patch_pairs, style_grams
from mesh2tex.nn.batch import collate_shapes
from mesh2tex.nn.generator import TextureGenerator
from mesh2tex.nn.pose import PoseBins
from mesh2tex.nn.render_texture import rasterize_batch, render_field_views
from mesh2tex.progress import progress_bar
from mesh2tex.render import crop_mask, crop_square, interpolate, object_box, orbit_camera, rasterize, transform_points


@dataclass
class TransferConfig:
    resolution: int = 128  # side of the photo crop and of the optimised renders
    latent_iters: int = 100  # stage 1: iterations on the latent w (paper: 100)
    refine_iters: int = 300  # stage 2: iterations on the last two synthesis blocks (paper: 300)
    refine_blocks: int = 2  # synthesis blocks unfrozen in stage 2 (paper: 2)
    lr: float = 1e-2  # Adam learning rate of both stages (paper: 1e-2)
    w_glob: float = 1.0  # weight of the global style loss
    w_patch: float = 1.0  # weight of the patch style loss
    scales: int = 3  # resolution levels of the global style loss, and of the patch loss when patch_scales is 0 (paper: 3)
    patches: int = 2  # patch pairs per iteration (paper: 2)
    patch_size: int = 32  # side of a patch in pixels (paper: 64; at 128 px crops 32 beats it, docs/protocols.md)
    patch_scales: int = 2  # resolution levels of the patch loss alone (0: ``scales``; 2 keeps 32 px patches at a 16 px coarsest level)
    use_noc: bool = True  # NOC-guided patch pairs (False: random pairs, the "w/o NOC" ablation)
    use_patches: bool = True  # patch style loss (False: the "w/o patch loss" ablation)
    refine: bool = True  # stage 2 (False: the "w/o surface features" ablation)
    margin: float = 0.1  # crop margin around the object, as a share of its larger side
    pose_search: bool = True  # --pose auto: pick the pose whose silhouette best matches the photo's mask (False: the network's bin centres, as the paper)
    pose_search_step: float = 10.0  # azimuth spacing of the silhouette search in degrees (then one finer pass at half of it)
    pose_search_elevations: int = 2  # elevation bins searched: the network's most likely ones
    render_oversample: float = 1.5  # render at this multiple of ``resolution`` before cropping to the object
    turntable_frames: int = 12  # frames of turntable.gif
    texture_size: int = 1024  # side of the baked UV texture in textured.glb
    faces: int = 6144  # finest quad count when a raw mesh is prepared on the fly
    seed: int = 0  # seed of the initial latent and the patch sampling
    device: str = "auto"  # auto, cpu or cuda
    vgg_weights: str = ""  # VGG19 ImageNet weights file ('' looks in $TORCH_HOME, else a random-weight fallback)

    @property
    def patch_levels(self) -> int:
        """Resolution levels the patch loss uses: ``patch_scales``, or ``scales`` when that is 0."""
        return self.patch_scales or self.scales


@dataclass
class Photo:
    """The query, cropped: image (1,3,R,R) in [-1,1]; mask (1,1,R,R) {0,1}."""

    image: torch.Tensor
    mask: torch.Tensor


@dataclass
class View:
    """The mesh seen at the query's pose, cropped like the photo.

    mvp (1,4,4) camera; box (top, left, side) of the crop in the full render of side ``render_size``;
    noc (R,R,3) rendered NOC in [0,1]; mask (1,1,R,R).
    """

    mvp: torch.Tensor
    render_size: int
    box: tuple[int, int, int]
    noc: torch.Tensor
    mask: torch.Tensor


@dataclass
class TransferResult:
    ws: torch.Tensor  # (1, num_ws, w_dim) the optimised latent
    render: torch.Tensor  # (1, 3, R, R) the final render at the pose, cropped, in [-1, 1]
    losses: dict[str, list[float]] = field(default_factory=dict)  # per stage, one value per iteration
    seconds: dict[str, float] = field(default_factory=dict)  # per stage


# ------------------------------------------------------------------------------------- the photo
def load_photo(image_path: str | Path, mask_path: str | Path | None, cfg: TransferConfig) -> tuple[Photo, str]:
    """The query photo cropped around its object; also says where the mask came from."""
    rgb, alpha = load_image(image_path)
    if mask_path is not None:
        mask = load_mask(mask_path)
        if mask.shape != rgb.shape[:2]:
            raise UserError(f"{mask_path}: mask is {mask.shape[1]}x{mask.shape[0]}, the photo {rgb.shape[1]}x{rgb.shape[0]}")
        source = str(mask_path)
    elif alpha is not None and (alpha < 128).any():
        mask, source = alpha >= 128, "alpha channel"
    else:
        from data_prep.images import estimate_mask

        mask, source = estimate_mask(rgb), "estimated (GrabCut)"
    mask = np.asarray(mask, dtype=bool)
    if mask.sum() < 16:
        raise UserError(f"{mask_path or image_path}: the object mask is empty (fewer than 16 object pixels)")
    box = object_box(mask, cfg.margin)
    image = torch.from_numpy(np.array(rgb)).permute(2, 0, 1)[None].contiguous().float() / 127.5 - 1.0
    image = crop_square(image, box, cfg.resolution, fill=1.0)
    return Photo(image=image, mask=crop_mask(mask, box, cfg.resolution)), source


# -------------------------------------------------------------------------------------- the pose
def parse_pose(text: str) -> tuple[float, float] | None:
    """'auto' -> None; 'AZ,EL' -> degrees."""
    if text == "auto":
        return None
    try:
        azimuth, elevation = (float(v) for v in text.split(","))
    except ValueError:
        raise UserError(f"--pose {text!r}: give 'auto' or 'AZIMUTH,ELEVATION' in degrees, e.g. 30,20") from None
    return azimuth, elevation


@torch.no_grad()
def predict_pose(checkpoint: str | Path, photo: Photo, device: torch.device) -> tuple[float, float]:
    """Azimuth and elevation (degrees, bin centres) of the photo by the pose network."""
    return pose_network_beliefs(checkpoint, photo, device).most_likely()


@dataclass
class PoseBeliefs:
    """The pose network's softmax over its bins for one photo: azimuth [A], elevation [E] float32 (CPU)."""

    bins: PoseBins
    azimuth: torch.Tensor
    elevation: torch.Tensor

    def most_likely(self) -> tuple[float, float]:
        """Centres (degrees) of the most likely azimuth and elevation bins."""
        return (float(self.bins.bin_to_azimuth(int(self.azimuth.argmax()))),
                float(self.bins.bin_to_elevation(int(self.elevation.argmax()))))


@torch.no_grad()
def pose_network_beliefs(checkpoint: str | Path, photo: Photo, device: torch.device) -> PoseBeliefs:
    """The pose network's bin probabilities for the photo."""
    from train.view_nets import load_view_network

    net, cfg = load_view_network(checkpoint, "pose", device)
    azimuth_logits, elevation_logits = net(_network_input(photo, cfg.data.resolution, device))
    return PoseBeliefs(net.bins, F.softmax(azimuth_logits, 1)[0].float().cpu(), F.softmax(elevation_logits, 1)[0].float().cpu())


@torch.no_grad()
def silhouette_iou(shape: PreparedShape, photo_mask: torch.Tensor, azimuths: torch.Tensor, elevations: torch.Tensor,
                   distance: float, fov: float, margin: float, size: int = 64, batch: int = 24) -> torch.Tensor:
    """IoU of the photo's object mask with the mesh's silhouette at each pose, both cropped alike.

    photo_mask (1,1,R,R) {0,1}, already cropped around the object with ``margin``; azimuths,
    elevations [N] degrees. Each silhouette is rasterized, cropped around itself with the same
    margin (so the camera distance does not matter) and compared at ``size`` x ``size``. Returns [N].
    """
    target = (F.interpolate(photo_mask.float().cpu(), size=(size, size), mode="area")[0, 0] > 0.5)
    vertices = torch.as_tensor(shape.vertices[0], dtype=torch.float32)
    triangles = torch.as_tensor(shape.triangles(0))
    render = int(round(size * 1.5))
    scores = []
    for start in range(0, azimuths.shape[0], batch):
        camera = orbit_camera(azimuths[start:start + batch].float(), elevations[start:start + batch].float(), distance=distance, fov=fov)
        covered = (rasterize(transform_points(vertices, camera.mvp), triangles, (render, render)).face_id >= 0).numpy()
        for view in covered:
            if view.sum() < 4:
                scores.append(0.0)
                continue
            crop = crop_mask(view, object_box(view, margin), size)[0, 0] > 0.5
            scores.append(float((crop & target).sum()) / max(float((crop | target).sum()), 1.0))
    return torch.tensor(scores)


@dataclass
class PoseEstimate:
    """Where the camera is (degrees) and how it was found; ``network``: the pose network's own bin centres."""

    azimuth: float
    elevation: float
    source: str
    network: tuple[float, float] | None = None
    silhouette_iou: float | None = None  # of the chosen pose
    network_silhouette_iou: float | None = None  # of the network's own pose


def search_pose(shape: PreparedShape, photo: Photo, beliefs: PoseBeliefs, distance: float, fov: float,
                cfg: TransferConfig) -> PoseEstimate:
    """The pose whose silhouette best matches the photo's mask (render and compare).

    The pose network proposes the elevations (the centres of its ``pose_search_elevations`` most
    likely bins); every azimuth ``pose_search_step`` degrees apart is tried with each, then the
    best one's neighbours at half the step in both angles. Silhouettes tell a chair's front from its
    back where the network, trained on few shapes, often does not (docs/style_and_pose.md has figures);
    on ties the network's more likely bin wins.
    """
    bins, step = beliefs.bins, float(cfg.pose_search_step)

    def best_of(azimuths: torch.Tensor, elevations: torch.Tensor) -> tuple[float, float, float]:
        iou = silhouette_iou(shape, photo.mask, azimuths, elevations, distance, fov, cfg.margin)
        prior = beliefs.azimuth[bins.azimuth_to_bin(azimuths)] * beliefs.elevation[bins.elevation_to_bin(elevations)]
        best = int(torch.argmax(iou + 1e-6 * prior))  # the prior only breaks ties
        return float(azimuths[best]), float(elevations[best]), float(iou[best])

    order = beliefs.elevation.argsort(descending=True)[:max(1, cfg.pose_search_elevations)]
    elevations = bins.bin_to_elevation(order).float()
    azimuths = torch.arange(0.0, 360.0, step)
    best_az, best_el, _ = best_of(azimuths.repeat(len(elevations)), elevations.repeat_interleave(len(azimuths)))
    offsets = torch.tensor([-0.5, 0.0, 0.5]) * step
    best_az, best_el, best_iou = best_of((best_az + offsets).repeat(3) % 360.0, (best_el + offsets).repeat_interleave(3))
    network = beliefs.most_likely()
    network_iou = float(silhouette_iou(shape, photo.mask, torch.tensor([network[0]]), torch.tensor([network[1]]),
                                       distance, fov, cfg.margin)[0])
    return PoseEstimate(best_az, best_el, "pose network + silhouette search", network, round(best_iou, 4), round(network_iou, 4))


def estimate_pose(checkpoint: str | Path, shape: PreparedShape, photo: Photo, distance: float, fov: float,
                  cfg: TransferConfig, device: torch.device) -> PoseEstimate:
    """``--pose auto``: the pose network's bins, refined by :func:`search_pose` unless ``cfg.pose_search`` is off."""
    beliefs = pose_network_beliefs(checkpoint, photo, device)
    if cfg.pose_search:
        return search_pose(shape, photo, beliefs, distance, fov, cfg)
    azimuth, elevation = beliefs.most_likely()
    return PoseEstimate(azimuth, elevation, "pose network", (azimuth, elevation))


@torch.no_grad()
def predict_noc(checkpoint: str | Path, photo: Photo, device: torch.device) -> torch.Tensor:
    """(R,R,3) NOC map of the photo in [0,1], by the NOC network."""
    from train.view_nets import load_view_network

    net, cfg = load_view_network(checkpoint, "noc", device)
    size = cfg.data.resolution
    image = _network_input(photo, size, device)
    mask = F.interpolate(photo.mask.to(device), size=(size, size), mode="nearest")
    noc = net(image, mask)
    noc = F.interpolate(noc, size=photo.image.shape[-2:], mode="bilinear", align_corners=False)
    return noc[0].permute(1, 2, 0).cpu()


def _network_input(photo: Photo, size: int, device: torch.device) -> torch.Tensor:
    return F.interpolate(photo.image, size=(size, size), mode="area").to(device)


# --------------------------------------------------------------------------------------- the view
@torch.no_grad()
def view_at_pose(shape: PreparedShape, azimuth: float, elevation: float, distance: float, fov: float, cfg: TransferConfig) -> View:
    """Rasterize the mesh at the pose, find the object's square crop, render its NOC map there."""
    size = int(round(cfg.resolution * cfg.render_oversample))
    camera = orbit_camera(torch.tensor([azimuth]), torch.tensor([elevation]), distance=distance, fov=fov)
    vertices = torch.as_tensor(shape.vertices[0], dtype=torch.float32)
    triangles = torch.as_tensor(shape.triangles(0))
    raster = rasterize(transform_points(vertices, camera.mvp), triangles, (size, size))
    covered = (raster.face_id[0] >= 0).numpy()
    if covered.sum() < 16:
        raise UserError(f"the mesh is not visible at azimuth {azimuth}, elevation {elevation} (distance {distance})")
    box = object_box(covered, cfg.margin)
    noc = interpolate(torch.as_tensor(shape.noc, dtype=torch.float32), raster, triangles)  # (1,S,S,3)
    noc = crop_square(noc.permute(0, 3, 1, 2), box, cfg.resolution)[0].permute(1, 2, 0)
    return View(mvp=camera.mvp, render_size=size, box=box, noc=noc, mask=crop_mask(covered, box, cfg.resolution))


# ------------------------------------------------------------------------------- the optimisation
def transfer_texture(generator: TextureGenerator, shape: PreparedShape, photo: Photo, view: View,
                     photo_noc: torch.Tensor | None, vgg, cfg: TransferConfig, device: torch.device,
                     show_progress: bool = True) -> TransferResult:
    """Optimise the texture of ``shape`` to look like ``photo`` (Equation 2, then refinement).

    ``generator`` is modified in place by stage 2 (its last ``refine_blocks`` synthesis blocks):
    pass a copy if the original is needed again. ``photo_noc`` (R,R,3) is needed when
    ``cfg.use_noc`` and ``cfg.use_patches``.
    """
    guided = cfg.use_noc and cfg.use_patches
    if guided and photo_noc is None:
        raise UserError("NOC-guided patches need the photo's NOC: give --noc-checkpoint, or --no-noc")
    batch = collate_shapes([shape]).to(device)
    generator = generator.to(device).requires_grad_(False)
    encoded = [e.detach() for e in generator.encoder(batch)]
    samples = rasterize_batch(batch, view.mvp.to(device), (view.render_size, view.render_size))
    photo_image, photo_mask = photo.image.to(device), photo.mask.to(device)
    render_mask = view.mask.to(device)
    render_noc = view.noc.to(device)
    photo_noc = photo_noc.to(device) if photo_noc is not None else None
    with torch.no_grad():
        photo_grams = style_grams(vgg, photo_image, photo_mask, cfg.scales)
    grey = torch.zeros(1, 3, device=device)
    pick = torch.Generator().manual_seed(cfg.seed)

    def render(ws: torch.Tensor) -> torch.Tensor:
        full = render_field_views(generator, batch, ws, view.mvp.to(device), (view.render_size,) * 2, grey,
                                  encoded=encoded, noise_mode="none", samples=samples).images
        return crop_square(full, view.box, cfg.resolution)

    def loss_of(image: torch.Tensor, use_global: bool) -> tuple[torch.Tensor, dict[str, float]]:
        parts: dict[str, torch.Tensor] = {}
        if use_global:
            parts["global"] = cfg.w_glob * global_style_loss(vgg, image, render_mask, target_grams=photo_grams, scales=cfg.scales)
        if cfg.use_patches:
            pairs = sample_patch_pairs(photo_mask[0, 0], render_mask[0, 0], cfg.patches, photo_noc, render_noc, guided=guided, generator=pick)
            parts["patch"] = cfg.w_patch * patch_style_loss(vgg, image, render_mask, photo_image, photo_mask, pairs, cfg.patch_size, cfg.patch_levels)
        total = sum(parts.values())
        return total, {k: float(v.detach()) for k, v in parts.items()}

    with torch.no_grad():
        ws = generator.mapping.w_avg.reshape(1, 1, -1).expand(1, generator.num_ws, -1).clone()
    ws.requires_grad_(True)
    result = TransferResult(ws=ws, render=torch.empty(0))

    def optimise(stage: str, params: list[torch.Tensor], iters: int, use_global: bool) -> None:
        opt = torch.optim.Adam(params, lr=cfg.lr)
        history: list[float] = []
        start = time.perf_counter()
        iterator = progress_bar(range(iters), desc=f"transfer {stage}") if show_progress else range(iters)
        for _ in iterator:
            total, parts = loss_of(render(ws), use_global)
            if not torch.isfinite(total):
                raise UserError(f"transfer {stage}: the style loss became {float(total)}; lower the learning rate (lr)")
            opt.zero_grad(set_to_none=True)
            total.backward()
            opt.step()
            value = float(total.detach())
            history.append(round(value, 6))
            if show_progress:
                iterator.set_postfix(loss=f"{value:.4f}")
        result.losses[stage] = history
        result.seconds[stage] = round(time.perf_counter() - start, 2)

    optimise("latent", [ws], cfg.latent_iters, use_global=True)
    if cfg.refine and cfg.refine_iters > 0:
        ws.requires_grad_(False)
        params = generator.last_synthesis_parameters(cfg.refine_blocks)
        for p in params:
            p.requires_grad_(True)
        # Stage 2 uses the patch loss alone (paper); without patches it keeps the global loss.
        optimise("refine", params, cfg.refine_iters, use_global=not cfg.use_patches)
        for p in params:
            p.requires_grad_(False)
    with torch.no_grad():
        result.render = render(ws).cpu()
    result.ws = ws.detach()
    return result


# ------------------------------------------------------------------------------------------ outputs
def to_uint8_image(image: torch.Tensor) -> np.ndarray:
    """(1,3,H,W) or (3,H,W) in [-1,1] -> (H,W,3) uint8."""
    image = image.reshape(-1, *image.shape[-3:])[0]
    return ((image.clamp(-1, 1) + 1) * 127.5).round().to(torch.uint8).permute(1, 2, 0).cpu().numpy()


def noc_to_uint8(noc: torch.Tensor, mask: torch.Tensor) -> np.ndarray:
    """(H,W,3) NOC in [0,1] and a (…,H,W) mask -> (H,W,3) uint8, white background."""
    m = mask.reshape(noc.shape[:2] + (1,)).cpu()
    return ((noc.cpu().clamp(0, 1) * m + (1 - m)) * 255).round().to(torch.uint8).numpy()


@torch.no_grad()
def write_outputs(out: Path, generator: TextureGenerator, shape: PreparedShape, result: TransferResult, photo: Photo,
                  view: View, photo_noc: torch.Tensor | None, distance: float, fov: float, elevation: float,
                  cfg: TransferConfig, device: torch.device) -> dict[str, str]:
    """textured.glb/.ply, comparison.png, turntable frames and GIF; returns {what: file name}."""
    from PIL import Image

    from infer.generate import bake_texture, vertex_colors
    from mesh2tex.io.assets import save_glb, save_ply, smooth_vertex_normals
    from mesh2tex.io.atomic import atomic_path

    batch = collate_shapes([shape]).to(device)
    texture = generator.synthesize(batch, result.ws.to(device), noise_mode="none")
    verts, faces, uv, tex, _ = bake_texture(generator, texture, batch, cfg.texture_size)
    save_glb(out / "textured.glb", verts.numpy(), faces.numpy(), uv.numpy(), tex, smooth_vertex_normals(verts.numpy(), faces.numpy()))
    save_ply(out / "textured.ply", batch.shape_vertices(0).cpu().numpy(), batch.shape_triangles(0).cpu().numpy(),
             vertex_colors(generator, texture, batch))

    white_photo = photo.image * photo.mask + (1 - photo.mask)
    white_render = result.render * view.mask + (1 - view.mask)
    panels = [to_uint8_image(white_photo), to_uint8_image(white_render)]
    if photo_noc is not None:
        panels.append(noc_to_uint8(photo_noc, photo.mask))
    panels.append(noc_to_uint8(view.noc, view.mask))
    save_png(out / "comparison.png", np.concatenate(panels, axis=1))

    frames = []
    k = cfg.turntable_frames
    azimuths = torch.arange(k, dtype=torch.float32) * (360.0 / k)
    mvp = orbit_camera(azimuths, torch.full((k,), elevation), distance=distance, fov=fov).mvp.to(device)
    size = cfg.resolution * 2
    views = render_field_views(generator, batch, result.ws.to(device), mvp, (size, size), torch.ones(k, 3, device=device),
                               texture=texture, noise_mode="none")
    for i in range(k):
        frame = to_uint8_image(views.images[i])
        save_png(out / f"turntable_{i:02d}.png", frame)
        frames.append(Image.fromarray(frame))
    with atomic_path(out / "turntable.gif") as tmp:
        frames[0].save(tmp, format="GIF", save_all=True, append_images=frames[1:], duration=120, loop=0)
    return {"glb": "textured.glb", "ply": "textured.ply", "comparison": "comparison.png", "turntable": "turntable.gif"}


# -------------------------------------------------------------------------------------------- stage
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--checkpoint", required=True, help="GAN checkpoint (RUN/checkpoint.safetensors from 'train gan'), or a shipped "
                        "model's name (chair, car), which also supplies the pose and NOC networks unless given")
    parser.add_argument("--mesh", required=True, help="the mesh to texture: a prepared shape (.npz) or a mesh file")
    parser.add_argument("--image", required=True, help="the query photo")
    parser.add_argument("--mask", help="object mask of the photo (white = object); default: alpha channel or an estimate")
    parser.add_argument("--pose", default="auto", help="'auto' (pose network) or AZIMUTH,ELEVATION in degrees")
    parser.add_argument("--pose-checkpoint", help="pose network checkpoint (from 'train pose'), for --pose auto")
    parser.add_argument("--noc-checkpoint", help="NOC network checkpoint (from 'train noc'), for NOC-guided patches")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--config", help="YAML file with any fields of the transfer config")
    parser.add_argument("--resolution", type=int, help="side of the photo crop and the renders (default 128)")
    parser.add_argument("--latent-iters", type=int, help="stage 1 iterations (default 100)")
    parser.add_argument("--refine-iters", type=int, help="stage 2 iterations (default 300)")
    parser.add_argument("--no-noc", action="store_true", help="ablation: patch pairs without NOC guidance")
    parser.add_argument("--no-patches", action="store_true", help="ablation: global style loss only")
    parser.add_argument("--no-refine", action="store_true", help="ablation: optimise the latent only")
    parser.add_argument("--no-pose-search", action="store_true",
                        help="--pose auto takes the pose network's bin centres as they are (the paper), without the silhouette search")
    parser.add_argument("--vgg-weights", help="VGG19 ImageNet weights (torchvision's vgg19-dcbb9e9d.pth)")
    parser.add_argument("--device", choices=["auto", "cpu", "cuda"], help="where to run")
    parser.add_argument("--seed", type=int, help="random seed")
    parser.add_argument("--overwrite", action="store_true", help="replace the results already in --out")


def check_style_sizes(cfg: TransferConfig) -> None:
    """UserError unless the crop and the patches keep 16 pixels at the coarsest level of their style losses."""
    if cfg.scales < 1 or cfg.patch_scales < 0:
        raise UserError(f"scales {cfg.scales}, patch_scales {cfg.patch_scales}: scales must be at least 1, patch_scales at least 0")
    smallest = 16 * 2 ** (cfg.scales - 1)
    if cfg.resolution < smallest:
        raise UserError(f"--resolution {cfg.resolution}: must be at least {smallest} for {cfg.scales} style scales")
    patch = min(cfg.patch_size, cfg.resolution)  # a patch is clipped to the crop
    if cfg.use_patches and patch < 16 * 2 ** (cfg.patch_levels - 1):
        raise UserError(f"patch_size {cfg.patch_size}: a patch of {patch} px keeps fewer than 16 px at its "
                        f"{cfg.patch_levels} style scales; use larger patches or fewer patch_scales")


def build_config(args) -> TransferConfig:
    overrides = {"resolution": args.resolution, "latent_iters": args.latent_iters, "refine_iters": args.refine_iters,
                 "device": args.device, "seed": args.seed, "vgg_weights": args.vgg_weights,
                 "use_noc": False if args.no_noc else None, "use_patches": False if args.no_patches else None,
                 "refine": False if args.no_refine else None, "pose_search": False if args.no_pose_search else None}
    cfg = load_config(TransferConfig, args.config, overrides)
    check_style_sizes(cfg)
    if cfg.latent_iters < 0 or cfg.refine_iters < 0:
        raise UserError("--latent-iters and --refine-iters must not be negative")
    if not 0 < cfg.pose_search_step <= 90 or cfg.pose_search_elevations < 1:
        raise UserError(f"pose_search_step {cfg.pose_search_step}, pose_search_elevations {cfg.pose_search_elevations}: "
                        "the step must be in (0, 90] degrees and at least one elevation bin searched")
    return cfg


def run(args) -> int:
    from infer.generate import load_generator, load_shape
    from mesh2tex.nn.vgg import load_vgg19
    from train.runs import select_device

    cfg = build_config(args)
    out = Path(args.out)
    if (out / "report.json").exists() and not args.overwrite:
        raise UserError(f"{out}: already holds a transfer result (report.json); pass --overwrite to replace it")
    pose = parse_pose(args.pose)
    from mesh2tex.io.models import is_model_name

    if is_model_name(args.checkpoint):  # a shipped model brings its own pose and NOC networks
        args.pose_checkpoint = args.pose_checkpoint or args.checkpoint
        args.noc_checkpoint = args.noc_checkpoint or args.checkpoint
    if pose is None and not args.pose_checkpoint:
        raise UserError("--pose auto needs --pose-checkpoint (from 'mesh2tex train pose'), or give --pose AZIMUTH,ELEVATION")
    if cfg.use_noc and cfg.use_patches and not args.noc_checkpoint:
        raise UserError("NOC-guided patches need --noc-checkpoint (from 'mesh2tex train noc'); or pass --no-noc")
    device = select_device(cfg.device)
    torch.manual_seed(cfg.seed)
    started = time.perf_counter()
    seconds: dict[str, float] = {}

    generator, meta = load_generator(args.checkpoint, device)
    camera = meta.get("config", {}).get("camera", {})
    distance, fov = float(camera.get("distance", 1.7)), float(camera.get("fov", 40.0))
    shape = load_shape(args.mesh, generator, cfg.faces, cfg.seed)
    photo, mask_source = load_photo(args.image, args.mask, cfg)
    seconds["load"] = round(time.perf_counter() - started, 2)

    t = time.perf_counter()
    if pose is None:
        estimate = estimate_pose(args.pose_checkpoint, shape, photo, distance, fov, cfg, device)
    else:
        estimate = PoseEstimate(pose[0], pose[1], "given")
    azimuth, elevation, pose_source = estimate.azimuth, estimate.elevation, estimate.source
    photo_noc = predict_noc(args.noc_checkpoint, photo, device) if args.noc_checkpoint else None
    view = view_at_pose(shape, azimuth, elevation, distance, fov, cfg)
    seconds["pose_and_noc"] = round(time.perf_counter() - t, 2)

    vgg = load_vgg19(cfg.vgg_weights or None, device=device)
    result = transfer_texture(generator, shape, photo, view, photo_noc, vgg, cfg, device)
    seconds.update({f"stage_{k}": v for k, v in result.seconds.items()})

    t = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    files = write_outputs(out, generator, shape, result, photo, view, photo_noc, distance, fov, elevation, cfg, device)
    save_png(out / "photo_crop.png", to_uint8_image(photo.image))
    save_png(out / "render_at_pose.png", to_uint8_image(result.render))
    seconds["outputs"] = round(time.perf_counter() - t, 2)
    seconds["total"] = round(time.perf_counter() - started, 2)
    report = {
        "image": str(args.image), "mesh": str(args.mesh), "checkpoint": str(args.checkpoint),
        "mask_source": mask_source,
        "pose": {"azimuth": azimuth, "elevation": elevation, "source": pose_source, "distance": distance, "fov": fov,
                 **({"network": list(estimate.network), "silhouette_iou": estimate.silhouette_iou,
                     "network_silhouette_iou": estimate.network_silhouette_iou} if estimate.silhouette_iou is not None else {})},
        "noc_guidance": bool(cfg.use_noc and cfg.use_patches),
        "losses": {stage: {"first": h[0] if h else None, "last": h[-1] if h else None, "curve": h} for stage, h in result.losses.items()},
        "seconds": seconds,
        "vgg": {"source": vgg.source, "pretrained": vgg.pretrained},
        "settings": asdict(cfg),
        "files": {**files, "photo_crop": "photo_crop.png", "render_at_pose": "render_at_pose.png"},
    }
    write_json(out / "report.json", report)
    print(f"textured {args.mesh} after {args.image}: pose az {azimuth:.0f} el {elevation:.0f} ({pose_source}); "
          f"{seconds['total']:.0f} s; {out / 'textured.glb'}, {out / 'report.json'}")
    return 0
