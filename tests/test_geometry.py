"""Quad hierarchies: loading, repair, remeshing, neighbourhoods, pooling and features on shapes built here."""

from __future__ import annotations

import os

import numpy as np
import pytest
import trimesh

from mesh2tex.errors import InputError
from mesh2tex.geometry.clean import clean_mesh, decimate, isotropic_remesh, mesh_set, normalize
from mesh2tex.geometry.features import face_features, fundamental_forms, noc_coordinates
from mesh2tex.geometry.hierarchy import face_neighborhoods, orient_coherently, pooling_map
from mesh2tex.geometry.mesh_io import load_mesh
from mesh2tex.geometry.prepare import prepare_shape
from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.geometry.quadremesh import quadriflow, triangles_to_quads
from mesh2tex.geometry.quadriflow import _run_forked


def box_chair() -> trimesh.Trimesh:
    """Seat, back and four legs: six overlapping boxes (the kind of shape QuadriFlow fails on when coarse)."""
    parts = [
        trimesh.creation.box((1, 0.1, 1)).apply_translation((0, 0.5, 0)),
        trimesh.creation.box((1, 1, 0.1)).apply_translation((0, 1.0, -0.45)),
    ]
    parts += [
        trimesh.creation.box((0.1, 0.5, 0.1)).apply_translation((x, 0.22, z))
        for x in (-0.45, 0.45)
        for z in (-0.45, 0.45)
    ]
    return trimesh.util.concatenate(parts)


def sphere_with_hole() -> trimesh.Trimesh:
    sphere = trimesh.creation.icosphere(3)
    keep = sphere.triangles_center[:, 2] < 0.97  # a small cap removed
    return trimesh.Trimesh(sphere.vertices, sphere.faces[keep])


def non_manifold_mesh() -> trimesh.Trimesh:
    """Two boxes plus a fin: an extra triangle hanging on an edge of the first box (three faces on one edge)."""
    box = trimesh.creation.box()
    v, f = box.vertices, box.faces
    a, b = f[0][0], f[0][1]
    fin_vertex = len(v)
    vertices = np.vstack([v, (v[a] + v[b]) / 2 + np.array([0.0, 0.0, 0.0]) + 0.8 * np.cross(v[b] - v[a], [0, 1, 0.3])])
    faces = np.vstack([f, [[a, b, fin_vertex]]])
    return trimesh.Trimesh(vertices, faces, process=False)


SHAPES = {
    "box": lambda: trimesh.creation.box((1.0, 0.6, 0.4)),
    "sphere": lambda: trimesh.creation.icosphere(3),
    "torus": lambda: trimesh.creation.torus(1.0, 0.35, major_sections=48, minor_sections=16),
    "chair": box_chair,
    "hole": sphere_with_hole,
    "non_manifold": non_manifold_mesh,
}


@pytest.fixture(scope="module")
def prepared() -> dict[str, PreparedShape]:
    """Each test shape prepared once with a small hierarchy: 384, 96, 24 faces."""
    return {
        name: prepare_shape(make().vertices, make().faces, face_count=384, levels=3, seed=0, source=name)
        for name, make in SHAPES.items()
    }


def check_neighborhoods(quads: np.ndarray, neighbors: np.ndarray) -> None:
    """The invariants of a 3x3 neighbourhood table (see mesh2tex.geometry.hierarchy)."""
    f = len(quads)
    assert neighbors.shape == (f, 9) and neighbors.dtype == np.int64
    assert np.array_equal(neighbors[:, 0], np.arange(f))
    assert neighbors.min() >= -1 and neighbors.max() < f
    vertex_sets = [set(q) for q in quads.tolist()]
    edge_sets = [{frozenset((q[i], q[(i + 1) % 4])) for i in range(4)} for q in quads.tolist()]
    for face in range(f):
        edges, corners = neighbors[face, 1::2], neighbors[face, 2::2]
        for nb in edges[edges >= 0]:
            assert edge_sets[face] & edge_sets[nb], "an edge neighbour shares an edge with the centre face"
            assert face in neighbors[nb, 1::2], "edge neighbours are symmetric"
        for nb in corners[corners >= 0]:
            assert len(vertex_sets[face] & vertex_sets[nb]) == 1, "a corner neighbour shares exactly one vertex"
            assert face in neighbors[nb, 2::2], "corner neighbours are symmetric"
        ring = neighbors[face, 1:][neighbors[face, 1:] >= 0]
        assert len(set(ring.tolist())) == len(ring) and face not in ring


@pytest.mark.parametrize("name", list(SHAPES))
def test_every_shape_gets_every_level_with_valid_neighbourhoods_pooling_and_features(prepared, name):
    shape = prepared[name]
    assert shape.num_levels == 3
    counts = shape.face_counts
    assert 384 * 0.7 <= counts[0] <= 384 * 1.4, counts
    assert all(2.0 <= counts[l] / counts[l + 1] <= 8.0 for l in range(2)), f"every level really coarser: {counts}"
    assert not any("copy" in level["method"] for level in shape.metadata["levels"])
    for level in range(3):
        v, q = shape.vertices[level], shape.quads[level]
        assert v.dtype == np.float32 and q.dtype == np.int64 and q.shape[1] == 4
        assert q.min() >= 0 and q.max() < len(v)
        assert (np.sort(q, axis=1)[:, 1:] != np.sort(q, axis=1)[:, :-1]).all(), "no quad repeats a vertex"
        check_neighborhoods(q, shape.neighbors[level])
    for level in range(2):
        pool = shape.pool[level]
        assert pool.shape == (counts[level],) and pool.dtype == np.int64
        assert np.array_equal(np.unique(pool), np.arange(counts[level + 1])), "every coarse face receives a fine face"
    # normalised frame: bbox centre at the origin and diagonal 1 (up to the remeshing's deviation)
    v0 = shape.vertices[0]
    assert np.linalg.norm(v0.max(0) - v0.min(0)) == pytest.approx(1.0, abs=0.08)
    assert np.abs((v0.max(0) + v0.min(0)) / 2).max() < 0.05
    assert shape.face_features.shape == (counts[0], len(shape.feature_names))
    assert np.isfinite(shape.face_features).all()
    assert shape.noc.shape == (len(v0), 3) and shape.noc.min() >= 0 and shape.noc.max() <= 1


def test_most_ring_faces_exist_on_a_closed_regular_shape(prepared):
    """QuadriFlow meshes are mostly regular: on a torus nearly every ring slot is filled."""
    ring = prepared["torus"].neighbors[0][:, 1:]
    assert (ring >= 0).mean() > 0.9


def test_features_match_the_sphere_curvature(prepared):
    shape = prepared["sphere"]
    names = shape.feature_names
    radius = np.linalg.norm(shape.vertices[0], axis=1).mean()
    forms = fundamental_forms(shape.vertices[0], shape.quads[0])
    assert np.median(forms["H"]) == pytest.approx(1 / radius, rel=0.1)
    assert np.median(forms["K"]) == pytest.approx(1 / radius**2, rel=0.15)
    size = np.sqrt((forms["E"] + forms["G"]) / 2)
    stored = shape.face_features[:, names.index("mean_curvature")]
    assert np.allclose(stored, np.arcsinh(forms["H"] * size), atol=1e-5), "stored curvature is asinh(H s)"
    centres = shape.vertices[0][shape.quads[0]].mean(axis=1)
    normals = shape.face_features[:, [names.index(n) for n in ("normal_x", "normal_y", "normal_z")]]
    outward = np.einsum("ij,ij->i", normals, centres / np.linalg.norm(centres, axis=1, keepdims=True))
    assert (outward > 0.9).mean() > 0.95, "normals face outwards"


def test_features_are_scale_free_and_bounded(prepared):
    """The network input does not depend on the mesh's size or face count, and sharp creases stay bounded."""
    shape = prepared["chair"]
    features, _ = face_features(shape.vertices[0], shape.quads[0])
    scaled, _ = face_features(shape.vertices[0] * 7.0, shape.quads[0])
    assert np.allclose(features, scaled, atol=1e-4)
    assert np.abs(features).max() < 20


def test_neighbourhood_order_is_rotational_and_starts_deterministically():
    """A 3x3 grid of unit quads in the xy plane: the centre face sees all 8 ring faces in order."""
    xs, ys = np.meshgrid(np.arange(4.0), np.arange(4.0), indexing="xy")
    vertices = np.stack([xs.ravel(), ys.ravel(), np.zeros(16)], axis=1)
    quads = np.array(
        [[r * 4 + c, r * 4 + c + 1, (r + 1) * 4 + c + 1, (r + 1) * 4 + c] for r in range(3) for c in range(3)]
    )
    neighbors = face_neighborhoods(vertices, quads)
    check_neighborhoods(quads, neighbors)
    # centre face 4; the edge with the smallest midpoint (x, then y) is its left edge (x = 1), face 3;
    # then counter-clockwise: corner below-left 0, bottom 1, corner 2, right 5, corner 8, top 7, corner 6
    assert neighbors[4].tolist() == [4, 3, 0, 1, 2, 5, 8, 7, 6]
    # the order does not depend on how the centre quad's vertex list is rotated
    rotated = quads.copy()
    rotated[4] = np.roll(rotated[4], 2)
    assert face_neighborhoods(vertices, rotated)[4].tolist() == neighbors[4].tolist()
    # a corner face on the boundary has 3 of 8
    assert (neighbors[0, 1:] >= 0).sum() == 3


def test_pooling_covers_every_coarse_face_even_when_nearest_centres_miss_some():
    rng = np.random.default_rng(0)
    fine_vertices = rng.normal(size=(200, 3))
    fine_quads = rng.integers(0, 200, size=(40, 4))
    coarse_vertices = np.concatenate([fine_vertices[:40], np.full((4, 3), 50.0)])
    # the last one is far from all
    coarse_quads = np.array([[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11], [40, 41, 42, 43]])
    pool = pooling_map(fine_vertices, fine_quads, coarse_vertices, coarse_quads)
    assert pool.shape == (40,)
    assert set(pool.tolist()) == {0, 1, 2, 3}


def test_triangles_to_quads_is_a_closed_pure_quad_mesh():
    sphere = trimesh.creation.icosphere(1)
    v, q = triangles_to_quads(sphere.vertices, sphere.faces)
    assert q.shape == (3 * len(sphere.faces), 4)
    neighbors = face_neighborhoods(v, q)
    check_neighborhoods(q, neighbors)
    assert (neighbors[:, 1::2] >= 0).all(), "closed: every quad has four edge neighbours"


def test_quadriflow_wrapper_reaches_the_target():
    sphere = trimesh.creation.icosphere(3)
    v, q = quadriflow(sphere.vertices, sphere.faces, 200, seed=0)
    assert q.shape[1] == 4 and 100 <= len(q) <= 300
    assert q.max() < len(v)


def _prints_and_adds_one(x: int) -> int:
    os.write(1, b"wrong init 198 207!\n")  # as QuadriFlow's C code prints, past Python's streams
    os.write(2, b"Fail!!!!!!! 3\n")
    return x + 1


def test_quadriflow_s_own_debugging_lines_do_not_reach_the_user(capfd):
    """`prepare shapes` printed QuadriFlow's "wrong init 198 207!" among its own lines; the forked child
    that runs the library now keeps its prints, and its result still comes back."""
    assert _run_forked(_prints_and_adds_one, (1,), timeout=60) == 2
    out, err = capfd.readouterr()
    assert out == "" and err == ""


def test_normalize_and_clean_repair_duplicates_and_degenerate_faces():
    box = trimesh.creation.box((2.0, 4.0, 4.0))
    v = np.concatenate([box.vertices, box.vertices]) + 10.0  # a shifted copy of every vertex, used by nobody yet
    faces = np.concatenate([box.faces, box.faces + 8, [[0, 0, 1]]])  # a duplicated box and a degenerate face
    normalized, transform = normalize(v)
    assert np.linalg.norm(normalized.max(0) - normalized.min(0)) == pytest.approx(1.0)
    assert np.allclose(transform.invert(normalized), v)
    clean_v, clean_f = clean_mesh(normalized, faces)
    assert len(clean_v) == 8 and len(clean_f) == 12


def test_load_mesh_merges_scene_parts_and_reads_every_format(tmp_path):
    scene = trimesh.Scene([trimesh.creation.box(), trimesh.creation.icosphere(1).apply_translation((3, 0, 0))])
    scene.export(tmp_path / "scene.glb")
    v, f = load_mesh(tmp_path / "scene.glb")
    assert len(f) == 12 + 80 and v.dtype == np.float64 and f.dtype == np.int64
    assert v[:, 0].max() > 3.5, "the second part keeps its placement"
    for suffix in (".obj", ".ply", ".off", ".stl", ".gltf"):
        trimesh.creation.box().export(tmp_path / f"box{suffix}")
        v, f = load_mesh(tmp_path / f"box{suffix}")
        assert len(f) == 12, suffix


@pytest.mark.parametrize(
    "content,expected",
    [
        (b"", "empty file"),
        (b"\x00\x01\x02 not a mesh at all \xff" * 20, "cannot be read"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\n".encode(), "point cloud"),
    ],
)
def test_load_mesh_rejects_bad_files_with_the_reason(tmp_path, content, expected):
    path = tmp_path / ("bad.ply" if b"\x00" in content else "bad.obj")
    path.write_bytes(content)
    with pytest.raises(InputError) as error:
        load_mesh(path)
    assert str(path) in str(error.value) and expected in str(error.value)


def test_prepare_shape_rejects_a_mesh_without_area():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], dtype=float)
    with pytest.raises(InputError):
        prepare_shape(vertices, np.array([[0, 1, 2]]), face_count=96, levels=2)


def test_features_are_finite_on_degenerate_quads():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    features, names = face_features(vertices, np.array([[0, 1, 2, 3]]))
    assert np.isfinite(features).all() and len(names) == features.shape[1]
    assert noc_coordinates(np.array([[-0.5, 0.0, 0.5]])).tolist() == [[0.0, 0.5, 1.0]]


def test_features_do_not_depend_on_how_each_quad_is_listed(prepared):
    """The remesher's choice of first corner and direction is arbitrary: listing every quad from
    another corner, a random half of them in reverse, or the whole mesh in reverse changes no feature."""
    for name in ("chair", "sphere", "hole"):
        shape = prepared[name]
        v, q = shape.vertices[0], shape.quads[0]
        base, names = face_features(v, q)
        rng = np.random.default_rng(0)
        shifts = rng.integers(0, 4, len(q))
        reverse = rng.random(len(q)) < 0.5
        relisted = np.stack([np.roll(row[::-1] if r else row, -k) for row, k, r in zip(q, shifts, reverse)])
        assert np.allclose(face_features(v, relisted)[0], base, atol=1e-4), name
        assert np.allclose(face_features(v, q[:, ::-1])[0], base, atol=1e-4), name
        # the features still carry the orientation: normals face outwards on the sphere
        if name == "sphere":
            centres = v[q].mean(axis=1)
            normals = base[:, [names.index(n) for n in ("normal_x", "normal_y", "normal_z")]]
            assert (np.einsum("ij,ij->i", normals, centres) > 0).mean() > 0.95


def test_orient_coherently_restores_the_outward_orientation_of_every_part():
    """Two closed parts, a random half of each part's quads reversed: every quad comes back outwards."""
    parts = [trimesh.creation.icosphere(2), trimesh.creation.box().apply_translation((3, 0, 0))]
    v, q = triangles_to_quads(
        *[
            np.concatenate(x)
            for x in zip(
                *[(p.vertices, p.faces + sum(len(o.vertices) for o in parts[:i])) for i, p in enumerate(parts)]
            )
        ]
    )
    rng = np.random.default_rng(1)
    mixed = np.stack([row[::-1] if rng.random() < 0.5 else row for row in q])
    oriented = orient_coherently(v, mixed)
    assert np.array_equal(oriented, q)
    assert np.array_equal(orient_coherently(v, q[:, ::-1]), q)


def _pymeshlab_call(filter_name: str, **settings) -> None:
    """One pymeshlab filter run on a throwaway sphere, as other code in the same process might run it."""
    sphere = trimesh.creation.icosphere(2)
    getattr(mesh_set(sphere.vertices, sphere.faces), filter_name)(**settings)


def test_remeshing_and_decimation_do_not_depend_on_earlier_pymeshlab_calls():
    """MeshLab's filters take every unpassed setting from the previous call in the process; ours must
    give the same triangles whatever ran before (the same shape, prepared in any worker, any order)."""
    import pymeshlab

    chair = box_chair()
    chair = trimesh.Trimesh(chair.vertices, chair.faces).subdivide().subdivide()
    chair.vertices += np.random.default_rng(0).normal(scale=0.004, size=chair.vertices.shape)
    results = []
    for surface_check, adaptive in ((False, True), (True, False)):
        _pymeshlab_call(
            "meshing_isotropic_explicit_remeshing",
            targetlen=pymeshlab.PercentageValue(8.0),
            iterations=1,
            checksurfdist=surface_check,
            maxsurfdist=pymeshlab.PercentageValue(0.05),
            adaptive=adaptive,
            featuredeg=5.0,
            smoothflag=adaptive,
        )
        _pymeshlab_call(
            "meshing_decimation_quadric_edge_collapse",
            targetfacenum=100,
            preservetopology=adaptive,
            planarquadric=adaptive,
            qualitythr=0.9 if adaptive else 0.1,
            preservenormal=adaptive,
        )
        remeshed = isotropic_remesh(chair.vertices, chair.faces, 0.03)
        results.append((remeshed, decimate(chair.vertices, chair.faces, 600)))
    (iso_a, dec_a), (iso_b, dec_b) = results
    assert len(iso_a[1]) != len(chair.faces) and len(dec_a[1]) <= 620, "both filters ran"
    for a, b in ((iso_a, iso_b), (dec_a, dec_b)):
        assert a[0].shape == b[0].shape and np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_a_setting_pymeshlab_does_not_know_is_an_error_not_a_skipped_filter():
    from mesh2tex.geometry.clean import _apply_filter

    sphere = trimesh.creation.icosphere(1)
    with pytest.raises(RuntimeError, match="no_such_setting"):
        _apply_filter(
            mesh_set(sphere.vertices, sphere.faces), "meshing_isotropic_explicit_remeshing", no_such_setting=True
        )
