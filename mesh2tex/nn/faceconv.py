"""Convolutions on quad-mesh faces: the 3x3 face neighbourhood plays the role of a 3x3 pixel window.

A face convolution gathers, for every face, the features of the 9 faces of its neighbourhood
(column 0 the face itself, then the 8 ring faces in rotational order, edge and corner neighbours
alternating, column 1 an edge neighbour) into one (F, 9*C) matrix and multiplies it with the weight:
one gather, one matmul. A missing neighbour (-1) reads zeros, as zero padding does on an image.

Weights use the equalised learning rate of StyleGAN2 (stored N(0,1), scaled by 1/sqrt(fan_in) at
run time) so that per-module learning rates mean the same thing in every layer.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from mesh2tex.checks import check_shape

NEIGHBORHOOD = 9
# Smoothing blur of the unpooling step: the binomial 3x3 window [1,2,1] x [1,2,1] laid on the
# neighbourhood order (centre, then edge and corner neighbours alternating).
BLUR_WEIGHTS = (4.0, 2.0, 1.0, 2.0, 1.0, 2.0, 1.0, 2.0, 1.0)
LRELU_GAIN = math.sqrt(2.0)


def gather_neighborhood(x: torch.Tensor, neighbors: torch.Tensor) -> torch.Tensor:
    """x: (F, C) face features, neighbors: (F, 9) int64 with -1 missing -> (F, 9, C), zeros where missing."""
    check_shape(neighbors, "gather_neighborhood: neighbors", ("F", NEIGHBORHOOD), sizes=check_shape(x, "gather_neighborhood: x", ("F", "C")))
    padded = torch.cat([x, x.new_zeros(1, x.shape[1])], dim=0)
    index = torch.where(neighbors >= 0, neighbors, x.shape[0])
    return padded[index]


def bias_act(x: torch.Tensor, bias: torch.Tensor | None, activation: str = "lrelu", gain: float = 1.0, clamp: float | None = None) -> torch.Tensor:
    """Add ``bias`` (C,) along dim 1 of x (N, C, ...), apply LeakyReLU(0.2) scaled by sqrt(2) (or
    nothing), then ``gain`` and an optional clamp."""
    if bias is not None:
        x = x + bias.to(x.dtype).reshape([1, -1] + [1] * (x.dim() - 2))
    if activation == "lrelu":
        x = F.leaky_relu(x, 0.2) * (LRELU_GAIN * gain)
    elif gain != 1.0:
        x = x * gain
    if clamp is not None:
        x = x.clamp(-clamp, clamp)
    return x


class FullyConnected(nn.Module):
    """Linear layer with equalised learning rate; ``lr_multiplier`` scales its effective learning rate."""

    def __init__(self, in_features: int, out_features: int, activation: str = "linear", bias_init: float = 0.0, lr_multiplier: float = 1.0):
        super().__init__()
        self.activation = activation
        self.weight = nn.Parameter(torch.randn(out_features, in_features) / lr_multiplier)
        self.bias = nn.Parameter(torch.full((out_features,), float(bias_init)))
        self.weight_gain = lr_multiplier / math.sqrt(in_features)
        self.bias_gain = lr_multiplier

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """x: (N, in) -> (N, out)."""
        x = F.linear(x, self.weight.to(x.dtype) * self.weight_gain)
        return bias_act(x, self.bias * self.bias_gain, self.activation)


class FaceConv(nn.Module):
    """Plain face convolution: out[f] = W · concat_k x[n(f, k)] + b over the 9-face neighbourhood.

    ``weight`` is (out, 9, in): ``weight[o, k, c]`` multiplies channel c of neighbour k.
    """

    def __init__(self, in_channels: int, out_channels: int, activation: str = "lrelu", bias: bool = True):
        super().__init__()
        self.activation = activation
        self.weight = nn.Parameter(torch.randn(out_channels, NEIGHBORHOOD, in_channels))
        self.bias = nn.Parameter(torch.zeros(out_channels)) if bias else None
        self.weight_gain = 1.0 / math.sqrt(NEIGHBORHOOD * in_channels)

    def forward(self, x: torch.Tensor, neighbors: torch.Tensor) -> torch.Tensor:
        """x: (F, in) float, neighbors: (F, 9) int64 -> (F, out)."""
        check_shape(neighbors, "FaceConv: neighbors", ("F", NEIGHBORHOOD), sizes=check_shape(x, "FaceConv: x", ("F", self.weight.shape[2])))
        patches = gather_neighborhood(x, neighbors).flatten(1)  # (F, 9*in)
        w = (self.weight * self.weight_gain).flatten(1).to(x.dtype)  # (out, 9*in)
        return bias_act(patches @ w.t(), self.bias, self.activation)


class ModulatedFaceConv(nn.Module):
    """StyleGAN2 modulated (and demodulated) face convolution with per-sample styles and noise.

    A style s_b (in,) per sample b, from w through an affine layer, scales the input channels of the
    weight: w'_{b,o,k,c} = w_{o,k,c} s_{b,c}. Demodulation divides each output channel by
    sqrt(sum_{k,c} w'^2 + eps) so that unit-variance inputs give unit-variance outputs. Scaling the
    gathered input by s_b instead of the weight is the same product and keeps one shared matmul.
    ``kernel_size`` 1 is the per-face (1x1) layer used by toRGB.
    """

    def __init__(self, in_channels: int, out_channels: int, w_dim: int, kernel_size: int = 9, demodulate: bool = True,
                 activation: str = "lrelu", use_noise: bool = True, clamp: float | None = 256.0):
        super().__init__()
        if kernel_size not in (1, NEIGHBORHOOD):
            raise ValueError("kernel_size must be 1 or 9")
        self.in_channels, self.out_channels, self.kernel_size = in_channels, out_channels, kernel_size
        self.demodulate, self.activation, self.clamp = demodulate, activation, clamp
        self.affine = FullyConnected(w_dim, in_channels, bias_init=1.0)
        self.weight = nn.Parameter(torch.randn(out_channels, kernel_size, in_channels))
        self.bias = nn.Parameter(torch.zeros(out_channels))
        self.weight_gain = 1.0 / math.sqrt(kernel_size * in_channels)
        self.use_noise = use_noise
        if use_noise:
            self.noise_strength = nn.Parameter(torch.zeros([]))

    def forward(self, x: torch.Tensor, neighbors: torch.Tensor, w: torch.Tensor, sample_index: torch.Tensor,
                noise_mode: str = "random", gain: float = 1.0) -> torch.Tensor:
        """x: (F, in), neighbors: (F, 9) int64, w: (B, w_dim), sample_index: (F,) int64 in [0, B) -> (F, out).

        ``noise_mode``: "random" adds fresh per-face Gaussian noise scaled by a learnt strength,
        "none" adds nothing (deterministic output).
        """
        sizes = check_shape(x, "ModulatedFaceConv: x", ("F", self.in_channels))
        check_shape(sample_index, "ModulatedFaceConv: sample_index", ("F",), sizes=sizes)
        if self.kernel_size != 1:
            check_shape(neighbors, "ModulatedFaceConv: neighbors", ("F", NEIGHBORHOOD), sizes=sizes)
        check_shape(w, "ModulatedFaceConv: w", ("B", self.affine.weight.shape[1]))
        styles = self.affine(w)  # (B, in)
        weight = self.weight * self.weight_gain  # (out, k, in)
        if self.kernel_size == 1:
            patches = x.unsqueeze(1)
        else:
            patches = gather_neighborhood(x, neighbors)  # (F, 9, in)
        patches = patches * styles[sample_index].unsqueeze(1).to(x.dtype)
        out = patches.flatten(1) @ weight.flatten(1).t().to(x.dtype)  # (F, out)
        if self.demodulate:
            # (B, out): 1 / |w'_{b,o}| over the kernel and the input channels.
            dcoefs = (weight.square().sum(1).unsqueeze(0) * styles.square().unsqueeze(1)).sum(2).add(1e-8).rsqrt()
            out = out * dcoefs[sample_index].to(out.dtype)
        if self.use_noise and noise_mode == "random":
            out = out + torch.randn(out.shape[0], 1, device=out.device, dtype=out.dtype) * self.noise_strength.to(out.dtype)
        return bias_act(out, self.bias, self.activation, gain=gain, clamp=self.clamp)


def face_pool(x: torch.Tensor, pool: torch.Tensor, num_coarse: int, mode: str = "max") -> torch.Tensor:
    """Pool fine faces into coarse ones. x: (F_l, C), pool: (F_l,) int64 into level l+1 -> (F_{l+1}, C).

    ``mode`` "max" or "mean" over the fine faces that map to each coarse face.
    """
    check_shape(pool, "face_pool: pool", ("F",), sizes=check_shape(x, "face_pool: x", ("F", "C")))
    index = pool.unsqueeze(1).expand_as(x)
    out = x.new_zeros(num_coarse, x.shape[1])
    reduce = {"max": "amax", "mean": "mean"}[mode]
    return out.scatter_reduce(0, index, x, reduce=reduce, include_self=False)


def face_unpool(x: torch.Tensor, pool: torch.Tensor, neighbors_fine: torch.Tensor | None = None) -> torch.Tensor:
    """Copy coarse features to their fine faces, then smooth with the binomial blur over the fine
    neighbourhood (weights renormalised over the neighbours that exist) so that the copies do not
    leave blocky steps. x: (F_{l+1}, C), pool: (F_l,), neighbors_fine: (F_l, 9) or None (no blur) -> (F_l, C).
    """
    check_shape(x, "face_unpool: x", (None, "C"))
    sizes = check_shape(pool, "face_unpool: pool", ("F",))
    if neighbors_fine is not None:
        check_shape(neighbors_fine, "face_unpool: neighbors_fine", ("F", NEIGHBORHOOD), sizes=sizes)
    up = x[pool]
    if neighbors_fine is None:
        return up
    weights = up.new_tensor(BLUR_WEIGHTS)
    present = (neighbors_fine >= 0).to(up.dtype) * weights  # (F, 9)
    patches = gather_neighborhood(up, neighbors_fine)  # (F, 9, C)
    return (patches * present.unsqueeze(2)).sum(1) / present.sum(1, keepdim=True)


class FaceResNetBlock(nn.Module):
    """Two face convolutions with LeakyReLU and a residual connection (1x1 projection when widths differ)."""

    def __init__(self, in_channels: int, out_channels: int):
        super().__init__()
        self.conv0 = FaceConv(in_channels, out_channels)
        self.conv1 = FaceConv(out_channels, out_channels)
        self.skip = FullyConnected(in_channels, out_channels) if in_channels != out_channels else None

    def forward(self, x: torch.Tensor, neighbors: torch.Tensor) -> torch.Tensor:
        """x: (F, in) -> (F, out)."""
        y = self.conv1(self.conv0(x, neighbors), neighbors)
        skip = x if self.skip is None else self.skip(x)
        return (y + skip) * math.sqrt(0.5)
