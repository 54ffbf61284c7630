"""Style losses of texture transfer (Mesh2Tex section 3.3, supplement E).

Both losses compare masked Gram matrices of VGG19 features (:mod:`mesh2tex.nn.vgg`, layers relu1_2,
relu2_2, relu3_4, relu4_4, relu5_4) at ``scales`` resolution levels (original, half, quarter):

* :func:`global_style_loss` compares the whole rendered image with the whole photo;
* :func:`patch_style_loss` compares ``N`` pairs of patches (64 x 64 by default). The pairs come from
  :func:`sample_patch_pairs`: each photo patch is centred on a random pixel of the photo's object;
  with NOC guidance its rendered partner is centred on the rendered pixel whose (ground-truth) NOC
  is nearest in l2 to the photo's predicted NOC at the photo centre; without guidance (the paper's
  "w/o NOC" ablation) the rendered centre is a random pixel of the rendered object.

Masks. "Masked" means twice: before VGG the background is replaced by a constant grey (0 in
[-1, 1]), so background content cannot leak into object features through receptive fields; after
VGG the Gram matrix only sums feature positions inside the mask (area-resampled to the feature
resolution) and divides by that area. Changing the background of an image therefore changes
neither loss.

Scales. The global loss sees the image at full, half and quarter resolution. A patch is seen at
resolutions of its own, halving from its full size (64, 32 and 16 pixels for the paper's 64 px
patches at 3 scales; ``infer transfer`` uses 32 px patches at 2, 32 and 16 pixels): a local patch at
coarser resolution, rather than a larger crop of the coarser image, keeps the patch loss local and cheap.

Conventions: images [B, 3, H, W] float in [-1, 1]; masks [B, 1, H, W] float in [0, 1]; NOC maps
[H, W, 3] float in [0, 1]; pixel centres are (row, column) int64. Gram lists are indexed
[scale][layer], each [B, C, C].
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from mesh2tex.checks import check_shape, check_type
from mesh2tex.errors import InputError
from mesh2tex.metrics.appearance import masked_blur
from mesh2tex.render.shading import composite_images

Grams = list[list[torch.Tensor]]


def composite_background(images: torch.Tensor, masks: torch.Tensor | None, value: float = 0.0) -> torch.Tensor:
    """images [B, 3, H, W] with the background (mask 0 of masks [B, 1, H, W], or None) replaced by ``value``;
    soft masks blend."""
    sizes = check_shape(images, "composite_background: images", ("B", 3, "H", "W"), dtype="float")
    check_shape(masks, "composite_background: masks", ("B", 1, "H", "W"), sizes=sizes, optional=True)
    if masks is None:
        return images
    return composite_images(images, masks, value)


def masked_gram(features: torch.Tensor, masks: torch.Tensor | None = None) -> torch.Tensor:
    """Gram matrix of features over the masked area.

    features [B, C, h, w]; masks [B, 1, H, W] (any resolution; area-resampled to h x w) or None for
    all pixels. Returns [B, C, C] = sum_p m_p f_p f_p^T / sum_p m_p: positions outside the mask
    contribute nothing, and the result does not depend on the object's area. An empty mask gives 0.
    (No division by C: per-entry values then stay well above float32 noise at every layer.)
    """
    sizes = check_shape(features, "masked_gram: features", ("B", "C", "h", "w"), dtype="float")
    check_shape(masks, "masked_gram: masks", ("B", 1, None, None), sizes=sizes, optional=True)
    batch, channels, height, width = features.shape
    flat = features.reshape(batch, channels, height * width)
    if masks is None:
        return flat @ flat.transpose(1, 2) / (height * width)
    weights = F.adaptive_avg_pool2d(masks.to(features.dtype), (height, width)).reshape(batch, 1, height * width)
    area = weights.sum(dim=2, keepdim=True).clamp_min(1e-6)
    return (flat * weights) @ flat.transpose(1, 2) / area


def downsample(images: torch.Tensor, masks: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Halve the resolution by 2x2 averaging (images [B, C, H, W] and masks [B, 1, H, W] or None alike)."""
    sizes = check_shape(images, "downsample: images", ("B", "C", "H", "W"), dtype="float")
    check_shape(masks, "downsample: masks", ("B", 1, "H", "W"), sizes=sizes, optional=True)
    return F.avg_pool2d(images, 2), (F.avg_pool2d(masks, 2) if masks is not None else None)


def style_grams(vgg, images: torch.Tensor, masks: torch.Tensor | None = None, scales: int = 3) -> Grams:
    """Masked Gram matrices of ``images`` [B, 3, H, W] at ``scales`` resolutions x the VGG style layers.

    ``vgg``: a :class:`mesh2tex.nn.vgg.VGG19Features`; masks [B, 1, H, W] or None. The coarsest level must
    be at least 16 pixels on a side. Returns grams[scale][layer], each [B, C_layer, C_layer].
    """
    sizes = check_shape(images, "style_grams: images", ("B", 3, "H", "W"), dtype="float")
    check_shape(masks, "style_grams: masks", ("B", 1, "H", "W"), sizes=sizes, optional=True)
    if min(images.shape[-2:]) // 2 ** (scales - 1) < 16:
        raise ValueError(
            f"images of {tuple(images.shape[-2:])} are too small for {scales} style scales (coarsest < 16 px)"
        )
    grams: Grams = []
    # Composite once at full resolution: averaging then mixes object pixels with the constant grey only.
    images = composite_background(images, masks)
    for scale in range(scales):
        if scale:
            images, masks = downsample(images, masks)
        grams.append([masked_gram(f, masks) for f in vgg(images)])
    return grams


def gram_distance(grams: Grams, target_grams: Grams, layer_weights: list[float] | None = None) -> torch.Tensor:
    """Sum over scales and layers of the mean squared difference of Gram matrices; scalar.

    Batches broadcast (a target of batch 1 against a batch of B); the mean runs over the batch too.
    ``layer_weights`` (one per layer, default 1) weight the layers.
    """
    total = grams[0][0].new_zeros(())
    for scale_grams, scale_targets in zip(grams, target_grams, strict=True):
        for layer, (gram, target) in enumerate(zip(scale_grams, scale_targets, strict=True)):
            weight = 1.0 if layer_weights is None else layer_weights[layer]
            total = total + weight * (gram - target).pow(2).mean()
    return total


def global_style_loss(
    vgg,
    images: torch.Tensor,
    masks: torch.Tensor | None,
    target_images: torch.Tensor | None = None,
    target_masks: torch.Tensor | None = None,
    target_grams: Grams | None = None,
    scales: int = 3,
) -> torch.Tensor:
    """L_glob: masked Gram distance between rendered ``images`` [B, 3, H, W] and the photo, at ``scales`` levels.

    Give the photo either as ``target_images``/``target_masks`` or, to save recomputing it every
    iteration, as ``target_grams`` from :func:`style_grams` (computed under ``torch.no_grad()``).
    masks [B, 1, H, W] or None; target_images [T, 3, H', W'] with target_masks [T, 1, H', W'] or None.
    Differentiable w.r.t. ``images``; scalar.
    """
    sizes = check_shape(images, "global_style_loss: images", ("B", 3, "H", "W"), dtype="float")
    check_shape(masks, "global_style_loss: masks", ("B", 1, "H", "W"), sizes=sizes, optional=True)
    target = check_shape(
        target_images, "global_style_loss: target_images", ("T", 3, "H'", "W'"), dtype="float", optional=True
    )
    check_shape(target_masks, "global_style_loss: target_masks", ("T", 1, "H'", "W'"), sizes=target, optional=True)
    if target_grams is None:
        if target_images is None:
            raise ValueError("give target_images or target_grams")
        with torch.no_grad():
            target_grams = style_grams(vgg, target_images, target_masks, scales)
    return gram_distance(style_grams(vgg, images, masks, scales), target_grams)


@dataclass
class PatchPairs:
    """Centres of paired patches: photo_centres, render_centres [N, 2] int64 (row, column)."""

    photo_centres: torch.Tensor
    render_centres: torch.Tensor


_MASK_SHAPES = (("H", "W"), (1, "H", "W"), (1, 1, "H", "W"))  # one mask, with or without its batch and channel


def _object_pixels(mask: torch.Tensor, what: str) -> torch.Tensor:
    """(row, column) int64 [P, 2] of the pixels of mask [H, W] (or [1, H, W], [1, 1, H, W]) above 0.5."""
    mask = mask.reshape(mask.shape[-2:])
    pixels = torch.nonzero(mask > 0.5)
    if pixels.shape[0] == 0:
        raise InputError(f"the {what} mask is empty: there is no object pixel to centre a style patch on")
    return pixels


def random_object_pixels(
    mask: torch.Tensor, count: int, generator: torch.Generator | None = None, what: str = "object"
) -> torch.Tensor:
    """``count`` pixels drawn uniformly (with replacement) from mask [H, W] (or [1, H, W], [1, 1, H, W]) > 0.5:
    [count, 2] int64 (row, column)."""
    check_shape(mask, "random_object_pixels: mask", *_MASK_SHAPES)
    pixels = _object_pixels(mask, what)
    choice = torch.randint(pixels.shape[0], (count,), generator=generator, device="cpu")
    return pixels[choice.to(pixels.device)]


def nearest_noc_pixels(query_noc: torch.Tensor, render_noc: torch.Tensor, render_mask: torch.Tensor) -> torch.Tensor:
    """For each query NOC [N, 3], the rendered object pixel whose NOC (render_noc [H, W, 3]) is nearest in l2.

    Only pixels with render_mask [H, W] (or [1, H, W], [1, 1, H, W]) > 0.5 are candidates. Returns [N, 2]
    int64 (row, column).
    """
    check_shape(query_noc, "nearest_noc_pixels: query_noc", ("N", 3), dtype="float")
    sizes = check_shape(render_noc, "nearest_noc_pixels: render_noc", ("H", "W", 3), dtype="float")
    check_shape(render_mask, "nearest_noc_pixels: render_mask", *_MASK_SHAPES, sizes=sizes)
    pixels = _object_pixels(render_mask, "rendered")
    candidates = render_noc[pixels[:, 0], pixels[:, 1]].to(query_noc.dtype)  # [P, 3]
    nearest = torch.cdist(query_noc[None], candidates[None])[0].argmin(dim=1)
    return pixels[nearest]


def sample_patch_pairs(
    photo_mask: torch.Tensor,
    render_mask: torch.Tensor,
    num_patches: int,
    photo_noc: torch.Tensor | None = None,
    render_noc: torch.Tensor | None = None,
    guided: bool = True,
    generator: torch.Generator | None = None,
) -> PatchPairs:
    """Pick ``num_patches`` pairs of patch centres (Mesh2Tex section 3.3).

    photo_mask, render_mask: [H, W] and [H', W'] float/bool (or [1, H, W], [1, 1, H, W]), object > 0.5 (the two
    images may differ in size). photo_noc: the photo's predicted NOC [H, W, 3]; render_noc: the render's NOC
    [H', W', 3].
    guided=True (needs both NOC maps): photo centres uniform over the photo's object; each render
    centre is the rendered object pixel with the nearest NOC. guided=False: both centres uniform over
    their own object (the ablation without NOC). Raises InputError if a mask is empty.
    """
    photo = check_shape(photo_mask, "sample_patch_pairs: photo_mask", *_MASK_SHAPES)
    render = check_shape(render_mask, "sample_patch_pairs: render_mask", *_MASK_SHAPES)
    check_shape(photo_noc, "sample_patch_pairs: photo_noc", ("H", "W", 3), sizes=photo, dtype="float", optional=True)
    check_shape(render_noc, "sample_patch_pairs: render_noc", ("H", "W", 3), sizes=render, dtype="float", optional=True)
    photo_centres = random_object_pixels(photo_mask, num_patches, generator, "photo's object")
    if guided:
        if photo_noc is None or render_noc is None:
            raise ValueError("NOC-guided patch sampling needs photo_noc and render_noc")
        query = photo_noc[photo_centres[:, 0], photo_centres[:, 1]]
        render_centres = nearest_noc_pixels(query, render_noc, render_mask)
    else:
        render_centres = random_object_pixels(render_mask, num_patches, generator, "rendered object's")
    return PatchPairs(photo_centres, render_centres)


def crop_patches(images: torch.Tensor, centres: torch.Tensor, size: int) -> torch.Tensor:
    """Square crops of side ``size`` around ``centres`` [N, 2] (row, column), shifted to stay inside the image.

    images: [C, H, W] or [1, C, H, W]; centres int64. ``size`` is clipped to min(H, W). Returns [N, C, s, s];
    differentiable w.r.t. images.
    """
    check_shape(images, "crop_patches: images", ("C", "H", "W"), (1, "C", "H", "W"))
    check_shape(centres, "crop_patches: centres", ("N", 2), dtype="int")
    if images.dim() == 4:
        images = images[0]
    height, width = images.shape[-2:]
    size = min(size, height, width)
    patches = []
    for row, column in centres.tolist():
        top = min(max(row - size // 2, 0), height - size)
        left = min(max(column - size // 2, 0), width - size)
        patches.append(images[:, top : top + size, left : left + size])
    return torch.stack(patches)


def patch_style_loss(
    vgg,
    rendered: torch.Tensor,
    rendered_mask: torch.Tensor,
    photo: torch.Tensor,
    photo_mask: torch.Tensor,
    pairs: PatchPairs,
    patch_size: int = 64,
    scales: int = 3,
) -> torch.Tensor:
    """L_patch: sum over the patch pairs of the masked Gram distance at ``scales`` levels x 5 layers; scalar.

    rendered [1, 3, H, W] / [3, H, W] in [-1, 1] with rendered_mask [1, 1, H, W] / [1, H, W]; photo and
    photo_mask likewise (any size). Patches of ``patch_size`` (clipped to the images) are cut around
    ``pairs`` (see :func:`sample_patch_pairs`) with their masks. Differentiable w.r.t. ``rendered``.
    """
    sizes = check_shape(rendered, "patch_style_loss: rendered", (1, 3, "H", "W"), (3, "H", "W"), dtype="float")
    check_shape(rendered_mask, "patch_style_loss: rendered_mask", (1, 1, "H", "W"), (1, "H", "W"), sizes=sizes)
    photo_sizes = check_shape(photo, "patch_style_loss: photo", (1, 3, "H", "W"), (3, "H", "W"), dtype="float")
    check_shape(photo_mask, "patch_style_loss: photo_mask", (1, 1, "H", "W"), (1, "H", "W"), sizes=photo_sizes)
    check_type(pairs, "patch_style_loss: pairs", PatchPairs)
    rendered_patches = crop_patches(rendered, pairs.render_centres, patch_size)
    rendered_masks = crop_patches(rendered_mask.reshape(1, *rendered_mask.shape[-2:]), pairs.render_centres, patch_size)
    with torch.no_grad():
        photo_patches = crop_patches(photo, pairs.photo_centres, patch_size)
        photo_masks = crop_patches(photo_mask.reshape(1, *photo_mask.shape[-2:]), pairs.photo_centres, patch_size)
        target = style_grams(vgg, photo_patches, photo_masks.to(photo_patches.dtype), scales)
    grams = style_grams(vgg, rendered_patches, rendered_masks.to(rendered_patches.dtype), scales)
    # gram_distance averages over the batch of patches; Equation 2 sums over them.
    return gram_distance(grams, target) * pairs.photo_centres.shape[0]


def lowpass_colour_loss(
    rendered: torch.Tensor, rendered_mask: torch.Tensor, photo: torch.Tensor, photo_mask: torch.Tensor, sigma: float
) -> torch.Tensor:
    """Mean absolute difference of the two images' colours after a Gaussian blur of ``sigma`` pixels
    of each one's own object pixels (:func:`mesh2tex.metrics.appearance.masked_blur`), over the pixels
    both masks cover; scalar (0 when the masks do not overlap).

    rendered [1, 3, H, W] in [-1, 1] with rendered_mask [1, 1, H, W]; photo and photo_mask alike, the
    same size. The blur makes the loss forgive a pose a few pixels off and texture phase, while the
    colour of each region still has to match: where the style losses (Gram matrices) leave colours
    free to drift, this term pins them to the photo's. Differentiable w.r.t. ``rendered``.
    """
    sizes = check_shape(rendered, "lowpass_colour_loss: rendered", ("B", 3, "H", "W"), dtype="float")
    check_shape(rendered_mask, "lowpass_colour_loss: rendered_mask", ("B", 1, "H", "W"), sizes=sizes)
    photo_sizes = check_shape(
        photo, "lowpass_colour_loss: photo", ("B", 3, "H", "W"), sizes={"B": sizes["B"]}, dtype="float"
    )
    check_shape(photo_mask, "lowpass_colour_loss: photo_mask", ("B", 1, "H", "W"), sizes=photo_sizes)
    if rendered.shape[-2:] != photo.shape[-2:]:
        raise ValueError(
            f"lowpass_colour_loss: the render is {tuple(rendered.shape[-2:])}, the photo {tuple(photo.shape[-2:])}"
        )
    both = (rendered_mask * photo_mask).to(rendered.dtype)
    a = masked_blur(rendered, rendered_mask, sigma).to(rendered.dtype)
    with torch.no_grad():
        b = masked_blur(photo, photo_mask, sigma).to(rendered.dtype)
    return ((a - b).abs() * both).sum() / (both.sum() * rendered.shape[1]).clamp_min(1.0)
