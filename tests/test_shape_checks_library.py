"""Every checked public function of mesh2tex.losses and .metrics: a correct call still works, and a wrong rank, size
or dtype fails at the call with a message that names the function and the argument (ValueError for a shape,
TypeError for a non-tensor or a wrong dtype), not deep inside. The companions: tests/test_shape_checks.py (render
and nn), tests/test_shape_checks_geometry.py (transfer and geometry)."""

from __future__ import annotations

import importlib

import numpy as np
import pytest
import torch
from shape_check_cases import ANY, check_case, correct_inputs, pair_sets, stand_in_layers

from mesh2tex.losses import augment, ot_style, style
from mesh2tex.losses import structure as structure_loss
from mesh2tex.losses.gan import GanLoss, GanLossConfig, mode_seeking_ratio, object_lab_moments
from mesh2tex.metrics import appearance, distribution, evaluate, generation, spectrum, structure
from mesh2tex.metrics.features import FeatureExtractor
from mesh2tex.metrics.inception import InceptionV3Features

swd = importlib.import_module("mesh2tex.metrics.swd")  # the package's ``swd`` is the function of that name


@pytest.fixture(scope="module")
def w():
    """Small correct inputs that the cases below break one argument at a time."""
    return correct_inputs()


LOSSES = {
    "augment_colour x": (
        lambda w: augment.augment_colour(w.images),
        lambda w: augment.augment_colour(w.images[0]),
        ValueError,
        r"augment_colour: x must have shape \[N, C, H, W\], got \[3, 32, 32\]",
    ),
    "augment_translation x": (
        lambda w: augment.augment_translation(w.images),
        lambda w: augment.augment_translation((w.images * 255).long()),
        TypeError,
        r"augment_translation: x must be a floating-point tensor, got int64",
    ),
    "augment_cutout x": (
        lambda w: augment.augment_cutout(w.images),
        lambda w: augment.augment_cutout(w.images[:, 0]),
        ValueError,
        ANY,
    ),
    "DiffAugment x": (
        lambda w: augment.DiffAugment()(w.images),
        lambda w: augment.DiffAugment()(w.images.numpy()),
        TypeError,
        r"DiffAugment: x must be a torch.Tensor of shape \[N, C, H, W\], got ndarray",
    ),
    "mode_seeking_ratio mask": (
        lambda w: mode_seeking_ratio(w.images, w.images, w.masks, torch.rand(2, 4), torch.rand(2, 4)),
        lambda w: mode_seeking_ratio(w.images, w.images, w.masks[:1], torch.rand(2, 4), torch.rand(2, 4)),
        ValueError,
        r"mode_seeking_ratio: mask must have shape \[N, 1, H, W\] \(N = 2 from proxy_a\)",
    ),
    "mode_seeking_ratio z_b": (
        None,
        lambda w: mode_seeking_ratio(w.images, w.images, w.masks, torch.rand(2, 4), torch.rand(2, 5)),
        ValueError,
        r"mode_seeking_ratio: z_b must have shape \[B, Z\] \(Z = 4 from z_a\)",
    ),
    "object_lab_moments mask": (
        lambda w: object_lab_moments(w.images, w.masks),
        lambda w: object_lab_moments(w.images, w.masks[..., :16]),
        ValueError,
        r"object_lab_moments: mask must have shape \[N, 1, H, W\] \(W = 32 from images\)",
    ),
    "GanLoss.set_colour_target photos": (
        lambda w: GanLoss(GanLossConfig(), None, None).set_colour_target(w.images, w.masks),
        lambda w: GanLoss(GanLossConfig(), None, None).set_colour_target(w.images[:, :2], w.masks),
        ValueError,
        r"GanLoss.set_colour_target: photos must have shape \[N, 3, H, W\]",
    ),
    "GanLoss.colour_loss mask": (
        lambda w: w.gan.colour_loss(w.images, w.masks),
        lambda w: w.gan.colour_loss(w.images, w.masks[0]),
        ValueError,
        r"GanLoss.colour_loss: mask must have shape",
    ),
    "GanLoss.accumulate_gradients real": (
        None,
        lambda w: w.gan.accumulate_gradients("Dmain", None, torch.zeros(2, 4), w.images[0]),
        ValueError,
        r"GanLoss.accumulate_gradients: real must have shape \[\*, 3, \*, \*\]",
    ),
    "composite_background masks": (
        lambda w: style.composite_background(w.images, w.masks),
        lambda w: style.composite_background(w.images, w.masks[:, :, :8]),
        ValueError,
        r"composite_background: masks must have shape \[B, 1, H, W\] \(H = 32 from images\)",
    ),
    "masked_gram features": (
        lambda w: style.masked_gram(w.images, w.masks[..., ::2, ::2]),
        lambda w: style.masked_gram(w.images[0]),
        ValueError,
        r"masked_gram: features must have shape \[B, C, h, w\], got \[3, 32, 32\]",
    ),
    "downsample masks": (
        lambda w: style.downsample(w.images, None),
        lambda w: style.downsample(w.images, w.masks[:1]),
        ValueError,
        r"downsample: masks must have shape \[B, 1, H, W\] \(B = 2 from images\)",
    ),
    "style_grams images": (
        lambda w: style.style_grams(stand_in_layers, w.images, w.masks, scales=2),
        lambda w: style.style_grams(stand_in_layers, w.images[:, :1], w.masks, scales=2),
        ValueError,
        ANY,
    ),
    "global_style_loss target_masks": (
        lambda w: style.global_style_loss(stand_in_layers, w.images, w.masks, w.images[:1], w.masks[:1], scales=2),
        lambda w: style.global_style_loss(stand_in_layers, w.images, w.masks, w.images[:1], w.masks, scales=2),
        ValueError,
        r"global_style_loss: target_masks must have shape \[T, 1, H', W'\] \(T = 1",
    ),
    "random_object_pixels mask": (
        lambda w: style.random_object_pixels(w.masks[0], 3),
        lambda w: style.random_object_pixels(w.masks, 3),
        ValueError,
        r"random_object_pixels: mask must have shape \[H, W\] or \[1, H, W\] or \[1, 1, H, W\]",
    ),
    "nearest_noc_pixels render_mask": (
        lambda w: style.nearest_noc_pixels(w.noc[:2, 0], w.noc, w.photo.mask),
        lambda w: style.nearest_noc_pixels(w.noc[:2, 0], w.noc, w.masks[0]),
        ValueError,
        r"nearest_noc_pixels: render_mask must have shape .*\(H = 64 from render_noc\)",
    ),
    "sample_patch_pairs photo_noc": (
        lambda w: style.sample_patch_pairs(w.photo.mask, w.view.mask, 2, w.noc, w.view.noc),
        lambda w: style.sample_patch_pairs(w.photo.mask, w.view.mask, 2, w.noc[:32], w.view.noc),
        ValueError,
        r"sample_patch_pairs: photo_noc must have shape \[H, W, 3\] \(H = 64 from photo_mask\)",
    ),
    "crop_patches centres": (
        lambda w: style.crop_patches(w.images[:1], torch.tensor([[3, 4]]), 8),
        lambda w: style.crop_patches(w.images[:1], torch.tensor([[3.0, 4.0]]), 8),
        TypeError,
        r"crop_patches: centres must be an integer tensor, got float32",
    ),
    "patch_style_loss rendered_mask": (
        lambda w: style.patch_style_loss(
            stand_in_layers, w.photo.image, w.photo.mask, w.photo.image, w.photo.mask, pair_sets(), 32, 2
        ),
        lambda w: style.patch_style_loss(
            stand_in_layers, w.photo.image, w.masks[:1], w.photo.image, w.photo.mask, pair_sets(), 32, 2
        ),
        ValueError,
        r"patch_style_loss: rendered_mask must have shape .*\(H = 64 from rendered\)",
    ),
    "lowpass_colour_loss rendered_mask": (
        lambda w: style.lowpass_colour_loss(w.images, w.masks, w.images, w.masks, 2.0),
        lambda w: style.lowpass_colour_loss(w.images, w.masks[:, 0], w.images, w.masks, 2.0),
        ValueError,
        r"lowpass_colour_loss: rendered_mask must have shape \[B, 1, H, W\]",
    ),
    "image_layers images": (
        lambda w: ot_style.image_layers(stand_in_layers, w.images, 1),
        lambda w: ot_style.image_layers(stand_in_layers, w.images[0], 1),
        ValueError,
        ANY,
    ),
    "feature_sets mask": (
        lambda w: ot_style.feature_sets([w.images], w.masks[0], 64),
        lambda w: ot_style.feature_sets([w.images], w.masks, 64),
        ValueError,
        r"feature_sets: mask must have shape \[1, \*, \*\], got \[2, 1, 32, 32\]",
    ),
    "relaxed_emd b": (
        lambda w: ot_style.relaxed_emd(*w.sets, l2=True),
        lambda w: ot_style.relaxed_emd(w.sets[0], w.sets[1][:, :2], l2=True),
        ValueError,
        r"relaxed_emd: b must have shape \[Q, C\] \(C = 3 from a\), got \[10, 2\]",
    ),
    "moment_loss a": (
        lambda w: ot_style.moment_loss(*w.sets),
        lambda w: ot_style.moment_loss(w.sets[0][0], w.sets[1]),
        ValueError,
        ANY,
    ),
    "ot_style_distance exemplar_sets": (
        lambda w: ot_style.ot_style_distance([w.sets[0]], [w.sets[1]]),
        lambda w: ot_style.ot_style_distance([w.sets[0]], [w.sets[1], w.sets[1]]),
        ValueError,
        r"ot_style_distance: render_sets and exemplar_sets must hold one set per layer",
    ),
    "ExemplarFeatures.compute image": (
        lambda w: ot_style.ExemplarFeatures.compute(None, w.images[:1], 0),
        lambda w: ot_style.ExemplarFeatures.compute(None, w.images, 0),
        ValueError,
        r"ExemplarFeatures.compute: image must have shape \[1, 3, \*, \*\]",
    ),
    "style_loss masks": (
        lambda w: ot_style.style_loss(stand_in_layers, w.images, w.masks, w.exemplar, "gram"),
        lambda w: ot_style.style_loss(stand_in_layers, w.images, w.masks[:1], w.exemplar, "gram"),
        ValueError,
        ANY,
    ),
    "quantile_resample sorted_values": (
        lambda w: structure_loss.quantile_resample(w.sets[0], 5),
        lambda w: structure_loss.quantile_resample(w.sets[0][:, 0], 5),
        ValueError,
        ANY,
    ),
    "sliced_wasserstein2 directions": (
        lambda w: structure_loss.sliced_wasserstein2(*w.sets, torch.eye(3)),
        lambda w: structure_loss.sliced_wasserstein2(*w.sets, torch.eye(4)),
        ValueError,
        r"sliced_wasserstein2: directions must have shape \[C, K\] \(C = 3 from a\)",
    ),
    "sw_distance render_sets": (
        lambda w: structure_loss.sw_distance([w.sets[0]], [w.sets[1]]),
        lambda w: structure_loss.sw_distance(w.sets[0], [w.sets[1]]),
        TypeError,
        r"sw_distance: render_sets must be a list, got Tensor",
    ),
    "band_statistics mask": (
        lambda w: structure_loss.band_statistics(w.images[:1], w.masks[:1]),
        lambda w: structure_loss.band_statistics(w.images[:1], w.masks),
        ValueError,
        ANY,
    ),
    "exemplar_band_statistics image": (
        lambda w: structure_loss.exemplar_band_statistics(w.images[:1]),
        lambda w: structure_loss.exemplar_band_statistics(w.images[0]),
        ValueError,
        ANY,
    ),
    "ps_loss masks": (
        lambda w: structure_loss.ps_loss(w.images, w.masks, structure_loss.exemplar_band_statistics(w.images[:1])),
        lambda w: structure_loss.ps_loss(w.images, w.masks[:1], {}),
        ValueError,
        ANY,
    ),
}

METRICS = {
    "rgb_to_lab images": (
        lambda w: appearance.rgb_to_lab(w.images),
        lambda w: appearance.rgb_to_lab(w.images[:, :2]),
        ValueError,
        r"rgb_to_lab: images must have shape \[B, 3, H, W\], got \[2, 2, 32, 32\]",
    ),
    "part_colours parts": (
        lambda w: appearance.part_colours(w.images, torch.zeros(2, 32, 32, dtype=torch.long)),
        lambda w: appearance.part_colours(w.images, torch.zeros(2, 32, 32)),
        TypeError,
        r"part_colours: parts must be an integer tensor, got float32",
    ),
    "part_colour_error reference_parts": (
        lambda w: appearance.part_colour_error(w.images, w.images, torch.zeros(2, 32, 32, dtype=torch.long)),
        lambda w: appearance.part_colour_error(
            w.images,
            w.images[..., :16, :16],
            torch.zeros(2, 32, 32, dtype=torch.long),
            w.masks,
            torch.zeros(2, 32, 32, dtype=torch.long),
            w.masks[..., :16, :16],
        ),
        ValueError,
        r"part_colour_error: reference_parts must have shape \[B, H', W'\] \(H' = 16",
    ),
    "masked_blur masks": (
        lambda w: appearance.masked_blur(w.images, w.masks, 1.0),
        lambda w: appearance.masked_blur(w.images, w.masks[0], 1.0),
        ValueError,
        ANY,
    ),
    "lowpass_psnr references": (
        lambda w: appearance.lowpass_psnr(w.images, w.images.flip(0), w.masks),
        lambda w: appearance.lowpass_psnr(w.images, w.images[..., :16], w.masks),
        ValueError,
        r"lowpass_psnr: references must have shape \[B, 3, H, W\] \(W = 32 from images\)",
    ),
    "object_swd reference_masks": (
        lambda w: appearance.object_swd(w.images, w.images, w.masks, patches=16, projections=8),
        lambda w: appearance.object_swd(w.images, w.images, w.masks, w.masks[..., :16, :16]),
        ValueError,
        r"object_swd: reference_masks must have shape \[B, 1, H', W'\] \(H' = 32 from references\)",
    ),
    "kid features_b": (
        lambda w: distribution.kid(*w.sets, num_subsets=2),
        lambda w: distribution.kid(w.sets[0], w.sets[1][:, :2]),
        ValueError,
        r"kid: features_b must have shape \[M, D\] \(D = 3 from features_a\), got \[10, 2\]",
    ),
    "fid features_a": (
        lambda w: distribution.fid(*w.sets),
        lambda w: distribution.fid(w.sets[0].long(), w.sets[1]),
        TypeError,
        r"fid: features_a must be a floating-point tensor",
    ),
    "trace_sqrt_product centred_b": (
        lambda w: distribution.trace_sqrt_product(np.ones((4, 3)), np.ones((5, 3))),
        lambda w: distribution.trace_sqrt_product(np.ones((4, 3)), np.ones((5, 2))),
        ValueError,
        r"trace_sqrt_product: centred_b must have shape \[n_b, D\] \(D = 3 from centred_a\)",
    ),
    "evaluate_sets images": (
        None,
        lambda w: evaluate.evaluate_sets(w.images, w.images[..., :16, :16]),
        ValueError,
        r"evaluate_sets: images must have shape \[M, 3, H, W\] \(H = 32 from renders\)",
    ),
    "evaluate_sets image_features": (
        None,
        lambda w: evaluate.evaluate_sets(w.images, w.images, image_features=torch.zeros(3, 8)),
        ValueError,
        r"evaluate_sets: image_features must have shape \[M, \*\] \(M = 2 from images\)",
    ),
    "pooled_histogram_distance image_masks": (
        lambda w: evaluate.pooled_histogram_distance(w.images, w.images, w.masks, w.masks, 4),
        lambda w: evaluate.pooled_histogram_distance(w.images, w.images, w.masks, w.masks[:, 0], 4),
        ValueError,
        ANY,
    ),
    "evaluate_pairs masks": (
        lambda w: evaluate.evaluate_pairs(w.images, w.images, w.masks),
        lambda w: evaluate.evaluate_pairs(w.images, w.images, w.masks[:1]),
        ValueError,
        r"evaluate_pairs: masks must have shape \[N, 1, H, W\] \(N = 2 from renders\)",
    ),
    "FeatureExtractor images": (
        lambda w: FeatureExtractor("mean", "", lambda x: x.mean((2, 3)))(w.images),
        lambda w: FeatureExtractor("mean", "", lambda x: x.mean((2, 3)))(w.images[0]),
        ValueError,
        ANY,
    ),
    "InceptionV3Features images": (
        None,
        lambda w: InceptionV3Features()(w.images[:, :1]),
        ValueError,
        r"InceptionV3Features: images must have shape \[B, 3, H, W\]",
    ),
    "srgb_to_lab images": (
        lambda w: generation.srgb_to_lab(w.images),
        lambda w: generation.srgb_to_lab(w.images[0]),
        ValueError,
        ANY,
    ),
    "mean_object_lab masks": (
        lambda w: generation.mean_object_lab(w.images, w.masks),
        lambda w: generation.mean_object_lab(w.images, w.masks[:1]),
        ValueError,
        ANY,
    ),
    "colour_spread lab_means": (
        lambda w: generation.colour_spread(w.sets[0]),
        lambda w: generation.colour_spread(w.sets[0][:, :2]),
        ValueError,
        r"colour_spread: lab_means must have shape \[K, 3\], got \[20, 2\]",
    ),
    "mean_pairwise_delta_e mask": (
        lambda w: generation.mean_pairwise_delta_e(w.images, w.masks[0]),
        lambda w: generation.mean_pairwise_delta_e(w.images, w.masks[0, 0]),
        ValueError,
        ANY,
    ),
    "object_set_swd references": (
        lambda w: generation.object_set_swd(w.images, w.masks, w.images, w.masks, 16, projections=8),
        lambda w: generation.object_set_swd(w.images, w.masks, w.images[..., :16, :16], w.masks),
        ValueError,
        r"object_set_swd: references must have shape \[M, 3, H, W\] \(H = 32 from images\)",
    ),
    "object_patches masks": (
        lambda w: spectrum.object_patches(w.images, w.masks, 8),
        lambda w: spectrum.object_patches(w.images, w.masks.expand(2, 3, 32, 32), 8),
        ValueError,
        ANY,
    ),
    "high_frequency_share images": (
        lambda w: spectrum.high_frequency_share(w.images, w.masks, 0.25, patch=8),
        lambda w: spectrum.high_frequency_share(w.images[:, :1], w.masks, 0.25, patch=8),
        ValueError,
        r"high_frequency_share: images must have shape \[B, 3, H, W\]",
    ),
    "radial_power masks": (
        lambda w: spectrum.radial_power(w.images, w.masks, [0.0, 0.25, 0.5], patch=8),
        lambda w: spectrum.radial_power(w.images, w.masks[:1], [0.0, 0.5], patch=8),
        ValueError,
        ANY,
    ),
    "luminance images": (
        lambda w: structure.luminance(w.images),
        lambda w: structure.luminance(w.images[:, :1]),
        ValueError,
        ANY,
    ),
    "orientation_windows masks": (
        lambda w: structure.orientation_windows(w.images, w.masks, 8),
        lambda w: structure.orientation_windows(w.images, w.masks[0], 8),
        ValueError,
        r"orientation_windows: masks must have shape \[N, 1, H, W\]",
    ),
    "orientation_scores doubled": (
        lambda w: structure.orientation_scores(torch.ones(3, 16), torch.ones(3, dtype=torch.complex128)),
        lambda w: structure.orientation_scores(torch.ones(3, 16), torch.ones(4, dtype=torch.complex128)),
        ValueError,
        r"orientation_scores: doubled must have shape \[M\] \(M = 3 from histograms\)",
    ),
    "spectrum_period images": (
        lambda w: structure.spectrum_period(w.images, None, 16),
        lambda w: structure.spectrum_period(w.images.double().long(), None, 16),
        TypeError,
        "floating-point",
    ),
    "patch_swd exemplar": (
        lambda w: structure.patch_swd(w.images, w.masks, w.images[:1], levels=1, projections=8),
        lambda w: structure.patch_swd(w.images, w.masks, w.images[0], levels=1),
        ValueError,
        r"patch_swd: exemplar must have shape \[M, 3, h, w\], got \[3, 32, 32\]",
    ),
    "patch_swd exemplar_masks": (
        lambda w: structure.patch_swd(w.images, w.masks, w.images, levels=1, projections=8, exemplar_masks=w.masks),
        lambda w: structure.patch_swd(w.images, w.masks, w.images, levels=1, exemplar_masks=w.masks[..., :8]),
        ValueError,
        r"patch_swd: exemplar_masks must have shape \[M, 1, h, w\] \(w = 32 from exemplar\), got \[2, 1, 32, 8\]",
    ),
    "structure_scores masks": (None, lambda w: structure.structure_scores(w.images, w.masks[..., :8]), ValueError, ANY),
    "laplacian_pyramid images": (
        lambda w: swd.laplacian_pyramid(w.images),
        lambda w: swd.laplacian_pyramid(w.images[0]),
        ValueError,
        ANY,
    ),
    "sliced_wasserstein descriptors_b": (
        lambda w: swd.sliced_wasserstein(w.sets[0], w.sets[0], 4, torch.Generator()),
        lambda w: swd.sliced_wasserstein(w.sets[0], w.sets[1], 4, torch.Generator()),
        ValueError,
        r"sliced_wasserstein: descriptors_b must have shape \[M, D\] \(M = 20 from descriptors_a\)",
    ),
    "sorted_rows values": (
        lambda w: swd.sorted_rows(w.sets[0].double()),
        lambda w: swd.sorted_rows(w.sets[0][0]),
        ValueError,
        ANY,
    ),
    "swd_per_level images_b": (
        lambda w: swd.swd_per_level(w.images, w.images, 4, num_projections=8, repeats=1),
        lambda w: swd.swd_per_level(w.images, w.images[..., :16]),
        ValueError,
        r"swd_per_level: images_b must have shape \[M, 3, H, W\] \(W = 32 from images_a\)",
    ),
    "swd images_a": (None, lambda w: swd.swd(w.images[:, :2], w.images), ValueError, r"swd: images_a must have shape"),
}

CASES = {**LOSSES, **METRICS}


@pytest.mark.parametrize("case", list(CASES))
def test_each_checked_function_passes_a_correct_call_and_names_a_wrong_argument(case, w):
    check_case(CASES, case, w)
