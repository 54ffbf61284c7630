"""Atomic file writes: a reader (or a crash) never sees a half-written file under its final name.

A file being written lives in a hidden folder beside its target,
``<folder>/.mesh2tex-partial/<pid>@<host>.<random>/<name>``, so that no loader's pattern (``*.npz``,
``*.png``, ``*.json`` in ``<folder>``) can pick it up, and it keeps its final name (some writers,
numpy, PIL and trimesh, pick the format from the suffix). Writing anything into a folder removes
what killed writers of that folder on this machine left behind (their process is gone).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import socket
import tempfile
from pathlib import Path
from typing import Iterator

PARTIAL_DIR = ".mesh2tex-partial"


def _owner() -> str:
    """``<pid>@<host>``: whose a temporary folder is (a folder on a shared disk may see several machines)."""
    host = "".join(c if c.isalnum() or c == "-" else "-" for c in socket.gethostname()) or "host"
    return f"{os.getpid()}@{host}"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True
    return True


def clean_partials(folder: str | os.PathLike) -> list[Path]:
    """Remove the half-written files that killed processes left in ``folder``; returns what was removed."""
    root = Path(folder) / PARTIAL_DIR
    removed: list[Path] = []
    try:
        entries = list(root.iterdir())
    except OSError:
        return removed
    here = _owner().split("@", 1)[1]
    for entry in entries:
        pid, _, host = entry.name.split(".", 1)[0].partition("@")
        if host not in ("", here) or (pid.isdigit() and _alive(int(pid))):
            continue  # another machine's, or a live process's
        shutil.rmtree(entry, ignore_errors=True)
        removed.append(entry)
    with contextlib.suppress(OSError):
        root.rmdir()  # only when empty: another writer may be using it
    return removed


def _temp_dir(parent: Path) -> Path:
    for _ in range(5):  # another process may remove the (empty) partial folder between the two calls
        (parent / PARTIAL_DIR).mkdir(parents=True, exist_ok=True)
        try:
            return Path(tempfile.mkdtemp(prefix=f"{_owner()}.", dir=parent / PARTIAL_DIR))
        except FileNotFoundError:
            continue
    raise OSError(f"{parent}: cannot create a temporary folder for an atomic write")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path for ``path`` (see the module docstring); on success it is fsynced and
    renamed onto ``path``.

    The temporary name is ``path``'s own name (``suffix``, when given, replaces its suffix), because
    some writers pick the format from it. On an exception the temporary file is removed and ``path``
    is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    clean_partials(path.parent)
    folder = _temp_dir(path.parent)
    tmp = folder / (path.name if suffix is None else path.stem + suffix)
    tmp.touch()
    try:
        yield tmp
        with open(tmp, "rb+") as handle:
            os.fsync(handle.fileno())
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except OSError as error:
        if error.filename is None or str(error.filename).startswith(str(folder)):  # name the file the user asked for
            raise type(error)(error.errno, error.strerror or str(error), str(path)) from None
        raise
    finally:
        shutil.rmtree(folder, ignore_errors=True)
        with contextlib.suppress(OSError):
            folder.parent.rmdir()


@contextlib.contextmanager
def locked(path: str | os.PathLike) -> Iterator[None]:
    """Hold an exclusive lock (``fcntl.flock``) on the file ``path`` (created, and left in place) for
    the block: processes that read, change and rewrite one file take turns."""
    import fcntl

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as handle:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle.fileno(), fcntl.LOCK_UN)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    write_bytes(path, text.encode("utf-8"))


def write_json(path: str | os.PathLike, obj, indent: int = 2) -> None:
    """Write ``obj`` as JSON to ``path`` atomically."""
    write_text(path, json.dumps(obj, indent=indent, sort_keys=False) + "\n")


def json_ready(value):
    """``value`` as plain JSON: tuples as lists, NaN as null and infinities as "inf" / "-inf" (strict
    JSON has neither), nested dicts and lists alike."""
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, dict):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    return value
