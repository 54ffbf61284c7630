"""A gallery of a synthetic world's shapes: the first N shapes of a world, each with its ground-truth
material, rendered by the world's own renderer (``mesh2tex.synthetic.world.render_views``) from the
front-left, captioned with its family.

    python benchmarks/world_gallery.py --category chair --variety real --out docs/images/world_real_chairs.png
    python benchmarks/world_gallery.py --category car --variety real --out docs/images/world_real_cars.png

The shapes are those of ``prepare synthetic --category C --variety V --seed S`` (shape i of the world is
shape i here), so the gallery shows what a world of that seed trains on.
"""

from __future__ import annotations

import argparse

import numpy as np
from PIL import Image, ImageDraw

from mesh2tex.io.images import save_png
from mesh2tex.render import RenderSettings
from mesh2tex.synthetic.variety import generate_varied_shape
from mesh2tex.synthetic.world import PhotoSetup, WorldSpec, contact_sheet, make_material, make_shape, render_views


def gallery_tile(spec: WorldSpec, index: int, size: int, family: str | None = None) -> tuple[np.ndarray, str]:
    """(size, size, 3) uint8: shape ``index`` of the world over white, with its family (or style) written under
    it; and that caption. With ``family``, a shape of that family drawn from the seed and index instead."""
    if family is None:
        shape = make_shape(spec, index)
    else:
        shape = generate_varied_shape(spec.category, np.random.default_rng([spec.seed, index]), "real", family)
    material = make_material(spec, index)
    chair = spec.category == "chair"
    view = PhotoSetup(
        azimuth=35.0 if chair else 40.0,
        elevation=20.0 if chair else 25.0,
        distance=1.6 if chair else 1.3,
        fov=40.0,
        light=(0.45, 0.75, 0.48),
        ambient=0.45,
        background="solid",
        background_seed=0,
    )
    rendered = render_views(shape, material, [view], RenderSettings(size, 3))
    mask = rendered["mask"][0][..., None] > 0
    tile = np.where(mask, rendered["rgb"][0], 255).astype(np.uint8)
    image = Image.fromarray(tile)
    params = shape.params
    caption = params.get("family", params.get("style", params.get("legs", "")))
    ImageDraw.Draw(image).text((4, size - 13), f"{index}: {caption}", fill=(60, 60, 60))
    return np.asarray(image), str(caption)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--category", choices=("chair", "car"), default="chair")
    parser.add_argument("--variety", choices=("boxy", "real"), default="real")
    parser.add_argument("--seed", type=int, default=0, help="the world's seed")
    parser.add_argument("--count", type=int, default=32, help="shapes shown (the world's first ones)")
    parser.add_argument("--columns", type=int, default=8)
    parser.add_argument("--size", type=int, default=160, help="side of each tile in pixels")
    parser.add_argument(
        "--family", default=None, help="only shapes of this family of the varied world (e.g. office, suv)"
    )
    parser.add_argument("--out", required=True, help="PNG to write")
    args = parser.parse_args()
    spec = WorldSpec(category=args.category, seed=args.seed, variety=args.variety, shapes=max(args.count, 2))
    tiles, captions = zip(*(gallery_tile(spec, i, args.size, args.family) for i in range(args.count)))
    save_png(args.out, contact_sheet(list(tiles), args.columns, gap=2, fill=235))
    families = {name: captions.count(name) for name in sorted(set(captions))}
    print(
        f"{args.out}: {args.count} {args.category}s of the {args.variety} world, seed {args.seed}; families {families}"
    )


if __name__ == "__main__":
    main()
