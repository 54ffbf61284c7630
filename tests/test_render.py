"""Analytic checks of mesh2tex.render: conventions, visibility, clipping, interpolation, shading, UV."""

import math

import numpy as np
import pytest
import torch
import trimesh

from mesh2tex.render import (
    composite,
    dilate_texture,
    face_attribute,
    interpolate,
    orbit_camera,
    pixel_centres,
    rasterize,
    render_mask,
    render_noc,
    render_normals,
    sample_texture,
    shade_lambert,
    transform_points,
    unwrap_uv,
    uv_rasterize,
    vertex_normals,
)

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def inside_triangle(points, a, b, c):
    """(N,2) points -> (N,) bool, inclusive point-in-triangle test in float64."""

    def edge(p, q, r):
        return (q[0] - p[0]) * (r[:, 1] - p[1]) - (q[1] - p[1]) * (r[:, 0] - p[0])

    e0, e1, e2 = edge(a, b, points), edge(b, c, points), edge(c, a, points)
    return ((e0 >= 0) & (e1 >= 0) & (e2 >= 0)) | ((e0 <= 0) & (e1 <= 0) & (e2 <= 0))


def cube():
    """Unit cube [-0.5,0.5]^3: 8 vertices, 12 outward-facing counter-clockwise triangles."""
    v = torch.tensor([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tri = torch.tensor([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    return v, tri


@pytest.mark.parametrize("device", DEVICES)
def test_single_triangle_coverage_bary_and_depth(device):
    corners = np.array([[-0.7, -0.6], [0.8, -0.2], [-0.1, 0.9]])
    pos = torch.tensor([[x, y, 0.25, 1.0] for x, y in corners], device=device)
    raster = rasterize(pos, torch.tensor([[0, 1, 2]]), (37, 53))
    centres = pixel_centres((37, 53), dtype=torch.float64).reshape(-1, 2).numpy()
    expected = inside_triangle(centres, *corners).reshape(37, 53)
    covered = (raster.face_id[0] == 0).cpu().numpy()
    assert (covered == expected).mean() > 0.999 and covered.sum() > 300
    assert set(raster.face_id.unique().tolist()) == {-1, 0}
    # Barycentrics reproduce the pixel centre; depth is the constant NDC z.
    bary = raster.bary[0].cpu().double().numpy()[covered]
    assert np.abs(bary @ corners - centres.reshape(37, 53, 2)[covered]).max() < 1e-6
    assert np.abs(bary.sum(1) - 1).max() < 1e-6 and bary.min() >= 0
    assert torch.allclose(raster.depth[0][raster.face_id[0] == 0].cpu(), torch.tensor(0.25))
    assert (raster.bary[0][~raster.mask[0]] == 0).all() and (raster.depth[0][~raster.mask[0]] == 1).all()


def test_pixel_centre_convention():
    """A tiny triangle around pixel (row 2, col 5)'s centre covers exactly that pixel; row 0 is the top."""
    H, W = 6, 8
    x, y = (2 * 5 + 1) / W - 1, 1 - (2 * 2 + 1) / H
    d = 0.05
    pos = torch.tensor([[x - d, y - d, 0, 1], [x + d, y - d, 0, 1], [x, y + d, 0, 1.0]])
    raster = rasterize(pos, torch.tensor([[0, 1, 2]]), (H, W))
    assert torch.nonzero(raster.face_id[0] >= 0).tolist() == [[2, 5]]
    assert torch.allclose(pixel_centres((H, W))[2, 5], torch.tensor([x, y]))


def test_nearest_of_two_overlapping_triangles_wins_in_any_order():
    near_tri = [[-0.8, -0.8, -0.2, 1], [0.8, -0.8, -0.2, 1], [0.0, 0.8, -0.2, 1]]
    far_tri = [[-0.9, 0.9, 0.5, 1], [-0.9, -0.9, 0.5, 1], [0.9, 0.0, 0.5, 1]]
    pos = torch.tensor(near_tri + far_tri)
    for tri, near_id in ((torch.tensor([[0, 1, 2], [3, 4, 5]]), 0), (torch.tensor([[3, 4, 5], [0, 1, 2]]), 1)):
        raster = rasterize(pos, tri, (64, 64))
        centres = pixel_centres((64, 64), dtype=torch.float64).reshape(-1, 2).numpy()
        in_near = inside_triangle(centres, *np.array(near_tri)[:, :2]).reshape(64, 64)
        in_far = inside_triangle(centres, *np.array(far_tri)[:, :2]).reshape(64, 64)
        face = raster.face_id[0].numpy()
        both = in_near & in_far
        assert both.sum() > 100
        assert (face[both] == near_id).mean() > 0.99
        only_far = in_far & ~in_near
        assert (face[only_far] == 1 - near_id).mean() > 0.99
        assert np.allclose(raster.depth[0].numpy()[face == near_id], -0.2, atol=1e-6)


@pytest.mark.parametrize("device", DEVICES)
def test_cube_faces_seen_from_orbit_cameras(device):
    v, tri = cube()
    camera = orbit_camera(torch.tensor([0.0, 90.0, 45.0]), torch.tensor([0.0, 0.0, 35.0]), distance=3.0, fov=40.0)
    pos = transform_points(v.to(device), camera.mvp.to(device))
    raster = rasterize(pos, tri.to(device), (96, 96))
    normals = torch.tensor([[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1.0]])
    face_normal = normals.repeat_interleave(2, 0)
    # Front view (azimuth 0): only the +z face; azimuth 90: only +x; the corner view: +x, +y, +z.
    for view, visible in ((0, {(0, 0, 1)}), (1, {(1, 0, 0)}), (2, {(1, 0, 0), (0, 1, 0), (0, 0, 1)})):
        ids = raster.face_id[view][raster.face_id[view] >= 0].unique().cpu()
        seen = {tuple(int(c) for c in face_normal[i]) for i in ids.tolist()}
        assert seen == visible
    # The front face of the cube projects to a centred square of half-size 0.5 / (2.5 tan 20deg).
    half = 0.5 / (2.5 * math.tan(math.radians(20.0)))
    centres = pixel_centres((96, 96))
    expected = (centres.abs() < half).all(-1)
    assert ((raster.face_id[0].cpu() >= 0) == expected).float().mean() > 0.995
    # Culling back faces changes nothing for a closed, outward-facing mesh.
    culled = rasterize(pos, tri.to(device), (96, 96), cull_backfaces=True)
    assert torch.equal(culled.face_id, raster.face_id)


def test_backface_culling_drops_clockwise_triangles():
    pos = torch.tensor([[-0.5, -0.5, 0, 1], [0.5, -0.5, 0, 1], [0, 0.5, 0, 1.0]])
    assert rasterize(pos, torch.tensor([[0, 2, 1]]), (16, 16), cull_backfaces=True).face_id.max() == -1
    assert rasterize(pos, torch.tensor([[0, 2, 1]]), (16, 16)).face_id.max() == 0
    assert rasterize(pos, torch.tensor([[0, 1, 2]]), (16, 16), cull_backfaces=True).face_id.max() == 0


def test_triangles_crossing_the_near_plane_or_behind_the_camera():
    """A ground triangle reaching behind the camera is drawn exactly where pixel rays hit it in front
    of the near plane; one entirely behind the camera draws nothing."""
    H, W = 48, 64
    camera = orbit_camera(0.0, 10.0, distance=2.0, fov=60.0, near=0.5, far=50.0, aspect=W / H)
    ground = torch.tensor(
        [
            [-3.0, -0.3, 2.0 + 4.0],
            [3.0, -0.3, 2.0 + 4.0],
            [0.0, -0.3, -6.0],
            [-1, 0.2, 9.0],
            [1, 0.2, 9.0],
            [0, 1.0, 9.0],
        ],
        dtype=torch.float64,
    )
    tri = torch.tensor([[0, 1, 2], [3, 4, 5]])
    pos = transform_points(ground, camera.mvp)
    assert (pos[0, :, 3] < 0).any() and (pos[0, :, 3] > 0).any()  # vertices on both sides of the eye
    raster = rasterize(pos, tri, (H, W))
    assert not (raster.face_id == 1).any()  # the second triangle is behind the camera
    # Reference: rays from the near plane through every pixel centre, intersected with the plane y = -0.3.
    centres = pixel_centres((H, W), dtype=torch.float64).reshape(-1, 2)
    inverse = torch.linalg.inv(camera.mvp[0].double())
    ones = torch.ones(len(centres), 1, dtype=torch.float64)
    near = torch.cat([centres, -ones, ones], 1) @ inverse.T
    far = torch.cat([centres, ones, ones], 1) @ inverse.T
    near, far = near[:, :3] / near[:, 3:], far[:, :3] / far[:, 3:]
    t = (-0.3 - near[:, 1]) / (far[:, 1] - near[:, 1])
    hit = near + t[:, None] * (far - near)
    a, b, c = ground[0, [0, 2]].numpy(), ground[1, [0, 2]].numpy(), ground[2, [0, 2]].numpy()
    expected = ((t >= 0) & (t <= 1)).numpy() & inside_triangle(hit[:, [0, 2]].numpy(), a, b, c)
    covered = (raster.face_id[0] == 0).reshape(-1).numpy()
    assert expected.sum() > 0.3 * H * W
    assert (covered == expected).mean() > 0.998
    # Interpolated world positions of covered pixels are the ray hits (perspective-correct, no garbage).
    world = interpolate(ground, raster, tri)[0].reshape(-1, 3)
    both = covered & expected
    assert torch.allclose(world[both], hit[both], atol=1e-6)
    assert torch.isfinite(raster.bary).all() and torch.isfinite(raster.depth).all()
    assert (raster.depth[raster.mask] >= -1).all() and (raster.depth[raster.mask] <= 1).all()


def test_perspective_correct_interpolation_reprojects_to_pixel_centres():
    v, tri = cube()
    camera = orbit_camera(30.0, 25.0, distance=1.8, fov=60.0)
    pos = transform_points(v.double(), camera.mvp)
    raster = rasterize(pos, tri, (40, 40))
    world = interpolate(v.double(), raster, tri)
    clip = transform_points(world[0].reshape(-1, 3), camera.mvp)[0]
    ndc = (clip[:, :2] / clip[:, 3:]).reshape(40, 40, 2)
    m = raster.mask[0]
    assert m.sum() > 400
    assert torch.allclose(ndc[m], pixel_centres((40, 40), dtype=torch.float64)[m], atol=1e-9)
    assert torch.allclose(raster.depth[0][m].double(), (clip[:, 2] / clip[:, 3]).reshape(40, 40)[m], atol=1e-6)


def test_batch_views_chunks_and_tiles_agree(raster_path):
    """A batch equals its views rasterized one by one; tiny chunks and large triangles change nothing."""
    v, tri = cube()
    camera = orbit_camera(
        torch.tensor([10.0, 100.0, 250.0]),
        torch.tensor([20.0, -30.0, 60.0]),
        distance=torch.tensor([1.2, 3.0, 2.0]),
        fov=50.0,
    )
    pos = transform_points(v, camera.mvp)
    whole = rasterize(pos, tri, (150, 170))
    small_chunks = rasterize(pos, tri, (150, 170), max_pairs=500)
    for i in range(3):
        single = rasterize(pos[i], tri, (150, 170))
        assert torch.equal(single.face_id[0], whole.face_id[i])
        assert torch.equal(single.bary[0], whole.bary[i])
    assert torch.equal(small_chunks.face_id, whole.face_id)
    assert torch.equal(small_chunks.bary, whole.bary)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_renders_what_the_cpu_renders():
    """On a GPU the same views give the same face ids (bar a few pixels where float rounding of the
    depth key differs), the same barycentrics, and the same gradients through interpolate."""
    from test_render_raycast import bumpy_torus

    mesh = bumpy_torus(96, 64)
    camera = orbit_camera(
        torch.tensor([30.0 + 45.0 * i for i in range(8)]), torch.tensor([20.0] * 8), distance=3.6, fov=45.0
    )
    results = {}
    for device in ("cpu", "cuda"):
        vertices = torch.tensor(mesh.vertices, dtype=torch.float32, device=device)
        faces = torch.tensor(mesh.faces, device=device)
        colours = (
            torch.rand(len(mesh.vertices), 3, generator=torch.Generator().manual_seed(0))
            .to(device)
            .requires_grad_(True)
        )
        raster = rasterize(transform_points(vertices, camera.mvp.to(device)), faces, (256, 256))
        interpolate(colours, raster, faces).mean().backward()
        results[device] = (raster.face_id.cpu(), raster.bary.cpu(), colours.grad.cpu())
    (cpu_ids, cpu_bary, cpu_grad), (gpu_ids, gpu_bary, gpu_grad) = results["cpu"], results["cuda"]
    same = cpu_ids == gpu_ids
    assert same.float().mean() > 0.9999
    assert (cpu_bary - gpu_bary)[same].abs().max() < 1e-4
    assert torch.allclose(cpu_grad, gpu_grad, atol=1e-6, rtol=1e-3)


def test_a_closed_mesh_has_no_cracks_where_pixel_centres_fall_on_shared_edges():
    """Watertightness: on a closed convex mesh every covered pixel shows the near side, and a batch equals
    its views one by one, even where symmetric views put pixel centres exactly on edges."""
    from mesh2tex.geometry.primitives import cube_sphere

    vertices, quads = cube_sphere(4)
    positions = torch.as_tensor(np.asarray(vertices), dtype=torch.float32)
    quads = torch.as_tensor(np.asarray(quads), dtype=torch.long)
    triangles = torch.cat([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    azimuth = torch.tensor([90.0, 270.0])
    camera = orbit_camera(azimuth, 0.0, distance=3.2)
    whole = rasterize(transform_points(positions, camera.mvp), triangles, (24, 24))
    centres = positions[triangles].mean(1)
    for k in range(2):
        single = rasterize(transform_points(positions, camera.mvp[k : k + 1]), triangles, (24, 24))
        seen = whole.face_id[k][whole.face_id[k] >= 0]
        towards_camera = centres[seen] @ camera.position[k]
        assert bool((towards_camera > 0).all()), (
            f"view {k}: {int((towards_camera <= 0).sum())} pixels show the far side"
        )
        assert torch.equal(single.face_id[0], whole.face_id[k])


def closed_meshes():
    """Closed, outward-facing meshes with many edges through pixel centres in axis-aligned views:
    cube-spheres (quads split on one diagonal), a box of 12 triangles, and one whose faces are grids
    of coplanar triangles."""
    from mesh2tex.geometry.primitives import cube_sphere

    meshes = {}
    for n in (4, 7):
        vertices, quads = cube_sphere(n)
        quads = torch.as_tensor(np.asarray(quads), dtype=torch.long)
        meshes[f"cube_sphere_{n}"] = (
            torch.as_tensor(np.asarray(vertices), dtype=torch.float32),
            torch.cat([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]),
        )
    box = trimesh.creation.box((1.0, 0.8, 0.6))
    meshes["box"] = (torch.tensor(box.vertices, dtype=torch.float32), torch.tensor(box.faces))
    box = box.subdivide().subdivide()
    meshes["grid_box"] = (torch.tensor(box.vertices, dtype=torch.float32), torch.tensor(box.faces))
    return meshes


@pytest.mark.parametrize("name", ["cube_sphere_4", "cube_sphere_7", "box", "grid_box"])
def test_closed_meshes_show_only_front_faces_from_symmetric_and_random_cameras(name):
    """Watertightness as a property: from outside a closed mesh every pixel ray first enters it through
    a front face, so no covered pixel may show a back face; the front faces alone and the back faces
    alone cover the same pixels (each set tiles the silhouette, and on the silhouette both follow the
    same tie rule); and a batch equals its views one by one. Axis-aligned cameras put many pixel
    centres exactly on edges and vertices, at odd resolutions on the image centre too."""
    vertices, tri = closed_meshes()[name]
    rng = np.random.default_rng(7)
    views = [(a, e) for a in (0.0, 45.0, 90.0, 180.0, 270.0) for e in (0.0, 45.0, 90.0, -90.0)]
    views += [tuple(rng.uniform([0, -80], [360, 80])) for _ in range(6)]
    azimuth, elevation = (torch.tensor(t) for t in zip(*views))
    corners = vertices[tri]
    normal = torch.linalg.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    for resolution, distance in (((24, 24), 3.2), ((25, 25), 2.0), ((31, 40), 2.6)):
        camera = orbit_camera(azimuth, elevation, distance=distance, fov=45.0, aspect=resolution[1] / resolution[0])
        pos = transform_points(vertices, camera.mvp)
        raster = rasterize(pos, tri, resolution)
        for k in range(len(views)):
            seen = raster.face_id[k][raster.mask[k]]
            facing = ((camera.position[k] - corners[seen, 0]) * normal[seen]).sum(1)
            back_faces = int((facing <= 0).sum())
            assert back_faces == 0, f"view {views[k]}, {resolution}: {back_faces} pixels show back faces"
        front = rasterize(pos, tri, resolution, cull_backfaces=True)
        back = rasterize(pos, tri[:, [0, 2, 1]], resolution, cull_backfaces=True)
        assert torch.equal(front.face_id, raster.face_id)
        assert torch.equal(front.mask, back.mask)
        for k in (0, 1, 5, 10):
            assert torch.equal(rasterize(pos[k], tri, resolution).face_id[0], raster.face_id[k])


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("clockwise", [False, True])
def test_pixel_centres_on_edges_and_vertices_are_drawn_once_by_the_top_left_rule(dtype, clockwise):
    """A square split into a fan of 8 triangles around a pixel centre, every edge through pixel
    centres (exactly: clip x, y are even integers and w = 9 at 9x9 pixels). Each centre inside the
    square, on a shared edge or on the shared vertex, is covered by exactly one triangle; on the
    outline, centres on the left and top sides are drawn, those on the right and bottom are not (the
    top-left rule: a centre belongs to the triangle that holds it shifted right, then down, by an
    infinitesimal)."""
    ring = [(6, 0), (6, 6), (0, 6), (-6, 6), (-6, 0), (-6, -6), (0, -6), (6, -6)]
    pos = torch.tensor([[0, 0, 0, 9]] + [[x, y, 0, 9] for x, y in ring], dtype=dtype)
    tri = torch.tensor([[0, 1 + i, 1 + (i + 1) % 8] for i in range(8)])
    if clockwise:
        tri = tri[:, [0, 2, 1]]
    H = W = 9
    # Pixel (row i, column j) has its centre at clip x = 2j - 8, y = 8 - 2i (times 1 / w).
    cols, rows = torch.meshgrid(torch.arange(W), torch.arange(H), indexing="xy")
    x, y = 2 * cols - 8, 8 - 2 * rows
    expected = (x >= -6) & (x < 6) & (y > -6) & (y <= 6)
    count = sum(rasterize(pos, tri[t : t + 1], (H, W)).mask[0].long() for t in range(8))
    assert torch.equal(count, expected.long())
    assert torch.equal(rasterize(pos, tri, (H, W)).mask[0], expected)


def test_orbit_camera_convention():
    camera = orbit_camera(torch.tensor([0.0, 90.0, 30.0]), torch.tensor([0.0, 0.0, 90.0]), distance=2.0)
    expected = torch.tensor([[0.0, 0.0, 2.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    assert torch.allclose(camera.position, expected, atol=1e-6)
    assert torch.allclose(camera.mvp, camera.proj @ camera.view)
    assert torch.isfinite(camera.mvp).all()
    # The origin projects to the image centre; the camera looks down its -z axis; +x is right at az 0.
    clip = transform_points(torch.tensor([[0.0, 0, 0], [0.3, 0, 0], [0, 0.3, 0]]), camera.mvp)
    ndc = clip[..., :2] / clip[..., 3:]
    assert torch.allclose(ndc[:, 0], torch.zeros(3, 2), atol=1e-6)
    assert ndc[0, 1, 0] > 0 and ndc[0, 2, 1] > 0  # x right and y up in the front view
    eye = camera.view[:, :3, :3] @ camera.position[..., None] + camera.view[:, :3, 3:]
    assert torch.allclose(eye[..., 0], torch.zeros(3, 3), atol=1e-5)  # the camera sits at its eye origin
    assert torch.allclose(camera.view[:, :3, 3], torch.tensor([0.0, 0.0, -2.0]), atol=1e-6)  # origin ahead
    # Batched vertices (B,V,3) and shared vertices (V,3) give the same clip coordinates.
    verts = torch.randn(5, 3)
    assert torch.allclose(
        transform_points(verts[None].expand(3, 5, 3), camera.mvp), transform_points(verts, camera.mvp)
    )


def test_interpolate_gradcheck_and_face_attribute():
    pos = torch.tensor(
        [[-0.9, -0.9, 0, 1], [0.9, -0.8, 0.2, 1.5], [0.0, 0.9, 0.1, 1.0], [0.9, 0.9, 0.5, 1]], dtype=torch.float64
    )
    tri = torch.tensor([[0, 1, 2], [1, 3, 2]])
    raster = rasterize(pos, tri, (6, 7))
    attr = torch.randn(2, 4, 3, dtype=torch.float64, requires_grad=True)
    raster2 = rasterize(pos[None].expand(2, 4, 4), tri, (6, 7))
    assert torch.autograd.gradcheck(lambda a: interpolate(a, raster2, tri), (attr,))
    shared = torch.randn(4, 2, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda a: interpolate(a, raster, tri), (shared,))
    per_face = torch.randn(2, 3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda a: face_attribute(a, raster), (per_face,))
    looked_up = face_attribute(per_face, raster)[0]
    assert torch.equal(looked_up[raster.face_id[0] == 1], per_face[1].expand_as(looked_up[raster.face_id[0] == 1]))
    assert (looked_up[raster.face_id[0] < 0] == 0).all()


def test_texture_orientation_v_up():
    image = torch.zeros(1, 4, 2)
    image[0, 0] = 1.0  # top row of the image
    uv = torch.tensor([[[[0.25, 0.875], [0.25, 0.125]]]])  # (1,1,2,2): near the top, near the bottom
    out = sample_texture(image, uv)
    assert out.shape == (1, 1, 2, 1)
    assert out[0, 0, 0, 0] == 1.0 and out[0, 0, 1, 0] == 0.0


def test_shading_normals_noc_and_composite():
    v, tri = cube()
    camera = orbit_camera(0.0, 0.0, distance=3.0)
    raster = rasterize(transform_points(v, camera.mvp), tri, (32, 32))
    mask = render_mask(raster)
    normals = render_normals(v, tri, raster, smooth=False)
    assert torch.allclose(normals[mask[..., 0] > 0], torch.tensor([0.0, 0.0, 1.0]))
    smooth = render_normals(v, tri, raster)
    assert torch.allclose(smooth[mask[..., 0] > 0].norm(dim=-1), torch.ones(1))
    assert torch.allclose(vertex_normals(v, tri)[7], torch.ones(3) / math.sqrt(3))
    shaded = shade_lambert(torch.full((1, 32, 32, 3), 0.5), normals, [0.0, 0.0, 1.0], ambient=0.2)
    assert torch.allclose(shaded[mask[..., 0] > 0], torch.tensor(0.5))
    tilted = shade_lambert(torch.ones(1, 32, 32, 3), normals, [0.0, 1.0, 1.0], ambient=0.2)
    assert torch.allclose(tilted[mask[..., 0] > 0], torch.tensor(0.2 + 0.8 / math.sqrt(2)))
    noc = render_noc(v + 0.5, raster, tri)
    assert torch.allclose(noc[mask[..., 0] > 0][:, 2], torch.tensor(1.0))  # the front face is z = 1
    out = composite(shaded, mask, [0.0, 0.0, 1.0])
    assert torch.equal(out[mask[..., 0] == 0], torch.tensor([0.0, 0.0, 1.0]).expand(int((mask == 0).sum()), 3))
    background = torch.rand(32, 32, 3)
    out = composite(shaded, mask, background)
    assert torch.equal(out[0][mask[0, ..., 0] == 0], background[mask[0, ..., 0] == 0])


def test_uv_rasterize_maps_texel_centres_v_up():
    uv = torch.tensor([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    tri = torch.tensor([[0, 1, 2], [0, 2, 3]])
    raster = uv_rasterize(uv, tri, (8, 16))
    assert raster.mask.all()
    looked_up = interpolate(uv, raster, tri)[0]
    k = torch.arange(16, dtype=torch.float32)
    r = torch.arange(8, dtype=torch.float32)
    assert torch.allclose(looked_up[..., 0], ((k + 0.5) / 16).expand(8, 16), atol=1e-6)
    assert torch.allclose(looked_up[..., 1], (1 - (r + 0.5) / 8)[:, None].expand(8, 16), atol=1e-6)
    # Baking then sampling with sample_texture() round-trips: texel (r, k) is read back at its own uv.
    image = torch.rand(3, 8, 16)
    assert torch.allclose(sample_texture(image, looked_up[None]).permute(0, 3, 1, 2)[0], image, atol=1e-5)


def test_dilate_texture_fills_a_ring_and_keeps_defined_texels():
    image = torch.zeros(3, 9, 9)
    image[:, 4, 4] = torch.tensor([0.2, 0.4, 0.6])
    mask = torch.zeros(9, 9, dtype=torch.bool)
    mask[4, 4] = True
    out = dilate_texture(image, mask, 2)
    assert torch.allclose(out[:, 2:7, 2:7], torch.tensor([0.2, 0.4, 0.6])[:, None, None].expand(3, 5, 5))
    assert (out[:, 0] == 0).all() and (out[:, :, 8] == 0).all()
    assert torch.equal(out[:, 4, 4], image[:, 4, 4])


def test_unwrap_uv_keeps_geometry():
    v, tri = cube()
    new_v, new_f, uv, vertex_map = unwrap_uv(v, tri)
    assert new_f.shape == tri.shape and uv.shape == (new_v.shape[0], 2)
    assert torch.allclose(new_v, v[vertex_map])
    assert torch.equal(torch.sort(vertex_map[new_f], dim=1).values, torch.sort(tri, dim=1).values)
    assert uv.min() >= 0 and uv.max() <= 1
    # Every triangle gets its own non-degenerate patch of the atlas.
    raster = uv_rasterize(uv, new_f, (64, 64))
    assert set(raster.face_id.unique().tolist()) - {-1} == set(range(len(tri)))


def test_a_uv_texture_reads_its_image_where_the_surface_points_map():
    """UVTexture (a SurfaceTexture): the colour at a point is the image at the point's interpolated UV,
    texel centres exactly, in the networks' [-1, 1]; a texture not bound to a batch refuses to colour."""
    from mesh2tex.nn.generator import FaceTexture
    from mesh2tex.render.surface_texture import UVTexture

    image = torch.rand(1, 3, 4, 4) * 2 - 1
    # one triangle whose corners sit at the centres of texels (col 0, row 3), (col 3, row 3), (col 0, row 0)
    centre = lambda col, row: [(col + 0.5) / 4, 1 - (row + 0.5) / 4]  # noqa: E731
    uv = torch.tensor([[centre(0, 3), centre(3, 3), centre(0, 0)]])
    bary = torch.eye(3)
    colours = UVTexture(uv, image).colours(torch.zeros(3, dtype=torch.long), bary)
    expected = torch.stack([image[0, :, 3, 0], image[0, :, 3, 3], image[0, :, 0, 0]])
    torch.testing.assert_close(colours, expected)
    with pytest.raises(ValueError, match="not bound"):
        FaceTexture(torch.zeros(2, 4), torch.zeros(2, 3)).colours(
            torch.zeros(1, dtype=torch.long), torch.ones(1, 3) / 3
        )


def test_colours_read_in_chunks_are_the_colours_read_at_once():
    """Bakers read a texture chunk by chunk (bounded memory for a 2048^2 bake); the colours are the same."""
    from mesh2tex.render.surface_texture import UVTexture, read_colours

    g = torch.Generator().manual_seed(0)
    texture = UVTexture(torch.rand(5, 3, 2, generator=g), torch.rand(1, 3, 8, 8, generator=g) * 2 - 1)
    triangle_id = torch.randint(0, 5, (23,), generator=g)
    bary = torch.distributions.Dirichlet(torch.ones(3)).sample((23,))
    torch.testing.assert_close(
        read_colours(texture, triangle_id, bary, chunk=7), texture.colours(triangle_id, bary), rtol=0, atol=0
    )
    assert read_colours(texture, triangle_id[:0], bary[:0]).shape == (0, 3)
