"""Metrics between renders and images.

Sets (renders against a photo collection):
    :func:`kid`, :func:`fid` on features of a named :class:`FeatureExtractor`
    (:func:`get_feature_extractor`: standard Inception-v3 from a local weight file, or a clearly named
    substitute such as ``randvgg``; see :mod:`mesh2tex.metrics.features`);
    :func:`swd` / :func:`swd_per_level`, sliced Wasserstein distance on Laplacian-pyramid patches (no weights).
Pairs (render and reference with exactly the same geometry and pose):
    :func:`masked_psnr`, :func:`masked_ssim`, :func:`colour_histogram_distance`.
"""

from mesh2tex.metrics.distribution import fid, kid
from mesh2tex.metrics.features import EXTRACTOR_NAMES, FeatureExtractor, get_feature_extractor
from mesh2tex.metrics.image import colour_histogram_distance, colour_histograms, masked_psnr, masked_ssim, to_unit
from mesh2tex.metrics.inception import InceptionV3Features, find_inception_weights, load_inception
from mesh2tex.metrics.swd import swd, swd_per_level

__all__ = [
    "EXTRACTOR_NAMES",
    "FeatureExtractor",
    "InceptionV3Features",
    "colour_histogram_distance",
    "colour_histograms",
    "fid",
    "find_inception_weights",
    "get_feature_extractor",
    "kid",
    "load_inception",
    "masked_psnr",
    "masked_ssim",
    "swd",
    "swd_per_level",
    "to_unit",
]
