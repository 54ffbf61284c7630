"""Every checked public function of mesh2tex.losses, .metrics, .transfer and .geometry: a correct call still
works, and a wrong rank, size or dtype fails at the call with a message that names the function and the
argument (ValueError for a shape, TypeError for a non-tensor or a wrong dtype), not deep inside. The
companion of tests/test_shape_checks.py (render and nn)."""

from __future__ import annotations

import importlib
import re
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from mesh2tex.geometry import clean, features, hierarchy, levelset, prepare, prepared, primitives, regions
from mesh2tex.losses import augment, ot_style, style
from mesh2tex.losses import structure as structure_loss
from mesh2tex.losses.gan import GanLoss, GanLossConfig, mode_seeking_ratio, object_lab_moments
from mesh2tex.metrics import appearance, distribution, evaluate, generation, spectrum, structure
from mesh2tex.metrics.features import FeatureExtractor
from mesh2tex.metrics.inception import InceptionV3Features
from mesh2tex.nn.pose import PoseBins
from mesh2tex.transfer import automaton, fit, optimise, pose
from mesh2tex.transfer import mask as transfer_mask
from mesh2tex.transfer.config import TransferConfig
from mesh2tex.transfer.photo import FramedView, Photo

swd = importlib.import_module("mesh2tex.metrics.swd")  # the package's ``swd`` is the function of that name
R = 64  # the side of the small photos and views: three style scales need 16 px at the coarsest


def _layers(images, depth=None):
    """A stand-in for the VGG19 features: the image itself and its 2x2 average, as the style losses read them."""
    return [images, torch.nn.functional.avg_pool2d(images, 2)][: 2 if depth is None else depth]


@pytest.fixture(scope="module")
def w():
    """Small correct inputs that the cases below break one argument at a time."""
    g = torch.Generator().manual_seed(0)
    images, masks = torch.rand(2, 3, 32, 32, generator=g), torch.zeros(2, 1, 32, 32)
    masks[..., 4:28, 4:28] = 1
    photo_mask = torch.zeros(1, 1, R, R)
    photo_mask[..., 8:56, 12:52] = 1
    photo = Photo(image=torch.rand(1, 3, R, R, generator=g) * 2 - 1, mask=photo_mask)
    view = FramedView(mvp=torch.eye(4)[None], render_size=R, box=(0, 0, R), noc=torch.rand(R, R, 3, generator=g),
                      mask=photo_mask.clone(), azimuth=0.0, elevation=20.0, distance=2.0, fov=40.0)
    cfg = TransferConfig(resolution=R)
    vertices, quads = primitives.cube_sphere(2)
    gan = GanLoss(GanLossConfig(), None, None)
    gan.set_colour_target(images * 2 - 1, masks)
    return SimpleNamespace(images=images, masks=masks, photo=photo, view=view, cfg=cfg,
                           noc=torch.rand(R, R, 3, generator=g), vertices=vertices, quads=quads,
                           triangles=prepared.quads_to_triangles(quads), gan=gan,
                           loss=optimise.PhotoLoss(photo, view, torch.rand(R, R, 3, generator=g), _layers, cfg, "cpu"),
                           exemplar=ot_style.ExemplarFeatures.compute(_layers, images[:1] * 2 - 1, 1),
                           sets=[torch.rand(20, 3, generator=g), torch.rand(10, 3, generator=g)],
                           beliefs=pose.PoseBeliefs(PoseBins(), torch.full((12,), 1 / 12), torch.full((5,), 0.2)))


def _pairs():
    return style.PatchPairs(torch.tensor([[30, 30]]), torch.tensor([[30, 30]]))


ANY = r"must have shape"
# name: (a correct call, the same call with one argument wrong, the error, a regex its message must match)
LOSSES = {
    "augment_colour x": (lambda w: augment.augment_colour(w.images), lambda w: augment.augment_colour(w.images[0]),
        ValueError, r"augment_colour: x must have shape \[N, C, H, W\], got \[3, 32, 32\]"),
    "augment_translation x": (lambda w: augment.augment_translation(w.images),
        lambda w: augment.augment_translation((w.images * 255).long()),
        TypeError, r"augment_translation: x must be a floating-point tensor, got int64"),
    "augment_cutout x": (lambda w: augment.augment_cutout(w.images), lambda w: augment.augment_cutout(w.images[:, 0]),
        ValueError, ANY),
    "DiffAugment x": (lambda w: augment.DiffAugment()(w.images), lambda w: augment.DiffAugment()(w.images.numpy()),
        TypeError, r"DiffAugment: x must be a torch.Tensor of shape \[N, C, H, W\], got ndarray"),
    "mode_seeking_ratio mask": (
        lambda w: mode_seeking_ratio(w.images, w.images, w.masks, torch.rand(2, 4), torch.rand(2, 4)),
        lambda w: mode_seeking_ratio(w.images, w.images, w.masks[:1], torch.rand(2, 4), torch.rand(2, 4)),
        ValueError, r"mode_seeking_ratio: mask must have shape \[N, 1, H, W\] \(N = 2 from proxy_a\)"),
    "mode_seeking_ratio z_b": (None,
        lambda w: mode_seeking_ratio(w.images, w.images, w.masks, torch.rand(2, 4), torch.rand(2, 5)),
        ValueError, r"mode_seeking_ratio: z_b must have shape \[B, Z\] \(Z = 4 from z_a\)"),
    "object_lab_moments mask": (lambda w: object_lab_moments(w.images, w.masks),
        lambda w: object_lab_moments(w.images, w.masks[..., :16]),
        ValueError, r"object_lab_moments: mask must have shape \[N, 1, H, W\] \(W = 32 from images\)"),
    "GanLoss.set_colour_target photos": (
        lambda w: GanLoss(GanLossConfig(), None, None).set_colour_target(w.images, w.masks),
        lambda w: GanLoss(GanLossConfig(), None, None).set_colour_target(w.images[:, :2], w.masks),
        ValueError, r"GanLoss.set_colour_target: photos must have shape \[N, 3, H, W\]"),
    "GanLoss.colour_loss mask": (lambda w: w.gan.colour_loss(w.images, w.masks),
        lambda w: w.gan.colour_loss(w.images, w.masks[0]), ValueError, r"GanLoss.colour_loss: mask must have shape"),
    "GanLoss.accumulate_gradients real": (None,
        lambda w: w.gan.accumulate_gradients("Dmain", None, torch.zeros(2, 4), w.images[0]),
        ValueError, r"GanLoss.accumulate_gradients: real must have shape \[\*, 3, \*, \*\]"),
    "composite_background masks": (lambda w: style.composite_background(w.images, w.masks),
        lambda w: style.composite_background(w.images, w.masks[:, :, :8]),
        ValueError, r"composite_background: masks must have shape \[B, 1, H, W\] \(H = 32 from images\)"),
    "masked_gram features": (lambda w: style.masked_gram(w.images, w.masks[..., ::2, ::2]),
        lambda w: style.masked_gram(w.images[0]),
        ValueError, r"masked_gram: features must have shape \[B, C, h, w\], got \[3, 32, 32\]"),
    "downsample masks": (lambda w: style.downsample(w.images, None), lambda w: style.downsample(w.images, w.masks[:1]),
        ValueError, r"downsample: masks must have shape \[B, 1, H, W\] \(B = 2 from images\)"),
    "style_grams images": (lambda w: style.style_grams(_layers, w.images, w.masks, scales=2),
        lambda w: style.style_grams(_layers, w.images[:, :1], w.masks, scales=2), ValueError, ANY),
    "global_style_loss target_masks": (
        lambda w: style.global_style_loss(_layers, w.images, w.masks, w.images[:1], w.masks[:1], scales=2),
        lambda w: style.global_style_loss(_layers, w.images, w.masks, w.images[:1], w.masks, scales=2),
        ValueError, r"global_style_loss: target_masks must have shape \[T, 1, H', W'\] \(T = 1"),
    "random_object_pixels mask": (lambda w: style.random_object_pixels(w.masks[0], 3),
        lambda w: style.random_object_pixels(w.masks, 3),
        ValueError, r"random_object_pixels: mask must have shape \[H, W\] or \[1, H, W\] or \[1, 1, H, W\]"),
    "nearest_noc_pixels render_mask": (lambda w: style.nearest_noc_pixels(w.noc[:2, 0], w.noc, w.photo.mask),
        lambda w: style.nearest_noc_pixels(w.noc[:2, 0], w.noc, w.masks[0]),
        ValueError, r"nearest_noc_pixels: render_mask must have shape .*\(H = 64 from render_noc\)"),
    "sample_patch_pairs photo_noc": (
        lambda w: style.sample_patch_pairs(w.photo.mask, w.view.mask, 2, w.noc, w.view.noc),
        lambda w: style.sample_patch_pairs(w.photo.mask, w.view.mask, 2, w.noc[:32], w.view.noc),
        ValueError, r"sample_patch_pairs: photo_noc must have shape \[H, W, 3\] \(H = 64 from photo_mask\)"),
    "crop_patches centres": (lambda w: style.crop_patches(w.images[:1], torch.tensor([[3, 4]]), 8),
        lambda w: style.crop_patches(w.images[:1], torch.tensor([[3.0, 4.0]]), 8),
        TypeError, r"crop_patches: centres must be an integer tensor, got float32"),
    "patch_style_loss rendered_mask": (
        lambda w: style.patch_style_loss(_layers, w.photo.image, w.photo.mask, w.photo.image, w.photo.mask, _pairs(),
            32, 2),
        lambda w: style.patch_style_loss(_layers, w.photo.image, w.masks[:1], w.photo.image, w.photo.mask, _pairs(), 32,
            2),
        ValueError, r"patch_style_loss: rendered_mask must have shape .*\(H = 64 from rendered\)"),
    "lowpass_colour_loss rendered_mask": (
        lambda w: style.lowpass_colour_loss(w.images, w.masks, w.images, w.masks, 2.0),
        lambda w: style.lowpass_colour_loss(w.images, w.masks[:, 0], w.images, w.masks, 2.0),
        ValueError, r"lowpass_colour_loss: rendered_mask must have shape \[B, 1, H, W\]"),
    "image_layers images": (lambda w: ot_style.image_layers(_layers, w.images, 1),
        lambda w: ot_style.image_layers(_layers, w.images[0], 1), ValueError, ANY),
    "feature_sets mask": (lambda w: ot_style.feature_sets([w.images], w.masks[0], 64),
        lambda w: ot_style.feature_sets([w.images], w.masks, 64),
        ValueError, r"feature_sets: mask must have shape \[1, \*, \*\], got \[2, 1, 32, 32\]"),
    "relaxed_emd b": (lambda w: ot_style.relaxed_emd(*w.sets, l2=True),
        lambda w: ot_style.relaxed_emd(w.sets[0], w.sets[1][:, :2], l2=True),
        ValueError, r"relaxed_emd: b must have shape \[Q, C\] \(C = 3 from a\), got \[10, 2\]"),
    "moment_loss a": (lambda w: ot_style.moment_loss(*w.sets), lambda w: ot_style.moment_loss(w.sets[0][0], w.sets[1]),
        ValueError, ANY),
    "ot_style_distance exemplar_sets": (lambda w: ot_style.ot_style_distance([w.sets[0]], [w.sets[1]]),
        lambda w: ot_style.ot_style_distance([w.sets[0]], [w.sets[1], w.sets[1]]),
        ValueError, r"ot_style_distance: render_sets and exemplar_sets must hold one set per layer"),
    "ExemplarFeatures.compute image": (lambda w: ot_style.ExemplarFeatures.compute(None, w.images[:1], 0),
        lambda w: ot_style.ExemplarFeatures.compute(None, w.images, 0),
        ValueError, r"ExemplarFeatures.compute: image must have shape \[1, 3, \*, \*\]"),
    "style_loss masks": (lambda w: ot_style.style_loss(_layers, w.images, w.masks, w.exemplar, "gram"),
        lambda w: ot_style.style_loss(_layers, w.images, w.masks[:1], w.exemplar, "gram"), ValueError, ANY),
    "quantile_resample sorted_values": (lambda w: structure_loss.quantile_resample(w.sets[0], 5),
        lambda w: structure_loss.quantile_resample(w.sets[0][:, 0], 5), ValueError, ANY),
    "sliced_wasserstein2 directions": (lambda w: structure_loss.sliced_wasserstein2(*w.sets, torch.eye(3)),
        lambda w: structure_loss.sliced_wasserstein2(*w.sets, torch.eye(4)),
        ValueError, r"sliced_wasserstein2: directions must have shape \[C, K\] \(C = 3 from a\)"),
    "sw_distance render_sets": (lambda w: structure_loss.sw_distance([w.sets[0]], [w.sets[1]]),
        lambda w: structure_loss.sw_distance(w.sets[0], [w.sets[1]]),
        TypeError, r"sw_distance: render_sets must be a list, got Tensor"),
    "band_statistics mask": (lambda w: structure_loss.band_statistics(w.images[:1], w.masks[:1]),
        lambda w: structure_loss.band_statistics(w.images[:1], w.masks), ValueError, ANY),
    "exemplar_band_statistics image": (lambda w: structure_loss.exemplar_band_statistics(w.images[:1]),
        lambda w: structure_loss.exemplar_band_statistics(w.images[0]), ValueError, ANY),
    "ps_loss masks": (
        lambda w: structure_loss.ps_loss(w.images, w.masks, structure_loss.exemplar_band_statistics(w.images[:1])),
        lambda w: structure_loss.ps_loss(w.images, w.masks[:1], {}), ValueError, ANY),
}

METRICS = {
    "rgb_to_lab images": (lambda w: appearance.rgb_to_lab(w.images), lambda w: appearance.rgb_to_lab(w.images[:, :2]),
        ValueError, r"rgb_to_lab: images must have shape \[B, 3, H, W\], got \[2, 2, 32, 32\]"),
    "part_colours parts": (lambda w: appearance.part_colours(w.images, torch.zeros(2, 32, 32, dtype=torch.long)),
        lambda w: appearance.part_colours(w.images, torch.zeros(2, 32, 32)),
        TypeError, r"part_colours: parts must be an integer tensor, got float32"),
    "part_colour_error reference_parts": (
        lambda w: appearance.part_colour_error(w.images, w.images, torch.zeros(2, 32, 32, dtype=torch.long)),
        lambda w: appearance.part_colour_error(w.images, w.images[..., :16, :16],
            torch.zeros(2, 32, 32, dtype=torch.long), w.masks, torch.zeros(2, 32, 32, dtype=torch.long),
            w.masks[..., :16, :16]),
        ValueError, r"part_colour_error: reference_parts must have shape \[B, H', W'\] \(H' = 16"),
    "masked_blur masks": (lambda w: appearance.masked_blur(w.images, w.masks, 1.0),
        lambda w: appearance.masked_blur(w.images, w.masks[0], 1.0), ValueError, ANY),
    "lowpass_psnr references": (lambda w: appearance.lowpass_psnr(w.images, w.images.flip(0), w.masks),
        lambda w: appearance.lowpass_psnr(w.images, w.images[..., :16], w.masks),
        ValueError, r"lowpass_psnr: references must have shape \[B, 3, H, W\] \(W = 32 from images\)"),
    "object_swd reference_masks": (
        lambda w: appearance.object_swd(w.images, w.images, w.masks, patches=16, projections=8),
        lambda w: appearance.object_swd(w.images, w.images, w.masks, w.masks[..., :16, :16]),
        ValueError, r"object_swd: reference_masks must have shape \[B, 1, H', W'\] \(H' = 32 from references\)"),
    "kid features_b": (lambda w: distribution.kid(*w.sets, num_subsets=2),
        lambda w: distribution.kid(w.sets[0], w.sets[1][:, :2]),
        ValueError, r"kid: features_b must have shape \[M, D\] \(D = 3 from features_a\), got \[10, 2\]"),
    "fid features_a": (lambda w: distribution.fid(*w.sets), lambda w: distribution.fid(w.sets[0].long(), w.sets[1]),
        TypeError, r"fid: features_a must be a floating-point tensor"),
    "trace_sqrt_product centred_b": (lambda w: distribution.trace_sqrt_product(np.ones((4, 3)), np.ones((5, 3))),
        lambda w: distribution.trace_sqrt_product(np.ones((4, 3)), np.ones((5, 2))),
        ValueError, r"trace_sqrt_product: centred_b must have shape \[n_b, D\] \(D = 3 from centred_a\)"),
    "evaluate_sets images": (None, lambda w: evaluate.evaluate_sets(w.images, w.images[..., :16, :16]),
        ValueError, r"evaluate_sets: images must have shape \[M, 3, H, W\] \(H = 32 from renders\)"),
    "evaluate_sets image_features": (None,
        lambda w: evaluate.evaluate_sets(w.images, w.images, image_features=torch.zeros(3, 8)),
        ValueError, r"evaluate_sets: image_features must have shape \[M, \*\] \(M = 2 from images\)"),
    "pooled_histogram_distance image_masks": (
        lambda w: evaluate.pooled_histogram_distance(w.images, w.images, w.masks, w.masks, 4),
        lambda w: evaluate.pooled_histogram_distance(w.images, w.images, w.masks, w.masks[:, 0], 4), ValueError, ANY),
    "evaluate_pairs masks": (lambda w: evaluate.evaluate_pairs(w.images, w.images, w.masks),
        lambda w: evaluate.evaluate_pairs(w.images, w.images, w.masks[:1]),
        ValueError, r"evaluate_pairs: masks must have shape \[N, 1, H, W\] \(N = 2 from renders\)"),
    "FeatureExtractor images": (lambda w: FeatureExtractor("mean", "", lambda x: x.mean((2, 3)))(w.images),
        lambda w: FeatureExtractor("mean", "", lambda x: x.mean((2, 3)))(w.images[0]), ValueError, ANY),
    "InceptionV3Features images": (None, lambda w: InceptionV3Features()(w.images[:, :1]),
        ValueError, r"InceptionV3Features: images must have shape \[B, 3, H, W\]"),
    "srgb_to_lab images": (lambda w: generation.srgb_to_lab(w.images), lambda w: generation.srgb_to_lab(w.images[0]),
        ValueError, ANY),
    "mean_object_lab masks": (lambda w: generation.mean_object_lab(w.images, w.masks),
        lambda w: generation.mean_object_lab(w.images, w.masks[:1]), ValueError, ANY),
    "colour_spread lab_means": (lambda w: generation.colour_spread(w.sets[0]),
        lambda w: generation.colour_spread(w.sets[0][:, :2]),
        ValueError, r"colour_spread: lab_means must have shape \[K, 3\], got \[20, 2\]"),
    "mean_pairwise_delta_e mask": (lambda w: generation.mean_pairwise_delta_e(w.images, w.masks[0]),
        lambda w: generation.mean_pairwise_delta_e(w.images, w.masks[0, 0]), ValueError, ANY),
    "object_set_swd references": (
        lambda w: generation.object_set_swd(w.images, w.masks, w.images, w.masks, 16, projections=8),
        lambda w: generation.object_set_swd(w.images, w.masks, w.images[..., :16, :16], w.masks),
        ValueError, r"object_set_swd: references must have shape \[M, 3, H, W\] \(H = 32 from images\)"),
    "object_patches masks": (lambda w: spectrum.object_patches(w.images, w.masks, 8),
        lambda w: spectrum.object_patches(w.images, w.masks.expand(2, 3, 32, 32), 8), ValueError, ANY),
    "high_frequency_share images": (lambda w: spectrum.high_frequency_share(w.images, w.masks, 0.25, patch=8),
        lambda w: spectrum.high_frequency_share(w.images[:, :1], w.masks, 0.25, patch=8),
        ValueError, r"high_frequency_share: images must have shape \[B, 3, H, W\]"),
    "radial_power masks": (lambda w: spectrum.radial_power(w.images, w.masks, [0.0, 0.25, 0.5], patch=8),
        lambda w: spectrum.radial_power(w.images, w.masks[:1], [0.0, 0.5], patch=8), ValueError, ANY),
    "luminance images": (lambda w: structure.luminance(w.images), lambda w: structure.luminance(w.images[:, :1]),
        ValueError, ANY),
    "orientation_windows masks": (lambda w: structure.orientation_windows(w.images, w.masks, 8),
        lambda w: structure.orientation_windows(w.images, w.masks[0], 8),
        ValueError, r"orientation_windows: masks must have shape \[N, 1, H, W\]"),
    "orientation_scores doubled": (
        lambda w: structure.orientation_scores(torch.ones(3, 16), torch.ones(3, dtype=torch.complex128)),
        lambda w: structure.orientation_scores(torch.ones(3, 16), torch.ones(4, dtype=torch.complex128)),
        ValueError, r"orientation_scores: doubled must have shape \[M\] \(M = 3 from histograms\)"),
    "spectrum_period images": (lambda w: structure.spectrum_period(w.images, None, 16),
        lambda w: structure.spectrum_period(w.images.double().long(), None, 16), TypeError, "floating-point"),
    "patch_swd exemplar": (lambda w: structure.patch_swd(w.images, w.masks, w.images[:1], levels=1, projections=8),
        lambda w: structure.patch_swd(w.images, w.masks, w.images[0], levels=1),
        ValueError, r"patch_swd: exemplar must have shape \[\*, 3, \*, \*\], got \[3, 32, 32\]"),
    "structure_scores masks": (None, lambda w: structure.structure_scores(w.images, w.masks[..., :8]), ValueError, ANY),
    "laplacian_pyramid images": (lambda w: swd.laplacian_pyramid(w.images),
        lambda w: swd.laplacian_pyramid(w.images[0]), ValueError, ANY),
    "sliced_wasserstein descriptors_b": (lambda w: swd.sliced_wasserstein(w.sets[0], w.sets[0], 4, torch.Generator()),
        lambda w: swd.sliced_wasserstein(w.sets[0], w.sets[1], 4, torch.Generator()),
        ValueError, r"sliced_wasserstein: descriptors_b must have shape \[M, D\] \(M = 20 from descriptors_a\)"),
    "sorted_rows values": (lambda w: swd.sorted_rows(w.sets[0].double()), lambda w: swd.sorted_rows(w.sets[0][0]),
        ValueError, ANY),
    "swd_per_level images_b": (lambda w: swd.swd_per_level(w.images, w.images, 4, num_projections=8, repeats=1),
        lambda w: swd.swd_per_level(w.images, w.images[..., :16]),
        ValueError, r"swd_per_level: images_b must have shape \[M, 3, H, W\] \(W = 32 from images_a\)"),
    "swd images_a": (None, lambda w: swd.swd(w.images[:, :2], w.images), ValueError, r"swd: images_a must have shape"),
}

TRANSFER = {
    "check_fit render_mask": (lambda w: fit.check_fit(w.photo.image, w.photo.mask, w.photo.image, w.photo.mask),
        lambda w: fit.check_fit(w.photo.image, w.photo.mask, w.photo.image, w.masks[:1]),
        ValueError, r"check_fit: render_mask must have shape \[1, 1, R, R\] \(R = 64 from photo_image\)"),
    "outline_agreement b": (lambda w: fit.outline_agreement(w.photo.mask > 0.5, w.view.mask > 0.5, 1),
        lambda w: fit.outline_agreement(w.photo.mask > 0.5, w.view.mask, 1),
        TypeError, r"outline_agreement: b must be a bool tensor, got float32"),
    "network_probability rgb": (None, lambda w: transfer_mask.network_probability("none", np.zeros((8, 8), np.uint8)),
        ValueError, r"network_probability: rgb must have shape \[H, W, 3\], got \[8, 8\]"),
    "refine_with_grabcut probability": (
        lambda w: transfer_mask.refine_with_grabcut(np.zeros((16, 16, 3), np.uint8), np.full((16, 16), 0.6)),
        lambda w: transfer_mask.refine_with_grabcut(np.zeros((16, 16, 3), np.uint8), np.zeros((8, 16))),
        ValueError, r"refine_with_grabcut: probability must have shape \[H, W\] \(H = 16 from rgb\)"),
    "predict_pose photo": (None, lambda w: pose.predict_pose("none", w.photo.image, "cpu"),
        TypeError, r"predict_pose: photo must be a Photo, got Tensor"),
    "pose_network_beliefs photo.mask": (None,
        lambda w: pose.pose_network_beliefs("none", Photo(w.photo.image, w.masks[:1]), "cpu"),
        ValueError, r"pose_network_beliefs: photo.mask must have shape \[1, 1, R, R\] \(R = 64"),
    "silhouette_iou elevations": (None,
        lambda w: pose.silhouette_iou(None, w.photo.mask, torch.zeros(3), torch.zeros(2), 2.0, 40.0, 0.1),
        ValueError, r"silhouette_iou: elevations must have shape \[N\] \(N = 3 from azimuths\)"),
    "search_pose beliefs.elevation": (None,
        lambda w: pose.search_pose(None, w.photo, pose.PoseBeliefs(PoseBins(), torch.ones(12), torch.ones(5, 1)), 2.0,
            40.0, w.cfg),
        ValueError, r"search_pose: beliefs.elevation must have shape \[E\]"),
    "estimate_pose photo.mask": (None,
        lambda w: pose.estimate_pose("none", None, Photo(w.images[:1], w.photo.mask), 2.0, 40.0, w.cfg, "cpu"),
        ValueError, r"estimate_pose: photo.mask must have shape \[1, 1, R, R\] \(R = 32 from photo.image\)"),
    "predict_noc photo.image": (None,
        lambda w: pose.predict_noc("none", Photo(w.photo.image.half().long(), w.photo.mask), "cpu"),
        TypeError, r"predict_noc: photo.image must be a floating-point tensor"),
    "PhotoLoss photo_noc": (lambda w: optimise.PhotoLoss(w.photo, w.view, w.noc, _layers, w.cfg, "cpu"),
        lambda w: optimise.PhotoLoss(w.photo, w.view, w.noc[:32, :32], _layers, w.cfg, "cpu"),
        ValueError, r"PhotoLoss: photo_noc must have shape \[R, R, 3\] \(R = 64 from photo.image\), got \[32, 32, 3\]"),
    "PhotoLoss view.noc": (None,
        lambda w: optimise.PhotoLoss(w.photo, FramedView(w.view.mvp, R, (0, 0, R), w.noc[..., :2], w.view.mask), None,
            _layers, w.cfg, "cpu"),
        ValueError, r"PhotoLoss: view.noc must have shape \[R, R, 3\]"),
    "PhotoLoss image": (lambda w: w.loss(w.photo.image, use_global=True),
        lambda w: w.loss(w.images[:1], use_global=True),
        ValueError, r"PhotoLoss: image must have shape \[1, 3, R, R\] \(R = 64 from photo.image\), got \[1, 3, 32"),
    "transfer_texture view": (None,
        lambda w: optimise.transfer_texture(None, None, w.photo, w.photo, None, _layers, w.cfg, "cpu"),
        TypeError, r"transfer_texture: view must be a FramedView, got Photo"),
    "unseen_anchors view.mvp": (None,
        lambda w: optimise.unseen_anchors(None, FramedView(torch.eye(4), R, (0, 0, R), w.noc, w.view.mask), None, None,
            w.cfg, "cpu", None, None),
        ValueError, r"unseen_anchors: view.mvp must have shape \[1, 4, 4\], got \[4, 4\]"),
    "fit_automaton photo_noc": (None,
        lambda w: automaton.fit_automaton(None, w.photo, w.view, w.noc.long(), None, w.cfg, None, "cpu"),
        TypeError, r"fit_automaton: photo_noc must be a floating-point tensor"),
}

GEOMETRY = {
    "quads_to_triangles quads": (lambda w: prepared.quads_to_triangles(torch.as_tensor(w.quads)),
        lambda w: prepared.quads_to_triangles(w.triangles),
        ValueError, r"quads_to_triangles: quads must have shape \[F, 4\], got \[48, 3\]"),
    "edge_neighbors quads": (lambda w: hierarchy.edge_neighbors(w.quads),
        lambda w: hierarchy.edge_neighbors(w.quads.ravel()),
        ValueError, r"edge_neighbors: quads must have shape \[F, 4\], got \[96\]"),
    "face_neighborhoods vertices": (lambda w: hierarchy.face_neighborhoods(w.vertices, w.quads),
        lambda w: hierarchy.face_neighborhoods(w.vertices[:, :2], w.quads), ValueError, ANY),
    "face_centres quads": (lambda w: hierarchy.face_centres(w.vertices, w.quads),
        lambda w: hierarchy.face_centres(w.vertices, w.triangles), ValueError, ANY),
    "pooling_map coarse_quads": (lambda w: hierarchy.pooling_map(w.vertices, w.quads, w.vertices, w.quads[:6]),
        lambda w: hierarchy.pooling_map(w.vertices, w.quads, w.vertices, w.triangles),
        ValueError, r"pooling_map: coarse_quads must have shape \[F_c, 4\]"),
    "orient_coherently vertices": (lambda w: hierarchy.orient_coherently(w.vertices, w.quads),
        lambda w: hierarchy.orient_coherently(w.vertices.tolist()[0], w.quads), ValueError, ANY),
    "quad_normals quads": (lambda w: features.quad_normals(w.vertices, w.quads),
        lambda w: features.quad_normals(w.vertices, w.quads[0]),
        ValueError, r"quad_normals: quads must have shape \[F, 4\], got \[4\]"),
    "vertex_normals vertices": (lambda w: features.vertex_normals(w.vertices, w.quads),
        lambda w: features.vertex_normals(w.vertices[None], w.quads), ValueError, ANY),
    "fundamental_forms quads": (lambda w: features.fundamental_forms(w.vertices, w.quads),
        lambda w: features.fundamental_forms(w.vertices, w.triangles), ValueError, ANY),
    "face_features vertices": (lambda w: features.face_features(w.vertices, w.quads),
        lambda w: features.face_features(w.vertices.T, w.quads), ValueError, ANY),
    "noc_coordinates vertices": (lambda w: features.noc_coordinates(w.vertices / 4),
        lambda w: features.noc_coordinates(w.vertices[:, :2]), ValueError, ANY),
    "normalize vertices": (lambda w: clean.normalize(w.vertices), lambda w: clean.normalize(w.vertices.ravel()),
        ValueError, ANY),
    "mesh_set faces": (None, lambda w: clean.mesh_set(w.vertices, w.quads),
        ValueError, r"mesh_set: faces must have shape \[T, 3\]"),
    "clean_mesh faces": (None, lambda w: clean.clean_mesh(w.vertices, w.quads), ValueError, ANY),
    "triangle_areas faces": (lambda w: clean.triangle_areas(w.vertices, w.triangles),
        lambda w: clean.triangle_areas(w.vertices, w.quads), ValueError, ANY),
    "decimate vertices": (lambda w: clean.decimate(w.vertices, w.triangles, 1000),
        lambda w: clean.decimate(w.vertices[:, :2], w.triangles, 1000), ValueError, ANY),
    "isotropic_remesh faces": (None, lambda w: clean.isotropic_remesh(w.vertices, w.quads, 0.1), ValueError, ANY),
    "prepare_shape faces": (None, lambda w: prepare.prepare_shape(w.vertices, w.quads),
        ValueError, r"prepare_shape: faces must have shape \[T, 3\], got \[24, 4\]"),
    "surface_deviation quads": (
        lambda w: prepare.surface_deviation(w.vertices, w.triangles, w.vertices, w.quads, max_points=100),
        lambda w: prepare.surface_deviation(w.vertices, w.triangles, w.vertices, w.triangles), ValueError, ANY),
    "coarseness_check quad_vertices": (None,
        lambda w: prepare.coarseness_check(w.vertices, w.triangles, w.vertices[:, :2], w.quads, 24),
        ValueError, r"coarseness_check: quad_vertices must have shape \[V', 3\]"),
    "subdivide_quads quads": (lambda w: primitives.subdivide_quads(w.vertices, w.quads),
        lambda w: primitives.subdivide_quads(w.vertices, w.triangles), ValueError, ANY),
    "unit_surface faces": (lambda w: primitives.unit_surface(w.vertices, w.triangles),
        lambda w: primitives.unit_surface(w.vertices, w.quads[:, :2]),
        ValueError, r"unit_surface: faces must have shape \[F, 4\] or \[F, 3\], got \[24, 2\]"),
    "unit_transform vertices": (lambda w: primitives.unit_transform(w.vertices),
        lambda w: primitives.unit_transform(w.vertices[0]), ValueError, ANY),
    "mean_edge_length faces": (lambda w: primitives.mean_edge_length(w.vertices, w.quads),
        lambda w: primitives.mean_edge_length(w.vertices, w.quads.ravel()), ValueError, ANY),
    "expression_weights positions": (lambda w: regions.expression_weights("x > 0", w.vertices),
        lambda w: regions.expression_weights("x > 0", w.vertices[:, :2]),
        ValueError, r"expression_weights: positions must have shape \[V, 3\], got \[26, 2\]"),
    "region_weights positions": (None, lambda w: regions.region_weights("x > 0", w.vertices[:, 0]), ValueError, ANY),
    "surface_samples faces": (lambda w: levelset.surface_samples(w.vertices, w.triangles, 0.5),
        lambda w: levelset.surface_samples(w.vertices, w.quads, 0.5), ValueError, ANY),
    "solid_field samples": (None, lambda w: levelset.solid_field(w.vertices[:, :2], 0.5, 0.1), ValueError, ANY),
    "make_well_composed inside": (lambda w: levelset.make_well_composed(np.zeros((4, 4, 4), bool)),
        lambda w: levelset.make_well_composed(np.zeros((4, 4), bool)),
        ValueError, r"make_well_composed: inside must have shape \[X, Y, Z\], got \[4, 4\]"),
}

CASES = {**LOSSES, **METRICS, **TRANSFER, **GEOMETRY}


@pytest.mark.parametrize("case", list(CASES))
def test_each_checked_function_passes_a_correct_call_and_names_a_wrong_argument(case, w):
    """The correct call (when the table gives one) runs through; the wrong one raises ``error`` whose message
    starts with the function's name (the case's first word) and matches the table's regex."""
    function, _, argument = case.partition(" ")
    good, bad, error, message = CASES[case]
    if good is not None:
        good(w)
    with pytest.raises(error, match=f"^{re.escape(function)}: ") as caught:
        bad(w)
    assert re.search(message, str(caught.value)), f"{argument}: {caught.value}"


def test_check_array_shape_reads_shapes_of_arrays_lists_and_tensors():
    from mesh2tex.checks import check_array_shape

    sizes = check_array_shape(np.zeros((5, 3)), "f: v", ("V", 3))
    assert sizes == {"V": (5, "v")}
    check_array_shape([[0, 1, 2, 3]], "f: q", ("F", 4))
    check_array_shape(torch.zeros(5, 2), "f: uv", ("V", 2), sizes=sizes)
    assert check_array_shape(None, "f: x", ("V", 3), optional=True) == {}
    with pytest.raises(ValueError, match=r"f: uv must have shape \[V, 2\] \(V = 5 from v\), got \[4, 2\]"):
        check_array_shape(np.zeros((4, 2)), "f: uv", ("V", 2), sizes=sizes)
