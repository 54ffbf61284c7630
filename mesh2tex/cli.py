"""The ``mesh2tex`` console script.

Every subcommand lives in a stage module (``data_prep``, ``train``, ``infer``) that defines
``add_arguments(parser)`` and ``run(args) -> int``. This file only routes; it imports a stage
lazily so that ``mesh2tex --help`` stays fast and one broken stage cannot break the others.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import sys

from mesh2tex.errors import UserError

# (command, subcommand or None) -> (stage module, one-line help)
COMMANDS: dict[tuple[str, str | None], tuple[str, str]] = {
    ("prepare", "shapes"): ("data_prep.shapes", "turn meshes into quad-mesh hierarchies (.npz)"),
    ("prepare", "images"): ("data_prep.images", "turn a folder of photos into square crops with masks"),
    ("prepare", "synthetic"): ("data_prep.synthetic", "build the synthetic world (shapes, textures, photos, queries)"),
    ("train", "gan"): ("train.gan", "train the mesh-field texture GAN"),
    ("train", "pose"): ("train.pose", "train the pose network"),
    ("train", "noc"): ("train.noc", "train the NOC network"),
    ("train", "nca"): ("train.nca", "grow a texture from one exemplar image with a mesh cellular automaton"),
    ("infer", "generate"): ("infer.generate", "texture a mesh from random latent codes"),
    ("infer", "transfer"): ("infer.transfer", "texture a mesh after one photo"),
    ("infer", "nca"): ("infer.nca", "grow a trained cellular automaton's texture on any mesh"),
    ("evaluate", None): ("infer.evaluate", "metrics between renders and images"),
    ("demo", None): ("infer.demo", "run the whole pipeline on the embedded synthetic world"),
}


# errno values an OSError without a file name still means the user's environment for
USER_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM}


def _load_stage(module_name: str):
    """The stage module, or None while it is not written yet (never a pretend command)."""
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as error:
        if error.name == module_name:
            return None
        raise
    if not (hasattr(module, "add_arguments") and hasattr(module, "run")):
        return None
    return module


def build_parser() -> argparse.ArgumentParser:
    from mesh2tex import __version__

    parser = argparse.ArgumentParser(prog="mesh2tex", description="Texture 3D meshes from photographs.")
    parser.add_argument("--version", action="version", version=f"mesh2tex {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    groups: dict[str, argparse._SubParsersAction] = {}
    for (command, sub), (module_name, help_text) in COMMANDS.items():
        if sub is None:
            target = commands.add_parser(command, help=help_text, description=help_text)
        else:
            if command not in groups:
                group_parser = commands.add_parser(command, help=f"{command} subcommands")
                groups[command] = group_parser.add_subparsers(dest="subcommand", metavar="SUBCOMMAND", required=True)
            target = groups[command].add_parser(sub, help=help_text, description=help_text)
        target.set_defaults(_stage=module_name)
        module = _load_stage(module_name)
        if module is not None:
            module.add_arguments(target)
        else:
            target.set_defaults(_unfinished=True)
            target.add_argument("rest", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    name = args.command + (f" {args.subcommand}" if getattr(args, "subcommand", None) else "")
    if getattr(args, "_unfinished", False):
        print(f"mesh2tex: error: '{name}' is not available in this version yet", file=sys.stderr)
        return 3
    module = _load_stage(args._stage)
    try:
        return int(module.run(args) or 0)
    except UserError as error:
        print(f"mesh2tex: error: {error}", file=sys.stderr)
        return error.exit_code
    except OSError as error:
        # a path the user gave that cannot be used (a file where a folder is needed, no permission, a full
        # disk): the environment, not a bug; anything else keeps its traceback
        if error.filename is None and error.errno not in USER_ERRNOS:
            raise
        where = f"{error.filename}: " if error.filename is not None else ""
        reason = error.strerror or str(error)
        if isinstance(error, (FileExistsError, NotADirectoryError)) and os.path.isfile(error.filename or ""):
            reason = "is a file where a folder is needed"
        print(f"mesh2tex: error: {where}{reason}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"mesh2tex: {name} interrupted; re-run the same command to resume", file=sys.stderr)
        return 130


def console() -> int:
    """The ``mesh2tex`` console script: :func:`main` with torch's thread count chosen for the machine's
    load (:func:`mesh2tex.runtime.choose_threads`). ``main`` itself leaves threads alone, so that a
    program or test calling it keeps its own setting."""
    argv = sys.argv[1:]
    if not any(a in ("-h", "--help", "--version") for a in argv) and argv:
        from mesh2tex.runtime import configure_threads

        configure_threads()
    return main(argv)


if __name__ == "__main__":
    sys.exit(console())
