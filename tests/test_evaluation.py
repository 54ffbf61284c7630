"""Judging quality on equal footing (``mesh2tex.evaluation``, ``mesh2tex.metrics.appearance``) on a tiny world."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from mesh2tex.cli import main
from mesh2tex.evaluation import (
    backproject_photo,
    common_mask,
    flat_surface,
    other_views,
    photo_mean_colour,
    render_for_comparison,
    score_views,
    seen_and_unseen,
    textured_surface,
)
from mesh2tex.evaluation.world import load_query_truth, reference_renders
from mesh2tex.metrics.appearance import lowpass_psnr, object_swd, part_colour_error


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """A 3-chair world at 64 px (1 held-out shape, 2 queries) and the truth of its first query."""
    root = tmp_path_factory.mktemp("evaluation") / "world"
    assert (
        main(
            [
                "prepare",
                "synthetic",
                "--out",
                str(root),
                "--shapes",
                "3",
                "--views",
                "1",
                "--resolution",
                "64",
                "--texture-size",
                "256",
                "--seed",
                "2",
                "--query-views",
                "2",
            ]
        )
        == 0
    )
    index = json.loads((root / "index.json").read_text())
    return root, index, load_query_truth(root, index, index["queries"][0])


def test_the_exact_material_rendered_for_comparison_is_the_photo(world):
    """One render function for every candidate: the world's own material through it reproduces the
    query photo (same camera, light, background, anti-aliasing), up to the photo's 8-bit rounding."""
    _, _, truth = world
    render = render_for_comparison(truth.truth.exact, [truth.view], truth.render_settings())
    assert float((render.rgb[0] - truth.photo[0]).abs().max()) <= 1.01 / 255
    assert torch.equal(render.mask[0], truth.photo_mask[0])
    assert set(render.parts[0][render.mask[0, 0] > 0].tolist()) == set(truth.truth.shape.face_parts.tolist()) & set(
        render.parts[0].unique().tolist()
    ), "every object pixel carries a part label"


def test_the_oracle_wins_every_metric_seen_and_unseen(world):
    _, _, truth = world
    views = [truth.view] + other_views(truth.view)
    reference = reference_renders(truth, views)
    shape = truth.truth.shape
    oracle = render_for_comparison(truth.truth.oracle, views, truth.render_settings())
    flat = render_for_comparison(
        flat_surface(shape.vertices, shape.faces, photo_mean_colour(truth.photo[0], truth.photo_mask[0])),
        views,
        truth.render_settings(),
    )
    # A plausible wrong texture: the ground truth's own texture image, upside down.
    from mesh2tex.io.assets import load_glb

    root, _, _ = world
    v, f, uv, tex = load_glb(root / "textured" / f"{truth.truth.name}.glb")
    flipped = render_for_comparison(textured_surface(v, f, uv, tex[::-1].copy()), views, truth.render_settings())
    mask = common_mask(reference.mask, oracle.mask)
    scores = {
        name: seen_and_unseen(score_views(r, reference.rgb, reference.parts, mask))
        for name, r in (("oracle", oracle), ("flat", flat), ("flipped", flipped))
    }
    assert len(scores["oracle"]) == 10, "five metrics, the photo's view and the unseen views apart"
    for column, value in scores["oracle"].items():
        sign = -1 if column.endswith(("part_delta_e", "swd")) else 1
        for other in ("flat", "flipped"):
            assert (value - scores[other][column]) * sign > 0, f"the oracle loses {column} to {other}"
    assert scores["oracle"]["seen part_delta_e"] < 2.3, (
        "the baked texture's part colours are the photo's (below one JND)"
    )


def test_back_projection_at_the_true_pose_reproduces_the_photo_on_visible_parts(world):
    _, _, truth = world
    shape = truth.truth.shape
    v = truth.view
    surface = backproject_photo(
        shape.vertices,
        shape.faces,
        truth.photo[0],
        truth.photo_mask[0, 0],
        v.azimuth,
        v.elevation,
        v.distance,
        v.fov,
        align="photo",
        face_parts=shape.face_parts,
    )
    # Unlit, the back-projected colours are the photo's pixels again.
    render = render_for_comparison(surface, [v], truth.render_settings("albedo"))
    mask = common_mask(render.mask, truth.photo_mask)
    delta_e = float(part_colour_error(render.rgb, truth.photo, render.parts, mask)[0])
    assert delta_e < 1.5, f"per-part colour error {delta_e:.2f} of the photo against itself"
    assert float(lowpass_psnr(render.rgb, truth.photo, mask)[0]) > 30
    # Every point gets a colour, also where the photo does not see (the nearest seen point's).
    back = render_for_comparison(surface, other_views(v, [180.0]), truth.render_settings("albedo"))
    assert back.mask.sum() > 0 and torch.isfinite(back.rgb).all()


def test_silhouette_framing_matches_photo_framing_at_the_true_pose(world):
    """With an estimated pose the photo and the mesh are framed by their own silhouettes; at the true
    pose that gives (nearly) the same colours as the photo's own frame."""
    _, _, truth = world
    shape, v = truth.truth.shape, truth.view
    args = (
        shape.vertices,
        shape.faces,
        truth.photo[0],
        truth.photo_mask[0, 0],
        v.azimuth,
        v.elevation,
        v.distance,
        v.fov,
    )
    a = render_for_comparison(
        backproject_photo(*args, align="photo", face_parts=shape.face_parts), [v], truth.render_settings("albedo")
    )
    b = render_for_comparison(backproject_photo(*args, align="silhouette"), [v], truth.render_settings("albedo"))
    mask = common_mask(a.mask, b.mask)
    assert float(part_colour_error(b.rgb, a.rgb, a.parts, mask)[0]) < 2.0


def test_part_colour_error_ignores_texture_phase_and_sees_wrong_colours():
    torch.manual_seed(0)
    parts = torch.zeros(1, 16, 16, dtype=torch.int64)
    parts[:, 8:] = 1
    image = torch.rand(1, 3, 16, 16)
    mask = torch.ones(1, 1, 16, 16)
    assert float(part_colour_error(image, image, parts, mask)[0]) == 0
    shuffled = image.clone()
    for label in (0, 1):  # the same colours moved around inside each part: the same per-part means
        where = (parts[0] == label).reshape(-1)
        flat = shuffled.reshape(3, -1)
        index = where.nonzero().squeeze(1)
        flat[:, index] = flat[:, index[torch.randperm(index.numel())]]
    assert float(part_colour_error(shuffled, image, parts, mask)[0]) < 1e-6
    redder = image.clone()
    redder[:, 0, 8:] = (redder[:, 0, 8:] + 0.3).clamp(0, 1)
    assert float(part_colour_error(redder, image, parts, mask)[0]) > 5
    # Another geometry: parts matched by label, each image on its own mask.
    other_parts = torch.roll(parts, 3, dims=1)
    value = part_colour_error(image, image, other_parts, mask, parts, mask)
    assert math.isfinite(float(value[0]))
    assert math.isnan(float(part_colour_error(image, image, parts + 5, mask, parts, mask)[0])), "no shared part: NaN"


def test_lowpass_psnr_rewards_right_colours_not_texture_phase():
    x = torch.arange(96).float()
    stripes = ((x // 2) % 2).expand(96, 96)  # 4 px period
    image = torch.stack([stripes, 0.5 * stripes, 1 - stripes])[None]
    shifted = torch.roll(image, 2, dims=3)  # half a period: every pixel wrong, every colour right
    mask = torch.zeros(1, 1, 96, 96)
    mask[..., 8:88, 8:88] = 1
    from mesh2tex.metrics import masked_psnr

    assert float(masked_psnr(shifted, image, mask)[0]) < 5
    assert float(lowpass_psnr(shifted, image, mask, sigma=3.0)[0]) > 25
    assert float(lowpass_psnr((image + 0.2).clamp(0, 1), image, mask, sigma=3.0)[0]) < 18, "a colour shift still counts"
    other_background = image.clone()
    other_background[..., :8, :] = 0.0
    assert float(lowpass_psnr(other_background, image, mask, sigma=3.0)[0]) == float("inf"), (
        "the background never bleeds in"
    )


def test_object_swd_looks_at_object_patches_only():
    torch.manual_seed(1)
    mask = torch.zeros(1, 1, 64, 64)
    mask[..., 16:48, 16:48] = 1
    noise = torch.rand(1, 3, 64, 64)
    same_texture = torch.rand(1, 3, 64, 64)  # another draw of the same noise
    flat = torch.full((1, 3, 64, 64), 0.5)
    base = float(object_swd(same_texture, noise, mask)[0])
    assert base < float(object_swd(flat, noise, mask)[0])
    elsewhere = same_texture.clone()
    elsewhere[..., :8, :] = 1.0  # off the object
    assert abs(float(object_swd(elsewhere, noise, mask)[0]) - base) < 1e-9


def test_unseen_views_turn_the_light_with_the_camera(world):
    _, _, truth = world
    v = truth.view
    views = other_views(v)
    assert [round(w.azimuth - v.azimuth) % 360 for w in views] == [72, 144, 216, 288]

    def towards_camera(view):
        az, el = math.radians(view.azimuth), math.radians(view.elevation)
        return np.array([math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az)])

    for w in views:
        assert abs(np.dot(w.light, towards_camera(w)) - np.dot(v.light, towards_camera(v))) < 1e-5
        assert (w.elevation, w.distance, w.ambient, w.background, w.background_seed) == (
            v.elevation,
            v.distance,
            v.ambient,
            v.background,
            v.background_seed,
        )


def test_glb_round_trip_keeps_face_order_and_texture(tmp_path):
    from mesh2tex.io.assets import load_glb, save_glb

    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    uv = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], np.float32)
    texture = (np.arange(4 * 4 * 3) % 256).astype(np.uint8).reshape(4, 4, 3)
    save_glb(tmp_path / "a.glb", vertices, faces, uv, texture)
    v, f, u, t = load_glb(tmp_path / "a.glb")
    assert np.allclose(v[f], vertices[faces]) and np.allclose(u[f], uv[faces], atol=1e-6) and np.array_equal(t, texture)
    (tmp_path / "bad.glb").write_bytes(b"not a glb")
    with pytest.raises(ValueError, match="bad.glb"):
        load_glb(tmp_path / "bad.glb")


def test_a_generator_texture_is_judged_as_the_generator_paints_it(tiny_gan):
    """The surface the protocols score for a GAN texture (a transfer, the mean texture) has the colours
    the generator's own renderer paints: psi's output and the per-face colours it is added to."""
    from mesh2tex.evaluation import generator_surface
    from mesh2tex.evaluation.surfaces import SurfacePoints
    from mesh2tex.geometry.prepared import PreparedShape
    from mesh2tex.models import load_generator
    from mesh2tex.nn.batch import collate_shapes
    from mesh2tex.nn.render_texture import rasterize_batch, render_field_views
    from mesh2tex.render import orbit_camera

    generator = load_generator(tiny_gan / "run" / "checkpoint.safetensors", torch.device("cpu")).network
    batch = collate_shapes([PreparedShape.load(tiny_gan / "shapes" / "box0.npz")])
    torch.manual_seed(0)
    texture = generator.synthesize(batch, generator.mapping(torch.randn(1, generator.cfg.z_dim)), noise_mode="none")
    texture.face_rgb += torch.linspace(-0.5, 0.5, texture.face_rgb.shape[0])[:, None]  # per-face colours that matter
    mvp = orbit_camera(torch.tensor([30.0]), torch.tensor([20.0]), distance=2.5).mvp
    painted = render_field_views(
        generator, batch, None, mvp, (32, 32), torch.ones(1, 3), texture=texture, noise_mode="none"
    )
    samples = rasterize_batch(batch, mvp, (32, 32))
    covered = samples.mask.reshape(-1)
    points = SurfacePoints(
        face=samples.triangle_id.reshape(-1)[covered],
        bary=samples.bary.reshape(-1, 3)[covered],
        points=torch.zeros(int(covered.sum()), 3),
        normals=torch.zeros(int(covered.sum()), 3),
    )
    judged = generator_surface(generator, texture, batch).colour(points)  # [P, 3] in [0, 1]
    expected = ((painted.images.permute(0, 2, 3, 1).reshape(-1, 3)[covered] + 1) * 0.5).clamp(0, 1)
    assert covered.sum() > 50
    assert torch.allclose(judged, expected.float(), atol=1e-5)
