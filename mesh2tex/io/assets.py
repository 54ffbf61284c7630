"""Writers for textured assets: GLB with an embedded base-colour texture (PNG, JPEG or WebP), PLY with
vertex colours (and :func:`load_glb`, the reader of such a GLB).

Both write atomically (``mesh2tex.io.atomic``) and take numpy arrays or torch tensors.
UV convention at this boundary is the trimesh / OpenGL one: u to the right, v up, (0, 0) the
bottom-left corner of the image (``mesh2tex.render.texture`` uses the same). glTF stores v down,
so ``save_glb`` writes (u, 1 - v); trimesh, Blender and three.js undo that when they load.
"""

from __future__ import annotations

import io
import json
import os
import struct

import numpy as np
from PIL import Image

from mesh2tex.io.atomic import write_bytes

_FLOAT, _UINT32 = 5126, 5125  # glTF component types
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_LINEAR, _LINEAR_MIPMAP_LINEAR, _CLAMP_TO_EDGE = 9729, 9987, 33071

# The texture formats a GLB can embed (``--texture-format``): PNG (lossless, the default) and JPEG are
# core glTF 2.0; WebP needs the EXT_texture_webp extension, declared required (no PNG fallback is
# stored, so a viewer without WebP support refuses the file instead of showing it untextured).
TEXTURE_FORMATS = ("png", "jpeg", "webp")
MIME_TYPES = {"png": "image/png", "jpeg": "image/jpeg", "webp": "image/webp"}
LOSSY_QUALITY = 90  # JPEG and WebP quality (Pillow's 0-100 scale)
WEBP_EXTENSION = "EXT_texture_webp"


def _array(value, dtype, name: str, columns: int | None = None) -> np.ndarray:
    if hasattr(value, "detach"):  # a torch tensor
        value = value.detach().cpu().numpy()
    array = np.ascontiguousarray(np.asarray(value), dtype=dtype)
    if columns is not None and (array.ndim != 2 or array.shape[1] != columns):
        raise ValueError(f"{name} must have shape (N, {columns}), got {array.shape}")
    return array


def _check_faces(faces: np.ndarray, vertex_count: int) -> None:
    if len(faces) and (faces.min() < 0 or faces.max() >= vertex_count):
        raise ValueError(f"faces index vertices outside 0..{vertex_count - 1}")


def png_bytes(image_rgb_uint8) -> bytes:
    """(H, W, 3) or (H, W, 4) uint8 -> PNG file bytes."""
    image = _array(image_rgb_uint8, np.uint8, "texture")
    if image.ndim != 3 or image.shape[2] not in (3, 4):
        raise ValueError(f"texture must have shape (H, W, 3) or (H, W, 4), got {image.shape}")
    buffer = io.BytesIO()
    Image.fromarray(image).save(buffer, format="PNG", compress_level=6)
    return buffer.getvalue()


def check_texture_format(texture_format: str) -> None:
    """ValueError unless ``texture_format`` is one of :data:`TEXTURE_FORMATS` (every command's ``texture_format``
    setting)."""
    if texture_format not in TEXTURE_FORMATS:
        raise ValueError(f"texture_format {texture_format!r}: choose one of {', '.join(TEXTURE_FORMATS)}")


def image_bytes(image_rgb_uint8, texture_format: str = "png") -> bytes:
    """(H, W, 3) uint8 -> file bytes in ``texture_format`` (one of :data:`TEXTURE_FORMATS`; JPEG and
    WebP lossy at :data:`LOSSY_QUALITY`, an alpha channel dropped for JPEG)."""
    check_texture_format(texture_format)
    if texture_format == "png":
        return png_bytes(image_rgb_uint8)
    image = _array(image_rgb_uint8, np.uint8, "texture")
    if image.ndim != 3 or image.shape[2] not in (3, 4):
        raise ValueError(f"texture must have shape (H, W, 3) or (H, W, 4), got {image.shape}")
    if texture_format == "jpeg":
        image = image[:, :, :3]
    buffer = io.BytesIO()
    Image.fromarray(image).save(buffer, format=texture_format.upper(), quality=LOSSY_QUALITY)
    return buffer.getvalue()


# The node rotation (x, y, z, w) that stands a z-up mesh up in glTF's y-up frame: -90 degrees about x,
# (x, y, z) -> (x, z, -y). Blender's glTF importer turns it back, so the asset lands as it was.
Z_UP_NODE_ROTATION = [-(0.5**0.5), 0.0, 0.0, 0.5**0.5]


def glb_bytes(
    vertices,
    faces,
    uv,
    texture_rgb_uint8,
    vertex_normals=None,
    name: str = "mesh",
    texture_format: str = "png",
    up_axis: str = "y",
) -> bytes:
    """A binary glTF 2.0 file holding one textured triangle mesh; see :func:`save_glb`."""
    if up_axis not in ("y", "z"):
        raise ValueError(f"up_axis must be 'y' or 'z', got {up_axis!r}")
    positions = _array(vertices, np.float32, "vertices", 3)
    triangles = _array(faces, np.int64, "faces", 3)
    texcoords = _array(uv, np.float32, "uv", 2).copy()
    if len(texcoords) != len(positions):
        raise ValueError(f"uv has {len(texcoords)} rows but there are {len(positions)} vertices (one uv per vertex)")
    _check_faces(triangles, len(positions))
    texcoords[:, 1] = 1.0 - texcoords[:, 1]  # glTF's v points down the image
    image = image_bytes(texture_rgb_uint8, texture_format)

    blobs = [positions.tobytes(), texcoords.tobytes(), triangles.astype(np.uint32).tobytes()]
    attributes = {"POSITION": 0, "TEXCOORD_0": 1}
    accessors = [
        {
            "bufferView": 0,
            "componentType": _FLOAT,
            "count": len(positions),
            "type": "VEC3",
            "min": positions.min(axis=0).tolist() if len(positions) else [0, 0, 0],
            "max": positions.max(axis=0).tolist() if len(positions) else [0, 0, 0],
        },
        {"bufferView": 1, "componentType": _FLOAT, "count": len(texcoords), "type": "VEC2"},
        {"bufferView": 2, "componentType": _UINT32, "count": triangles.size, "type": "SCALAR"},
    ]
    targets = [_ARRAY_BUFFER, _ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER]
    if vertex_normals is not None:
        normals = _array(vertex_normals, np.float32, "vertex_normals", 3)
        if len(normals) != len(positions):
            raise ValueError("vertex_normals must have one row per vertex")
        normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        blobs.append(normals.astype(np.float32).tobytes())
        targets.append(_ARRAY_BUFFER)
        attributes["NORMAL"] = len(accessors)
        accessors.append({"bufferView": len(blobs) - 1, "componentType": _FLOAT, "count": len(normals), "type": "VEC3"})
    blobs.append(image)
    targets.append(None)

    buffer_views, binary = _pack_buffers(blobs, targets)
    document = _gltf_document(name, attributes, accessors, buffer_views, len(binary), texture_format, up_axis)
    return _glb_container(document, binary)


def _pack_buffers(blobs: list[bytes], targets: list[int | None]) -> tuple[list[dict], bytearray]:
    """The glTF buffer views of ``blobs`` (one each, with its ``target`` when not None) and the binary chunk
    that holds them, every view starting 4-byte aligned."""
    buffer_views, binary = [], bytearray()
    for blob, target in zip(blobs, targets):
        view = {"buffer": 0, "byteOffset": len(binary), "byteLength": len(blob)}
        if target is not None:
            view["target"] = target
        buffer_views.append(view)
        binary += blob
        binary += b"\x00" * (-len(binary) % 4)
    return buffer_views, binary


def _gltf_document(
    name: str,
    attributes: dict,
    accessors: list[dict],
    buffer_views: list[dict],
    binary_length: int,
    texture_format: str,
    up_axis: str,
) -> dict:
    """The glTF JSON of one textured mesh whose image is the last buffer view."""
    texture = {"sampler": 0, "source": 0}
    if texture_format == "webp":  # the image is named by the extension only (no core-format fallback)
        texture = {"sampler": 0, "extensions": {WEBP_EXTENSION: {"source": 0}}}
    material = {
        "name": f"{name}_material",
        "doubleSided": True,
        "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0.0, "roughnessFactor": 1.0},
    }
    sampler = {
        "magFilter": _LINEAR,
        "minFilter": _LINEAR_MIPMAP_LINEAR,
        "wrapS": _CLAMP_TO_EDGE,
        "wrapT": _CLAMP_TO_EDGE,
    }
    document = {
        "asset": {"version": "2.0", "generator": "mesh2tex"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": name, **({"rotation": Z_UP_NODE_ROTATION} if up_axis == "z" else {})}],
        "meshes": [{"name": name, "primitives": [{"attributes": attributes, "indices": 2, "material": 0, "mode": 4}]}],
        "materials": [material],
        "textures": [texture],
        "samplers": [sampler],
        "images": [{"bufferView": len(buffer_views) - 1, "mimeType": MIME_TYPES[texture_format]}],
        "accessors": accessors,
        "bufferViews": buffer_views,
        "buffers": [{"byteLength": binary_length}],
    }
    if texture_format == "webp":
        document["extensionsUsed"] = document["extensionsRequired"] = [WEBP_EXTENSION]
    return document


def _glb_container(document: dict, binary: bytearray) -> bytes:
    """The GLB file: header, the JSON chunk (space-padded) and the binary chunk."""
    text = json.dumps(document, separators=(",", ":")).encode("utf-8")
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(binary)
    return b"".join(
        [
            struct.pack("<4sII", b"glTF", 2, total),
            struct.pack("<I4s", len(text), b"JSON"),
            text,
            struct.pack("<I4s", len(binary), b"BIN\x00"),
            bytes(binary),
        ]
    )


def save_glb(
    path: str | os.PathLike,
    vertices,
    faces,
    uv,
    texture_rgb_uint8,
    vertex_normals=None,
    name: str = "mesh",
    texture_format: str = "png",
    up_axis: str = "y",
) -> None:
    """Write a textured triangle mesh as GLB (glTF 2.0 binary) with the texture embedded as
    ``texture_format``: "png" (lossless), "jpeg" or "webp" (lossy, quality :data:`LOSSY_QUALITY`; WebP
    through the EXT_texture_webp extension, declared required).

    vertices: (V, 3) float, faces: (T, 3) int (counter-clockwise seen from outside), uv: (V, 2) float
    in [0, 1], v up (one uv per vertex: split vertices on UV seams, as ``unwrap_uv`` returns them),
    texture_rgb_uint8: (H, W, 3) uint8, row 0 the top of the image; vertex_normals: optional (V, 3)
    for smooth shading (without them viewers shade flat). Loads in trimesh, Blender and three.js (WebP:
    in viewers that support EXT_texture_webp, such as three.js's GLTFLoader and Blender 4.x).
    up_axis: 'y' (glTF's own), or 'z' for vertices of a z-up file: they are stored as they are and the
    mesh's node carries :data:`Z_UP_NODE_ROTATION`, so that viewers stand it up.
    """
    write_bytes(path, glb_bytes(vertices, faces, uv, texture_rgb_uint8, vertex_normals, name, texture_format, up_axis))


def smooth_vertex_normals(vertices, faces) -> np.ndarray:
    """(V, 3) float32 unit normals for smooth shading: area-weighted face normals summed over every
    vertex at the same position, so that vertices split on UV seams get one normal and the seams do
    not show. vertices: (V, 3) float, faces: (T, 3) int, counter-clockwise seen from outside."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    _, welded = np.unique(np.round(v, 6), axis=0, return_inverse=True)
    welded = welded.reshape(-1)
    area_normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    sums = np.zeros((welded.max() + 1, 3))
    for corner in range(3):
        np.add.at(sums, welded[f[:, corner]], area_normals)
    normals = sums[welded]
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.where(length > 1e-20, normals / np.maximum(length, 1e-20), [0.0, 0.0, 1.0]).astype(np.float32)


def load_glb(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Read a textured GLB of one mesh (as :func:`save_glb` writes): vertices (V, 3) float32, faces
    (T, 3) int64 in the file's order, uv (V, 2) float32 (v up) and the base-colour texture (H, W, 3)
    uint8. Raises ValueError naming the file when it holds no textured triangle mesh."""
    import trimesh

    try:
        scene = trimesh.load(str(path), force="scene", process=False)
    except Exception as error:  # trimesh raises many types for malformed files
        raise ValueError(
            f"{path}: cannot be read as a GLB "
            f"({str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__})"
        ) from None
    meshes = list(scene.geometry.values())
    if len(meshes) != 1 or not isinstance(meshes[0], trimesh.Trimesh):
        raise ValueError(f"{path}: expected one textured mesh, found {len(meshes)} geometries")
    mesh = meshes[0]
    visual = mesh.visual
    image = getattr(getattr(visual, "material", None), "baseColorTexture", None)
    if getattr(visual, "uv", None) is None or image is None:
        raise ValueError(f"{path}: the mesh has no UV coordinates or no base-colour texture")
    return (
        np.asarray(mesh.vertices, dtype=np.float32),
        np.asarray(mesh.faces, dtype=np.int64),
        np.asarray(visual.uv, dtype=np.float32),
        np.asarray(image.convert("RGB"), dtype=np.uint8),
    )


def ply_bytes(vertices, faces, vertex_colours_uint8) -> bytes:
    """A binary little-endian PLY with per-vertex RGB colours; see :func:`save_ply`."""
    positions = _array(vertices, np.float32, "vertices", 3)
    triangles = _array(faces, np.int64, "faces", 3)
    colours = _array(vertex_colours_uint8, np.uint8, "vertex_colours_uint8")
    if colours.ndim != 2 or colours.shape[1] not in (3, 4) or len(colours) != len(positions):
        raise ValueError(f"vertex_colours_uint8 must have shape ({len(positions)}, 3), got {colours.shape}")
    _check_faces(triangles, len(positions))
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment written by mesh2tex\n"
        f"element vertex {len(positions)}\nproperty float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        f"element face {len(triangles)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode("ascii")
    vertex_records = np.empty(len(positions), dtype=[("p", "<f4", 3), ("c", "u1", 3)])
    vertex_records["p"], vertex_records["c"] = positions, colours[:, :3]
    face_records = np.empty(len(triangles), dtype=[("n", "u1"), ("i", "<i4", 3)])
    face_records["n"], face_records["i"] = 3, triangles
    return header + vertex_records.tobytes() + face_records.tobytes()


def save_ply(path: str | os.PathLike, vertices, faces, vertex_colours_uint8) -> None:
    """Write a triangle mesh with per-vertex colours as binary PLY.

    vertices: (V, 3) float, faces: (T, 3) int, vertex_colours_uint8: (V, 3) uint8 (or (V, 4); alpha dropped).
    """
    write_bytes(path, ply_bytes(vertices, faces, vertex_colours_uint8))


def obj_text(vertices, faces, face_groups=None) -> str:
    """Wavefront OBJ text of a triangle mesh; ``face_groups`` (T,) names put runs of faces into ``g`` groups."""
    positions = _array(vertices, np.float64, "vertices", 3)
    triangles = _array(faces, np.int64, "faces", 3)
    _check_faces(triangles, len(positions))
    lines = ["# written by mesh2tex"]
    lines += [f"v {x:.8f} {y:.8f} {z:.8f}" for x, y, z in positions]
    current = None
    for index, (a, b, c) in enumerate(triangles + 1):  # OBJ indices start at 1
        if face_groups is not None and face_groups[index] != current:
            current = face_groups[index]
            lines.append(f"g {current}")
        lines.append(f"f {a} {b} {c}")
    return "\n".join(lines) + "\n"


def save_obj(path: str | os.PathLike, vertices, faces, face_groups=None) -> None:
    """Write a triangle mesh as OBJ (positions and faces only; vertices shared, so a closed mesh stays closed).

    vertices: (V, 3) float, faces: (T, 3) int, face_groups: optional (T,) group name per face.
    """
    write_bytes(path, obj_text(vertices, faces, face_groups).encode("utf-8"))
