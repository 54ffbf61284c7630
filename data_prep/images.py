"""``mesh2tex prepare images``: square crops and masks of the photos the texture GAN learns from.

For every image under ``--input`` (recursive) the object's mask comes from, in order: a mask file of
the same stem under ``--masks``, the image's alpha channel, or an estimate (OpenCV GrabCut seeded
with the image border as background). The image is cropped to a square around the mask (with a
margin), padded with white where the square leaves the photo, and resized to ``--size``. Output:
``DIR/images/<name>.png``, ``DIR/masks/<name>.png`` and ``DIR/index.json`` (per input: status,
reason, mask source, mask coverage). Exit status 0 when every image succeeded, 2 when any failed.

A file it would write that is already there stops the command before any work, unless
``--overwrite``: then the earlier preparation is replaced, and its images that this one does not
write again (listed in the earlier ``index.json``) are moved aside with the rest of what it replaces
(:func:`mesh2tex.io.outputs.move_aside`), so that the folder holds this run's set only.

Each photo gets the checks of every photo set (:func:`mesh2tex.photos.read_set_photo`: readable, a
photo's kind of image, at least 8 pixels a side, a mask file of its size that is a mask); a rejected
one is a failed entry of the index with its reason, and the others are prepared.
"""

from __future__ import annotations

import json
import os
import re
import sys
import time
from pathlib import Path

from mesh2tex.errors import InputError, UserError
from mesh2tex.io.atomic import write_json
from mesh2tex.io.images import is_image_file, save_png
from mesh2tex.io.outputs import guard_outputs, move_aside, walked
from mesh2tex.photos import estimate_mask, read_set_photo, square_crop
from mesh2tex.progress import progress_bar


def find_mask_file(masks_dir: Path | None, relative: Path) -> Path | None:
    """The mask of a photo: same relative path and stem under ``masks_dir``, any image suffix; or None."""
    if masks_dir is None:
        return None
    folder = masks_dir / relative.parent
    for candidate in sorted(folder.glob(f"{relative.stem}.*")) if folder.is_dir() else []:
        if is_image_file(candidate):
            return candidate
    flat = sorted(p for p in masks_dir.glob(f"{relative.stem}.*") if is_image_file(p))
    return flat[0] if flat else None


def prepare_image(path: Path, relative: Path, name: str, output: Path, size: int, masks_dir: Path | None) -> dict:
    """Crop one photo and its mask into ``output``; returns its index record (never raises for bad input)."""
    start = time.perf_counter()
    record = {"source": str(path), "name": name}
    try:
        mask_file = find_mask_file(masks_dir, relative)
        rgb, alpha = read_set_photo(path, mask_file)  # the checks every photo set gets: size, kind, mask
        if mask_file is not None:
            mask, source = alpha >= 128, f"file {mask_file}"
        elif alpha is not None and alpha.min() < 128:
            mask, source = alpha >= 128, "alpha"
        else:
            mask, source = estimate_mask(rgb), "estimated (GrabCut)"
        if not mask.any():
            raise UserError(f"{path}: the object's mask is empty ({source})")
        image, out_mask = square_crop(rgb, mask, size)
        save_png(output / "images" / f"{name}.png", image)
        save_png(output / "masks" / f"{name}.png", out_mask)
        record.update(status="ok", reason="", mask=source, coverage=round(float(out_mask.mean()), 4))
    except (UserError, InputError) as error:  # the mask check here, or the library reading the photo
        record.update(status="failed", reason=str(error))
    except Exception as error:  # unforeseen: reported, the batch goes on
        record.update(status="failed", reason=f"{path}: unexpected {error.__class__.__name__}: {error}")
    record["seconds"] = round(time.perf_counter() - start, 3)
    return record


def earlier_outputs(output: Path, kept: set[str]) -> list[str]:
    """``--overwrite``: the images and masks an earlier preparation in ``output`` wrote (as its
    ``index.json`` lists them) that this one will not write again, as paths in ``output``; they are
    moved aside with the rest of what the new set replaces, and nothing else in the folder is touched."""
    try:
        earlier = json.loads((output / "index.json").read_text(encoding="utf-8"))["images"]
    except (OSError, ValueError, KeyError, TypeError):
        return []
    names = []
    for record in earlier if isinstance(earlier, list) else []:
        name = record.get("name") if isinstance(record, dict) else None
        if (
            isinstance(name, str)
            and name not in kept
            and "/" not in name
            and os.sep not in name
            and not name.startswith(".")
        ):
            names += [f"{folder}/{name}.png" for folder in ("images", "masks")]
    return names


def run(args) -> int:
    input_dir, output = Path(args.input), Path(args.out)
    if not input_dir.is_dir():
        raise UserError(
            f"{input_dir}: {'is a file; --input takes a folder of photos' if input_dir.is_file() else 'no such folder'}"
        )
    if args.size < 8:
        raise UserError(f"--size must be at least 8 (got {args.size})")
    masks_dir = Path(args.masks) if args.masks else None
    if masks_dir is not None and not masks_dir.is_dir():
        raise UserError(f"{masks_dir}: no such mask folder")
    photos = []
    for root, dirs, files in os.walk(input_dir):
        dirs[:] = walked(dirs)  # not what --overwrite moved aside
        photos.extend(Path(root) / f for f in sorted(files) if is_image_file(f))
    if masks_dir is not None:
        photos = [p for p in photos if masks_dir.resolve() not in p.resolve().parents]
    if not photos:
        raise UserError(
            f"{input_dir}: no images ({' '.join(s for s in ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.webp'))})"
        )
    names, used = [], set()
    for path in photos:
        name = re.sub(r"[^A-Za-z0-9_.-]", "_", str(path.relative_to(input_dir).with_suffix("")).replace(os.sep, "_"))
        while name in used:
            name += "_"
        used.add(name)
        names.append(name)
    # read before guard_outputs moves index.json aside
    earlier = earlier_outputs(output, set(names)) if args.overwrite else []
    guard_outputs(
        output,
        ["index.json"] + [f"{folder}/{name}.png" for name in names for folder in ("images", "masks")],
        args.overwrite,
    )
    move_aside(output, earlier)
    output.mkdir(parents=True, exist_ok=True)
    records = []
    for path, name in progress_bar(list(zip(photos, names)), desc="prepare images", unit="image"):
        record = prepare_image(path, path.relative_to(input_dir), name, output, args.size, masks_dir)
        if record["status"] == "failed":
            print(f"mesh2tex: failed: {record['reason']}", file=sys.stderr)
        records.append(record)
    failed = sum(r["status"] == "failed" for r in records)
    write_json(
        output / "index.json",
        {
            "settings": {"size": int(args.size), "masks": str(masks_dir) if masks_dir else None},
            "images": records,
            "ok": len(records) - failed,
            "failed": failed,
        },
    )
    print(
        f"prepared {len(records) - failed} of {len(records)} images into {output}"
        + (f"; failed: {failed}" if failed else "")
    )
    return 2 if failed else 0
