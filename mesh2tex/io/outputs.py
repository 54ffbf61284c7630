"""The output folder of every command that writes (``--out``): one run at a time, and no file lost.

Three rules, all here:

* **One run per folder** (:func:`output_run`, taken by ``mesh2tex/cli.py`` around every command):
  a run holds ``<out>/.mesh2tex-lock``, a file holding its PID, host and command line, locked with
  ``fcntl.flock``. A second run into the same folder stops at once with a line naming the first
  (its PID and command); ``prepare shapes``, whose runs add to one shared index by design, waits its
  turn instead. The kernel releases the lock when its process ends, however it ends (``kill -9``
  too), so the lock of a dead process is taken over without a PID check that PID reuse could fool.
  The lock file is removed when the run ends; a folder the run created and left empty is removed.
* **A run replaces only its own files** (:func:`guard_outputs`): each command lists the files it
  will write before its work starts; one that exists and was not written by an unfinished earlier
  run of the *same command line* in this folder is refused, unless ``--overwrite``: then it is
  moved aside, never deleted, to ``<out>/.mesh2tex-replaced/<date-time>/<its path in out>`` (one such
  folder per run, :func:`move_aside`), and a warning names the files and that folder. What each run claimed is recorded
  in ``<out>/.mesh2tex-manifest.json`` (file -> run, run -> command line and whether it finished), so
  that the same command, re-run after an interruption, continues and replaces its own half-finished
  outputs, while a finished run's results are kept.
* **Nothing added on failure**: a run that ends with an error drops its claims of files it never
  wrote, and the manifest is removed when it then names none.

Without :func:`output_run` (a program calling the library), :func:`guard_outputs` refuses every
existing file, as before there were manifests.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import hashlib
import json
import os
import shlex
import shutil
import socket
import sys
import time
from pathlib import Path
from typing import Callable, Iterable, Iterator

from mesh2tex.errors import InputError, warning

LOCK_NAME = ".mesh2tex-lock"
MANIFEST_NAME = ".mesh2tex-manifest.json"
# Where --overwrite puts what it replaces (the user's files: not bookkeeping, so a folder holding it is not empty).
REPLACED_NAME = ".mesh2tex-replaced"
# What mesh2tex keeps in an output folder for itself (the partial folder: mesh2tex.io.atomic).
BOOKKEEPING = (LOCK_NAME, MANIFEST_NAME, ".mesh2tex-partial")


def walked(dirs: list[str]) -> list[str]:
    """The sub-folders an ``os.walk`` over inputs descends into, sorted: not mesh2tex's own folders
    (``.mesh2tex-replaced``, ``.mesh2tex-partial``), whose files are no input. Assign to ``dirs[:]``."""
    return sorted(name for name in dirs if not name.startswith(".mesh2tex-"))


def user_entries(folder: str | os.PathLike) -> list[Path]:
    """The entries of ``folder`` other than mesh2tex's bookkeeping (a folder is "empty" without them)."""
    try:
        return [p for p in Path(folder).iterdir() if p.name not in BOOKKEEPING]
    except (FileNotFoundError, NotADirectoryError):
        return []


# ------------------------------------------------------------------------------------- the run
@dataclasses.dataclass
class _Run:
    out: Path
    key: str  # the command line's fingerprint (working folder + arguments)
    command: str  # as the user would type it
    fd: int | None = None  # the locked lock file (None: the folder was already ours, or locking is unsupported)
    created: list[Path] = dataclasses.field(default_factory=list)
    claimed: set[str] = dataclasses.field(default_factory=set)
    replaced: Path | None = None  # the run's folder under REPLACED_NAME, made by its first move_aside


_ACTIVE: list[_Run] = []  # innermost last (the demo runs stages inside its own run)


def _current(out: Path) -> _Run | None:
    try:
        resolved = out.resolve()
    except OSError:
        return None
    for run in reversed(_ACTIVE):
        if run.out == resolved:
            return run
    return None


def run_key(argv: list[str]) -> str:
    """The fingerprint of a command line: the same arguments typed in the same folder."""
    return hashlib.sha1(json.dumps([os.getcwd(), list(argv)]).encode()).hexdigest()[:16]


def _host() -> str:
    return socket.gethostname() or "host"


def _make_folder(out: Path) -> list[Path]:
    """Create ``out`` (and missing parents); returns the folders created, deepest first."""
    missing = []
    folder = out
    while not folder.exists() and not folder.is_symlink() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    out.mkdir(parents=True, exist_ok=True)
    return missing


def _holder(path: Path) -> str:
    """Who holds the lock file ``path``, as a message ends: 'PID 12 on host (mesh2tex train gan ...)'."""
    try:
        info = json.loads(path.read_text(encoding="utf-8") or "{}")
        command = str(info.get("command", ""))
        shown = command if len(command) <= 160 else command[:157] + "..."
        return f"PID {info.get('pid')} on {info.get('host')} since {info.get('started')} ({shown})"
    except (OSError, ValueError, AttributeError):
        return "another process"


def _lock(out: Path, run: _Run, wait: bool) -> int | None:
    """Lock ``out`` for ``run`` (see the module docstring); the locked file's descriptor, or None where
    the file system cannot lock (then the run goes on unlocked)."""
    import fcntl

    path = out / LOCK_NAME
    waited = False
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if not wait:
                os.close(fd)
                raise InputError(
                    f"{out}: in use by another mesh2tex run, {_holder(path)}; wait for it to end or choose "
                    f"another --out"
                ) from None
            if not waited:
                print(f"mesh2tex: note: {out}: waiting for the run that holds it, {_holder(path)}", file=sys.stderr)
                waited = True
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError as error:
            os.close(fd)
            if error.errno in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS):
                return None
            raise
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if not same:  # the holder removed the file as it ended: lock the new one
            os.close(fd)
            continue
        info = {
            "pid": os.getpid(),
            "host": _host(),
            "started": time.strftime("%Y-%m-%d %H:%M:%S"),
            "command": run.command,
        }
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(info) + "\n").encode(), 0)
        return fd


@contextlib.contextmanager
def output_run(
    out: str | os.PathLike, argv: list[str], command: str, *, wait: bool = False, lock: bool = True
) -> Iterator[_Run]:
    """Hold ``out`` for one run of ``command`` (``argv``: its arguments) for the block; see the module
    docstring. ``wait``: wait for a run holding it instead of refusing. ``lock`` False: only the
    manifest (the other processes of a distributed run, whose first process holds the lock). A run
    whose block raises keeps only the claims of files that exist. A folder already held by this
    process (a stage run by another into the same folder) is entered as it is."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: --out is a file, not a folder")
    if out.is_symlink() and not out.exists():
        raise InputError(
            f"{out}: a symbolic link to {os.readlink(out)}, which does not exist; create that folder or choose "
            "another --out"
        )
    held = _current(out)
    if held is not None:
        yield held
        return
    created = _make_folder(out)
    run = _Run(out.resolve(), run_key(argv), command, created=created)
    try:
        run.fd = _lock(out, run, wait) if lock else None
    except BaseException:
        _remove_created(run)
        raise
    _ACTIVE.append(run)
    finished = False
    try:
        yield run
        finished = True
    finally:
        _ACTIVE.remove(run)
        with contextlib.suppress(OSError):
            _end(run, finished)
        if run.fd is not None:
            with contextlib.suppress(OSError):
                (out / LOCK_NAME).unlink()
            os.close(run.fd)
        _remove_created(run)


def _remove_created(run: _Run) -> None:
    for folder in run.created:  # deepest first; only while empty
        try:
            folder.rmdir()
        except OSError:
            break


# -------------------------------------------------------------------------------- the manifest
def _read_manifest(out: Path) -> dict:
    try:
        data = json.loads((out / MANIFEST_NAME).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {"files": {}, "runs": {}}
    if not isinstance(data, dict) or not isinstance(data.get("files"), dict) or not isinstance(data.get("runs"), dict):
        return {"files": {}, "runs": {}}
    return data


def _write_manifest(out: Path, data: dict) -> None:
    from mesh2tex.io.atomic import write_json

    files = {name: key for name, key in data["files"].items() if (out / name).exists() or (out / name).is_symlink()}
    runs = {key: value for key, value in data["runs"].items() if key in files.values()}
    path = out / MANIFEST_NAME
    if not files:
        path.unlink(missing_ok=True)
        return
    write_json(path, {"files": files, "runs": runs})


def _claim(run: _Run, out: Path, names: list[str]) -> None:
    data = _read_manifest(out)
    data["runs"][run.key] = {"command": run.command, "finished": False}
    for name in names:
        data["files"][name] = run.key
    run.claimed.update(names)
    from mesh2tex.io.atomic import write_json

    out.mkdir(parents=True, exist_ok=True)
    write_json(
        out / MANIFEST_NAME,
        {"files": data["files"], "runs": {k: v for k, v in data["runs"].items() if k in data["files"].values()}},
    )


def _end(run: _Run, finished: bool) -> None:
    """Record the end of ``run``: finished, or (after an error) its claims of files it never wrote dropped."""
    data = _read_manifest(run.out)
    if run.key not in data["runs"]:
        return
    if finished:
        data["runs"][run.key]["finished"] = True
    _write_manifest(run.out, data)


def continues_own_run(out: str | os.PathLike) -> bool:
    """Whether the current command line (:func:`output_run`) ran in ``out`` before and did not finish:
    re-run, it continues that run (a trainer resumes its checkpoint)."""
    run = _current(Path(out))
    if run is None:
        return False
    entry = _read_manifest(run.out)["runs"].get(run.key)
    return isinstance(entry, dict) and entry.get("finished") is False


def _own_files(out: Path, run: _Run | None) -> set[str]:
    if run is None:
        return set()
    data = _read_manifest(out)
    entry = data["runs"].get(run.key)
    if not (isinstance(entry, dict) and entry.get("finished") is False):
        return set(run.claimed)
    return {name for name, key in data["files"].items() if key == run.key} | run.claimed


def continue_command(argv: list[str]) -> str:
    """The command line that continues an interrupted run: the same one (see the module docstring)."""
    return shlex.join(["mesh2tex", *argv])


# ---------------------------------------------------------------------------------- the guard
def _shown(names: list[str]) -> str:
    return ", ".join(names[:4]) + (f" and {len(names) - 4} more" if len(names) > 4 else "")


def guard_outputs(
    out: str | os.PathLike, names: Iterable[str], overwrite: bool, accept: Callable[[Path], bool] | None = None
) -> Path:
    """Check, before any work, the files ``out/<name>`` a command will write: one that exists and is
    not the run's own (see the module docstring) is refused (InputError), unless ``overwrite``, when
    a warning names what is replaced. ``accept(path)``: an existing file the command may take over
    (an index its runs share). The names are then claimed for the run. Returns ``out`` as a Path."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: --out is a file, not a folder")
    names = list(names)
    run = _current(out)
    own = _own_files(out, run)
    foreign = [
        name
        for name in names
        if name not in own
        and ((out / name).exists() or (out / name).is_symlink())
        and not (accept is not None and accept(out / name))
    ]
    if foreign and not overwrite:
        raise InputError(
            f"{out}: already holds {_shown(foreign)}; pass --overwrite to replace them, or choose another --out"
        )
    if foreign:
        folder = move_aside(out, foreign)
        warning(f"{out}: --overwrite moved {_shown(foreign)} (not written by this command) aside to {folder}")
    if run is not None:
        _claim(run, out, names)
    return out


def _replaced_folder(out: Path, run: _Run | None) -> Path:
    """The folder this run moves replaced files into: ``<out>/.mesh2tex-replaced/<date-time>[-N]``,
    made on first use, one per run (and one per call outside a run)."""
    if run is not None and run.replaced is not None:
        return run.replaced
    stamp = time.strftime("%Y%m%d-%H%M%S")
    (out / REPLACED_NAME).mkdir(exist_ok=True)
    for n in range(1, 10000):
        folder = out / REPLACED_NAME / (stamp if n == 1 else f"{stamp}-{n}")
        try:
            folder.mkdir()
            break
        except FileExistsError:  # two runs replacing in the same second
            continue
    else:
        raise InputError(f"{out / REPLACED_NAME}: too many folders named {stamp}; empty it")
    if run is not None:
        run.replaced = folder
    return folder


def move_aside(out: str | os.PathLike, names: Iterable[str]) -> Path | None:
    """Move the files and folders ``out/<name>`` that exist into the run's replaced folder (see
    :func:`_replaced_folder`), each at its own relative path there (a link is moved, never followed);
    returns that folder, or None when none existed. What ``--overwrite`` replaces is never deleted."""
    out = Path(out)
    present = [name for name in names if (out / name).exists() or (out / name).is_symlink()]
    if not present:
        return None
    folder = _replaced_folder(out, _current(out))
    for name in present:
        target = folder / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(str(out / name), str(target))  # a rename on one file system; copied across a mount
    return folder


def remove_outputs(out: str | os.PathLike, names: Iterable[str]) -> None:
    """``--overwrite`` of a command that starts again: remove the files and folders ``out/<name>`` an
    earlier run of it wrote (a link is removed, never followed); anything else in ``out`` stays."""
    out = Path(out)
    for name in names:
        path = out / name
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.exists() or path.is_symlink():
            path.unlink()
