"""The runtime a command runs in: device selection, memory, data-parallel processes, seeding, RNG
state, the exponential moving average of weights and how a stop request reaches a training loop.

Every stage (training, inference, evaluation) picks its device with :func:`select_device` and seeds
with :func:`seed_everything`; the trainers keep RNG states in their checkpoints
(:func:`rng_to_state`, :func:`rng_from_state`) so that ``--resume`` continues exactly.
"""

from __future__ import annotations

import copy
import os
import random
import resource
import signal
import sys
import threading
import time
from typing import Any

import numpy as np
import torch
import torch.distributed as dist
from torch import nn

from mesh2tex.errors import InputError

# ----------------------------------------------------------------------------------------- threads
THREAD_VARIABLES = ("MESH2TEX_THREADS", "OMP_NUM_THREADS")


def busy_cores_now(interval: float = 0.2, stat_path: str = "/proc/stat") -> float | None:
    """Cores busy over the next ``interval`` seconds, from the kernel's CPU time counters (Linux's
    ``/proc/stat``: the share of non-idle time on its ``cpu`` line times its ``cpuN`` lines); None
    where they cannot be read."""

    def sample() -> tuple[int, int, int]:
        with open(stat_path) as stat:
            lines = stat.read().splitlines()
        values = [int(v) for v in lines[0].split()[1:9]]  # user nice system idle iowait irq softirq steal
        cores = sum(1 for line in lines if line.startswith("cpu") and line[3:4].isdigit())
        return sum(values), values[3] + values[4], cores

    try:
        total_before, idle_before, cores = sample()
        time.sleep(interval)
        total_after, idle_after, _ = sample()
    except (OSError, ValueError, IndexError):
        return None
    if total_after <= total_before or cores < 1:
        return None
    return (1.0 - (idle_after - idle_before) / (total_after - total_before)) * cores


def user_threads(environ=os.environ) -> int | None:
    """The threads the user asked for: the first of :data:`THREAD_VARIABLES` set to a whole number of at least 1,
    else None."""
    for name in THREAD_VARIABLES:
        value = environ.get(name, "")
        if value.isdigit() and int(value) >= 1:
            return int(value)
    return None


def choose_threads(cpu_count: int | None = None, load: float | None = None, environ=os.environ) -> int:
    """Threads for torch's CPU pool: the user's ``MESH2TEX_THREADS`` or ``OMP_NUM_THREADS`` when set,
    else the cores that other work leaves idle (at least 1): the busy cores of the last minute's load
    average or of the moment (:func:`busy_cores_now`), whichever is fewer.

    Why not all cores: torch's threads wait for one another at every operation, so one descheduled
    thread stalls the rest. With one competing CPU-bound process on a 2-core machine, two threads
    took 1.8x (best of 8) to 3.5x (median) the time of one thread for a 256 px render
    (docs/results/rendering.md). Why the moment too: the load average still counts a job that has just
    ended. Right after ``make install``, on an otherwise idle 2-core machine, it gave ``make demo``
    one thread, and its GAN 0.89 s per iteration instead of 0.65 with two.
    """
    chosen = user_threads(environ)
    if chosen is not None:
        return chosen
    cpu_count = cpu_count or os.cpu_count() or 1
    if load is None:
        try:
            load = os.getloadavg()[0]
        except OSError:  # not available on this platform
            load = 0.0
        if int(round(load)) > 0:  # the moment can only lower the load: measure it (0.2 s) only when that matters
            now = busy_cores_now()
            if now is not None:
                load = min(load, now)
    return max(1, min(cpu_count, cpu_count - int(round(load))))


def configure_threads() -> int:
    """Apply :func:`choose_threads` to torch; returns the count."""
    threads = choose_threads()
    torch.set_num_threads(threads)
    return threads


# ----------------------------------------------------------------------------------------- devices
def select_device(name: str) -> torch.device:
    """ "auto" (CUDA when available, else CPU), "cpu" or "cuda"; a missing GPU is a user error."""
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda" and not torch.cuda.is_available():
        raise InputError("--device cuda: no CUDA device is available (use --device cpu or auto)")
    if name not in ("cpu", "cuda"):
        raise InputError(f"--device {name}: expected auto, cpu or cuda")
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

    def mean(self, value: float, device: torch.device) -> float:
        """The mean of ``value`` over the processes."""
        if not self.enabled:
            return float(value)
        t = torch.tensor([float(value)], device=device)
        dist.all_reduce(t)
        return float(t.item()) / self.world_size

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


# ------------------------------------------------------------------------------------ stop requests
class StopAfterStep:
    """Ctrl-C and ``kill`` (SIGINT, SIGTERM) held while a training loop runs (a context manager).

    The first signal asks the loop to stop once the step in progress is done (``requested`` turns
    true; the loop raises KeyboardInterrupt between steps), so the checkpoint saved on the way out is
    the state after a whole step and a resumed run repeats the uninterrupted one exactly: a step cut
    short leaves one optimizer stepped and not the other and the random streams drawn part way. A
    second signal stops at once, as a plain Ctrl-C does. Only signals whose handler is a Python
    function are taken (Ctrl-C's, and SIGTERM where a command made ``kill`` an interrupt); ignored or
    default ones, and loops outside the main thread, are left alone.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self, announce: bool = True):
        self.announce = announce  # one line on the first signal (the main process of a distributed run)
        self.requested = False
        self._previous: dict[int, Any] = {}

    def _handle(self, signum, frame) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        if self.announce:
            print("\nmesh2tex: stopping after this step, its checkpoint saved (again to stop at once)", file=sys.stderr)

    def __enter__(self) -> "StopAfterStep":
        if threading.current_thread() is threading.main_thread():
            for signum in self.SIGNALS:
                if callable(signal.getsignal(signum)):
                    self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        self._previous.clear()


# ------------------------------------------------------------------------------------ random state
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
