"""Speckle: the high-frequency share of rendered textures, the shipped generators' against the world's materials'.

    python benchmarks/speckle.py --category chair|car [--variety boxy|real] [--seeds 0-4] [--work DIR]
                                 [--checkpoint RUN/snapshots/iterN.safetensors]
    python benchmarks/speckle.py --albedo     # the varied world's materials' albedo statistics (docs/synthetic.md)

On the held-out shapes of the shipped model's world (its card's world settings; ``--variety real``:
the same indices of the varied world, shapes the model never saw, with the materials a photo would
show), every row rendered the same way: the world's photo pipeline (``render_views`` for materials,
``render_for_comparison`` for generators, via :mod:`mesh2tex.evaluation.generation`), unlit (the texture's
albedo: faceted shading would add power of its own), at ``--resolution`` px supersampled twice, at
the world's photo cameras. The share is :func:`mesh2tex.metrics.spectrum.high_frequency_share`:
the power above ``--cutoff`` cycles per object diagonal (L*, and L*a*b* summed) on patches wholly on
the object, pooled over every view.

    world's materials   fresh draws of the world's own material sampler (``--draws`` per view): the target
    oracle              the sampler drawn again, one material per view for each seed (as a generator seed
                        paints one latent per view): how far a perfect generator's row lies from the target
    ground truth        each held-out shape's own material (one draw per shape: with 8 shapes, a noisy sample)
    generator, seed s   the shipped generator (or ``--checkpoint``'s, a candidate trained on the same
                        world), one latent per view drawn from seed s
    untrained           a freshly initialised generator of the same configuration
    flat mean colour    the world's materials' mean object colour (no power at all: share 0)

The ratio columns divide by the world's materials' share: 1 is the world's own texture scale, above
1 finer than its materials (speckle), below 1 smoother. Prepared shapes are cached in ``--work``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mesh2tex.evaluation.generation import WorldData  # noqa: E402
from mesh2tex.evaluation.generation_renders import generator_renders, ground_truth_renders, material_renders  # noqa: E402
from mesh2tex.geometry.prepare import prepare_shape  # noqa: E402
from mesh2tex.geometry.prepared import PreparedShape  # noqa: E402
from mesh2tex.metrics.spectrum import DEFAULT_CUTOFF, high_frequency_share, view_pixels_per_unit  # noqa: E402
from mesh2tex.models import load_generator  # noqa: E402
from mesh2tex.nn.generator import TextureGenerator  # noqa: E402
from mesh2tex.render import RenderSettings, composite_images  # noqa: E402
from mesh2tex.synthetic.world import WorldSpec, make_shape, sample_material, sample_views  # noqa: E402

_DRAW_STREAM = 7951  # seeds the world's material draws (the target) apart from every other stream
_ORACLE_STREAM = 7963  # seeds the oracle's draws


def parse_seeds(text: str) -> list[int]:
    """'0-4' or '0,2,5' -> seeds."""
    if "-" in text:
        low, high = text.split("-")
        return list(range(int(low), int(high) + 1))
    return [int(s) for s in text.split(",")]


def albedo_table(draws: int = 40) -> None:
    """CIELAB L* of each varied-world material on a flat 50 cm patch (chair materials at a chair's band limit,
    car materials at a car's): mean over ``draws`` draws, spread of the draws' means, mean std within a patch."""
    from kornia.color import rgb_to_lab

    from mesh2tex.synthetic import real_materials as rm
    from mesh2tex.synthetic.materials import GLASS, PAINT

    chair, car = rm.LIMIT_PER_UNIT / rm.TYPICAL_METRES["chair"], rm.LIMIT_PER_UNIT / rm.TYPICAL_METRES["car"]

    def brushed(rng):
        while not isinstance(pattern := rm.metal(rng, chair), rm.BrushedMetal):
            pass
        return pattern

    kinds = {
        "wood": lambda rng: rm.wood(rng, chair),
        "fabric": lambda rng: rm.fabric(rng, chair),
        "leather": lambda rng: rm.leather(rng, chair),
        "upholstery with seams": lambda rng: rm.cover(rng, chair, True),
        "brushed metal": brushed,
        "painted metal (car)": lambda rng: rm.painted(rng, car, PAINT[int(rng.integers(len(PAINT)))]),
        "plastic": lambda rng: rm.plastic(rng, chair),
        "tyre rubber": lambda rng: rm.Rubber(seed=int(rng.integers(99)), limit=car),
        "dark glass": lambda rng: rm.DarkGlass(
            GLASS[int(rng.integers(len(GLASS)))], float(rng.uniform(0.3, 0.9)), 1.6, car
        ),
    }
    n = 96
    y, z = np.meshgrid(np.linspace(-0.25, 0.25, n), np.linspace(-0.25, 0.25, n), indexing="ij")
    points = np.stack([np.full(n * n, 0.01), y.ravel(), z.ravel()], axis=1)
    normals = np.tile([1.0, 0.0, 0.0], (len(points), 1))
    print("| material | mean L* | spread of draws | within a patch |\n| --- | --- | --- | --- |")
    for kind, draw in kinds.items():
        means, within = [], []
        for s in range(draws):
            rgb = draw(np.random.default_rng([3, s]))(points, normals)
            lightness = rgb_to_lab(torch.tensor(rgb.T[None, :, :, None], dtype=torch.float32))[0, 0, :, 0].numpy()
            means.append(lightness.mean())
            within.append(lightness.std())
        print(f"| {kind} | {np.mean(means):.0f} | {np.std(means):.0f} | {np.mean(within):.1f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--category", choices=("chair", "car"), default="chair")
    parser.add_argument("--variety", choices=("boxy", "real"), default="boxy")
    parser.add_argument("--seeds", default="0-4", help="latent seeds of the generator rows")
    parser.add_argument("--views", type=int, default=4, help="views per held-out shape")
    parser.add_argument("--draws", type=int, default=3, help="draws of the world's material sampler per view")
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--cutoff", type=float, default=DEFAULT_CUTOFF, help="cycles per object diagonal")
    parser.add_argument("--work", default="/tmp/mesh2tex_speckle", help="prepared shapes are cached here")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--json", default="", help="also write the rows here")
    parser.add_argument(
        "--checkpoint", default="", help="a GAN checkpoint in place of the shipped model's generator (same world)"
    )
    parser.add_argument(
        "--albedo", action="store_true", help="print the varied world's materials' albedo statistics and stop"
    )
    args = parser.parse_args()
    if args.albedo:
        albedo_table()
        return
    torch.set_num_threads(args.threads)
    start = time.perf_counter()
    device = torch.device("cpu")
    card = json.loads(
        (Path(__file__).resolve().parents[1] / "mesh2tex" / "models" / args.category / "card.json").read_text()
    )
    world_settings = {k: v for k, v in card["world"].items() if k != "variety"}  # --variety picks the world
    spec = WorldSpec(category=args.category, variety=args.variety, **world_settings)
    train, held = spec.split()
    rendered = dataclasses.replace(spec, resolution=args.resolution)
    world = WorldData(
        rendered,
        Path(args.work),
        [spec.shape_name(i) for i in held],
        [spec.shape_name(i) for i in train],
        {spec.shape_name(i): i for i in range(spec.shapes)},
    )
    model = load_generator(args.checkpoint or args.category, device)
    generator = model.network
    torch.manual_seed(0)
    untrained = TextureGenerator(generator.cfg).to(device).eval().requires_grad_(False)
    work = Path(args.work) / f"{args.category}_{args.variety}"
    work.mkdir(parents=True, exist_ok=True)
    r = args.resolution
    sets: dict[str, list] = {}

    def add(row, images_masks):
        sets.setdefault(row, []).append(images_masks)

    ppu = []
    seeds = parse_seeds(args.seeds)
    for name in world.held_out:
        index = world.indices[name]
        path = work / f"{name}.npz"
        shape = make_shape(spec, index)
        if not path.exists():
            s = card["shapes"]
            prepare_shape(shape.vertices, shape.faces, face_count=s["faces"], levels=s["levels"], seed=s["seed"]).save(
                path
            )
        prepared = PreparedShape.load(path)
        views = sample_views(spec, index, args.views)
        ppu += [view_pixels_per_unit(v.distance, v.fov, r) for v in views]
        add("ground_truth", ground_truth_renders(world, name, views, r, lit=False))
        for d in range(args.draws):
            materials = [
                sample_material(spec, np.random.default_rng([_DRAW_STREAM, d, index, k]), shape)
                for k in range(len(views))
            ]
            add(f"draw_{d}", material_renders(world, name, views, materials, r, lit=False))
        for (
            seed
        ) in seeds:  # the oracle: the world's sampler drawn again, one material per view, as a generator seed paints
            materials = [
                sample_material(spec, np.random.default_rng([_ORACLE_STREAM, seed, index, k]), shape)
                for k in range(len(views))
            ]
            add(f"oracle_{seed}", material_renders(world, name, views, materials, r, lit=False))
        for seed in seeds:
            z = torch.randn(
                len(views), generator.cfg.z_dim, generator=torch.Generator().manual_seed(seed * 1000 + index)
            )
            add(
                f"seed_{seed}",
                generator_renders(
                    generator, prepared, views, r, z, device, lit=False, photo_render=RenderSettings(r, 2)
                ),
            )
        z = torch.randn(len(views), generator.cfg.z_dim, generator=torch.Generator().manual_seed(index))
        add(
            "untrained",
            generator_renders(untrained, prepared, views, r, z, device, lit=False, photo_render=RenderSettings(r, 2)),
        )
        print(f"{name} rendered ({time.perf_counter() - start:.0f} s)", file=sys.stderr)

    def measure(items, space, pixels):
        images, masks = torch.cat([a for a, _ in items]), torch.cat([b for _, b in items])
        return high_frequency_share(images, masks, args.cutoff, pixels_per_unit=pixels, space=space).share

    draws = [item for d in range(args.draws) for item in sets[f"draw_{d}"]]
    rows = {"world's materials": {s: measure(draws, s, ppu * args.draws) for s in ("L", "lab")}}
    per_seed = {seed: {s: measure(sets[f"seed_{seed}"], s, ppu) for s in ("L", "lab")} for seed in seeds}
    oracle = {seed: {s: measure(sets[f"oracle_{seed}"], s, ppu) for s in ("L", "lab")} for seed in seeds}
    trained = "generator (--checkpoint)" if args.checkpoint else "shipped generator"
    for label, values_of in (("oracle: the world's materials drawn again", oracle), (trained, per_seed)):
        for space in ("L", "lab"):
            values = [v[space] for v in values_of.values()]
            rows.setdefault(f"{label}, median of seeds", {})[space] = statistics.median(values)
            rows.setdefault(f"{label}, lowest seed", {})[space] = min(values)
            rows.setdefault(f"{label}, highest seed", {})[space] = max(values)
    rows["ground truth: the held-out shapes' own materials"] = {
        s: measure(sets["ground_truth"], s, ppu) for s in ("L", "lab")
    }
    rows["untrained generator"] = {s: measure(sets["untrained"], s, ppu) for s in ("L", "lab")}
    images, masks = torch.cat([a for a, _ in draws]), torch.cat([b for _, b in draws])
    mean = (images * masks).sum(dim=(0, 2, 3)) / masks.sum()
    flat = composite_images(mean.reshape(1, 3, 1, 1).expand_as(images), masks, 1.0)
    rows["flat mean colour"] = {
        s: high_frequency_share(flat, masks, args.cutoff, pixels_per_unit=ppu * args.draws, space=s).share
        for s in ("L", "lab")
    }
    target = rows["world's materials"]
    world_name = f"{args.category} world ({args.variety})"
    print(
        f"\nSpeckle on the {len(world.held_out)} held-out shapes of the {world_name}, {args.views} views each at {r} "
        f"px, unlit; power above {args.cutoff:g} cycles per object diagonal; generator seeds {args.seeds}; "
        f"iteration {model.iteration}; {time.perf_counter() - start:.0f} s\n"
    )
    print("| row | high-frequency share, L* | x the world's materials' | L*a*b* | x the world's materials' |")
    print("| --- | --- | --- | --- | --- |")
    for row, values in rows.items():
        ratio = {s: values[s] / max(target[s], 1e-12) for s in ("L", "lab")}
        print(f"| {row} | {values['L']:.3f} | {ratio['L']:.2f} | {values['lab']:.3f} | {ratio['lab']:.2f} |")
    print("\nper seed (L*): " + ", ".join(f"{seed}: {v['L']:.3f}" for seed, v in per_seed.items()))
    print("oracle per seed (L*): " + ", ".join(f"{seed}: {v['L']:.3f}" for seed, v in oracle.items()))
    if args.json:
        Path(args.json).write_text(
            json.dumps(
                {"rows": rows, "per_seed": per_seed, "oracle_per_seed": oracle, "settings": vars(args)}, indent=1
            )
        )


if __name__ == "__main__":
    main()
