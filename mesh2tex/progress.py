"""Progress for long loops: a tqdm bar for people, JSON lines for scripts."""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import Any, Iterable

from tqdm.auto import tqdm

from mesh2tex.errors import InputError


def progress_bar(
    iterable: Iterable | None = None, total: int | None = None, desc: str = "", initial: int = 0, **kwargs
) -> tqdm:
    """A tqdm bar on stderr, shown when stderr is a terminal: redirected logs get no ``\r`` frames.

    ``MESH2TEX_PROGRESS=1`` shows it anyway, ``MESH2TEX_PROGRESS=0`` hides it everywhere.
    """
    setting = os.environ.get("MESH2TEX_PROGRESS")
    disable = setting == "0" if setting in ("0", "1") else not sys.stderr.isatty()
    return tqdm(
        iterable,
        total=total,
        desc=desc,
        initial=initial,
        file=sys.stderr,
        disable=disable,
        dynamic_ncols=True,
        **kwargs,
    )


def write_line(text: str, file=None) -> None:
    """Print one line (default: stdout) without tearing a progress bar that is showing (``tqdm.write``)."""
    tqdm.write(text, file=file or sys.stdout)
    (file or sys.stdout).flush()


class JsonLines:
    """Append one JSON object per line to ``path`` (flushed each time, so a crash loses nothing written)."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)  # its folder is made by the first write, so that naming a file writes nothing

    def write(self, record: dict[str, Any]) -> None:
        record = {"time": round(time.time(), 3), **record}
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with open(self.path, "a") as handle:
            handle.write(json.dumps(record) + "\n")
            handle.flush()

    def read(self) -> list[dict[str, Any]]:
        """The records written so far. A torn last line (the process was killed while writing it) is
        left out; any other line that is not a JSON object is an InputError naming the file and line."""
        if not self.path.exists():
            return []
        lines = self.path.read_text(encoding="utf-8", errors="replace").splitlines()
        records = []
        for number, line in enumerate(lines, 1):
            if not line.strip():
                continue
            try:
                record = json.loads(line)
            except ValueError:
                record = None
            if not isinstance(record, dict):
                if number == len(lines):
                    break
                raise InputError(f"{self.path}: line {number} is not a JSON record; remove it to go on")
            records.append(record)
        return records

    def truncate_after(self, key: str, value) -> None:
        """Drop records whose ``key`` exceeds ``value`` (used when a run resumes from an earlier checkpoint)."""
        kept = [r for r in self.read() if not isinstance(r.get(key, -1), (int, float)) or r.get(key, -1) <= value]
        from mesh2tex.io.atomic import write_text

        write_text(self.path, "".join(json.dumps(r) + "\n" for r in kept))
