"""Seconds per stage of building a synthetic world: shape generation, photo rendering, texture baking.

    python benchmarks/bench_synthetic.py [--category chair] [--shapes 12] [--views 8] [--resolution 128]

Prints the seconds each stage took over all shapes and the share of each; the figures are in
docs/synthetic.md. The machine's load is printed too, since a shared machine slows every stage.
"""

from __future__ import annotations

import argparse
import os
import time

import torch

from mesh2tex.synthetic.world import WorldSpec, bake_material, make_material, make_shape, render_views, sample_views


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--category", default="chair")
    parser.add_argument("--shapes", type=int, default=12)
    parser.add_argument("--views", type=int, default=8)
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--supersample", type=int, default=2)
    parser.add_argument("--texture-size", type=int, default=512)
    args = parser.parse_args()
    spec = WorldSpec(
        category=args.category,
        shapes=args.shapes,
        views=args.views,
        resolution=args.resolution,
        supersample=args.supersample,
        texture_size=args.texture_size,
    )
    bake_material(make_shape(spec, 0), make_material(spec, 0), 64)  # warm-up: imports, bundled images
    seconds = {"shapes and materials": 0.0, "photos": 0.0, "texture bake": 0.0}
    triangles = 0
    for i in range(spec.shapes):
        t = time.perf_counter()
        shape, material = make_shape(spec, i), make_material(spec, i)
        seconds["shapes and materials"] += time.perf_counter() - t
        triangles += len(shape.faces)
        t = time.perf_counter()
        render_views(shape, material, sample_views(spec, i, spec.views), spec.photo_render)
        seconds["photos"] += time.perf_counter() - t
        t = time.perf_counter()
        bake_material(shape, material, spec.texture_size)
        seconds["texture bake"] += time.perf_counter() - t
    total = sum(seconds.values())
    print(
        f"{spec.shapes} {spec.category}s (mean {triangles / spec.shapes:.0f} triangles), {spec.views} photos each at "
        f"{spec.resolution}px (x{spec.supersample} supersampled), {spec.texture_size}px textures; "
        f"torch threads {torch.get_num_threads()}, load average {os.getloadavg()[0]:.1f}"
    )
    for name, value in seconds.items():
        print(f"  {name:22s} {value:7.2f} s  ({value / total:5.1%})  {value / spec.shapes:.3f} s/shape")
    print(f"  {'total':22s} {total:7.2f} s")


if __name__ == "__main__":
    main()
