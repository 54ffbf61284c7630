"""The generation protocol (``mesh2tex evaluate --generation``) and its measures."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch
import yaml
from conftest import TINY_GAN, make_tiny_world

from mesh2tex.cli import main
from mesh2tex.evaluation.generation import GenerationConfig, read_world, run_generation_protocol
from mesh2tex.evaluation.generation_renders import fresh_photo_set, ground_truth_renders
from mesh2tex.evaluation.report import generation_markdown
from mesh2tex.photos import list_images, load_set
from mesh2tex.synthetic.world import sample_views


def _world_photos(world, resolution: int, shape: str | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """The world's photo set as the protocol reads it (only ``shape``'s photos when given)."""
    photos, masks = load_set(
        world.root / "images", "image", resolution, 1.0, masks=list_images(world.root / "masks", "mask")
    )
    if shape is None:
        return photos, masks
    keep = torch.tensor([stem.rsplit("_", 1)[0] == shape for stem in list_images(world.root / "images", "image")])
    return photos[keep], masks[keep]


def test_ground_truth_rows_are_rendered_as_the_world_renders_its_photos(world_and_gan):
    """The oracle and ground-truth rows go through the photos' own pipeline (the world's resolution,
    then resized as the photo set is read): a training shape's own material at its photos' cameras
    is its photos, pixel for pixel, at an evaluation resolution below the world's too."""
    world = read_world(world_and_gan / "world")
    name = world.train[0]
    views = sample_views(world.spec, world.indices[name], world.spec.views)
    images, masks = ground_truth_renders(world, name, views, 16)
    photos, photo_masks = _world_photos(world, 16, name)
    assert images.shape == photos.shape == (world.spec.views, 3, 16, 16)
    assert torch.equal(masks, photo_masks)
    assert (images - photos).abs().max() < 1e-6


def test_generator_rows_are_rendered_through_the_oracles_pipeline(world_and_gan, monkeypatch):
    """With ``photo_render``, a generator's texture is rendered as the oracle and the photos are (at
    the world's resolution, supersampled, on white, resized as the photo set is read): a generator that
    paints one colour gives exactly the world pipeline's render of that colour on its mesh, antialiased
    edges included, which the GAN's own renderer straight at the metric's resolution does not."""
    from mesh2tex.evaluation import generation_renders as renders
    from mesh2tex.evaluation.compare import render_for_comparison
    from mesh2tex.evaluation.surfaces import flat_surface
    from mesh2tex.geometry.prepared import PreparedShape
    from mesh2tex.models import load_generator
    from mesh2tex.nn.batch import collate_shapes
    from mesh2tex.nn.generator import FaceTexture
    from mesh2tex.render import composite_images

    world = read_world(world_and_gan / "world")
    name = world.held_out[0]
    shape = PreparedShape.load(world_and_gan / "shapes" / f"{name}.npz")
    generator = load_generator(world_and_gan / "gan" / "checkpoint.safetensors", torch.device("cpu")).network
    monkeypatch.setattr(
        FaceTexture, "colours", lambda texture, triangle_id, bary: torch.full((len(triangle_id), 3), 0.2)
    )
    views = sample_views(world.spec, world.indices[name], 2)
    z = torch.randn(2, generator.cfg.z_dim)
    images, masks = renders.generator_renders(
        generator, shape, views, 16, z, torch.device("cpu"), lit=True, photo_render=world.spec.photo_render
    )
    batch = collate_shapes([shape])
    out = render_for_comparison(
        flat_surface(batch.shape_vertices(0), batch.shape_triangles(0), [0.6, 0.6, 0.6]), views, world.spec.photo_render
    )
    expected, expected_masks = renders.read_as_photos(composite_images(out.rgb, out.mask, 1.0), out.mask, 16)
    assert torch.equal(masks, expected_masks) and (images - expected).abs().max() < 1e-5
    direct, _ = renders.generator_renders(generator, shape, views, 16, z, torch.device("cpu"), lit=True)
    assert (direct - expected).abs().max() > 0.05


def test_distances_are_to_a_fresh_photo_set_not_the_training_photos(world_and_gan):
    """The reference of every distance shows the training shapes at their photos' cameras, each photo
    with a new material of the world's sampler: not the photos the GAN learnt from."""
    world = read_world(world_and_gan / "world")
    reference, reference_masks = fresh_photo_set(world, 32, seed=0)
    photos, photo_masks = _world_photos(world, 32)
    assert torch.equal(reference_masks, photo_masks), "same shapes, same cameras"
    assert ((reference - photos).abs() * photo_masks).amax(dim=(1, 2, 3)).min() > 0.1, (
        "every photo gets another material"
    )
    again, _ = fresh_photo_set(world, 32, seed=0)
    assert torch.equal(again, reference)


@pytest.fixture(scope="module")
def world_and_gan(tmp_path_factory):
    root = tmp_path_factory.mktemp("generation")
    make_tiny_world(root, views=3, resolution=32, query_views=1)
    world, shapes = root / "world", root / "shapes"
    (root / "tiny.yaml").write_text(yaml.safe_dump(TINY_GAN))
    assert (
        main(
            [
                "train",
                "gan",
                "--shapes",
                str(shapes),
                "--images",
                str(world),
                "--out",
                str(root / "gan"),
                "--config",
                str(root / "tiny.yaml"),
                "--iters",
                "1",
                "--batch",
                "1",
                "--views",
                "1",
                "--resolution",
                "32",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    return root


def test_protocol_rows_oracle_and_diversity(world_and_gan, tmp_path):
    root = world_and_gan
    cfg = GenerationConfig(
        views=6, latents=3, kid_fid=False, repeats=2
    )  # 3 draws against 6 fresh photos are too few to rank
    result = run_generation_protocol(
        root / "world",
        root / "shapes",
        root / "gan" / "checkpoint.safetensors",
        cfg,
        samples_path=tmp_path / "grid.png",
        log=lambda line: None,
    )
    rows = result["rows"]
    assert set(rows) == {
        "trained",
        "untrained",
        "oracle",
        "oracle_unlit",
        "ground_truth",
        "training_materials",
        "flat_colour",
        "mean_texture",
    }
    # The oracle's textures also beat the simple baseline, one flat colour (the photo set's mean).
    assert rows["oracle"]["object_swd"] < rows["flat_colour"]["object_swd"]
    # The oracle is fresh photos of the held-out shapes with textures from the world's sampler: it must
    # beat a generator that has not learnt.
    assert rows["oracle"]["object_swd"] < rows["untrained"]["object_swd"]
    assert rows["oracle"]["swd"] < rows["untrained"]["swd"]
    assert rows["oracle"]["color_hist_tv"] < rows["untrained"]["color_hist_tv"]
    assert np.isfinite(result["gap_closed"]) and np.isfinite(result["gap_closed_training_materials"])
    assert isinstance(result["oracle_loses"], list)
    # Every distance is the mean of the draws; the first draw is the one-draw protocol's.
    per_draw = rows["trained"]["object_swd_per_draw"]
    assert len(per_draw) == 2 == len(result["gap_closed_per_draw"]) and rows["trained"]["object_swd"] == pytest.approx(
        np.mean(per_draw)
    )
    one = run_generation_protocol(
        root / "world",
        root / "shapes",
        root / "gan" / "checkpoint.safetensors",
        dataclasses.replace(cfg, repeats=1),
        log=lambda line: None,
    )
    assert one["rows"]["oracle"]["object_swd"] == pytest.approx(rows["oracle"]["object_swd_per_draw"][0])
    assert one["rows"]["trained"]["object_swd"] == pytest.approx(per_draw[0])
    assert all(np.isfinite(rows[row]["object_swd_vs_photos"]) for row in rows)
    d = result["diversity"]
    assert (
        d["reference_materials"]["spread"] > 1
        and d["reference_materials"]["pairwise"] > 1
        and d["photo_set_spread"] > 1
    )
    assert d["trained"]["spread"] >= 0 and d["trained_spread_vs_photo_set"] == pytest.approx(
        d["trained"]["spread"] / d["photo_set_spread"]
    )
    assert (tmp_path / "grid.png").is_file()


def test_a_generator_that_ignores_its_latent_has_no_diversity(world_and_gan, tmp_path, monkeypatch):
    root = world_and_gan
    from mesh2tex.evaluation import generation

    original = generation.load_generator

    def collapsed(path, device):
        model = original(path, device)
        mapping = model.network.mapping.forward
        model.network.mapping.forward = lambda z, *a, **k: mapping(torch.zeros_like(z) + 1.0, *a, **k)
        return model

    monkeypatch.setattr(generation, "load_generator", collapsed)
    result = run_generation_protocol(
        root / "world",
        root / "shapes",
        root / "gan" / "checkpoint.safetensors",
        GenerationConfig(views=2, latents=3, kid_fid=False, repeats=1),
        log=lambda line: None,
    )
    assert result["diversity"]["trained"]["spread"] == pytest.approx(0, abs=1e-3)
    assert result["diversity"]["trained"]["pairwise"] == pytest.approx(0, abs=1e-3)


def test_full_truncation_paints_the_mean_texture_for_every_latent(world_and_gan, capsys):
    # Truncation 0 pulls every latent onto w_avg: the trained row is the mean texture, with no diversity.
    root = world_and_gan
    result = run_generation_protocol(
        root / "world",
        root / "shapes",
        root / "gan" / "checkpoint.safetensors",
        GenerationConfig(views=2, latents=3, kid_fid=False, repeats=1, truncation=0.0),
        log=lambda line: None,
    )
    rows, diversity = result["rows"], result["diversity"]
    assert rows["trained"]["object_swd"] == pytest.approx(rows["mean_texture"]["object_swd"], rel=1e-4)
    assert diversity["trained"]["spread"] == pytest.approx(0, abs=1e-3) and diversity["untrained"]["spread"] > 0.1
    with pytest.raises(ValueError, match=r"truncation must be in \[0, 1\]"):
        GenerationConfig(truncation=1.5)
    # The command takes it as 'infer generate' does.
    assert (
        main(
            [
                "evaluate",
                "--generation",
                "--world",
                "w",
                "--shapes",
                "s",
                "--checkpoint",
                "g",
                "--out",
                "o",
                "--truncation",
                "0.7",
                "--print-config",
            ]
        )
        == 0
    )
    assert "truncation: 0.7" in capsys.readouterr().out
    # The generator's renders: as the oracle's by default, the GAN's own renderer on request (earlier figures).
    assert (
        main(
            [
                "evaluate",
                "--generation",
                "--world",
                "w",
                "--shapes",
                "s",
                "--checkpoint",
                "g",
                "--out",
                "o",
                "--generator-render",
                "direct",
                "--print-config",
            ]
        )
        == 0
    )
    assert "generator_render: direct" in capsys.readouterr().out
    assert GenerationConfig().generator_render == "photo"
    with pytest.raises(ValueError, match="generator_render must be one of photo, direct"):
        GenerationConfig(generator_render="fast")


@pytest.mark.parametrize("enabled", [True, False])
def test_generator_rows_are_lit_as_the_generator_was_trained(world_and_gan, tmp_path, monkeypatch, enabled):
    """A generator trained under the light prior is rendered under each view's light on every held-out
    shape (as the oracle is), together with its material reference; one trained unlit is rendered unlit."""
    root = world_and_gan
    from mesh2tex.evaluation import generation
    from mesh2tex.evaluation import generation_renders as renders

    original_load, original_render, original_draws = (
        generation.load_generator,
        generation.generator_renders,
        generation.material_draws,
    )
    seen, sides, oracle, diversity_reference, fresh_photos = [], [], [], [], []

    def load(path, device):
        return dataclasses.replace(original_load(path, device), lit=enabled)

    def render(*args, **kwargs):
        seen.append(args[6] if len(args) > 6 else kwargs.get("lit", False))
        sides.append(kwargs.get("photo_render"))
        return original_render(*args, **kwargs)

    def material(*args, **kwargs):
        lit = kwargs.get("lit", args[6] if len(args) > 6 else False)
        stream = kwargs.get("stream", args[5] if len(args) > 5 else renders.REFERENCE_STREAM)
        if stream == renders.FRESH_PHOTOS_STREAM:
            fresh_photos.append(lit)  # the reference: photos, lit whatever the generator
        elif stream == renders.ORACLE_STREAM:
            oracle.append(lit)
        else:
            diversity_reference.append(lit)
        return original_draws(*args, **kwargs)

    monkeypatch.setattr(generation, "load_generator", load)
    monkeypatch.setattr(generation, "generator_renders", render)
    monkeypatch.setattr(generation, "material_draws", material)
    monkeypatch.setattr(renders, "material_draws", material)  # the fresh photo set's draws
    result = run_generation_protocol(
        root / "world",
        root / "shapes",
        root / "gan" / "checkpoint.safetensors",
        GenerationConfig(views=2, latents=2, kid_fid=False),
        log=lambda line: None,
    )
    assert result["generator_lit"] is enabled
    assert len(seen) >= 4 * len(result["shapes"]) and all(lit is enabled for lit in seen)
    # Every generator render goes through the pipeline of the oracle and the photos, with the world's photos' settings.
    assert sides == [read_world(root / "world").spec.photo_render] * len(seen)
    assert fresh_photos and all(fresh_photos)
    # The oracle is drawn lit and unlit for every shape in every draw; the diversity reference as the generator.
    assert oracle == [True, False] * (len(result["shapes"]) * result["settings"]["repeats"])
    assert len(diversity_reference) == len(result["shapes"]) and all(lit is enabled for lit in diversity_reference)


def test_command_writes_results_and_refuses_to_overwrite(world_and_gan, tmp_path, capsys):
    root = world_and_gan
    args = [
        "evaluate",
        "--generation",
        "--world",
        str(root / "world"),
        "--shapes",
        str(root / "shapes"),
        "--checkpoint",
        str(root / "gan" / "checkpoint.safetensors"),
        "--out",
        str(tmp_path / "out"),
        "--latents",
        "2",
        "--repeats",
        "1",
        "--kid-subsets",
        "2",
        "--device",
        "cpu",
        "--features",
        "randvgg",
    ]
    assert main(args) == 0
    assert {"generation.json", "generation.md", "generation_samples.png"} <= {
        p.name for p in (tmp_path / "out").iterdir()
    }
    assert "Gap closed" in (tmp_path / "out" / "generation.md").read_text()
    assert main(args) == 2 and "--overwrite" in capsys.readouterr().err
    assert main(args[:5] + args[7:]) == 2 and "--generation needs --checkpoint" in capsys.readouterr().err


def test_the_training_split_measures_the_shapes_the_gan_trained_on(world_and_gan, tmp_path, capsys):
    """``split: train`` puts the world's training shapes, not its held-out ones, through the same rows."""
    root = world_and_gan
    index = json.loads((root / "world" / "index.json").read_text())
    result = run_generation_protocol(
        root / "world",
        root / "shapes",
        root / "gan" / "checkpoint.safetensors",
        GenerationConfig(views=6, latents=2, kid_fid=False, max_shapes=1, split="train", repeats=1),
        log=lambda line: None,
    )
    assert result["split"] == "train" and result["shapes"] == index["split"]["train_shapes"][:1]
    assert result["shapes"][0] not in index["split"]["query_shapes"]
    assert result["rows"]["oracle"]["object_swd"] < result["rows"]["untrained"]["object_swd"]
    assert "1 training shapes" in generation_markdown(result)
    # Through the command: only the first training shape is prepared, so the second one is named.
    args = [
        "evaluate",
        "--generation",
        "--world",
        str(root / "world"),
        "--shapes",
        str(root / "shapes"),
        "--checkpoint",
        str(root / "gan" / "checkpoint.safetensors"),
        "--out",
        str(tmp_path / "out"),
        "--latents",
        "2",
        "--split",
        "train",
        "--device",
        "cpu",
        "--features",
        "randvgg",
    ]
    assert main(args) == 2
    assert f"the training shape {index['split']['train_shapes'][1]} is not prepared" in capsys.readouterr().err
