"""Where a transfer's learnt light starts: found from the photo's shading on the mesh at the pose."""

from __future__ import annotations

import math

import pytest
import torch
import trimesh

from mesh2tex.render import LightConfig, orbit_direction
from mesh2tex.transfer.light import LightStart, PhotoLight, search_light


@pytest.fixture(scope="module")
def ball():
    """A prepared ball: every normal the camera can see, each quad a flat piece."""
    from mesh2tex.geometry.prepare import prepare_shape

    sphere = trimesh.creation.icosphere(subdivisions=3)
    return prepare_shape(sphere.vertices, sphere.faces, face_count=600, levels=2, seed=0)


def photo_of(shape, camera: tuple[float, float], light: tuple[float, float, float], albedo, resolution: int = 128):
    """The shape rendered by the synthetic world's renderer (its own shading, not the search's) at ``camera``
    (azimuth, elevation), lit from ``light`` (azimuth offset from the camera, elevation, ambient), cropped as
    the transfer crops a photo; ``albedo(points) -> (P, 3)``. Returns (photo, view, batch, samples)."""
    from mesh2tex.evaluation.compare import render_for_comparison
    from mesh2tex.evaluation.surfaces import Surface
    from mesh2tex.nn.batch import collate_shapes
    from mesh2tex.nn.render_texture import rasterize_batch
    from mesh2tex.render import RenderSettings, crop_square
    from mesh2tex.synthetic.world import PhotoSetup
    from mesh2tex.transfer.config import TransferConfig
    from mesh2tex.transfer.photo import Photo, view_at_pose

    cfg = TransferConfig(resolution=resolution)
    view = view_at_pose(shape, camera[0], camera[1], 3.0, 40.0, cfg)
    direction = orbit_direction(torch.tensor([camera[0] + light[0]]), torch.tensor([light[1]]))[0]
    setup = PhotoSetup(camera[0], camera[1], 3.0, 40.0, tuple(direction.tolist()), light[2], "solid", 0)
    surface = Surface(shape.vertices[0], shape.triangles(0), albedo)
    render = render_for_comparison(surface, [setup], RenderSettings(view.render_size, 2))
    image = crop_square(render.rgb * 2 - 1, view.box, resolution)
    photo = Photo(image=image, mask=view.mask)
    batch = collate_shapes([shape])
    return photo, view, batch, rasterize_batch(batch, view.mvp, (view.render_size, view.render_size))


def light_angle(start: LightStart, offset: float, elevation: float) -> float:
    """Degrees between the found light and the true one, both relative to the same camera."""
    found = orbit_direction(torch.tensor([start.azimuth_offset]), torch.tensor([start.elevation]))[0]
    true = orbit_direction(torch.tensor([offset]), torch.tensor([elevation]))[0]
    return math.degrees(math.acos(float((found @ true).clamp(-1.0, 1.0))))


@pytest.mark.parametrize("light", [(-50.0, 40.0, 0.4), (30.0, 65.0, 0.5), (60.0, 25.0, 0.55)])
def test_the_search_finds_the_light_that_shaded_one_material(ball, light):
    grey = lambda p: torch.full((p.face.shape[0], 3), 0.7)  # noqa: E731
    photo, view, batch, samples = photo_of(ball, (40.0, 20.0), light, grey)
    start = search_light(photo, view, batch, samples)
    assert start.pairs >= 32
    assert light_angle(start, light[0], light[1]) < 10.0, start
    middle = LightStart.prior_middle()
    assert light_angle(start, light[0], light[1]) < light_angle(middle, light[0], light[1])


def test_a_second_material_does_not_move_the_light_far(ball):
    """Pixel pairs across a material's edge disagree with every light alike; the median keeps to the folds."""
    two = lambda p: torch.where((p.points[:, :1] > 0.0), torch.tensor([0.8, 0.2, 0.2]), torch.tensor([0.3, 0.6, 0.9]))  # noqa: E731
    photo, view, batch, samples = photo_of(ball, (40.0, 20.0), (-50.0, 40.0, 0.4), two)
    assert light_angle(search_light(photo, view, batch, samples), -50.0, 40.0) < 15.0


def test_a_photo_without_folds_keeps_the_prior_middle(ball):
    """At 16 px the ball shows too few pixel pairs across its folds to say where the light is."""
    grey = lambda p: torch.full((p.face.shape[0], 3), 0.7)  # noqa: E731
    photo, view, batch, samples = photo_of(ball, (40.0, 20.0), (-50.0, 40.0, 0.4), grey, resolution=16)
    assert search_light(photo, view, batch, samples) == LightStart.prior_middle()


def test_the_learnt_light_starts_where_it_is_told_and_turns_with_the_camera():
    prior = LightConfig()
    light = PhotoLight(camera_azimuth=120.0, prior=prior).lights()
    middle = 0.5 * (prior.elevation_min + prior.elevation_max)
    assert torch.allclose(light.direction, orbit_direction(torch.tensor([120.0]), torch.tensor([middle])), atol=1e-6)
    assert light.ambient.item() == pytest.approx(0.5 * (prior.ambient_min + prior.ambient_max))
    started = PhotoLight(camera_azimuth=120.0, start=LightStart(-30.0, 60.0, 0.4)).lights()
    assert torch.allclose(started.direction, orbit_direction(torch.tensor([90.0]), torch.tensor([60.0])), atol=1e-5)
    assert started.ambient.item() == pytest.approx(0.4)


def test_the_learnt_light_is_mirrored_with_the_camera():
    """Read across a mirror plane, the photo's light is where the plane reflects it."""
    from mesh2tex.geometry.symmetry import mirrored_azimuth

    light = PhotoLight(camera_azimuth=30.0)
    with torch.no_grad():
        light.azimuth_offset.fill_(0.35)  # radians: the light about 20 degrees off the camera
    for axis in (0, 2):
        direction = light.lights().direction[0]
        reflected = direction.clone()
        reflected[axis] *= -1.0
        mirrored = light.lights(mirrored_azimuth(30.0, axis)).direction[0]
        assert torch.allclose(mirrored.detach(), reflected.detach(), atol=1e-5)


def test_a_held_ambient_share_is_kept_and_the_direction_still_found(ball):
    """``transfer.light_ambient``: the search holds the ambient share given and looks for the direction only."""
    grey = lambda p: torch.full((p.face.shape[0], 3), 0.7)  # noqa: E731
    photo, view, batch, samples = photo_of(ball, (40.0, 20.0), (-50.0, 40.0, 0.4), grey)
    start = search_light(photo, view, batch, samples, ambient=0.45)
    assert start.ambient == 0.45
    assert light_angle(start, -50.0, 40.0) < 15.0, start


@pytest.mark.parametrize("ambient", [0.0, 1.0, 1.5])
def test_an_ambient_share_outside_its_range_is_refused(ambient):
    from mesh2tex.transfer.config import TransferConfig

    with pytest.raises(ValueError, match="light_ambient"):
        TransferConfig(light_ambient=ambient)
