"""The fast rasterizer (size bins, stencils, row spans of large triangles) equals the slow reference bit for bit
on meshes whose triangles differ wildly in size. Also builds the benchmark's meshes of that kind."""

import manifold3d as mf
import numpy as np
import pytest
import torch
import trimesh

from mesh2tex.render import orbit_camera, rasterize, transform_points
from mesh2tex.render.rasterize_reference import rasterize_reference


def bevelled_table(segments: int = 300) -> trimesh.Trimesh:
    """A box with finely rounded edges on four round legs, bbox centred with diagonal 1: a few huge
    flat triangles (the faces, the legs' long sides) beside many tiny ones (the bevels); 48,348
    triangles with the default ``segments``, like a CAD model exported as triangles."""
    r, h = 0.02, 0.48
    ball = mf.Manifold.sphere(r, segments)
    top = mf.Manifold.batch_hull([ball.translate((x, y, z)) for x in (-h, h) for y in (-0.28, 0.28) for z in (-h, h)])
    legs = [mf.Manifold.cylinder(0.9, 0.03, 0.03, 96).translate((x, y, -1.2)) for x in (-0.4, 0.4) for y in (-0.2, 0.2)]
    mesh = mf.Manifold.batch_boolean([top, *legs], mf.OpType.Add).to_mesh()
    return normalised(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts))


def scan_sphere(frequency: int = 72, seed: int = 0) -> trimesh.Trimesh:
    """A noisy, irregular closed blob like a 3D scan: an icosahedron whose faces are cut into
    ``frequency``^2 triangles (20 * frequency^2: 103,680 for 72), vertices jittered along the surface
    and displaced by smooth bumps and fine noise; bbox centred with diagonal 1."""
    rng = np.random.default_rng(seed)
    ico = trimesh.creation.icosahedron()
    n = frequency
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    i, j = i[keep], j[keep]
    local = {(a, b): k for k, (a, b) in enumerate(zip(i.tolist(), j.tolist()))}
    grid = []  # triangles of one face over the (i, j) lattice
    for a in range(n):
        for b in range(n - a):
            grid.append((local[a, b], local[a + 1, b], local[a, b + 1]))
            if a + b < n - 1:
                grid.append((local[a + 1, b], local[a + 1, b + 1], local[a, b + 1]))
    grid = np.array(grid)
    weights = np.stack([n - i - j, i, j], axis=1) / n
    points = np.concatenate([weights @ ico.vertices[f] for f in ico.faces])
    faces = np.concatenate([grid + k * len(weights) for k in range(len(ico.faces))])
    mesh = trimesh.Trimesh(points, faces)  # merges the vertices shared by neighbouring faces
    v = mesh.vertices / np.linalg.norm(mesh.vertices, axis=1, keepdims=True)
    v += rng.normal(scale=0.3 / n, size=v.shape)  # irregular triangles
    directions = rng.normal(size=(12, 3))
    bumps = np.sin(v @ directions.T * 3 + rng.uniform(0, 6, 12)).sum(1) * 0.04
    radius = 1 + bumps + rng.normal(scale=0.004, size=len(v))
    return normalised(v / np.linalg.norm(v, axis=1, keepdims=True) * radius[:, None], mesh.faces)


def normalised(vertices, faces) -> trimesh.Trimesh:
    """The mesh centred with bbox diagonal 1, in float32-representable coordinates (what the
    rasterizer sees)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    low, high = vertices.min(0), vertices.max(0)
    vertices = (vertices - (low + high) / 2) / np.linalg.norm(high - low)
    return trimesh.Trimesh(vertices.astype(np.float32).astype(np.float64), np.asarray(faces), process=False)


def overlapping_giants() -> tuple[torch.Tensor, torch.Tensor]:
    """Triangles far larger than the image, crossing one another and the near plane, over a fan of
    slivers and sub-pixel triangles: every path of the fast rasterizer at once."""
    rng = np.random.default_rng(3)
    giants = rng.uniform(-3, 3, size=(6, 3, 3))
    centres = rng.uniform(-0.5, 0.5, size=(400, 1, 3))
    tiny = centres + rng.normal(scale=0.004, size=(400, 3, 3))
    slivers = centres[:60] + rng.normal(size=(60, 1, 3)) * np.array([1, 0.01, 1]) * rng.uniform(0, 1, (60, 3, 1))
    corners = np.concatenate([giants, tiny, slivers]).reshape(-1, 3)
    return torch.tensor(corners, dtype=torch.float32), torch.arange(len(corners)).reshape(-1, 3)


@pytest.fixture(scope="module")
def meshes():
    table = bevelled_table(48)
    return {
        "table": (torch.tensor(table.vertices, dtype=torch.float32), torch.tensor(table.faces)),
        "giants": overlapping_giants(),
    }


def assert_bitwise(a, b):
    assert torch.equal(a.face_id, b.face_id)
    assert torch.equal(a.bary, b.bary)
    assert torch.equal(a.depth, b.depth)


@pytest.mark.parametrize("name", ["table", "giants"])
@pytest.mark.parametrize("dtype,cull,max_pairs", [(torch.float32, False, 1 << 21), (torch.float64, True, 2000)])
def test_fast_rasterizer_equals_reference(meshes, name, dtype, cull, max_pairs, raster_path):
    vertices, faces = meshes[name]
    # Close cameras put the giants and the table's faces across the near plane and the whole image.
    camera = orbit_camera(
        torch.tensor([20.0, 140.0, 260.0]),
        torch.tensor([30.0, -15.0, 70.0]),
        distance=torch.tensor([1.4, 0.35, 2.5]),
        fov=60.0,
    )
    pos = transform_points(vertices.to(dtype), camera.mvp.to(dtype))
    fast = rasterize(pos, faces, (120, 97), cull_backfaces=cull, max_pairs=max_pairs)
    assert fast.mask.float().mean() > 0.2 and len(fast.face_id.unique()) > 30
    assert_bitwise(fast, rasterize_reference(pos, faces, (120, 97), cull_backfaces=cull))


def test_scan_sphere_and_table_are_what_the_benchmark_says():
    sphere = scan_sphere(8)
    assert len(sphere.faces) == 20 * 64 and sphere.is_watertight
    table = bevelled_table(32)
    areas = table.area_faces
    assert areas.max() > 1000 * np.median(areas)


@pytest.mark.parametrize("name", ["cube_sphere_7", "box", "grid_box"])
def test_fast_rasterizer_equals_reference_with_centres_on_edges(name, monkeypatch, raster_path):
    """Axis-aligned views of closed meshes put pixel centres exactly on edges and vertices, where the
    fast path's float32 planes cannot decide and the exact test (and its tie rule) does; near views
    make the faces large enough for the coarse pass by rows."""
    from test_render import closed_meshes

    import mesh2tex.render.edges as edges

    exact = []
    signs = edges.exact_edge_signs
    monkeypatch.setattr(edges, "exact_edge_signs", lambda c, *a: exact.append(c.shape[1]) or signs(c, *a))
    vertices, faces = closed_meshes()[name]
    camera = orbit_camera(
        torch.tensor([0.0, 90.0, 45.0, 180.0]),
        torch.tensor([0.0, 0.0, 90.0, -45.0]),
        distance=torch.tensor([2.0, 1.1, 2.5, 3.0]),
        fov=45.0,
    )
    pos = transform_points(vertices, camera.mvp)
    for resolution, max_pairs in (((25, 25), 1 << 21), ((64, 48), 3000)):
        fast = rasterize(pos, faces, resolution, max_pairs=max_pairs)
        assert_bitwise(fast, rasterize_reference(pos, faces, resolution))
    assert sum(exact) > 10  # the exact test decided pixels on edges
