"""``mesh2tex infer transfer``: a textured asset and a report from one photo; clear errors for bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from PIL import Image

from mesh2tex.cli import main

FAST = ["--resolution", "64", "--latent-iters", "6", "--refine-iters", "3", "--device", "cpu"]


@pytest.fixture(scope="module")
def setup(tiny_gan, tmp_path_factory):
    """The tiny GAN, NOC and pose networks (2 steps each) and a photo with an alpha mask."""
    root = tmp_path_factory.mktemp("transfer")
    (root / "gan").symlink_to(tiny_gan / "run")
    (root / "shapes").symlink_to(tiny_gan / "shapes")
    (root / "noc.yaml").write_text("width: 4\n")
    for kind in ("noc", "pose"):
        assert (
            main(
                [
                    "train",
                    kind,
                    "--shapes",
                    str(root / "shapes"),
                    "--out",
                    str(root / kind),
                    "--config",
                    str(root / "noc.yaml"),
                    "--iters",
                    "2",
                    "--samples",
                    "8",
                    "--resolution",
                    "32",
                    "--batch",
                    "4",
                    "--device",
                    "cpu",
                ]
            )
            == 0
        )
    # The query: a striped object on a transparent background (the alpha channel is its mask).
    photo = np.zeros((48, 48, 4), np.uint8)
    photo[10:40, 14:34, :3] = 40
    photo[10:40:4, 14:34, :3] = (220, 180, 30)
    photo[10:40, 14:34, 3] = 255
    Image.fromarray(photo).save(root / "query.png")
    return root


def transfer_args(root, out, *extra):
    return [
        "infer",
        "transfer",
        "--checkpoint",
        str(root / "gan" / "checkpoint.safetensors"),
        "--mesh",
        str(root / "shapes" / "box0.npz"),
        "--image",
        str(root / "query.png"),
        "--noc-checkpoint",
        str(root / "noc" / "checkpoint.safetensors"),
        "--pose",
        "30,20",
        "--out",
        str(out),
        *FAST,
        *extra,
    ]


def transfer_report(root, out, settings, *extra):
    """Run a transfer into ``out`` with ``settings`` (TransferConfig YAML) as --config; its report.json."""
    config = out.parent / f"{out.name}.yaml"
    config.write_text(settings)
    assert main(transfer_args(root, out, "--config", str(config), *extra)) == 0
    return json.loads((out / "report.json").read_text())


def test_transfer_writes_a_textured_asset_and_a_report(setup, tmp_path):
    out = tmp_path / "out"
    assert main(transfer_args(setup, out, "--texture-format", "jpeg", "--texture-size", "48")) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["pose"] == {
        "azimuth": 30.0,
        "elevation": 20.0,
        "source": "given",
        "distance": report["pose"]["distance"],
        "fov": report["pose"]["fov"],
    }
    assert report["mask_source"] == "alpha channel" and report["noc_guidance"] is True
    assert set(report["losses"]) == {"latent", "refine"}
    assert len(report["losses"]["latent"]["curve"]) == 6 and len(report["losses"]["refine"]["curve"]) == 3
    assert all(np.isfinite(report["losses"]["latent"]["curve"]))
    scene = trimesh.load(out / "textured.glb")
    mesh = next(iter(scene.geometry.values())) if isinstance(scene, trimesh.Scene) else scene
    assert mesh.visual.material.baseColorTexture.format == "JPEG" and report["settings"]["texture_format"] == "jpeg"
    assert mesh.visual.material.baseColorTexture.size == (48, 48)
    assert Image.open(out / "turntable.gif").n_frames == 12
    assert Image.open(out / "comparison.png").size == (4 * 64, 64)


def test_an_automaton_fitted_to_the_photo_writes_the_same_files(setup, tmp_path, capsys):
    """``--automaton``: a mesh automaton grown on the mesh and fitted to the photo replaces the GAN's texture; its
    loss falls, and the GLB's baked texture, the PLY's colours and the turntable come from its growth."""
    out = tmp_path / "auto"
    assert main(transfer_args(setup, out, "--automaton", "--automaton-iters", "12", "--texture-size", "48")) == 0
    report = json.loads((out / "report.json").read_text())
    curve = report["losses"]["automaton"]["curve"]
    assert set(report["losses"]) == {"automaton"} and len(curve) == 12 and all(np.isfinite(curve))
    assert min(curve[-3:]) < curve[0], "the fit lowers the photo's losses"
    assert report["method"].startswith("automaton") and report["light"] is None
    scene = trimesh.load(out / "textured.glb")
    mesh = next(iter(scene.geometry.values())) if isinstance(scene, trimesh.Scene) else scene
    assert mesh.visual.material.baseColorTexture.size == (48, 48)
    colours = trimesh.load(out / "textured.ply", process=False).visual.vertex_colors[:, :3].astype(float)
    assert colours.std(0).max() > 0, "the cells do not all take one colour"
    assert Image.open(out / "turntable.gif").n_frames == 12 and (out / "comparison.png").is_file()
    again = tmp_path / "again"  # seeded: the same run twice is the same fit
    assert main(transfer_args(setup, again, "--automaton", "--automaton-iters", "12", "--texture-size", "48")) == 0
    assert json.loads((again / "report.json").read_text())["losses"]["automaton"]["curve"] == curve
    assert main(transfer_args(setup, tmp_path / "bad", "--automaton", "--automaton-iters", "0")) == 2
    assert capsys.readouterr().err.strip().endswith("config.automaton: iters must be at least 1, got 0")


def test_pose_auto_searches_silhouettes_unless_told_not_to(setup, tmp_path):
    auto = [
        "--pose",
        "auto",
        "--pose-checkpoint",
        str(setup / "pose" / "checkpoint.safetensors"),
        "--no-refine",
        "--latent-iters",
        "1",
    ]
    assert main(transfer_args(setup, tmp_path / "search", *auto)) == 0
    pose = json.loads((tmp_path / "search" / "report.json").read_text())["pose"]
    assert pose["source"].startswith("pose network + silhouette search") and len(pose["network"]) == 2
    # a half turn the creases chose may trade up to pose_halfturn_tie of the silhouette's IoU
    tie = 0.05 if pose["turned"] else 0.0
    assert 0.0 <= pose["network_silhouette_iou"] <= pose["silhouette_iou"] + tie <= 1.0 + tie
    assert main(transfer_args(setup, tmp_path / "plain", *auto, "--no-pose-search")) == 0
    pose = json.loads((tmp_path / "plain" / "report.json").read_text())["pose"]
    assert pose["source"] == "pose network" and "network" not in pose
    assert pose["azimuth"] % 30 == 0  # a bin centre


def test_latent_stage_lowers_the_style_loss(setup, tmp_path):
    out = tmp_path / "out"
    assert main(transfer_args(setup, out, "--no-refine", "--latent-iters", "12")) == 0
    curve = json.loads((out / "report.json").read_text())["losses"]["latent"]["curve"]
    assert min(curve[-3:]) < curve[0]


def test_several_starts_begin_at_the_best_one(setup, tmp_path):
    """latent_starts: stage 1 begins at the start whose render scores lowest, so its first loss is at
    most the mean latent's (with latent_space w, one latent shared by every style input, as well)."""

    def first_loss(name, settings):
        report = transfer_report(setup, tmp_path / name, settings, "--no-refine", "--latent-iters", "2")
        return report["losses"]["latent"]["curve"][0], report["settings"]

    mean_start, _ = first_loss("mean", "latent_starts: 1\n")
    best_start, settings = first_loss("starts", "latent_starts: 4\nlatent_space: w\n")
    assert settings["latent_starts"] == 4 and settings["latent_space"] == "w"
    assert best_start <= mean_start + 1e-6


def test_ablation_flags_change_the_run(setup, tmp_path):
    out = tmp_path / "out"
    assert main(transfer_args(setup, out, "--no-noc", "--no-patches", "--no-refine")) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["noc_guidance"] is False and set(report["losses"]) == {"latent"}
    assert report["settings"]["use_patches"] is False and report["settings"]["refine"] is False


def test_bad_inputs_are_one_line_errors_and_nothing_is_overwritten(setup, tmp_path, capsys):
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"not an image")
    assert main(transfer_args(setup, tmp_path / "a", "--image", str(junk))) == 2
    assert "junk.png" in capsys.readouterr().err

    empty = tmp_path / "empty_mask.png"
    Image.fromarray(np.zeros((48, 48), np.uint8)).save(empty)
    assert main(transfer_args(setup, tmp_path / "b", "--mask", str(empty))) == 2
    assert "mask is empty" in capsys.readouterr().err

    wrong = transfer_args(setup, tmp_path / "c")
    wrong[wrong.index("--checkpoint") + 1] = str(setup / "noc" / "checkpoint.safetensors")
    assert main(wrong) == 2
    assert "expected a 'gan' checkpoint" in capsys.readouterr().err

    assert main(transfer_args(setup, tmp_path / "d", "--pose", "auto")) == 2
    assert "--pose-checkpoint" in capsys.readouterr().err

    out = tmp_path / "e"
    out.mkdir()
    (out / "report.json").write_text("{}")
    assert main(transfer_args(setup, out)) == 2
    assert (out / "report.json").read_text() == "{}"


def test_style_and_pose_search_settings_are_checked_before_any_work(setup, tmp_path, capsys):
    # The paper's 64 px patches at 3 scales (64, 32, 16 px), beside the default 32 px patches at 2.
    small = tmp_path / "small.yaml"
    small.write_text("patch_size: 64\npatch_scales: 3\n")
    out = tmp_path / "ok"
    assert main(transfer_args(setup, out, "--config", str(small), "--refine-iters", "1")) == 0
    settings = json.loads((out / "report.json").read_text())["settings"]
    assert (settings["patch_size"], settings["patch_scales"], settings["scales"]) == (64, 3, 3)
    # At 3 patch scales a 32 px patch would shrink to 8 px: refused before any work.
    small.write_text("patch_size: 32\npatch_scales: 3\n")
    assert main(transfer_args(setup, tmp_path / "bad", "--config", str(small))) == 2
    assert "patch_size 32" in capsys.readouterr().err
    small.write_text("pose_search_step: 0\n")
    assert main(transfer_args(setup, tmp_path / "bad", "--config", str(small))) == 2
    assert "pose_search_step 0" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()


def test_a_lit_generator_learns_the_photos_light_and_the_colour_loss_joins_both_stages(setup, tmp_path):
    report = transfer_report(setup, tmp_path / "out", "w_colour: 2.0\nlight_fixed: false\n")
    # The tiny GAN was trained under the light prior (the default), so 'auto' learns a light; not held, it moves.
    assert report["settings"]["light"] == "auto" and set(report["light"]) == {"azimuth_offset", "elevation", "ambient"}
    assert 0.0 < report["light"]["ambient"] < 1.0
    start = report["light_start"]
    assert set(start) == {"azimuth_offset", "elevation", "ambient", "pairs"}
    assert report["light"] != {k: start[k] for k in ("azimuth_offset", "elevation", "ambient")}, "the light moved"
    unlit = transfer_report(setup, tmp_path / "unlit", "w_colour: 2.0\nlight: 'off'\n")
    assert unlit["light"] is None and unlit["light_start"] is None


def test_by_default_the_light_stays_where_the_search_starts_it(setup, tmp_path):
    report = transfer_report(setup, tmp_path / "fixed", "seed: 0\n")
    assert report["settings"]["light_start"] == "search" and report["settings"]["light_fixed"] is True
    start = report["light_start"]
    assert report["light"] == pytest.approx({k: start[k] for k in ("azimuth_offset", "elevation", "ambient")}, abs=0.01)


def test_the_anchor_covers_only_surfaces_the_photo_does_not_show(tiny_gan):
    """unseen_anchors: at the photo's own pose nothing is left to anchor; around it, the surfaces the
    photo's view does not see are, and the albedo there is the current texture's."""
    import torch

    from mesh2tex.geometry.prepared import PreparedShape
    from mesh2tex.nn.batch import collate_shapes
    from mesh2tex.nn.render_texture import rasterize_batch
    from mesh2tex.transfer.config import TransferConfig
    from mesh2tex.transfer.optimise import unseen_anchors
    from mesh2tex.transfer.photo import view_at_pose

    shape = PreparedShape.load(tiny_gan / "shapes" / "box0.npz")
    cfg = TransferConfig(resolution=32, anchor_views=12, w_anchor=1.0)
    view = view_at_pose(shape, 30.0, 20.0, 2.5, 40.0, cfg)
    batch = collate_shapes([shape])
    samples = rasterize_batch(batch, view.mvp, (view.render_size, view.render_size))
    calls = []

    def albedo(ws, at, at_samples):
        calls.append(at.azimuth)
        return torch.full((1, 3, 32, 32), 0.5)

    anchors = unseen_anchors(shape, view, batch, [samples], cfg, torch.device("cpu"), albedo, lambda: None)
    azimuths = [round(at.azimuth % 360) for at, _, _, _ in anchors]
    assert 30 not in azimuths, "the photo's own view shows nothing the photo does not"
    assert 210 in azimuths and len(anchors) >= 6  # the far side is anchored
    assert all(float(mask.sum()) >= 16 and set(mask.unique().tolist()) <= {0.0, 1.0} for _, _, mask, _ in anchors)
    assert sorted(calls) == sorted(at.azimuth for at, _, _, _ in anchors)


def test_a_transfer_with_the_anchor_runs_both_stages(setup, tmp_path):
    report = transfer_report(setup, tmp_path / "out", "w_anchor: 5.0\nanchor_views: 3\n")
    assert report["settings"]["w_anchor"] == 5.0 and len(report["losses"]["refine"]["curve"]) == 3


def test_a_photo_without_a_mask_is_segmented_with_the_meshs_help_and_the_report_says_how(setup, tmp_path):
    """No mask file and no alpha: the mask is estimated (GrabCut without a mask network), then made again
    from the mesh's outline at the pose the search found; ``transfer.mask_refine: false`` keeps the estimate."""
    photo = np.array(Image.open(setup / "query.png"))
    rgb = np.where(photo[..., 3:] > 0, photo[..., :3], 150).astype(np.uint8)  # on grey, no alpha channel
    Image.fromarray(rgb).save(tmp_path / "query.jpg", quality=95)
    args = [
        "--image",
        str(tmp_path / "query.jpg"),
        "--pose",
        "auto",
        "--pose-checkpoint",
        str(setup / "pose" / "checkpoint.safetensors"),
    ]
    assert main(transfer_args(setup, tmp_path / "out", *args)) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["mask_source"] == "estimated (GrabCut); refined by GrabCut on the mesh's outline at the pose"
    assert report["pose"]["source"] == "pose network + silhouette search" and report["settings"]["mask_refine"] is True
    plain = transfer_report(setup, tmp_path / "plain", "mask_refine: false\n", *args)
    assert plain["mask_source"] == "estimated (GrabCut)"


def test_the_photo_flipped_is_what_the_mirrored_camera_sees_of_a_symmetric_mesh(tiny_gan):
    """mirror_query: on a mirror-symmetric mesh the mesh's own picture flipped left to right (its outline and
    its NOC, the NOC's mirrored coordinate turned to 1 - c) matches the view at the mirrored pose."""
    from mesh2tex.geometry.prepared import PreparedShape
    from mesh2tex.geometry.symmetry import mirror_axis
    from mesh2tex.transfer.config import TransferConfig
    from mesh2tex.transfer.photo import Photo, mirror_query, view_at_pose

    shape = PreparedShape.load(tiny_gan / "shapes" / "box0.npz")
    axis = mirror_axis(shape.vertices[0], shape.triangles(0))
    assert axis in (0, 2)
    cfg = TransferConfig(resolution=32)
    view = view_at_pose(shape, 30.0, 20.0, 2.5, 40.0, cfg)
    photo = Photo(image=view.noc.permute(2, 0, 1)[None] * 2 - 1, mask=view.mask)
    flipped, mirrored, noc = mirror_query(shape, photo, view, view.noc, axis, cfg)
    assert mirrored.azimuth == pytest.approx(330.0 if axis == 0 else 150.0)
    both = (flipped.mask > 0.5) & (mirrored.mask > 0.5)
    either = (flipped.mask > 0.5) | (mirrored.mask > 0.5)
    assert float(both.sum() / either.sum()) > 0.9
    inside = both[0, 0]
    assert float((noc[inside] - mirrored.noc[inside]).abs().mean()) < 0.03
    unmirrored = view.noc.flip(1)[inside]  # flipped without turning the coordinate: far off on that axis
    assert float((unmirrored[:, axis] - mirrored.noc[inside][:, axis]).abs().mean()) > 0.1


def test_a_symmetric_mesh_is_also_read_across_its_mirror_unless_told_not_to(setup, tmp_path):
    assert transfer_report(setup, tmp_path / "out", "")["mirror"] in ("x", "z")
    assert transfer_report(setup, tmp_path / "off", "w_mirror: 0\n")["mirror"] is None
