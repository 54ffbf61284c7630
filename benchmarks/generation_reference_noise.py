"""How far apart sets of the same textures lie under the generation protocol's object SWD.

    python benchmarks/generation_reference_noise.py --world WORLD [--resolution 64] [--seeds 3] [--threads 2]

On a synthetic world (``mesh2tex prepare synthetic``), the figures behind the protocol's choice of
reference (:mod:`mesh2tex.evaluation.generation`, docs/gan.md):

    photo set halves          the training photos of one half of the training shapes against the other
                              half's: how far two samples of a few materials each lie apart
    fresh vs fresh            two fresh photo sets (new materials on every photo) against each other
    training photos vs fresh  the photo set the GAN learns from against a fresh photo set: how far a
                              generator that copied its training photos would stay from the world's textures
    own materials, straight   the training shapes' own materials at their photos' cameras, rendered at
                              the evaluation resolution, against the photos (the same textures, another
                              image pipeline)
    own materials, as photos  the same rendered as the world renders its photos and resized as they are
                              read: the patch sampling alone

Each figure is the mean object SWD over ``--seeds`` patch samplings (x1000, lower is closer).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mesh2tex.evaluation.generation import read_world  # noqa: E402
from mesh2tex.evaluation.generation_renders import fresh_photo_set, ground_truth_renders, on_white  # noqa: E402
from mesh2tex.metrics.generation import object_set_swd  # noqa: E402
from mesh2tex.photos import list_images, load_set  # noqa: E402
from mesh2tex.render import RenderSettings  # noqa: E402
from mesh2tex.synthetic.world import make_material, make_shape, render_views, sample_views  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--world", required=True)
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    world = read_world(args.world)
    r = args.resolution
    photos, masks = load_set(world.root / "images", "image", r, 1.0, masks=list_images(world.root / "masks", "mask"))
    shape_of = [stem.rsplit("_", 1)[0] for stem in list_images(world.root / "images", "image")]
    first_half = torch.tensor([name in set(world.train[: len(world.train) // 2]) for name in shape_of])

    def distance(a: tuple[torch.Tensor, torch.Tensor], b: tuple[torch.Tensor, torch.Tensor]) -> float:
        return sum(object_set_swd(*a, *b, seed=s) for s in range(args.seeds)) / args.seeds

    def own_materials(as_photos: bool) -> tuple[torch.Tensor, torch.Tensor]:
        images, image_masks = [], []
        for name in world.train:
            index = world.indices[name]
            views = sample_views(world.spec, index, world.spec.views)
            if as_photos:
                image, mask = ground_truth_renders(world, name, views, r)
            else:
                out = render_views(
                    make_shape(world.spec, index), make_material(world.spec, index), views, RenderSettings(r, 2)
                )
                image, mask = on_white(out["rgb"], out["mask"])
            images.append(image)
            image_masks.append(mask)
        return torch.cat(images), torch.cat(image_masks)

    fresh, fresh_again = fresh_photo_set(world, r, seed=0), fresh_photo_set(world, r, seed=1)
    figures = {
        f"photo set halves ({len(world.train) // 2} vs {len(world.train) - len(world.train) // 2} materials)": distance(
            (photos[first_half], masks[first_half]), (photos[~first_half], masks[~first_half])
        ),
        f"fresh vs fresh ({fresh[0].shape[0]} materials each)": distance(fresh, fresh_again),
        "training photos vs fresh": distance((photos, masks), fresh),
        "own materials, straight at the evaluation resolution, vs photos": distance(
            own_materials(False), (photos, masks)
        ),
        "own materials, as photos, vs photos": distance(own_materials(True), (photos, masks)),
    }
    print(f"{world.root}: {world.spec.category}, {len(world.train)} training shapes, {photos.shape[0]} photos, {r} px")
    for name, value in figures.items():
        print(f"{name:66s} {value:7.1f}")


if __name__ == "__main__":
    main()
