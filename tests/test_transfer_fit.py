"""The transfer's check of its result at the found pose: a good fit passes, a wrong outline or wrong
colours are named."""

import torch

from mesh2tex.transfer.fit import check_fit


def _photo(size: int = 64):
    torch.manual_seed(0)
    mask = torch.zeros(1, 1, size, size)
    mask[..., 12:52, 16:48] = 1
    # Two coloured halves with a little noise: a texture a flat colour cannot match.
    image = torch.full((1, 3, size, size), 1.0)
    image[:, :, 12:32, 16:48] = torch.tensor([0.6, -0.4, -0.4]).view(1, 3, 1, 1)
    image[:, :, 32:52, 16:48] = torch.tensor([-0.5, -0.3, 0.5]).view(1, 3, 1, 1)
    image = image + 0.02 * torch.randn_like(image) * mask
    return image, mask


def test_a_render_that_matches_the_photo_is_a_good_fit():
    image, mask = _photo()
    check = check_fit(image, mask, image.clone(), mask.clone())
    assert not check.poor
    assert check.silhouette_iou == 1.0
    assert check.lowpass_psnr > check.flat_lowpass_psnr + 5


def test_an_outline_one_pixel_off_is_not_a_poor_fit():
    image, mask = _photo()
    check = check_fit(image, mask, image.clone(), torch.roll(mask, shifts=1, dims=3))
    assert check.outline_agreement == 1.0 and not check.poor


def test_an_outline_off_the_photo_is_named():
    image, mask = _photo()
    shifted = torch.roll(mask, shifts=24, dims=3)
    check = check_fit(image, mask, image.clone(), shifted)
    assert check.poor and any("outline" in p for p in check.problems)


def test_colours_worse_than_the_photo_mean_are_named():
    image, mask = _photo()
    swapped = image.clone()
    swapped[:, :, 12:32], swapped[:, :, 32:52] = image[:, :, 32:52], image[:, :, 12:32]  # the halves' colours exchanged
    check = check_fit(image, mask, swapped, mask)
    assert check.silhouette_iou == 1.0
    assert check.lowpass_psnr < check.flat_lowpass_psnr
    assert check.poor and any("flat colour" in p for p in check.problems)
    assert check.as_dict()["poor"] is True
