"""Run conventions shared by the trainers (gan, pose, noc).

A run directory ``RUN/`` holds:
    config.yaml                 the resolved config (every hyperparameter of the run)
    checkpoint.safetensors      the last good checkpoint (tensors + JSON metadata, written atomically:
                                a kill during a save leaves the previous one intact)
    nonfinite.safetensors       only after a NaN/inf loss: the state at the failing iteration
    metrics.jsonl               one JSON object per logged iteration
    samples/                    images the trainer writes while it runs

Checkpoints hold modules, optimizers (with their state), EMA copies, RNG states (torch, CUDA, numpy,
Python; one set per process of a distributed run) and the iteration, so that ``--resume`` continues
exactly where the run stopped.
"""

from __future__ import annotations

import copy
import json
import os
import random
import resource
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist
from torch import nn

from mesh2tex.config import save_config
from mesh2tex.errors import UserError
from mesh2tex.io.checkpoint import load_checkpoint, save_checkpoint
from mesh2tex.progress import JsonLines

CHECKPOINT_NAME = "checkpoint.safetensors"
NONFINITE_NAME = "nonfinite.safetensors"


# ----------------------------------------------------------------------------------------- devices
def select_device(name: str) -> torch.device:
    """"auto" (CUDA when available, else CPU), "cpu" or "cuda"; a missing GPU is a user error."""
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda" and not torch.cuda.is_available():
        raise UserError("--device cuda: no CUDA device is available (use --device cpu or auto)")
    if name not in ("cpu", "cuda"):
        raise UserError(f"--device {name}: expected auto, cpu or cuda")
    if name == "cuda" and dist.is_available() and dist.is_initialized():
        return torch.device("cuda", int(os.environ.get("LOCAL_RANK", 0)))
    return torch.device(name)


def peak_memory_gb(device: torch.device) -> float:
    """Peak memory of this process so far: CUDA allocator peak on a GPU, resident set size on a CPU."""
    if device.type == "cuda":
        return torch.cuda.max_memory_allocated(device) / 2**30
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # Linux: kilobytes


# ------------------------------------------------------------------------------------ distribution
class Distributed:
    """Data-parallel state of this process under ``torchrun`` (or a single process without it).

    Gradients are averaged with one all-reduce per optimizer step (as stylegan2-ada does), which
    works for training loops with several forward/backward phases per step.
    """

    def __init__(self, device_name: str):
        self.world_size = int(os.environ.get("WORLD_SIZE", "1"))
        self.rank = int(os.environ.get("RANK", "0"))
        if self.world_size > 1 and not dist.is_initialized():
            backend = "nccl" if device_name != "cpu" and torch.cuda.is_available() else "gloo"
            if backend == "nccl":
                torch.cuda.set_device(int(os.environ.get("LOCAL_RANK", 0)))
            dist.init_process_group(backend=backend)

    @property
    def enabled(self) -> bool:
        return self.world_size > 1

    @property
    def is_main(self) -> bool:
        return self.rank == 0

    def broadcast_module(self, module: nn.Module) -> None:
        """Make every process start from rank 0's parameters and buffers."""
        if self.enabled:
            for tensor in list(module.parameters()) + list(module.buffers()):
                dist.broadcast(tensor.data, src=0)

    def average_gradients(self, params: list[nn.Parameter]) -> None:
        """All-reduce (mean) the gradients of ``params`` in one flat buffer; missing grads count as zero."""
        if not self.enabled:
            return
        params = [p for p in params if p.requires_grad]
        for p in params:
            if p.grad is None:
                p.grad = torch.zeros_like(p)
        flat = torch.cat([p.grad.reshape(-1) for p in params])
        dist.all_reduce(flat)
        flat /= self.world_size
        offset = 0
        for p in params:
            n = p.numel()
            p.grad.copy_(flat[offset : offset + n].view_as(p))
            offset += n

    def any(self, flag: bool, device: torch.device) -> bool:
        """True when ``flag`` is true on any process."""
        if not self.enabled:
            return flag
        t = torch.tensor([1.0 if flag else 0.0], device=device)
        dist.all_reduce(t)
        return bool(t.item() > 0)

    def gather_objects(self, obj) -> list:
        if not self.enabled:
            return [obj]
        out = [None] * self.world_size
        dist.all_gather_object(out, obj)
        return out

    def barrier(self) -> None:
        if self.enabled:
            dist.barrier()

    def close(self) -> None:
        if self.enabled and dist.is_initialized():
            dist.destroy_process_group()


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

    def has_checkpoint(self) -> bool:
        return self.checkpoint_path.is_file()

    def start(self, cfg, resume: bool) -> None:
        """Create the directory and write the resolved config; refuse to overwrite a run by accident."""
        if not resume and self.has_checkpoint():
            raise UserError(f"{self.root}: already holds a run ({CHECKPOINT_NAME}); pass --resume to continue it or choose another --out")
        self.root.mkdir(parents=True, exist_ok=True)
        self.samples_dir.mkdir(exist_ok=True)
        save_config(cfg, self.config_path)


# ------------------------------------------------------------------------------------- state codecs
def optimizer_to_state(opt: torch.optim.Optimizer) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """Optimizer -> (tensors, JSON meta): per-parameter state tensors and the param groups."""
    sd = opt.state_dict()
    tensors, scalars = {}, {}
    for index, state in sd["state"].items():
        for key, value in state.items():
            if torch.is_tensor(value):
                tensors[f"{index}.{key}"] = value
            else:
                scalars[f"{index}.{key}"] = value
    return tensors, {"param_groups": sd["param_groups"], "scalars": scalars}


def optimizer_from_state(opt: torch.optim.Optimizer, tensors: dict[str, torch.Tensor], meta: dict[str, Any]) -> None:
    """Inverse of :func:`optimizer_to_state`."""
    state: dict[int, dict[str, Any]] = {}
    for name, value in list(tensors.items()) + list(meta["scalars"].items()):
        index, _, key = name.partition(".")
        state.setdefault(int(index), {})[key] = value
    groups = []
    for group in meta["param_groups"]:
        group = dict(group)
        if "betas" in group:
            group["betas"] = tuple(group["betas"])
        groups.append(group)
    opt.load_state_dict({"state": state, "param_groups": groups})


def rng_to_state() -> dict[str, Any]:
    """JSON-serialisable RNG states of torch (CPU and CUDA), numpy and Python's ``random``."""
    np_state = np.random.get_state()
    return {
        "torch": torch.get_rng_state().tolist(),
        "cuda": [s.tolist() for s in torch.cuda.get_rng_state_all()] if torch.cuda.is_available() else [],
        "numpy": [np_state[0], np_state[1].tolist(), int(np_state[2]), int(np_state[3]), float(np_state[4])],
        "python": [random.getstate()[0], list(random.getstate()[1]), random.getstate()[2]],
    }


def rng_from_state(state: dict[str, Any]) -> None:
    torch.set_rng_state(torch.tensor(state["torch"], dtype=torch.uint8))
    if state["cuda"] and torch.cuda.is_available():
        torch.cuda.set_rng_state_all([torch.tensor(s, dtype=torch.uint8) for s in state["cuda"]])
    name, keys, pos, has_gauss, cached = state["numpy"]
    np.random.set_state((name, np.array(keys, dtype=np.uint32), pos, has_gauss, cached))
    version, internal, gauss = state["python"]
    random.setstate((version, tuple(internal), gauss))


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


# ------------------------------------------------------------------------------------------- EMA
def make_ema(module: nn.Module) -> nn.Module:
    """A frozen copy of ``module`` for the exponential moving average of its weights."""
    ema = copy.deepcopy(module).eval()
    ema.requires_grad_(False)
    return ema


def ema_beta(images_seen: int, images_per_step: int, halflife_images: float, rampup: float = 0.0) -> float:
    """Decay of the generator EMA for one step, as stylegan2-ada ramps it up.

    The half-life is ``halflife_images``, but at most ``rampup`` times the images seen so far
    (``rampup`` 0: no limit). Without the ramp-up a short run's EMA still carries most of its random
    initial weights (half-life 5000 images, 600 steps of 8 images: 51 %); with it the EMA follows the
    live generator early and averages over ever longer spans later.
    """
    halflife = float(halflife_images)
    if rampup > 0:
        halflife = min(halflife, images_seen * rampup)
    return 0.5 ** (images_per_step / max(halflife, 1e-8))


@torch.no_grad()
def ema_update(ema: nn.Module, module: nn.Module, beta: float) -> None:
    """ema <- beta * ema + (1 - beta) * module for parameters; buffers are copied."""
    for p_ema, p in zip(ema.parameters(), module.parameters()):
        p_ema.lerp_(p.detach(), 1.0 - beta)
    for b_ema, b in zip(ema.buffers(), module.buffers()):
        b_ema.copy_(b)


# ------------------------------------------------------------------------------------ checkpoints
def save_training_state(path: Path, kind: str, modules: dict[str, nn.Module], optimizers: dict[str, torch.optim.Optimizer],
                        extra_tensors: dict[str, dict[str, torch.Tensor]], meta: dict[str, Any], rng_states: list[dict[str, Any]]) -> None:
    """Write modules, optimizers, extra tensor groups, per-process RNG states and ``meta`` atomically."""
    groups: dict[str, dict[str, torch.Tensor]] = {name: m.state_dict() for name, m in modules.items()}
    optim_meta = {}
    for name, opt in optimizers.items():
        tensors, optim_meta[name] = optimizer_to_state(opt)
        groups[f"optim_{name}"] = tensors
    groups.update(extra_tensors)
    meta = {**meta, "optimizers": optim_meta, "rng": rng_states}
    save_checkpoint(path, groups, kind=kind, meta=meta)


def load_training_state(path: Path, kind: str, modules: dict[str, nn.Module], optimizers: dict[str, torch.optim.Optimizer],
                        device: torch.device) -> tuple[dict[str, dict[str, torch.Tensor]], dict[str, Any]]:
    """Load what :func:`save_training_state` wrote into ``modules`` and ``optimizers``; returns
    (all tensor groups, meta) for the caller's extra state. RNG states are not applied here."""
    groups, meta = load_checkpoint(path, kind=kind)
    for name, module in modules.items():
        if name not in groups:
            raise UserError(f"{path}: checkpoint has no '{name}' weights")
        try:
            module.load_state_dict(groups[name])
        except RuntimeError as error:
            raise UserError(f"{path}: '{name}' weights do not fit this config ({str(error).splitlines()[0]})") from None
        module.to(device)
    for name, opt in optimizers.items():
        optimizer_from_state(opt, groups.get(f"optim_{name}", {}), meta["optimizers"][name])
    return groups, meta


# ------------------------------------------------------------------------------------ NaN guard
class NonFiniteLoss(Exception):
    """A loss became NaN or infinite."""


def check_finite(logs: dict[str, torch.Tensor | float], iteration: int) -> None:
    """Raise :class:`NonFiniteLoss` naming the first non-finite value of ``logs``."""
    for name, value in logs.items():
        v = float(value.detach()) if isinstance(value, torch.Tensor) else float(value)
        if not np.isfinite(v):
            raise NonFiniteLoss(f"{name} = {v} at iteration {iteration}")


def scalars(logs: dict[str, torch.Tensor | float]) -> dict[str, float]:
    """Plain floats (rounded) of a dict of scalar tensors, for metrics.jsonl."""
    return {k: round(float(v), 6) for k, v in logs.items()}


def dumps_config(cfg) -> dict[str, Any]:
    """The config as plain JSON (for checkpoint metadata)."""
    import dataclasses

    return json.loads(json.dumps(dataclasses.asdict(cfg)))
