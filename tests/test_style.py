"""Style features and losses: VGG weight loading, masked Gram matrices, NOC-guided patch pairs."""

import warnings

import pytest
import torch

from mesh2tex.errors import InputError
from mesh2tex.losses.style import (
    crop_patches,
    global_style_loss,
    lowpass_colour_loss,
    masked_gram,
    nearest_noc_pixels,
    patch_style_loss,
    sample_patch_pairs,
    style_grams,
)
from mesh2tex.nn.vgg import VGG19_FILE_NAME, VGG19Features, load_vgg19


@pytest.fixture(scope="module")
def vgg():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = VGG19Features()
        model.init_random()
        return model.eval().requires_grad_(False)


def _disk_mask(size=64, radius=20, centre=(32, 32)):
    rows, cols = torch.meshgrid(torch.arange(size), torch.arange(size), indexing="ij")
    return (((rows - centre[0]) ** 2 + (cols - centre[1]) ** 2) <= radius**2).float()[None, None]


def test_vgg_feature_shapes(vgg):
    features = vgg(torch.rand(2, 3, 64, 48) * 2 - 1)
    assert [tuple(f.shape) for f in features] == [
        (2, 64, 64, 48),
        (2, 128, 32, 24),
        (2, 256, 16, 12),
        (2, 512, 8, 6),
        (2, 512, 4, 3),
    ]
    assert all(float(f.min()) >= 0 for f in features)  # ReLU outputs


def test_vgg_loads_a_weight_file_from_the_torch_cache(tmp_path, monkeypatch):
    source = VGG19Features()
    source.init_random(seed=7)
    state = {f"features.{k}": v for k, v in source.features.state_dict().items()}
    state["classifier.0.weight"] = torch.zeros(4, 4)  # torchvision files carry the classifier too; ignored
    checkpoints = tmp_path / "hub" / "checkpoints"
    checkpoints.mkdir(parents=True)
    torch.save(state, checkpoints / VGG19_FILE_NAME)
    monkeypatch.setenv("TORCH_HOME", str(tmp_path))
    monkeypatch.delenv("MESH2TEX_VGG_WEIGHTS", raising=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no fallback warning when the file is there
        model = load_vgg19()
    assert model.pretrained and model.source == str(checkpoints / VGG19_FILE_NAME)
    assert torch.equal(model.features[34].weight, source.features[34].weight)
    assert not any(p.requires_grad for p in model.parameters())


def test_vgg_rejects_a_wrong_file_with_a_clear_error(tmp_path):
    wrong = tmp_path / "not_vgg.pth"
    torch.save({"features.0.weight": torch.zeros(8, 3, 3, 3), "features.0.bias": torch.zeros(8)}, wrong)
    with pytest.raises(InputError, match="not_vgg.pth: not VGG19 weights"):
        load_vgg19(wrong)
    text = tmp_path / "notes.pth"
    text.write_text("hello")
    with pytest.raises(InputError, match="notes.pth: not a readable VGG19 weight file"):
        load_vgg19(text)
    with pytest.raises(InputError, match="missing.pth: VGG19 weight file not found"):
        load_vgg19(tmp_path / "missing.pth")


def test_vgg_fallback_warns_how_to_get_weights(tmp_path, monkeypatch):
    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "empty"))
    monkeypatch.delenv("MESH2TEX_VGG_WEIGHTS", raising=False)
    with pytest.warns(UserWarning, match="random-weight VGG19.*--vgg-weights"):
        model = load_vgg19(device="cpu")
    assert not model.pretrained and "random" in model.source


def test_masked_gram_ignores_background_and_area():
    features = torch.rand(1, 4, 8, 8)
    mask = torch.zeros(1, 1, 8, 8)
    mask[..., 2:6, 2:6] = 1
    changed = features.clone()
    changed[..., 0, :] = 9.0  # background only
    assert torch.allclose(masked_gram(features, mask), masked_gram(changed, mask))
    # A constant texture has the same Gram matrix over a small and a large object.
    constant = torch.ones(1, 4, 8, 8) * torch.arange(1.0, 5.0).view(1, 4, 1, 1)
    big = torch.ones(1, 1, 8, 8)
    assert torch.allclose(masked_gram(constant, mask), masked_gram(constant, big))
    assert masked_gram(features, mask).shape == (1, 4, 4)


def test_global_style_loss_ignores_background_and_flows_to_the_render(vgg):
    torch.manual_seed(0)
    mask = _disk_mask()
    photo = torch.rand(1, 3, 64, 64) * 2 - 1
    render = (torch.rand(1, 3, 64, 64) * 2 - 1).requires_grad_()
    loss = global_style_loss(vgg, render, mask, photo, mask)
    other_background = photo * mask + (1 - mask) * torch.rand(1, 3, 64, 64)
    assert global_style_loss(vgg, render, mask, other_background, mask).item() == pytest.approx(loss.item(), rel=1e-5)
    assert float(global_style_loss(vgg, photo, mask, photo, mask)) == 0.0
    loss.backward()
    assert render.grad.abs().sum() > 0
    assert float(render.grad[..., 0, 0].abs().sum()) == 0.0  # background pixels get no gradient
    grams = style_grams(vgg, photo, mask, scales=3)
    assert len(grams) == 3 and all(len(level) == 5 for level in grams)


def _noc_map(size, offset):
    """A NOC map whose value at (row, col) is the canonical coordinate of object point (row - dr, col - dc)."""
    rows, cols = torch.meshgrid(torch.arange(size).float(), torch.arange(size).float(), indexing="ij")
    return torch.stack([(rows - offset[0]) / size, (cols - offset[1]) / size, torch.full_like(rows, 0.5)], dim=-1)


def test_nearest_noc_patch_centre_lands_where_the_nocs_match():
    size = 64
    photo_mask = _disk_mask(size, 18, (30, 34))[0, 0]
    render_mask = _disk_mask(size, 20, (24, 40))[0, 0]
    # The same object seen shifted: photo pixel (r, c) shows the point rendered at (r - 6, c + 6).
    photo_noc = _noc_map(size, (6, -6))
    render_noc = _noc_map(size, (0, 0))
    generator = torch.Generator().manual_seed(3)
    pairs = sample_patch_pairs(photo_mask, render_mask, 16, photo_noc, render_noc, generator=generator)
    assert bool(photo_mask[pairs.photo_centres[:, 0], pairs.photo_centres[:, 1]].all())
    expected = pairs.photo_centres + torch.tensor([-6, 6])
    assert torch.equal(pairs.render_centres, expected)
    assert torch.equal(nearest_noc_pixels(photo_noc[30, 34][None], render_noc, render_mask), torch.tensor([[24, 40]]))


def test_unguided_pairs_are_random_object_pixels_and_empty_masks_fail():
    photo_mask = _disk_mask(32, 8, (10, 10))[0, 0]
    render_mask = _disk_mask(32, 8, (20, 20))[0, 0]
    pairs = sample_patch_pairs(photo_mask, render_mask, 50, guided=False, generator=torch.Generator().manual_seed(0))
    assert bool(render_mask[pairs.render_centres[:, 0], pairs.render_centres[:, 1]].all())
    assert len({tuple(c) for c in pairs.render_centres.tolist()}) > 10
    with pytest.raises(InputError, match="mask is empty"):
        sample_patch_pairs(torch.zeros(32, 32), render_mask, 2, guided=False)


def test_crop_patches_stay_inside_the_image():
    image = torch.arange(100.0 * 80).view(1, 100, 80)
    patches = crop_patches(image, torch.tensor([[0, 0], [99, 79], [50, 40]]), 64)
    assert patches.shape == (3, 1, 64, 64)
    assert float(patches[0, 0, 0, 0]) == 0.0  # clamped to the top-left corner
    assert float(patches[1, 0, -1, -1]) == float(image[0, -1, -1])  # clamped to the bottom-right corner
    assert float(patches[2, 0, 32, 32]) == float(image[0, 50, 40])  # centred when it fits
    assert crop_patches(image, torch.tensor([[5, 5]]), 128).shape == (1, 1, 80, 80)  # size clipped to the image


def test_patch_style_loss_zero_for_matching_patches_and_differentiable(vgg):
    torch.manual_seed(0)
    mask = _disk_mask(96, 40, (48, 48))
    photo = torch.rand(1, 3, 96, 96) * 2 - 1
    noc = _noc_map(96, (0, 0))
    pairs = sample_patch_pairs(mask[0, 0], mask[0, 0], 2, noc, noc, generator=torch.Generator().manual_seed(1))
    assert torch.equal(pairs.photo_centres, pairs.render_centres)
    assert float(patch_style_loss(vgg, photo, mask, photo, mask, pairs)) == 0.0
    render = (torch.rand(1, 3, 96, 96) * 2 - 1).requires_grad_()
    loss = patch_style_loss(vgg, render, mask, photo, mask, pairs)
    assert loss.item() > 0
    loss.backward()
    assert render.grad.abs().sum() > 0


def test_lowpass_colour_loss_pins_colours_where_both_show_the_object_and_nowhere_else():
    mask = _disk_mask()
    photo = torch.zeros(1, 3, 64, 64)
    photo[:, 0] = 0.5
    assert lowpass_colour_loss(photo.clone(), mask, photo, mask, sigma=2.0) == 0
    # Colours outside either mask (background, or object pixels the photo does not show) do not count.
    elsewhere = photo.clone()
    elsewhere[..., :, :8] = -1.0
    assert lowpass_colour_loss(elsewhere, mask, photo, mask, sigma=2.0) == 0
    half = mask.clone()
    half[..., 32:, :] = 0
    other_half = photo.clone()
    # wrong, but where the photo does not show the object, beyond the blur's reach (3 sigma)
    other_half[..., 40:, :] = 1.0
    assert lowpass_colour_loss(other_half, mask, photo, half, sigma=2.0) == 0
    # A wrong colour on the object is the loss, in [-1, 1] units per channel; the gradient reaches it.
    render = torch.zeros(1, 3, 64, 64, requires_grad=True)
    loss = lowpass_colour_loss(render, mask, photo, mask, sigma=2.0)
    assert loss.item() == pytest.approx(0.5 / 3, rel=1e-5)
    loss.backward()
    assert render.grad[0, 0].abs().sum() > 0 and render.grad[0, 1].abs().sum() == 0
    with pytest.raises(ValueError, match="render is"):
        lowpass_colour_loss(render, mask, photo[..., :32, :32], mask[..., :32, :32], sigma=2.0)
