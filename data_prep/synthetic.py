"""``mesh2tex prepare synthetic``: build the synthetic world the project trains, tests and demos on.

Layout of ``--out`` (``<s>`` a shape name such as ``chair_0003``, ``<k>`` a two-digit view number):

    index.json                 settings (with ``variety`` when it is not the default 'boxy'), the train/query
                               split, every shape (design choices, its family in a varied world, material),
                               every photo and query with its camera
    meshes/<s>.obj             watertight mesh, normalised frame (bbox centre 0, diagonal 1), y up,
                               front +z; one OBJ group per part (seat, leg, body, wheel, ...)
    textured/<s>.glb           the same shape with its ground-truth material baked into a UV texture
    images/<s>_<k>.png         "photos" of the training shapes: random pose, background and light
    masks/<s>_<k>.png          their object masks (0 / 255)
    queries/<s>_<k>.png        photos of held-out shapes (never in images/), with
    queries/<s>_<k>_mask.png   mask,
    queries/<s>_<k>_noc.png    ground-truth NOC map (NOC = position + 0.5, times 255; 0 on background),
    queries/<s>_<k>.json       sidecar: shape, mesh, pose (orbit_camera convention), light, files
    preview.png                a contact sheet: photos, then queries beside their NOC maps
    log.jsonl                  one JSON line per shape built

Deterministic for a seed. Every file is written atomically, so a re-run skips what is finished.
A folder holding a world of other settings, or other files, is refused; ``--overwrite`` replaces a
world of other settings (its entries above are removed first) and builds beside other files, as
long as none of them has a name of the layout above.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
from PIL import Image

from mesh2tex.errors import UserError
from mesh2tex.io.atomic import write_json
from mesh2tex.io.images import save_png
from mesh2tex.io.outputs import remove_outputs, user_entries
from mesh2tex.progress import JsonLines, progress_bar

FORMAT = "mesh2tex-synthetic-world"
GENERATOR_VERSION = 1  # bump when a change makes different files for the same settings
CAMERA_CONVENTION = (
    "mesh2tex.render.orbit_camera: degrees, y up, camera at distance*(cos(el)sin(az), sin(el), cos(el)cos(az)) "
    "looking at the origin; the object's front faces +z (azimuth 0 sees the front)"
)
NOC_CONVENTION = (
    "NOC = vertex position + 0.5 in the normalised frame (bbox centre 0, diagonal 1); PNG stores "
    "NOC*255, 0 off the mask"
)


def spec_from_args(args):
    from mesh2tex.synthetic.world import WorldSpec

    checks = [
        (args.shapes >= 2, "--shapes must be at least 2 (training shapes and at least one query shape)"),
        (args.shapes <= 100_000, "--shapes must be at most 100000"),
        (1 <= args.views <= 10_000, "--views must be between 1 and 10000"),
        (1 <= args.query_views <= 10_000, "--query-views must be between 1 and 10000"),
        (0 <= args.seed < 2**63, "--seed must be in [0, 2^63)"),
        (16 <= args.resolution <= 2048, "--resolution must be between 16 and 2048"),
        (64 <= args.texture_size <= 8192, "--texture-size must be between 64 and 8192"),
        (-89 <= args.elevation[0] <= args.elevation[1] <= 89, "--elevation needs -89 <= MIN <= MAX <= 89"),
        (0 <= args.query_shapes < args.shapes, "--query-shapes must leave at least one training shape"),
    ]
    for ok, message in checks:
        if not ok:
            raise UserError(message)
    return WorldSpec(
        category=args.category,
        shapes=args.shapes,
        views=args.views,
        seed=args.seed,
        resolution=args.resolution,
        query_shapes=args.query_shapes,
        query_views=args.query_views,
        elevation_min=float(args.elevation[0]),
        elevation_max=float(args.elevation[1]),
        texture_size=args.texture_size,
        variety=args.variety,
    )


def _settings(spec) -> dict:
    return {"generator_version": GENERATOR_VERSION, **spec.to_dict()}


# The entries of a world's folder (the layout of the module docstring).
WORLD_ENTRIES = ("index.json", "meshes", "textured", "images", "masks", "queries", "preview.png", "log.jsonl")


def _check_output(output: Path, settings: dict, overwrite: bool = False) -> None:
    """Refuse to mix two worlds in one folder: an existing index.json must have the same settings.
    ``overwrite``: a world of other settings is removed (its entries only), and a folder of other
    files is built into when none of them is named like a world's entry."""
    index_path = output / "index.json"
    if output.exists() and not output.is_dir():
        raise UserError(f"{output}: exists and is not a folder")
    if index_path.exists():
        try:
            existing = json.loads(index_path.read_text())
        except (OSError, json.JSONDecodeError):
            raise UserError(f"{index_path}: unreadable; remove the folder or choose another --out") from None
        if existing.get("format") != FORMAT:
            raise UserError(f"{index_path}: not a synthetic world index; choose another --out")
        if existing.get("settings") != settings:
            changed = sorted(k for k in settings if existing.get("settings", {}).get(k) != settings[k])
            if not overwrite:
                raise UserError(
                    f"{output}: holds a world built with other settings ({', '.join(changed)}); pass --overwrite to "
                    f"replace it, or choose another --out"
                )
            remove_outputs(output, WORLD_ENTRIES)
    elif output.is_dir() and user_entries(output):
        if not overwrite:
            raise UserError(
                f"{output}: folder is not empty and holds no synthetic world (no index.json); pass --overwrite to "
                f"build the world beside its files, or choose another --out"
            )
        clashing = [name for name in WORLD_ENTRIES if (output / name).exists()]
        if clashing:
            raise UserError(
                f"{output}: holds {', '.join(clashing)} of no synthetic world; --overwrite replaces only a world's "
                f"own files: move them or choose another --out"
            )


def _photo_record(spec, view, shape_name: str, k: int, query: bool) -> dict:
    stem = f"{shape_name}_{k:02d}"
    folder = "queries" if query else "images"
    record = {
        "shape": shape_name,
        "image": f"{folder}/{stem}.png",
        "mask": f"queries/{stem}_mask.png" if query else f"masks/{stem}.png",
    }
    if query:
        record.update({"noc": f"queries/{stem}_noc.png", "sidecar": f"queries/{stem}.json"})
    record.update(asdict(view))
    record["light"] = list(view.light)
    return record


def plan(spec) -> dict:
    """The whole index (without per-shape details): every photo and query with its view, from the seed alone."""
    from mesh2tex.synthetic.world import sample_views

    train, held_out = spec.split()
    images, queries = [], []
    for i in train:
        images += [
            _photo_record(spec, v, spec.shape_name(i), k, False)
            for k, v in enumerate(sample_views(spec, i, spec.views))
        ]
    for i in held_out:
        queries += [
            _photo_record(spec, v, spec.shape_name(i), k, True)
            for k, v in enumerate(sample_views(spec, i, spec.query_views, query=True))
        ]
    return {
        "format": FORMAT,
        "settings": _settings(spec),
        "complete": False,
        "camera_convention": CAMERA_CONVENTION,
        "noc_convention": NOC_CONVENTION,
        "split": {
            "train_shapes": [spec.shape_name(i) for i in train],
            "query_shapes": [spec.shape_name(i) for i in held_out],
        },
        "shapes": [],
        "images": images,
        "queries": queries,
    }


def build_shape(spec, index: int, output: Path, records: list[dict], query: bool) -> dict:
    """Write the mesh, the textured GLB and the photos (or queries) of shape ``index`` that are missing."""
    from mesh2tex.io.assets import save_glb, save_obj
    from mesh2tex.synthetic.solids import PART_NAMES
    from mesh2tex.synthetic.world import PhotoSetup, bake_material, make_material, make_shape, render_views

    name = spec.shape_name(index)
    shape = make_shape(spec, index)
    material = make_material(spec, index)
    mesh_path, glb_path = output / "meshes" / f"{name}.obj", output / "textured" / f"{name}.glb"
    wrote = []
    if not mesh_path.exists():
        save_obj(mesh_path, shape.vertices, shape.faces, [PART_NAMES[p] for p in shape.face_parts])
        wrote.append("mesh")
    if not glb_path.exists():
        baked = bake_material(shape, material, spec.texture_size)
        save_glb(glb_path, baked.vertices, baked.faces, baked.uv, baked.texture, name=name)
        wrote.append("textured")

    def finished(record):
        files = [record["image"], record["mask"]] + ([record["noc"], record["sidecar"]] if query else [])
        return all((output / f).exists() for f in files)

    todo = [r for r in records if not finished(r)]
    if todo:
        views = [
            PhotoSetup(**{k: (tuple(r[k]) if k == "light" else r[k]) for k in PhotoSetup.__dataclass_fields__})
            for r in todo
        ]
        rendered = render_views(shape, material, views, spec.photo_render)
        for b, record in enumerate(todo):
            save_png(output / record["image"], rendered["rgb"][b])
            save_png(output / record["mask"], rendered["mask"][b])
            if query:
                save_png(output / record["noc"], rendered["noc"][b])
                sidecar = {key: value for key, value in record.items() if key != "sidecar"}
                sidecar.update(
                    {
                        "mesh": f"meshes/{name}.obj",
                        "textured": f"textured/{name}.glb",
                        "resolution": spec.resolution,
                        "camera_convention": CAMERA_CONVENTION,
                        "noc_convention": NOC_CONVENTION,
                    }
                )
                write_json(output / record["sidecar"], sidecar)
        wrote.append(f"{len(todo)} {'queries' if query else 'photos'}")
    return {
        "name": name,
        "split": "query" if query else "train",
        "mesh": f"meshes/{name}.obj",
        "textured": f"textured/{name}.glb",
        "triangles": int(len(shape.faces)),
        "parts": shape.part_names,
        "design": shape.params,
        "material": material.describe(),
        "wrote": wrote,
    }


def write_preview(output: Path, index: dict, columns: int = 8, rows: int = 4) -> Path:
    """``preview.png``: photos of different training shapes; the last row, queries beside their NOC maps."""
    from mesh2tex.synthetic.world import contact_sheet

    by_shape: dict[str, list[dict]] = {}
    for record in index["images"]:
        by_shape.setdefault(record["shape"], []).append(record)
    photos = []
    for round_ in range(max(len(r) for r in by_shape.values())):  # one view of each shape, then the next view
        photos += [records[round_] for records in by_shape.values() if round_ < len(records)]
    queries = index["queries"][: columns // 2]
    files = [r["image"] for r in photos[: columns * (rows - 1)]] + [f for q in queries for f in (q["image"], q["noc"])]
    images = [np.asarray(Image.open(output / f).convert("RGB")) for f in files]
    path = output / "preview.png"
    save_png(path, contact_sheet(images, columns))
    return path


def run(args) -> int:
    spec = spec_from_args(args)
    output = Path(args.out)
    _check_output(output, _settings(spec), args.overwrite)
    index = plan(spec)
    write_json(output / "index.json", index)
    log = JsonLines(output / "log.jsonl")
    train, held_out = spec.split()
    started = time.time()
    shapes = []
    with progress_bar(total=spec.shapes, desc=f"synthetic {spec.category}", unit="shape") as bar:
        for i in train + held_out:
            query = i in held_out
            name = spec.shape_name(i)
            records = [r for r in (index["queries"] if query else index["images"]) if r["shape"] == name]
            t0 = time.time()
            record = build_shape(spec, i, output, records, query)
            log.write(
                {
                    "shape": name,
                    "split": record["split"],
                    "wrote": record["wrote"],
                    "seconds": round(time.time() - t0, 3),
                }
            )
            shapes.append({k: v for k, v in record.items() if k != "wrote"})
            bar.update(1)
    index.update({"shapes": shapes, "complete": True})
    write_json(output / "index.json", index)
    write_preview(output, index)
    print(
        f"{output}: {len(train)} training shapes with {len(index['images'])} photos, {len(held_out)} query shapes with "
        f"{len(index['queries'])} queries ({time.time() - started:.1f} s)"
    )
    return 0
