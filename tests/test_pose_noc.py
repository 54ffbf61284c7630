"""Pose and NOC networks: bins agree with the orbit camera, shapes, gradients, masked NOC loss."""

import pytest
import torch

from mesh2tex.nn.noc import NocUNet, noc_error, noc_loss
from mesh2tex.nn.pose import PoseBins, PoseNet, angle_to_bin, azimuth_error, bin_to_angle, pose_accuracy, pose_loss


def test_bin_centres_map_back_to_their_bins():
    bins = PoseBins()
    az_bins, el_bins = torch.arange(12), torch.arange(5)
    azimuth, _ = bin_to_angle(az_bins, torch.zeros(12, dtype=torch.long), bins)
    _, elevation = bin_to_angle(torch.zeros(5, dtype=torch.long), el_bins, bins)
    assert torch.equal(bins.azimuth_to_bin(azimuth), az_bins)
    assert torch.equal(bins.elevation_to_bin(elevation), el_bins)
    assert torch.allclose(azimuth, torch.arange(12) * 30.0)
    assert torch.allclose(elevation, torch.tensor([5.0, 15.0, 25.0, 35.0, 45.0]))


def test_bin_edges_wrap_and_clamp():
    az_bin, el_bin = angle_to_bin(
        torch.tensor([14.9, 15.0, -15.1, 359.0, 720.0 + 31.0]), torch.tensor([-30.0, 0.0, 9.99, 10.0, 89.0])
    )
    assert az_bin.tolist() == [0, 1, 11, 0, 1]
    assert el_bin.tolist() == [0, 0, 0, 1, 4]
    assert azimuth_error(torch.tensor([350.0]), torch.tensor([10.0])).item() == pytest.approx(20.0)


def test_azimuth_bins_follow_the_orbit_camera_convention():
    """Bin k's centre puts the camera at the azimuth angle_to_bin reads back from its position."""
    render = pytest.importorskip("mesh2tex.render")
    bins = PoseBins()
    azimuth, elevation = bin_to_angle(torch.arange(12), torch.full((12,), 2), bins)
    position = render.orbit_camera(azimuth, elevation, distance=2.0).position
    read_azimuth = torch.rad2deg(torch.atan2(position[:, 0], position[:, 2]))
    read_elevation = torch.rad2deg(torch.asin(position[:, 1] / position.norm(dim=1)))
    az_bin, el_bin = angle_to_bin(read_azimuth, read_elevation, bins)
    assert az_bin.tolist() == list(range(12))
    assert el_bin.tolist() == [2] * 12
    # azimuth 90 looks from +x
    assert position[3, 0] > 1.0 and abs(float(position[3, 2])) < 1e-4


def test_pose_net_shapes_gradients_and_learning():
    torch.manual_seed(0)
    net = PoseNet(width=8)
    images = torch.rand(4, 3, 64, 64) * 2 - 1
    azimuth = torch.tensor([0.0, 90.0, 180.0, 270.0])
    elevation = torch.tensor([5.0, 15.0, 25.0, 45.0])
    az_logits, el_logits = net(images)
    assert az_logits.shape == (4, 12) and el_logits.shape == (4, 5)
    loss = pose_loss(az_logits, el_logits, azimuth, elevation, net.bins)
    loss.backward()
    assert net.backbone.stem[0].weight.grad.abs().sum() > 0
    optimizer = torch.optim.Adam(net.parameters(), lr=1e-3)
    first = loss.item()
    for _ in range(15):
        optimizer.zero_grad()
        loss = pose_loss(*net(images), azimuth, elevation, net.bins)
        loss.backward()
        optimizer.step()
    assert loss.item() < 0.5 * first
    net.eval()
    prediction = net.predict(images)
    assert prediction["azimuth"].shape == (4,) and set(prediction) >= {"azimuth", "elevation", "azimuth_prob"}
    accuracy = pose_accuracy(*net(images), azimuth, elevation, net.bins)
    assert 0.0 <= accuracy["azimuth_accuracy"] <= 1.0


def test_paper_heads_at_full_width():
    net = PoseNet()
    assert net.backbone.out_features == 512
    assert [m.out_features for m in net.refine if isinstance(m, torch.nn.Linear)] == [256, 256]
    assert [m.out_features for m in net.azimuth_head if isinstance(m, torch.nn.Linear)] == [128, 12]
    assert [m.out_features for m in net.elevation_head if isinstance(m, torch.nn.Linear)] == [128, 5]


def test_noc_unet_shapes_range_and_gradients():
    torch.manual_seed(0)
    net = NocUNet(width=8, depth=3)
    images = torch.rand(2, 3, 50, 70) * 2 - 1
    masks = torch.zeros(2, 1, 50, 70)
    masks[:, :, 10:40, 20:60] = 1
    noc = net(images, masks)
    assert noc.shape == (2, 3, 50, 70)
    assert float(noc.detach().min()) >= 0.0 and float(noc.detach().max()) <= 1.0
    target = torch.rand(2, 3, 50, 70)
    loss = noc_loss(noc, target, masks)
    loss.backward()
    assert net.encoders[0][0].weight.grad.abs().sum() > 0
    assert noc_error(noc.detach(), target, masks) > 0


def test_noc_loss_ignores_background():
    target = torch.rand(1, 3, 16, 16)
    masks = torch.zeros(1, 1, 16, 16)
    masks[..., 4:12, 4:12] = 1
    predicted = target.clone()
    predicted[..., :4, :] = 0.0  # wrong only on the background
    assert float(noc_loss(predicted, target, masks)) == 0.0
    predicted[..., 6, 6] += 0.5  # wrong on the object
    assert float(noc_loss(predicted, target, masks)) == pytest.approx(1.5 / (3 * 64))


@pytest.fixture(scope="module")
def chair():
    """A procedural chair of the synthetic world, really prepared (384 quads): its silhouette changes with azimuth."""
    from mesh2tex.geometry.prepare import prepare_shape
    from mesh2tex.synthetic.world import WorldSpec, make_shape

    shape = make_shape(WorldSpec(), 0)
    return prepare_shape(shape.vertices, shape.faces, face_count=384, levels=2, seed=0)


def test_silhouette_search_finds_the_pose_the_network_gets_backwards(chair):
    from mesh2tex.transfer import Photo, PoseBeliefs, TransferConfig, search_pose, view_at_pose

    cfg = TransferConfig(resolution=64)
    # The "photo": the chair's silhouette from farther away than the search's camera (crops remove the scale).
    truth = view_at_pose(chair, 133.0, 22.0, 2.1, 40.0, cfg)
    photo = Photo(image=torch.zeros(1, 3, 64, 64), mask=truth.mask)
    bins = PoseBins()
    # A confident network that sees the chair from behind (azimuth bin 310 -> 300) at the right elevation.
    azimuth = torch.full((bins.azimuth_bins,), 0.01)
    azimuth[int(bins.azimuth_to_bin(310.0))] = 0.9
    elevation = torch.full((bins.elevation_bins,), 0.05)
    elevation[int(bins.elevation_to_bin(22.0))] = 0.8
    estimate = search_pose(chair, photo, PoseBeliefs(bins, azimuth, elevation), 1.7, 40.0, cfg)
    assert estimate.network == (300.0, 25.0)
    assert float(azimuth_error(estimate.azimuth, 133.0)) <= 5.0 and abs(estimate.elevation - 22.0) <= 5.0
    assert estimate.silhouette_iou > estimate.network_silhouette_iou + 0.2


def sure_network(azimuth_deg: float, elevation_deg: float):
    """The pose network's beliefs, 0.9 on the azimuth bin of ``azimuth_deg`` and 0.8 on the elevation bin."""
    from mesh2tex.transfer import PoseBeliefs

    bins = PoseBins()
    azimuth = torch.full((bins.azimuth_bins,), 0.01)
    azimuth[int(bins.azimuth_to_bin(azimuth_deg))] = 0.9
    elevation = torch.full((bins.elevation_bins,), 0.05)
    elevation[int(bins.elevation_to_bin(elevation_deg))] = 0.8
    return PoseBeliefs(bins, azimuth, elevation)


def test_where_silhouettes_nearly_tie_the_network_bin_decides_and_where_they_differ_the_silhouettes_do():
    """A long box with a small block on one end looks almost the same turned half round (as a car does):
    the search keeps to the network's confident bin when the best silhouette there is within
    ``pose_search_tie`` of the best anywhere, and follows the silhouettes when told to (a negative tie)."""
    import dataclasses

    import trimesh

    from mesh2tex.geometry.prepare import prepare_shape
    from mesh2tex.transfer import Photo, TransferConfig, search_pose, view_at_pose

    body = trimesh.creation.box((1.0, 0.3, 0.4))
    on_one_end = trimesh.transformations.translation_matrix((0.4, 0.2, 0))
    block = trimesh.creation.box((0.12, 0.12, 0.12), transform=on_one_end)
    mesh = trimesh.util.concatenate([body, block])
    shape = prepare_shape(mesh.vertices, mesh.faces, face_count=384, levels=2, seed=0)
    cfg = TransferConfig(resolution=64)
    photo = Photo(image=torch.zeros(1, 3, 64, 64), mask=view_at_pose(shape, 40.0, 20.0, 1.7, 40.0, cfg).mask)
    beliefs = sure_network(220.0, 20.0)  # sure of the half turn
    silhouettes = search_pose(shape, photo, beliefs, 1.7, 40.0, dataclasses.replace(cfg, pose_search_tie=-1.0))
    assert float(azimuth_error(silhouettes.azimuth, 40.0)) <= 10.0, "the block tells the ends apart, a little"
    kept = search_pose(shape, photo, beliefs, 1.7, 40.0, dataclasses.replace(cfg, pose_search_tie=0.2))
    assert float(azimuth_error(kept.azimuth, 220.0)) <= 15.0, "within the tie, the network's bin decides"
    assert kept.silhouette_iou >= silhouettes.silhouette_iou - 0.2


def test_where_the_outline_cannot_tell_the_ends_apart_the_creases_turn_the_pose_round():
    """A long box with a groove across its top near one end has nearly the same outline turned half round (as
    a car does) but its shading creases differ: a network sure of the half turn is overruled by the creases
    (``pose_halfturn_tie``), and is not where the check is off or the photo shows no shading."""
    import dataclasses

    import numpy as np
    import trimesh

    from mesh2tex.geometry.prepare import prepare_shape
    from mesh2tex.transfer import Photo, TransferConfig, normals_at_pose, search_pose

    box = trimesh.creation.box((1.0, 0.3, 0.4))
    vertices, faces = trimesh.remesh.subdivide_to_size(box.vertices, box.faces, max_edge=0.02)
    top = np.isclose(vertices[:, 1], 0.15)
    vertices[top, 1] -= 0.06 * np.clip(1 - np.abs(vertices[top, 0] - 0.25) / 0.12, 0, None)
    shape = prepare_shape(vertices, faces, face_count=384, levels=2, seed=0)
    cfg = TransferConfig(resolution=64, pose_search_tie=0.2)
    # The "photo": the mesh lit from above at azimuth 40, seen from farther than the search's camera.
    normals, mask = normals_at_pose(shape, 40.0, 20.0, 2.0, 40.0, cfg)
    light = torch.nn.functional.normalize(torch.tensor([0.3, 0.8, 0.5]), dim=0)
    shade = (normals * light[None, :, None, None]).sum(1, keepdim=True).clamp(min=0) * 0.8 + 0.2
    image = torch.where(mask > 0.5, shade * 2 - 1, torch.ones_like(shade)).expand(1, 3, 64, 64).contiguous()
    beliefs = sure_network(220.0, 20.0)  # sure of the half turn

    turned = search_pose(shape, Photo(image=image, mask=mask), beliefs, 1.7, 40.0, cfg)
    assert float(azimuth_error(turned.azimuth, 40.0)) <= 5.0 and turned.turned
    assert turned.creases[1] > turned.creases[0] + 0.1
    assert "turned half round" in turned.source
    unchecked = search_pose(
        shape, Photo(image=image, mask=mask), beliefs, 1.7, 40.0, dataclasses.replace(cfg, pose_halfturn_tie=-1.0)
    )
    assert float(azimuth_error(unchecked.azimuth, 220.0)) <= 5.0
    assert unchecked.creases is None and not unchecked.turned
    flat = search_pose(shape, Photo(image=torch.zeros_like(image), mask=mask), beliefs, 1.7, 40.0, cfg)
    assert float(azimuth_error(flat.azimuth, 220.0)) <= 5.0 and flat.creases == (0.0, 0.0) and not flat.turned
