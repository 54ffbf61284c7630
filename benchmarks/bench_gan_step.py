"""Seconds per training iteration and peak memory of ``train gan`` at its default configuration.

    python benchmarks/bench_gan_step.py [--iters 8] [--device auto|cpu|cuda] [--faces 6144] [--levels 5]
                                        [--batch 2] [--views 4] [--resolution 128] [--config YAML] [--threads N]
                                        [--previous REV] [--check N]

Two procedural chairs are prepared (quad hierarchy of --faces faces), the trainer is built with the
default config (or --config) and a random photo set, one warm-up iteration runs, then --iters timed
iterations. Iterations with the lazy regularisers (path length every 4, R1 every 16) are slower;
the script prints the mean over main-only iterations, over iterations with the path-length term,
the amortised mean of the schedule, the plain mean over all timed iterations (which amortises every
lazy term, the diversity term's included, when --iters is a multiple of their intervals), and the
ratio to the 2 s target.

``--previous REV`` builds a second trainer from the ``mesh2tex`` and ``train`` packages of git
revision REV (``benchmarks/previous.py``) on the same shapes and photos, and times the two in
alternation (which goes first swaps every iteration), so that both see the same machine load; it
prints both figures and the speed-up, previous / current. ``--check N`` (with ``--previous``) first
runs N iterations of each from the same seed and prints the relative difference of every logged
scalar: the two versions should compute the same losses. ``--previous-config YAML`` gives the
previous version its own config (default: --config's), so that ``--previous HEAD --config lazy.yaml``
times two settings of one revision side by side.

``--flops`` also counts the floating-point operations of a main-only iteration and of one with the
path-length term (``torch.utils.flop_counter.FlopCounterMode``: matmuls and convolutions, forward and
backward), measures what this process sustains on a 2048^3 float32 matmul and on a 3x3 convolution of
the discriminators' shapes, and prints the step's achieved rate and its ratio to each. Work the
counter does not see is named and timed apart: drawing the scene (the rasterizer, a few passes of
integer and gather work per view) and everything else (gathers and scatters of the face
convolutions, elementwise ops, Python) as the remainder. ``--profile`` then splits a main-only step's
wall time by what its operators do (:data:`OP_CATEGORIES`, torch.profiler's self time per operator),
the rest being Python and the autograd engine.
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from previous import Revision  # noqa: E402  (this folder)

from mesh2tex.geometry.prepare import prepare_shape  # noqa: E402
from mesh2tex.synthetic.shapes import generate_shape  # noqa: E402

TARGET_SECONDS = 2.0


def sustained_rates(reps: int = 5) -> dict[str, float]:
    """GFLOP/s this process sustains now: a 2048^3 float32 matmul, and a 3x3 convolution of 64 channels on
    8 images of 64 x 64 (the discriminators' middle blocks)."""

    def rate(fn, flops: float) -> float:
        fn()  # warm-up
        start = time.perf_counter()
        for _ in range(reps):
            fn()
        return flops * reps / (time.perf_counter() - start) / 1e9

    a, b = torch.randn(2048, 2048), torch.randn(2048, 2048)
    x, w = torch.randn(8, 64, 64, 64), torch.randn(64, 64, 3, 3)
    return {
        "matmul 2048^3": rate(lambda: a @ b, 2 * 2048**3),
        "conv 3x3, 64 ch, 8 x 64^2": rate(
            lambda: torch.nn.functional.conv2d(x, w, padding=1), 2 * 8 * 64 * 64 * 64 * 64 * 9
        ),
    }


def flop_account(version: "Version", trainer, seconds: dict[bool, float]) -> None:
    """Count one main-only iteration and one with the path-length term, time the scene drawing (the
    rasterizer), and print the achieved rate against the sustained ones (``seconds``: {has path length: s})."""
    from torch.utils.flop_counter import FlopCounterMode

    counted: dict[bool, float] = {}
    while len(counted) < 2:
        greg = any(phase == "Greg" for phase, _ in trainer.loss.phases(trainer.iteration))
        with FlopCounterMode(display=False) as counter:
            version.step(trainer)
        counted.setdefault(greg, counter.get_total_flops())
    scene = []
    for _ in range(3):
        start = time.perf_counter()
        trainer.draw_scene()
        scene.append(time.perf_counter() - start)
    rates = sustained_rates()
    print("\nfloating-point work (matmuls and convolutions, forward and backward; FlopCounterMode):")
    for greg, flops in sorted(counted.items()):
        s = seconds.get(greg, float("nan"))
        achieved = flops / s / 1e9
        shares = ", ".join(f"{achieved / r:.2f} of the {name}'s {r:.0f}" for name, r in rates.items())
        print(
            f"  {'with path-length reg' if greg else 'main phases only'}: {flops / 1e9:.1f} GFLOP in {s:.3f} s = "
            f"{achieved:.1f} GFLOP/s; {shares} GFLOP/s sustained"
        )
    main_s = seconds.get(False, float("nan"))
    drawn = statistics.median(scene)
    print(
        f"  not counted: the scene (rasterizing {trainer.cfg.batch * trainer.cfg.views} views) {drawn:.3f} s = "
        f"{drawn / main_s:.0%} of a main-only step; at the matmul's rate the counted work would take "
        f"{counted[False] / 1e9 / rates['matmul 2048^3']:.3f} s, "
        f"the rest ({max(main_s - drawn - counted[False] / 1e9 / rates['matmul 2048^3'], 0.0):.3f} s) is gathers and "
        "scatters, elementwise ops and Python"
    )


# Where a step's time goes, by what the operators do (torch.profiler's self time of each aten operator).
# The first category whose names hold the operator's wins; anything else of aten is elementwise arithmetic.
OP_CATEGORIES = (
    (
        "matmuls and convolutions (the counted FLOPs)",
        ("mm", "addmm", "bmm", "baddbmm", "matmul", "linear", "conv", "addmv"),
    ),
    (
        "gathers and scatters (face neighbourhoods, rows)",
        ("index", "gather", "scatter", "take", "embedding", "segment"),
    ),
    (
        "copies, layout and allocation",
        (
            "copy",
            "clone",
            "contiguous",
            "_to_",
            "cat",
            "stack",
            "permute",
            "reshape",
            "view",
            "expand",
            "narrow",
            "slice",
            "select",
            "transpose",
            "pad",
            "empty",
            "zero",
            "ones",
            "full",
            "fill",
            "as_strided",
            "unsqueeze",
            "squeeze",
            "flatten",
            "split",
            "chunk",
            "unbind",
            "detach",
            "alias",
        ),
    ),
    (
        "reductions, pooling and sorting",
        (
            "sum",
            "mean",
            "amax",
            "amin",
            "max",
            "min",
            "norm",
            "pool",
            "var",
            "std",
            "softmax",
            "logsumexp",
            "cumsum",
            "sort",
            "topk",
            "bincount",
            "nonzero",
            "unique",
        ),
    ),
)


def op_category(name: str) -> str:
    """The :data:`OP_CATEGORIES` entry of an aten operator's name (``aten::index_select`` -> gathers and scatters)."""
    op = name.split("::", 1)[-1]
    for category, words in OP_CATEGORIES:
        if any(word in op for word in words):
            return category
    return "elementwise arithmetic (activations, adds, products, comparisons)"


def profile_account(version: "Version", trainer, steps: int = 3) -> None:
    """Run ``steps`` main-only iterations under torch.profiler and print their wall time split by
    :func:`op_category` (operators' self time on the calling thread), the rest being Python and the
    autograd engine's own work. Profiling slows every operator a little: the shares, not the seconds,
    are what this tells."""
    from torch.profiler import ProfilerActivity, profile

    wall, done, by_category, by_op = 0.0, 0, {}, {}
    while done < steps:
        if any(not phase.endswith("main") for phase, _ in trainer.loss.phases(trainer.iteration)):
            version.step(trainer)  # a regulariser's iteration runs extra phases: not profiled
            continue
        with profile(activities=[ProfilerActivity.CPU]) as prof:
            start = time.perf_counter()
            version.step(trainer)
            wall += time.perf_counter() - start
        done += 1
        for event in prof.key_averages():
            if event.key.startswith("aten::"):
                category = op_category(event.key)
                by_category[category] = by_category.get(category, 0.0) + event.self_cpu_time_total / 1e6
                by_op[event.key] = by_op.get(event.key, 0.0) + event.self_cpu_time_total / 1e6
    print(
        f"\nwhere a main-only step's time goes (torch.profiler, {steps} steps, {wall / steps:.3f} s each while "
        "profiled):"
    )
    for category, seconds in sorted(by_category.items(), key=lambda item: -item[1]):
        print(f"  {category:66s} {seconds / steps:7.3f} s  {seconds / wall:5.1%}")
    rest = wall - sum(by_category.values())
    print(f"  {'Python, autograd bookkeeping and the profiler':66s} {rest / steps:7.3f} s  {rest / wall:5.1%}")
    print("the ten slowest operators (self time per step):")
    for name, seconds in sorted(by_op.items(), key=lambda item: -item[1])[:10]:
        print(f"  {name:40s} {seconds / steps:7.3f} s  {op_category(name)}")


class Version:
    """One version of the trainer: today's packages, or a :class:`Revision`'s."""

    def __init__(self, name: str, revision: Revision | None = None):
        self.name, self.revision = name, revision
        with self.active():
            from mesh2tex.train import runs

            # TrainGanConfig through train.gan, its home in older revisions and an import there today
            from mesh2tex.train.gan import GanTrainer, TrainGanConfig

            from mesh2tex.config import load_config
        self.load_config, self.runs, self.GanTrainer, self.TrainGanConfig = (
            load_config,
            runs,
            GanTrainer,
            TrainGanConfig,
        )

    def active(self):
        return self.revision.active() if self.revision else contextlib.nullcontext()

    def trainer(self, args, shapes, folder: str, config: str | None = None):
        """A fresh trainer (its constructor seeds every generator) on ``shapes`` and a random photo set."""
        with self.active():
            cfg = self.load_config(
                self.TrainGanConfig,
                config,
                {
                    "batch": args.batch,
                    "views": args.views,
                    "resolution": args.resolution,
                    "device": args.device,
                    "iters": 10**6,
                },
            )
            cfg.generator.input_features = shapes[0].face_features.shape[1]
            device = self.runs.select_device(cfg.device)
            rng = np.random.default_rng(0)
            images = torch.from_numpy(rng.integers(0, 256, (32, 4, cfg.resolution, cfg.resolution), dtype=np.uint8))
            return self.GanTrainer(
                cfg, shapes, images, self.runs.RunDirectory(folder), device, self.runs.Distributed("cpu")
            )

    def step(self, trainer) -> tuple[float, dict[str, float]]:
        """Seconds of one iteration and its logged scalars."""
        with self.active():
            if trainer.device.type == "cuda":
                torch.cuda.synchronize()
            start = time.perf_counter()
            logs = trainer.step()
            if trainer.device.type == "cuda":
                torch.cuda.synchronize()
            return time.perf_counter() - start, logs


def check(versions: list[Version], args, shapes, tmp: str) -> None:
    """Run ``args.check`` seeded iterations of each version; print the largest difference of each logged scalar."""
    logs, weights = {}, {}
    for version in versions:
        trainer = version.trainer(args, shapes, f"{tmp}/check-{version.name}", args.config)
        logs[version.name] = [version.step(trainer)[1] for _ in range(args.check)]
        weights[version.name] = {
            name: module.state_dict()
            for name, module in (
                ("generator", trainer.generator),
                ("d_field", trainer.d_field),
                ("d_proxy", trainer.d_proxy),
            )
        }
        del trainer
    old, new = (logs[v.name] for v in versions)
    print(
        f"agreement of the logged scalars (rounded to 1e-6), |previous - current| relative to |previous|: in the first "
        f"iteration (same weights) and the largest over {args.check} (Adam's normalised steps amplify rounding "
        "differences)"
    )
    for key in old[0]:
        a = np.array([step[key] for step in old if key in step])
        b = np.array([step[key] for step in new if key in step])
        rel = np.abs(a - b) / np.maximum(np.abs(a), 1e-12)
        print(f"  {key:18s} first {rel[0]:.2g}  largest {rel.max():.2g}")
    a, b = (weights[v.name] for v in versions)
    for name in a:
        diff = max(float((a[name][k].float() - b[name][k].float()).abs().max()) for k in a[name])
        print(f"  {name} weights after {args.check} iterations: largest |previous - current| {diff:.2g}")


def summary(times: list[tuple[float, bool]], pl_interval: int) -> tuple[float, float, float, int, int]:
    """(main-only mean, path-length mean, amortised mean, n main, n path-length) of (seconds, had path length) pairs."""
    main_only = [s for s, pl in times if not pl]
    with_pl = [s for s, pl in times if pl]
    m = statistics.mean(main_only) if main_only else float("nan")
    p = statistics.mean(with_pl) if with_pl else m
    return m, p, m + (p - m) / pl_interval, len(main_only), len(with_pl)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--iters", type=int, default=8)
    parser.add_argument("--device", default="auto")
    parser.add_argument("--faces", type=int, default=6144)
    parser.add_argument("--levels", type=int, default=5, help="levels of the quad hierarchy (the demo: 4)")
    parser.add_argument("--batch", type=int, default=2)
    parser.add_argument("--views", type=int, default=4)
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--config")
    parser.add_argument("--threads", type=int, default=0, help="torch CPU threads (0: torch's default)")
    parser.add_argument("--previous", default="", help="also time the trainer of this git revision, in alternation")
    parser.add_argument("--previous-config", help="with --previous: that version's config (default: --config)")
    parser.add_argument(
        "--check",
        type=int,
        default=0,
        help="with --previous: compare the logged losses of this many seeded iterations first",
    )
    parser.add_argument(
        "--flops",
        action="store_true",
        help="count the step's FLOPs and compare with the sustained matmul and conv rates",
    )
    parser.add_argument(
        "--profile", action="store_true", help="split a main-only step's time by what its operators do (torch.profiler)"
    )
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    if args.check and not args.previous:
        parser.error("--check needs --previous")

    t0 = time.perf_counter()
    shapes = []
    for i in range(2):
        mesh = generate_shape("chair", np.random.default_rng(i))
        shapes.append(prepare_shape(mesh.vertices, mesh.faces, face_count=args.faces, levels=args.levels, seed=0))
    print(f"prepared 2 chairs in {time.perf_counter() - t0:.1f} s; finest faces {[s.face_counts[0] for s in shapes]}")

    versions = [Version("current")]
    if args.previous:
        versions.insert(0, Version(f"previous {args.previous}", Revision(args.previous)))
    with tempfile.TemporaryDirectory() as tmp:
        if args.check:
            check(versions, args, shapes, tmp)
        configs = [args.previous_config or args.config, args.config][-len(versions) :]
        trainers = [v.trainer(args, shapes, f"{tmp}/{i}", c) for i, (v, c) in enumerate(zip(versions, configs))]
        first = trainers[-1]
        params = sum(p.numel() for p in first.generator.parameters())
        dparams = sum(p.numel() for p in first.d_field.parameters())
        print(
            f"device {first.device}, threads {torch.get_num_threads()}, generator {params / 1e6:.2f} M parameters, "
            f"each discriminator {dparams / 1e6:.2f} M"
        )
        for version, trainer in zip(versions, trainers):
            version.step(trainer)  # warm-up (iteration 0 runs every regulariser)
        times: list[list[tuple[float, bool]]] = [[] for _ in versions]
        for i in range(args.iters):
            due = {phase for phase, _ in first.loss.phases(first.iteration)}
            order = list(range(len(versions)))
            for k in order[::-1] if i % 2 else order:
                times[k].append((versions[k].step(trainers[k])[0], "Greg" in due))
        peak = versions[-1].runs.peak_memory_gb(first.device)
        if args.flops:
            m, p, *_ = summary(times[-1], first.cfg.loss.pl_interval)
            flop_account(versions[-1], first, {False: m, True: p})
        if args.profile:
            profile_account(versions[-1], first)
    pl_interval = first.cfg.loss.pl_interval
    for version, t in zip(versions, times):
        m, p, amortised, n_m, n_p = summary(t, pl_interval)
        print(
            f"{version.name}: seconds per iteration: main phases {m:.3f} (n={n_m}), with path-length reg {p:.3f} "
            f"(n={n_p}), amortised {amortised:.3f}, mean of all {len(t)} {statistics.mean(s for s, _ in t):.3f}"
        )
    if len(versions) == 2:
        old, new = (summary(t, pl_interval) for t in times)
        mean_old, mean_new = (statistics.mean(s for s, _ in t) for t in times)
        print(
            f"speed-up previous / current: main phases {old[0] / new[0]:.2f}, with path-length reg "
            f"{old[1] / new[1]:.2f}, amortised {old[2] / new[2]:.2f}, mean of all {mean_old / mean_new:.2f}"
        )
    both = " (both versions)" if len(versions) == 2 else ""
    print(f"peak memory {peak:.2f} GB ({'CUDA allocator' if first.device.type == 'cuda' else 'process RSS'}){both}")
    print(f"ratio to the {TARGET_SECONDS:.0f} s target: {summary(times[-1], pl_interval)[2] / TARGET_SECONDS:.2f}")


if __name__ == "__main__":
    main()
