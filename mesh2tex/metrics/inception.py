"""Inception-v3 up to its 2048-d pool features, for FID and KID, written without torchvision.

Two weight files are understood, both plain state dicts read with ``torch.load(weights_only=True)``:

* ``pt_inception-2015-12-05-6726825d.pth``: the port of the TensorFlow FID Inception used by the
  standard FID code (1008 classes). Its blocks differ slightly from torchvision's (average pools
  that exclude padding, a max pool in the last block); with it, ``fid``/``kid`` are the standard
  metrics (up to resizing differences).
* ``inception_v3_google-0cc3c7bd.pth``: torchvision's ImageNet Inception-v3 (1000 classes). Its
  features are close to, but not the same as, the standard ones, so its metrics are named
  ``fid_tvinception``/``kid_tvinception``.

The variant is recognised from the file (the classifier has 1008 or 1000 outputs). Inputs are
images in [-1, 1], resized bilinearly to 299 x 299 (both weight sets expect that range).
"""

from __future__ import annotations

import os
from pathlib import Path

import torch
import torch.nn as nn
import torch.nn.functional as F

from mesh2tex.checks import check_shape
from mesh2tex.errors import InputError
from mesh2tex.nn.vgg import find_weight_file, read_state_dict

INCEPTION_FILE_NAMES = (
    "pt_inception-2015-12-05-6726825d.pth",
    "inception_v3_google-0cc3c7bd.pth",
    "inception_v3_google-1a9a5a14.pth",
)
FID_INCEPTION_URL = (
    "https://github.com/mseitzer/pytorch-fid/releases/download/fid_weights/pt_inception-2015-12-05-6726825d.pth"
)


class ConvBN(nn.Module):
    """Convolution without bias, batch norm (eps 1e-3), ReLU: Inception's basic layer."""

    def __init__(self, in_channels: int, out_channels: int, kernel_size, stride=1, padding=0):
        super().__init__()
        self.conv = nn.Conv2d(in_channels, out_channels, kernel_size, stride=stride, padding=padding, bias=False)
        self.bn = nn.BatchNorm2d(out_channels, eps=0.001)

    def forward(self, x):
        return F.relu(self.bn(self.conv(x)))


def _avg_pool(x, fid: bool):
    # The TensorFlow graph behind FID averages only over real (unpadded) pixels.
    return F.avg_pool2d(x, 3, stride=1, padding=1, count_include_pad=not fid)


class InceptionA(nn.Module):
    def __init__(self, in_channels: int, pool_features: int, fid: bool):
        super().__init__()
        self.fid = fid
        self.branch1x1 = ConvBN(in_channels, 64, 1)
        self.branch5x5_1 = ConvBN(in_channels, 48, 1)
        self.branch5x5_2 = ConvBN(48, 64, 5, padding=2)
        self.branch3x3dbl_1 = ConvBN(in_channels, 64, 1)
        self.branch3x3dbl_2 = ConvBN(64, 96, 3, padding=1)
        self.branch3x3dbl_3 = ConvBN(96, 96, 3, padding=1)
        self.branch_pool = ConvBN(in_channels, pool_features, 1)

    def forward(self, x):
        return torch.cat(
            [
                self.branch1x1(x),
                self.branch5x5_2(self.branch5x5_1(x)),
                self.branch3x3dbl_3(self.branch3x3dbl_2(self.branch3x3dbl_1(x))),
                self.branch_pool(_avg_pool(x, self.fid)),
            ],
            1,
        )


class InceptionB(nn.Module):
    def __init__(self, in_channels: int):
        super().__init__()
        self.branch3x3 = ConvBN(in_channels, 384, 3, stride=2)
        self.branch3x3dbl_1 = ConvBN(in_channels, 64, 1)
        self.branch3x3dbl_2 = ConvBN(64, 96, 3, padding=1)
        self.branch3x3dbl_3 = ConvBN(96, 96, 3, stride=2)

    def forward(self, x):
        return torch.cat(
            [
                self.branch3x3(x),
                self.branch3x3dbl_3(self.branch3x3dbl_2(self.branch3x3dbl_1(x))),
                F.max_pool2d(x, 3, stride=2),
            ],
            1,
        )


class InceptionC(nn.Module):
    def __init__(self, in_channels: int, channels_7x7: int, fid: bool):
        super().__init__()
        self.fid = fid
        c7 = channels_7x7
        self.branch1x1 = ConvBN(in_channels, 192, 1)
        self.branch7x7_1 = ConvBN(in_channels, c7, 1)
        self.branch7x7_2 = ConvBN(c7, c7, (1, 7), padding=(0, 3))
        self.branch7x7_3 = ConvBN(c7, 192, (7, 1), padding=(3, 0))
        self.branch7x7dbl_1 = ConvBN(in_channels, c7, 1)
        self.branch7x7dbl_2 = ConvBN(c7, c7, (7, 1), padding=(3, 0))
        self.branch7x7dbl_3 = ConvBN(c7, c7, (1, 7), padding=(0, 3))
        self.branch7x7dbl_4 = ConvBN(c7, c7, (7, 1), padding=(3, 0))
        self.branch7x7dbl_5 = ConvBN(c7, 192, (1, 7), padding=(0, 3))
        self.branch_pool = ConvBN(in_channels, 192, 1)

    def forward(self, x):
        double = x
        for layer in (
            self.branch7x7dbl_1,
            self.branch7x7dbl_2,
            self.branch7x7dbl_3,
            self.branch7x7dbl_4,
            self.branch7x7dbl_5,
        ):
            double = layer(double)
        return torch.cat(
            [
                self.branch1x1(x),
                self.branch7x7_3(self.branch7x7_2(self.branch7x7_1(x))),
                double,
                self.branch_pool(_avg_pool(x, self.fid)),
            ],
            1,
        )


class InceptionD(nn.Module):
    def __init__(self, in_channels: int):
        super().__init__()
        self.branch3x3_1 = ConvBN(in_channels, 192, 1)
        self.branch3x3_2 = ConvBN(192, 320, 3, stride=2)
        self.branch7x7x3_1 = ConvBN(in_channels, 192, 1)
        self.branch7x7x3_2 = ConvBN(192, 192, (1, 7), padding=(0, 3))
        self.branch7x7x3_3 = ConvBN(192, 192, (7, 1), padding=(3, 0))
        self.branch7x7x3_4 = ConvBN(192, 192, 3, stride=2)

    def forward(self, x):
        return torch.cat(
            [
                self.branch3x3_2(self.branch3x3_1(x)),
                self.branch7x7x3_4(self.branch7x7x3_3(self.branch7x7x3_2(self.branch7x7x3_1(x)))),
                F.max_pool2d(x, 3, stride=2),
            ],
            1,
        )


class InceptionE(nn.Module):
    """``pool``: "avg" (torchvision), "avg_fid" (FID Mixed_7b) or "max" (FID Mixed_7c)."""

    def __init__(self, in_channels: int, pool: str):
        super().__init__()
        self.pool = pool
        self.branch1x1 = ConvBN(in_channels, 320, 1)
        self.branch3x3_1 = ConvBN(in_channels, 384, 1)
        self.branch3x3_2a = ConvBN(384, 384, (1, 3), padding=(0, 1))
        self.branch3x3_2b = ConvBN(384, 384, (3, 1), padding=(1, 0))
        self.branch3x3dbl_1 = ConvBN(in_channels, 448, 1)
        self.branch3x3dbl_2 = ConvBN(448, 384, 3, padding=1)
        self.branch3x3dbl_3a = ConvBN(384, 384, (1, 3), padding=(0, 1))
        self.branch3x3dbl_3b = ConvBN(384, 384, (3, 1), padding=(1, 0))
        self.branch_pool = ConvBN(in_channels, 192, 1)

    def forward(self, x):
        single = self.branch3x3_1(x)
        double = self.branch3x3dbl_2(self.branch3x3dbl_1(x))
        if self.pool == "max":
            pooled = F.max_pool2d(x, 3, stride=1, padding=1)
        else:
            pooled = _avg_pool(x, self.pool == "avg_fid")
        return torch.cat(
            [
                self.branch1x1(x),
                torch.cat([self.branch3x3_2a(single), self.branch3x3_2b(single)], 1),
                torch.cat([self.branch3x3dbl_3a(double), self.branch3x3dbl_3b(double)], 1),
                self.branch_pool(pooled),
            ],
            1,
        )


class InceptionV3Features(nn.Module):
    """Inception-v3 trunk: images [B, 3, H, W] in [-1, 1] -> pool features [B, 2048] float32.

    ``fid_variant`` selects the FID blocks (pt_inception weights) or torchvision's. Module names
    match both weight files, so their state dicts load directly (classifier and auxiliary head ignored).
    """

    def __init__(self, fid_variant: bool = True):
        super().__init__()
        self.fid_variant = fid_variant
        self.Conv2d_1a_3x3 = ConvBN(3, 32, 3, stride=2)
        self.Conv2d_2a_3x3 = ConvBN(32, 32, 3)
        self.Conv2d_2b_3x3 = ConvBN(32, 64, 3, padding=1)
        self.Conv2d_3b_1x1 = ConvBN(64, 80, 1)
        self.Conv2d_4a_3x3 = ConvBN(80, 192, 3)
        self.Mixed_5b = InceptionA(192, 32, fid_variant)
        self.Mixed_5c = InceptionA(256, 64, fid_variant)
        self.Mixed_5d = InceptionA(288, 64, fid_variant)
        self.Mixed_6a = InceptionB(288)
        self.Mixed_6b = InceptionC(768, 128, fid_variant)
        self.Mixed_6c = InceptionC(768, 160, fid_variant)
        self.Mixed_6d = InceptionC(768, 160, fid_variant)
        self.Mixed_6e = InceptionC(768, 192, fid_variant)
        self.Mixed_7a = InceptionD(768)
        self.Mixed_7b = InceptionE(1280, "avg_fid" if fid_variant else "avg")
        self.Mixed_7c = InceptionE(2048, "max" if fid_variant else "avg")
        self.source = "uninitialised"

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """images [B, 3, H, W] float in [-1, 1] -> [B, 2048] pool features."""
        check_shape(images, "InceptionV3Features: images", ("B", 3, "H", "W"), dtype="float")
        x = F.interpolate(images, size=(299, 299), mode="bilinear", align_corners=False)
        x = self.Conv2d_2b_3x3(self.Conv2d_2a_3x3(self.Conv2d_1a_3x3(x)))
        x = F.max_pool2d(x, 3, stride=2)
        x = self.Conv2d_4a_3x3(self.Conv2d_3b_1x1(x))
        x = F.max_pool2d(x, 3, stride=2)
        for block in (
            self.Mixed_5b,
            self.Mixed_5c,
            self.Mixed_5d,
            self.Mixed_6a,
            self.Mixed_6b,
            self.Mixed_6c,
            self.Mixed_6d,
            self.Mixed_6e,
            self.Mixed_7a,
            self.Mixed_7b,
            self.Mixed_7c,
        ):
            x = block(x)
        return torch.flatten(F.adaptive_avg_pool2d(x, 1), 1)


def find_inception_weights(path: str | os.PathLike | None = None) -> Path | None:
    """The Inception weight file: ``path``, else $MESH2TEX_INCEPTION_WEIGHTS, else a known file name in
    ``$TORCH_HOME/hub/checkpoints``; None if none exists. A given path that does not exist is an InputError."""
    return find_weight_file(path, "MESH2TEX_INCEPTION_WEIGHTS", INCEPTION_FILE_NAMES, "Inception-v3")


def load_inception(path: str | os.PathLike, device: str | torch.device = "cpu") -> InceptionV3Features:
    """Inception-v3 features with the weights in ``path`` (either variant); frozen, eval mode.

    Raises InputError naming the file when it is not an Inception-v3 state dict.
    """
    path = Path(path)
    state = read_state_dict(path, "Inception-v3")
    classes = state.get("fc.weight", torch.empty(0, 0)).shape[0]
    if classes not in (1000, 1008):
        raise InputError(f"{path}: not Inception-v3 weights (no 'fc.weight' with 1000 or 1008 classes)")
    model = InceptionV3Features(fid_variant=classes == 1008)
    own = model.state_dict()
    missing = [k for k in own if k not in state and not k.endswith("num_batches_tracked")]
    if missing:
        raise InputError(f"{path}: not Inception-v3 weights: missing {len(missing)} key(s), e.g. '{missing[0]}'")
    for key, tensor in own.items():
        if key in state and tuple(state[key].shape) != tuple(tensor.shape):
            raise InputError(
                f"{path}: not Inception-v3 weights: '{key}' has shape {tuple(state[key].shape)}, expected "
                f"{tuple(tensor.shape)}"
            )
    model.load_state_dict({k: state[k] for k in own if k in state}, strict=False)
    model.source = str(path)
    model = model.to(device).eval()
    for parameter in model.parameters():
        parameter.requires_grad_(False)
    return model
