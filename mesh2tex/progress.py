"""Progress for long loops: a tqdm bar for people, JSON lines for scripts."""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import Any, Iterable

from tqdm.auto import tqdm


def progress_bar(iterable: Iterable | None = None, total: int | None = None, desc: str = "", initial: int = 0, **kwargs) -> tqdm:
    """A tqdm bar on stderr; hidden when stderr is not a terminal and MESH2TEX_PROGRESS=0."""
    disable = os.environ.get("MESH2TEX_PROGRESS", "1") == "0"
    return tqdm(iterable, total=total, desc=desc, initial=initial, file=sys.stderr, disable=disable, dynamic_ncols=True, **kwargs)


class JsonLines:
    """Append one JSON object per line to ``path`` (flushed each time, so a crash loses nothing written)."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)

    def write(self, record: dict[str, Any]) -> None:
        record = {"time": round(time.time(), 3), **record}
        with open(self.path, "a") as handle:
            handle.write(json.dumps(record) + "\n")
            handle.flush()

    def read(self) -> list[dict[str, Any]]:
        if not self.path.exists():
            return []
        return [json.loads(line) for line in self.path.read_text().splitlines() if line.strip()]

    def truncate_after(self, key: str, value) -> None:
        """Drop records whose ``key`` exceeds ``value`` (used when a run resumes from an earlier checkpoint)."""
        kept = [r for r in self.read() if r.get(key, -1) <= value]
        from mesh2tex.io.atomic import write_text

        write_text(self.path, "".join(json.dumps(r) + "\n" for r in kept))
