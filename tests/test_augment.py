"""Differentiable augmentation of the discriminators' inputs, and how the GAN loss applies it."""

from __future__ import annotations

import pytest
import torch

from mesh2tex.losses.augment import AugmentConfig, DiffAugment, augment_cutout, augment_translation
from mesh2tex.losses.gan import GanLoss, GanLossConfig
from mesh2tex.nn.discriminator import Discriminator, DiscriminatorConfig


def test_every_transform_lets_the_gradient_through():
    torch.manual_seed(0)
    for policy in ("color", "translation", "cutout", "color,translation,cutout"):
        x = torch.rand(4, 3, 16, 16, requires_grad=True)
        y = DiffAugment(AugmentConfig(policy=policy))(x * 2 - 1)
        assert y.shape == x.shape
        (y * torch.randn_like(y)).sum().backward()
        assert torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0, policy


def test_augmentation_changes_images_and_can_be_switched_off():
    torch.manual_seed(0)
    x = torch.rand(8, 3, 16, 16) * 2 - 1
    assert not torch.allclose(DiffAugment()(x), x)
    assert torch.equal(DiffAugment(AugmentConfig(policy=""))(x), x)
    assert torch.equal(DiffAugment(AugmentConfig(p=0.0))(x), x)
    with pytest.raises(ValueError, match="unknown augmentation"):
        DiffAugment(AugmentConfig(policy="colour"))


def test_translation_moves_content_by_whole_pixels_and_cutout_blanks_a_square():
    torch.manual_seed(0)
    x = torch.zeros(16, 1, 16, 16)
    x[:, :, 8, 8] = 1.0
    moved = augment_translation(x, ratio=0.125)
    assert (moved.sum(dim=[1, 2, 3]) == 1).all(), "a dot inside the shift range stays one dot"
    where = moved[:, 0].flatten(1).argmax(1)
    rows, cols = where // 16, where % 16
    assert ((rows - 8).abs() <= 2).all() and ((cols - 8).abs() <= 2).all() and len(set(where.tolist())) > 1
    ones = torch.ones(16, 3, 16, 16)
    cut = augment_cutout(ones, ratio=0.5)
    blank = (cut == 0).all(1).float().mean(dim=[1, 2])
    assert (blank > 0.05).all() and (blank <= 0.25 + 1e-6).all()


def test_gan_loss_augments_reals_and_fakes_in_every_discriminator_call():
    torch.manual_seed(0)
    seen = []

    def augment(x):
        seen.append(x.shape[0])
        return x

    d = Discriminator(16, DiscriminatorConfig(channel_base=64, channel_max=16))
    fake, real = torch.randn(4, 3, 16, 16), torch.randn(4, 3, 16, 16)

    class FixedFakes(GanLoss):  # the discriminators' phases on given fakes, no generator
        def fakes(self, z, scene, update_w_avg=False):
            return fake, None, None, None

    loss = FixedFakes(GanLossConfig(proxy_weight=0.0), None, d, d, augment=augment)
    loss.accumulate_gradients("Dmain", None, torch.zeros(1), real)
    assert seen == [4, 4], "fakes and reals each augmented, in separate calls"
    seen.clear()
    loss.accumulate_gradients("Dreg", None, torch.zeros(1), real)
    assert seen == [4]


def test_adaptive_probability_follows_the_discriminators_overfitting():
    """ADA's rule: p rises while E[sign D(real)] is above the target, falls below it, stays in [0, 1],
    moves only every ada_interval iterations, and survives a checkpoint round trip."""
    from mesh2tex.losses.augment import AdaptiveAugment

    cfg = AugmentConfig(p=0.0, ada_target=0.6, ada_interval=2, ada_images=80.0)
    ada = AdaptiveAugment(DiffAugment(cfg))
    assert ada.adaptive and ada.augment.p == 0.0 and not ada.augment.enabled
    for it in range(8):  # overfitting: every real called real
        ada.observe(1.0)
        ada.step(it, images_per_iteration=8)
        assert ada.augment.p == pytest.approx(min((it + 1) // 2 * 0.2, 1.0))
    for it in range(8, 40):
        ada.observe(1.0)
        ada.step(it, 8)
    assert ada.augment.p == 1.0
    ada.observe(0.0)  # at chance: p falls
    state = ada.state_dict()
    restored = AdaptiveAugment(DiffAugment(cfg))
    restored.load_state_dict(state)
    for a in (ada, restored):
        a.observe(0.0)
        a.step(41, 8)
    assert ada.augment.p == restored.augment.p == pytest.approx(0.8)
    fixed = AdaptiveAugment(DiffAugment(AugmentConfig(p=0.5, ada_target=0.0)))
    fixed.observe(1.0)
    fixed.step(3, 8)
    assert not fixed.adaptive and fixed.augment.p == 0.5
