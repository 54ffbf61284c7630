"""Renders against images, as tensors: unpaired set metrics (KID/FID on named features, SWD, pooled
colour histograms) and paired metrics (masked PSNR/SSIM, colour histograms), with the meaning of
each metric name; renders and images paired by file name (:func:`load_pairs`; a set is read by
:func:`mesh2tex.photos.load_set`). ``mesh2tex evaluate`` writes the results.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import torch

from mesh2tex.checks import check_shape
from mesh2tex.errors import InputError
from mesh2tex.metrics.distribution import fid, kid
from mesh2tex.metrics.features import FeatureExtractor, get_feature_extractor
from mesh2tex.metrics.image import colour_histogram_distance, colour_histograms, masked_psnr, masked_ssim
from mesh2tex.metrics.swd import swd_per_level
from mesh2tex.photos import image_tensor, list_images, mask_tensor


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


def evaluate_sets(
    renders: torch.Tensor,
    images: torch.Tensor,
    extractor: FeatureExtractor | None = None,
    config: EvaluateConfig | None = None,
    render_masks: torch.Tensor | None = None,
    image_masks: torch.Tensor | None = None,
    kid_fid: bool = True,
    image_features: torch.Tensor | None = None,
) -> dict:
    """Unpaired metrics between renders [N, 3, H, W] and images [M, 3, H, W], both float in [0, 1], same H, W.

    ``extractor``: KID/FID features (default: ``get_feature_extractor(config.features)``; metric
    names carry its suffix, e.g. ``kid_randvgg``). ``render_masks`` [N, 1, H, W] and ``image_masks``
    [M, 1, H, W] (1 on the object): with both, the colour histograms pool object pixels only
    (``color_hist_tv``); without, every pixel, background included, and the metric is named
    ``color_hist_tv_whole_image`` (it then also measures how much of each image the object covers).
    KID, FID and SWD always see the whole images (objects on their background, as in the paper).
    ``kid_fid=False`` skips KID and FID (and the feature network, most of the cost; ``features`` is None).
    ``image_features``: ``extractor``'s features of ``images`` [M, D], when several sets are measured
    against the same images (computed here when None).
    Returns {"metrics": {name: value}, "features": description, "counts": {"renders": N, "images": M}}.
    KID has a ``<name>_std`` entry (spread over subsets); SWD has one entry per pyramid level (``swd_<side>px``).
    """
    sizes = _check_sets("evaluate_sets", renders, images, render_masks, image_masks)
    check_shape(image_features, "evaluate_sets: image_features", ("M", None), sizes=sizes, dtype="float", optional=True)
    config = config or EvaluateConfig()
    if renders.shape[0] < 2 or images.shape[0] < 2:
        raise InputError(
            f"set metrics need at least 2 renders and 2 images (got {renders.shape[0]} and {images.shape[0]})"
        )
    metrics: dict[str, float] = {}
    if kid_fid:
        extractor = extractor or get_feature_extractor(config.features)
        features_renders = extractor(renders * 2 - 1)
        features_images = extractor(images * 2 - 1) if image_features is None else image_features
        kid_mean, kid_std = kid(
            features_images, features_renders, config.kid_subsets, config.kid_subset_size, config.seed
        )
        metrics[extractor.metric_name("kid")] = kid_mean
        metrics[extractor.metric_name("kid") + "_std"] = kid_std
        metrics[extractor.metric_name("fid")] = fid(features_images, features_renders)
    metrics.update(
        swd_per_level(
            images,
            renders,
            config.swd_patches_per_image,
            num_projections=config.swd_projections,
            repeats=config.swd_repeats,
            seed=config.seed,
        )
    )
    metrics.update(pooled_histogram_distance(renders, images, render_masks, image_masks, config.histogram_bins))
    return {
        "metrics": metrics,
        "features": extractor.description if kid_fid else None,
        "counts": {"renders": int(renders.shape[0]), "images": int(images.shape[0])},
    }


def _check_sets(
    function: str,
    renders: torch.Tensor,
    images: torch.Tensor,
    render_masks: torch.Tensor | None,
    image_masks: torch.Tensor | None,
) -> dict:
    """renders [N, 3, H, W] and images [M, 3, H, W] float; render_masks [N, 1, H, W], image_masks [M, 1, H, W] or None.
    Returns the sizes."""
    sizes = check_shape(renders, f"{function}: renders", ("N", 3, "H", "W"), dtype="float")
    check_shape(images, f"{function}: images", ("M", 3, "H", "W"), sizes=sizes, dtype="float")
    check_shape(render_masks, f"{function}: render_masks", ("N", 1, "H", "W"), sizes=sizes, optional=True)
    return check_shape(image_masks, f"{function}: image_masks", ("M", 1, "H", "W"), sizes=sizes, optional=True)


def pooled_histogram_distance(
    renders: torch.Tensor,
    images: torch.Tensor,
    render_masks: torch.Tensor | None,
    image_masks: torch.Tensor | None,
    bins: int,
) -> dict[str, float]:
    """TV distance between the colour histograms of two sets, each pooled as one distribution of pixels:
    {"color_hist_tv": d} over object pixels when both sets have masks, else {"color_hist_tv_whole_image": d}.

    Pooling counts every object pixel once (a large object weighs more than a small one), so the
    distance compares the colours of the two sets, not of single images. renders [N, 3, H, W] and images
    [M, 3, H, W] in [0, 1]; render_masks [N, 1, H, W] and image_masks [M, 1, H, W] or None."""
    _check_sets("pooled_histogram_distance", renders, images, render_masks, image_masks)
    if render_masks is None or image_masks is None:
        name, render_masks, image_masks = "color_hist_tv_whole_image", None, None
    else:
        name = "color_hist_tv"
        if render_masks.sum() == 0 or image_masks.sum() == 0:
            raise InputError("set colour histograms: one of the sets has no object pixel (all masks empty)")

    def pooled(x: torch.Tensor, masks: torch.Tensor | None) -> torch.Tensor:
        def stacked(t: torch.Tensor) -> torch.Tensor:  # [N, C, H, W] -> one [1, C, N*H, W] image
            return t.transpose(0, 1).reshape(1, t.shape[1], -1, t.shape[-1])

        return colour_histograms(stacked(x), None if masks is None else stacked(masks), bins)[0]

    return {name: float(0.5 * (pooled(renders, render_masks) - pooled(images, image_masks)).abs().sum())}


def evaluate_pairs(
    renders: torch.Tensor,
    images: torch.Tensor,
    masks: torch.Tensor | None = None,
    names: list[str] | None = None,
    config: EvaluateConfig | None = None,
) -> dict:
    """Paired metrics: renders and images [N, 3, H, W] float in [0, 1], masks [N, 1, H, W] in {0, 1} or None.

    Returns {"metrics": {"psnr_masked", "ssim_masked", "color_hist_tv"} (means over pairs; PSNR is
    +inf if every pair is identical), "per_pair": [{"name", "psnr_masked", "ssim_masked", "color_hist_tv"}],
    "counts": {"pairs": N}}.
    """
    # A size mismatch of the two sets is the InputError below (they are the user's files).
    sizes = check_shape(renders, "evaluate_pairs: renders", ("N", 3, "H", "W"), dtype="float")
    check_shape(images, "evaluate_pairs: images", (None, 3, None, None), dtype="float")
    check_shape(masks, "evaluate_pairs: masks", ("N", 1, "H", "W"), sizes=sizes, optional=True)
    config = config or EvaluateConfig()
    if renders.shape != images.shape:
        raise InputError(
            f"paired metrics need renders and images of one shape, got {tuple(renders.shape)} and {tuple(images.shape)}"
        )
    if masks is not None and bool((masks.flatten(1).sum(1) == 0).any()):
        empty = int((masks.flatten(1).sum(1) == 0).nonzero()[0])
        raise InputError(f"the mask of pair '{names[empty] if names else empty}' is empty")
    psnr = masked_psnr(renders, images, masks)
    ssim = masked_ssim(renders, images, masks)
    histogram = colour_histogram_distance(renders, images, masks, bins=config.histogram_bins)
    names = names or [str(i) for i in range(renders.shape[0])]
    per_pair = [
        {"name": name, "psnr_masked": float(p), "ssim_masked": float(s), "color_hist_tv": float(h)}
        for name, p, s, h in zip(names, psnr, ssim, histogram)
    ]
    metrics = {
        "psnr_masked": float(psnr.mean()),
        "ssim_masked": float(ssim.mean()),
        "color_hist_tv": float(histogram.mean()),
    }
    return {"metrics": metrics, "per_pair": per_pair, "counts": {"pairs": int(renders.shape[0])}}


METRIC_MEANINGS = {
    "kid": "Kernel Inception Distance (FID Inception-v3 features), lower is better",
    "fid": "Frechet Inception Distance (FID Inception-v3 features), lower is better",
    "swd": "sliced Wasserstein distance x1e3 on Laplacian-pyramid 7x7 patches, mean over levels, lower is better",
    "color_hist_tv": "total-variation distance of joint RGB histograms of object pixels, 0 (same colours) to 1, lower "
    "is better",
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
        what = {
            "randvgg": "random-weight VGG19 statistics (no pretrained weights; NOT standard " + base.upper() + ")",
            "vgg": "ImageNet VGG19 statistics (not standard " + base.upper() + ")",
            "tvinception": "torchvision Inception-v3 features (close to, not equal to, standard " + base.upper() + ")",
        }
        return f"{base.upper()} on {what.get(suffix, suffix + ' features')}, lower is better"
    if name == "kid_std":
        return "standard deviation of KID over subsets"
    return ""


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


def load_pairs(
    renders_dir: str | Path, images_dir: str | Path, masks: dict[str, Path] | None
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None, list[str]]:
    """Renders and images matched by file stem, with masks; InputError for unmatched names or size mismatches."""
    renders = list_images(renders_dir, "render")
    images = list_images(images_dir, "image")
    missing = sorted(set(renders) - set(images))
    if missing:
        raise InputError(
            f"{images_dir}: no image for render(s) {', '.join(missing[:5])}{' ...' if len(missing) > 5 else ''} "
            "(pairs match by file name)"
        )
    names = sorted(renders)
    render_list, image_list, mask_list = [], [], []
    any_mask = False
    for name in names:
        render, render_alpha = image_tensor(renders[name])
        image, image_alpha = image_tensor(images[name])
        if render.shape != image.shape:
            raise InputError(
                f"{images[name]}: size {tuple(image.shape[-2:])} differs from its render's {tuple(render.shape[-2:])}"
            )
        if masks is not None and name in masks:
            mask = mask_tensor(masks[name])
        elif render_alpha is not None or image_alpha is not None:
            alphas = [(a > 0.5).float() for a in (render_alpha, image_alpha) if a is not None]
            mask = alphas[0] if len(alphas) == 1 else alphas[0] * alphas[1]
        else:
            mask = None
        if mask is not None and mask.shape[-2:] != render.shape[-2:]:
            raise InputError(
                f"{masks[name] if masks is not None and name in masks else images[name]}: mask size "
                f"{tuple(mask.shape[-2:])} differs from the render's {tuple(render.shape[-2:])}"
            )
        any_mask = any_mask or mask is not None
        render_list.append(render)
        image_list.append(image)
        mask_list.append(mask if mask is not None else torch.ones_like(render[:1]))
    if len({tuple(r.shape) for r in render_list}) > 1:
        raise InputError(f"{renders_dir}: renders of different sizes; paired metrics need one size")
    return torch.stack(render_list), torch.stack(image_list), torch.stack(mask_list) if any_mask else None, names
