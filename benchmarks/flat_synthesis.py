"""Which style loss draws an exemplar's structure at all? Texture synthesis on a flat canvas, no mesh.

    OMP_NUM_THREADS=1 python benchmarks/flat_synthesis.py [--exemplars stripes checker bricks dots]
        [--losses ps patch sw ot] [--steps 300] [--size 128] [--seed 0] [--out FILE.json] [--figure FILE.png]

A surface adds views, foreshortening, seams and a direction field to the question; this takes them
away. For each exemplar (drawn at ``--size`` px over the unit square of its pattern) and loss, a
canvas of the same size, parametrised as ``infer synthesize``'s texels are (a pyramid of 5 levels
whose upsampled sum is the image, :class:`mesh2tex.texel_synthesis.TexelPyramid`), starts from noise
around the exemplar's mean colour and takes ``--steps`` Adam steps (rate 0.02) on the loss alone
(:func:`mesh2tex.losses.ot_style.style_loss`, whole canvas as the object).

Judged (:mod:`mesh2tex.metrics.structure`), each figure also of the *oracle*, the same pattern moved
by a quarter period-ish offset (drawn twice as large and cropped), and of two baselines, the
exemplar's *flat* mean colour and its pixels *shuffled*:
- ``swd``: the raw-patch distance to the exemplar (x1000, ``turns`` off: a canvas keeps the
  exemplar's orientation). Too close to the ``patch`` loss to judge it;
- ``ps``: the distance of the ``ps`` loss's statistics to the exemplar's. Too close to ``ps`` to judge it;
- ``coh``, ``ratio``, ``period``, ``reg``: orientation coherence and perpendicular-energy ratio in 24 px
  windows, the spectral period in px (stripes: coherence 1, ratio 0; checks: ratio near 1) and the
  regularity (the autocorrelation's strongest repeat: periodic patterns near 1, blotches near 0).
Each loss row's independent distance is the one it does not train on; seconds per step beside it.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mesh2tex.losses.ot_style import ExemplarFeatures, needs_vgg, style_loss  # noqa: E402
from mesh2tex.losses.structure import band_statistics, statistics_distance  # noqa: E402
from mesh2tex.metrics.structure import patch_swd, structure_scores  # noqa: E402
from mesh2tex.nn.vgg import load_vgg19  # noqa: E402
from mesh2tex.synthetic.exemplars import EXEMPLARS, exemplar_image  # noqa: E402
from mesh2tex.texel_synthesis import TexelPyramid  # noqa: E402

LEVELS = 5
LR = 0.02
OFFSET = 0.19  # the oracle's pattern moved by this much (pattern units), a fraction of every exemplar's period


def exemplar_tensor(name: str, size: int, offset: float = 0.0) -> torch.Tensor:
    """(1, 3, size, size) in [0, 1]: the exemplar over [offset, offset + 1]^2 of its pattern."""
    if offset == 0.0:
        image = exemplar_image(name, size)
    else:
        skip = round(offset * size)
        image = exemplar_image(name, 2 * size, extent=2.0)[skip : skip + size, skip : skip + size]
    return torch.from_numpy(image.copy()).permute(2, 0, 1)[None].float() / 255


def synthesise(target: torch.Tensor, loss: str, steps: int, seed: int, vgg) -> tuple[torch.Tensor, float]:
    """A canvas like ``target`` (1, 3, S, S) in [0, 1] optimised ``steps`` steps on ``loss``; (canvas, s/step)."""
    generator = torch.Generator().manual_seed(seed)
    exemplar = target * 2 - 1
    features = ExemplarFeatures.compute(vgg, exemplar, 4 if needs_vgg(loss) else 0)
    size = target.shape[-1]
    pyramid = TexelPyramid(size, LEVELS, exemplar.mean((0, 2, 3)), generator=generator)
    optimizer = torch.optim.Adam(pyramid.parameters(), lr=LR)
    mask = torch.ones(1, 1, size, size)
    start = time.perf_counter()
    for _ in range(steps):
        canvas = pyramid()[None]
        value = style_loss(vgg, canvas, mask, features, loss, 1024, generator)
        optimizer.zero_grad()
        value.backward()
        optimizer.step()
    seconds = (time.perf_counter() - start) / steps
    with torch.no_grad():
        return ((pyramid()[None].clamp(-1, 1) + 1) / 2), seconds


def judge(image: torch.Tensor, target: torch.Tensor) -> dict[str, float]:
    """The figures of one canvas (1, 3, S, S) in [0, 1] against the exemplar ``target``."""
    scores = structure_scores(image.double(), None, None).as_dict()
    scores["swd"] = patch_swd(image.double(), None, target.double(), turns=False)
    with torch.no_grad():
        scores["ps"] = float(statistics_distance(band_statistics(image * 2 - 1), band_statistics(target * 2 - 1)))
    return scores


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--exemplars", nargs="+", default=["stripes", "checker", "bricks", "dots"])
    parser.add_argument("--losses", nargs="+", default=["ps", "patch"])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", help="write every figure as JSON here")
    parser.add_argument("--figure", help="write the canvases as one picture here (PNG)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    unknown = [n for n in args.exemplars if n not in EXEMPLARS]
    if unknown:
        parser.error(f"unknown exemplars {unknown}; choose from {sorted(EXEMPLARS)}")
    vgg = load_vgg19(None, warn=False) if any(needs_vgg(k) for k in args.losses) else None
    results: dict = {"steps": args.steps, "size": args.size, "seed": args.seed, "exemplars": {}}
    tiles: list[list[torch.Tensor]] = []
    columns = ["exemplar", "oracle", "flat", "shuffled", *args.losses]
    for name in args.exemplars:
        target = exemplar_tensor(name, args.size)
        shuffle = torch.randperm(args.size**2, generator=torch.Generator().manual_seed(args.seed))
        canvases = {
            "oracle": exemplar_tensor(name, args.size, OFFSET),
            "flat": target.mean((2, 3), keepdim=True).expand_as(target),
            "shuffled": target.flatten(2)[:, :, shuffle].reshape(target.shape),
        }
        seconds = {}
        for loss in args.losses:
            canvases[loss], seconds[loss] = synthesise(target, loss, args.steps, args.seed, vgg)
        own = structure_scores(target.double(), None, None)
        rows = {row: judge(image, target) for row, image in canvases.items()}
        results["exemplars"][name] = {"exemplar": own.as_dict(), "rows": rows, "seconds_per_step": seconds}
        tiles.append([target[0], *(canvases[c][0] for c in columns[1:])])
        print(
            f"\n{name}: exemplar coherence {own.coherence:.2f}, ratio {own.ratio:.2f}, period {own.period:.1f} px, "
            f"regularity {own.regularity:.2f}" + "".join(f"; {k} {v:.3f} s/step" for k, v in seconds.items())
        )
        print("| row | swd | ps | coh | ratio | period | reg |")
        print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
        for row, s in rows.items():
            print(
                f"| {row} | {s['swd']:.0f} | {s['ps']:.2f} | {s['coherence']:.2f} | {s['ratio']:.2f} | "
                f"{s['period']:.1f} | {s['regularity']:.2f} |"
            )
        if args.out:
            Path(args.out).write_text(json.dumps(results, indent=1))
        if args.figure:
            write_figure(Path(args.figure), tiles, columns)
    return 0


def write_figure(path: Path, rows: list[list[torch.Tensor]], columns: list[str]) -> None:
    """A grid of (3, S, S) tiles in [0, 1], one row per exemplar, the ``columns`` named above them."""
    from PIL import Image, ImageDraw

    side, label, gap = rows[0][0].shape[-1], 14, 4
    image = Image.new("RGB", ((side + gap) * len(columns), label + (side + gap) * len(rows)), "white")
    draw = ImageDraw.Draw(image)
    for c, title in enumerate(columns):
        draw.text((c * (side + gap) + 3, 1), title, fill="black")
    for r, tiles in enumerate(rows):
        for c, tile in enumerate(tiles):
            pixels = (tile.clamp(0, 1).permute(1, 2, 0).numpy() * 255 + 0.5).astype("uint8")
            image.paste(Image.fromarray(pixels), (c * (side + gap), label + r * (side + gap)))
    path.parent.mkdir(parents=True, exist_ok=True)
    image.save(path)


if __name__ == "__main__":
    raise SystemExit(main())
