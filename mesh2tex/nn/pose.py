"""The pose network: a ResNet-18 that classifies a photo's camera azimuth and elevation into bins.

Angles follow the one orbit-camera convention of :func:`mesh2tex.render.orbit_camera`: degrees,
y up, object at the origin, camera at ``distance * (cos(el) sin(az), sin(el), cos(el) cos(az))``.
So azimuth 0 looks at the object from +z, azimuth 90 from +x; elevation 0 is level with the
object's centre and positive elevations look down on it.

Bins (:class:`PoseBins`): azimuth in 12 bins of 30 degrees centred on 0, 30, ..., 330 (bin k holds
[30k - 15, 30k + 15) modulo 360); elevation in 5 bins of equal width over [0, 50] degrees by
default, centred on 5, 15, 25, 35, 45 (elevations outside the range fall in the end bins). The
elevation range is a field of PoseBins, stored with every pose checkpoint, and should cover the
elevations the training renders are drawn from.

Architecture (Mesh2Tex supplement D): a ResNet-18 backbone (BasicBlocks 2-2-2-2, widths 64-128-256-512
times ``width / 64``) whose 512 pooled features pass through two linear layers to 256, then one
two-layer MLP (hidden 128) per angle gives the bin logits.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn as nn
import torch.nn.functional as F

from mesh2tex.checks import check_shape


@dataclass
class PoseBins:
    """How continuous angles (degrees) map to class bins and back."""

    azimuth_bins: int = 12  # bins over the full circle, bin 0 centred on azimuth 0
    elevation_bins: int = 5  # bins of equal width over [elevation_min, elevation_max]
    elevation_min: float = 0.0  # degrees, lower edge of the first elevation bin
    elevation_max: float = 50.0  # degrees, upper edge of the last elevation bin

    @property
    def azimuth_width(self) -> float:
        return 360.0 / self.azimuth_bins

    @property
    def elevation_width(self) -> float:
        return (self.elevation_max - self.elevation_min) / self.elevation_bins

    def azimuth_to_bin(self, azimuth) -> torch.Tensor:
        """Azimuth in degrees (tensor or float, any real value) -> bin index int64 in [0, azimuth_bins)."""
        azimuth = torch.as_tensor(azimuth, dtype=torch.float64)
        return torch.floor(azimuth / self.azimuth_width + 0.5).long().remainder(self.azimuth_bins)

    def elevation_to_bin(self, elevation) -> torch.Tensor:
        """Elevation in degrees -> bin index int64 in [0, elevation_bins), clamped at the range ends."""
        elevation = torch.as_tensor(elevation, dtype=torch.float64)
        index = torch.floor((elevation - self.elevation_min) / self.elevation_width).long()
        return index.clamp(0, self.elevation_bins - 1)

    def bin_to_azimuth(self, index) -> torch.Tensor:
        """Azimuth bin index -> its centre in degrees, float32 in [0, 360)."""
        return torch.as_tensor(index).float() * self.azimuth_width

    def bin_to_elevation(self, index) -> torch.Tensor:
        """Elevation bin index -> its centre in degrees, float32."""
        return self.elevation_min + (torch.as_tensor(index).float() + 0.5) * self.elevation_width


def angle_to_bin(azimuth, elevation, bins: PoseBins | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """(azimuth, elevation) in degrees -> (azimuth bin, elevation bin), int64 tensors of the input's shape."""
    bins = bins or PoseBins()
    return bins.azimuth_to_bin(azimuth), bins.elevation_to_bin(elevation)


def bin_to_angle(azimuth_bin, elevation_bin, bins: PoseBins | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """(azimuth bin, elevation bin) -> the bin centres (azimuth, elevation) in degrees, float32."""
    bins = bins or PoseBins()
    return bins.bin_to_azimuth(azimuth_bin), bins.bin_to_elevation(elevation_bin)


class BasicBlock(nn.Module):
    """ResNet basic block: two 3x3 conv-BN layers with an identity (or 1x1 projection) shortcut."""

    def __init__(self, in_channels: int, out_channels: int, stride: int):
        super().__init__()
        self.conv1 = nn.Conv2d(in_channels, out_channels, 3, stride, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(out_channels)
        self.conv2 = nn.Conv2d(out_channels, out_channels, 3, 1, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(out_channels)
        self.shortcut = nn.Identity()
        if stride != 1 or in_channels != out_channels:
            self.shortcut = nn.Sequential(
                nn.Conv2d(in_channels, out_channels, 1, stride, bias=False), nn.BatchNorm2d(out_channels)
            )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = F.relu(self.bn1(self.conv1(x)))
        out = self.bn2(self.conv2(out))
        return F.relu(out + self.shortcut(x))


class ResNet18Backbone(nn.Module):
    """ResNet-18 trunk: [B, in_channels, H, W] -> pooled features [B, 8 * width].

    ``width`` 64 is the standard ResNet-18 (512 features); smaller widths make a cheaper network
    of the same shape for CPU budgets.
    """

    def __init__(self, in_channels: int = 3, width: int = 64):
        super().__init__()
        self.stem = nn.Sequential(
            nn.Conv2d(in_channels, width, 7, 2, 3, bias=False),
            nn.BatchNorm2d(width),
            nn.ReLU(inplace=True),
            nn.MaxPool2d(3, 2, 1),
        )
        stages = []
        channels = width
        for stage, multiplier in enumerate((1, 2, 4, 8)):
            out_channels = width * multiplier
            stride = 1 if stage == 0 else 2
            stages.append(
                nn.Sequential(BasicBlock(channels, out_channels, stride), BasicBlock(out_channels, out_channels, 1))
            )
            channels = out_channels
        self.stages = nn.Sequential(*stages)
        self.out_features = channels
        for module in self.modules():
            if isinstance(module, nn.Conv2d):
                nn.init.kaiming_normal_(module.weight, mode="fan_out", nonlinearity="relu")

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.flatten(F.adaptive_avg_pool2d(self.stages(self.stem(x)), 1), 1)


class PoseNet(nn.Module):
    """Pose classifier (Mesh2Tex supplement D).

    ``forward(images)``: images [B, in_channels, H, W] float, RGB in [-1, 1] (plus the object mask
    in {0, 1} as a 4th channel when ``in_channels`` is 4); H, W >= 32. Returns
    ``(azimuth_logits [B, azimuth_bins], elevation_logits [B, elevation_bins])``.
    """

    def __init__(
        self,
        bins: PoseBins | None = None,
        in_channels: int = 3,
        width: int = 64,
        feature_dim: int = 256,
        hidden: int = 128,
    ):
        super().__init__()
        self.bins = bins or PoseBins()
        self.backbone = ResNet18Backbone(in_channels, width)
        # "two linear layers with output dimension 256"
        self.refine = nn.Sequential(
            nn.Linear(self.backbone.out_features, feature_dim),
            nn.ReLU(inplace=True),
            nn.Linear(feature_dim, feature_dim),
            nn.ReLU(inplace=True),
        )
        # "a two-layer MLP with hidden size 128" per angle
        self.azimuth_head = nn.Sequential(
            nn.Linear(feature_dim, hidden), nn.ReLU(inplace=True), nn.Linear(hidden, self.bins.azimuth_bins)
        )
        self.elevation_head = nn.Sequential(
            nn.Linear(feature_dim, hidden), nn.ReLU(inplace=True), nn.Linear(hidden, self.bins.elevation_bins)
        )

    def forward(self, images: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        check_shape(images, "PoseNet: images", (None, self.backbone.stem[0].in_channels, None, None), dtype="float")
        features = self.refine(self.backbone(images))
        return self.azimuth_head(features), self.elevation_head(features)

    @torch.no_grad()
    def predict(self, images: torch.Tensor) -> dict[str, torch.Tensor]:
        """Most likely bins and their centre angles: dict of azimuth/elevation [B] float32 degrees,
        azimuth_bin/elevation_bin [B] int64, azimuth_prob/elevation_prob [B] float32 (softmax of the chosen bin)."""
        azimuth_logits, elevation_logits = self(images)
        azimuth_prob, azimuth_bin = F.softmax(azimuth_logits, dim=1).max(dim=1)
        elevation_prob, elevation_bin = F.softmax(elevation_logits, dim=1).max(dim=1)
        azimuth, elevation = bin_to_angle(azimuth_bin, elevation_bin, self.bins)
        return {
            "azimuth": azimuth,
            "elevation": elevation,
            "azimuth_bin": azimuth_bin,
            "elevation_bin": elevation_bin,
            "azimuth_prob": azimuth_prob,
            "elevation_prob": elevation_prob,
        }


def pose_loss(
    azimuth_logits: torch.Tensor, elevation_logits: torch.Tensor, azimuth, elevation, bins: PoseBins
) -> torch.Tensor:
    """Cross-entropy of both heads against the bins of the true angles (degrees, [B]); scalar."""
    azimuth_bin, elevation_bin = angle_to_bin(azimuth, elevation, bins)
    device = azimuth_logits.device
    return F.cross_entropy(azimuth_logits, azimuth_bin.to(device)) + F.cross_entropy(
        elevation_logits, elevation_bin.to(device)
    )


def azimuth_error(predicted, target) -> torch.Tensor:
    """Absolute circular difference of azimuths in degrees, in [0, 180]."""
    difference = torch.remainder(
        torch.as_tensor(predicted, dtype=torch.float64) - torch.as_tensor(target, dtype=torch.float64), 360.0
    )
    return torch.minimum(difference, 360.0 - difference)


def symmetric_azimuth_error(found: float, truth: float, turns: list[float]) -> float:
    """The azimuth error (degrees, in [0, 180]) up to the shape's own symmetries: the smallest error to
    any pose the photo cannot tell from the true one, ``truth`` turned by each of ``turns``
    (:func:`mesh2tex.geometry.symmetry.azimuth_symmetries`; ``[0.0]``: the plain error)."""
    return float(azimuth_error(found, torch.tensor([truth + turn for turn in turns], dtype=torch.float64)).min())


def pose_accuracy(
    azimuth_logits: torch.Tensor, elevation_logits: torch.Tensor, azimuth, elevation, bins: PoseBins
) -> dict[str, float]:
    """Bin accuracies (fraction in [0, 1]) and the mean absolute azimuth error (degrees) of the predicted bin
    centres."""
    azimuth_bin, elevation_bin = angle_to_bin(azimuth, elevation, bins)
    predicted_azimuth_bin = azimuth_logits.argmax(1).cpu()
    predicted_elevation_bin = elevation_logits.argmax(1).cpu()
    return {
        "azimuth_accuracy": float((predicted_azimuth_bin == azimuth_bin).float().mean()),
        "elevation_accuracy": float((predicted_elevation_bin == elevation_bin).float().mean()),
        "azimuth_error_deg": float(azimuth_error(bins.bin_to_azimuth(predicted_azimuth_bin), azimuth).mean()),
    }
