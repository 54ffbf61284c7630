"""The page of ``mesh2tex app`` in a real browser (the system's Chromium, driven by playwright):

    python benchmarks/app_page.py screenshot --out docs/images/app.png
    python benchmarks/app_page.py timing --repeats 5

``screenshot`` starts the app, picks the example chair, paints seed 0 with the shipped chair model, waits
for the viewer to show it and saves the page. ``timing`` measures, on this machine, the time from pressing
Generate to the viewer's ``load`` event of the textured GLB, against the wall time of the same command run
from a shell (``mesh2tex infer generate --checkpoint chair --mesh chair.obj --seeds 0 --views 1``, the job
the page runs), alternating the two, and prints a Markdown table (docs/results/app.md).
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from figures import CHROMIUM_FLAGS  # this folder

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "app" / "static" / "examples" / "chair.obj"
# the figures' headless, offline Chromium, its scrollbars as a user sees them
BROWSER_ARGS = [flag for flag in CHROMIUM_FLAGS if flag != "--hide-scrollbars"]


def start_app(folder: Path) -> tuple[subprocess.Popen, str]:
    """``mesh2tex app --port 0`` in the background; its process and address."""
    env = {**os.environ, "TMPDIR": str(folder), "PYTHONPATH": str(ROOT)}
    process = subprocess.Popen(
        [sys.executable, "-m", "mesh2tex", "app", "--port", "0", "--device", "cpu"],
        env=env,
        stdout=subprocess.PIPE,
        text=True,
    )
    line = process.stdout.readline()
    if "http://" not in line:
        raise SystemExit(f"the app did not start: {line}")
    return process, line.split()[2].rstrip("/")


def stop_app(process: subprocess.Popen) -> None:
    process.send_signal(signal.SIGINT)
    process.wait(timeout=60)


def generate(page, seed: int, timeout_s: float = 600) -> tuple[float, float]:
    """Press Generate for ``seed``; the seconds until the viewer's load event, and the command's own
    seconds within them (its process's start to its end, as the server saw them)."""
    page.fill("#seed", str(seed))
    page.dispatch_event("#seed", "change")
    page.click("#generate")
    page.wait_for_function(
        "window.mesh2tex.loaded > 0 || !document.getElementById('error').hidden", timeout=timeout_s * 1000
    )
    if not page.is_hidden("#error"):
        raise SystemExit(page.inner_text("#error"))
    return page.evaluate("[window.mesh2tex.seconds, window.mesh2tex.jobSeconds]")


def launch(playwright):
    chromium = shutil.which("chromium") or "/usr/bin/chromium"
    return playwright.chromium.launch(executable_path=chromium, args=BROWSER_ARGS)


def open_page(browser, url: str, width: int = 1280, height: int = 860):
    """A new tab on the page, the example chair uploaded and shown untextured, the shipped chair model chosen."""
    page = browser.new_page(viewport={"width": width, "height": height})
    page.goto(url + "/")
    page.wait_for_function("window.mesh2tex && window.mesh2tex.ready", timeout=60000)
    page.select_option("#mesh-example", EXAMPLE.name)
    page.wait_for_function("document.getElementById('mesh-summary').textContent.includes('(example)')")
    page.wait_for_function("document.getElementById('viewer').loaded", timeout=120000)  # the mesh, untextured
    page.select_option("#source", "chair")
    return page


def screenshot(args) -> None:
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as folder, sync_playwright() as playwright:
        process, url = start_app(Path(folder))
        try:
            browser = launch(playwright)
            page = open_page(browser, url)
            seconds, _ = generate(page, 0)
            page.wait_for_timeout(1500)  # the viewer turns the model a little
            page.screenshot(path=args.out)
            browser.close()
        finally:
            stop_app(process)
    print(f"{args.out}: seed 0 in the viewer {seconds:.1f} s after pressing Generate")


def cli_seconds(folder: Path, seed: int) -> float:
    out = folder / f"cli{seed}"
    command = [
        sys.executable,
        "-m",
        "mesh2tex",
        "infer",
        "generate",
        "--checkpoint",
        "chair",
        "--mesh",
        str(EXAMPLE),
        "--seeds",
        str(seed),
        "--views",
        "1",
        "--device",
        "cpu",
        "--out",
        str(out),
    ]
    start = time.perf_counter()
    subprocess.run(command, check=True, capture_output=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    seconds = time.perf_counter() - start
    shutil.rmtree(out)
    return seconds


def timing(args) -> None:
    from playwright.sync_api import sync_playwright

    page_s, job_s, cli_s = [], [], []
    with tempfile.TemporaryDirectory() as folder, sync_playwright() as playwright:
        process, url = start_app(Path(folder))
        try:
            browser = launch(playwright)
            for repeat in range(args.repeats):
                page = open_page(browser, url)  # a fresh tab each time: the viewer starts cold, as for a new visitor
                seconds, job = generate(page, 0)
                page_s.append(seconds)
                job_s.append(job)
                page.close()  # a turning model in a software-rendered viewer would take CPU from the command line's run
                cli_s.append(cli_seconds(Path(folder), 0))
                print(
                    f"repeat {repeat}: page {seconds:.2f} s (its command {job:.2f} s), command line {cli_s[-1]:.2f} s",
                    flush=True,
                )
            browser.close()
        finally:
            stop_app(process)
    own = [p - j for p, j in zip(page_s, job_s)]
    gaps = [p - c for p, c in zip(page_s, cli_s)]
    print("\n| | median | min | max |\n| --- | --- | --- | --- |")
    rows = (
        ("page: Generate pressed to the viewer's load event", page_s),
        ("the page's command, from its start to its end", job_s),
        ("the page's own time (the two above apart)", own),
        ("command line: wall time of the same `infer generate`", cli_s),
        ("page minus command line", gaps),
    )
    for name, values in rows:
        print(f"| {name} | {statistics.median(values):.2f} s | {min(values):.2f} s | {max(values):.2f} s |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True)
    shot = commands.add_parser("screenshot", help="the page after Generate, as a PNG")
    shot.add_argument("--out", default=str(ROOT / "docs" / "images" / "app.png"))
    shot.set_defaults(run=screenshot)
    timed = commands.add_parser("timing", help="Generate to the viewer, against the same command from a shell")
    timed.add_argument("--repeats", type=int, default=5)
    timed.set_defaults(run=timing)
    args = parser.parse_args()
    args.run(args)


if __name__ == "__main__":
    main()
