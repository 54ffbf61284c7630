"""``mesh2tex train gan`` on a tiny synthetic set: iterations, checkpoints, resume, NaN guard, DDP."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from conftest import TINY_GAN
from PIL import Image
from test_faceconv import cube_shape

from mesh2tex.cli import main
from mesh2tex.io.checkpoint import load_checkpoint, read_checkpoint_meta

TINY = {
    **TINY_GAN,
    "log_every": 1,
    "checkpoint_every": 2,
    "sample_shapes": 2,
    "loss": {"r1_interval": 2, "pl_interval": 2},
    "camera": {"distance": 1.6},
}


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory):
    root = tmp_path_factory.mktemp("gan_data")
    shapes = root / "shapes"
    shapes.mkdir()
    for i in range(3):
        cube_shape(3, seed=i).save(shapes / f"cube{i}.npz")
    rng = np.random.default_rng(0)
    (root / "photos" / "images").mkdir(parents=True)
    (root / "photos" / "masks").mkdir()
    for i in range(6):
        img = np.zeros((24, 24, 3), np.uint8) + rng.integers(0, 255, 3, dtype=np.uint8)
        mask = np.zeros((24, 24), np.uint8)
        mask[5:19, 6:18] = 255
        Image.fromarray(img).save(root / "photos" / "images" / f"{i:03d}.png")
        Image.fromarray(mask).save(root / "photos" / "masks" / f"{i:03d}.png")
    config = root / "tiny.yaml"
    config.write_text(yaml.safe_dump(TINY))
    return root


def train(data, out, *extra):
    args = ["train", "gan", "--shapes", str(data / "shapes"), "--images", str(data / "photos"), "--out", str(out),
            "--config", str(data / "tiny.yaml"), "--batch", "2", "--views", "2", "--resolution", "16", "--device", "cpu", *extra]
    return main(args)


def metrics(out):
    return [json.loads(line) for line in (Path(out) / "metrics.jsonl").read_text().splitlines()]


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


def test_resume_reproduces_the_uninterrupted_run(tiny_data, tmp_path):
    full, part = tmp_path / "full", tmp_path / "part"
    assert train(tiny_data, full, "--iters", "4") == 0
    assert train(tiny_data, part, "--iters", "2") == 0
    assert train(tiny_data, part, "--iters", "4", "--resume") == 0
    a, b = metrics(full), metrics(part)
    assert [r["iteration"] for r in b] == [1, 2, 3, 4]
    for ra, rb in zip(a, b):
        for key in ra:
            if key.startswith(("loss_", "r1_", "pl_")):
                assert ra[key] == pytest.approx(rb[key], rel=1e-5, abs=1e-6), (ra["iteration"], key)
    ga, _ = load_checkpoint(full / "checkpoint.safetensors")
    gb, _ = load_checkpoint(part / "checkpoint.safetensors")
    for name, tensor in ga["generator_ema"].items():
        torch.testing.assert_close(tensor, gb["generator_ema"][name], rtol=1e-5, atol=1e-6)


def test_a_late_diversity_term_is_the_run_without_it_resumed_with_it(tiny_data, tmp_path):
    """``loss.diversity_start: S`` in one run gives the two-run recipe the shipped chair was trained by:
    S iterations without the term, then a run resumed from that checkpoint with it."""
    def config(name, loss):
        path = tmp_path / name
        path.write_text(yaml.safe_dump({**TINY, "loss": {**TINY["loss"], **loss}}))
        return str(path)

    late = config("late.yaml", {"diversity_weight": 1.0, "diversity_target": 10.0, "diversity_start": 2})
    without = config("without.yaml", {"diversity_weight": 0.0})
    with_term = config("with.yaml", {"diversity_weight": 1.0, "diversity_target": 10.0})
    one, first, second = tmp_path / "one", tmp_path / "first", tmp_path / "second"
    assert train(tiny_data, one, "--iters", "4", "--config", late) == 0
    assert train(tiny_data, first, "--iters", "2", "--config", without) == 0
    assert train(tiny_data, second, "--iters", "4", "--config", with_term, "--resume", str(first / "checkpoint.safetensors")) == 0
    a, b = metrics(one), metrics(second)
    assert [r["iteration"] for r in b] == [3, 4] and [r["iteration"] for r in a] == [1, 2, 3, 4]
    assert "mode_seeking" not in a[1] and "mode_seeking" in a[2]
    for ra, rb in zip(a[2:], b):
        for key in rb:
            if key.startswith(("loss_", "r1_", "pl_", "mode_seeking")):
                assert ra[key] == pytest.approx(rb[key], rel=1e-5, abs=1e-6), (ra["iteration"], key)
    ga, _ = load_checkpoint(one / "checkpoint.safetensors")
    gb, _ = load_checkpoint(second / "checkpoint.safetensors")
    for name, tensor in ga["generator_ema"].items():
        torch.testing.assert_close(tensor, gb["generator_ema"][name], rtol=1e-5, atol=1e-6)


def test_resume_applies_the_run_configs_learning_rates(tiny_data, tmp_path, capsys):
    """The NaN message's advice (lower the rates in RUN/config.yaml, --resume) works: the resumed
    optimizers use the config's rates, not the checkpoint's, and say so; a torn last metrics line is dropped."""
    out = tmp_path / "run"
    assert train(tiny_data, out, "--iters", "2") == 0
    cfg = yaml.safe_load((out / "config.yaml").read_text())
    cfg["optim"]["lr_generator"] = 6e-4
    cfg["optim"]["lr_discriminator"] = "7e-4"  # YAML 1.1 reads this as a string: a number all the same
    (out / "config.yaml").write_text(yaml.safe_dump(cfg))
    with open(out / "metrics.jsonl", "a") as handle:
        handle.write('{"iteration": 3, "loss_g')  # a kill while a line was written
    capsys.readouterr()
    assert train(tiny_data, out, "--iters", "3", "--resume") == 0
    assert "g[1] 0.0012 -> 0.0006" in capsys.readouterr().err
    _, meta = load_checkpoint(out / "checkpoint.safetensors")
    assert [g["lr"] for g in meta["optimizers"]["g"]["param_groups"]] == [1e-4, 6e-4, 1e-4]
    assert [g["lr"] for g in meta["optimizers"]["d"]["param_groups"]] == [7e-4]
    assert [r["iteration"] for r in metrics(out)] == [1, 2, 3]


def test_annealed_learning_rates_fall_linearly_and_survive_a_resume(tiny_data, tmp_path, capsys):
    """``optim.lr_decay_*``: every rate is the config's up to lr_decay_start, then falls linearly to
    lr_decay_to times it over lr_decay_iters steps and stays there; a run interrupted during the fall
    and resumed is the uninterrupted run, and the resume does not report the annealed rates as changed."""
    from mesh2tex.train.gan_config import OptimConfig
    optim = OptimConfig(lr_decay_start=10, lr_decay_iters=4, lr_decay_to=0.5)
    assert [optim.lr_scale(i) for i in (0, 10, 11, 12, 14, 100)] == [1.0, 1.0, 0.875, 0.75, 0.5, 0.5]
    assert OptimConfig().lr_scale(10 ** 6) == 1.0  # off by default
    with pytest.raises(ValueError, match="lr_decay_to"):
        OptimConfig(lr_decay_start=1, lr_decay_to=1.5)
    config = tmp_path / "anneal.yaml"
    config.write_text(yaml.safe_dump({**TINY, "optim": {"lr_decay_start": 1, "lr_decay_iters": 2, "lr_decay_to": 0.5}}))
    full, part = tmp_path / "full", tmp_path / "part"
    assert train(tiny_data, full, "--iters", "4", "--config", str(config)) == 0
    assert train(tiny_data, part, "--iters", "3", "--config", str(config)) == 0
    _, meta = load_checkpoint(part / "checkpoint.safetensors")
    assert [g["lr"] for g in meta["optimizers"]["g"]["param_groups"]] == pytest.approx([0.75e-4, 9e-4, 0.75e-4])  # step 2 -> 3: 0.75
    capsys.readouterr()
    assert train(tiny_data, part, "--iters", "4", "--resume") == 0
    assert "learning rates" not in capsys.readouterr().err
    ga, meta = load_checkpoint(full / "checkpoint.safetensors")
    assert [g["lr"] for g in meta["optimizers"]["d"]["param_groups"]] == pytest.approx([7e-4])
    gb, _ = load_checkpoint(part / "checkpoint.safetensors")
    for name, tensor in ga["generator_ema"].items():
        torch.testing.assert_close(tensor, gb["generator_ema"][name], rtol=1e-5, atol=1e-6)


def test_a_run_killed_before_its_first_checkpoint_starts_its_metrics_afresh(tiny_data, tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "metrics.jsonl").write_text('{"iteration": 1, "loss_g_field": 0.5}\n{"iteration": 2, "loss_g_field": 0.4}\n')  # no checkpoint
    assert train(tiny_data, out, "--iters", "2", "--resume") == 0
    assert [r["iteration"] for r in metrics(out)] == [1, 2]


def test_nca_generator_trains_resumes_and_generates(tiny_data, tmp_path):
    config = tmp_path / "nca.yaml"
    config.write_text(yaml.safe_dump({**TINY, "generator": {**TINY["generator"], "kind": "nca", "nca_channels": 6, "nca_hidden": 16,
                                                              "nca_steps": 3, "nca_condition": 4}}))
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
    assert main(["infer", "generate", "--checkpoint", str(full / "checkpoint.safetensors"), "--mesh", str(tiny_data / "shapes" / "cube0.npz"),
                 "--out", str(out), "--seeds", "0,1", "--views", "1", "--resolution", "16", "--texture-size", "16", "--device", "cpu"]) == 0
    a, b = (np.asarray(Image.open(out / f"seed{s}_view0.png"), dtype=np.float64) for s in (0, 1))
    assert np.abs(a - b).mean() > 0.05


def test_nonfinite_loss_stops_with_a_clear_message(tiny_data, tmp_path, capsys):
    config = tmp_path / "bad.yaml"
    config.write_text(yaml.safe_dump({**TINY, "optim": {"lr_discriminator": 1e30, "lr_generator": 1e30}}))
    out = tmp_path / "bad"
    code = main(["train", "gan", "--shapes", str(tiny_data / "shapes"), "--images", str(tiny_data / "photos"), "--out", str(out),
                 "--config", str(config), "--batch", "2", "--views", "2", "--resolution", "16", "--device", "cpu", "--iters", "30"])
    err = capsys.readouterr().err
    assert code == 4 and "non-finite loss" in err and "nonfinite.safetensors" in err
    assert (out / "nonfinite.safetensors").is_file()


def test_bad_inputs_are_user_errors(tiny_data, tmp_path, capsys):
    assert main(["train", "gan", "--shapes", str(tmp_path), "--images", str(tiny_data / "photos"), "--out", str(tmp_path / "r")]) == 2
    assert "no prepared shapes" in capsys.readouterr().err
    assert train(tiny_data, tmp_path / "r2", "--resolution", "20") == 2
    assert "power of two" in capsys.readouterr().err


def test_two_process_data_parallel_run(tiny_data, tmp_path):
    out = tmp_path / "ddp"
    env = {**os.environ, "MESH2TEX_PROGRESS": "0", "OMP_NUM_THREADS": "1"}
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2", "-m", "mesh2tex",
           "train", "gan", "--shapes", str(tiny_data / "shapes"), "--images", str(tiny_data / "photos"), "--out", str(out),
           "--config", str(tiny_data / "tiny.yaml"), "--batch", "1", "--views", "2", "--resolution", "16", "--device", "cpu", "--iters", "2"]
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
    assert main(["train", "gan", "--shapes", str(tiny_data / "shapes"), "--images", str(tiny_data / "photos"), "--out", str(out),
                 "--config", str(config), "--batch", "2", "--views", "2", "--resolution", "16", "--device", "cpu", "--iters", "2"]) == 0
    snaps = sorted((out / "snapshots").glob("iter*.safetensors"))
    assert [p.name for p in snaps] == ["iter0000001.safetensors", "iter0000002.safetensors"]
    model = load_generator(snaps[-1], torch.device("cpu"))
    generator = model.network
    assert model.iteration == 2 and model.resolution == 16
    groups, _ = load_checkpoint(out / "checkpoint.safetensors", kind="gan")
    for name, tensor in generator.state_dict().items():
        torch.testing.assert_close(tensor, groups["generator_ema"][name].float(), rtol=2e-3, atol=2e-3)


# ------------------------------------------------------------------ --resume PATH and snapshot retention
def test_a_run_starts_from_another_runs_checkpoint(tiny_data, tmp_path, capsys):
    """``--resume PATH`` into a new --out reaches the weights of the source run continued in place, and says where it started."""
    source, other = tmp_path / "source", tmp_path / "other"
    assert train(tiny_data, source, "--iters", "2") == 0
    capsys.readouterr()
    assert train(tiny_data, other, "--iters", "4", "--resume", str(source / "checkpoint.safetensors")) == 0
    err = capsys.readouterr().err
    assert f"{other} starts from {source / 'checkpoint.safetensors'} (iteration 2)" in err
    assert (source / "metrics.jsonl").read_text().count("\n") == 2, "the source run is left as it was"
    assert train(tiny_data, source, "--iters", "4", "--resume") == 0
    assert [r["iteration"] for r in metrics(other)] == [3, 4]
    assert yaml.safe_load((other / "config.yaml").read_text())["iters"] == 4
    ga, meta_a = load_checkpoint(source / "checkpoint.safetensors", kind="gan")
    gb, meta_b = load_checkpoint(other / "checkpoint.safetensors", kind="gan")
    assert meta_a["iteration"] == meta_b["iteration"] == 4
    for group in ("generator_ema", "generator", "d_field", "d_proxy"):
        for name, tensor in ga[group].items():
            torch.testing.assert_close(tensor, gb[group][name], rtol=1e-5, atol=1e-6)
    # A run folder stands for its checkpoint; the new run then continues with --resume alone.
    third = tmp_path / "third"
    assert train(tiny_data, third, "--iters", "5", "--resume", str(other)) == 0
    assert [r["iteration"] for r in metrics(third)] == [5]


@pytest.fixture(scope="module")
def refused_sources(tiny_data, tmp_path_factory):
    """Checkpoints a run must not start from: another kind, an inference snapshot, a shipped model, a missing file."""
    from mesh2tex.io.checkpoint import save_checkpoint
    from mesh2tex.models import save_inference_checkpoint

    root = tmp_path_factory.mktemp("refused")
    save_checkpoint(root / "pose.safetensors", {"net": {"w": torch.zeros(2)}}, kind="pose",
                    meta={"iteration": 2, "optimizers": {}, "rng": []})
    save_inference_checkpoint(root / "snapshot.safetensors", "gan", {"w": torch.zeros(2)}, {"iteration": 2})
    shipped = Path(__file__).resolve().parents[1] / "mesh2tex" / "models" / "chair" / "generator.safetensors"
    (root / "text.safetensors").write_text("not a checkpoint")
    return {"another kind": (root / "pose.safetensors", "a 'pose' checkpoint, expected a 'gan' training checkpoint"),
            "snapshot": (root / "snapshot.safetensors", "an inference checkpoint (float16 weights without optimizer state"),
            "shipped": (shipped, "an inference checkpoint"),
            "not a checkpoint": (root / "text.safetensors", "not a mesh2tex checkpoint"),
            "missing": (root / "missing.safetensors", "checkpoint not found")}


@pytest.mark.parametrize("case", ["another kind", "snapshot", "shipped", "not a checkpoint", "missing"])
def test_resume_refuses_what_is_not_a_gan_training_checkpoint(case, refused_sources, tiny_data, tmp_path, capsys):
    path, reason = refused_sources[case]
    if case == "shipped" and not path.is_file():
        pytest.skip("no shipped chair model in this checkout")
    out = tmp_path / "run"
    capsys.readouterr()
    assert train(tiny_data, out, "--iters", "2", "--resume", str(path)) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"mesh2tex: error: {path}: ") and reason in err, err
    assert not out.exists(), "nothing is written to --out"


def test_overwrite_starts_a_new_run_in_place_of_the_one_in_out(tiny_data, tmp_path, capsys):
    run = tmp_path / "run"
    assert train(tiny_data, run, "--iters", "2") == 0
    capsys.readouterr()
    assert train(tiny_data, run, "--iters", "1") == 2
    err = capsys.readouterr().err
    assert "at iteration 2); pass --resume to continue it (with a larger --iters to extend a finished one), --overwrite to replace it" in err
    assert train(tiny_data, run, "--iters", "1", "--resume", "--overwrite") == 2, "continue or replace: not both"
    assert "give one of them" in capsys.readouterr().err
    assert train(tiny_data, run, "--iters", "1", "--overwrite") == 0
    assert max(record["iteration"] for record in metrics(run)) == 1, "the replaced run's metrics are gone"
    assert read_checkpoint_meta(run / "checkpoint.safetensors")["meta"]["iteration"] == 1


def test_resume_from_another_run_refuses_an_out_that_holds_a_run(tiny_data, tmp_path, capsys):
    a, b = tmp_path / "a", tmp_path / "b"
    assert train(tiny_data, a, "--iters", "1") == 0
    assert train(tiny_data, b, "--iters", "1") == 0
    before = {p.name: p.read_bytes() for p in b.iterdir() if p.is_file()}
    capsys.readouterr()
    assert train(tiny_data, b, "--iters", "2", "--resume", str(a / "checkpoint.safetensors")) == 2
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if line.startswith("mesh2tex: error:")]
    assert len(errors) == 1 and err.endswith(errors[0] + "\n") and "already holds a run" in errors[0]
    assert {p.name: p.read_bytes() for p in b.iterdir() if p.is_file()} == before
    # --resume naming the run's own checkpoint continues it, as --resume alone does.
    assert train(tiny_data, b, "--iters", "2", "--resume", str(b / "checkpoint.safetensors")) == 0
    assert [r["iteration"] for r in metrics(b)] == [1, 2]


def test_keep_snapshots_keeps_the_newest(tiny_data, tmp_path, capsys):
    config = tmp_path / "keep.yaml"
    config.write_text(yaml.safe_dump({**TINY, "snapshot_every": 1, "keep_snapshots": 2}))
    out = tmp_path / "keep"
    assert train(tiny_data, out, "--iters", "4", "--config", str(config)) == 0
    assert sorted(p.name for p in (out / "snapshots").iterdir()) == ["iter0000003.safetensors", "iter0000004.safetensors"]
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
    assert all(np.isfinite(r["metric_swd"]) and r["metric_swd"] > 0 and np.isfinite(r["metric_diversity"]) for r in measured)
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


def test_kill_stops_a_run_with_its_checkpoint_saved(tiny_data, tmp_path):
    """SIGTERM (``kill PID``, a scheduler's stop) saves the checkpoint as Ctrl-C does; the same command resumes."""
    import signal
    import time

    out = tmp_path / "killed"
    env = {**os.environ, "MESH2TEX_PROGRESS": "0", "OMP_NUM_THREADS": "1"}
    cmd = [sys.executable, "-m", "mesh2tex", "train", "gan", "--shapes", str(tiny_data / "shapes"), "--images", str(tiny_data / "photos"),
           "--out", str(out), "--config", str(tiny_data / "tiny.yaml"), "--batch", "1", "--views", "2", "--resolution", "16",
           "--device", "cpu", "--iters", "100000"]
    process = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and not ((out / "metrics.jsonl").is_file() and len(metrics(out)) >= 3):
        time.sleep(0.2)
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr[-2000:]
    assert "interrupted; re-run the same command to resume" in stderr
    _, meta = load_checkpoint(out / "checkpoint.safetensors")
    assert meta["iteration"] >= 3 and meta["iteration"] >= metrics(out)[-1]["iteration"]


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


def test_supersampled_fakes_are_rendered_larger_and_box_filtered_to_the_photos_resolution(tiny_data, tmp_path, monkeypatch):
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
    assert main(["train", "gan", "--shapes", str(tiny_data / "shapes"), "--images", str(tiny_data / "photos"), "--out", str(tmp_path / "run"),
                 "--config", str(config), "--batch", "2", "--views", "2", "--resolution", "16", "--device", "cpu", "--iters", "1"]) == 0
    assert rendered and all(images.shape[-1] == 32 for images in rendered)
    assert len(judged) == len(rendered)
    for big, small in zip(rendered, judged):
        assert small.shape[-1] == 16 and torch.allclose(small, F.avg_pool2d(big, 2))
    with pytest.raises(ValueError, match="supersample"):
        trainer.TrainGanConfig(supersample=0)
