"""The plumbing every stage relies on: the CLI routes, errors are one line, writes are atomic, checkpoints carry no
pickle."""

import json

import pytest
import torch

from mesh2tex.cli import main
from mesh2tex.config import load_config, save_config
from mesh2tex.errors import InputError
from mesh2tex.io.atomic import atomic_path, write_json
from mesh2tex.io.checkpoint import load_checkpoint, read_checkpoint_meta, save_checkpoint


def test_help_lists_every_command(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    for command in ("prepare", "train", "infer", "evaluate", "demo"):
        assert command in out


def test_atomic_write_leaves_old_file_on_failure(tmp_path):
    target = tmp_path / "a.json"
    write_json(target, {"v": 1})
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("killed")
    assert json.loads(target.read_text()) == {"v": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["a.json"]


def test_checkpoint_round_trip_and_kind_check(tmp_path):
    path = tmp_path / "ckpt.safetensors"
    weights = {"w": torch.randn(3, 4), "b": torch.zeros(4)}
    save_checkpoint(path, {"model": weights}, kind="gan", meta={"iteration": 7})
    groups, meta = load_checkpoint(path, kind="gan")
    assert meta == {"iteration": 7}
    assert torch.equal(groups["model"]["w"], weights["w"])
    with pytest.raises(InputError, match="expected a 'pose' checkpoint"):
        load_checkpoint(path, kind="pose")


def test_garbage_checkpoint_is_a_user_error(tmp_path):
    path = tmp_path / "junk.safetensors"
    path.write_bytes(b"\x00" * 64)
    with pytest.raises(InputError, match="junk.safetensors"):
        read_checkpoint_meta(path)


def test_config_yaml_overrides_and_unknown_keys(tmp_path):
    from dataclasses import dataclass, field

    @dataclass
    class Inner:
        lr: float = 1e-3

    @dataclass
    class Outer:
        iters: int = 5
        optim: Inner = field(default_factory=Inner)

    yaml_path = tmp_path / "c.yaml"
    yaml_path.write_text("iters: 9\noptim:\n  lr: 2\n")
    cfg = load_config(Outer, yaml_path, overrides={"optim.lr": 0.5, "iters": None})
    assert cfg.iters == 9 and cfg.optim.lr == 0.5
    save_config(cfg, tmp_path / "resolved.yaml")
    assert load_config(Outer, tmp_path / "resolved.yaml") == cfg
    yaml_path.write_text("itres: 9\n")
    with pytest.raises(InputError, match="itres"):
        load_config(Outer, yaml_path)


def test_progress_bars_show_on_a_terminal_only_unless_asked(monkeypatch):
    import io
    import sys

    from mesh2tex.progress import progress_bar

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    for stream, setting, shown in (
        (io.StringIO(), None, False),
        (Terminal(), None, True),
        (io.StringIO(), "1", True),
        (Terminal(), "0", False),
    ):
        monkeypatch.setattr(sys, "stderr", stream)
        if setting is None:
            monkeypatch.delenv("MESH2TEX_PROGRESS", raising=False)
        else:
            monkeypatch.setenv("MESH2TEX_PROGRESS", setting)
        bar = progress_bar(range(3), desc="x")
        list(bar)
        bar.close()
        assert bool(stream.getvalue()) == shown, (setting, shown)


def test_threads_follow_the_idle_cores_unless_the_user_sets_them():
    from mesh2tex.runtime import choose_threads

    assert choose_threads(cpu_count=2, load=0.2, environ={}) == 2
    assert choose_threads(cpu_count=2, load=1.1, environ={}) == 1  # one competing process: one thread
    assert choose_threads(cpu_count=2, load=7.0, environ={}) == 1
    assert choose_threads(cpu_count=16, load=3.4, environ={}) == 13
    assert choose_threads(cpu_count=2, load=5.0, environ={"OMP_NUM_THREADS": "2"}) == 2
    assert choose_threads(cpu_count=2, load=0.0, environ={"MESH2TEX_THREADS": "1", "OMP_NUM_THREADS": "2"}) == 1
    assert choose_threads(cpu_count=2, load=0.0, environ={"OMP_NUM_THREADS": "junk"}) == 2


def test_busy_cores_are_read_from_the_kernels_cpu_counters(tmp_path, monkeypatch):
    """Between two readings of /proc/stat, 300 of 400 ticks busy on a 2-core machine: 1.5 cores."""
    from mesh2tex import runtime

    stat = tmp_path / "stat"
    # user nice system idle iowait irq softirq steal guest guest_nice
    stat.write_text(
        "cpu  100 0 100 500 0 0 0 0 0 0\ncpu0 50 0 50 250 0 0 0 0 0 0\ncpu1 50 0 50 250 0 0 0 0 0 0\nintr 1\n"
    )
    later = "cpu  350 0 150 580 20 0 0 0 0 0\ncpu0 1 0 1 1 0 0 0 0 0 0\ncpu1 1 0 1 1 0 0 0 0 0 0\n"
    monkeypatch.setattr(runtime.time, "sleep", lambda seconds: stat.write_text(later))
    assert runtime.busy_cores_now(stat_path=str(stat)) == pytest.approx(1.5)
    assert runtime.busy_cores_now(stat_path=str(tmp_path / "missing")) is None
