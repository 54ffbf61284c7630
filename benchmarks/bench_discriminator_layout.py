"""Milliseconds of one discriminator pass, channels-last (what ``Discriminator.forward`` does on a CPU)
against the same layers on contiguous activations, timed in alternation in one process.

    python benchmarks/bench_discriminator_layout.py [--images 8] [--resolution 128] [--repeats 20] [--threads N]

Two passes are timed, as the GAN step runs them: forward and backward to the weights (D main) and
forward and backward to the input only (G main, the discriminator's weights frozen). Prints the
median of each and the speed-up, contiguous / channels-last.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mesh2tex.nn.discriminator import Discriminator  # noqa: E402


def contiguous_forward(d: Discriminator, images: torch.Tensor) -> torch.Tensor:
    """The discriminator's layers on contiguous activations (its forward before the layout change)."""
    x = d.fromrgb(images.contiguous())
    for block in d.blocks:
        x = block(x.contiguous())
    return d.out(d.fc(d.conv(d.minibatch_std(x.contiguous())).flatten(1))).squeeze(1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--images", type=int, default=8)
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--threads", type=int, default=0, help="torch CPU threads (0: torch's default)")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    d = Discriminator(args.resolution)
    images = torch.rand(args.images, 3, args.resolution, args.resolution) * 2 - 1
    layouts = {"contiguous": lambda x: contiguous_forward(d, x), "channels-last": d}

    def weights_pass(forward) -> None:
        d.requires_grad_(True)
        forward(images).sum().backward()

    def input_pass(forward) -> None:
        d.requires_grad_(False)
        x = images.clone().requires_grad_(True)
        torch.autograd.grad(forward(x).sum(), x)

    print(f"discriminator at {args.resolution} px, {args.images} images, threads {torch.get_num_threads()}")
    for name, run in (("backward to the weights", weights_pass), ("backward to the input only", input_pass)):
        times = {layout: [] for layout in layouts}
        for i in range(args.repeats + 2):
            order = list(layouts.items())
            for layout, forward in order[::-1] if i % 2 else order:
                start = time.perf_counter()
                run(forward)
                if i >= 2:  # two warm-up rounds
                    times[layout].append((time.perf_counter() - start) * 1e3)
        medians = {layout: statistics.median(t) for layout, t in times.items()}
        print(
            f"{name}: contiguous {medians['contiguous']:.1f} ms, channels-last {medians['channels-last']:.1f} ms, "
            f"speed-up {medians['contiguous'] / medians['channels-last']:.2f}"
        )


if __name__ == "__main__":
    main()
