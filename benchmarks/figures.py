"""Build the grid images of the docs (docs/images/) from the folders the commands wrote.

    python benchmarks/figures.py protocols RUN/renders/PROTOCOL --columns full,no_noc,no_patches,no_refine \\
        [--view 0] [--panels 1] --out FILE.png
        rows: the queries (name order); columns: the reference (the query photo, for the seen view) and
        each method's render, all at view --view of the strips 'evaluate --protocols' writes
        (0: the photo's view); a column with a '/' is a folder of another run (PATH/renders/PROTOCOL/full);
        --panels N splits the rows into N panels side by side
    python benchmarks/figures.py generate DIR [--seeds 0,1,2,3] [--views 0,1,2,3] --out FILE.png
        rows: seeds; columns: views; from the seed{S}_view{V}.png files of 'infer generate'
    python benchmarks/figures.py rows --row A.png,B.gif:3,... [--row ...] --out FILE.png
        any images, one --row per row; FILE.gif:K is frame K of a GIF (the growth.gif of 'infer nca')
    python benchmarks/figures.py screenshot demo_out/report.html [--width 1200] [--height 2400] [--scale 1] --out
    FILE.png
        the page as headless Chromium shows it (the demo's self-contained report), white space below the
        content cropped; needs a Chromium or Chrome binary (Debian: apt-get install chromium), else it
        stops with that message; --browser PATH names one

Every tile is resized to --size pixels (default: the first tile's height) and framed by --pad white
pixels. The docs give, next to each image, the commands that made its folders and the line of this
script that assembled it.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

PANEL_GAP = 16  # white pixels between panels
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome")
# Headless, offline and stateless: no sandbox (root in containers), no GPU, no network side traffic.
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
)


def read_tile(spec: str) -> Image.Image:
    """An image file, or ``FILE.gif:K`` for frame K of a GIF, as RGB."""
    match = re.fullmatch(r"(.+\.gif):(\d+)", spec, flags=re.IGNORECASE)
    path = Path(match.group(1) if match else spec)
    if not path.is_file():
        sys.exit(f"figures: error: {path}: no such file")
    image = Image.open(path)
    if match:
        try:
            image.seek(int(match.group(2)))
        except EOFError:
            sys.exit(f"figures: error: {path} has no frame {match.group(2)} (it has {getattr(image, 'n_frames', 1)})")
    return image.convert("RGB")


def strip_view(path: Path, view: int) -> Image.Image:
    """View ``view`` of a strip of square views 2 px apart (``mesh2tex.evaluation.protocols._strip``)."""
    strip = read_tile(str(path))
    side = strip.height
    count = (strip.width + 2) // (side + 2)
    if not 0 <= view < count:
        sys.exit(f"figures: error: {path} holds {count} views, not view {view}")
    left = view * (side + 2)
    return strip.crop((left, 0, left + side, side))


def grid(rows: list[list[Image.Image]], size: int | None, pad: int, panels: int = 1) -> Image.Image:
    """Tiles (rows of images) framed by ``pad`` white pixels, rows split into ``panels`` side by side."""
    size = size or rows[0][0].height
    tiles = [
        [np.asarray(t.resize((size, size), Image.LANCZOS) if t.size != (size, size) else t) for t in row]
        for row in rows
    ]
    cell = size + 2 * pad
    columns = max(len(row) for row in tiles)
    per_panel = -(-len(tiles) // panels)
    width = panels * columns * cell + (panels - 1) * PANEL_GAP
    canvas = np.full((per_panel * cell, width, 3), 255, np.uint8)
    for r, row in enumerate(tiles):
        panel, r_in = divmod(r, per_panel)
        for c, tile in enumerate(row):
            y = r_in * cell + pad
            x = panel * (columns * cell + PANEL_GAP) + c * cell + pad
            canvas[y : y + size, x : x + size] = tile
    return Image.fromarray(canvas)


def protocol_rows(folder: Path, columns: list[str], view: int) -> list[list[Image.Image]]:
    """Rows of queries: the reference, then each column: a method's folder under ``folder``, or any folder
    (a path with a '/') of per-query images, such as another run's method. Runs before the strips
    wrote one view per file and the photo as ``<query>_photo.png``: read alike (view 0)."""
    suffix = "_reference.png" if any(folder.glob("*_reference.png")) else "_photo.png"
    references = sorted(folder.glob(f"*{suffix}"))
    if not references:
        sys.exit(
            f"figures: error: {folder}: no <query>_reference.png (a renders/<protocol> folder of 'evaluate "
            "--protocols')"
        )
    rows = []
    for reference in references:
        query = reference.name[: -len(suffix)]
        row = [strip_view(reference, view)]
        for column in columns:
            row.append(strip_view((Path(column) if "/" in column else folder / column) / f"{query}.png", view))
        rows.append(row)
    return rows


def generate_rows(folder: Path, seeds: list[int] | None, views: list[int] | None) -> list[list[Image.Image]]:
    pattern = re.compile(r"seed(-?\d+)_view(\d+)\.png")
    found = {(int(m[1]), int(m[2])) for p in folder.glob("seed*_view*.png") if (m := pattern.fullmatch(p.name))}
    if not found:
        sys.exit(f"figures: error: {folder}: no seed<S>_view<V>.png (an 'infer generate' output folder)")
    seeds = seeds if seeds is not None else sorted({s for s, _ in found})
    views = views if views is not None else sorted({v for _, v in found})
    return [[read_tile(str(folder / f"seed{s}_view{v}.png")) for v in views] for s in seeds]


def find_browser(name: str | None) -> str:
    """The Chromium (or Chrome) executable: ``name`` (a path or a command), else the first of BROWSERS on PATH."""
    for candidate in [name] if name else BROWSERS:
        found = shutil.which(candidate)
        if found:
            return found
    wanted = name or " / ".join(BROWSERS)
    sys.exit(
        f"figures: error: no {wanted} executable found; install Chromium (Debian/Ubuntu: apt-get install chromium) "
        f"or pass --browser PATH"
    )


def screenshot(
    page: Path, out: Path, width: int, height: int, browser: str | None = None, scale: float = 1.0, margin: int = 24
) -> Image.Image:
    """``page`` (an HTML file) rendered by headless Chromium in a ``width`` x ``height`` window (CSS
    pixels) at ``scale`` image pixels per CSS pixel, the uniform rows below its content cropped
    (``margin`` pixels kept)."""
    if not page.is_file():
        sys.exit(
            f"figures: error: {page}: no such file (a demo's report.html: 'mesh2tex demo --out DIR' writes "
            "DIR/report.html)"
        )
    executable = find_browser(browser)
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="figures-chromium-") as profile:
        shot = Path(profile) / "shot.png"
        command = [
            executable,
            *CHROMIUM_FLAGS,
            f"--force-device-scale-factor={scale:g}",
            f"--user-data-dir={profile}/profile",
            f"--screenshot={shot}",
            f"--window-size={width},{height}",
            page.resolve().as_uri(),
        ]
        try:
            result = subprocess.run(command, capture_output=True, text=True, timeout=120)
        except subprocess.TimeoutExpired:
            sys.exit(f"figures: error: {executable} took more than 120 s to render {page}")
        if not shot.is_file():
            detail = (result.stderr.strip().splitlines() or ["no output"])[-1]
            sys.exit(f"figures: error: {executable} wrote no screenshot of {page} (exit {result.returncode}: {detail})")
        image = Image.open(shot).convert("RGB")
        image.load()
    pixels = np.asarray(image).astype(np.int16)
    differs = np.abs(pixels - pixels[-1:, :1]).max(axis=(1, 2)) > 8  # rows unlike the page's background at the bottom
    bottom = int(np.nonzero(differs)[0].max()) + 1 + margin if differs.any() else image.height
    return image.crop((0, 0, image.width, min(bottom, image.height)))


def numbers(text: str | None) -> list[int] | None:
    return None if text is None else [int(t) for t in text.split(",") if t.strip()]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    kinds = parser.add_subparsers(dest="kind", required=True)
    protocols = kinds.add_parser("protocols", help="queries x methods from 'evaluate --protocols' renders")
    protocols.add_argument("folder", help="RUN/renders/<protocol>")
    protocols.add_argument(
        "--columns", required=True, help="comma-separated methods (ablations or baselines), after the reference"
    )
    protocols.add_argument("--view", type=int, default=0, help="view of each strip (0: the photo's)")
    protocols.add_argument("--panels", type=int, default=1, help="panels side by side the rows are split into")
    generate = kinds.add_parser("generate", help="seeds x views from 'infer generate' outputs")
    generate.add_argument("folder")
    generate.add_argument("--seeds", help="comma-separated seeds (default: all found)")
    generate.add_argument("--views", help="comma-separated views (default: all found)")
    rows = kinds.add_parser("rows", help="any images, row by row")
    rows.add_argument(
        "--row", action="append", required=True, help="comma-separated images of one row (FILE.gif:K: frame K)"
    )
    for sub in (protocols, generate, rows):
        sub.add_argument("--out", required=True, help="the PNG to write")
        sub.add_argument("--size", type=int, help="tile side in pixels (default: the first tile's height)")
        sub.add_argument("--pad", type=int, default=2, help="white pixels around each tile")
    shot = kinds.add_parser("screenshot", help="an HTML page (the demo's report.html) as headless Chromium shows it")
    shot.add_argument("page", help="the HTML file, e.g. demo_out/report.html")
    shot.add_argument("--out", required=True, help="the PNG to write")
    shot.add_argument("--width", type=int, default=1200, help="window width in pixels")
    shot.add_argument("--height", type=int, default=2400, help="window height in pixels (the page below it is cut)")
    shot.add_argument(
        "--scale", type=float, default=1.0, help="image pixels per CSS pixel (0.6: a smaller image of the same layout)"
    )
    shot.add_argument(
        "--browser",
        help="Chromium or Chrome executable (default: the first of chromium, chromium-browser, google-chrome on PATH)",
    )
    args = parser.parse_args(argv)
    if args.kind == "screenshot":
        if not 0.1 <= args.scale <= 4 or args.width < 100 or args.height < 100:
            sys.exit("figures: error: --scale must be within 0.1-4 and --width, --height at least 100")
        image = screenshot(Path(args.page), Path(args.out), args.width, args.height, args.browser, args.scale)
        image.save(args.out, optimize=True)
        print(f"{args.out}: {image.width}x{image.height}, {Path(args.out).stat().st_size // 1024} KiB")
        return 0
    if args.kind == "protocols":
        tiles = protocol_rows(Path(args.folder), [c for c in args.columns.split(",") if c], args.view)
    elif args.kind == "generate":
        tiles = generate_rows(Path(args.folder), numbers(args.seeds), numbers(args.views))
    else:
        tiles = [[read_tile(spec) for spec in row.split(",") if spec] for row in args.row]
    image = grid(tiles, args.size, args.pad, getattr(args, "panels", 1))
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    image.save(args.out)
    print(f"{args.out}: {len(tiles)} rows, {image.width}x{image.height}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
