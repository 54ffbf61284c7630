"""The GAN's colour-moment term (``loss.colour_weight``): it corrects the generator's global colour
bias towards the photos' CIELAB moments, without pulling each batch's samples towards the mean colour."""

from __future__ import annotations

import pytest
import torch
from kornia.color import rgb_to_lab

from mesh2tex.losses.gan import GanLoss, GanLossConfig, object_lab_moments


def photo_batch(seed: int, n: int = 8, size: int = 16) -> tuple[torch.Tensor, torch.Tensor]:
    """Random coloured objects on a grey background: images (n, 3, size, size) in [-1, 1], masks (n, 1, size, size)."""
    g = torch.Generator().manual_seed(seed)
    colours = torch.rand(n, 3, 1, 1, generator=g) * 2 - 1
    images = (colours + 0.2 * torch.randn(n, 3, size, size, generator=g)).clamp(-1, 1)
    masks = torch.zeros(n, 1, size, size)
    masks[:, :, 3:13, 4:12] = 1.0
    return torch.where(masks > 0.5, images, torch.zeros_like(images)), masks


def test_moments_are_those_of_the_object_pixels_alone():
    images, masks = photo_batch(0)
    mean, square = object_lab_moments(images, masks)
    lab = rgb_to_lab((images + 1) / 2).permute(1, 0, 2, 3)[:, masks[:, 0] > 0.5]  # (3, P) object pixels only
    torch.testing.assert_close(mean, lab.mean(1))
    torch.testing.assert_close(square, lab.square().mean(1))
    images[masks.expand_as(images) < 0.5] = 1.0  # another background: the same moments
    torch.testing.assert_close(object_lab_moments(images, masks)[0], mean)


def test_a_dark_generator_is_pushed_brighter_and_one_at_the_photos_moments_is_left_alone():
    photos, masks = photo_batch(0)
    loss = GanLoss(GanLossConfig(colour_weight=1.0, colour_decay=1.0), None, None)
    loss.set_colour_target(photos, masks)
    assert loss.colour_loss(photos, masks).item() == pytest.approx(0.0, abs=1e-6)
    dark = (((photos + 1) / 2) * 0.6 * 2 - 1).requires_grad_(True)
    value = loss.colour_loss(dark, masks)
    assert value.item() > 0.05
    value.backward()
    stepped = dark.detach() - 0.5 * dark.grad / dark.grad.abs().max()
    # lighter (CIELAB L)
    assert object_lab_moments(stepped, masks)[0][0] > object_lab_moments(dark.detach(), masks)[0][0] + 1.0


def test_running_moments_correct_the_bias_without_shrinking_a_batch_towards_the_mean():
    """With the running moments at the photos', an unusual batch (every sample red) gets a small
    gradient; matching each batch's own moments (decay 1) would pull its samples to the mean colour."""
    photos, masks = photo_batch(0)
    red = torch.zeros_like(photos)
    red[:, 0] = 0.8
    red[:, 1:] = -0.7
    red = torch.where(masks > 0.5, red, photos)

    def gradient(decay: float) -> float:
        loss = GanLoss(GanLossConfig(colour_weight=1.0, colour_decay=decay), None, None)
        loss.set_colour_target(photos, masks)
        loss.colour_loss(photos, masks)  # the running moments start at the photos' own
        images = red.clone().requires_grad_(True)
        loss.colour_loss(images, masks).backward()
        return images.grad.norm().item()

    assert gradient(0.05) < 0.15 * gradient(1.0)


def test_running_moments_are_kept_in_the_loss_state_and_old_states_load():
    photos, masks = photo_batch(1)
    loss = GanLoss(GanLossConfig(colour_weight=1.0), None, None)
    loss.set_colour_target(photos, masks)
    loss.colour_loss(photos * 0.5, masks)
    state = loss.state_dict()
    restored = GanLoss(GanLossConfig(colour_weight=1.0), None, None)
    restored.load_state_dict(state)
    torch.testing.assert_close(restored.colour_running, loss.colour_running)
    restored.load_state_dict({"pl_mean": torch.zeros([])})  # a checkpoint from before the term
    assert restored.colour_running is None


def test_the_term_needs_a_target_and_a_mask():
    photos, masks = photo_batch(2)
    with pytest.raises(ValueError, match="set_colour_target"):
        GanLoss(GanLossConfig(colour_weight=1.0), None, None).colour_loss(photos, masks)
    with pytest.raises(ValueError, match="colour_decay"):
        GanLossConfig(colour_decay=1.5)
