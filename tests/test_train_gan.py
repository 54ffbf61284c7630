"""``mesh2tex train gan`` on a tiny synthetic set: iterations, checkpoints, resume, NaN guard, DDP."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
import torch
import yaml
from gan_runs import TINY, make_tiny_data, metrics, train, train_args
from PIL import Image

from mesh2tex.cli import main
from mesh2tex.io.checkpoint import load_checkpoint


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory):
    return make_tiny_data(tmp_path_factory.mktemp("gan_data"))


def test_train_writes_config_checkpoint_metrics_samples(tiny_data, tmp_path):
    out = tmp_path / "run"
    assert train(tiny_data, out, "--iters", "3") == 0
    cfg = yaml.safe_load((out / "config.yaml").read_text())
    assert cfg["iters"] == 3 and cfg["generator"]["input_features"] == 4 and cfg["optim"]["lr_generator"] == 12e-4
    records = metrics(out)
    assert [r["iteration"] for r in records] == [1, 2, 3]
    for key in ("loss_g_field", "loss_g_proxy", "loss_d_field", "loss_d_proxy", "iters_per_second", "peak_memory_gb"):
        assert np.isfinite(records[-1][key]), key
    assert "r1_field" in records[0] and "pl_penalty" in records[0]  # lazy regularisers ran at iteration 0
    groups, meta = load_checkpoint(out / "checkpoint.safetensors", kind="gan")
    assert meta["iteration"] == 3
    assert {"generator", "generator_ema", "d_field", "d_proxy", "optim_g", "optim_d", "loss"} <= set(groups)
    assert list((out / "samples").glob("iter*.png"))
    # A second run into the same directory without --resume is refused.
    assert train(tiny_data, out, "--iters", "3") == 2


def test_lazy_terms_are_logged_with_their_last_value(tiny_data, tmp_path):
    """A lazy term (path length and R1 every 2 steps here) that never runs on a logged step still
    shows in metrics.jsonl, with the value of its last run."""
    config = tmp_path / "log2.yaml"
    config.write_text(yaml.safe_dump({**TINY, "log_every": 2, "loss": {**TINY["loss"], "diversity_interval": 2}}))
    out = tmp_path / "run"
    assert train(tiny_data, out, "--iters", "4", "--config", str(config)) == 0
    records = metrics(out)
    assert [r["iteration"] for r in records] == [2, 4]  # the steps logged are 1 and 3; the lazy terms ran at 0 and 2
    for key in ("pl_penalty", "r1_field", "mode_seeking"):
        assert all(key in r for r in records), key


def test_nca_generator_trains_resumes_and_generates(tiny_data, tmp_path):
    config = tmp_path / "nca.yaml"
    config.write_text(
        yaml.safe_dump(
            {
                **TINY,
                "generator": {
                    **TINY["generator"],
                    "kind": "nca",
                    "nca_channels": 6,
                    "nca_hidden": 16,
                    "nca_steps": 3,
                    "nca_condition": 4,
                },
            }
        )
    )
    full, part = tmp_path / "full", tmp_path / "part"
    assert train(tiny_data, full, "--iters", "3", "--config", str(config)) == 0
    assert train(tiny_data, part, "--iters", "2", "--config", str(config)) == 0
    assert train(tiny_data, part, "--iters", "3", "--resume") == 0
    ga, meta = load_checkpoint(full / "checkpoint.safetensors")
    gb, _ = load_checkpoint(part / "checkpoint.safetensors")
    assert meta["generator_config"]["kind"] == "nca"
    assert any(name.startswith("synthesis.nca.") for name in ga["generator_ema"])
    for name, tensor in ga["generator_ema"].items():
        torch.testing.assert_close(tensor, gb["generator_ema"][name], rtol=1e-5, atol=1e-6)
    out = tmp_path / "generated"
    assert (
        main(
            [
                "infer",
                "generate",
                "--checkpoint",
                str(full / "checkpoint.safetensors"),
                "--mesh",
                str(tiny_data / "shapes" / "cube0.npz"),
                "--out",
                str(out),
                "--seeds",
                "0,1",
                "--views",
                "1",
                "--resolution",
                "16",
                "--texture-size",
                "16",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    a, b = (np.asarray(Image.open(out / f"seed{s}_view0.png"), dtype=np.float64) for s in (0, 1))
    assert np.abs(a - b).mean() > 0.05


def test_nonfinite_loss_stops_with_a_clear_message(tiny_data, tmp_path, capsys):
    config = tmp_path / "bad.yaml"
    config.write_text(yaml.safe_dump({**TINY, "optim": {"lr_discriminator": 1e30, "lr_generator": 1e30}}))
    out = tmp_path / "bad"
    code = main(train_args(tiny_data, out, "--iters", "30", config=config))
    err = capsys.readouterr().err
    assert code == 4 and "non-finite loss" in err and "nonfinite.safetensors" in err
    assert (out / "nonfinite.safetensors").is_file()


def test_bad_inputs_are_user_errors(tiny_data, tmp_path, capsys):
    assert (
        main(
            [
                "train",
                "gan",
                "--shapes",
                str(tmp_path),
                "--images",
                str(tiny_data / "photos"),
                "--out",
                str(tmp_path / "r"),
            ]
        )
        == 2
    )
    assert "no prepared shapes" in capsys.readouterr().err
    assert train(tiny_data, tmp_path / "r2", "--resolution", "20") == 2
    assert "power of two" in capsys.readouterr().err


def test_two_process_data_parallel_run(tiny_data, tmp_path):
    out = tmp_path / "ddp"
    env = {**os.environ, "MESH2TEX_PROGRESS": "0", "OMP_NUM_THREADS": "1"}
    cmd = [
        sys.executable,
        "-m",
        "torch.distributed.run",
        "--standalone",
        "--nproc_per_node",
        "2",
        "-m",
        "mesh2tex",
        *train_args(tiny_data, out, "--iters", "2", batch=1),
    ]
    result = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=240)
    assert result.returncode == 0, result.stderr[-3000:]
    records = metrics(out)
    assert [r["iteration"] for r in records] == [1, 2] and records[-1]["world_size"] == 2
    assert records[-1]["torch_threads"] == 1, "OMP_NUM_THREADS=1: the run records the threads it summed with"
    _, meta = load_checkpoint(out / "checkpoint.safetensors")
    assert meta["world_size"] == 2 and len(meta["rng"]) == 2


def test_ema_follows_the_generator_from_the_start():
    """With the ramp-up the EMA of a short run is not its random initialisation: after the demo's
    600 steps of 8 images it keeps under 1 % of the initial weights (51 % without the ramp-up), and
    after the first step it equals the live generator."""
    from mesh2tex.runtime import ema_beta

    def initial_share(steps, rampup):
        share = 1.0
        for it in range(steps):
            share *= ema_beta(it * 8, 8, 5000.0, rampup)
        return share

    assert initial_share(600, 0.05) < 0.01
    assert initial_share(600, 0.0) == pytest.approx(0.5 ** (4800 / 5000), rel=1e-6)
    assert ema_beta(0, 8, 5000.0, 0.05) == 0.0
    assert ema_beta(10**7, 8, 5000.0, 0.05) == pytest.approx(0.5 ** (8 / 5000))


def test_after_one_step_the_ema_is_the_live_generator(tiny_data, tmp_path):
    out = tmp_path / "one"
    assert train(tiny_data, out, "--iters", "1") == 0
    groups, _ = load_checkpoint(out / "checkpoint.safetensors", kind="gan")
    for name, tensor in groups["generator"].items():
        torch.testing.assert_close(groups["generator_ema"][name], tensor)


def test_snapshots_keep_loadable_float16_generators(tiny_data, tmp_path):
    from mesh2tex.models import load_generator

    config = tmp_path / "snap.yaml"
    config.write_text(yaml.safe_dump({**TINY, "snapshot_every": 1}))
    out = tmp_path / "snap"
    assert main(train_args(tiny_data, out, "--iters", "2", config=config)) == 0
    snaps = sorted((out / "snapshots").glob("iter*.safetensors"))
    assert [p.name for p in snaps] == ["iter0000001.safetensors", "iter0000002.safetensors"]
    model = load_generator(snaps[-1], torch.device("cpu"))
    generator = model.network
    assert model.iteration == 2 and model.resolution == 16
    groups, _ = load_checkpoint(out / "checkpoint.safetensors", kind="gan")
    for name, tensor in generator.state_dict().items():
        torch.testing.assert_close(tensor, groups["generator_ema"][name].float(), rtol=2e-3, atol=2e-3)


def test_keep_snapshots_keeps_the_newest(tiny_data, tmp_path, capsys):
    config = tmp_path / "keep.yaml"
    config.write_text(yaml.safe_dump({**TINY, "snapshot_every": 1, "keep_snapshots": 2}))
    out = tmp_path / "keep"
    assert train(tiny_data, out, "--iters", "4", "--config", str(config)) == 0
    assert sorted(p.name for p in (out / "snapshots").iterdir()) == [
        "iter0000003.safetensors",
        "iter0000004.safetensors",
    ]
    config.write_text(yaml.safe_dump({**TINY, "keep_snapshots": -1}))
    capsys.readouterr()
    assert train(tiny_data, tmp_path / "bad", "--iters", "1", "--config", str(config)) == 2
    assert "keep_snapshots must be at least 0" in capsys.readouterr().err


def test_the_held_out_metric_keeps_the_best_generator(tiny_data, tmp_path, capsys):
    from mesh2tex.models import load_generator

    config = tmp_path / "metric.yaml"
    config.write_text(yaml.safe_dump({**TINY, "metric_every": 2, "metric_photos": 2}))
    out = tmp_path / "metric"
    assert train(tiny_data, out, "--iters", "4", "--config", str(config)) == 0
    measured = [r for r in metrics(out) if "metric_swd" in r]
    assert [r["iteration"] for r in measured] == [2, 4]
    assert all(
        np.isfinite(r["metric_swd"]) and r["metric_swd"] > 0 and np.isfinite(r["metric_diversity"]) for r in measured
    )
    best = min(measured, key=lambda r: r["metric_swd"])
    assert [r["best"] for r in measured] == [True, measured[1]["metric_swd"] < measured[0]["metric_swd"]]
    model = load_generator(out / "best.safetensors", torch.device("cpu"))
    meta = model.meta
    assert model.iteration == best["iteration"] and meta["metric"]["swd"] == best["metric_swd"]
    _, state = load_checkpoint(out / "checkpoint.safetensors", kind="gan")
    assert state["best"] == meta["metric"]
    # Holding out every photo leaves none to train on.
    config.write_text(yaml.safe_dump({**TINY, "metric_every": 2, "metric_photos": 6}))
    capsys.readouterr()
    assert train(tiny_data, tmp_path / "none", "--iters", "2", "--config", str(config)) == 2
    assert "metric_photos 6" in capsys.readouterr().err and not (tmp_path / "none").exists()


def test_the_path_length_phase_renders_the_first_half_of_the_batch(tiny_data, tmp_path, monkeypatch):
    """As StyleGAN2 does (``loss.pl_batch_shrink`` 2), the path-length phase renders half of the
    batch's shapes, each from its own views, with the rasterization of those shapes alone; the other
    phases render the whole batch."""
    import mesh2tex.losses.gan as gan
    from mesh2tex.losses.gan import GanLoss
    from mesh2tex.nn.render_texture import rasterize_batch

    phase_now, seen = [], []
    accumulate, render = GanLoss.accumulate_gradients, gan.render_field_views

    def recording_accumulate(self, phase, *args, **kwargs):
        phase_now[:] = [phase]
        return accumulate(self, phase, *args, **kwargs)

    def recording_render(generator, batch, ws, mvp, resolution, background, **kwargs):
        samples = kwargs.get("samples")
        expected = rasterize_batch(batch, mvp, resolution)
        assert torch.equal(samples.triangle_id, expected.triangle_id) and torch.equal(samples.bary, expected.bary)
        assert background.shape[0] == kwargs["lights"].direction.shape[0] == mvp.shape[0] == 2 * batch.num_shapes
        seen.append((phase_now[0], batch.num_shapes, ws.shape[0]))
        return render(generator, batch, ws, mvp, resolution, background, **kwargs)

    monkeypatch.setattr(GanLoss, "accumulate_gradients", recording_accumulate)
    monkeypatch.setattr(gan, "render_field_views", recording_render)
    assert train(tiny_data, tmp_path / "run", "--iters", "1", "--batch", "4") == 0
    assert sorted(set(seen)) == [("Dmain", 4, 4), ("Gmain", 4, 4), ("Greg", 2, 2)]


def test_supersampled_fakes_are_rendered_larger_and_box_filtered_to_the_photos_resolution(
    tiny_data, tmp_path, monkeypatch
):
    """``supersample: 2`` renders every training fake at twice the resolution and averages 2 x 2 blocks,
    as the photos were antialiased, so that the discriminators see fakes and photos of one size."""
    import mesh2tex.train.gan as trainer
    import torch.nn.functional as F

    import mesh2tex.losses.gan as gan
    from mesh2tex.losses.gan import GanLoss

    rendered, judged = [], []
    render, fakes = gan.render_field_views, GanLoss.fakes

    def recording_render(generator, batch, ws, mvp, resolution, background, **kwargs):
        out = render(generator, batch, ws, mvp, resolution, background, **kwargs)
        rendered.append(out.images.detach())
        return out

    def recording_fakes(self, *args, **kwargs):
        images, proxy, ws, encoded = fakes(self, *args, **kwargs)
        judged.append(images.detach())
        return images, proxy, ws, encoded

    monkeypatch.setattr(gan, "render_field_views", recording_render)
    monkeypatch.setattr(GanLoss, "fakes", recording_fakes)
    config = tmp_path / "ss.yaml"
    config.write_text(yaml.safe_dump({**TINY, "supersample": 2}))
    assert (
        main(
            [
                "train",
                "gan",
                "--shapes",
                str(tiny_data / "shapes"),
                "--images",
                str(tiny_data / "photos"),
                "--out",
                str(tmp_path / "run"),
                "--config",
                str(config),
                "--batch",
                "2",
                "--views",
                "2",
                "--resolution",
                "16",
                "--device",
                "cpu",
                "--iters",
                "1",
            ]
        )
        == 0
    )
    assert rendered and all(images.shape[-1] == 32 for images in rendered)
    assert len(judged) == len(rendered)
    for big, small in zip(rendered, judged):
        assert small.shape[-1] == 16 and torch.allclose(small, F.avg_pool2d(big, 2))
    with pytest.raises(ValueError, match="supersample"):
        trainer.TrainGanConfig(supersample=0)
