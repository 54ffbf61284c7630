"""The options of ``mesh2tex prepare shapes|images|synthetic``, built without importing the preparation
code (``--help`` stays fast); each command's ``run()`` is in its own module. ``--output`` is the old
spelling of ``--out`` and still works. The preparation runs on the CPU (QuadriFlow, GrabCut, the
synthetic world's small renders), so these commands take no ``--device``."""

from __future__ import annotations

import argparse

from mesh2tex.options import add_out, add_overwrite, add_up


def shapes(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--input", nargs="+", required=True, metavar="PATH", help="mesh files and/or folders (searched recursively)"
    )
    add_out(parser, "folder for <name>.npz files and index.json", alias="--output")
    parser.add_argument("--faces", type=int, default=6144, help="quads of the finest level")
    parser.add_argument(
        "--levels", type=int, default=5, help="levels, each with a quarter of the faces of the finer one"
    )
    parser.add_argument("--workers", type=int, default=1, help="shapes prepared in parallel processes")
    parser.add_argument("--seed", type=int, default=0, help="QuadriFlow seed")
    parser.add_argument(
        "--max-seconds",
        type=float,
        help="time budget of one shape; past it the shape fails with that reason (default: none)",
    )
    parser.add_argument(
        "--max-memory-gb", type=float, help="memory budget of each QuadriFlow process of a shape, GiB (default: none)"
    )
    add_up(parser)
    add_overwrite(
        parser,
        help="prepare every shape again, replacing its .npz and index entry (without it, shapes already prepared "
        "in --out with the same settings are kept and skipped)",
    )


def images(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--input", required=True, metavar="DIR", help="folder of photos (searched recursively)")
    add_out(parser, "folder for images/, masks/ and index.json", alias="--output")
    parser.add_argument("--size", type=int, default=256, help="side of the square output images in pixels")
    parser.add_argument(
        "--masks",
        metavar="DIR",
        default=None,
        help="folder of mask images named like the photos (any image suffix; default: the alpha channel, else a "
        "GrabCut estimate)",
    )
    add_overwrite(
        parser,
        "replace an earlier preparation in --out (its images and masks, index.json); without it, a file that would "
        "be replaced stops the command before any work",
    )


def synthetic(parser: argparse.ArgumentParser) -> None:
    add_out(parser, "folder of the world (created; an unfinished one is resumed)", alias="--output")
    parser.add_argument("--category", choices=("chair", "car"), default="chair", help="shape category")
    parser.add_argument("--shapes", type=int, default=12, help="shapes in all, query shapes included")
    parser.add_argument("--views", type=int, default=8, help="photos per training shape")
    parser.add_argument("--seed", type=int, default=0, help="master seed")
    parser.add_argument("--resolution", type=int, default=128, help="photo size in pixels")
    parser.add_argument(
        "--query-shapes", type=int, default=0, help="shapes held out for queries/ (default: a quarter, at least 1)"
    )
    parser.add_argument("--query-views", type=int, default=2, help="query photos per held-out shape")
    parser.add_argument(
        "--elevation",
        type=float,
        nargs=2,
        default=(5.0, 35.0),
        metavar=("MIN", "MAX"),
        help="elevation range in degrees",
    )
    parser.add_argument("--texture-size", type=int, default=512, help="side of the baked UV texture of textured/*.glb")
    parser.add_argument(
        "--variety",
        choices=("boxy", "real"),
        default="boxy",
        help="shapes: 'boxy' (the original straight-member chairs and hull cars) or 'real' (families of real "
        "chairs and cars: office, club, sofa, stool, bench, rocking, folding, shell; sedan, SUV, van, ...)",
    )
    add_overwrite(
        parser,
        "replace what --out holds (a world of other settings, or other files) with this world; without it such a "
        "folder is refused (an unfinished world of the same settings is resumed either way)",
    )
