"""Meshes a user brings, made apart from the synthetic world's code: a three-legged stool of separate
parts (several components, open tubes), with or without UVs, in each file format, z-up and scaled."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

# (x, y, z) of a y-up frame -> the same point in a z-up frame (the inverse of the glTF conversion)
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def stool(sections: int = 16) -> trimesh.Trimesh:
    """A stool, y-up, in metres: a round seat, three splayed legs (open-ended tubes) and a ring; parts
    not welded together, as modelling tools export them."""
    seat = trimesh.creation.cylinder(radius=0.2, height=0.04, sections=sections)
    seat.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    seat.apply_translation([0, 0.45, 0])
    parts = [seat]
    for k in range(3):
        angle = 2 * np.pi * k / 3
        foot = np.array([0.22 * np.cos(angle), 0.0, 0.22 * np.sin(angle)])
        top = np.array([0.12 * np.cos(angle), 0.44, 0.12 * np.sin(angle)])
        leg = trimesh.creation.cylinder(radius=0.015, segment=[foot, top], sections=8)
        keep = np.abs(leg.face_normals @ ((top - foot) / np.linalg.norm(top - foot))) < 0.9  # drop the caps: open tubes
        parts.append(trimesh.Trimesh(leg.vertices, leg.faces[keep], process=False))
    ring = trimesh.creation.torus(major_radius=0.17, minor_radius=0.01, major_sections=24, minor_sections=6)
    ring.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    ring.apply_translation([0, 0.18, 0])
    parts.append(ring)
    return trimesh.util.concatenate(parts)


def with_planar_uvs(mesh: trimesh.Trimesh, mirrored: bool = False) -> trimesh.Trimesh:
    """The mesh with UVs from an xatlas atlas (a usable one), or, ``mirrored``, a projection that maps
    the front and the back of the mesh onto the same texels (not usable for baking)."""
    import xatlas

    if mirrored:
        low, high = mesh.bounds
        uv = (mesh.vertices[:, :2] - low[:2]) / (high[:2] - low[:2])
        return trimesh.Trimesh(mesh.vertices, mesh.faces, visual=trimesh.visual.TextureVisuals(uv=uv), process=False)
    vertex_map, faces, uv = xatlas.parametrize(mesh.vertices.astype(np.float32), mesh.faces.astype(np.uint32))
    return trimesh.Trimesh(mesh.vertices[vertex_map], faces, visual=trimesh.visual.TextureVisuals(uv=uv), process=False)


def write_obj(path: Path, vertices, faces, uv=None) -> Path:
    """An OBJ written by hand: vertices, UVs (one per vertex) when given, triangles."""
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in np.asarray(vertices, dtype=np.float64)]
    if uv is not None:
        lines += [f"vt {u:.9g} {v:.9g}" for u, v in np.asarray(uv, dtype=np.float64)]
    face_lines = []
    for a, b, c in np.asarray(faces) + 1:
        face_lines.append(f"f {a}/{a} {b}/{b} {c}/{c}" if uv is not None else f"f {a} {b} {c}")
    path.write_text("\n".join(lines + face_lines) + "\n")
    return path


def user_files(folder: Path) -> dict[str, Path]:
    """The stool in each format a user may bring: {name: path}."""
    folder.mkdir(parents=True, exist_ok=True)
    mesh = stool()
    files = {}
    for suffix in ("obj", "ply", "off", "glb"):
        files[suffix] = folder / f"stool.{suffix}"
        mesh.export(files[suffix])
    # centimetres... of a giant
    z_up = trimesh.Trimesh(mesh.vertices @ Y_UP_TO_Z_UP.T * 40.0, mesh.faces, process=False)
    files["stl"] = folder / "stool_z_up.stl"
    z_up.export(files["stl"])
    return files
