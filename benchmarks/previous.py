"""The packages of an earlier git revision, imported beside today's in one process, so that a
benchmark can time old and new code side by side under the same machine load.

    old = Revision("HEAD~1")                           # mesh2tex/ and train/ of that revision, extracted
    rasterize = old.module("mesh2tex.render.rasterize").rasterize
    with old.active():                                 # imports made meanwhile resolve to the old packages
        trainer = old.module("mesh2tex.train.gan").GanTrainer(...)

Both versions live under the same package names, so ``sys.modules`` holds one at a time:
:meth:`Revision.active` swaps the revision's modules in and today's out, and back. Functions and
classes already imported keep pointing at their own version either way; code that imports inside a
function body needs ``active()`` around the call.
"""

from __future__ import annotations

import contextlib
import importlib
import io
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("mesh2tex", "train")
# The stages are installed as mesh2tex.<stage> from their own top-level folders (pyproject's package-dir):
# in the extracted tree each gets a link mesh2tex/<stage> -> <stage>, or the installed (today's) one would answer.
STAGES = ("data_prep", "train", "infer", "evaluate", "app")


def _ours(name: str) -> bool:
    return name.split(".")[0] in PACKAGES + STAGES


class Revision:
    """``PACKAGES`` at git revision ``revision`` of this repository, extracted into a temporary folder
    (kept while the object lives)."""

    def __init__(self, revision: str):
        self.commit = subprocess.run(
            ["git", "rev-parse", "--short", revision], cwd=ROOT, check=True, capture_output=True, text=True
        ).stdout.strip()
        present = subprocess.run(
            ["git", "ls-tree", "--name-only", self.commit], cwd=ROOT, check=True, capture_output=True, text=True
        ).stdout.split()
        folders = [name for name in dict.fromkeys(PACKAGES + STAGES) if name in present]
        archive = subprocess.run(
            ["git", "archive", "--format=tar", self.commit, *folders], cwd=ROOT, check=True, capture_output=True
        ).stdout
        self._folder = tempfile.TemporaryDirectory(prefix=f"mesh2tex-{self.commit}-")
        with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
            tar.extractall(self._folder.name, filter="data")
        package = Path(self._folder.name) / "mesh2tex"
        for stage in STAGES:
            if stage in folders and not (package / stage).exists():
                (package / stage).symlink_to(Path("..") / stage, target_is_directory=True)
        self._modules: dict = {}

    @contextlib.contextmanager
    def active(self):
        """Within the block, ``import mesh2tex...`` and ``import train...`` give this revision's modules."""
        today = {name: sys.modules.pop(name) for name in list(sys.modules) if _ours(name)}
        sys.modules.update(self._modules)
        sys.path.insert(0, self._folder.name)
        try:
            yield self
        finally:
            sys.path.remove(self._folder.name)
            self._modules = {name: sys.modules.pop(name) for name in list(sys.modules) if _ours(name)}
            sys.modules.update(today)

    def module(self, name: str):
        """The module ``name`` (e.g. ``"mesh2tex.train.gan"``) of this revision."""
        with self.active():
            return importlib.import_module(name)
