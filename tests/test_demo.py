"""``mesh2tex demo --quick``: every stage runs end to end, the report links files that exist, a re-run resumes."""

import json
import re

import numpy as np
import pytest
import yaml
from mesh2tex.infer.demo import QUICK, DemoConfig

from mesh2tex.cli import main
from mesh2tex.config import load_config
from mesh2tex.errors import InputError
from mesh2tex.io.checkpoint import read_checkpoint_meta


def test_quick_demo_runs_every_stage_and_resumes(tmp_path):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--quick"]) == 0
    report = (out / "report.html").read_text()
    images = re.findall(r'src="([^"]+)"', report)
    assert len(images) >= 5 and all(src.startswith("data:image/") for src in images), (
        "every image is embedded: the report moves alone"
    )
    linked = re.findall(r'href="([^"]+)"', report)
    assert linked and all((out / path).is_file() for path in linked), "every file the report links exists"
    metrics = json.loads((out / "metrics.json").read_text())
    assert all(np.isfinite(v) for v in metrics["transfer"]["transfer"].values() if v != float("inf"))
    generation = metrics["generation"]
    assert set(generation["rows"]) == {
        "trained",
        "untrained",
        "oracle",
        "oracle_unlit",
        "ground_truth",
        "training_materials",
        "flat_colour",
        "mean_texture",
    }
    assert {"gap_closed", "diversity"} <= set(generation) and (out / "gan" / "generation_samples.png").is_file()
    stages = [json.loads(line)["stage"] for line in (out / "demo_log.jsonl").read_text().splitlines()]
    assert stages[:2] == ["prepare synthetic", "prepare shapes (train)"]
    iteration = read_checkpoint_meta(out / "gan" / "checkpoint.safetensors")["meta"]["iteration"]
    pose_views, noc_views = np.load(out / "pose" / "views.npz"), np.load(out / "noc" / "views.npz")
    assert str(noc_views["fingerprint"]) == str(pose_views["fingerprint"]), "the NOC run trains on the pose run's views"
    assert pose_views["gan_textured"].any(), "some training views are textured by the demo's GAN"
    nets = load_config(DemoConfig, None, QUICK).view_nets
    widths = {kind: yaml.safe_load((out / kind / "config.yaml").read_text())["width"] for kind in ("pose", "noc")}
    assert widths == {"pose": nets.width, "noc": nets.noc_width} and nets.width != nets.noc_width, (
        "each network its own width"
    )

    assert main(["demo", "--out", str(out), "--quick"]) == 0, "a second run resumes from what is there"
    assert read_checkpoint_meta(out / "gan" / "checkpoint.safetensors")["meta"]["iteration"] == iteration
    assert main(["demo", "--out", str(out)]) == 2, "a run with other settings does not mix into this folder"


def test_settings_recorded_before_they_were_nested_still_resume(tmp_path):
    """A demo folder records its settings (demo_config.yaml) and refuses other ones; a folder recorded
    with the flat names (gan_iters, view_samples, latent_iters ...) reads as the same nested settings."""
    from mesh2tex.infer.demo import saved_config

    flat = {
        "shapes": 4,
        "views": 2,
        "photo_resolution": 64,
        "faces": 96,
        "levels": 3,
        "workers": 1,
        "gan_iters": 2,
        "gan_resolution": 32,
        "gan_views": 1,
        "gan_channels": [8, 8, 8],
        "view_samples": 16,
        "view_resolution": 32,
        "view_width": 4,
        "pose_iters": 2,
        "noc_iters": 2,
        "latent_iters": 3,
        "refine_iters": 2,
        "texture_size": 64,
        "eval_views": 2,
        "eval_latents": 2,
        "tiny_networks": True,
        "transfer_resolution": 64,
        "texture_format": "png",
        "query": 0,
    }
    (tmp_path / "demo_config.yaml").write_text(yaml.safe_dump(flat))
    quick = load_config(DemoConfig, None, QUICK)
    assert saved_config(tmp_path / "demo_config.yaml") == quick
    (tmp_path / "demo_config.yaml").write_text(yaml.safe_dump({**flat, "gan_iters": 3}))
    assert saved_config(tmp_path / "demo_config.yaml") != quick
    # A hand-written --config of the flat layout is told where its keys went.
    (tmp_path / "flat.yaml").write_text(yaml.safe_dump({"view_width": 4, "gan_iters": 5, "seed": 1}))
    with pytest.raises(InputError, match=r"key\(s\) moved: gan_iters -> gan.iters, view_width -> view_nets.width$"):
        load_config(DemoConfig, tmp_path / "flat.yaml")


def test_demo_overwrite_removes_only_what_a_demo_wrote(tmp_path):
    from mesh2tex.infer.demo import DEMO_OUTPUTS

    from mesh2tex.io.outputs import remove_outputs

    for name in DEMO_OUTPUTS:
        path = tmp_path / name
        if "." in name:
            path.write_text("x")
        else:
            (path / "inner").mkdir(parents=True)
    (tmp_path / "my_notes.md").write_text("mine")
    remove_outputs(tmp_path, DEMO_OUTPUTS)
    assert [p.name for p in tmp_path.iterdir()] == ["my_notes.md"]
