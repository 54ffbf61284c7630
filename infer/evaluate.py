"""``mesh2tex evaluate``: metrics between a folder of renders and a folder of images.

Two modes:

* sets (default): the renders against an image collection, unpaired. KID and FID on the features
  of a named extractor (standard Inception-v3 from a local weight file, else clearly named
  substitutes, see :mod:`mesh2tex.metrics.features`), the sliced Wasserstein distance on
  Laplacian-pyramid patches, and the total-variation distance between the sets' pooled colour
  histograms. Images are centre-cropped to squares and resized to ``--resolution``.
* pairs (``--pairs``): each render against the image of the same file stem, for renders whose
  geometry and pose match exactly: masked PSNR, masked SSIM, colour-histogram distance, per pair and
  averaged. Pairs must have the same size.

Masks: the alpha channel of an RGBA file, and/or a file of the same stem in ``--masks DIR``
(white = object). In sets mode masked pixels' background is replaced by ``--background`` (renders
and images alike) so that backgrounds do not dominate the comparison; in pairs mode the metrics are
computed over the mask (the ``--masks`` file, else the intersection of the alpha channels).

The library entry points :func:`evaluate_sets` and :func:`evaluate_pairs` take tensors and return
plain dicts; the command writes ``OUT/metrics.json`` and ``OUT/metrics.md``.

``--generation`` measures a texture GAN against a synthetic world's ground truth (trained, untrained
and oracle rows, the gap closed, diversity across latents): see :mod:`infer.generation`.

``--protocols`` runs the paper's evaluation protocols on a synthetic world instead (unconditional
generation; transfer with known pose, unknown pose, to another shape; each with the ablations of
Table 8): see :mod:`infer.protocols`.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image, UnidentifiedImageError

from mesh2tex.errors import UserError
from mesh2tex.io.atomic import write_json, write_text
from mesh2tex.metrics import (EXTRACTOR_NAMES, FeatureExtractor, color_histogram_distance, color_histograms, fid,
                              get_feature_extractor, kid, masked_psnr, masked_ssim, swd_per_level)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".webp", ".tif", ".tiff")
BACKGROUNDS = {"white": 1.0, "black": 0.0, "grey": 0.5}


@dataclass
class EvaluateConfig:
    resolution: int = 128  # sets mode: square side images are resized to (pairs keep their size)
    features: str = "auto"  # KID/FID features: auto, inception, tvinception, vgg or randvgg
    kid_subsets: int = 100  # random subsets averaged by KID
    kid_subset_size: int = 1000  # vectors per KID subset (at most the smaller set's size)
    swd_patches_per_image: int = 128  # 7x7 descriptors per image and pyramid level for SWD
    swd_projections: int = 512  # random directions per SWD repeat
    swd_repeats: int = 4  # SWD repeats averaged
    histogram_bins: int = 8  # bins per colour channel of the joint RGB histogram
    background: str = "white"  # sets mode: colour replacing masked-out pixels (white, black, grey)
    seed: int = 0  # seed of KID subsets and SWD sampling


# ----------------------------------------------------------------------------------------------
# Metrics on tensors (the library API)


def evaluate_sets(renders: torch.Tensor, images: torch.Tensor, extractor: FeatureExtractor | None = None,
                  config: EvaluateConfig | None = None, render_masks: torch.Tensor | None = None,
                  image_masks: torch.Tensor | None = None, kid_fid: bool = True) -> dict:
    """Unpaired metrics between renders [N, 3, H, W] and images [M, 3, H, W], both float in [0, 1], same H, W.

    ``extractor``: KID/FID features (default: ``get_feature_extractor(config.features)``; metric
    names carry its suffix, e.g. ``kid_randvgg``). ``render_masks`` [N, 1, H, W] and ``image_masks``
    [M, 1, H, W] (1 on the object): with both, the colour histograms pool object pixels only
    (``color_hist_tv``); without, every pixel, background included, and the metric is named
    ``color_hist_tv_whole_image`` (it then also measures how much of each image the object covers).
    KID, FID and SWD always see the whole images (objects on their background, as in the paper).
    ``kid_fid=False`` skips KID and FID (and the feature network, most of the cost; ``features`` is None).
    Returns {"metrics": {name: value}, "features": description, "counts": {"renders": N, "images": M}}.
    KID has a ``<name>_std`` entry (spread over subsets); SWD has one entry per pyramid level (``swd_<side>px``).
    """
    config = config or EvaluateConfig()
    if renders.shape[0] < 2 or images.shape[0] < 2:
        raise UserError(f"set metrics need at least 2 renders and 2 images (got {renders.shape[0]} and {images.shape[0]})")
    metrics: dict[str, float] = {}
    if kid_fid:
        extractor = extractor or get_feature_extractor(config.features)
        features_renders = extractor(renders * 2 - 1)
        features_images = extractor(images * 2 - 1)
        kid_mean, kid_std = kid(features_images, features_renders, config.kid_subsets, config.kid_subset_size, config.seed)
        metrics[extractor.metric_name("kid")] = kid_mean
        metrics[extractor.metric_name("kid") + "_std"] = kid_std
        metrics[extractor.metric_name("fid")] = fid(features_images, features_renders)
    metrics.update(swd_per_level(images, renders, config.swd_patches_per_image, num_projections=config.swd_projections,
                                 repeats=config.swd_repeats, seed=config.seed))
    metrics.update(pooled_histogram_distance(renders, images, render_masks, image_masks, config.histogram_bins))
    return {"metrics": metrics, "features": extractor.description if kid_fid else None,
            "counts": {"renders": int(renders.shape[0]), "images": int(images.shape[0])}}


def pooled_histogram_distance(renders: torch.Tensor, images: torch.Tensor, render_masks: torch.Tensor | None,
                              image_masks: torch.Tensor | None, bins: int) -> dict[str, float]:
    """TV distance between the colour histograms of two sets, each pooled as one distribution of pixels:
    {"color_hist_tv": d} over object pixels when both sets have masks, else {"color_hist_tv_whole_image": d}.

    Pooling counts every object pixel once (a large object weighs more than a small one), so the
    distance compares the colours of the two sets, not of single images."""
    if render_masks is None or image_masks is None:
        name, render_masks, image_masks = "color_hist_tv_whole_image", None, None
    else:
        name = "color_hist_tv"
        if render_masks.sum() == 0 or image_masks.sum() == 0:
            raise UserError("set colour histograms: one of the sets has no object pixel (all masks empty)")

    def pooled(x: torch.Tensor, masks: torch.Tensor | None) -> torch.Tensor:
        def stacked(t: torch.Tensor) -> torch.Tensor:  # [N, C, H, W] -> one [1, C, N*H, W] image
            return t.transpose(0, 1).reshape(1, t.shape[1], -1, t.shape[-1])

        return color_histograms(stacked(x), None if masks is None else stacked(masks), bins)[0]

    return {name: float(0.5 * (pooled(renders, render_masks) - pooled(images, image_masks)).abs().sum())}


def evaluate_pairs(renders: torch.Tensor, images: torch.Tensor, masks: torch.Tensor | None = None,
                   names: list[str] | None = None, config: EvaluateConfig | None = None) -> dict:
    """Paired metrics: renders and images [N, 3, H, W] float in [0, 1], masks [N, 1, H, W] in {0, 1} or None.

    Returns {"metrics": {"psnr_masked", "ssim_masked", "color_hist_tv"} (means over pairs; PSNR is
    +inf if every pair is identical), "per_pair": [{"name", "psnr_masked", "ssim_masked", "color_hist_tv"}],
    "counts": {"pairs": N}}.
    """
    config = config or EvaluateConfig()
    if renders.shape != images.shape:
        raise UserError(f"paired metrics need renders and images of one shape, got {tuple(renders.shape)} and {tuple(images.shape)}")
    if masks is not None and bool((masks.flatten(1).sum(1) == 0).any()):
        empty = int((masks.flatten(1).sum(1) == 0).nonzero()[0])
        raise UserError(f"the mask of pair '{names[empty] if names else empty}' is empty")
    psnr = masked_psnr(renders, images, masks)
    ssim = masked_ssim(renders, images, masks)
    histogram = color_histogram_distance(renders, images, masks, bins=config.histogram_bins)
    names = names or [str(i) for i in range(renders.shape[0])]
    per_pair = [{"name": name, "psnr_masked": float(p), "ssim_masked": float(s), "color_hist_tv": float(h)}
                for name, p, s, h in zip(names, psnr, ssim, histogram)]
    metrics = {"psnr_masked": float(psnr.mean()), "ssim_masked": float(ssim.mean()), "color_hist_tv": float(histogram.mean())}
    return {"metrics": metrics, "per_pair": per_pair, "counts": {"pairs": int(renders.shape[0])}}


METRIC_MEANINGS = {
    "kid": "Kernel Inception Distance (FID Inception-v3 features), lower is better",
    "fid": "Frechet Inception Distance (FID Inception-v3 features), lower is better",
    "swd": "sliced Wasserstein distance x1e3 on Laplacian-pyramid 7x7 patches, mean over levels, lower is better",
    "color_hist_tv": "total-variation distance of joint RGB histograms of object pixels, 0 (same colours) to 1, lower is better",
    "color_hist_tv_whole_image": "the same over every pixel, background included (no masks given), lower is better",
    "psnr_masked": "PSNR in dB over the mask, higher is better",
    "ssim_masked": "SSIM over the mask, 1 is identical",
}


def describe_metric(name: str) -> str:
    """One line saying what a metric name means (suffixes name substitute features)."""
    if name in METRIC_MEANINGS:
        return METRIC_MEANINGS[name]
    base, _, suffix = name.partition("_")
    if name.startswith("swd_") and name.endswith("px"):
        return f"SWD x1e3 at the {name[4:]} pyramid level"
    if base in ("kid", "fid"):
        if suffix.endswith("_std"):
            return "standard deviation of KID over subsets"
        what = {"randvgg": "random-weight VGG19 statistics (no pretrained weights; NOT standard " + base.upper() + ")",
                "vgg": "ImageNet VGG19 statistics (not standard " + base.upper() + ")",
                "tvinception": "torchvision Inception-v3 features (close to, not equal to, standard " + base.upper() + ")"}
        return f"{base.upper()} on {what.get(suffix, suffix + ' features')}, lower is better"
    if name == "kid_std":
        return "standard deviation of KID over subsets"
    return ""


# ----------------------------------------------------------------------------------------------
# Files


def list_images(folder: str | Path, what: str) -> dict[str, Path]:
    """{file stem: path} of the image files in ``folder`` (sorted); UserError if missing, empty or ambiguous."""
    folder = Path(folder)
    if not folder.is_dir():
        raise UserError(f"{folder}: {what} folder not found")
    found: dict[str, Path] = {}
    for path in sorted(folder.iterdir()):
        if path.suffix.lower() in IMAGE_SUFFIXES and path.is_file():
            if path.stem in found:
                raise UserError(f"{folder}: two {what} files share the name '{path.stem}' ({found[path.stem].name}, {path.name})")
            found[path.stem] = path
    if not found:
        raise UserError(f"{folder}: no {what} images ({', '.join(IMAGE_SUFFIXES)})")
    return found


def load_image(path: Path) -> tuple[torch.Tensor, torch.Tensor | None]:
    """RGB [3, H, W] float in [0, 1] and alpha [1, H, W] (None without an alpha channel); UserError if not an image."""
    try:
        with Image.open(path) as image:
            image.load()
            has_alpha = image.mode in ("RGBA", "LA") or (image.mode == "P" and "transparency" in image.info)
            array = np.asarray(image.convert("RGBA" if has_alpha else "RGB"), dtype=np.float32) / 255.0
    except (UnidentifiedImageError, OSError, ValueError) as error:
        raise UserError(f"{path}: not a readable image ({error.__class__.__name__})") from None
    tensor = torch.from_numpy(array).permute(2, 0, 1).contiguous()
    return (tensor[:3], tensor[3:]) if has_alpha else (tensor, None)


def load_mask(path: Path) -> torch.Tensor:
    """A mask file -> [1, H, W] float in {0, 1} (object where the grey value or alpha exceeds one half)."""
    rgb, alpha = load_image(path)
    value = alpha if alpha is not None else rgb.mean(0, keepdim=True)
    return (value > 0.5).float()


def square_resize(image: torch.Tensor, resolution: int) -> torch.Tensor:
    """Centre-crop [C, H, W] to a square and resize it (antialiased bilinear) to resolution^2."""
    height, width = image.shape[-2:]
    side = min(height, width)
    top, left = (height - side) // 2, (width - side) // 2
    crop = image[:, top:top + side, left:left + side]
    if side == resolution:
        return crop
    return F.interpolate(crop[None], size=(resolution, resolution), mode="bilinear", align_corners=False, antialias=True)[0]


def _mask_for(stem: str, alpha: torch.Tensor | None, masks: dict[str, Path] | None) -> torch.Tensor | None:
    if masks is not None and stem in masks:
        return load_mask(masks[stem])
    return None if alpha is None else (alpha > 0.5).float()


def load_set(folder: str | Path, what: str, resolution: int, background: float,
             masks: dict[str, Path] | None = None) -> tuple[torch.Tensor, torch.Tensor | None]:
    """All images of ``folder`` as [N, 3, R, R] in [0, 1], masked-out pixels set to ``background``, and
    their object masks [N, 1, R, R] (0/1) when every image has one (a ``masks`` file or an alpha
    channel), else None."""
    images, object_masks = [], []
    for stem, path in list_images(folder, what).items():
        rgb, alpha = load_image(path)
        mask = _mask_for(stem, alpha, masks)
        if mask is not None:
            if mask.shape[-2:] != rgb.shape[-2:]:
                raise UserError(f"{masks[stem] if masks and stem in masks else path}: mask size {tuple(mask.shape[-2:])} differs from the image's {tuple(rgb.shape[-2:])}")
            rgb = rgb * mask + background * (1 - mask)
            object_masks.append((square_resize(mask.reshape(1, *mask.shape[-2:]), resolution) > 0.5).float())
        images.append(square_resize(rgb, resolution))
    return torch.stack(images), (torch.stack(object_masks) if len(object_masks) == len(images) else None)


def load_pairs(renders_dir: str | Path, images_dir: str | Path, masks: dict[str, Path] | None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None, list[str]]:
    """Renders and images matched by file stem, with masks; UserError for unmatched names or size mismatches."""
    renders = list_images(renders_dir, "render")
    images = list_images(images_dir, "image")
    missing = sorted(set(renders) - set(images))
    if missing:
        raise UserError(f"{images_dir}: no image for render(s) {', '.join(missing[:5])}{' ...' if len(missing) > 5 else ''} (pairs match by file name)")
    names = sorted(renders)
    render_list, image_list, mask_list = [], [], []
    any_mask = False
    for name in names:
        render, render_alpha = load_image(renders[name])
        image, image_alpha = load_image(images[name])
        if render.shape != image.shape:
            raise UserError(f"{images[name]}: size {tuple(image.shape[-2:])} differs from its render's {tuple(render.shape[-2:])}")
        if masks is not None and name in masks:
            mask = load_mask(masks[name])
        elif render_alpha is not None or image_alpha is not None:
            alphas = [(a > 0.5).float() for a in (render_alpha, image_alpha) if a is not None]
            mask = alphas[0] if len(alphas) == 1 else alphas[0] * alphas[1]
        else:
            mask = None
        if mask is not None and mask.shape[-2:] != render.shape[-2:]:
            raise UserError(f"mask of '{name}': size {tuple(mask.shape[-2:])} differs from the render's {tuple(render.shape[-2:])}")
        any_mask = any_mask or mask is not None
        render_list.append(render)
        image_list.append(image)
        mask_list.append(mask if mask is not None else torch.ones_like(render[:1]))
    if len({tuple(r.shape) for r in render_list}) > 1:
        raise UserError(f"{renders_dir}: renders of different sizes; paired metrics need one size")
    return torch.stack(render_list), torch.stack(image_list), torch.stack(mask_list) if any_mask else None, names


def _json_value(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, dict):
        return {k: _json_value(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_json_value(v) for v in value]
    return value


def markdown_table(result: dict) -> str:
    """The metrics of an evaluation result as a markdown table with one line of meaning per metric."""
    lines = ["| metric | value | meaning |", "| --- | --- | --- |"]
    metrics = result["metrics"]
    for name, value in metrics.items():
        if name.endswith("_std"):
            continue
        shown = f"{value:.4g}" if isinstance(value, float) and math.isfinite(value) else str(value)
        if f"{name}_std" in metrics:
            shown += f" ± {metrics[name + '_std']:.2g}"
        lines.append(f"| {name} | {shown} | {describe_metric(name)} |")
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------------------------
# Command line


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from infer.protocols import add_protocol_arguments

    parser.add_argument("--renders", help="folder of rendered images (PNG/JPEG; RGBA alpha is the mask); required unless --protocols")
    parser.add_argument("--images", help="folder of reference images (photos, or ground-truth renders with --pairs); required unless --protocols")
    parser.add_argument("--masks", help="folder of masks named like the images (white = object)")
    parser.add_argument("--pairs", action="store_true", help="paired metrics (PSNR, SSIM, histogram) between files of the same name")
    parser.add_argument("--out", required=True, help="output folder for metrics.json and metrics.md")
    parser.add_argument("--resolution", type=int, help="sets mode: square side images are resized to (default 128)")
    parser.add_argument("--features", choices=EXTRACTOR_NAMES, help="KID/FID features (default auto: Inception if its weights are found, else randvgg)")
    parser.add_argument("--inception-weights", help="Inception-v3 weight file (pt_inception-2015-12-05 or torchvision's inception_v3_google)")
    parser.add_argument("--vgg-weights", help="VGG19 weight file (torchvision's vgg19-dcbb9e9d.pth), for --features vgg")
    parser.add_argument("--kid-subsets", type=int, help="KID subsets (default 100)")
    parser.add_argument("--kid-subset-size", type=int, help="KID subset size (default 1000)")
    parser.add_argument("--background", choices=sorted(BACKGROUNDS), help="sets mode: colour for masked-out pixels (default white)")
    parser.add_argument("--device", default="auto", help="auto, cpu or cuda")
    parser.add_argument("--seed", type=int, help="seed for KID subsets and SWD sampling (default 0)")
    parser.add_argument("--overwrite", action="store_true", help="replace metrics already in --out")
    add_protocol_arguments(parser)
    parser.add_argument("--generation", action="store_true",
                        help="the generation protocol: --gan against --world's ground truth on the held-out shapes in --shapes")
    parser.add_argument("--latents", type=int, help="--generation: latents per held-out shape for the diversity measures (default 16)")


def run_generation_command(args: argparse.Namespace) -> int:
    """``mesh2tex evaluate --generation``: OUT/generation.json, OUT/generation.md, OUT/generation_samples.png."""
    from infer.generation import GenerationConfig, generation_markdown, run_generation_protocol
    from mesh2tex.config import load_config

    for flag in ("world", "shapes", "gan"):
        if not getattr(args, flag):
            raise UserError(f"--generation needs --{flag}")
    cfg = load_config(GenerationConfig, None, {"latents": args.latents, "resolution": args.resolution, "features": args.features,
                                               "seed": args.seed})
    if cfg.latents < 2:
        raise UserError(f"--latents {cfg.latents}: diversity needs at least 2")
    out = Path(args.out)
    if (out / "generation.json").exists() and not args.overwrite:
        raise UserError(f"{out}: already holds generation results (generation.json); pass --overwrite to replace them")
    if args.device not in ("auto", "cpu", "cuda"):
        raise UserError(f"--device {args.device}: expected auto, cpu or cuda")
    device = torch.device(("cuda" if torch.cuda.is_available() else "cpu") if args.device == "auto" else args.device)
    extractor = None
    if cfg.kid_fid:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            extractor = get_feature_extractor(cfg.features, args.inception_weights, args.vgg_weights, device)
        for warning in caught:
            print(f"mesh2tex: warning: {warning.message}", file=sys.stderr)
    out.mkdir(parents=True, exist_ok=True)
    result = run_generation_protocol(args.world, args.shapes, args.gan, cfg, device, extractor, out / "generation_samples.png",
                                     log=lambda line: print(line, file=sys.stderr, flush=True))
    write_json(out / "generation.json", _json_value(result))
    text = generation_markdown(result)
    write_text(out / "generation.md", text)
    print(text, end="")
    print(f"wrote {out / 'generation.json'}, {out / 'generation.md'} and {out / 'generation_samples.png'} ({result['seconds']:.0f} s)")
    return 0


def run(args: argparse.Namespace) -> int:
    from mesh2tex.config import load_config

    if getattr(args, "generation", False):
        return run_generation_command(args)
    if getattr(args, "protocols", False):
        from infer.protocols import run_protocols_command

        return run_protocols_command(args)
    if not args.renders or not args.images:
        raise UserError("evaluate needs --renders and --images (or --protocols with --world, --shapes and --gan)")
    config = load_config(EvaluateConfig, None, {
        "resolution": args.resolution, "features": args.features, "kid_subsets": args.kid_subsets,
        "kid_subset_size": args.kid_subset_size, "background": args.background, "seed": args.seed})
    if config.resolution < 16:
        raise UserError(f"--resolution {config.resolution}: must be at least 16")
    out = Path(args.out)
    targets = [out / "metrics.json", out / "metrics.md"]
    if not args.overwrite and any(t.exists() for t in targets):
        raise UserError(f"{out}: already holds metrics; pass --overwrite to replace them")
    device = ("cuda" if torch.cuda.is_available() else "cpu") if args.device == "auto" else args.device
    masks = list_images(args.masks, "mask") if args.masks else None
    start = time.perf_counter()
    if args.pairs:
        renders, images, pair_masks, names = load_pairs(args.renders, args.images, masks)
        result = evaluate_pairs(renders, images, pair_masks, names, config)
        mode = "pairs"
    else:
        background = BACKGROUNDS[config.background]
        renders, render_masks = load_set(args.renders, "render", config.resolution, background)
        images, image_masks = load_set(args.images, "image", config.resolution, background, masks)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            extractor = get_feature_extractor(config.features, args.inception_weights, args.vgg_weights, device)
        for warning in caught:
            print(f"mesh2tex: warning: {warning.message}", file=sys.stderr)
        result = evaluate_sets(renders, images, extractor, config, render_masks, image_masks)
        mode = "sets"
    result = {"mode": mode, "renders": str(args.renders), "images": str(args.images), "masks": args.masks,
              **result, "seconds": round(time.perf_counter() - start, 2), "settings": asdict(config)}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "metrics.json", _json_value(result))
    header = (f"# mesh2tex evaluate ({mode})\n\nrenders: `{args.renders}`, images: `{args.images}`"
              + (f", masks: `{args.masks}`" if args.masks else "") + f"; counts: {result['counts']}\n\n")
    if "features" in result:
        header += f"KID/FID features: {result['features']}\n\n"
    write_text(out / "metrics.md", header + markdown_table(result))
    print(markdown_table(result), end="")
    print(f"wrote {targets[0]} and {targets[1]}")
    return 0
