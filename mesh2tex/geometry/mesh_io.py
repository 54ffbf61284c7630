"""Loading triangle meshes from the common file formats into plain arrays.

``load_mesh`` reads .obj .ply .off .stl .glb .gltf with trimesh, merges every part of a scene
(applying each node's transform), triangulates polygons and rejects anything that is not a usable
surface with a :class:`~mesh2tex.errors.InputError` that says why.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from mesh2tex.errors import InputError

MESH_SUFFIXES = (".obj", ".ply", ".off", ".stl", ".glb", ".gltf")


def is_mesh_file(path: str | os.PathLike) -> bool:
    """True when ``path`` has one of the suffixes :func:`load_mesh` reads (case-insensitive)."""
    return Path(path).suffix.lower() in MESH_SUFFIXES


def _geometry_parts(loaded) -> list:
    """The geometries of a loaded trimesh object, scene transforms applied (a list of trimesh objects)."""
    import trimesh

    if isinstance(loaded, trimesh.Scene):
        parts = []
        for node_name in loaded.graph.nodes_geometry:
            transform, geometry_name = loaded.graph[node_name]
            geometry = loaded.geometry[geometry_name].copy()
            geometry.apply_transform(transform)
            parts.append(geometry)
        return parts
    if isinstance(loaded, (list, tuple)):
        return [part for item in loaded for part in _geometry_parts(item)]
    return [loaded]


def load_mesh(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a triangle mesh; all parts of a multi-part file are merged into one mesh.

    Args:
        path: a .obj .ply .off .stl .glb or .gltf file.
    Returns:
        vertices: (V, 3) float64; faces: (T, 3) int64 indices into ``vertices``.
    Raises:
        InputError: the file is missing, empty, unreadable, not a mesh, a point cloud, has no faces,
        or has a vertex with non-finite coordinates.
    """
    import trimesh

    path = Path(path)
    if path.is_symlink() and not path.exists():
        raise InputError(f"{path}: a broken or looping symbolic link")
    if not path.exists():
        raise InputError(f"{path}: file not found")
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not a mesh file")
    if not is_mesh_file(path):
        raise InputError(f"{path}: unsupported mesh format '{path.suffix}' (expected one of {' '.join(MESH_SUFFIXES)})")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file")
    try:
        # materials and textures are irrelevant to the geometry and slow to read
        loaded = trimesh.load(str(path), process=False, skip_materials=True)
    except Exception as error:  # trimesh raises many types for malformed files
        message = str(error).strip().splitlines()[0] if str(error).strip() else error.__class__.__name__
        if isinstance(error, ImportError):  # trimesh reaches for an optional decoder when the bytes are no known format
            message = f"not a valid {path.suffix.lower()} file"
        raise InputError(f"{path}: cannot be read as a mesh ({message})") from None

    vertex_blocks, face_blocks, offset = [], [], 0
    point_cloud_parts = 0
    for part in _geometry_parts(loaded):
        if isinstance(part, trimesh.PointCloud):
            point_cloud_parts += 1
            continue
        if not isinstance(part, trimesh.Trimesh):
            continue  # 2-D/3-D paths and other non-surface geometry carry no faces
        faces = np.asarray(part.faces, dtype=np.int64).reshape(-1, 3)
        vertices = np.asarray(part.vertices, dtype=np.float64).reshape(-1, 3)
        if len(faces) == 0:
            if len(vertices):
                point_cloud_parts += 1
            continue
        vertex_blocks.append(vertices)
        face_blocks.append(faces + offset)
        offset += len(vertices)
    if not face_blocks:
        if point_cloud_parts:
            raise InputError(f"{path}: is a point cloud (vertices but no faces); a surface mesh is needed")
        raise InputError(f"{path}: contains no faces")
    vertices = np.concatenate(vertex_blocks)
    faces = np.concatenate(face_blocks)
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InputError(f"{path}: face indices refer to vertices that do not exist")
    finite = np.isfinite(vertices).all(axis=1)
    if not finite.all():  # a damaged file: dropping its faces would change the shape without a word
        used = int((~finite[faces]).any(axis=1).sum())
        raise InputError(f"{path}: {int((~finite).sum())} vertex(es) with non-finite (NaN or infinite) coordinates, "
                        f"used by {used} of {len(faces)} faces")
    return vertices, faces
