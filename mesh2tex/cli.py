"""The ``mesh2tex`` console script.

Every subcommand is a stage module (``data_prep``, ``train``, ``infer``) that defines ``run(args) -> int``
(and ``build_config(args)`` where the command has a config); its options are the function of the same
name in the package's ``options.py`` (``mesh2tex.train.gan`` -> ``mesh2tex.train.options.gan(parser)``), which imports
no torch. This file only routes: it builds the options of the one command asked for and imports its
stage when it runs, so that ``mesh2tex --help`` and ``mesh2tex CMD --help`` stay fast and one broken
stage cannot break the others. ``--print-config`` prints the command's resolved config and exits.
Every Python warning raised while a command runs (the library's ``warnings.warn``, a dependency's)
is shown as one line, ``mesh2tex: warning: ...`` (:func:`show_warning`), never with a source line.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import importlib
import os
import signal
import sys
import warnings
from pathlib import Path

from mesh2tex.errors import InputError, UserError, one_line, warning
from mesh2tex.options import HelpFormatter, Parser

# (command, subcommand or None) -> (stage module, one-line help)
COMMANDS: dict[tuple[str, str | None], tuple[str, str]] = {
    ("prepare", "shapes"): ("mesh2tex.data_prep.shapes", "turn meshes into quad-mesh hierarchies (.npz)"),
    ("prepare", "images"): ("mesh2tex.data_prep.images", "turn a folder of photos into square crops with masks"),
    ("prepare", "synthetic"): (
        "mesh2tex.data_prep.synthetic",
        "build the synthetic world (shapes, textures, photos, queries)",
    ),
    ("train", "gan"): ("mesh2tex.train.gan", "train the mesh-field texture GAN"),
    ("train", "pose"): ("mesh2tex.train.pose", "train the pose network"),
    ("train", "noc"): ("mesh2tex.train.noc", "train the NOC network"),
    ("train", "mask"): ("mesh2tex.train.mask", "train the mask network (finds the object in a photo without a mask)"),
    ("train", "nca"): ("mesh2tex.train.nca", "grow a texture from one exemplar image with a mesh cellular automaton"),
    ("infer", "generate"): ("mesh2tex.infer.generate", "texture a mesh from random latent codes"),
    ("infer", "transfer"): ("mesh2tex.infer.transfer", "texture a mesh after one photo"),
    ("infer", "nca"): ("mesh2tex.infer.nca", "grow a trained cellular automaton's texture on any mesh"),
    ("infer", "synthesize"): ("mesh2tex.infer.synthesize", "texture a mesh after one exemplar image, no model"),
    ("evaluate", None): ("mesh2tex.evaluate.evaluate", "metrics between renders and images"),
    ("demo", None): ("mesh2tex.infer.demo", "run the whole pipeline on the embedded synthetic world"),
    ("app", None): ("mesh2tex.app.server", "serve a local web page to texture a mesh and look at it in 3D"),
}


# errno values an OSError without a file name still means the user's environment for
USER_ERRNOS = {
    errno.ENOSPC,
    errno.EDQUOT,
    errno.EROFS,
    errno.EACCES,
    errno.EPERM,
    errno.EFBIG,
    errno.EIO,
    errno.EMFILE,
    errno.ENAMETOOLONG,
}


def _options(stage: str):
    """The options function of ``stage`` (``mesh2tex.train.gan`` -> ``mesh2tex.train.options.gan``), or None while the
    command is not written yet (never a pretend command)."""
    package, name = stage.rsplit(".", 1)
    try:
        module = importlib.import_module(f"{package}.options")
    except ModuleNotFoundError as error:
        if error.name == f"{package}.options":
            return None
        raise
    return getattr(module, name, None)


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The parser of every command; with ``argv``, only the command it names gets its options (the others
    are not needed to parse it). ``--print-config`` in ``argv`` makes the required options optional."""
    from mesh2tex import __version__

    parser = Parser(prog="mesh2tex", description="Texture 3D meshes from photographs.", formatter_class=HelpFormatter)
    parser.add_argument("--version", action="version", version=f"mesh2tex {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    groups: dict[str, argparse._SubParsersAction] = {}
    words = argv[:2] if argv is not None else None
    for (command, sub), (stage, help_text) in COMMANDS.items():
        if sub is None:
            target = commands.add_parser(command, help=help_text, description=help_text, formatter_class=HelpFormatter)
        else:
            if command not in groups:
                group_parser = commands.add_parser(
                    command, help=f"{command} subcommands", formatter_class=HelpFormatter
                )
                groups[command] = group_parser.add_subparsers(dest="subcommand", metavar="SUBCOMMAND", required=True)
            target = groups[command].add_parser(
                sub, help=help_text, description=help_text, formatter_class=HelpFormatter
            )
        target.set_defaults(_stage=stage, _parser=target)
        if words is not None and words[: 1 if sub is None else 2] != [command] + ([sub] if sub else []):
            continue
        add_options = _options(stage)
        if add_options is None:
            target.set_defaults(_unfinished=True)
            target.add_argument("rest", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
            continue
        add_options(target)
        if argv is not None and "--print-config" in argv:
            for action in target._actions:
                action.required = False
    return parser


def print_config(stage, args) -> int:
    """``--print-config``: the config ``stage.build_config(args)`` resolves, as YAML on stdout. Without
    ``--out`` there is no run to resume, so the defaults, ``--config`` and the flags decide."""
    from mesh2tex.config import config_yaml

    if getattr(args, "out", "") is None:
        args.out, args.resume = "", False
    print(config_yaml(stage.build_config(args)), end="")
    return 0


def show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """``warnings.showwarning`` while a command runs: one ``mesh2tex: warning: ...`` line. The
    library's own warnings (raised from ``mesh2tex``) are the message alone; a dependency's names its
    category and package, so that it is not taken for ours."""
    origin = Path(filename).resolve()
    if any(folder.resolve() in origin.parents for folder in _package_folders()):
        warning(message)
    else:
        source = _package_of(origin)
        warning(f"{message} ({category.__name__}{f' from {source}' if source else ''})")


def _package_folders() -> list[Path]:
    """The folders of mesh2tex's code: the package and its stage folders (beside it in a source tree)."""
    import mesh2tex

    package = Path(mesh2tex.__file__).parent
    return [package] + [Path(entry) / stage for entry in mesh2tex.__path__ for stage in ("data_prep", "train", "infer")]


def _package_of(path: Path) -> str:
    """The top-level package a source file belongs to (the folder under site-packages), or ''."""
    parts = path.parts
    for marker in ("site-packages", "dist-packages"):
        if marker in parts and parts.index(marker) + 1 < len(parts):
            return parts[parts.index(marker) + 1].removesuffix(".py")
    return ""


def main(argv: list[str] | None = None, prepare=None) -> int:
    """Run the command ``argv``; ``prepare()``: called once the command holds its ``--out``, before its
    stage is imported (the console script sets torch's threads there)."""
    with warnings.catch_warnings():
        warnings.showwarning = show_warning
        return _main(argv, prepare)


def _main(argv: list[str] | None = None, prepare=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv)
    args, unknown = parser.parse_known_args(argv)
    if unknown:  # named by the command's own parser, whose --help lists what it takes
        args._parser.error(f"unrecognized arguments: {' '.join(one_line(word)[:80] for word in unknown)}")
    for action in args._parser._actions:  # an empty value is never meant (as a path it would be the current folder),
        value = getattr(args, action.dest, None)  # nor a NUL character (no path can hold one)
        texts = [v for v in (value if isinstance(value, (list, tuple)) else [value]) if isinstance(v, str)]
        if action.option_strings and any(text == "" or "\x00" in text for text in texts):
            args._parser.error(
                f"argument {action.option_strings[0]}: "
                f"{'an empty value' if '' in texts else 'a NUL character in its value'}"
            )
    name = args.command + (f" {args.subcommand}" if getattr(args, "subcommand", None) else "")
    if getattr(args, "_unfinished", False):
        print(f"mesh2tex: error: '{name}' is not available in this version yet", file=sys.stderr)
        return 3
    try:
        if getattr(args, "print_config", False):
            return print_config(importlib.import_module(args._stage), args)
        with _output_folder(args, argv, name):  # before the stage is imported: a busy folder is refused at once
            if prepare is not None:
                prepare()
            return int(importlib.import_module(args._stage).run(args) or 0)
    except (UserError, InputError) as error:  # a command's refusal, or bad input the library found
        print(f"mesh2tex: error: {one_line(error)}", file=sys.stderr)
        return getattr(error, "exit_code", 2)
    except OSError as error:
        # the system's refusal (a file where a folder is needed, no permission, a full disk, a file too
        # large, a read-only disk): the environment, not a bug; an OSError naming neither a path nor a
        # cause of the environment keeps its traceback
        if error.filename is None and error.errno not in USER_ERRNOS:
            raise
        print(f"mesh2tex: error: {os_error_line(error)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        if _NESTED:  # a stage run by another command (the demo): the outer command says how to continue
            raise
        from mesh2tex.io.outputs import continue_command

        print(
            f"mesh2tex: {name} interrupted; re-run the same command to resume: {continue_command(argv)}",
            file=sys.stderr,
        )
        return 130


# the commands running in this process, outermost first (the demo runs the other stages in-process)
_NESTED: list[str] = []


def os_error_line(error: OSError) -> str:
    """An OSError as the user reads it: the path (both of a rename) and the cause."""
    where = f"{error.filename}: " if error.filename is not None else ""
    if getattr(error, "filename2", None) is not None:
        where = f"{error.filename} -> {error.filename2}: "
    reason = error.strerror or str(error)
    if isinstance(error, (FileExistsError, NotADirectoryError)) and os.path.isfile(error.filename or ""):
        reason = "is a file where a folder is needed"
    elif error.errno in CAUSES:
        reason = f"{reason} ({CAUSES[error.errno]})"
    return one_line(f"{where}{reason}")


# what to do about the system's refusals
CAUSES = {
    errno.ENOSPC: "free some space or choose another --out",
    errno.EDQUOT: "over the disk quota; free some space",
    errno.EFBIG: "a file larger than this file system or `ulimit -f` allows",
    errno.EROFS: "choose a writable --out",
    errno.EACCES: "check the permissions",
    errno.EPERM: "check the permissions",
}


@contextlib.contextmanager
def _output_folder(args, argv: list[str], name: str):
    """The command's hold on its ``--out`` (:func:`mesh2tex.io.outputs.output_run`): one run at a time,
    and a manifest of the files it claims. ``prepare shapes`` waits its turn (its runs share an
    index); the other processes of a distributed run (RANK > 0) share their first process's hold."""
    out = getattr(args, "out", None)
    _NESTED.append(name)
    try:
        if not out:
            yield
            return
        from mesh2tex.io.outputs import continue_command, output_run

        rank = os.environ.get("RANK", "0")
        with output_run(out, argv, continue_command(argv), wait=name == "prepare shapes", lock=rank in ("", "0")):
            yield
    finally:
        _NESTED.pop()


def _interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def console() -> int:
    """The ``mesh2tex`` console script: :func:`main` with torch's thread count chosen for the machine's
    load (:func:`mesh2tex.runtime.choose_threads`). ``main`` itself leaves threads alone, so that a
    program or test calling it keeps its own setting."""
    argv = sys.argv[1:]
    # `kill PID` (what schedulers and `timeout` send) stops a run as Ctrl-C does: the long stages save
    # their checkpoint, and the same command resumes. A shell starts background jobs with SIGINT ignored.
    signal.signal(signal.SIGTERM, _interrupt)

    def prepare() -> None:
        from mesh2tex.runtime import configure_threads

        configure_threads()

    return main(argv, prepare)


if __name__ == "__main__":
    sys.exit(console())
