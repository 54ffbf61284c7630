"""Loading meshes from the common file formats into plain arrays.

:func:`load_user_mesh` reads .obj .ply .off .stl .glb .gltf with trimesh into a :class:`UserMesh`: the
mesh as the file holds it, the asset every inferring command hands back, textured. The prepared quad
hierarchy (:mod:`mesh2tex.geometry.prepare`) is a working copy in a normalised, y-up frame;
:class:`UserMesh` keeps what the user gave: vertex positions in the file's own frame and units, its
faces (polygons triangulated, nothing added or removed), its UVs and normals when it has them, and
which axis is up. :func:`load_mesh` gives the vertices and faces alone.

The up axis (``--up y|z|auto``): glTF is y-up by definition; STL files (CAD and 3D printing) are
taken as z-up; OBJ, PLY and OFF as y-up (the convention of ShapeNet and of most tools' OBJ exports).
``auto`` applies that rule and says so; ``y`` or ``z`` overrides it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mesh2tex.errors import InputError

MESH_SUFFIXES = (".obj", ".ply", ".off", ".stl", ".glb", ".gltf")

UP_AXES = ("auto", "y", "z")
Z_UP_SUFFIXES = (".stl",)  # the formats taken as z-up by --up auto; the rest are y-up
GLTF_SUFFIXES = (".glb", ".gltf")
# (3, 3) rotation from a z-up frame to the y-up one: (x, y, z) -> (x, z, -y), the glTF exporters' conversion
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def choose_up(path: str | os.PathLike, up: str = "auto") -> tuple[str, str]:
    """(axis 'y' or 'z', why) for the mesh file ``path`` under ``--up up`` (see the module docstring)."""
    if up not in UP_AXES:
        raise InputError(f"--up {up!r}: choose one of {', '.join(UP_AXES)}")
    suffix = Path(path).suffix.lower()
    if up != "auto":
        if up == "z" and suffix in GLTF_SUFFIXES:
            return "y", f"glTF is y-up by definition (--up z ignored for {suffix})"
        return up, f"--up {up}"
    if suffix in GLTF_SUFFIXES:
        return "y", "glTF is y-up by definition"
    if suffix in Z_UP_SUFFIXES:
        return "z", f"{suffix} files are usually z-up; pass --up y if this one is not"
    return "y", f"{suffix} files are usually y-up; pass --up z if this one is not"


@dataclass
class UserMesh:
    """A triangle mesh as its file holds it.

    path: the file; vertices: (V, 3) float64 in the file's frame and units; faces: (T, 3) int64
    (polygons fanned into triangles, corners in the file's order); uv: (V, 2) float64 (v up) when the
    file gives every vertex one, else None; normals: (V, 3) float64 when the file has them, else None;
    up: 'y' or 'z', the file's up axis; up_reason: why (:func:`choose_up`).
    """

    path: str
    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray | None
    normals: np.ndarray | None
    up: str = "y"
    up_reason: str = ""

    def to_working_frame(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) points of the file's frame -> (N, 3) float64 in the y-up frame a prepared shape is normalised from."""
        points = np.asarray(points, dtype=np.float64)
        return points @ Z_UP_TO_Y_UP.T if self.up == "z" else points

    def working_vertices(self) -> np.ndarray:
        """(V, 3) float64 vertices in the y-up working frame (what :func:`mesh2tex.geometry.prepare.prepare_shape`
        takes)."""
        return self.to_working_frame(self.vertices)


def _parts(loaded) -> list:
    """The geometries of a loaded trimesh object, each with its scene transform applied."""
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
        return [part for item in loaded for part in _parts(item)]
    return [loaded]


def _file_normals(part) -> np.ndarray | None:
    """The vertex normals a trimesh part was loaded with, or None when the file had none (trimesh
    computes them lazily otherwise, which would pass computed normals off as the file's)."""
    normals = part._cache.cache.get("vertex_normals") if hasattr(part, "_cache") else None
    if normals is None or len(normals) != len(part.vertices):
        return None
    return np.asarray(normals, dtype=np.float64)


def check_path(path: Path) -> None:
    """InputError unless ``path`` is an existing, non-empty mesh file of a format :func:`load_user_mesh` reads."""
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


def load_user_mesh(path: str | os.PathLike, up: str = "auto") -> UserMesh:
    """Read a mesh file as it is (.obj .ply .off .stl .glb .gltf): every part of a scene, with its node
    transform applied, merged into one mesh; vertices kept as the reader gives them (duplicates
    included; unreferenced ones too, except in OBJ files, whose reader drops them), polygons fanned
    into triangles.

    Raises:
        InputError: naming the file: missing, empty, unreadable, a point cloud, no faces, vertices
        with non-finite coordinates, or face indices out of range.
    """
    import trimesh

    path = Path(path)
    check_path(path)
    axis, reason = choose_up(path, up)
    try:
        # materials are not read (slow, and the texture is what we make); UVs and normals are
        loaded = trimesh.load(str(path), process=False, skip_materials=True)
    except Exception as error:  # trimesh raises many types for malformed files
        message = str(error).strip().splitlines()[0] if str(error).strip() else error.__class__.__name__
        if isinstance(error, ImportError):  # trimesh reaches for an optional decoder when the bytes are no known format
            message = f"not a valid {path.suffix.lower()} file"
        raise InputError(f"{path}: cannot be read as a mesh ({message})") from None

    parts = _parts(loaded)
    if not parts:  # trimesh reads bytes of no known layout as an empty scene
        raise InputError(f"{path}: cannot be read as a mesh (not a valid {path.suffix.lower()} file)")
    vertex_blocks, face_blocks, uv_blocks, normal_blocks, offset = [], [], [], [], 0
    point_cloud_parts = 0
    for part in parts:
        if isinstance(part, trimesh.PointCloud):
            point_cloud_parts += 1
            continue
        if not isinstance(part, trimesh.Trimesh):
            continue  # 2-D/3-D paths and other non-surface geometry carry no faces
        faces = np.asarray(part.faces, dtype=np.int64).reshape(-1, 3)
        vertices = np.asarray(part.vertices, dtype=np.float64).reshape(-1, 3)
        if len(faces) == 0:
            point_cloud_parts += bool(len(vertices))
            continue
        uv = getattr(part.visual, "uv", None)
        uv_blocks.append(None if uv is None or len(uv) != len(vertices) else np.asarray(uv, dtype=np.float64))
        normal_blocks.append(_file_normals(part))
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
        raise InputError(
            f"{path}: {int((~finite).sum())} vertex(es) with non-finite (NaN or infinite) coordinates, "
            f"used by {used} of {len(faces)} faces"
        )
    uv = np.concatenate(uv_blocks) if all(b is not None for b in uv_blocks) else None
    normals = np.concatenate(normal_blocks) if all(b is not None for b in normal_blocks) else None
    if uv is not None and not np.isfinite(uv).all():
        uv = None
    if normals is not None and not np.isfinite(normals).all():
        normals = None
    return UserMesh(str(path), vertices, faces, uv, normals, axis, reason)


def is_mesh_file(path: str | os.PathLike) -> bool:
    """True when ``path`` has one of the suffixes :func:`load_mesh` reads (case-insensitive)."""
    return Path(path).suffix.lower() in MESH_SUFFIXES


def load_mesh(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """The vertices (V, 3) float64 and faces (T, 3) int64 of :func:`load_user_mesh`, in the file's frame."""
    mesh = load_user_mesh(path)
    return mesh.vertices, mesh.faces
