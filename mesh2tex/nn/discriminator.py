"""The StyleGAN2 residual image discriminator (used twice: on psi renders and on proxy renders)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from mesh2tex.checks import check_shape
from mesh2tex.config import MAX_CHANNELS, check_fields
from mesh2tex.nn.faceconv import FullyConnected, bias_act

_BLUR_1D = torch.tensor([1.0, 3.0, 3.0, 1.0])


@dataclass
class DiscriminatorConfig:
    channel_base: int = 2048  # channels at resolution r: min(channel_base // r, channel_max) (sized for a CPU)
    channel_max: int = 128  # widest layer
    mbstd_group: int = 4  # minibatch standard deviation group size
    conv_clamp: float = 256.0  # clamp of activations (keeps mixed precision finite)

    def __post_init__(self):
        check_fields(
            self,
            between={"channel_base": (1, 64 * MAX_CHANNELS), "channel_max": (1, MAX_CHANNELS)},
            at_least={"mbstd_group": 1},
            positive=("conv_clamp",),
        )

    def check_resolution(self, resolution: int) -> None:
        """ValueError when a layer at ``resolution`` would have no channel (``channel_base // resolution`` is 0)."""
        if self.channel_base // resolution < 1:
            raise ValueError(
                f"channel_base {self.channel_base} is too small for resolution {resolution}: "
                f"every layer needs a channel (channel_base >= {resolution})"
            )


class Conv2dLayer(nn.Module):
    """Conv with equalised learning rate; ``down`` 2 blurs with [1,3,3,1] then strides by 2."""

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        kernel_size: int,
        activation: str = "lrelu",
        down: bool = False,
        bias: bool = True,
        clamp: float | None = None,
    ):
        super().__init__()
        self.activation, self.down, self.clamp = activation, down, clamp
        self.weight = nn.Parameter(torch.randn(out_channels, in_channels, kernel_size, kernel_size))
        self.bias = nn.Parameter(torch.zeros(out_channels)) if bias else None
        self.weight_gain = 1.0 / math.sqrt(in_channels * kernel_size * kernel_size)
        self.padding = kernel_size // 2
        blur = torch.outer(_BLUR_1D, _BLUR_1D)
        self.register_buffer("blur", blur / blur.sum(), persistent=False)

    def forward(self, x: torch.Tensor, gain: float = 1.0) -> torch.Tensor:
        w = (self.weight * self.weight_gain).to(x.dtype)
        if self.down:
            c = x.shape[1]
            kernel = self.blur.to(x.dtype).expand(c, 1, 4, 4)
            # Pad so that the strided conv after the blur sees the aligned window (as upfirdn2d does).
            pad = (w.shape[-1] - 1) // 2 + 1
            if w.shape[-1] == 1:  # a 1x1 conv at stride 2 reads every other blurred pixel: blur only those
                x = F.conv2d(F.conv2d(x, kernel, padding=pad, groups=c, stride=2), w)
            else:
                x = F.conv2d(F.conv2d(x, kernel, padding=pad, groups=c), w, stride=2)
        else:
            x = F.conv2d(x, w, padding=self.padding)
        return bias_act(x, self.bias, self.activation, gain=gain, clamp=self.clamp)


class DiscriminatorBlock(nn.Module):
    """Residual block: conv 3x3, conv 3x3 down, plus a 1x1 down skip; sum scaled by sqrt(1/2)."""

    def __init__(self, in_channels: int, out_channels: int, clamp: float | None):
        super().__init__()
        self.conv0 = Conv2dLayer(in_channels, in_channels, 3, clamp=clamp)
        self.conv1 = Conv2dLayer(in_channels, out_channels, 3, down=True, clamp=clamp)
        self.skip = Conv2dLayer(in_channels, out_channels, 1, activation="linear", down=True, bias=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.skip(x, gain=math.sqrt(0.5))
        x = self.conv1(self.conv0(x), gain=math.sqrt(0.5))
        return y + x


class Discriminator(nn.Module):
    """Images (N, 3, R, R) in [-1, 1], R a power of two >= 8 -> logits (N,)."""

    def __init__(self, resolution: int, cfg: DiscriminatorConfig | None = None, in_channels: int = 3):
        super().__init__()
        cfg = cfg or DiscriminatorConfig()
        log2 = int(math.log2(resolution))
        if 2**log2 != resolution or resolution < 8:
            raise ValueError(f"discriminator resolution must be a power of two >= 8, got {resolution}")
        self.resolution, self.mbstd_group = resolution, cfg.mbstd_group

        def ch(res):
            return min(cfg.channel_base // res, cfg.channel_max)

        self.fromrgb = Conv2dLayer(in_channels, ch(resolution), 1, clamp=cfg.conv_clamp)
        self.blocks = nn.ModuleList(
            DiscriminatorBlock(ch(2**r), ch(2 ** (r - 1)), cfg.conv_clamp) for r in range(log2, 2, -1)
        )
        c4 = ch(4)
        self.conv = Conv2dLayer(c4 + 1, c4, 3, clamp=cfg.conv_clamp)
        self.fc = FullyConnected(c4 * 16, c4, activation="lrelu")
        self.out = FullyConnected(c4, 1)

    def minibatch_std(self, x: torch.Tensor) -> torch.Tensor:
        """Append the standard deviation across groups of samples as one extra channel."""
        n, c, h, w = x.shape
        g = min(self.mbstd_group, n)
        while n % g:
            g -= 1
        y = x.float().reshape(g, -1, c, h, w)
        y = (y - y.mean(0)).square().mean(0).add(1e-8).sqrt().mean(dim=[1, 2, 3])  # (n/g,)
        y = y.reshape(-1, 1, 1, 1).repeat(g, 1, h, w).to(x.dtype)
        return torch.cat([x, y], dim=1)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """images (N, in_channels, R, R) float -> logits (N,)."""
        check_shape(
            images,
            "Discriminator: images",
            (None, self.fromrgb.weight.shape[1], self.resolution, self.resolution),
            dtype="float",
        )
        if images.device.type == "cpu":
            # oneDNN's CPU convolutions, forward and backward, run about a fifth faster on channels-last
            # activations (docs/results/gan.md, "Seconds per iteration"). Safe here because no convolution of
            # this network is a strided 1x1 (oneDNN issue 6035: that backward writes out of bounds on
            # channels-last inputs with few channels): Conv2dLayer's 1x1 downsampling strides its blur.
            images = images.contiguous(memory_format=torch.channels_last)
        x = self.fromrgb(images)
        for block in self.blocks:
            x = block(x)
        x = self.conv(self.minibatch_std(x))
        return self.out(self.fc(x.flatten(1))).squeeze(1)
