"""The discriminators: their resolutions, blur-then-stride downsampling, memory-layout independence, and that they tell
fakes from reals."""

from __future__ import annotations

import pytest
import torch

from mesh2tex.nn.discriminator import Discriminator, DiscriminatorConfig


def test_discriminator_resolutions():
    d = Discriminator(32, DiscriminatorConfig(channel_base=128, channel_max=16))
    assert d(torch.randn(3, 3, 32, 32)).shape == (3,)
    with pytest.raises(ValueError):
        Discriminator(48)


def test_discriminator_downsampling_blurs_then_strides():
    """A down layer blurs with [1,3,3,1] (zero padded) and then strides; the 1x1 skip blurs only the
    pixels it reads, which is the same as blurring everything and striding."""
    from mesh2tex.nn.discriminator import Conv2dLayer

    torch.manual_seed(7)
    x = torch.randn(2, 3, 16, 16)
    for kernel in (1, 3):
        layer = Conv2dLayer(3, 5, kernel, activation="linear", down=True, bias=False)
        pad = (kernel - 1) // 2 + 1
        blurred = torch.nn.functional.conv2d(
            torch.nn.functional.pad(x, [pad] * 4), layer.blur.expand(3, 1, 4, 4), groups=3
        )
        expected = torch.nn.functional.conv2d(blurred, layer.weight * layer.weight_gain, stride=2)
        torch.testing.assert_close(layer(x), expected)
        assert layer(x).shape == (2, 5, 8, 8)


def test_discriminator_logits_and_gradients_do_not_depend_on_the_memory_layout():
    """On a CPU the discriminator runs channels-last: its logits, input gradients (with R1's double
    backward) and weight gradients are those of the same layers run on contiguous tensors."""
    torch.manual_seed(3)
    d = Discriminator(32, DiscriminatorConfig(channel_base=256, channel_max=32)).double()
    x = torch.randn(4, 3, 32, 32, dtype=torch.float64, requires_grad=True)

    def contiguous_forward(images):
        y = d.fromrgb(images)
        for block in d.blocks:
            y = block(y.contiguous())
        return d.out(d.fc(d.conv(d.minibatch_std(y.contiguous())).flatten(1))).squeeze(1)

    results = []
    for forward in (d, contiguous_forward):
        d.zero_grad()
        logits = forward(x)
        (grad,) = torch.autograd.grad(logits.sum(), x, create_graph=True)
        (logits.sum() + grad.square().sum()).backward()
        results.append(
            [logits.detach(), grad.detach()] + [p.grad.clone() for p in d.parameters() if p.grad is not None]
        )
    assert len(results[0]) == len(results[1])
    for a, b in zip(*results):
        torch.testing.assert_close(a, b, rtol=1e-10, atol=1e-12)


def test_discriminator_has_no_strided_1x1_convolution(monkeypatch):
    """oneDNN's backward of a strided 1x1 convolution on channels-last inputs with few channels writes
    out of bounds (oneDNN issue 6035): the channels-last discriminator must never run one."""
    calls = []
    conv2d = torch.nn.functional.conv2d

    def recording_conv2d(x, weight, *args, stride=1, **kwargs):
        calls.append((tuple(weight.shape[-2:]), stride))
        return conv2d(x, weight, *args, stride=stride, **kwargs)

    monkeypatch.setattr(torch.nn.functional, "conv2d", recording_conv2d)
    d = Discriminator(32, DiscriminatorConfig(channel_base=256, channel_max=32))
    d(torch.randn(4, 3, 32, 32)).sum().backward()
    assert any(kernel == (1, 1) for kernel, _ in calls) and any(stride == 2 for _, stride in calls)
    assert not [c for c in calls if c[0] == (1, 1) and c[1] not in (1, (1, 1))]


def test_discriminator_judges_fakes_apart_from_reals():
    """The minibatch standard deviation is the discriminator's one view of diversity: the fakes'
    logits in the D loss must not depend on which reals share the step."""
    import torch.nn.functional as F

    from mesh2tex.losses.gan import GanLoss, GanLossConfig

    torch.manual_seed(0)
    d = Discriminator(16, DiscriminatorConfig(channel_base=64, channel_max=16, mbstd_group=4))
    loss = GanLoss(GanLossConfig(), None, d, d)
    fake = torch.randn(1, 3, 16, 16).repeat(4, 1, 1, 1)  # a collapsed generator: four identical fakes
    real = torch.randn(4, 3, 16, 16)
    with torch.no_grad():
        combined = loss._d_main(d, fake, real)
        apart = F.softplus(d(fake)).mean() + F.softplus(-d(real)).mean()
    torch.testing.assert_close(combined, apart)
