"""Convolutions on quad-mesh faces: the 3x3 face neighbourhood plays the role of a 3x3 pixel window.

A face convolution gathers, for every face, the features of the 9 faces of its neighbourhood
(column 0 the face itself, then the 8 ring faces in rotational order, edge and corner neighbours
alternating, column 1 an edge neighbour) into one (F, 9*C) matrix and multiplies it with the weight:
one gather, one matmul (or, with fewer output than input channels, the matmul first and the gather
of its narrower products: :func:`neighborhood_matmul`). A missing neighbour (-1) reads zeros, as
zero padding does on an image.

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
    sizes = check_shape(x, "gather_neighborhood: x", ("F", "C"))
    check_shape(neighbors, "gather_neighborhood: neighbors", ("F", NEIGHBORHOOD), sizes=sizes, dtype="int")
    return _gather_rows(x, neighbors)


def take_rows(x: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """x[index] for a differentiable x: x (R, ...), index (...) int64 rows of x -> (*index.shape, *x.shape[1:]).

    The same values as ``x[index]``, but its gradient is ``index_add`` instead of an accumulating
    ``index_put``: on a CPU with several threads the latter adds the rows that share an index in
    whichever order the threads reach them, so two runs from one seed drift apart; ``index_add``
    adds them in index order (at one thread both give the same bits; a GAN step costs the same).
    """
    return x.index_select(0, index.reshape(-1)).reshape(*index.shape, *x.shape[1:])


def _gather_rows(x: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """x: (R, C), index: (...) int64 rows of x or -1 -> (..., C), zeros at -1."""
    padded = torch.cat([x, x.new_zeros(1, x.shape[1])], dim=0)
    return take_rows(padded, torch.where(index >= 0, index, x.shape[0]))


class _BiasLeakyReLU(torch.autograd.Function):
    """The LeakyReLU path of :func:`bias_act` on one new tensor: add the bias, LeakyReLU(0.2), multiply
    by ``gain`` and clamp, each in place, so that a layer writes one activation instead of four and
    its backward makes three passes instead of seven. Values and gradients are those of the separate
    operations, in the same order. The backward reads the slope from the output alone (with
    ``gain`` > 0 its sign is the pre-activation's) and the clamp's mask only when something was
    clamped; it is made of differentiable operations, so double backward (R1, path length) works."""

    @staticmethod
    def forward(ctx, x: torch.Tensor, bias: torch.Tensor | None, gain: float, clamp: float | None) -> torch.Tensor:
        if bias is not None:
            y = x + bias.to(x.dtype).reshape([1, -1] + [1] * (x.dim() - 2))
            F.leaky_relu_(y, 0.2)
        else:
            y = F.leaky_relu(x, 0.2)
        y.mul_(gain)
        inside = None
        if clamp is not None:
            # Rarely needed on a CPU (NaN counts as needed); an accelerator would wait for the answer, so
            # it always keeps the mask.
            low, high = torch.aminmax(_elements(y)) if y.device.type == "cpu" else (None, None)
            if low is None or not (low.item() >= -clamp and high.item() <= clamp):
                inside = (y >= -clamp) & (y <= clamp)  # clamp's own mask: its ends pass the gradient
                y.clamp_(-clamp, clamp)
        ctx.gain, ctx.has_bias = gain, bias is not None
        ctx.save_for_backward(y, inside)
        return y

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        y, inside = ctx.saved_tensors
        if inside is not None:
            grad = torch.where(inside, grad, 0.0)
        grad = torch.ops.aten.leaky_relu_backward(grad * ctx.gain, y.detach(), 0.2, True)
        grad_bias = None
        if ctx.has_bias and ctx.needs_input_grad[1]:
            grad_bias = grad.sum([d for d in range(grad.dim()) if d != 1])
        return grad, grad_bias, None, None


def _elements(y: torch.Tensor) -> torch.Tensor:
    """Every element of y, as a 1-D view where possible: aminmax would copy a channels-last tensor
    (the discriminator's activations) into a contiguous one first."""
    if y.dim() == 4 and not y.is_contiguous() and y.is_contiguous(memory_format=torch.channels_last):
        return y.permute(0, 2, 3, 1).reshape(-1)
    return y.reshape(-1)


def neighborhood_matmul(x: torch.Tensor, neighbors: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """The face convolution's product: out[f] = sum_k weight[:, k, :] @ x[n(f, k)], missing neighbours zero.

    x: (F, in), neighbors: (F, 9) int64 with -1 missing, weight: (out, 9, in) -> (F, out).
    With fewer outputs than inputs the 9 products of every face are computed first, (F, 9, out),
    and the neighbours' rows of them gathered and summed, instead of gathering (F, 9, in) inputs:
    the same multiplications, a third of the memory traffic at the finest synthesis level.
    """
    faces, c_out, c_in = x.shape[0], weight.shape[0], weight.shape[2]
    if c_out >= c_in:
        return gather_neighborhood(x, neighbors).flatten(1) @ weight.flatten(1).t()
    # (F, 9*out): face g under kernel position k
    per_k = x @ weight.transpose(0, 1).reshape(NEIGHBORHOOD * c_out, c_in).t()
    per_k = torch.cat([per_k, per_k.new_zeros(1, NEIGHBORHOOD * c_out)]).view(-1, c_out)  # row 9g+k; row 9F+k: zeros
    rows = torch.where(neighbors >= 0, neighbors, faces) * NEIGHBORHOOD + torch.arange(
        NEIGHBORHOOD, device=neighbors.device
    )
    return row_sums(per_k, rows)


def bias_act(
    x: torch.Tensor, bias: torch.Tensor | None, activation: str = "lrelu", gain: float = 1.0, clamp: float | None = None
) -> torch.Tensor:
    """Add ``bias`` (C,) along dim 1 of x (N, C, ...), apply LeakyReLU(0.2) scaled by sqrt(2) (or
    nothing), then ``gain`` and an optional clamp."""
    if activation == "lrelu" and LRELU_GAIN * gain > 0:
        return _BiasLeakyReLU.apply(x, bias, LRELU_GAIN * gain, clamp)
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

    def __init__(
        self,
        in_features: int,
        out_features: int,
        activation: str = "linear",
        bias_init: float = 0.0,
        lr_multiplier: float = 1.0,
    ):
        super().__init__()
        self.activation = activation
        self.weight = nn.Parameter(torch.randn(out_features, in_features) / lr_multiplier)
        self.bias = nn.Parameter(torch.full((out_features,), float(bias_init)))
        self.weight_gain = lr_multiplier / math.sqrt(in_features)
        self.bias_gain = lr_multiplier

    def forward(self, x: torch.Tensor, shared: torch.Tensor | None = None) -> torch.Tensor:
        """x: (N, in) -> (N, out); or, with ``shared`` (1, in_s), x: (N, in - in_s) and the input of every
        row is [x ‖ shared]: the shared columns' product is computed once and added to the bias."""
        w = self.weight.to(x.dtype) * self.weight_gain
        bias = self.bias * self.bias_gain
        if shared is not None:
            split = x.shape[1]
            bias = bias + F.linear(shared.to(x.dtype), w[:, split:])[0]
            w = w[:, :split]
        return bias_act(F.linear(x, w), bias, self.activation)


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
        sizes = check_shape(x, "FaceConv: x", ("F", self.weight.shape[2]), dtype="float")
        check_shape(neighbors, "FaceConv: neighbors", ("F", NEIGHBORHOOD), sizes=sizes, dtype="int")
        w = (self.weight * self.weight_gain).to(x.dtype)  # (out, 9, in)
        return bias_act(neighborhood_matmul(x, neighbors, w), self.bias, self.activation)


class ModulatedFaceConv(nn.Module):
    """StyleGAN2 modulated (and demodulated) face convolution with per-sample styles and noise.

    A style s_b (in,) per sample b, from w through an affine layer, scales the input channels of the
    weight: w'_{b,o,k,c} = w_{o,k,c} s_{b,c}. Demodulation divides each output channel by
    sqrt(sum_{k,c} w'^2 + eps) so that unit-variance inputs give unit-variance outputs. Scaling the
    input faces by s_b instead of the weight is the same product and keeps one shared matmul; it is
    done before the gather (9x fewer products), as a face's neighbours belong to its own sample.
    ``kernel_size`` 1 is the per-face (1x1) layer used by toRGB.
    """

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        w_dim: int,
        kernel_size: int = 9,
        demodulate: bool = True,
        activation: str = "lrelu",
        use_noise: bool = True,
        clamp: float | None = 256.0,
    ):
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

    def forward(
        self,
        x: torch.Tensor,
        neighbors: torch.Tensor,
        w: torch.Tensor,
        sample_index: torch.Tensor,
        noise_mode: str = "random",
        gain: float = 1.0,
    ) -> torch.Tensor:
        """x: (F, in), neighbors: (F, 9) int64, w: (B, w_dim), sample_index: (F,) int64 in [0, B) -> (F, out).

        ``noise_mode``: "random" adds fresh per-face Gaussian noise scaled by a learnt strength,
        "none" adds nothing (deterministic output).
        """
        sizes = check_shape(x, "ModulatedFaceConv: x", ("F", self.in_channels), dtype="float")
        check_shape(sample_index, "ModulatedFaceConv: sample_index", ("F",), sizes=sizes, dtype="int")
        if self.kernel_size != 1:
            check_shape(neighbors, "ModulatedFaceConv: neighbors", ("F", NEIGHBORHOOD), sizes=sizes, dtype="int")
        check_shape(w, "ModulatedFaceConv: w", ("B", self.affine.weight.shape[1]), dtype="float")
        styles = self.affine(w)  # (B, in)
        weight = self.weight * self.weight_gain  # (out, k, in)
        x = x * take_rows(styles, sample_index).to(x.dtype)
        if self.kernel_size == 1:
            out = x @ weight[:, 0].t().to(x.dtype)  # (F, out)
        else:
            out = neighborhood_matmul(x, neighbors, weight.to(x.dtype))  # (F, out)
        if self.demodulate:
            # (B, out): 1 / |w'_{b,o}| over the kernel and the input channels.
            dcoefs = (weight.square().sum(1).unsqueeze(0) * styles.square().unsqueeze(1)).sum(2).add(1e-8).rsqrt()
            out = out * take_rows(dcoefs, sample_index).to(out.dtype)
        if self.use_noise and noise_mode == "random":
            out = out + torch.randn(out.shape[0], 1, device=out.device, dtype=out.dtype) * self.noise_strength.to(
                out.dtype
            )
        return bias_act(out, self.bias, self.activation, gain=gain, clamp=self.clamp)


def face_pool(x: torch.Tensor, pool: torch.Tensor, num_coarse: int, mode: str = "max") -> torch.Tensor:
    """Pool fine faces into coarse ones. x: (F_l, C), pool: (F_l,) int64 into level l+1 -> (F_{l+1}, C).

    ``mode`` "max" or "mean" over the fine faces that map to each coarse face.
    """
    check_shape(pool, "face_pool: pool", ("F",), sizes=check_shape(x, "face_pool: x", ("F", "C")), dtype="int")
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
    sizes = check_shape(pool, "face_unpool: pool", ("F",), dtype="int")
    if neighbors_fine is not None:
        check_shape(neighbors_fine, "face_unpool: neighbors_fine", ("F", NEIGHBORHOOD), sizes=sizes, dtype="int")
    if neighbors_fine is None:
        return x[pool]
    present = (neighbors_fine >= 0).to(x.dtype) * x.new_tensor(BLUR_WEIGHTS)  # (F, 9)
    # The coarse face of each fine neighbour (x's zero row past the end where missing): the copies
    # are read straight from x, never made.
    coarse = torch.where(neighbors_fine >= 0, pool[neighbors_fine.clamp(min=0)], x.shape[0])
    padded = torch.cat([x, x.new_zeros(1, x.shape[1])], dim=0)
    return row_sums(padded, coarse, present) / present.sum(1, keepdim=True)


def row_sums(x: torch.Tensor, index: torch.Tensor, weight: torch.Tensor | None = None) -> torch.Tensor:
    """out[r] = sum_k weight[r, k] * x[index[r, k]] (weight 1 when None): x (R, C), index (F, K) int64
    rows of x, weight (F, K) constant -> (F, C).

    The same products, summed in the same order, as ``(x[index] * weight[..., None]).sum(1)``, but
    with no (F, K, C) intermediate in either direction: forward and backward are each one fused
    gather and sum (``embedding_bag``), the backward over the transposed index. Twice
    differentiable (the path-length term needs it; ``embedding_bag``'s own backward is not).
    """
    faces, k = index.shape
    offsets = torch.arange(0, faces * k, k, device=index.device)
    flat_weight = None if weight is None else weight.reshape(-1).to(x.dtype)
    return _RowSums.apply(x, index.reshape(-1), offsets, flat_weight)


class _RowSums(torch.autograd.Function):
    """out[b] = sum_{e in bag b} weight[e] * x[column[e]], bag b the entries offsets[b] .. offsets[b+1]-1;
    its gradient is the same operator transposed (entries sorted by column, bags over x's rows)."""

    @staticmethod
    def forward(
        ctx, x: torch.Tensor, column: torch.Tensor, offsets: torch.Tensor, weight: torch.Tensor | None
    ) -> torch.Tensor:
        ctx.save_for_backward(column, offsets, weight)
        ctx.rows = x.shape[0]
        return F.embedding_bag(column, x, offsets, mode="sum", per_sample_weights=weight)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        column, offsets, weight = ctx.saved_tensors
        sizes = torch.diff(offsets, append=offsets.new_tensor([column.shape[0]]))
        bag = torch.repeat_interleave(torch.arange(offsets.shape[0], device=offsets.device), sizes)  # (E,)
        order = torch.argsort(column, stable=True)  # each row of x gathers its entries in their original order
        counts = torch.bincount(column, minlength=ctx.rows)
        t_offsets = torch.cumsum(counts, 0) - counts
        t_weight = None if weight is None else weight.index_select(0, order)
        return _RowSums.apply(grad, bag.index_select(0, order), t_offsets, t_weight), None, None, None


class FaceResNetBlock(nn.Module):
    """Two face convolutions with LeakyReLU and a residual connection (1x1 projection when widths differ)."""

    def __init__(self, in_channels: int, out_channels: int):
        super().__init__()
        self.conv0 = FaceConv(in_channels, out_channels)
        self.conv1 = FaceConv(out_channels, out_channels)
        self.skip = FullyConnected(in_channels, out_channels) if in_channels != out_channels else None

    def forward(self, x: torch.Tensor, neighbors: torch.Tensor) -> torch.Tensor:
        """x: (F, in) float, neighbors: (F, 9) int64 -> (F, out)."""
        check_shape(x, "FaceResNetBlock: x", (None, self.conv0.weight.shape[2]))
        y = self.conv1(self.conv0(x, neighbors), neighbors)
        skip = x if self.skip is None else self.skip(x)
        return (y + skip) * math.sqrt(0.5)
