"""`train gan` resumed, restarted and killed: the same run as uninterrupted, learning rates and late terms that survive
a resume, runs started from another run's checkpoint, what it refuses to start from."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import yaml
from gan_runs import TINY, make_tiny_data, metrics, train, train_args

from mesh2tex.io.checkpoint import load_checkpoint, read_checkpoint_meta
from mesh2tex.losses.gan import GanLoss
from mesh2tex.models.store import D_FIELD, GENERATOR_EMA


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory):
    return make_tiny_data(tmp_path_factory.mktemp("gan_data"))


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
    assert (
        train(
            tiny_data, second, "--iters", "4", "--config", with_term, "--resume", str(first / "checkpoint.safetensors")
        )
        == 0
    )
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
    assert OptimConfig().lr_scale(10**6) == 1.0  # off by default
    with pytest.raises(ValueError, match="lr_decay_to"):
        OptimConfig(lr_decay_start=1, lr_decay_to=1.5)
    config = tmp_path / "anneal.yaml"
    config.write_text(yaml.safe_dump({**TINY, "optim": {"lr_decay_start": 1, "lr_decay_iters": 2, "lr_decay_to": 0.5}}))
    full, part = tmp_path / "full", tmp_path / "part"
    assert train(tiny_data, full, "--iters", "4", "--config", str(config)) == 0
    assert train(tiny_data, part, "--iters", "3", "--config", str(config)) == 0
    _, meta = load_checkpoint(part / "checkpoint.safetensors")
    assert [g["lr"] for g in meta["optimizers"]["g"]["param_groups"]] == pytest.approx(
        [0.75e-4, 9e-4, 0.75e-4]
    )  # step 2 -> 3: 0.75
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
    (out / "metrics.jsonl").write_text(
        '{"iteration": 1, "loss_g_field": 0.5}\n{"iteration": 2, "loss_g_field": 0.4}\n'
    )  # no checkpoint
    assert train(tiny_data, out, "--iters", "2", "--resume") == 0
    assert [r["iteration"] for r in metrics(out)] == [1, 2]


# ------------------------------------------------------------------ --resume PATH and snapshot retention
def test_a_run_starts_from_another_runs_checkpoint(tiny_data, tmp_path, capsys):
    """``--resume PATH`` into a new --out reaches the weights of the source run continued in place, and says where it
    started."""
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


def test_a_kept_checkpoint_starts_a_branch_that_equals_the_run_it_came_from(tiny_data, tmp_path, capsys):
    """``keep_checkpoints: [2]`` keeps the whole state at iteration 2 beside the run's own checkpoint; a run started
    from it (``--resume FILE``) with the same settings reaches the source run's weights at iteration 4."""
    config = tmp_path / "keep.yaml"
    config.write_text(yaml.safe_dump({**TINY, "keep_checkpoints": [2]}))
    source, branch = tmp_path / "source", tmp_path / "branch"
    assert train(tiny_data, source, "--iters", "4", "--config", str(config)) == 0
    kept = source / "checkpoints" / "iter0000002.safetensors"
    assert sorted(p.name for p in (source / "checkpoints").iterdir()) == [kept.name]
    assert read_checkpoint_meta(kept)["meta"]["iteration"] == 2
    assert train(tiny_data, branch, "--iters", "4", "--config", str(config), "--resume", str(kept)) == 0
    ga, _ = load_checkpoint(source / "checkpoint.safetensors", kind="gan")
    gb, _ = load_checkpoint(branch / "checkpoint.safetensors", kind="gan")
    for group in ("generator_ema", "generator", "d_field", "d_proxy"):
        for name, tensor in ga[group].items():
            torch.testing.assert_close(tensor, gb[group][name], rtol=1e-5, atol=1e-6)


@pytest.fixture(scope="module")
def refused_sources(tiny_data, tmp_path_factory):
    """Checkpoints a run must not start from: another kind, an inference snapshot, a shipped model, a missing file."""
    from mesh2tex.io.checkpoint import save_checkpoint
    from mesh2tex.models import save_inference_checkpoint

    root = tmp_path_factory.mktemp("refused")
    save_checkpoint(
        root / "pose.safetensors",
        {"net": {"w": torch.zeros(2)}},
        kind="pose",
        meta={"iteration": 2, "optimizers": {}, "rng": []},
    )
    save_inference_checkpoint(root / "snapshot.safetensors", "gan", {"w": torch.zeros(2)}, {"iteration": 2})
    shipped = Path(__file__).resolve().parents[1] / "mesh2tex" / "models" / "chair" / "generator.safetensors"
    (root / "text.safetensors").write_text("not a checkpoint")
    return {
        "another kind": (root / "pose.safetensors", "a 'pose' checkpoint, expected a 'gan' training checkpoint"),
        "snapshot": (root / "snapshot.safetensors", "an inference checkpoint (float16 weights without optimizer state"),
        "shipped": (shipped, "an inference checkpoint"),
        "not a checkpoint": (root / "text.safetensors", "not a mesh2tex checkpoint"),
        "missing": (root / "missing.safetensors", "checkpoint not found"),
    }


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
    assert (
        "at iteration 2); pass --resume to continue it (with a larger --iters to extend a finished one), --overwrite "
        "to replace it" in err
    )
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


def test_kill_stops_a_run_with_its_checkpoint_saved(tiny_data, tmp_path):
    """SIGTERM (``kill PID``, a scheduler's stop) saves the checkpoint as Ctrl-C does; the same command resumes."""
    import signal
    import time

    out = tmp_path / "killed"
    env = {**os.environ, "MESH2TEX_PROGRESS": "0", "OMP_NUM_THREADS": "1"}
    cmd = [
        sys.executable,
        "-m",
        "mesh2tex",
        *train_args(tiny_data, out, "--iters", "100000", batch=1),
    ]
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


def test_ctrl_c_mid_step_stops_after_it_and_the_run_resumes_as_uninterrupted(tiny_data, tmp_path, monkeypatch, capsys):
    """Ctrl-C (or kill) arriving after the generator's update of step 3 and before the discriminator's stops
    the run once step 3 is done: its checkpoint is the state after three whole steps, so the re-run command
    repeats the uninterrupted run to the last digit (a step cut short would leave D one update behind G)."""
    full, part = tmp_path / "full", tmp_path / "part"
    assert train(tiny_data, full, "--iters", "5") == 0

    accumulate = GanLoss.accumulate_gradients
    d_steps = []

    def interrupting(self, phase, *args, **kwargs):
        if phase == "Dmain":
            d_steps.append(phase)
            if len(d_steps) == 3:  # step 3: G stepped, D still to come
                os.kill(os.getpid(), signal.SIGINT)
        return accumulate(self, phase, *args, **kwargs)

    monkeypatch.setattr(GanLoss, "accumulate_gradients", interrupting)
    assert train(tiny_data, part, "--iters", "5") == 130
    assert "stopping after this step" in capsys.readouterr().err
    assert read_checkpoint_meta(part / "checkpoint.safetensors")["meta"]["iteration"] == 3
    assert [r["iteration"] for r in metrics(part)] == [1, 2, 3]
    monkeypatch.setattr(GanLoss, "accumulate_gradients", accumulate)
    assert train(tiny_data, part, "--iters", "5", "--resume") == 0
    a, b = metrics(full), metrics(part)
    assert [r["iteration"] for r in b] == [1, 2, 3, 4, 5]
    for ra, rb in zip(a, b):
        assert ra.keys() == rb.keys(), ra["iteration"]  # the lazy terms' last values carried over the resume
        for key in ra:
            if key.startswith(("loss_", "score_", "r1_", "pl_")):
                assert ra[key] == rb[key], (ra["iteration"], key)
    ga, _ = load_checkpoint(full / "checkpoint.safetensors")
    gb, _ = load_checkpoint(part / "checkpoint.safetensors")
    for group in (GENERATOR_EMA, D_FIELD):
        for name, tensor in ga[group].items():
            torch.testing.assert_close(tensor, gb[group][name], rtol=0, atol=0)
