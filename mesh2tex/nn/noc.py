"""The NOC network: a U-Net that predicts normalized object coordinates for a photo's object pixels.

Normalized object coordinates (NOC) map every surface point of a shape to its position in the
shape's canonical box, scaled to [0, 1]^3 (the ``noc`` of a prepared shape). For a photo they give
dense correspondences to the canonical space, which the NOC-guided patch style loss uses to pair a
photo patch with the rendered pixel of the same part of the object.

The paper uses a U-Net with an EfficientNet-b4 encoder; here the encoder is a plain convolutional
one (two 3x3 conv-BN-ReLU layers per level, max-pool down, bilinear up with skip connections), small
enough to train on a CPU. Input: RGB plus the object mask (4 channels); output: NOC (3 channels,
sigmoid, so always in [0, 1]).
"""

from __future__ import annotations

import torch
import torch.nn as nn
import torch.nn.functional as F

from mesh2tex.checks import check_shape


def _double_conv(in_channels: int, out_channels: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(in_channels, out_channels, 3, padding=1, bias=False),
        nn.BatchNorm2d(out_channels),
        nn.ReLU(inplace=True),
        nn.Conv2d(out_channels, out_channels, 3, padding=1, bias=False),
        nn.BatchNorm2d(out_channels),
        nn.ReLU(inplace=True),
    )


class NocUNet(nn.Module):
    """U-Net from (RGB, mask) to NOC.

    ``forward(images, masks)``: images [B, 3, H, W] float RGB in [-1, 1]; masks [B, 1, H, W] float in
    {0, 1} (1 on the object). Any H, W (inputs are padded to a multiple of 2^depth and the output
    cropped back). Returns NOC [B, 3, H, W] float in [0, 1]; only object pixels are meaningful
    (multiply by the mask, as :func:`noc_loss` does).

    ``width`` is the channel count of the first level; it doubles per level for ``depth`` levels.
    """

    def __init__(self, width: int = 32, depth: int = 4, in_channels: int = 4, out_channels: int = 3):
        super().__init__()
        self.depth = depth
        widths = [width * 2**level for level in range(depth + 1)]
        self.encoders = nn.ModuleList(
            [_double_conv(in_channels, widths[0])] + [_double_conv(widths[i], widths[i + 1]) for i in range(depth)]
        )
        self.decoders = nn.ModuleList(
            [_double_conv(widths[i + 1] + widths[i], widths[i]) for i in reversed(range(depth))]
        )
        self.head = nn.Conv2d(widths[0], out_channels, 1)

    def forward(self, images: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
        sizes = check_shape(
            images, "NocUNet: images", ("B", self.encoders[0][0].in_channels - 1, "H", "W"), dtype="float"
        )
        check_shape(masks, "NocUNet: masks", ("B", 1, "H", "W"), sizes=sizes)
        return torch.sigmoid(self.logits(torch.cat([images, masks.to(images.dtype)], dim=1)))

    def logits(self, x: torch.Tensor) -> torch.Tensor:
        """The head's raw output [B, out_channels, H, W] for the network's input x [B, in_channels, H, W]."""
        height, width = x.shape[-2:]
        multiple = 2**self.depth
        pad_h, pad_w = (-height) % multiple, (-width) % multiple
        if pad_h or pad_w:
            x = F.pad(x, (0, pad_w, 0, pad_h))
        skips = []
        for level, encoder in enumerate(self.encoders):
            x = encoder(x if level == 0 else F.max_pool2d(x, 2))
            skips.append(x)
        x = skips.pop()
        for decoder in self.decoders:
            skip = skips.pop()
            x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = decoder(torch.cat([x, skip], dim=1))
        return self.head(x)[..., :height, :width]


def noc_loss(predicted: torch.Tensor, target: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
    """Mean L1 distance over object pixels: predicted, target [B, 3, H, W] in [0, 1], masks [B, 1, H, W]; scalar.

    Background pixels (mask 0) do not contribute; an all-background batch gives 0.
    """
    weight = masks.to(predicted.dtype)
    return ((predicted - target).abs() * weight).sum() / (3.0 * weight.sum()).clamp_min(1.0)


def noc_error(predicted: torch.Tensor, target: torch.Tensor, masks: torch.Tensor) -> float:
    """Mean Euclidean distance (NOC units, the canonical box has side 1) over object pixels."""
    weight = masks.to(predicted.dtype)[:, 0]
    distance = (predicted - target).norm(dim=1)
    return float((distance * weight).sum() / weight.sum().clamp_min(1.0))
