"""A batch of prepared shapes for the face networks: faces concatenated with offsets.

Every level of every shape is stacked into one long list of faces (the Texturify layout), so a face
convolution over a whole batch is a single gather and a single matmul. Indices into faces (the
neighbourhoods, the pooling maps) and into vertices (the quads) are shifted by the shape's offset;
``-1`` stays ``-1`` (a missing neighbour). ``shape_index[l][f]`` says which shape (sample) face ``f``
of level ``l`` belongs to, which is how per-sample styles reach per-face layers.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, fields

import numpy as np
import torch

from mesh2tex.geometry.prepared import PreparedShape, quads_to_triangles


@dataclass
class MeshBatch:
    """Concatenated hierarchy of ``num_shapes`` prepared shapes (level 0 the finest).

    Per level ``l`` (lists of length ``num_levels``):
        neighbors[l]    int64 (F_l, 9)   batch face indices of the 3x3 neighbourhood, -1 missing
        shape_index[l]  int64 (F_l,)     sample of each face, in ``0 .. num_shapes-1``
        face_offsets[l] int64 (S+1,)     faces of shape s are ``face_offsets[l][s] : face_offsets[l][s+1]``
    pool[l]             int64 (F_l,)     coarse face (batch index at level l+1) of each face, l < L-1
    Finest level only:
        vertices        float32 (V, 3)   vertex positions of all shapes
        quads           int64 (F_0, 4)   batch vertex indices of each finest quad
        vertex_offsets  int64 (S+1,)
        face_features   float32 (F_0, C) geometric input features

    Derived once per batch, on first use (as trimesh caches a mesh's properties; :meth:`to` starts
    afresh): :meth:`triangles`, :meth:`shape_triangles`, :attr:`face_ranges`, :attr:`vertex_ranges`,
    :attr:`vertex_shape`. The tensors are not to be changed in place.
    """

    num_shapes: int
    neighbors: list[torch.Tensor]
    shape_index: list[torch.Tensor]
    face_offsets: list[torch.Tensor]
    pool: list[torch.Tensor]
    vertices: torch.Tensor
    quads: torch.Tensor
    vertex_offsets: torch.Tensor
    face_features: torch.Tensor

    @property
    def num_levels(self) -> int:
        return len(self.neighbors)

    def num_faces(self, level: int = 0) -> int:
        return int(self.neighbors[level].shape[0])

    @property
    def num_vertices(self) -> int:
        return int(self.vertices.shape[0])

    def triangles(self) -> torch.Tensor:
        """(2 F_0, 3) int64 batch vertex indices; triangle 2f and 2f+1 are the halves (a,b,c), (a,c,d) of quad f."""
        return self._triangles

    @functools.cached_property
    def _triangles(self) -> torch.Tensor:
        return quads_to_triangles(self.quads)

    @functools.cached_property
    def face_ranges(self) -> list[tuple[int, int]]:
        """(first, end) of each shape's finest faces in the batch: shape s has faces ``first : end`` (Python ints)."""
        offsets = self.face_offsets[0].tolist()
        return list(zip(offsets[:-1], offsets[1:]))

    @functools.cached_property
    def vertex_ranges(self) -> list[tuple[int, int]]:
        """(first, end) of each shape's vertices in the batch (Python ints)."""
        offsets = self.vertex_offsets.tolist()
        return list(zip(offsets[:-1], offsets[1:]))

    @functools.cached_property
    def vertex_shape(self) -> torch.Tensor:
        """(V,) int64: the shape (sample) of each vertex, on the device of ``vertex_offsets``."""
        counts = self.vertex_offsets[1:] - self.vertex_offsets[:-1]
        return torch.repeat_interleave(torch.arange(self.num_shapes, device=counts.device), counts)

    def shape_vertices(self, s: int) -> torch.Tensor:
        """(V_s, 3) float32 vertices of shape ``s``."""
        first, end = self.vertex_ranges[s]
        return self.vertices[first:end]

    def shape_triangles(self, s: int) -> torch.Tensor:
        """(2 F_0s, 3) int64 triangles of shape ``s`` indexing :meth:`shape_vertices` (local indices);
        its triangle t is the batch's triangle ``2 * face_ranges[s][0] + t``."""
        if s not in self._shape_triangles:
            f0, f1 = self.face_ranges[s]
            self._shape_triangles[s] = quads_to_triangles(self.quads[f0:f1] - self.vertex_offsets[s])
        return self._shape_triangles[s]

    @functools.cached_property
    def _shape_triangles(self) -> dict[int, torch.Tensor]:
        return {}

    def to(self, device) -> "MeshBatch":
        """The same batch with every tensor on ``device``."""
        moved = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, torch.Tensor):
                value = value.to(device)
            elif isinstance(value, list):
                value = [v.to(device) for v in value]
            moved[f.name] = value
        return MeshBatch(**moved)


def collate_shapes(shapes: list[PreparedShape]) -> MeshBatch:
    """Concatenate prepared shapes into one :class:`MeshBatch`; all must have the same number of levels
    and the same face-feature columns."""
    if not shapes:
        raise ValueError("collate_shapes needs at least one shape")
    levels = shapes[0].num_levels
    channels = shapes[0].face_features.shape[1]
    for shape in shapes:
        if shape.num_levels != levels:
            raise ValueError(f"shapes in a batch must share the number of levels ({shape.num_levels} != {levels})")
        if shape.face_features.shape[1] != channels:
            raise ValueError("shapes in a batch must share the face-feature columns")

    def offsets(counts):
        return torch.as_tensor(np.concatenate([[0], np.cumsum(counts)]), dtype=torch.int64)

    face_offsets = [offsets([s.face_counts[l] for s in shapes]) for l in range(levels)]
    vertex_offsets = offsets([s.vertices[0].shape[0] for s in shapes])

    def shifted(arrays, shift):
        out = []
        for array, o in zip(arrays, shift):
            a = torch.as_tensor(np.asarray(array), dtype=torch.int64)
            out.append(torch.where(a >= 0, a + int(o), a))  # -1 stays missing
        return torch.cat(out)

    neighbors = [shifted([s.neighbors[l] for s in shapes], face_offsets[l][:-1]) for l in range(levels)]
    pool = [shifted([s.pool[l] for s in shapes], face_offsets[l + 1][:-1]) for l in range(levels - 1)]
    shape_index = [
        torch.repeat_interleave(torch.arange(len(shapes)), face_offsets[l][1:] - face_offsets[l][:-1])
        for l in range(levels)
    ]
    return MeshBatch(
        num_shapes=len(shapes),
        neighbors=neighbors,
        shape_index=shape_index,
        face_offsets=face_offsets,
        pool=pool,
        vertices=torch.as_tensor(np.concatenate([s.vertices[0] for s in shapes]), dtype=torch.float32),
        quads=shifted([s.quads[0] for s in shapes], vertex_offsets[:-1]),
        vertex_offsets=vertex_offsets,
        face_features=torch.as_tensor(np.concatenate([s.face_features for s in shapes]), dtype=torch.float32),
    )
