"""The generation protocol's measures (colour, object SWD, gap closed), its pose views and options, and worlds of one
training shape."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import yaml
from conftest import TINY_GAN

from mesh2tex.cli import main
from mesh2tex.metrics.generation import (
    colour_spread,
    gap_closed,
    mean_object_lab,
    mean_pairwise_delta_e,
    object_set_swd,
)


def test_colour_measures_on_known_images():
    white, black = torch.ones(1, 3, 4, 4), torch.zeros(1, 3, 4, 4)
    mask = torch.ones(1, 1, 4, 4)
    lab = mean_object_lab(torch.cat([white, black]), mask.repeat(2, 1, 1, 1))
    assert lab[0, 0] == pytest.approx(100, abs=0.1) and lab[1, 0] == pytest.approx(0, abs=0.1)
    assert colour_spread(lab) == pytest.approx(50, abs=0.1), "two colours 100 apart: spread 50"
    assert colour_spread(lab[[0, 0]]) == 0
    assert mean_pairwise_delta_e(torch.cat([white, black, white]), mask[0]) == pytest.approx(200 / 3, abs=0.1)
    with pytest.raises(ValueError, match="no object pixel"):
        mean_object_lab(white, torch.zeros(1, 1, 4, 4))


def test_object_set_swd_sees_object_colours_not_backgrounds():
    torch.manual_seed(0)
    masks = torch.zeros(6, 1, 32, 32)
    masks[:, :, 8:24, 8:24] = 1
    red = torch.zeros(6, 3, 32, 32)
    red[:, 0] = 0.8
    noisy_red = (red + 0.05 * torch.randn_like(red)).clamp(0, 1)
    blue = noisy_red[:, [2, 1, 0]]
    other_background = noisy_red * masks + torch.rand(6, 3, 32, 32) * (1 - masks)
    same = object_set_swd(noisy_red, masks, noisy_red.flip(0), masks)
    assert object_set_swd(other_background, masks, noisy_red, masks) == pytest.approx(same, rel=0.3, abs=5)
    assert object_set_swd(blue, masks, noisy_red, masks) > 5 * max(same, 1.0)


def test_gap_closed():
    assert gap_closed(200.0, 200.0, 50.0) == 0
    assert gap_closed(200.0, 50.0, 50.0) == pytest.approx(1)
    assert gap_closed(200.0, 100.0, 50.0) == pytest.approx(0.5)
    assert gap_closed(200.0, 300.0, 50.0) < 0
    assert np.isnan(gap_closed(50.0, 40.0, 60.0)), "an oracle that loses makes the figure meaningless"


def test_pose_view_turns_the_light_with_the_camera():
    """The diversity pose keeps a photo's light where the photo had it relative to the camera."""
    import math

    from mesh2tex.evaluation.generation_renders import pose_view
    from mesh2tex.render import orbit_direction as light_direction
    from mesh2tex.synthetic.world import PhotoSetup

    light = light_direction(torch.tensor([100.0 + 40.0]), torch.tensor([50.0]))[0].tolist()
    view = PhotoSetup(
        azimuth=100.0,
        elevation=10.0,
        distance=1.7,
        fov=40.0,
        light=tuple(light),
        ambient=0.4,
        background="solid",
        background_seed=0,
    )
    moved = pose_view(view, 35.0, 20.0, 1.8)
    expected = light_direction(torch.tensor([35.0 + 40.0]), torch.tensor([50.0]))[0]
    assert torch.allclose(torch.tensor(moved.light), expected, atol=1e-5)
    assert (moved.azimuth, moved.elevation, moved.distance, moved.ambient) == (35.0, 20.0, 1.8, 0.4)
    assert math.isclose(sum(v * v for v in moved.light), 1.0, abs_tol=1e-5)


def test_the_commands_offer_the_protocols_lightings_and_splits():
    """evaluate/options.py spells the choices out (it must not import torch); they stay the protocol's."""
    import argparse

    from mesh2tex.evaluate.options import evaluate

    from mesh2tex.evaluation.generation import LIGHTING_MODES, SPLITS

    parser = argparse.ArgumentParser()
    evaluate(parser)
    choices = {action.dest: list(action.choices) for action in parser._actions if action.choices}
    assert choices["gan_lighting"] == list(LIGHTING_MODES)
    assert choices["split"] == list(SPLITS)


def test_a_world_of_one_training_shape_reports_its_photo_spread_as_undefined(tmp_path):
    """The photo set's spread across shapes needs two shapes: with one, the protocol still finishes and
    its report says the figure is undefined, instead of ending in a traceback."""
    from mesh2tex.evaluation.generation_renders import photo_set_spread

    photos, masks = torch.rand(3, 3, 8, 8), torch.ones(3, 1, 8, 8)
    assert np.isnan(photo_set_spread(None, photos, masks, ["chair_0001_00", "chair_0001_01", "chair_0001_02"]))
    assert np.isfinite(photo_set_spread(None, photos, masks, ["chair_0001_00", "chair_0002_00", "chair_0002_01"]))


@pytest.mark.slow
def test_the_protocol_runs_on_a_world_of_one_training_shape(tmp_path, capsys):
    from mesh2tex.geometry.mesh_io import load_mesh
    from mesh2tex.geometry.prepare import prepare_shape

    world, shapes = tmp_path / "world", tmp_path / "shapes"
    assert (
        main(
            [
                "prepare",
                "synthetic",
                "--out",
                str(world),
                "--shapes",
                "2",
                "--query-shapes",
                "1",
                "--views",
                "3",
                "--resolution",
                "32",
                "--texture-size",
                "64",
                "--seed",
                "3",
                "--query-views",
                "1",
            ]
        )
        == 0
    )
    shapes.mkdir()
    split = json.loads((world / "index.json").read_text())["split"]
    assert len(split["train_shapes"]) == 1
    for name in split["train_shapes"] + split["query_shapes"]:
        vertices, faces = load_mesh(world / "meshes" / f"{name}.obj")
        prepare_shape(vertices, faces, face_count=96, levels=3, seed=0).save(shapes / f"{name}.npz")
    (tmp_path / "tiny.yaml").write_text(yaml.safe_dump(TINY_GAN))
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
                str(tmp_path / "gan"),
                "--config",
                str(tmp_path / "tiny.yaml"),
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
    capsys.readouterr()
    assert (
        main(
            [
                "evaluate",
                "--generation",
                "--world",
                str(world),
                "--shapes",
                str(shapes),
                "--checkpoint",
                str(tmp_path / "gan" / "checkpoint.safetensors"),
                "--out",
                str(tmp_path / "ev"),
                "--latents",
                "2",
                "--repeats",
                "1",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "| photo set, across shapes (reference) | undefined (one training shape) |" in out
    assert json.loads((tmp_path / "ev" / "generation.json").read_text())["diversity"]["photo_set_spread"] is None
