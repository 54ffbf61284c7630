"""Metrics: KID/FID properties, honest feature names, SWD, paired metrics, Inception weights, `mesh2tex evaluate`."""

import json

import numpy as np
import pytest
import scipy.linalg
import torch
from PIL import Image

from mesh2tex.cli import main
from mesh2tex.errors import InputError
from mesh2tex.metrics import (
    InceptionV3Features,
    colour_histogram_distance,
    fid,
    get_feature_extractor,
    kid,
    load_inception,
    masked_psnr,
    masked_ssim,
    swd,
)


def test_kid_near_zero_for_one_distribution_and_grows_with_a_shift():
    generator = torch.Generator().manual_seed(0)
    a = torch.randn(200, 32, generator=generator)
    same = torch.randn(200, 32, generator=generator)
    shifted = torch.randn(200, 32, generator=generator) + 0.5
    self_kid, _ = kid(a, a, num_subsets=10, subset_size=100)
    same_kid, _ = kid(a, same, num_subsets=10, subset_size=100)
    shifted_kid, _ = kid(a, shifted, num_subsets=10, subset_size=100)
    # Unbiased: two samples of one distribution give about 0 (either sign), a shifted one clearly more.
    assert abs(self_kid) < 0.1 * shifted_kid and abs(same_kid) < 0.1 * shifted_kid
    assert shifted_kid > 0


def test_fid_matches_the_matrix_square_root_formula():
    generator = torch.Generator().manual_seed(1)
    for n_a, n_b, dim in ((40, 50, 10), (8, 9, 12)):  # more and fewer samples than dimensions
        a = torch.randn(n_a, dim, generator=generator)
        b = torch.randn(n_b, dim, generator=generator) * 1.5 + 0.3
        x, y = a.double().numpy(), b.double().numpy()
        sx, sy = np.cov(x, rowvar=False), np.cov(y, rowvar=False)
        reference = (
            ((x.mean(0) - y.mean(0)) ** 2).sum()
            + np.trace(sx + sy)
            - 2 * np.trace(np.real(scipy.linalg.sqrtm(sx @ sy)))
        )
        assert fid(a, b) == pytest.approx(reference, rel=1e-6)
    assert fid(a, a) == pytest.approx(0.0, abs=1e-6)


def _textures(count, seed, shift=0.0, blur=False):
    generator = torch.Generator().manual_seed(seed)
    images = torch.rand(count, 3, 32, 32, generator=generator) * 0.5 + 0.25 + shift
    if blur:
        images = torch.nn.functional.avg_pool2d(images, 3, 1, 1)
    return images.clamp(0, 1)


def test_swd_grows_with_a_distribution_shift():
    reference = _textures(8, 0)
    same = _textures(8, 1)
    options = dict(num_projections=64, repeats=1, patches_per_image=64)
    base = swd(reference, same, **options)
    assert swd(reference, _textures(8, 2, shift=0.1), **options) > 1.5 * base
    assert swd(reference, _textures(8, 3, shift=0.2), **options) > swd(reference, _textures(8, 2, shift=0.1), **options)
    assert swd(reference, _textures(8, 4, blur=True), **options) > 1.5 * base
    # [-1, 1] input gives the same value as [0, 1]
    assert swd(reference * 2 - 1, same * 2 - 1, **options) == pytest.approx(base, rel=1e-5)


def test_swd_sorts_projections_exactly_as_torch_does():
    # The SWD sorts with numpy for speed: its rows must be torch.sort's, ties and duplicates included.
    from mesh2tex.metrics.swd import sorted_rows

    values = torch.randn(64, 300, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    values[:, ::7] = values[:, :1]  # repeated values in every row
    assert torch.equal(sorted_rows(values), torch.sort(values, dim=1).values)
    # a view that is not contiguous
    assert torch.equal(sorted_rows(values[:, 1:]), torch.sort(values[:, 1:], dim=1).values)


def test_paired_metrics():
    generator = torch.Generator().manual_seed(0)
    images = torch.rand(2, 3, 32, 32, generator=generator)
    masks = torch.zeros(2, 1, 32, 32)
    masks[..., 8:24, 8:24] = 1
    assert torch.isinf(masked_psnr(images, images)).all()
    assert torch.allclose(masked_ssim(images, images), torch.ones(2, dtype=torch.float64))
    other_background = images * masks + (1 - masks) * torch.rand(2, 3, 32, 32, generator=generator)
    assert torch.isinf(masked_psnr(other_background, images, masks)).all()
    noisy = (images + 0.05 * torch.randn(2, 3, 32, 32, generator=generator)).clamp(0, 1)
    assert (masked_psnr(noisy, images) > 20).all() and (masked_psnr(noisy, images) < 40).all()
    assert torch.allclose(colour_histogram_distance(images, images), torch.zeros(2, dtype=torch.float64))
    red, blue = torch.zeros(1, 3, 8, 8), torch.zeros(1, 3, 8, 8)
    red[:, 0], blue[:, 2] = 1.0, 1.0
    assert float(colour_histogram_distance(red, blue)) == pytest.approx(1.0)


def test_weight_free_features_are_named_for_what_they_are(tmp_path, monkeypatch):
    monkeypatch.setenv("TORCH_HOME", str(tmp_path))
    monkeypatch.delenv("MESH2TEX_INCEPTION_WEIGHTS", raising=False)
    with pytest.warns(UserWarning, match="kid_randvgg"):
        extractor = get_feature_extractor("auto")
    assert extractor.name == "randvgg"
    assert extractor.metric_name("kid") == "kid_randvgg" and extractor.metric_name("fid") == "fid_randvgg"
    with pytest.raises(InputError, match="no Inception-v3 weights"):
        get_feature_extractor("inception")


def test_inception_loads_a_weight_file_written_by_the_test(tmp_path):
    model = InceptionV3Features(fid_variant=True)
    state = dict(model.state_dict())
    state["fc.weight"] = torch.zeros(1008, 2048)  # the FID Inception's classifier: 1008 classes
    state["fc.bias"] = torch.zeros(1008)
    path = tmp_path / "pt_inception-2015-12-05-6726825d.pth"
    torch.save(state, path)
    loaded = load_inception(path)
    assert loaded.fid_variant and loaded.source == str(path)
    assert torch.equal(loaded.Mixed_7c.branch_pool.conv.weight, model.Mixed_7c.branch_pool.conv.weight)
    extractor = get_feature_extractor("auto", inception_weights=path)
    assert extractor.name == "" and extractor.metric_name("kid") == "kid"
    with pytest.raises(InputError, match="holds inception weights, not tvinception"):
        get_feature_extractor("tvinception", inception_weights=path)
    del state["Mixed_5b.branch1x1.conv.weight"]
    torch.save(state, tmp_path / "broken.pth")
    with pytest.raises(InputError, match="broken.pth: not Inception-v3 weights: missing 1 key"):
        load_inception(tmp_path / "broken.pth")


@pytest.mark.slow
def test_inception_features_shape():
    model = InceptionV3Features(fid_variant=False).eval()
    with torch.no_grad():
        features = model(torch.rand(2, 3, 64, 64) * 2 - 1)
    assert features.shape == (2, 2048)


def _write_set(folder, count, seed, shift=0.0, alpha=False):
    folder.mkdir(parents=True)
    rng = np.random.default_rng(seed)
    for k in range(count):
        rgb = np.clip(rng.random((32, 32, 3)) * 0.5 + 0.25 + shift, 0, 1)
        array = (rgb * 255).astype(np.uint8)
        if alpha:
            mask = np.zeros((32, 32, 1), np.uint8)
            mask[4:28, 6:26] = 255
            array = np.concatenate([array, mask], axis=2)
        Image.fromarray(array).save(folder / f"view{k:02d}.png")


def test_evaluate_command_sets_and_pairs(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "no_weights"))
    _write_set(tmp_path / "renders", 6, 0, alpha=True)
    _write_set(tmp_path / "photos", 6, 1, shift=0.1)
    out = tmp_path / "eval"
    args = [
        "evaluate",
        "--renders",
        str(tmp_path / "renders"),
        "--images",
        str(tmp_path / "photos"),
        "--out",
        str(out),
        "--resolution",
        "32",
        "--kid-subsets",
        "3",
    ]
    assert main(args) == 0
    assert "mesh2tex: warning: no Inception-v3 weights found" in capsys.readouterr().err
    result = json.loads((out / "metrics.json").read_text())
    assert result["mode"] == "sets" and result["counts"] == {"renders": 6, "images": 6}
    # The photos have neither alpha nor --masks: their histogram can only pool whole images, and says so.
    assert {"kid_randvgg", "fid_randvgg", "swd", "color_hist_tv_whole_image"} <= set(result["metrics"])
    assert "color_hist_tv" not in result["metrics"]
    assert "kid" not in result["metrics"] and "fid" not in result["metrics"]
    assert "| kid_randvgg |" in (out / "metrics.md").read_text()
    assert main(args) == 2  # refuses to overwrite
    assert "--overwrite" in capsys.readouterr().err

    pairs_out = tmp_path / "pairs"
    assert (
        main(
            [
                "evaluate",
                "--renders",
                str(tmp_path / "renders"),
                "--images",
                str(tmp_path / "renders"),
                "--pairs",
                "--out",
                str(pairs_out),
            ]
        )
        == 0
    )
    result = json.loads((pairs_out / "metrics.json").read_text())
    assert result["metrics"]["psnr_masked"] == "inf" and result["metrics"]["ssim_masked"] == pytest.approx(1.0)
    assert len(result["per_pair"]) == 6


def test_set_colour_histograms_compare_object_pixels_not_backgrounds():
    from mesh2tex.metrics.evaluate import pooled_histogram_distance

    def objects(colour, side, n=3):
        """n white 32x32 images with a centred square of ``colour`` and ``side`` pixels, and its masks."""
        images, masks = torch.ones(n, 3, 32, 32), torch.zeros(n, 1, 32, 32)
        lo = (32 - side) // 2
        images[:, :, lo : lo + side, lo : lo + side] = torch.tensor(colour).reshape(1, 3, 1, 1)
        masks[:, :, lo : lo + side, lo : lo + side] = 1
        return images, masks

    small_red, small_mask = objects([0.8, 0.1, 0.1], 8)
    large_red, large_mask = objects([0.8, 0.1, 0.1], 24)
    large_blue, blue_mask = objects([0.1, 0.1, 0.8], 24)
    # Same object colour, different object sizes: only the whole-image variant sees a difference.
    assert pooled_histogram_distance(small_red, large_red, small_mask, large_mask, 8) == {
        "color_hist_tv": pytest.approx(0.0)
    }
    assert pooled_histogram_distance(small_red, large_red, None, large_mask, 8)["color_hist_tv_whole_image"] > 0.4
    # Disjoint object colours are as far apart as histograms get, however much white surrounds them.
    assert pooled_histogram_distance(large_red, large_blue, large_mask, blue_mask, 8) == {
        "color_hist_tv": pytest.approx(1.0)
    }
    assert pooled_histogram_distance(small_red, large_blue, small_mask, blue_mask, 8) == {
        "color_hist_tv": pytest.approx(1.0)
    }
    with pytest.raises(InputError, match="no object pixel"):
        pooled_histogram_distance(large_red, large_blue, torch.zeros_like(large_mask), blue_mask, 8)


def test_evaluate_sets_without_kid_fid_skips_the_feature_network(monkeypatch):
    import mesh2tex.metrics.evaluate as evaluate

    def no_network(*args, **kwargs):
        raise AssertionError("the feature network was built")

    monkeypatch.setattr(evaluate, "get_feature_extractor", no_network)
    generator = torch.Generator().manual_seed(0)
    renders, images = torch.rand(4, 3, 32, 32, generator=generator), torch.rand(5, 3, 32, 32, generator=generator)
    masks = torch.ones(4, 1, 32, 32), torch.ones(5, 1, 32, 32)
    result = evaluate.evaluate_sets(
        renders,
        images,
        config=evaluate.EvaluateConfig(resolution=32),
        render_masks=masks[0],
        image_masks=masks[1],
        kid_fid=False,
    )
    assert result["features"] is None
    assert not any(name.startswith(("kid", "fid")) for name in result["metrics"])
    assert {"swd", "color_hist_tv"} <= set(result["metrics"])


def test_evaluate_sets_takes_the_images_features_once_computed():
    """Several sets measured against one reference reuse its features: the same figures."""
    import mesh2tex.metrics.evaluate as evaluate

    generator = torch.Generator().manual_seed(0)
    renders, images = torch.rand(4, 3, 32, 32, generator=generator), torch.rand(6, 3, 32, 32, generator=generator)
    extractor = get_feature_extractor("randvgg")
    config = evaluate.EvaluateConfig(resolution=32, kid_subsets=2, kid_subset_size=4)
    fresh = evaluate.evaluate_sets(renders, images, extractor, config)["metrics"]
    reused = evaluate.evaluate_sets(renders, images, extractor, config, image_features=extractor(images * 2 - 1))[
        "metrics"
    ]
    assert reused == pytest.approx(fresh)


def test_evaluate_names_a_bad_file(tmp_path, capsys):
    _write_set(tmp_path / "renders", 2, 0)
    _write_set(tmp_path / "photos", 2, 1)
    (tmp_path / "photos" / "view01.png").write_text("not an image")
    code = main(
        [
            "evaluate",
            "--renders",
            str(tmp_path / "renders"),
            "--images",
            str(tmp_path / "photos"),
            "--pairs",
            "--out",
            str(tmp_path / "o"),
        ]
    )
    assert code == 2
    assert "view01.png: not a readable image" in capsys.readouterr().err
    (tmp_path / "photos" / "view01.png").unlink()
    code = main(
        [
            "evaluate",
            "--renders",
            str(tmp_path / "renders"),
            "--images",
            str(tmp_path / "photos"),
            "--pairs",
            "--out",
            str(tmp_path / "o"),
        ]
    )
    assert code == 2
    assert "no image for render(s) view01" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
