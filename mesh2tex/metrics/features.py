"""Feature extractors for KID and FID, each with the name its metrics are reported under.

A metric is only called ``kid``/``fid`` when it is computed on the features it is defined on (the
FID Inception-v3). Every other extractor gives its metrics a suffix naming the features:

============  =======================================================  ======================
name          features                                                  metrics reported as
============  =======================================================  ======================
inception     FID Inception-v3 (pt_inception weights), pool3 2048-d     ``kid``, ``fid``
tvinception   torchvision Inception-v3 ImageNet weights, pool 2048-d    ``kid_tvinception`` ...
vgg           ImageNet VGG19, mean and std of the 5 style layers        ``kid_vgg`` ...
randvgg       random-weight VGG19 (seed 0), same statistics, no files   ``kid_randvgg`` ...
============  =======================================================  ======================

``randvgg`` needs no weights: it ranks sets by colour and texture statistics and is useful to
compare runs with each other, but its values are not comparable with published KID/FID numbers.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from typing import Callable

import torch
import torch.nn.functional as F

from mesh2tex.checks import check_shape
from mesh2tex.errors import InputError
from mesh2tex.metrics.inception import FID_INCEPTION_URL, INCEPTION_FILE_NAMES, find_inception_weights, load_inception
from mesh2tex.nn.vgg import VGG19Features, find_vgg19_weights, load_vgg19, torch_hub_checkpoint_dir

EXTRACTOR_NAMES = ("auto", "inception", "tvinception", "vgg", "randvgg")
VGG_FEATURE_RESOLUTION = 128  # images are resized to this square size before the VGG statistics


@dataclass
class FeatureExtractor:
    """``name`` (the metric suffix, "" for the standard Inception), ``description`` (what the features
    are, for reports) and ``extract``: images [B, 3, H, W] float in [-1, 1] -> features [B, D] float32."""

    name: str
    description: str
    extract: Callable[[torch.Tensor], torch.Tensor]

    def metric_name(self, metric: str) -> str:
        """``kid`` -> ``kid`` for the standard features, ``kid_<name>`` otherwise."""
        return metric if not self.name else f"{metric}_{self.name}"

    @torch.no_grad()
    def __call__(self, images: torch.Tensor, batch_size: int = 32) -> torch.Tensor:
        """Features of all images [N, 3, H, W] in [-1, 1], in batches: [N, D] float64 on the CPU."""
        check_shape(images, "FeatureExtractor: images", ("N", 3, "H", "W"), dtype="float")
        chunks = [
            self.extract(images[i : i + batch_size]).double().cpu() for i in range(0, images.shape[0], batch_size)
        ]
        return torch.cat(chunks)


def vgg_statistics(vgg: VGG19Features) -> Callable[[torch.Tensor], torch.Tensor]:
    """Images -> per-channel mean and standard deviation of the 5 VGG19 style layers, concatenated
    ([B, 2 * 1472]): first- and second-order texture statistics, after resizing to 128 x 128."""
    parameter = next(vgg.parameters())

    def extract(images: torch.Tensor) -> torch.Tensor:
        images = F.interpolate(
            images.to(parameter),
            size=(VGG_FEATURE_RESOLUTION,) * 2,
            mode="bilinear",
            align_corners=False,
            antialias=True,
        )
        statistics = []
        for features in vgg(images):
            flat = features.flatten(2)
            statistics += [flat.mean(dim=2), flat.std(dim=2)]
        return torch.cat(statistics, dim=1)

    return extract


def get_feature_extractor(
    name: str = "auto",
    inception_weights: str | os.PathLike | None = None,
    vgg_weights: str | os.PathLike | None = None,
    device: str | torch.device = "cpu",
) -> FeatureExtractor:
    """The extractor ``name`` (see the module table).

    ``auto``: the Inception-v3 of ``inception_weights`` / $MESH2TEX_INCEPTION_WEIGHTS / torchvision's
    cache when one is found (variant read from the file), else ``randvgg`` with a warning.
    ``inception``/``tvinception`` need such a file (InputError if none, or if it is the other variant);
    ``vgg`` needs ImageNet VGG19 weights (see :mod:`mesh2tex.nn.vgg`); ``randvgg`` needs nothing.
    """
    if name not in EXTRACTOR_NAMES:
        raise InputError(f"unknown feature extractor '{name}' (choose from {', '.join(EXTRACTOR_NAMES)})")
    if name in ("auto", "inception", "tvinception"):
        found = find_inception_weights(inception_weights)
        if found is None and name != "auto":
            raise InputError(
                f"no Inception-v3 weights found for '{name}': pass --inception-weights PATH or put one of "
                f"{', '.join(INCEPTION_FILE_NAMES)} in {torch_hub_checkpoint_dir()}"
            )
        if found is not None:
            model = load_inception(found, device)
            variant = "inception" if model.fid_variant else "tvinception"
            if name != "auto" and name != variant:
                raise InputError(f"{found}: holds {variant} weights, not {name} weights")
            parameter = next(model.parameters())
            description = (
                "FID Inception-v3 pool3 features" if model.fid_variant else "torchvision Inception-v3 pool features"
            ) + f" ({found})"
            return FeatureExtractor(
                "" if model.fid_variant else "tvinception", description, lambda x: model(x.to(parameter))
            )
        warnings.warn(
            "no Inception-v3 weights found (looked for $MESH2TEX_INCEPTION_WEIGHTS and "
            f"{', '.join(INCEPTION_FILE_NAMES)} in "
            f"{torch_hub_checkpoint_dir()}); KID/FID are computed on random-weight VGG19 statistics and reported as "
            f"kid_randvgg/fid_randvgg, which rank runs but are not comparable with published numbers. For standard "
            f"KID/FID download {FID_INCEPTION_URL} there or pass --inception-weights PATH.",
            UserWarning,
            stacklevel=2,
        )
        name = "randvgg"
    if name == "vgg":
        if find_vgg19_weights(vgg_weights) is None:
            raise InputError(
                "the 'vgg' feature extractor needs ImageNet VGG19 weights: pass --vgg-weights PATH "
                f"or put vgg19-dcbb9e9d.pth in {torch_hub_checkpoint_dir()}"
            )
        vgg = load_vgg19(vgg_weights, device)
        return FeatureExtractor(
            "vgg", f"ImageNet VGG19 style-layer channel means and stds ({vgg.source})", vgg_statistics(vgg)
        )
    vgg = VGG19Features()
    vgg.init_random()
    vgg = vgg.to(device).eval().requires_grad_(False)
    return FeatureExtractor(
        "randvgg",
        "random-weight VGG19 (seed 0) style-layer channel means and stds; no pretrained weights",
        vgg_statistics(vgg),
    )
