"""Open a GLB that mesh2tex wrote with three.js's GLTFLoader in headless Chromium, and keep a screenshot.

    npm install --prefix THREE_DIR three@0.170.0
    python benchmarks/threejs_check.py GLB --three THREE_DIR [--out shot.png] [--browser chromium]

``benchmarks/threejs_check.html`` loads the GLB with GLTFLoader (three.js from THREE_DIR/node_modules),
prints what three.js made of it (vertex count, whether it has normals and their length range, UVs,
the material type, flat or smooth shading, the base-colour texture's size and colour space), and
renders it lit (a hemisphere light and a directional light, PBR as the file asks) from azimuth 30,
elevation 20, distance 1.7, vertical fov 40 (mesh2tex's orbit convention, which is three.js's y-up
frame). The files are served from a temporary folder over http on 127.0.0.1 (module imports do not
load from file://). Chromium renders WebGL with SwiftShader, so no GPU is needed.
"""

from __future__ import annotations

import argparse
import http.server
import shutil
import subprocess
import sys
import tempfile
import threading
from functools import partial
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from figures import find_browser  # noqa: E402  (this folder)

PAGE = Path(__file__).resolve().parent / "threejs_check.html"


class QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args) -> None:  # the page's requests are not the report
        pass


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("glb", type=Path)
    parser.add_argument(
        "--three", type=Path, required=True, help="folder holding node_modules/three (npm install --prefix DIR three)"
    )
    parser.add_argument("--out", type=Path, help="screenshot PNG (384 x 384)")
    parser.add_argument("--browser", help="Chromium or Chrome executable")
    args = parser.parse_args()
    if not (args.three / "node_modules" / "three" / "build" / "three.module.js").is_file():
        sys.exit(f"{args.three}: no node_modules/three (npm install --prefix {args.three} three@0.170.0)")
    if not args.glb.is_file():
        sys.exit(f"{args.glb}: no such file")
    browser = find_browser(args.browser)
    with tempfile.TemporaryDirectory(prefix="threejs-check-") as tmp:
        root = Path(tmp)
        shutil.copy(PAGE, root / "page.html")
        shutil.copy(args.glb, root / "asset.glb")
        (root / "node_modules").symlink_to((args.three / "node_modules").resolve())
        server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), partial(QuietHandler, directory=str(root)))
        threading.Thread(target=server.serve_forever, daemon=True).start()
        shot = root / "shot.png"
        command = [
            browser,
            "--headless=new",
            "--no-sandbox",
            "--use-gl=angle",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--virtual-time-budget=60000",
            "--enable-logging=stderr",
            "--v=0",
            "--window-size=384,384",
            f"--user-data-dir={root / 'profile'}",
            f"--screenshot={shot}",
            f"http://127.0.0.1:{server.server_address[1]}/page.html?glb=asset.glb",
        ]
        try:
            result = subprocess.run(command, capture_output=True, text=True, timeout=180)
        finally:
            server.shutdown()
        lines = [line for line in result.stderr.splitlines() if "CONSOLE" in line]
        found = next((line for line in lines if '"OK ' in line or '"ERROR ' in line), None)
        if found is None:
            sys.exit(f"{args.glb}: three.js reported nothing (exit {result.returncode}); console: {lines[-3:]}")
        message = found[found.index('"') + 1 : found.rindex('"')]
        print(f"{args.glb}: {message}")
        if args.out and shot.is_file():
            args.out.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(shot, args.out)
        if message.startswith("ERROR"):
            sys.exit(1)


if __name__ == "__main__":
    main()
