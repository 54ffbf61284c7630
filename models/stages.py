"""How ``build_model.py`` runs its stages: ``mesh2tex`` commands in its own process (:func:`run`), the mask
network's training in a process of its own beside them (:func:`start_mask_training`), and the training time
a run's log records (:func:`training_seconds`)."""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
from pathlib import Path

import yaml

from mesh2tex.cli import main as cli
from mesh2tex.runtime import user_threads

ROOT = Path(__file__).resolve().parents[1]
# A mask training that ends within this many seconds of its start has failed on its input or finished before.
MASK_STARTUP_SECONDS = 20


def cli_flags(**values) -> list[str]:
    """``["--name", "value", ...]`` of keyword arguments, in their order (underscores become dashes)."""
    return [item for name, value in values.items() for item in (f"--{name.replace('_', '-')}", str(value))]


def command_line(argv: list[str]) -> str:
    """The ``mesh2tex`` command line of ``argv``, as a shell takes it (for the log and the card)."""
    return "mesh2tex " + " ".join(shlex.quote(a) for a in argv)


def run(argv: list[str], log: list[str]) -> None:
    line = command_line(argv)
    print(f"\n== {line}", flush=True)
    log.append(line)
    code = cli(argv)
    if code == 130:  # mesh2tex's exit on Ctrl-C or kill, its checkpoint saved
        sys.exit(f"build_model: stopped during: {line}; the same build_model command resumes")
    if code != 0:
        sys.exit(f"build_model: stage failed (exit {code}): {line}")


def split_threads(environ=os.environ, cpu_count: int | None = None) -> tuple[int | None, dict]:
    """How the build's two processes share the cores while the mask network trains beside the rest: (torch
    threads for the build's own stages, the mask process's environment overrides), half the cores each (at
    least one); (None, {}) where the user set the threads (:func:`mesh2tex.runtime.user_threads`), which
    both processes then take."""
    if user_threads(environ) is not None:
        return None, {}
    cores = cpu_count or os.cpu_count() or 1
    mask = max(1, cores // 2)
    return max(1, cores - mask), {"MESH2TEX_THREADS": str(mask)}


def start_mask_training(argv: list[str], log: Path, threads: dict, commands: list[str]) -> subprocess.Popen:
    """``mesh2tex train mask`` in a process of its own: the mask network learns from the world alone, so it
    trains beside the GAN and the view networks, and on a machine of two cores the build takes the longer
    of the two instead of their sum. ``threads``: its environment overrides (:func:`split_threads`); its
    output goes to ``log``. A training that fails as it starts (a bad folder, a run in use) stops the build
    here, not after the GAN's hours."""
    line = command_line(argv)
    print(f"\n== {line}  (beside the rest; its output in {log})", flush=True)
    commands.append(line)
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
    env = {**os.environ, **threads, "PYTHONPATH": path}
    with open(log, "ab") as handle:
        process = subprocess.Popen(
            [sys.executable, "-m", "mesh2tex", *argv], env=env, stdout=handle, stderr=subprocess.STDOUT
        )
    try:
        process.wait(timeout=MASK_STARTUP_SECONDS)
    except subprocess.TimeoutExpired:
        return process  # training
    finish_mask_training(process, log)  # it has ended already: done (a resumed build) or failed
    return process


def finish_mask_training(process: subprocess.Popen, log: Path) -> None:
    """Wait for :func:`start_mask_training`'s process; its failure stops the build, naming its output."""
    code = process.wait()
    if code != 0:
        sys.exit(f"build_model: the mask network's training failed (exit {code}); its output: {log}")


def gan_run_dir(checkpoint: Path) -> Path:
    """The run directory of a GAN checkpoint or snapshot (RUN/checkpoint.safetensors,
    RUN/snapshots/iter*.safetensors)."""
    return checkpoint.parent.parent if checkpoint.parent.name == "snapshots" else checkpoint.parent


def training_seconds(run_dir: Path, until: int) -> float | None:
    """Seconds a training run spent stepping, from its metrics.jsonl (iterations / iterations per second).

    Only this run's own iterations count: a run that started from another run's checkpoint at
    iteration N logs its first record at N + log_every, and the N iterations before are not its own."""
    path = run_dir / "metrics.jsonl"
    if not path.is_file():
        return None
    config = run_dir / "config.yaml"
    log_every = int((yaml.safe_load(config.read_text()) or {}).get("log_every", 10)) if config.is_file() else 10
    total, last = 0.0, None
    for line in path.read_text().splitlines():
        record = json.loads(line)
        if record["iteration"] > until:
            break
        if last is None:
            last = max(0, record["iteration"] - log_every)
        if record.get("iters_per_second"):
            total += (record["iteration"] - last) / record["iters_per_second"]
        last = record["iteration"]
    return round(total, 1)
