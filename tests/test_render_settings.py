"""A render's settings are one checked record: bad values are refused where the record is made, and
every renderer that takes one renders what it says."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from mesh2tex.render import RenderSettings


@pytest.mark.parametrize(
    "fields, named",
    [
        ({"resolution": 0}, "resolution"),
        ({"resolution": 64.0}, "resolution"),
        ({"resolution": True}, "resolution"),
        ({"resolution": 64, "supersample": 0}, "supersample"),
        ({"resolution": 64, "supersample": 9}, "supersample"),
        ({"resolution": 4096, "supersample": 4}, "rasterizes 16384 px"),
        ({"resolution": 64, "lighting": "lit"}, "lighting"),
    ],
)
def test_bad_settings_are_refused_when_made_naming_the_field(fields, named):
    with pytest.raises(ValueError, match=named):
        RenderSettings(**fields)


def test_the_box_filter_averages_each_block_in_either_layout():
    settings = RenderSettings(4, supersample=2)
    assert settings.raster_side == 8
    images = torch.arange(2 * 3 * 8 * 8, dtype=torch.float32).reshape(2, 3, 8, 8)
    blocks = images.reshape(2, 3, 4, 2, 4, 2).mean((3, 5))
    torch.testing.assert_close(settings.down(images), blocks)
    torch.testing.assert_close(settings.down_channels_last(images.permute(0, 2, 3, 1)), blocks.permute(0, 2, 3, 1))
    assert RenderSettings(8).down(images) is images, "one sample per pixel: nothing to filter"


def test_unlit_world_renders_are_the_albedo_the_world_would_photograph_under_full_ambient_light():
    from mesh2tex.synthetic.materials import Material, Solid
    from mesh2tex.synthetic.shapes import generate_shape
    from mesh2tex.synthetic.world import WorldSpec, render_views, sample_views

    shape = generate_shape("chair", np.random.default_rng([3, 0]))
    views = sample_views(WorldSpec(), 0, 2)
    material = Material(default=Solid((0.8, 0.4, 0.2)))
    unlit = render_views(shape, material, views, RenderSettings(24, 2, "albedo"))
    full_ambient = render_views(shape, material, [replace(v, ambient=1.0) for v in views], RenderSettings(24, 2))
    lit = render_views(shape, material, views, RenderSettings(24, 2))
    for key in ("rgb", "mask", "noc"):
        assert np.array_equal(unlit[key], full_ambient[key])
    assert not np.array_equal(unlit["rgb"], lit["rgb"]), "the lit render is shaded"


def test_a_world_and_a_training_config_make_their_settings_from_their_own_fields():
    from mesh2tex.train.gan_config import TrainGanConfig

    from mesh2tex.synthetic.world import WorldSpec

    assert WorldSpec(resolution=96, supersample=3).photo_render == RenderSettings(96, 3, "photo")
    with pytest.raises(ValueError, match="supersample"):
        WorldSpec(supersample=0)
    config = TrainGanConfig(resolution=64, supersample=2)
    assert config.render_settings.raster_side == 128
    assert config.render_settings.lit == config.lighting.enabled
