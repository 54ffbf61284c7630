"""Generators on meshes the synthetic world did not make: how far their textures are from the world's
photos, beside the untrained generator, the world's own materials and a flat colour.

    python benchmarks/outside_generation.py --world WORK/world --checkpoint chair [--checkpoint
    RUN/checkpoint.safetensors]
        [--category chair] [--views 8] [--latents 8] [--repeats 2]

The meshes: the hand-modelled chairs (or cars) of ``benchmarks/world_reference_shapes.py``, made
apart from the world's code, and for chairs the stool of ``tests/user_assets.py``; each is read as a
user's file is (``infer generate --mesh FILE``: turned y-up, prepared with the model's hierarchy).
Each is seen from ``--views`` of the world's photo cameras and lights, rendered as the world renders
its photos (the generation protocol's photo pipeline, ``mesh2tex.evaluation.generation``), and read as the
photo set is. Rows, one texture per view:

  trained     each checkpoint's generator, a latent per view
  untrained   the same architecture with its initial weights
  materials   the world's own material sampler (``sample_material``), the mesh's faces labelled by
              height (the upper 40 % as seat, the rest as legs for a chair; body and wheels for a
              car): the world's textures on these meshes, with guessed parts. A baseline, not an
              oracle: no ground truth exists for these meshes, and a part layout guessed by height
              is not the world's
  flat        the photo set's mean object colour

Distance: object SWD (x 1000) to a fresh photo set of the world (its training shapes, every photo
with a new material of the world's sampler; the generation protocol's reference), averaged over
``--repeats`` draws; ratio: the row's distance over the untrained generator's. Diversity: the
spread of the mean object colour over ``--latents`` latents at one view, over the photo set's spread
of mean colours across shapes (the generation protocol's measure).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))


def outside_meshes(category: str, folder: Path) -> list[tuple[str, Path]]:
    """[(name, file)] of the meshes the world did not make, written as PLY files."""
    from world_reference_shapes import reference_shapes

    meshes = list(reference_shapes(category))
    if category == "chair":
        from user_assets import stool

        meshes.append(("stool", stool()))
    files = []
    for name, mesh in meshes:
        path = folder / f"{name}.ply"
        mesh.export(path)
        files.append((name, path))
    return files


def height_parts(vertices: np.ndarray, faces: np.ndarray, category: str, car_cues: bool = False) -> np.ndarray:
    """(T,) part ids by height: the upper 40 % of the mesh seat (chair) or body (car), the rest leg or wheel.
    ``car_cues`` (cars, y up and the front towards +z): a car's front and back as a photo shows them, the
    world's car materials' glass and lights on guessed places: the cabin above 62 % of the height (its
    material is glass on the sides and paint where it faces up), and on the body between 30 and 55 % of the
    height, faces looking along the length (|n_z| > 0.6) in the outer half of the width, head lights at the
    front end and tail lights at the back."""
    from mesh2tex.synthetic.solids import PART_ID

    centres = vertices[faces].mean(axis=1)
    low, high = vertices[:, 1].min(), vertices[:, 1].max()
    share = (centres[:, 1] - low) / (high - low)
    if category == "chair":
        return np.where(share > 0.6, PART_ID["seat"], PART_ID["leg"])
    parts = np.where(share > 0.25, PART_ID["body"], PART_ID["wheel"])
    if not car_cues:
        return parts
    corners = vertices[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    half_width = np.abs(vertices[:, 0]).max()
    # |n_z|: the faces' winding is the remesher's; which end a face lies on says front or back
    lamp = (share > 0.3) & (share < 0.55) & (np.abs(centres[:, 0]) > 0.5 * half_width) & (np.abs(normals[:, 2]) > 0.6)
    parts = np.where(share > 0.62, PART_ID["cabin"], parts)
    parts = np.where(lamp & (centres[:, 2] > 0), PART_ID["headlight"], parts)
    return np.where(lamp & (centres[:, 2] < 0), PART_ID["taillight"], parts)


@torch.no_grad()
def main() -> None:
    from mesh2tex.evaluation.compare import render_for_comparison
    from mesh2tex.evaluation.generation import read_world
    from mesh2tex.evaluation.generation_renders import (
        draw_key,
        fresh_photo_set,
        generator_renders,
        photo_set_spread,
        read_as_photos,
        seeded_generator,
    )
    from mesh2tex.evaluation.surfaces import material_surface
    from mesh2tex.geometry.prepared import quads_to_triangles
    from mesh2tex.metrics.generation import colour_spread, mean_object_lab, object_set_swd
    from mesh2tex.models import load_generator
    from mesh2tex.nn.generator import TextureGenerator
    from mesh2tex.photos import list_images, load_set
    from mesh2tex.render import RenderSettings, composite_images
    from mesh2tex.synthetic.world import sample_material, sample_views
    from mesh2tex.texturing import load_shape

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--world", required=True)
    parser.add_argument("--checkpoint", action="append", required=True)
    parser.add_argument("--category", default="chair", choices=["chair", "car"])
    parser.add_argument("--views", type=int, default=8)
    parser.add_argument("--latents", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    device = torch.device("cpu")
    world = read_world(args.world)
    side = world.spec.resolution
    models = {str(c): load_generator(c, device) for c in args.checkpoint}
    first = next(iter(models.values()))
    resolution = first.resolution
    torch.manual_seed(0)
    untrained = TextureGenerator(first.network.cfg).eval().requires_grad_(False)
    generators = [(label, model.network, model.lit) for label, model in models.items()]
    photos, photo_masks = load_set(
        world.root / "images", "image", resolution, 1.0, masks=list_images(world.root / "masks", "mask")
    )
    photo_names = list(list_images(world.root / "images", "image"))
    photo_mean = (photos * photo_masks).sum(dim=(0, 2, 3)) / photo_masks.sum().clamp_min(1.0)
    photo_spread = photo_set_spread(world, photos, photo_masks, photo_names)
    folder = Path(tempfile.mkdtemp(prefix="outside-"))
    views = sample_views(world.spec, world.indices[world.held_out[0]], args.views)
    rows: dict[str, list] = {}
    spread: dict[str, list] = {}
    meshes = outside_meshes(args.category, folder)
    for index, (name, path) in enumerate(meshes):
        shape, _ = load_shape(path, first.network, first.face_count(), output_mesh="prepared")  # one working copy
        for label, generator, lit in [*generators, ("untrained", untrained, first.lit)]:
            for repeat in range(args.repeats):
                z = torch.randn(args.views, generator.cfg.z_dim, generator=seeded_generator(draw_key(0, repeat), 1))
                rows.setdefault((label, repeat), []).append(
                    generator_renders(
                        generator, shape, views, resolution, z, device, lit, photo_render=RenderSettings(side, 2)
                    )
                )
            z = torch.randn(args.latents, generator.cfg.z_dim, generator=torch.Generator().manual_seed(7))
            images, masks = generator_renders(
                generator,
                shape,
                [views[0]] * args.latents,
                resolution,
                z,
                device,
                lit,
                photo_render=RenderSettings(side, 2),
            )
            spread.setdefault(label, []).append(colour_spread(mean_object_lab(images, masks)))
        vertices, faces = shape.vertices[0], quads_to_triangles(shape.quads[0])
        parts = height_parts(vertices, faces, args.category)
        for repeat in range(args.repeats):
            images, masks = [], []
            for k, view in enumerate(views):
                material = sample_material(world.spec, np.random.default_rng([repeat, 99, index, k]))
                out = render_for_comparison(
                    material_surface(vertices, faces, parts, material), [view], RenderSettings(side, 2)
                )
                images.append(composite_images(out.rgb, out.mask, 1.0))
                masks.append(out.mask)
            rows.setdefault(("materials", repeat), []).append(
                read_as_photos(torch.cat(images), torch.cat(masks), resolution)
            )
            generated_masks = rows[(generators[0][0], repeat)][-1][1]
            rows.setdefault(("flat", repeat), []).append(
                (
                    composite_images(
                        photo_mean.reshape(1, 3, 1, 1).expand(len(views), 3, resolution, resolution),
                        generated_masks,
                        1.0,
                    ),
                    generated_masks,
                )
            )
        print(f"{name}: rendered", flush=True)
    labels = [g[0] for g in generators] + ["untrained", "materials", "flat"]
    distance = {label: [] for label in labels}
    for repeat in range(args.repeats):
        reference, reference_masks = fresh_photo_set(world, resolution, draw_key(0, repeat))
        for label in labels:
            images = torch.cat([i for i, _ in rows[(label, repeat)]])
            masks = torch.cat([m for _, m in rows[(label, repeat)]])
            distance[label].append(object_set_swd(images, masks, reference, reference_masks, seed=repeat))
    untrained_distance = float(np.mean(distance["untrained"]))
    print(
        f"\n{len(meshes)} {args.category} meshes from outside the world, {args.views} views each, "
        f"{args.repeats} draws; photo set spread {photo_spread:.2f}"
    )
    print(f"{'row':44s} {'object SWD':>10s} {'vs untrained':>12s} {'diversity':>9s}")
    for label in labels:
        d = float(np.mean(distance[label]))
        diversity = f"{np.mean(spread[label]) / photo_spread:9.2f}" if label in spread else f"{'':9s}"
        print(f"{label:44s} {d:10.1f} {d / untrained_distance:12.2f} {diversity}")


if __name__ == "__main__":
    main()
