"""The rasterizer agrees with first-hit ray casting (trimesh + Embree) through the same pixel centres."""

import numpy as np
import pytest
import torch

from mesh2tex.render import orbit_camera, pixel_centres, rasterize, transform_points

trimesh = pytest.importorskip("trimesh")
pytest.importorskip("embreex")
from trimesh.ray.ray_pyembree import RayMeshIntersector  # noqa: E402


def bumpy_torus(major_sections: int = 192, minor_sections: int = 128) -> "trimesh.Trimesh":
    """A torus with a wavy tube (2 * major * minor triangles, 49,152 by default), so both silhouettes
    and self-occlusion occur. Also used by benchmarks/bench_rasterize.py."""
    mesh = trimesh.creation.torus(1.0, 0.35, major_sections=major_sections, minor_sections=minor_sections)
    v = mesh.vertices
    angle = np.arctan2(v[:, 2], v[:, 0])
    radial = np.c_[np.cos(angle), np.zeros_like(angle), np.sin(angle)]
    tube = v - radial
    bump = 1.0 + 0.15 * np.sin(5 * angle)[:, None]
    vertices = (radial + tube * bump).astype(np.float32).astype(np.float64)  # what the rasterizer sees
    return trimesh.Trimesh(vertices, mesh.faces, process=False)


def pixel_rays(camera, resolution):
    """Origins (on the near plane) and unit directions (float64) of the rays through the pixel
    centres of one camera, from the inverse of its mvp matrix."""
    centres = pixel_centres(resolution, dtype=torch.float64).reshape(-1, 2).numpy()
    inverse = np.linalg.inv(camera.mvp[0].double().numpy())
    ones = np.ones(len(centres))
    near = np.c_[centres, -ones, ones] @ inverse.T
    far = np.c_[centres, ones, ones] @ inverse.T
    near, far = near[:, :3] / near[:, 3:], far[:, :3] / far[:, 3:]
    direction = far - near
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    # Rays start on the near plane: the eye implied by the float32 mvp is not exactly camera.position.
    return near, direction


def ray_triangle_barycentrics(origin, direction, triangles):
    """Barycentrics (N,3) float64 of where each ray meets the plane of its triangle (N,3,3)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    edge1, edge2 = b - a, c - a
    p = np.cross(direction, edge2)
    det = (edge1 * p).sum(1)
    s = origin - a
    u = (s * p).sum(1) / det
    q = np.cross(s, edge1)
    v = (direction * q).sum(1) / det
    return np.c_[1 - u - v, u, v]


def ray_cast(mesh, camera, resolution):
    """Face ids (H,W) int64 (-1 for misses) of Embree's first hits and their barycentrics (H,W,3).

    Embree reports hits in float32; the barycentrics are recomputed in float64 from the same rays and
    faces, so they are a reference for ours rather than an approximation of it.
    """
    H, W = resolution
    origin, direction = pixel_rays(camera, resolution)
    faces, rays = RayMeshIntersector(mesh).intersects_id(origin, direction, multiple_hits=False)
    face_id = np.full(H * W, -1, dtype=np.int64)
    bary = np.zeros((H * W, 3))
    face_id[rays] = faces
    bary[rays] = ray_triangle_barycentrics(origin[rays], direction[rays], mesh.triangles[faces])
    return face_id.reshape(H, W), bary.reshape(H, W, 3)


@pytest.mark.parametrize(
    "azimuth,elevation,distance,dtype",
    [(30.0, 35.0, 2.6, torch.float64), (200.0, -20.0, 3.2, torch.float64), (30.0, 35.0, 2.6, torch.float32)],
)
def test_rasterize_agrees_with_embree(azimuth, elevation, distance, dtype):
    mesh = bumpy_torus()
    assert len(mesh.faces) >= 40_000
    resolution = (160, 192)
    camera = orbit_camera(azimuth, elevation, distance=distance, fov=45.0, aspect=resolution[1] / resolution[0])
    pos = transform_points(torch.tensor(mesh.vertices, dtype=dtype), camera.mvp)
    raster = rasterize(pos, torch.tensor(mesh.faces), resolution)
    ours_id = raster.face_id[0].numpy()
    ours_bary = raster.bary[0].numpy()
    ref_id, ref_bary = ray_cast(mesh, camera, resolution)

    either = (ours_id >= 0) | (ref_id >= 0)
    same = (ours_id == ref_id) & (ref_id >= 0)
    assert either.sum() > 0.2 * either.size  # the mesh fills a good part of the frame
    assert same.sum() >= 0.995 * either.sum()
    error = np.abs(ours_bary[same] - ref_bary[same]).max(1)
    print(
        f"{same.sum() / either.sum():.5f} agree, bary error max {error.max():.2e} 99.9% {np.quantile(error, 0.999):.2e}"
    )
    if dtype == torch.float64:
        assert error.max() < 1e-4
    else:  # float32 clip coordinates limit nearly edge-on triangles, not the rasterizer
        assert np.quantile(error, 0.999) < 1e-4 and error.max() < 1e-2


@pytest.mark.parametrize("name", ["box", "grid_box", "cube_sphere_7"])
def test_edge_aligned_views_agree_with_embree(name):
    """Axis-aligned views of closed meshes, at odd and even resolutions, put pixel centres exactly on
    shared edges and vertices: the covered pixels are exactly Embree's, and where the face ids differ
    (a centre on an edge, which either triangle may claim) the two triangles share a vertex and the
    surface points agree."""
    from test_render import closed_meshes

    from mesh2tex.render import interpolate

    vertices, faces = closed_meshes()[name]
    mesh = trimesh.Trimesh(vertices.double().numpy(), faces.numpy(), process=False)
    differ = 0
    for azimuth, elevation in ((0.0, 0.0), (90.0, 0.0), (45.0, 0.0), (0.0, 90.0)):
        for resolution in ((25, 25), (64, 64), (33, 48)):
            camera = orbit_camera(azimuth, elevation, distance=2.0, fov=45.0, aspect=resolution[1] / resolution[0])
            raster = rasterize(transform_points(vertices, camera.mvp), faces, resolution)
            ours = raster.face_id[0].numpy()
            ref_id, ref_bary = ray_cast(mesh, camera, resolution)
            assert np.array_equal(ours >= 0, ref_id >= 0), (azimuth, elevation, resolution)
            covered = ours >= 0
            world = interpolate(vertices.double(), raster, faces)[0].numpy()[covered]
            ref_world = (ref_bary[..., None] * mesh.triangles[np.maximum(ref_id, 0)]).sum(-2)[covered]
            assert np.abs(world - ref_world).max() < 1e-5
            other = ours != ref_id
            shared = [len(set(a) & set(b)) for a, b in zip(mesh.faces[ours[other]], mesh.faces[ref_id[other]])]
            assert min(shared, default=1) >= 1
            differ += int(other.sum())
    assert differ > 0  # centres on shared edges occurred
