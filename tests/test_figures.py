"""benchmarks/figures.py, which assembles the docs' grid images, on folders laid out as the commands write them."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
from PIL import Image

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "figures.py"


def figures(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True, timeout=60)


def strip(path: Path, colours: list[int], side: int = 8) -> None:
    """A strip of square views 2 px apart (as mesh2tex.evaluation.protocols writes them), view k filled with
    colours[k]."""
    image = np.full((side, len(colours) * (side + 2) - 2, 3), 255, np.uint8)
    for k, c in enumerate(colours):
        image[:, k * (side + 2) : k * (side + 2) + side] = c
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(image).save(path)


def test_protocol_grid_takes_the_asked_view_of_every_strip(tmp_path):
    folder = tmp_path / "run" / "renders" / "unknown_pose"
    for q, query in enumerate(["chair_a_00", "chair_b_00"]):
        strip(folder / f"{query}_reference.png", [10 + q, 20 + q])
        strip(folder / "full" / f"{query}.png", [30 + q, 40 + q])
        strip(tmp_path / "other" / "full" / f"{query}.png", [50 + q, 60 + q])
    result = figures(
        "protocols",
        folder,
        "--columns",
        f"full,{tmp_path / 'other' / 'full'}",
        "--view",
        1,
        "--pad",
        0,
        "--out",
        tmp_path / "grid.png",
    )
    assert result.returncode == 0, result.stderr
    grid = np.asarray(Image.open(tmp_path / "grid.png"))
    assert grid.shape == (16, 24, 3)  # 2 queries x (reference, full, the other run's full), 8 px tiles
    assert [int(grid[4 + 8 * r, 4 + 8 * c, 0]) for r in range(2) for c in range(3)] == [20, 40, 60, 21, 41, 61]


def test_generate_grid_is_seeds_by_views_and_a_missing_folder_is_one_line(tmp_path):
    for seed in (0, 1):
        for view in (0, 1, 2):
            Image.fromarray(np.full((16, 16, 3), 10 * seed + view, np.uint8)).save(
                tmp_path / f"seed{seed}_view{view}.png"
            )
    result = figures(
        "generate", tmp_path, "--views", "0,2", "--size", 8, "--pad", 1, "--out", tmp_path / "g" / "grid.png"
    )
    assert result.returncode == 0, result.stderr
    grid = np.asarray(Image.open(tmp_path / "g" / "grid.png"))
    assert grid.shape == (20, 20, 3) and int(grid[0, 0, 0]) == 255  # 2 x 2 tiles of 8 px framed by 1 px
    assert [int(grid[5 + 10 * r, 5 + 10 * c, 0]) for r in range(2) for c in range(2)] == [0, 2, 10, 12]
    missing = figures("generate", tmp_path / "nowhere", "--out", tmp_path / "x.png")
    assert missing.returncode != 0 and missing.stderr.strip().count("\n") == 0 and "nowhere" in missing.stderr


def test_screenshot_without_a_browser_says_how_to_get_one(tmp_path):
    """The report screenshot needs Chromium; without it the script says so in one line (no browser is run here)."""
    page = tmp_path / "report.html"
    page.write_text("<html><body>report</body></html>")
    result = figures("screenshot", page, "--browser", tmp_path / "no-such-chromium", "--out", tmp_path / "shot.png")
    assert result.returncode != 0 and not (tmp_path / "shot.png").exists()
    assert (
        result.stderr.strip().count("\n") == 0
        and "install Chromium (Debian/Ubuntu: apt-get install chromium)" in result.stderr
    )
