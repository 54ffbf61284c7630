"""The output guard of every command that writes into ``--out``: files already there are kept
unless the user asks to replace them."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Iterable

from mesh2tex.errors import InputError


def guard_outputs(out: str | os.PathLike, names: Iterable[str], overwrite: bool) -> Path:
    """Refuse (InputError, before any work) when a file ``out/<name>`` a command would write already
    exists, unless ``overwrite``; returns ``out`` as a Path. Nothing is created here."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: --out is a file, not a folder")
    if overwrite:
        return out
    existing = [name for name in names if (out / name).exists()]
    if existing:
        shown = ", ".join(existing[:4]) + (f" and {len(existing) - 4} more" if len(existing) > 4 else "")
        raise InputError(f"{out}: already holds {shown}; pass --overwrite to replace them, or choose another --out")
    return out


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
