"""The prepared-shape record: a quad-mesh hierarchy with neighbourhoods, pooling maps and features.

One ``<name>.npz`` per shape (see docs/prepared_shape_format.md), loadable with
``np.load(path, allow_pickle=False)``. Level 0 is the finest.

Arrays, for every level ``l`` in ``0 .. L-1``:
    vertices_{l}   float32 (V_l, 3)  positions in the normalised frame (bbox centre 0, diagonal 1)
    quads_{l}      int64   (F_l, 4)  vertex indices of each quad, in cyclic order
    neighbors_{l}  int64   (F_l, 9)  column 0 the face itself, then its 8 ring faces in rotational
                                    order, edge and corner neighbours alternating; -1 where missing
    pool_{l}       int64   (F_l,)    index of the coarser face (level l+1) each face maps to (not for l = L-1)
Plus:
    face_features  float32 (F_0, C)  geometric features of the finest faces
    feature_names  str     (C,)      name of each feature column
    noc_0          float32 (V_0, 3)  NOC coordinates of the finest vertices, in [0, 1]^3
    metadata       str     ()        JSON: schema_version, source, transform, seconds, seeds, ...
"""

from __future__ import annotations

import functools
import json
import os
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mesh2tex.checks import check_array_shape
from mesh2tex.errors import InputError
from mesh2tex.io.atomic import atomic_path

SCHEMA_VERSION = 1
# Largest prepared shape read (its arrays uncompressed): a 6144-quad shape of 5 levels is about 1 MB.
MAX_UNCOMPRESSED_BYTES = 1 << 30
MAX_LEVELS = 16


def quads_to_triangles(quads):
    """(F, 4) quads -> (2F, 3) triangles: quad f gives (a, b, c) as 2f and (a, c, d) as 2f + 1.

    The project's one quad split (prepared shapes, mesh batches, renders, exports all index it).
    A torch tensor stays a tensor on its device (this module does not import torch, so it checks by
    duck type); anything else becomes an int64 numpy array.
    """
    check_array_shape(quads, "quads_to_triangles: quads", ("F", 4))
    if not hasattr(quads, "device"):
        quads = np.asarray(quads, dtype=np.int64)
    return quads[:, [0, 1, 2, 0, 2, 3]].reshape(-1, 3)


@dataclass
class PreparedShape:
    """Plain arrays of a prepared shape; see the module docstring for shapes and meaning."""

    vertices: list[np.ndarray]  # per level, (V_l, 3) float32
    quads: list[np.ndarray]  # per level, (F_l, 4) int64
    neighbors: list[np.ndarray]  # per level, (F_l, 9) int64
    pool: list[np.ndarray]  # per level but the coarsest, (F_l,) int64
    face_features: np.ndarray  # (F_0, C) float32
    feature_names: list[str]
    noc: np.ndarray  # (V_0, 3) float32
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def num_levels(self) -> int:
        return len(self.quads)

    @property
    def face_counts(self) -> list[int]:
        return [int(q.shape[0]) for q in self.quads]

    def triangles(self, level: int = 0) -> np.ndarray:
        """(2 F_l, 3) int64: each quad (a, b, c, d) split into (a, b, c) and (a, c, d).

        Triangle ``2 f`` and ``2 f + 1`` belong to quad ``f``. Split once per level, on first use (not
        to be changed in place; ``torch.as_tensor`` of it shares its memory).
        """
        if level not in self._triangles:
            self._triangles[level] = quads_to_triangles(self.quads[level])
        return self._triangles[level]

    @functools.cached_property
    def _triangles(self) -> dict[int, np.ndarray]:
        return {}

    def save(self, path: str | os.PathLike) -> None:
        """Write the record atomically as an uncompressed-pickle-free .npz."""
        arrays: dict[str, np.ndarray] = {}
        for level in range(self.num_levels):
            arrays[f"vertices_{level}"] = np.asarray(self.vertices[level], dtype=np.float32)
            arrays[f"quads_{level}"] = np.asarray(self.quads[level], dtype=np.int64)
            arrays[f"neighbors_{level}"] = np.asarray(self.neighbors[level], dtype=np.int64)
        for level, pool in enumerate(self.pool):
            arrays[f"pool_{level}"] = np.asarray(pool, dtype=np.int64)
        arrays["face_features"] = np.asarray(self.face_features, dtype=np.float32)
        arrays["feature_names"] = np.asarray(self.feature_names, dtype=np.str_)
        arrays["noc_0"] = np.asarray(self.noc, dtype=np.float32)
        metadata = {"schema_version": SCHEMA_VERSION, "num_levels": self.num_levels, **self.metadata}
        arrays["metadata"] = np.asarray(json.dumps(metadata), dtype=np.str_)
        with atomic_path(path, suffix=".npz") as tmp:
            np.savez_compressed(tmp, **arrays)

    def validate(self) -> None:
        """ValueError naming the first array whose shape, index range or values are not a prepared shape's."""
        levels = self.num_levels
        if (
            not 1 <= levels <= MAX_LEVELS
            or len(self.vertices) != levels
            or len(self.neighbors) != levels
            or len(self.pool) != levels - 1
        ):
            raise ValueError(f"inconsistent level count ({levels} quad levels, {len(self.pool)} pooling maps)")

        def check(name, array, shape, low=None, high=None, finite=False):
            if array.ndim != len(shape) or any(s is not None and a != s for a, s in zip(array.shape, shape)):
                raise ValueError(
                    f"{name} has shape {array.shape}, expected {tuple('N' if s is None else s for s in shape)}"
                )
            if not np.issubdtype(array.dtype, np.integer if low is not None else np.number):
                raise ValueError(
                    f"{name} holds {array.dtype} values, expected {'integers' if low is not None else 'numbers'}"
                )
            if finite and not np.isfinite(array).all():
                raise ValueError(f"{name} holds NaN or infinite values")
            if array.size and low is not None and (array.min() < low or array.max() >= high):
                raise ValueError(f"{name} has indices outside [{low}, {high})")

        for l in range(levels):
            check(f"vertices_{l}", self.vertices[l], (None, 3), finite=True)
            faces = self.quads[l].shape[0] if self.quads[l].ndim == 2 else -1
            check(f"quads_{l}", self.quads[l], (None, 4), 0, self.vertices[l].shape[0])
            check(f"neighbors_{l}", self.neighbors[l], (faces, 9), -1, faces)
            if l + 1 < levels:
                check(f"pool_{l}", self.pool[l], (faces,), 0, self.quads[l + 1].shape[0])
        check("face_features", self.face_features, (self.quads[0].shape[0], len(self.feature_names)), finite=True)
        check("noc_0", self.noc, (self.vertices[0].shape[0], 3), finite=True)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "PreparedShape":
        """Read a record written by :meth:`save`; a damaged, foreign or inconsistent file (see
        :meth:`validate`), or one that would inflate beyond ``MAX_UNCOMPRESSED_BYTES``, is a :class:`InputError`."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                if not isinstance(data, np.lib.npyio.NpzFile):
                    raise ValueError("not an .npz archive")
                inflated = sum(info.file_size for info in data.zip.infolist())
                if inflated > MAX_UNCOMPRESSED_BYTES:
                    raise ValueError(
                        f"its arrays would take {inflated / 2**30:.1f} GiB, more than the "
                        f"{MAX_UNCOMPRESSED_BYTES / 2**30:.0f} GiB a prepared shape may"
                    )
                metadata = json.loads(str(data["metadata"]))
                if not isinstance(metadata, dict):
                    raise ValueError("its metadata is not a JSON mapping")
                if metadata.get("schema_version") != SCHEMA_VERSION:
                    raise InputError(
                        f"{path}: prepared-shape schema {metadata.get('schema_version')} is not supported (expected "
                        f"{SCHEMA_VERSION}); re-run 'mesh2tex prepare shapes'"
                    )
                levels = metadata.get("num_levels")
                if not isinstance(levels, int) or not 1 <= levels <= MAX_LEVELS:
                    raise ValueError(f"num_levels {levels!r} is not a level count")
                shape = cls(
                    vertices=[data[f"vertices_{l}"] for l in range(levels)],
                    quads=[data[f"quads_{l}"] for l in range(levels)],
                    neighbors=[data[f"neighbors_{l}"] for l in range(levels)],
                    pool=[data[f"pool_{l}"] for l in range(levels - 1)],
                    face_features=data["face_features"],
                    feature_names=[str(n) for n in data["feature_names"]],
                    noc=data["noc_0"],
                    metadata=metadata,
                )
            shape.validate()
            return shape
        except InputError:
            raise
        except FileNotFoundError:
            raise InputError(f"{path}: prepared shape not found") from None
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error, RecursionError) as error:
            raise InputError(f"{path}: not a valid prepared shape ({error.__class__.__name__}: {error})") from None


def shape_paths(folder: str | os.PathLike) -> dict[str, Path]:
    """{name: path} of the prepared shapes (``<name>.npz``) in ``folder``, sorted by name; InputError
    when the folder is missing or holds none."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: prepared-shape folder not found (make it with 'mesh2tex prepare shapes')")
    # hidden: half-written by an old version
    found = {p.stem: p for p in sorted(folder.glob("*.npz")) if not p.name.startswith(".")}
    if not found:
        raise InputError(f"{folder}: no prepared shapes (*.npz); run 'mesh2tex prepare shapes' first")
    return found


def load_shapes(folder: str | os.PathLike) -> tuple[list[PreparedShape], list[str]]:
    """All prepared shapes of ``folder`` (:func:`shape_paths`) and their names; they must share levels and
    feature columns (InputError naming the first that does not)."""
    paths = list(shape_paths(folder).values())
    shapes = [PreparedShape.load(p) for p in paths]
    first = shapes[0]
    for path, shape in zip(paths, shapes):
        if shape.num_levels != first.num_levels or list(shape.feature_names) != list(first.feature_names):
            raise InputError(
                f"{path}: levels or face features differ from {paths[0].name}; prepare all shapes with the same "
                "settings"
            )
    return shapes, [p.stem for p in paths]
