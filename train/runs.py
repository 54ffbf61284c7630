"""Run conventions shared by the trainers (gan, pose, noc, nca).

A run directory ``RUN/`` holds:
    config.yaml                 the resolved config (every hyperparameter of the run)
    checkpoint.safetensors      the last good checkpoint (tensors + JSON metadata, written atomically:
                                a kill during a save leaves the previous one intact)
    nonfinite.safetensors       only after a NaN/inf loss: the state at the failing iteration
    metrics.jsonl               one JSON object per logged iteration
    tensorboard/                the same numbers as TensorBoard scalars, when the ``tensorboard``
                                package is installed (``pip install tensorboard``; MESH2TEX_TENSORBOARD=0 turns it off)
    samples/                    images the trainer writes while it runs
    snapshots/                  train gan only, every snapshot_every iterations: float16 EMA generators
    (keep_snapshots: the newest N)
    checkpoints/                train gan only, at the keep_checkpoints iterations: the whole training state,
                                to start other runs from (``--resume RUN/checkpoints/iterNNNNNNN.safetensors``)

A folder that holds a run is continued with ``--resume`` or replaced with ``--overwrite`` (the files
the replaced run wrote, :data:`REPLACED_BY_OVERWRITE`, are moved aside to ``RUN/.mesh2tex-replaced/<date-time>/``
with the fixed-name files :func:`mesh2tex.io.outputs.guard_outputs` moves; nothing is deleted), and refused otherwise.

Checkpoints hold modules, optimizers (with their state), EMA copies, RNG states (torch, CUDA, numpy,
Python; one set per process of a distributed run) and the iteration, so that ``--resume`` continues
exactly where the run stopped; ``--resume CHECKPOINT`` starts a new run from another run's
(:func:`start_from`). The pieces live in the library (:mod:`mesh2tex.runtime` for devices,
processes, RNG and EMA; :mod:`mesh2tex.io.checkpoint` for training states); this module keeps the
run directory, the NaN guard and the one training loop of every trainer (:func:`training_loop`: steps,
the NaN guard, metrics lines, checkpoints, periodic work, progress and the save on an interrupt),
and names the library pieces for the trainers.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from pathlib import Path
from typing import Any, Callable, Protocol, Sequence

import numpy as np
import torch

from mesh2tex.config import save_config
from mesh2tex.errors import InputError, UserError
from mesh2tex.io.atomic import json_ready

# The library pieces every trainer uses, in the one namespace the trainers read (``runs.X``).
# noqa: F401
from mesh2tex.io.checkpoint import (
    check_training_checkpoint,
    load_training_state,
    read_checkpoint_meta,
    save_training_state,
)
from mesh2tex.io.outputs import continues_own_run, guard_outputs, move_aside
from mesh2tex.progress import JsonLines, progress_bar
from mesh2tex.runtime import (
    Distributed,
    StopAfterStep,
    ema_beta,
    ema_update,
    make_ema,
    peak_memory_gb,
    rng_from_state,  # noqa: F401
    rng_to_state,
    seed_everything,
    select_device,
)

__all__ = [
    "CHECKPOINT_NAME",
    "NONFINITE_NAME",
    "Distributed",
    "At",
    "Every",
    "NonFiniteLoss",
    "RunDirectory",
    "Trainer",
    "apply_learning_rates",
    "check_finite",
    "dumps_config",
    "training_loop",
    "ema_beta",
    "ema_update",
    "load_training_state",
    "make_ema",
    "peak_memory_gb",
    "rng_from_state",
    "rng_to_state",
    "save_training_state",
    "scalars",
    "seed_everything",
    "select_device",
    "start_from",
]

CHECKPOINT_NAME = "checkpoint.safetensors"
NONFINITE_NAME = "nonfinite.safetensors"
# What a run writes into its folder (the module docstring; best.safetensors of train gan, model.safetensors
# of train nca): a new run started with --overwrite moves these of the run it replaces aside, and nothing else.
REPLACED_BY_OVERWRITE = (
    CHECKPOINT_NAME,
    NONFINITE_NAME,
    "metrics.jsonl",
    "best.safetensors",
    "model.safetensors",
    "snapshots/iter*.safetensors",
    "checkpoints/iter*.safetensors",
    "samples/iter*.png",
    "tensorboard/events.out.tfevents.*",
)
# The files a new run writes at fixed names: one already there that no run of this command line wrote is kept
# without --overwrite (mesh2tex.io.outputs.guard_outputs).
RUN_FILES = ("config.yaml", CHECKPOINT_NAME, NONFINITE_NAME, "metrics.jsonl", "best.safetensors", "model.safetensors")


# ---------------------------------------------------------------------------------- run directory
class RunDirectory:
    """The files of one training run (see the module docstring)."""

    def __init__(self, root: str | os.PathLike):
        self.root = Path(root)
        self.config_path = self.root / "config.yaml"
        self.checkpoint_path = self.root / CHECKPOINT_NAME
        self.nonfinite_path = self.root / NONFINITE_NAME
        self.samples_dir = self.root / "samples"
        self.metrics = JsonLines(self.root / "metrics.jsonl")
        self.tensorboard_dir = self.root / "tensorboard"
        self._scalars = None  # the TensorBoard writer, made by the first log()
        # --resume: the folder is a run's (one killed before its first checkpoint starts again there)
        self.resume_asked = False

    def log(self, record: dict[str, Any]) -> None:
        """One logged iteration (``record["iteration"]`` and numbers): a line of metrics.jsonl, and the
        numbers as TensorBoard scalars (tag = key, step = iteration) when TensorBoard is available."""
        self.metrics.write(record)
        if self._scalars is None:
            self._scalars = tensorboard_writer(self.tensorboard_dir) or False
        if self._scalars:
            step = int(record["iteration"])
            for key, value in record.items():
                if key != "iteration" and isinstance(value, (int, float)) and not isinstance(value, bool):
                    self._scalars.add_scalar(key, value, step)
            self._scalars.flush()

    def has_checkpoint(self) -> bool:
        return self.checkpoint_path.is_file()

    def start(self, cfg, resume: bool, overwrite: bool = False) -> None:
        """Create the directory and write the resolved config; refuse to overwrite a run by accident.
        ``overwrite`` (``--overwrite``): a new run replaces the one there (its checkpoint, NaN state and metrics go)."""
        if not resume and self.has_checkpoint() and not overwrite:
            try:  # the iteration tells a stopped run from a finished one
                at = f", at iteration {int(read_checkpoint_meta(self.checkpoint_path)['meta']['iteration'])}"
            # a damaged checkpoint is named when resumed; here the refusal matters
            except (
                InputError,
                KeyError,
                TypeError,
                ValueError,
            ):
                at = ""
            raise UserError(
                f"{self.root}: already holds a run ({CHECKPOINT_NAME}{at}); pass --resume to continue it (with a "
                f"larger --iters to extend a finished one), --overwrite to replace it, or choose another --out"
            )
        if resume:
            # a damaged checkpoint is refused before config.yaml is rewritten
            read_checkpoint_meta(self.checkpoint_path)
        # a new run: files already at its names (a config.yaml of the user's) are kept without --overwrite
        elif not self.resume_asked:
            guard_outputs(self.root, RUN_FILES, overwrite)
        self.root.mkdir(parents=True, exist_ok=True)
        self.samples_dir.mkdir(exist_ok=True)
        # nothing of the replaced run may be resumed or read as this one's: moved aside, not deleted
        if not resume and overwrite:
            replaced = [
                path.relative_to(self.root).as_posix()
                for pattern in REPLACED_BY_OVERWRITE
                for path in sorted(self.root.glob(pattern))
                if path.is_file() or path.is_symlink()
            ]
            folder = move_aside(self.root, replaced)
            if folder is not None:
                print(
                    f"mesh2tex: note: {self.root}: the replaced run's files ({len(replaced)}) were moved aside to "
                    f"{folder}",
                    file=sys.stderr,
                )
        # left by a run killed before its first checkpoint: it starts again
        if not resume and self.metrics.path.exists():
            self.metrics.truncate_after("iteration", 0)
        save_config(cfg, self.config_path)


def tensorboard_writer(folder: Path):
    """A ``torch.utils.tensorboard.SummaryWriter`` writing into ``folder``, or None when the
    ``tensorboard`` package is not installed or ``MESH2TEX_TENSORBOARD`` is 0 (metrics.jsonl holds
    every number either way; TensorBoard is a viewer, not a record)."""
    if os.environ.get("MESH2TEX_TENSORBOARD", "1") == "0":
        return None
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:  # torch raises it when the tensorboard package is missing
        return None
    return SummaryWriter(log_dir=str(folder))


def start_from(
    resume: bool | str | None, run: RunDirectory, kind: str, note: bool = True, overwrite: bool = False
) -> Path | None:
    """The checkpoint a run starts from, checked before anything is written to ``run``.

    ``--resume`` alone (``True``): the run's own checkpoint, which it continues (None, with a note,
    when there is none yet). ``--resume PATH``: another run's training checkpoint of ``kind`` (a run
    folder stands for its checkpoint), from which ``run``, which must not hold a run of its own,
    starts; the header is checked here (kind, optimizer state) and a note names the source. Without
    ``--resume``: None. ``note``: whether this process prints the notes (the main one of a run).
    ``overwrite`` (``--overwrite``): the run in ``run`` is to be replaced, so ``--resume`` alone is refused
    and ``--resume PATH`` may start there."""
    if resume is not True and run.has_checkpoint() and continues_own_run(run.root):
        # the same command line, re-run after an interruption, continues its run (mesh2tex.io.outputs)
        if note:
            print(f"mesh2tex: note: {run.root}: continuing the interrupted run of this command", file=sys.stderr)
        return run.checkpoint_path
    if resume is True and overwrite:
        raise UserError("--resume continues the run in --out and --overwrite replaces it: give one of them")
    run.resume_asked = resume is True
    if not resume:
        return None
    if resume is not True:
        path = Path(resume)
        if path.is_dir():
            if not (path / CHECKPOINT_NAME).is_file():
                raise UserError(_no_checkpoint_yet(path))
            path = path / CHECKPOINT_NAME
        if path.resolve() != run.checkpoint_path.resolve():
            header = check_training_checkpoint(path, kind)
            if not run.has_checkpoint() and continues_own_run(run.root) and note:
                # killed before its first checkpoint: nothing of this run to continue, so it starts from PATH again
                print(
                    f"mesh2tex: note: {run.root}: the interrupted run of this command saved no checkpoint yet; "
                    f"starting from {path} again",
                    file=sys.stderr,
                )
            if run.has_checkpoint() and not overwrite:
                raise UserError(
                    f"{run.root}: already holds a run ({CHECKPOINT_NAME}); --resume {path} starts a new run: choose "
                    f"another --out, pass --overwrite to replace it, or pass --resume alone to continue this one"
                )
            if note:
                print(
                    f"mesh2tex: note: {run.root} starts from {path} (iteration {header['meta']['iteration']}) with "
                    "this run's config "
                    f"(its config.yaml, else --config and the flags), not the checkpoint's",
                    file=sys.stderr,
                )
            return path
    if run.has_checkpoint():
        return run.checkpoint_path
    if note:
        print(f"mesh2tex: note: {run.checkpoint_path} not found; starting a new run", file=sys.stderr)
    return None


def _no_checkpoint_yet(folder: Path) -> str:
    """Why ``--resume FOLDER`` has nothing to start from: a run not at its first checkpoint yet, or no run."""
    if (folder / "config.yaml").is_file() or (folder / "metrics.jsonl").is_file():
        return (
            f"{folder}: this run has no {CHECKPOINT_NAME} yet (a run writes it every checkpoint_every iterations, "
            f"when it ends and when it is interrupted); --resume it once it is there, or start without --resume"
        )
    return f"{folder}: no {CHECKPOINT_NAME} in this folder; --resume takes a run folder or a training checkpoint file"


# ------------------------------------------------------------------------------------ NaN guard
class Throughput:
    """The speed and memory fields of a metrics.jsonl record: iterations per second since the last
    record (or since the loop started) and the process's peak memory so far."""

    def __init__(self, iteration: int, device: torch.device, digits: int = 4):
        self.device, self.digits = device, digits
        self.last_time, self.last_iteration = time.perf_counter(), iteration

    def fields(self, iteration: int) -> dict[str, float]:
        """{"iters_per_second", "peak_memory_gb"} at ``iteration``; the next call measures from here."""
        now = time.perf_counter()
        rate = (iteration - self.last_iteration) / max(now - self.last_time, 1e-9)
        self.last_time, self.last_iteration = now, iteration
        return {"iters_per_second": round(rate, self.digits), "peak_memory_gb": round(peak_memory_gb(self.device), 3)}


class NonFiniteLoss(Exception):
    """A loss became NaN or infinite."""


def check_finite(logs: dict[str, torch.Tensor | float], iteration: int) -> None:
    """Raise :class:`NonFiniteLoss` naming the first non-finite value of ``logs``."""
    for name, value in logs.items():
        v = float(value.detach()) if isinstance(value, torch.Tensor) else float(value)
        if not np.isfinite(v):
            raise NonFiniteLoss(f"{name} = {v} at iteration {iteration}")


def apply_learning_rates(optimizers: dict[str, torch.optim.Optimizer], rates: dict[str, list[float]]) -> list[str]:
    """Set each parameter group's learning rate to the config's (``rates[name][group]``) after a resumed
    optimizer state brought the checkpoint's; returns the changes, e.g. ``"g[1] 0.0012 -> 0.0006"``."""
    changes = []
    for name, opt in optimizers.items():
        for index, (group, lr) in enumerate(zip(opt.param_groups, rates[name])):
            if group["lr"] != lr:
                changes.append(f"{name}[{index}] {group['lr']:g} -> {lr:g}")
                group["lr"] = lr
    return changes


def scalars(logs: dict[str, torch.Tensor | float]) -> dict[str, float]:
    """Plain floats (rounded) of a dict of scalar tensors, for metrics.jsonl."""
    return {k: round(float(v), 6) for k, v in logs.items()}


def dumps_config(cfg) -> dict[str, Any]:
    """The config as plain JSON (for checkpoint metadata)."""
    return json_ready(dataclasses.asdict(cfg))


# ------------------------------------------------------------------------------------ the loop
class Trainer(Protocol):
    """What :func:`training_loop` drives: ``iteration`` (steps done), ``step()`` (one step: advances
    ``iteration``, returns its scalars, raises :class:`NonFiniteLoss` before any optimizer step of a
    step whose losses are not finite) and ``save(path)`` (the whole training state)."""

    iteration: int

    def step(self) -> dict[str, float]: ...

    def save(self, path: Path) -> None: ...


@dataclasses.dataclass
class Every:
    """Work done every ``every`` iterations (0: never): ``action()``. At the last iteration, ``final``:
    "if_multiple" (as at any other), "always", or "never" (the trainer does it after the loop);
    ``main_only``: on the main process of a distributed run only."""

    every: int
    action: Callable[[], object]
    final: str = "if_multiple"
    main_only: bool = True

    def due(self, iteration: int, last: int) -> bool:
        if not self.every:
            return False
        if iteration == last and self.final != "if_multiple":
            return self.final == "always"
        return iteration % self.every == 0


@dataclasses.dataclass
class At:
    """Work done at the given ``iterations`` only: ``action()``; ``main_only`` as :class:`Every`'s."""

    iterations: Sequence[int]
    action: Callable[[], object]
    main_only: bool = True

    def due(self, iteration: int, last: int) -> bool:
        return iteration in self.iterations


def _guarded_step(trainer: Trainer, run: RunDirectory, advice: str) -> dict[str, float]:
    """``trainer.step()``; a non-finite loss saves the state to ``RUN/nonfinite.safetensors`` and stops
    with one error line naming the last good checkpoint and ``advice``, exit status 4."""
    try:
        return trainer.step()
    except NonFiniteLoss as error:
        trainer.save(run.nonfinite_path)
        kept = f"; the last good checkpoint is {run.checkpoint_path}" if run.has_checkpoint() else ""
        raise UserError(
            f"{run.root}: training stopped, non-finite loss ({error}); state saved to {run.nonfinite_path}{kept}. "
            f"{advice}",
            exit_code=4,
        ) from None


def training_loop(
    trainer: Trainer,
    run: RunDirectory,
    *,
    iters: int,
    desc: str,
    device: torch.device,
    log_every: int,
    checkpoint_every: int,
    advice: str,
    postfix: Callable[[dict], dict] = lambda logs: {},
    measure: Every | None = None,
    periodic: Sequence[Every | At] = (),
    main: bool = True,
    extra: dict | None = None,
    stop_together: Callable[[bool], bool] = lambda requested: requested,
) -> None:
    """Run ``trainer`` from its iteration to ``iters``, as every trainer does:

    * a progress bar on the main process (``postfix(logs)``: the step's figures it shows);
    * a non-finite loss saves the state to ``RUN/nonfinite.safetensors`` and stops with one error line
      naming the last good checkpoint and ``advice`` (what to change before ``--resume``), exit status 4;
    * a metrics line every ``log_every`` iterations and at the last: the step's scalars, the run's own
      ``measure`` when due (its dict merged in; a due measure always writes a line), iterations per
      second of the training steps since the last line, peak memory, the torch thread count (it changes
      float sums, so a long run's trajectory) and ``extra``;
    * the checkpoint every ``checkpoint_every`` iterations (and at the end, and on Ctrl-C or ``kill``
      before the interrupt goes on), and the ``periodic`` work (snapshots, samples) when due;
    * Ctrl-C or ``kill`` stops the loop once the step in progress and its logging are done
      (:class:`mesh2tex.runtime.StopAfterStep`; a second one at once), so that the saved checkpoint
      resumes exactly; ``stop_together(requested)`` is true when any process was asked (a distributed
      run stops all its processes after the same step).
    """
    bar = progress_bar(total=iters, initial=trainer.iteration, desc=desc) if main else None
    throughput = Throughput(trainer.iteration, device)
    try:
        with StopAfterStep(announce=main) as stop:
            while trainer.iteration < iters:
                logs = _guarded_step(trainer, run, advice)
                it = trainer.iteration
                if bar is not None:
                    bar.update(1)
                    bar.set_postfix(postfix(logs))
                measured = main and measure is not None and measure.due(it, iters)
                if main and (it % log_every == 0 or it == iters or measured):
                    speed = throughput.fields(it)  # before measuring: the measure counts towards the next interval
                    figures = measure.action() if measured else {}
                    run.log(
                        {
                            "iteration": it,
                            **logs,
                            **figures,
                            **speed,
                            "torch_threads": torch.get_num_threads(),
                            **(extra or {}),
                        }
                    )
                if checkpoint_every and it % checkpoint_every == 0 and it < iters:
                    trainer.save(run.checkpoint_path)
                for work in periodic:
                    if (main or not work.main_only) and work.due(it, iters):
                        work.action()
                # between steps: the state is whole, so the checkpoint saved below resumes exactly
                if stop_together(stop.requested):
                    raise KeyboardInterrupt
    except KeyboardInterrupt:
        trainer.save(run.checkpoint_path)
        raise
    finally:
        if bar is not None:
            bar.close()
    trainer.save(run.checkpoint_path)
