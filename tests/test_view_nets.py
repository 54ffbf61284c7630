"""`train pose` / `train noc`: they learn from rendered views, checkpoint without pickle, resume, and load back."""

import json

import numpy as np
import pytest
import torch
import trimesh

from mesh2tex.cli import main
from mesh2tex.errors import UserError
from mesh2tex.geometry.prepare import prepare_shape
from train.view_nets import ViewDataConfig, load_view_network, render_view_dataset


@pytest.fixture(scope="module")
def shapes_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("shapes")
    box = trimesh.creation.box((0.4, 0.8, 0.3))
    prepare_shape(box.vertices, box.faces, face_count=96, levels=2, seed=0, source="box").save(folder / "box.npz")
    return folder


def test_rendered_views_carry_consistent_ground_truth(shapes_dir):
    from mesh2tex.geometry.prepared import PreparedShape

    shape = PreparedShape.load(shapes_dir / "box.npz")
    cfg = ViewDataConfig(samples=6, views_per_material=3, resolution=32)
    views = render_view_dataset([shape], cfg, seed=1)
    assert views["rgb"].shape == (6, 32, 32, 3) and views["noc"].shape == (6, 32, 32, 3)
    covered = views["mask"] > 127
    assert covered.any(axis=(1, 2)).all(), "every view shows the object"
    assert (views["noc"][~covered] == 0).all(), "NOC is zero off the object"
    assert ((views["elevation"] >= cfg.elevation_min) & (views["elevation"] <= cfg.elevation_max)).all()
    again = render_view_dataset([shape], cfg, seed=1)
    assert np.array_equal(views["rgb"], again["rgb"]), "deterministic for a seed"


@pytest.mark.parametrize("kind", ["pose", "noc"])
def test_train_resume_and_load(kind, shapes_dir, tmp_path):
    run = tmp_path / kind
    config = tmp_path / "c.yaml"
    config.write_text("width: 8\nlog_every: 1\ndata:\n  views_per_material: 4\n")
    base = ["train", kind, "--shapes", str(shapes_dir), "--out", str(run), "--config", str(config),
            "--samples", "12", "--resolution", "32", "--batch", "4", "--device", "cpu"]
    assert main(base + ["--iters", "2"]) == 0
    assert main(base + ["--iters", "2"]) == 2, "a finished run is not overwritten without --resume"
    assert main(base + ["--iters", "4", "--resume"]) == 0
    records = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in records] == [1, 2, 3, 4]
    assert all(np.isfinite(r["loss"]) for r in records)
    net, cfg = load_view_network(run / "checkpoint.safetensors", kind)
    assert cfg.width == 8 and cfg.data.resolution == 32
    image = torch.zeros(1, 3, 32, 32)
    out = net(image) if kind == "pose" else net(image, torch.ones(1, 1, 32, 32))
    assert (out[0].shape == (1, 12)) if kind == "pose" else (out.shape == (1, 3, 32, 32))
    other = "noc" if kind == "pose" else "pose"
    with pytest.raises(UserError, match=f"expected a '{other}' checkpoint"):
        load_view_network(run / "checkpoint.safetensors", other)
