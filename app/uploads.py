"""A visitor's uploads: read into the visitor's folder without ever writing more than the bound, then
checked as the command that reads them checks them, so that a bad file is refused with the command's own
one-line message before any job starts.

A body is read as it arrives (the page sends the file itself as the request body, not a multipart form,
which a server would spool whole before looking at it): a ``Content-Length`` over the bound is refused
before a byte is written, and a body without one is cut off as soon as it passes the bound, its partial
file deleted.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

from mesh2tex.app.jobs import Refused

from mesh2tex.errors import InputError

# Self-contained mesh files (a .gltf names other files, which an upload does not bring).
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".webp", ".bmp")
MODEL_SUFFIXES = (".safetensors",)
# what each upload is, the suffixes it may have and which limit of AppConfig bounds it
ROLES = {
    "mesh": ("a mesh", MESH_SUFFIXES, "max_mesh_mb"),
    "photo": ("a photo", IMAGE_SUFFIXES, "max_photo_mb"),
    "exemplar": ("an exemplar image", IMAGE_SUFFIXES, "max_photo_mb"),
    "nca": ("an NCA model", MODEL_SUFFIXES, "max_photo_mb"),
}
# the first bytes of files people mistake for meshes or photos (none short enough to open a text mesh by chance)
MAGIC = [
    (b"\x89PNG\r\n\x1a\n", "a PNG image"),
    (b"\xff\xd8\xff", "a JPEG image"),
    (b"GIF87a", "a GIF image"),
    (b"GIF89a", "a GIF image"),
    (b"%PDF-", "a PDF document"),
    (b"PK\x03\x04", "a ZIP archive"),
    (b"glTF", "a GLB mesh"),
]
# what a file of each suffix with a signature starts as
SIGNED = {
    ".png": "a PNG image",
    ".jpg": "a JPEG image",
    ".jpeg": "a JPEG image",
    ".glb": "a GLB mesh",
    ".webp": "a WebP image",
}


@dataclass
class Upload:
    """A checked upload: its file and what the page shows of it."""

    role: str
    path: Path
    summary: str


def safe_name(name: str, role: str) -> str:
    """The uploaded file's own name, reduced to a plain file name (no folders, no odd characters)."""
    base = re.sub(r"[^A-Za-z0-9._-]+", "_", os.path.basename(name.replace("\\", "/"))).lstrip(".")[-80:]
    return base or f"{role}.bin"


def check_name(name: str, role: str) -> None:
    """Refused unless ``name`` has a suffix the role takes."""
    what, suffixes, _ = ROLES[role]
    suffix = Path(name).suffix.lower()
    if suffix not in suffixes:
        raise Refused(415, f"{name}: unsupported format '{suffix}' for {what} (expected one of {' '.join(suffixes)})")


def megabytes(size: int) -> str:
    return f"{size / 2**20:.1f} MB"


async def receive(request, target: Path, limit: int) -> int:
    """Write ``request``'s body to ``target``, refusing (413) a body over ``limit`` bytes: by its declared
    length before reading, else as soon as the bytes read pass it. Returns the size written."""
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > limit:
        raise Refused(413, f"{target.name}: {megabytes(int(declared))} is over the upload limit of {megabytes(limit)}")
    partial = target.with_name(f".{target.name}.partial")
    written = 0
    try:
        with open(partial, "wb") as handle:
            async for chunk in request.stream():
                written += len(chunk)
                if written > limit:
                    raise Refused(413, f"{target.name}: over the upload limit of {megabytes(limit)}")
                handle.write(chunk)
        os.replace(partial, target)
    finally:
        partial.unlink(missing_ok=True)
    return written


def what_is(head: bytes) -> str | None:
    """What the first bytes of a file say it is (None: no known signature)."""
    if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        return "a WebP image"
    return next((what for magic, what in MAGIC if head.startswith(magic)), None)


def sniff(path: Path, role: str) -> None:
    """Refused when the first bytes say the file is something else than its suffix claims."""
    with open(path, "rb") as handle:
        head = handle.read(16)
    if not head:
        raise Refused(422, f"{path.name}: empty file")
    suffix, found = path.suffix.lower(), what_is(head)
    expected = SIGNED.get(suffix)
    if found is not None and found != expected:
        raise Refused(422, f"{path.name}: is {found}, not {ROLES[role][0]} ({suffix} file)")
    if expected is not None and found != expected:
        raise Refused(422, f"{path.name}: not a valid {suffix} file")


def check(path: Path, role: str, preview: Path | None = None) -> str:
    """Check an upload as the command that reads it does; returns a summary line for the page, or
    raises Refused with the command's own one-line message (naming the file, not its folder). A mesh
    is also written to ``preview`` as an untextured GLB, y up, for the viewer."""
    sniff(path, role)
    try:
        if role == "mesh":
            from mesh2tex.geometry.mesh_io import load_user_mesh

            mesh = load_user_mesh(path)
            if preview is not None:
                write_mesh_preview(mesh, preview)
            return f"{path.name}: {len(mesh.vertices)} vertices, {len(mesh.faces)} triangles ({mesh.up}-up)"
        if role in ("photo", "exemplar"):
            from mesh2tex.io.images import load_image

            rgb, alpha = load_image(path)
            return f"{path.name}: {rgb.shape[1]} x {rgb.shape[0]} pixels{' with a mask' if alpha is not None else ''}"
        if (
            role == "nca"
        ):  # read as 'infer nca' reads it: a mesh2tex automaton checkpoint, its weights fitting its config
            from mesh2tex.models import load_nca

            load_nca(path)
    except InputError as error:
        raise Refused(422, str(error).replace(f"{path.parent}{os.sep}", "")) from None
    return f"{path.name}: {megabytes(path.stat().st_size)}"


def write_mesh_preview(mesh, target: Path) -> None:
    """The user's mesh as the commands read it, untextured, as a GLB (a z-up file turned y-up, as their GLBs are)."""
    import trimesh

    trimesh.Trimesh(mesh.working_vertices(), mesh.faces, process=False).export(target, file_type="glb")
