"""Open a GLB that mesh2tex wrote in Blender, and check that Blender shows what mesh2tex rendered.

    python benchmarks/blender_check.py GLB [GLB ...] [--blender blender] [--azimuth 30] [--elevation 20]
                                      [--distance 2.5] [--fov 40] [--size 256] [--out DIR]

For each GLB: Blender (headless, ``benchmarks/blender_scene.py``) imports it with its own glTF
importer and renders the base-colour texture unlit (emission, Cycles) from an orbit camera; mesh2tex's
renderer (``mesh2tex.evaluation.render_for_comparison``, albedo) renders the same file from the same
camera. Printed per file: what Blender found (meshes, UV layers, smooth shading and custom normals,
the base-colour texture's size and colour space), the intersection over union of the two object masks
(geometry and camera agree), and the mean absolute difference of the colours on the pixels both cover
(texture, UVs and colour space agree), in 0-255 levels. ``--out`` keeps both renders side by side.
Needs Blender on PATH (Debian/Ubuntu: ``apt install blender``); tested with 3.4.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mesh2tex.evaluation.compare import render_for_comparison  # noqa: E402
from mesh2tex.evaluation.surfaces import textured_surface  # noqa: E402
from mesh2tex.io.assets import load_glb  # noqa: E402
from mesh2tex.render import RenderSettings  # noqa: E402
from mesh2tex.synthetic.world import PhotoSetup  # noqa: E402

SCENE = Path(__file__).resolve().parent / "blender_scene.py"


def blender_render(blender: str, glb: Path, folder: Path, args) -> tuple[np.ndarray, dict]:
    """Blender's render (S, S, 4) uint8 RGBA and its report on the file."""
    png, report = folder / f"{glb.stem}_blender.png", folder / f"{glb.stem}_blender.json"
    cmd = [
        blender,
        "-b",
        "--factory-startup",
        "-noaudio",
        "-P",
        str(SCENE),
        "--",
        str(glb),
        str(png),
        str(report),
        str(args.azimuth),
        str(args.elevation),
        str(args.distance),
        str(args.fov),
        str(args.size),
    ]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    if result.returncode != 0 or not png.is_file():
        sys.exit(f"{glb}: Blender failed (exit {result.returncode}):\n{result.stdout[-2000:]}{result.stderr[-2000:]}")
    return np.asarray(Image.open(png).convert("RGBA")), json.loads(report.read_text())


def mesh2tex_render(glb: Path, args) -> tuple[np.ndarray, np.ndarray]:
    """mesh2tex's albedo render (S, S, 3) uint8 and its object mask (S, S) bool."""
    vertices, faces, uv, image = load_glb(glb)
    view = PhotoSetup(args.azimuth, args.elevation, args.distance, args.fov, (0.0, 1.0, 0.0), 1.0, "solid", 0)
    out = render_for_comparison(
        textured_surface(vertices, faces, uv, image), [view], RenderSettings(args.size, 2, "albedo")
    )
    rgb = (out.rgb[0].permute(1, 2, 0).clamp(0, 1).numpy() * 255 + 0.5).astype(np.uint8)
    return rgb, out.mask[0, 0].numpy() > 0.5


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("glb", nargs="+", type=Path)
    parser.add_argument("--blender", default="blender")
    parser.add_argument("--azimuth", type=float, default=30.0)
    parser.add_argument("--elevation", type=float, default=20.0)
    parser.add_argument("--distance", type=float, default=2.5)
    parser.add_argument("--fov", type=float, default=40.0)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument(
        "--out", type=Path, help="folder for the side-by-side images (mesh2tex | Blender | difference x4), on black"
    )
    args = parser.parse_args()
    blender = shutil.which(args.blender)
    if blender is None:
        sys.exit(f"{args.blender}: Blender not found (Debian/Ubuntu: apt install blender)")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for glb in args.glb:
            theirs, report = blender_render(blender, glb, Path(tmp), args)
            ours, ours_mask = mesh2tex_render(glb, args)
            their_mask = theirs[..., 3] >= 128
            both = ours_mask & their_mask
            iou = both.sum() / max(1, (ours_mask | their_mask).sum())
            # the object's edge pixels mix object and background differently in the two renderers: compare the interior
            interior = both & np.roll(both, 1, 0) & np.roll(both, -1, 0) & np.roll(both, 1, 1) & np.roll(both, -1, 1)
            difference = np.abs(ours.astype(np.int16) - theirs[..., :3].astype(np.int16))
            mean_difference = difference[interior].mean() if interior.any() else float("nan")
            for mesh in report["meshes"]:
                textures = [t for m in mesh["materials"] for t in m["base_color_textures"]]
                print(
                    f"{glb}: Blender {report['blender']} imported {mesh['vertices']} vertices, {mesh['polygons']} "
                    "polygons; "
                    f"UV layers {mesh['uv_layers']}; smooth polygons {mesh['smooth_polygons']}/{mesh['polygons']}; "
                    f"custom normals {mesh['custom_normals']}; base-colour textures {textures}"
                )
            print(
                f"{glb}: object masks IoU {iou:.4f}; mean |mesh2tex - Blender| on {int(interior.sum())} interior "
                f"pixels {mean_difference:.2f} of 255 (95th percentile {np.percentile(difference[interior], 95):.0f})"
            )
            if args.out:
                row = np.concatenate(
                    [
                        ours * ours_mask[..., None],
                        theirs[..., :3] * their_mask[..., None],
                        np.clip(difference * 4, 0, 255).astype(np.uint8),
                    ],
                    axis=1,
                )
                Image.fromarray(row).save(args.out / f"{glb.stem}_blender_check.png")


if __name__ == "__main__":
    main()
