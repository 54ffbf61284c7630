"""The demo report's transfer table (``mesh2tex.infer.demo.transfer_metrics``): like with like, the oracle on top."""

from __future__ import annotations

import html
import json
import math
import shutil

import numpy as np
import pytest
from mesh2tex.infer.demo import transfer_metrics
from mesh2tex.infer.demo_report import TRANSFER_METHODS, transfer_section

from mesh2tex.cli import main
from mesh2tex.geometry.mesh_io import load_mesh
from mesh2tex.geometry.prepare import prepare_shape


@pytest.fixture(scope="module")
def scored(tmp_path_factory, tiny_gan):
    """A 3-chair world at 48 px and a fake transfer folder whose 'result' is the world's own ground
    truth GLB, scored by transfer_metrics (whose crops, 64 px, differ from the photos' size)."""
    root = tmp_path_factory.mktemp("demo_metrics")
    world = root / "world"
    assert (
        main(
            [
                "prepare",
                "synthetic",
                "--out",
                str(world),
                "--shapes",
                "3",
                "--views",
                "1",
                "--resolution",
                "48",
                "--texture-size",
                "128",
                "--seed",
                "4",
                "--query-views",
                "1",
            ]
        )
        == 0
    )
    index = json.loads((world / "index.json").read_text())
    query = json.loads((world / index["queries"][0]["sidecar"]).read_text())
    vertices, faces = load_mesh(world / "meshes" / f"{query['shape']}.obj")
    prepare_shape(vertices, faces, face_count=96, levels=3, seed=0).save(root / "shape.npz")
    transfer = root / "transfer"
    transfer.mkdir()
    shutil.copyfile(world / query["textured"], transfer / "textured.glb")
    report = {
        "checkpoint": str(tiny_gan / "run" / "checkpoint.safetensors"),
        "mesh": str(root / "shape.npz"),
        "settings": {"faces": 96, "seed": 0, "margin": 0.1},
        "pose": {k: query[k] for k in ("azimuth", "elevation", "distance", "fov")},
    }
    (transfer / "report.json").write_text(json.dumps(report))
    return transfer_metrics(world, transfer, query, 64), transfer


def test_every_method_is_scored_on_seen_and_unseen_views(scored):
    metrics, transfer = scored
    assert set(TRANSFER_METHODS) <= set(metrics)
    for name in TRANSFER_METHODS:
        for side in ("seen", "unseen"):
            for metric in ("part_delta_e", "lowpass_psnr", "swd", "psnr", "ssim"):
                assert math.isfinite(metrics[name][f"{side} {metric}"]), (name, side, metric)
    assert (transfer / "comparison_views.png").is_file() and (transfer / "render_at_true_pose.png").is_file()


def test_the_ground_truth_as_a_result_scores_as_the_oracle(scored):
    """The same function renders the oracle and the result: a result that is the ground truth ties it."""
    metrics, _ = scored
    assert metrics["transfer"] == metrics["oracle"]


def test_the_oracle_beats_every_baseline_and_the_photo_is_read_in_unit_range(scored):
    metrics, _ = scored
    oracle = metrics["oracle"]
    for name in ("flat_colour", "mean_texture", "backprojection"):
        for column, value in oracle.items():
            sign = -1 if column.endswith(("part_delta_e", "swd")) else 1
            assert (value - metrics[name][column]) * sign > 0, f"the oracle loses {column} to {name}"
    # The --quick bug: a photo left in 0-255 made the flat colour match a white photo exactly (PSNR inf).
    assert metrics["flat_colour"]["seen psnr"] < 40 and metrics["flat_colour"]["seen part_delta_e"] > 1
    assert metrics["backprojection"]["seen part_delta_e"] < metrics["flat_colour"]["seen part_delta_e"]


def test_the_report_says_which_way_is_better_on_every_column(scored):
    metrics, _ = scored
    section = transfer_section(metrics)
    headers = section.count("<th>") - 2  # minus the two "method" headers
    assert section.count("is better</small>") == headers == 10
    for title in TRANSFER_METHODS.values():
        assert html.escape(title) in section
    assert np.isfinite(metrics["transfer"]["seen psnr"])
