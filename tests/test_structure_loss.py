"""The structure-aware style losses: sliced Wasserstein ("sw"), oriented-band statistics ("ps") and raw
multi-scale patches ("patch")."""

import pytest
import torch

from mesh2tex.losses.ot_style import STYLE_LOSSES, ExemplarFeatures, style_loss
from mesh2tex.losses.structure import (
    band_statistics,
    exemplar_band_statistics,
    exemplar_patch_sets,
    oriented_filters,
    patch_loss,
    patch_sets,
    ps_loss,
    quantile_resample,
    sliced_wasserstein2,
    statistics_distance,
)
from mesh2tex.nn.vgg import VGG19Features
from mesh2tex.synthetic.exemplars import exemplar_image


def _image(name: str, size: int = 64) -> torch.Tensor:
    return torch.from_numpy(exemplar_image(name, size)).permute(2, 0, 1)[None].float() / 127.5 - 1


def _disc(size: int = 64, radius: float = 26.0) -> torch.Tensor:
    yy, xx = torch.meshgrid(torch.arange(size), torch.arange(size), indexing="ij")
    return (((yy - size / 2 + 0.5) ** 2 + (xx - size / 2 + 0.5) ** 2) < radius**2).float()[None, None]


@pytest.fixture(scope="module")
def vgg():
    net = VGG19Features()
    net.init_random()
    return net.eval()


def test_the_new_kinds_are_registered():
    assert {"ot", "gram", "sw", "ps", "patch"} <= set(STYLE_LOSSES)


def test_quantile_resample_keeps_a_set_and_halves_a_doubled_one():
    values = torch.sort(torch.randn(50, 3, generator=torch.Generator().manual_seed(0)), dim=0).values
    assert torch.equal(quantile_resample(values, 50), values)
    doubled = torch.sort(torch.cat([values, values]), dim=0).values
    assert torch.allclose(quantile_resample(doubled, 50), values, atol=1e-6)


def test_sliced_wasserstein_is_zero_for_one_distribution_and_grows_with_a_shift():
    g = torch.Generator().manual_seed(1)
    a = torch.randn(400, 8, generator=g)
    directions = torch.nn.functional.normalize(torch.randn(8, 64, generator=g), dim=0)
    assert float(sliced_wasserstein2(a, torch.cat([a, a]), directions)) < 1e-10  # same distribution, twice the points
    near = float(sliced_wasserstein2(a, a + 0.1, directions))
    far = float(sliced_wasserstein2(a, a + 1.0, directions))
    assert 0 < near < far


def test_oriented_filters_ignore_flat_colour():
    bank = oriented_filters(4)
    assert bank.shape == (8, 1, 7, 7)
    assert bank.sum(dim=(1, 2, 3)).abs().max() < 1e-5


def test_band_statistics_ignore_the_background():
    image, mask = _image("checker"), _disc()
    other = image.clone()
    other[:, :, mask[0, 0] < 0.5] = torch.rand(3, int((mask < 0.5).sum())) * 2 - 1
    a, b = band_statistics(image, mask), band_statistics(other, mask)
    assert a.keys() == b.keys() and len(a) > 5
    for key in a:
        assert torch.allclose(a[key], b[key], atol=1e-5), key


def test_ps_ranks_the_exemplar_first_and_sees_orientation():
    """Under a mask, the exemplar itself is far closer to its statistics than the same stripes turned
    90 degrees, a checker of the same colours' kind, noise or its flat mean colour."""
    stripes, mask = _image("stripes"), _disc()
    target = exemplar_band_statistics(stripes)
    own = float(ps_loss(stripes, mask, target))
    others = {
        "turned": stripes.transpose(2, 3).flip(3),
        "checker": _image("checker"),
        "noise": torch.rand(1, 3, 64, 64, generator=torch.Generator().manual_seed(0)) * 2 - 1,
        "flat": stripes.mean(dim=(2, 3), keepdim=True).expand_as(stripes),
    }
    for name, image in others.items():
        assert float(ps_loss(image, mask, target)) > 10 * own, name


def test_ps_prefers_the_exemplars_colours_scattered_to_a_flat_colour():
    """A flat colour must not be the cheapest way out: the exemplar's own pixels shuffled score better."""
    stripes, mask = _image("stripes"), _disc()
    target = exemplar_band_statistics(stripes)
    shuffled = stripes.flatten(2)[:, :, torch.randperm(64 * 64, generator=torch.Generator().manual_seed(4))].reshape(
        stripes.shape
    )
    flat = stripes.mean(dim=(2, 3), keepdim=True).expand_as(stripes)
    assert float(ps_loss(shuffled, mask, target)) < float(ps_loss(flat, mask, target))


def test_ps_loss_falls_under_gradient_descent():
    target = exemplar_band_statistics(_image("checker"))
    mask = _disc()
    x = (torch.rand(1, 3, 64, 64, generator=torch.Generator().manual_seed(2)) * 0.2).requires_grad_(True)
    optimizer = torch.optim.Adam([x], lr=0.05)
    first = None
    for _ in range(25):
        loss = ps_loss(x, mask, target)
        first = float(loss.detach()) if first is None else first
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    assert float(ps_loss(x.detach(), mask, target)) < 0.5 * first


def test_statistics_distance_compares_shared_groups_only():
    a = {"x": torch.tensor([1.0, 2.0]), "y": torch.tensor([3.0])}
    b = {"x": torch.tensor([1.0, 2.0]), "z": torch.tensor([5.0])}
    assert float(statistics_distance(a, b)) == 0.0


def test_patch_sets_ignore_the_background_and_hold_only_whole_patches():
    """Pixels off the object change no patch at any octave, and a patch set holds only patches wholly on it."""
    image, mask = _image("checker"), _disc()
    other = image.clone()
    other[:, :, mask[0, 0] < 0.5] = torch.rand(3, int((mask < 0.5).sum())) * 2 - 1
    a, b = patch_sets(image, mask), patch_sets(other, mask)
    assert len(a) == 4 and all(len(x) > 0 for x in a[:3])
    for x, y in zip(a, b):
        assert torch.equal(x, y)
    whole = patch_sets(image)
    assert [len(x) for x in whole] == [60 * 60, 28 * 28, 12 * 12, 4 * 4]  # every 5 x 5 patch of 64, 32, 16, 8 px
    assert len(a[0]) < len(whole[0])


def test_patch_loss_is_zero_for_the_exemplar_and_sees_corners():
    """The exemplar itself scores 0 and the same checker moved scores near it; stripes of the same colours and
    period (no corners), a checker turned 45 degrees, its pixels shuffled and its flat colour score far worse."""
    checker = _image("checker")
    sets = exemplar_patch_sets(checker)
    full = torch.ones(1, 1, 64, 64)

    def loss(image):
        return float(patch_loss(image, full, sets, generator=torch.Generator().manual_seed(0)))

    assert loss(checker) < 1e-8
    big = torch.from_numpy(exemplar_image("checker", 128, extent=2.0)).permute(2, 0, 1)[None].float() / 127.5 - 1
    moved = big[..., 8:72, 4:68]  # the same pattern at the same pixel scale, moved (whole coarsest pixels)
    rows = (torch.arange(64) // 8 % 2).float()  # bands as wide as the checker's squares (64 px: 4 periods)
    colours = torch.stack([checker[0, :, 0, 0], checker[0, :, 0, 8]])  # its two colours
    stripes = colours[rows.long()].t()[:, :, None].expand(3, 64, 64)[None]
    yy, xx = torch.meshgrid(torch.arange(64), torch.arange(64), indexing="ij")
    diagonal = colours[(((yy + xx) // 11 + (yy - xx + 64) // 11) % 2)].permute(2, 0, 1)[None]
    shuffled = checker.flatten(2)[:, :, torch.randperm(64 * 64, generator=torch.Generator().manual_seed(4))]
    flat = checker.mean(dim=(2, 3), keepdim=True).expand_as(checker)
    near = loss(moved)
    for name, image in {
        "stripes": stripes,
        "diagonal": diagonal,
        "shuffled": shuffled.reshape(checker.shape),
        "flat": flat,
    }.items():
        assert loss(image) > 10 * near, name  # measured: 65x to 370x


def test_patch_loss_falls_under_gradient_descent():
    sets = exemplar_patch_sets(_image("checker"))
    mask = _disc()
    x = (torch.rand(1, 3, 64, 64, generator=torch.Generator().manual_seed(2)) * 0.2).requires_grad_(True)
    optimizer = torch.optim.Adam([x], lr=0.05)
    generator = torch.Generator().manual_seed(0)
    first = patch_loss(x, mask, sets, generator=generator).item()
    for _ in range(25):
        loss = patch_loss(x, mask, sets, max_points=512, generator=generator)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    assert float(patch_loss(x.detach(), mask, sets, generator=generator)) < 0.5 * first


@pytest.mark.parametrize("kind", ["sw", "ps", "patch"])
def test_style_loss_kinds_flow_to_the_render_and_rank_the_exemplar(vgg, kind):
    exemplar = ExemplarFeatures.compute(vgg, _image("stripes"), depth=2)
    mask = _disc()
    render = _image("stripes").clone().requires_grad_(True)
    own = style_loss(vgg, render, mask, exemplar, kind, max_points=256, generator=torch.Generator().manual_seed(0))
    own.backward()
    assert render.grad is not None and float(render.grad.abs().sum()) > 0
    noise = torch.rand(1, 3, 64, 64, generator=torch.Generator().manual_seed(3)) * 2 - 1
    other = style_loss(vgg, noise, mask, exemplar, kind, max_points=256, generator=torch.Generator().manual_seed(0))
    assert float(other.detach()) > 3 * float(own.detach())


def test_unknown_kind_is_refused(vgg):
    exemplar = ExemplarFeatures.compute(vgg, _image("stripes"), depth=1)
    with pytest.raises(ValueError, match="style loss must be one of"):
        style_loss(vgg, _image("stripes"), _disc(), exemplar, "bogus")


def test_train_nca_config_accepts_the_new_losses():
    from train.nca import TrainNCAConfig

    for kind in ("sw", "ps", "patch"):
        assert TrainNCAConfig(style_loss=kind).style_loss == kind
    with pytest.raises(ValueError, match="style_loss"):
        TrainNCAConfig(style_loss="bogus")
