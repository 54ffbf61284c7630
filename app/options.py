"""The options of ``mesh2tex app``, built without importing torch (``--help`` stays fast); the command's
``run()`` and ``build_config()`` are in :mod:`mesh2tex.app.server`."""

from __future__ import annotations

import argparse

from mesh2tex.options import DEVICES, ConfigOptions, add_out, add_overwrite


def server(parser: argparse.ArgumentParser) -> None:
    config = ConfigOptions(parser, "mesh2tex.app.settings:AppConfig", what="the app config")
    config.add(
        "--host", help="address to serve on: 127.0.0.1 is this machine only; 0.0.0.0 shares the page with the network"
    )
    config.add("--port", type=int, help="port to serve on (0: a free one, printed)")
    config.add("--device", choices=DEVICES, help="where the jobs run")
    add_out(
        parser,
        "also keep every result the page makes here, a folder per job (without it, results live only in "
        "each visitor's temporary folder and are deleted with it)",
        required=False,
    )
    add_overwrite(
        parser,
        "with --out: a kept result whose folder name exists replaces it (the old one is moved aside, "
        "never deleted); without it the new folder is numbered",
    )
