"""What the mask network's second look sees: for each photo, the photo, the network's probability from one
look at the whole photo and with the zoom pass (:func:`mesh2tex.transfer.mask.network_probability`), cut
around the object (the first look's square, grown by half) so that a far object's edges show.

    python benchmarks/mask_looks.py --checkpoint chair PHOTO.jpg [PHOTO.jpg ...] --out FILE.png [--passes zoom]

The photos of docs/results/transfer.md's figure are ``outside_transfer.py --variants far --images DIR``'s
``*_far.jpg``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.nca_structure import write_figure  # noqa: E402

SIDE = 192  # the figure's tiles


def cut(image: np.ndarray, box: tuple[int, int, int]) -> torch.Tensor:
    """(3, SIDE, SIDE) in [0, 1]: ``image`` (H, W, 3) or (H, W) in [0, 1] cut to the square ``box`` (top, left,
    side; white beyond the photo) and resized (:func:`mesh2tex.render.crop_square`)."""
    from mesh2tex.render import crop_square

    image = image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)
    tensor = torch.from_numpy(np.ascontiguousarray(image, dtype=np.float32)).permute(2, 0, 1)[None]
    return crop_square(tensor, box, SIDE, fill=1.0)[0].clamp(0, 1)


def main() -> int:
    import cv2

    from mesh2tex.models import MODEL_FILES, is_model_name, models_root
    from mesh2tex.render import object_box
    from mesh2tex.transfer.mask import MASK_PASSES, network_probability

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("photos", nargs="+")
    parser.add_argument("--checkpoint", default="chair", help="a shipped model's name or a mask checkpoint")
    parser.add_argument("--passes", nargs="+", default=["zoom"], choices=MASK_PASSES)
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    checkpoint = args.checkpoint
    if is_model_name(checkpoint):
        checkpoint = str(models_root() / checkpoint / MODEL_FILES["mask"])
    rows = []
    for path in args.photos:
        rgb = cv2.cvtColor(cv2.imread(path), cv2.COLOR_BGR2RGB)
        once = network_probability(checkpoint, rgb, passes=())
        again = network_probability(checkpoint, rgb, passes=tuple(args.passes))
        if not (once >= 0.5).any():
            print(f"{path}: the first look finds nothing; left out")
            continue
        box = object_box(once >= 0.5, 0.25)  # the first look's square, grown by half
        tiles = [cut(rgb.astype(np.float32) / 255, box), cut(once, box), cut(again, box)]
        rows.append((Path(path).stem, tiles))
        print(f"{path}: the first look's square grown by half, {box[2]} px of {rgb.shape[0]} x {rgb.shape[1]}")
    write_figure(Path(args.out), rows, ["photo", "one look", "+".join(args.passes)])
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
