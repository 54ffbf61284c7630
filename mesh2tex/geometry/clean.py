"""Repairing triangle meshes (pymeshlab) and normalising them to the ShapeNet frame.

QuadriFlow needs an edge-manifold, coherently oriented surface without degenerate faces; raw
meshes (ShapeNet, scans, CAD exports) often have duplicated vertices, zero-area faces, non-manifold
edges and small holes. :func:`clean_mesh` fixes what can be fixed; :func:`normalize` maps the mesh
to a bounding-box centre of 0 and a bounding-box diagonal of 1, as ShapeNet's normalised models.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mesh2tex.checks import check_array_shape
from mesh2tex.errors import InputError


@dataclass
class Normalization:
    """The similarity ``normalized = (original - centre) * scale``."""

    centre: np.ndarray  # (3,) float64, bounding-box centre of the original mesh
    scale: float  # 1 / bounding-box diagonal of the original mesh

    def apply(self, vertices: np.ndarray) -> np.ndarray:
        """(V, 3) original coordinates -> (V, 3) normalised coordinates."""
        return (np.asarray(vertices, dtype=np.float64) - self.centre) * self.scale

    def invert(self, vertices: np.ndarray) -> np.ndarray:
        """(V, 3) normalised coordinates -> (V, 3) original coordinates."""
        return np.asarray(vertices, dtype=np.float64) / self.scale + self.centre

    def matrix(self) -> np.ndarray:
        """(4, 4) float64 homogeneous matrix of :meth:`apply`."""
        m = np.eye(4) * self.scale
        m[3, 3] = 1.0
        m[:3, 3] = -self.centre * self.scale
        return m

    def to_json(self) -> dict:
        return {
            "center": [float(c) for c in self.centre],
            "scale": float(self.scale),
            "matrix": self.matrix().tolist(),
            "meaning": "normalized = (original - center) * scale",
        }

    def then(self, other: "Normalization") -> "Normalization":
        """The normalisation that applies this one, then ``other``."""
        return Normalization(centre=self.centre + other.centre / self.scale, scale=self.scale * other.scale)

    @classmethod
    def from_json(cls, record) -> "Normalization":
        """The transform :meth:`to_json` wrote; ValueError when ``record`` is not such a record."""
        try:
            centre = np.asarray(record["center"], dtype=np.float64).reshape(3)
            scale = float(record["scale"])
        except (KeyError, TypeError, ValueError) as error:
            raise ValueError(f"not a normalisation record ({error})") from None
        if not (np.isfinite(centre).all() and np.isfinite(scale) and scale > 0):
            raise ValueError("not a normalisation record (non-finite centre or non-positive scale)")
        return cls(centre=centre, scale=scale)


def normalize(vertices: np.ndarray) -> tuple[np.ndarray, Normalization]:
    """Centre the bounding box at the origin and scale its diagonal to 1.

    Args:
        vertices: (V, 3) float.
    Returns:
        (V, 3) float64 normalised vertices and the :class:`Normalization` that made them.
    Raises:
        InputError: all vertices coincide (zero-size bounding box), or the coordinates overflow.
    """
    check_array_shape(vertices, "normalize: vertices", ("V", 3))
    vertices = np.asarray(vertices, dtype=np.float64)
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    with np.errstate(over="ignore", invalid="ignore"):
        diagonal = float(np.linalg.norm(high - low))
    if not np.isfinite(diagonal):
        raise InputError(f"the mesh's coordinates are too large to normalise (up to {np.abs(vertices).max():.3g})")
    if diagonal <= 1e-12:
        raise InputError("the mesh has a zero-size bounding box")
    transform = Normalization(centre=(low + high) / 2.0, scale=1.0 / diagonal)
    return transform.apply(vertices), transform


# Every parameter of the two pymeshlab filters below is passed, never left to its default: MeshLab's
# plugin takes an unpassed parameter from the previous call in the process, and for the isotropic
# remeshing's surface-distance check (on/off and distance) from memory it never initialises, so the
# same mesh came out differently from one installation, one worker process or one call order to another.
DECIMATION = {
    "targetperc": 0.0,
    "qualitythr": 0.3,
    "preserveboundary": True,
    "boundaryweight": 1.0,
    "preservenormal": False,
    "preservetopology": True,
    "optimalplacement": True,
    "planarquadric": True,
    "planarweight": 0.001,
    "qualityweight": False,
    "autoclean": True,
    "selected": False,
}
ISOTROPIC_REMESHING = {
    "adaptive": False,
    "selectedonly": False,
    "featuredeg": 30.0,
    "checksurfdist": True,
    "splitflag": True,
    "collapseflag": True,
    "swapflag": True,
    "smoothflag": True,
    "reprojectflag": True,
}
ISOTROPIC_MAX_SURFACE_DISTANCE = 1.0  # per cent of the bounding-box diagonal a remeshing step may move the surface


def mesh_set(vertices: np.ndarray, faces: np.ndarray):
    """A pymeshlab MeshSet holding one mesh: (V, 3) vertices (float64) and (T, 3) triangles (int32)."""
    check_array_shape(vertices, "mesh_set: vertices", ("V", 3))
    check_array_shape(faces, "mesh_set: faces", ("T", 3))
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(
        pymeshlab.Mesh(
            vertex_matrix=np.asarray(vertices, dtype=np.float64), face_matrix=np.asarray(faces, dtype=np.int32)
        )
    )
    return ms


def _apply_filter(ms, name: str, **kwargs) -> bool:
    """Run one pymeshlab filter; a filter that refuses this mesh is skipped (False), not fatal. A setting
    the installed pymeshlab does not know raises: skipping the filter then would change every result silently."""
    import pymeshlab

    try:
        getattr(ms, name)(**kwargs)
        return True
    except pymeshlab.PyMeshLabException as error:
        if "not found for filter" in str(error):
            raise RuntimeError(f"pymeshlab {name}: {error}") from error
        return False


def clean_mesh(vertices: np.ndarray, faces: np.ndarray, max_hole_edges: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """Repair a triangle mesh for quad remeshing.

    Merges duplicate vertices, removes duplicate, zero-area and unreferenced elements, repairs
    non-manifold edges (by removing the fewest faces) and vertices (by splitting them), closes
    holes of at most ``max_hole_edges`` boundary edges and orients faces coherently.

    Args:
        vertices: (V, 3) float; faces: (T, 3) int.
    Returns:
        (V', 3) float64 vertices and (T', 3) int64 faces.
    Raises:
        InputError: nothing with area is left.
    """
    check_array_shape(vertices, "clean_mesh: vertices", ("V", 3))
    check_array_shape(faces, "clean_mesh: faces", ("T", 3))
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    # faces with a repeated index have no area and would confuse pymeshlab's topology filters
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
    if len(faces) == 0:
        raise InputError("every face is degenerate (repeated vertex)")
    ms = mesh_set(vertices, faces)
    _apply_filter(ms, "meshing_remove_duplicate_vertices")
    _apply_filter(ms, "meshing_remove_duplicate_faces")
    _apply_filter(ms, "meshing_remove_null_faces")
    _apply_filter(ms, "meshing_remove_unreferenced_vertices")
    _apply_filter(ms, "meshing_repair_non_manifold_edges", method=0)  # 0: remove faces
    _apply_filter(ms, "meshing_repair_non_manifold_vertices")
    _apply_filter(ms, "meshing_remove_unreferenced_vertices")
    if max_hole_edges > 0:
        _apply_filter(ms, "meshing_close_holes", maxholesize=int(max_hole_edges), newfaceselected=False)
    _apply_filter(ms, "meshing_re_orient_faces_coherently")
    _apply_filter(ms, "meshing_remove_null_faces")
    _apply_filter(ms, "meshing_remove_unreferenced_vertices")
    mesh = ms.current_mesh()
    out_vertices = np.asarray(mesh.vertex_matrix(), dtype=np.float64)
    out_faces = np.asarray(mesh.face_matrix(), dtype=np.int64)
    if len(out_faces) == 0 or triangle_areas(out_vertices, out_faces).sum() <= 0:
        raise InputError("no faces with area are left after repair")
    return out_vertices, out_faces


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(T,) float64 area of each triangle of (V, 3) ``vertices`` and (T, 3) ``faces``."""
    check_array_shape(vertices, "triangle_areas: vertices", ("V", 3))
    check_array_shape(faces, "triangle_areas: faces", ("T", 3))
    v = np.asarray(vertices, dtype=np.float64)[faces]
    return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)


def decimate(vertices: np.ndarray, faces: np.ndarray, target_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadric edge-collapse decimation to about ``target_faces`` triangles (pymeshlab).

    Returns (V', 3) float64 and (T', 3) int64; the input when it already has few enough faces.
    """
    check_array_shape(vertices, "decimate: vertices", ("V", 3))
    check_array_shape(faces, "decimate: faces", ("T", 3))
    if len(faces) <= target_faces:
        return np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    ms = mesh_set(vertices, faces)
    _apply_filter(ms, "meshing_decimation_quadric_edge_collapse", targetfacenum=int(max(target_faces, 4)), **DECIMATION)
    _apply_filter(ms, "meshing_remove_unreferenced_vertices")
    mesh = ms.current_mesh()
    return np.asarray(mesh.vertex_matrix(), dtype=np.float64), np.asarray(mesh.face_matrix(), dtype=np.int64)


def isotropic_remesh(
    vertices: np.ndarray, faces: np.ndarray, edge_length: float, iterations: int = 3
) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of about ``edge_length`` on the same surface (pymeshlab's isotropic explicit remeshing).

    QuadriFlow runs about twice as fast on such an even input as on the long, thin triangles of a CAD
    export. Inputs above 30 000 triangles are decimated first; sharp creases (above 30 degrees) are
    kept. Returns (V', 3) float64 and (T', 3) int64; the input when pymeshlab refuses it.
    """
    check_array_shape(vertices, "isotropic_remesh: vertices", ("V", 3))
    check_array_shape(faces, "isotropic_remesh: faces", ("T", 3))
    import pymeshlab

    vertices, faces = decimate(vertices, faces, 30_000)
    ms = mesh_set(vertices, faces)
    if not _apply_filter(
        ms,
        "meshing_isotropic_explicit_remeshing",
        targetlen=pymeshlab.PureValue(float(edge_length)),
        iterations=int(iterations),
        maxsurfdist=pymeshlab.PercentageValue(ISOTROPIC_MAX_SURFACE_DISTANCE),
        **ISOTROPIC_REMESHING,
    ):
        return np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    _apply_filter(ms, "meshing_remove_unreferenced_vertices")
    mesh = ms.current_mesh()
    if mesh.face_number() == 0:
        return np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    return np.asarray(mesh.vertex_matrix(), dtype=np.float64), np.asarray(mesh.face_matrix(), dtype=np.int64)
