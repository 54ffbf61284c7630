"""The object's mask of a photo without one: views placed over backdrops (the mask network's
training input), the network's loss, and GrabCut started from a probability map."""

import numpy as np
import pytest
import torch

from mesh2tex.nn.mask import MaskUNet, mask_iou, mask_loss
from mesh2tex.synthetic.backdrops import (
    BACKDROP_KINDS,
    backdrop,
    foot_shadow,
    place_over_backdrops,
    room,
    shaded_blob,
)
from mesh2tex.transfer.mask import refine_with_grabcut


def _framed_object(size: int = 48):
    """A red rectangle filling a framed view (the object), white around it: image [1,3,S,S] in [-1,1], mask."""
    image = torch.ones(1, 3, size, size)
    mask = torch.zeros(1, 1, size, size)
    mask[..., 6:42, 10:38] = 1
    image[:, :, 6:42, 10:38] = torch.tensor([0.8, -0.8, -0.8]).view(1, 3, 1, 1)
    return image, mask


def test_every_backdrop_kind_is_an_image_in_range():
    rng = np.random.default_rng(0)
    spreads = []
    for _ in range(40):
        image = backdrop(rng, 32)
        assert image.shape == (32, 32, 3) and image.dtype == np.float32
        assert 0.0 <= image.min() and image.max() <= 1.0
        spreads.append(float(image.std()))
    assert max(spreads) > 0.1, "busy backdrops occur"
    assert min(spreads) < 0.05, "and plain ones"
    assert "photo" in BACKDROP_KINDS and "clutter" in BACKDROP_KINDS


def test_placed_views_keep_the_object_under_their_mask():
    image, mask = _framed_object()
    images, masks = place_over_backdrops(image.repeat(6, 1, 1, 1), mask.repeat(6, 1, 1, 1), np.random.default_rng(1))
    assert images.shape == (6, 3, 48, 48) and masks.shape == (6, 1, 48, 48)
    assert images.min() >= -1 and images.max() <= 1
    covered = masks[:, 0] > 0.5
    assert covered.any(dim=(1, 2)).all(), "every view still shows the object"
    assert (covered.sum(dim=(1, 2)) <= mask.sum()).all(), "the object is shrunk or kept, never grown"
    red = (images[:, 0] > 0.2) & (images[:, 1] < -0.2)  # the object's colour, up to exposure and noise
    inside = (red & covered).sum() / covered.sum()
    assert inside > 0.8, "the mask sits on the object's pixels"
    again, _ = place_over_backdrops(image.repeat(6, 1, 1, 1), mask.repeat(6, 1, 1, 1), np.random.default_rng(1))
    assert torch.equal(images, again), "the same generator draws the same placements"


def test_rooms_are_drawn_only_when_asked_and_stand_the_object_on_a_floor():
    image, mask = _framed_object()
    views, masks = image.repeat(6, 1, 1, 1), mask.repeat(6, 1, 1, 1)
    plain, _ = place_over_backdrops(views, masks, np.random.default_rng(1))
    no_rooms, _ = place_over_backdrops(views, masks, np.random.default_rng(1), room_share=0.0)
    assert torch.equal(plain, no_rooms), "room_share 0 draws what the shipped mask networks learnt from"
    in_rooms, room_masks = place_over_backdrops(views, masks, np.random.default_rng(1), room_share=1.0)
    assert not torch.equal(in_rooms, plain)
    assert in_rooms.min() >= -1 and in_rooms.max() <= 1
    covered = room_masks[:, 0] > 0.5
    red = (in_rooms[:, 0] > 0.2) & (in_rooms[:, 1] < -0.2)
    assert (red & covered).sum() / covered.sum() > 0.8, "the mask sits on the object's pixels"
    rng = np.random.default_rng(5)
    for _ in range(10):
        scene, horizon = room(rng, 48)
        assert scene.shape == (48, 48, 3) and scene.dtype == np.float32
        assert 0.0 <= scene.min() and scene.max() <= 1.0
        assert 0 < horizon < 48, "wall above, floor below"


@pytest.mark.parametrize("share", ["camouflage_share", "distractor_share"])
def test_a_scene_option_at_zero_draws_what_was_drawn_before_it_existed(share):
    image, mask = _framed_object()
    views, masks = image.repeat(8, 1, 1, 1), mask.repeat(8, 1, 1, 1)
    plain, _ = place_over_backdrops(views, masks, np.random.default_rng(2), room_share=0.5)
    unasked, _ = place_over_backdrops(views, masks, np.random.default_rng(2), room_share=0.5, **{share: 0.0})
    assert torch.equal(plain, unasked)


def test_camouflaged_scenes_take_the_objects_colour():
    """camouflage_share 1: around the (red) object the scene is red too, so colour alone cannot cut it out."""
    image, mask = _framed_object()
    views, masks = image.repeat(8, 1, 1, 1), mask.repeat(8, 1, 1, 1)
    plain, plain_masks = place_over_backdrops(views, masks, np.random.default_rng(2), room_share=0.5)
    hidden, hidden_masks = place_over_backdrops(views, masks, np.random.default_rng(2), 0.5, camouflage_share=1.0)
    assert hidden.min() >= -1 and hidden.max() <= 1

    def red_around(images, placed):  # the share of the scene's pixels redder than they are green
        outside = placed[:, 0] < 0.5
        return float(((images[:, 0] > images[:, 1] + 0.3) & outside).sum() / outside.sum())

    assert red_around(hidden, hidden_masks) > 0.8 > 0.5 > red_around(plain, plain_masks)


def test_distractors_are_things_behind_the_object_never_in_its_mask():
    """distractor_share 1: every scene shows other things, never over the object and never in its mask."""
    image, mask = _framed_object()
    views, masks = image.repeat(6, 1, 1, 1), mask.repeat(6, 1, 1, 1)
    plain, _ = place_over_backdrops(views, masks, np.random.default_rng(3), room_share=0.5)
    busy, busy_masks = place_over_backdrops(views, masks, np.random.default_rng(3), 0.5, distractor_share=1.0)
    assert busy.min() >= -1 and busy.max() <= 1 and not torch.equal(busy, plain)
    covered = busy_masks[:, 0] > 0.5
    red = (busy[:, 0] > 0.2) & (busy[:, 1] < -0.2)
    assert (red & covered).sum() / covered.sum() > 0.8, "the object stays in front, under its mask"
    rng = np.random.default_rng(4)
    for _ in range(10):
        colours, cover = shaded_blob(rng, 64)
        assert colours.shape == (64, 64, 3) and cover.shape == (64, 64)
        assert 0 <= colours.min() and colours.max() <= 1 and 0 <= cover.min() and cover.max() <= 1
        assert (cover > 0.5).sum() > 8, "a thing of some size"


def test_the_foot_shadow_darkens_the_floor_under_the_object_only():
    alpha = torch.zeros(1, 1, 64, 64)
    alpha[..., 10:40, 20:44] = 1  # the object's foot is row 39
    factor = foot_shadow(alpha, 0.5)[0, 0]
    assert factor.shape == (64, 64) and factor.min() >= 0.5 and factor.max() <= 1.0
    assert factor[40, 32] < 0.9, "dark just under the foot"
    assert factor[5, 32] == 1.0 and factor[39, 2] > 0.99, "untouched above the object and far to its side"


def test_the_loss_prefers_the_true_mask_and_iou_reads_it():
    _, mask = _framed_object()
    right = mask * 20 - 10
    wrong = -right
    assert mask_loss(right, mask) < mask_loss(wrong, mask)
    assert mask_iou(right, mask) == 1.0 and mask_iou(wrong, mask) == 0.0
    assert MaskUNet(width=4)(torch.zeros(2, 3, 40, 24)).shape == (2, 1, 40, 24)


def test_grabcut_sharpens_a_blurred_probability_to_the_object():
    pytest.importorskip("cv2")
    import cv2

    rng = np.random.default_rng(2)
    size = 96
    rgb = (rng.uniform(0.3, 0.6, (size, size, 3)) * 255).astype(np.uint8)  # a busy grey backdrop
    truth = np.zeros((size, size), bool)
    cv2.circle(truth.view(np.uint8), (48, 48), 22, 1, -1)
    rgb[truth] = (200, 40, 40)
    probability = cv2.GaussianBlur(truth.astype(np.float32), (0, 0), 6)  # the right place, soft edges
    probability = cv2.dilate(probability, np.ones((9, 9), np.uint8))  # and too large
    refined = refine_with_grabcut(rgb, probability)
    thresholded = probability >= 0.5

    def iou(mask):
        return (mask & truth).sum() / (mask | truth).sum()

    assert iou(refined) > iou(thresholded) and iou(refined) > 0.9


def test_an_estimated_mask_gives_the_mesh_three_framings_to_pick_from(tmp_path):
    """Without a mask or alpha, the photo comes framed by each estimate (network with GrabCut edges,
    network, GrabCut); with an alpha channel, once. The pick takes the best outline, the first on ties."""
    from PIL import Image

    from mesh2tex.transfer import PoseEstimate, TransferConfig, photo_candidates, pick_by_outline

    rng = np.random.default_rng(3)
    rgb = (rng.uniform(0.2, 0.5, (96, 96, 3)) * 255).astype(np.uint8)
    rgb[20:80, 30:66] = (180, 60, 40)
    Image.fromarray(rgb).save(tmp_path / "photo.png")
    alpha = np.zeros((96, 96), np.uint8)
    alpha[20:80, 30:66] = 255
    Image.fromarray(np.dstack([rgb, alpha])).save(tmp_path / "alpha.png")
    cfg = TransferConfig(resolution=32)
    estimated = photo_candidates(tmp_path / "photo.png", None, cfg, mask_checkpoint="chair")
    assert [source for _, source in estimated] == [
        "estimated (mask network, GrabCut edges)",
        "estimated (mask network)",
        "estimated (GrabCut)",
    ][: len(estimated)] and len(estimated) >= 2
    assert all(photo.mask.shape == (1, 1, 32, 32) for photo, _ in estimated)
    given = photo_candidates(tmp_path / "alpha.png", None, cfg, mask_checkpoint="chair")
    assert [source for _, source in given] == ["alpha channel"]

    scores = iter([0.6, 0.9, 0.9])
    index, estimate = pick_by_outline(
        [p for p, _ in estimated] + [estimated[0][0]],
        lambda photo: PoseEstimate(0.0, 0.0, "test", silhouette_iou=next(scores, 0.1)),
    )
    assert index == 1 and estimate.silhouette_iou == 0.9


def test_the_meshs_outline_at_the_pose_mends_an_estimated_mask():
    """An estimated mask with a hole where the object is (a patch the estimate missed) is made again by
    GrabCut from the mesh's outline at the pose: the hole is filled, nothing of the background is taken,
    and the result says how it was made. A mask that came with the photo is kept as it is."""
    from test_faceconv import cube_shape

    from mesh2tex.render import orbit_camera, rasterize, transform_points
    from mesh2tex.transfer import MaskedPhoto, TransferConfig, locate_object

    shape = cube_shape(3)
    distance, fov, size = 2.4, 40.0, 128
    camera = orbit_camera(torch.tensor([30.0]), torch.tensor([20.0]), distance=distance, fov=fov)
    raster = rasterize(
        transform_points(torch.as_tensor(shape.vertices[0], dtype=torch.float32), camera.mvp),
        torch.as_tensor(shape.triangles(0)),
        (size, size),
    )
    truth = (raster.face_id[0] >= 0).numpy()
    rng = np.random.default_rng(0)
    rgb = (rng.uniform(0.3, 0.6, (size, size, 3)) * 255).astype(np.uint8)
    rgb[truth] = (200, 40, 30)
    rows, cols = np.nonzero(truth)
    r, c = int(rows.mean()), int(cols.mean())
    estimate = truth.copy()
    estimate[r - 8 : r + 8, c - 8 : c + 8] = False  # the estimate missed a patch in the middle of the object
    cfg = TransferConfig(resolution=32)

    def iou(mask):
        return float((mask & truth).sum() / (mask | truth).sum())

    located = locate_object(
        MaskedPhoto(rgb, [(estimate, "estimated (test)")], None, given=False),
        shape,
        None,
        (30.0, 20.0),
        distance,
        fov,
        cfg,
        torch.device("cpu"),
    )
    assert iou(located.mask) > 0.97 > iou(estimate), (iou(located.mask), iou(estimate))
    assert located.mask_source.endswith("refined by GrabCut on the mesh's outline at the pose")
    assert located.estimate.azimuth == 30.0 and located.photo.mask.shape == (1, 1, 32, 32)
    kept = locate_object(
        MaskedPhoto(rgb, [(estimate, "alpha channel")], None, given=True),
        shape,
        None,
        (30.0, 20.0),
        distance,
        fov,
        cfg,
        torch.device("cpu"),
    )
    assert np.array_equal(kept.mask, estimate) and kept.mask_source == "alpha channel"


class _RedNet(torch.nn.Module):
    """A stand-in mask network: the object is what is red (a pixel's own colour decides, at any scale)."""

    def forward(self, images):
        return 8.0 * (images[:, :1] - images[:, 1:2]) - 4.0


def _red_square(side: int, top: int, left: int, size: int) -> np.ndarray:
    rgb = np.full((side, side, 3), 90, np.uint8)
    rgb[top : top + size, left : left + size] = (230, 30, 30)
    return rgb


@pytest.fixture
def red_net(monkeypatch):
    """Installs the stand-in as every mask network, at the input side it is called with."""
    import types

    import mesh2tex.models

    def install(side: int) -> None:
        cfg = types.SimpleNamespace(data=types.SimpleNamespace(resolution=side))
        monkeypatch.setattr(mesh2tex.models, "load_view_network", lambda checkpoint, kind, device: (_RedNet(), cfg))

    return install


def test_the_flip_pass_reads_a_mirrored_photo_as_its_mirror():
    """With the flip pass the network's estimate does not depend on which way the photo faces."""
    from mesh2tex.transfer.mask import network_probability

    rng = np.random.default_rng(0)
    rgb = (rng.uniform(0, 1, (96, 96, 3)) * 255).astype(np.uint8)
    rgb[20:80, 10:50] = (180, 60, 40)
    probability = network_probability("chair", rgb, passes=("flip",))
    mirrored = network_probability("chair", np.ascontiguousarray(rgb[:, ::-1]), passes=("flip",))
    np.testing.assert_allclose(mirrored, probability[:, ::-1], atol=1e-5)
    with pytest.raises(ValueError, match="unknown passes"):
        network_probability("chair", rgb, passes=("blur",))


def test_the_zoom_pass_looks_again_at_a_small_object_and_only_there(red_net):
    """A small object in a large photo is seen again at the network's full side: its edges come out sharper,
    and nothing outside the zoomed square changes; an object that fills the photo, or whose square the network
    already saw at full detail, is left as it was."""
    from mesh2tex.transfer.mask import network_probability

    red_net(24)
    rgb = _red_square(320, 101, 57, 27)
    truth = np.zeros((320, 320), bool)
    truth[101:128, 57:84] = True
    once = network_probability("net", rgb, passes=())
    zoomed = network_probability("net", rgb, passes=("zoom",))

    def iou(p):
        return ((p >= 0.5) & truth).sum() / ((p >= 0.5) | truth).sum()

    assert iou(zoomed) > iou(once)
    assert np.abs(zoomed - once)[truth].max() > 0.01
    far = np.ones((320, 320), bool)
    far[80:150, 35:105] = False  # well outside the zoomed square
    np.testing.assert_array_equal(zoomed[far], once[far])
    filling = _red_square(96, 8, 8, 80)
    np.testing.assert_array_equal(
        network_probability("net", filling, passes=("zoom",)), network_probability("net", filling, passes=())
    )
    red_net(64)  # the object's square (about 32 px) is smaller than the network's side
    np.testing.assert_array_equal(
        network_probability("net", rgb, passes=("zoom",)), network_probability("net", rgb, passes=())
    )
