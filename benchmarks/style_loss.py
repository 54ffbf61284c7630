"""Seconds per texture-transfer style-loss step (forward + backward) at the paper's settings.

Global loss: the whole render at 3 scales x 5 VGG19 layers against precomputed photo Grams.
Patch loss: 2 NOC-guided 64x64 patch pairs at 3 scales. Prints one line per loss and device, and
the ratio of the patch step to the global step measured in the same process.

    python benchmarks/style_loss.py [--resolution 128] [--repeats 5] [--device cpu|cuda]
"""

import argparse
import time
import warnings

import torch

from mesh2tex.losses.style import global_style_loss, patch_style_loss, sample_patch_pairs, style_grams
from mesh2tex.nn.vgg import load_vgg19


def timed(step, repeats, device):
    step()  # warm-up
    if device == "cuda":
        torch.cuda.synchronize()
    start = time.perf_counter()
    for _ in range(repeats):
        step()
    if device == "cuda":
        torch.cuda.synchronize()
    return (time.perf_counter() - start) / repeats


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    args = parser.parse_args()
    torch.manual_seed(0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        vgg = load_vgg19(device=args.device)
    size = args.resolution
    rows, cols = torch.meshgrid(torch.arange(size), torch.arange(size), indexing="ij")
    mask = ((rows - size / 2) ** 2 + (cols - size / 2) ** 2 <= (0.4 * size) ** 2).float()[None, None].to(args.device)
    noc = (
        torch.stack([rows / size, cols / size, torch.full_like(rows, 0.5, dtype=torch.float)], -1)
        .float()
        .to(args.device)
    )
    photo = torch.rand(1, 3, size, size, device=args.device) * 2 - 1
    render = (torch.rand(1, 3, size, size, device=args.device) * 2 - 1).requires_grad_()
    with torch.no_grad():
        target = style_grams(vgg, photo, mask)

    def global_step():
        global_style_loss(vgg, render, mask, target_grams=target).backward()

    def patch_step():
        pairs = sample_patch_pairs(mask[0, 0], mask[0, 0], 2, noc, noc)
        patch_style_loss(vgg, render, mask, photo, mask, pairs).backward()

    seconds_global = timed(global_step, args.repeats, args.device)
    seconds_patch = timed(patch_step, args.repeats, args.device)
    name = torch.cuda.get_device_name() if args.device == "cuda" else f"cpu ({torch.get_num_threads()} threads)"
    print(f"device: {name}, resolution {size}, VGG19 {vgg.source}")
    print(f"global style loss step: {seconds_global:.3f} s")
    print(
        f"patch style loss step (2 x 64x64): {seconds_patch:.3f} s  (ratio to global "
        f"{seconds_patch / seconds_global:.2f})"
    )
    print(
        "transfer style cost at 100 + 300 iterations: "
        f"{100 * (seconds_global + seconds_patch) + 300 * seconds_patch:.1f} s"
    )


if __name__ == "__main__":
    main()
