"""The compiled CPU loop of the rasterizer (mesh2tex.render.kernels) gives, bit for bit, what the
vectorised passes (the CUDA path and the fallback) give."""

import numpy as np
import pytest
import torch

pytest.importorskip("numba")

from test_rasterize_reference import assert_bitwise, bevelled_table, scan_sphere  # noqa: E402
from test_render_raycast import bumpy_torus  # noqa: E402

import mesh2tex.render.binning as binning  # noqa: E402
import mesh2tex.render.edges as edges  # noqa: E402
import mesh2tex.render.kernels as kernels  # noqa: E402
from mesh2tex.render import orbit_camera, rasterize, transform_points  # noqa: E402

rasterize_module = __import__("mesh2tex.render.rasterize", fromlist=["_BOX_MARGIN"])


def both_paths(monkeypatch, *args, **kwargs):
    """(compiled, vectorised) rasters of one call."""
    compiled = rasterize(*args, **kwargs)
    with monkeypatch.context() as m:
        m.setenv("MESH2TEX_RASTER_KERNEL", "torch")
        vectorised = rasterize(*args, **kwargs)
    return compiled, vectorised


@pytest.fixture(scope="module")
def meshes():
    out = {}
    for name, mesh in (("torus", bumpy_torus(48, 32)), ("table", bevelled_table(48)), ("scan", scan_sphere(12))):
        out[name] = (torch.tensor(mesh.vertices, dtype=torch.float32), torch.tensor(mesh.faces))
    return out


@pytest.mark.parametrize("name", ["torus", "table", "scan"])
@pytest.mark.parametrize(
    "dtype,cull,resolution",
    [(torch.float32, False, (64, 64)), (torch.float32, True, (97, 150)), (torch.float64, False, (200, 120))],
)
def test_compiled_loop_equals_vectorised_passes(meshes, monkeypatch, name, dtype, cull, resolution):
    vertices, faces = meshes[name]
    # Orbit views at several distances: small and large triangles, part of the mesh off screen.
    camera = orbit_camera(
        torch.tensor([30.0, 75.0, 160.0, 290.0]),
        torch.tensor([25.0, -10.0, 60.0, 5.0]),
        distance=torch.tensor([1.6, 0.9, 2.5, 1.2]),
        fov=45.0,
    )
    pos = transform_points(vertices.to(dtype), camera.mvp.to(dtype))
    compiled, vectorised = both_paths(monkeypatch, pos, faces, resolution, cull_backfaces=cull)
    assert compiled.mask.float().mean() > 0.1
    assert_bitwise(compiled, vectorised)


def test_compiled_loop_with_many_pixels_on_edges(monkeypatch):
    """Views along the axes of a grid put thousands of pixel centres on edges: more band pixels than
    the loop first makes room for, so it runs again with room for all."""
    from test_render import closed_meshes

    monkeypatch.setattr(kernels, "BAND_CAPACITY", 8)
    vertices, faces = closed_meshes()["grid_box"]
    camera = orbit_camera(torch.tensor([0.0, 90.0, 0.0]), torch.tensor([0.0, 0.0, 90.0]), distance=2.0, fov=45.0)
    pos = transform_points(vertices, camera.mvp)
    buffer = binning.DepthBuffer(3, (64, 64), (binning.WHOLE, binning.WHOLE), faces.shape[0], "cpu")
    assert kernels.rasterize_views(pos, faces, (64, 64), False, buffer) is not None
    assert sum(len(pixels) for pixels, _, _ in buffer.undecided) > 8
    compiled, vectorised = both_paths(monkeypatch, pos, faces, (64, 64))
    assert_bitwise(compiled, vectorised)


def test_a_triangle_across_the_near_plane_takes_the_vectorised_path():
    corners = torch.tensor([[[0.0, 0.0, -2.0, 1.0], [1.0, 0.0, 0.5, 1.0], [0.0, 1.0, 0.5, 1.0]]])
    buffer = binning.DepthBuffer(1, (16, 16), (binning.WHOLE, binning.WHOLE), 1, "cpu")
    assert kernels.rasterize_views(corners, torch.tensor([[0, 1, 2]]), (16, 16), False, buffer) is None
    assert rasterize(corners, torch.tensor([[0, 1, 2]]), (16, 16)).mask.any()


def test_the_loop_uses_the_constants_of_the_vectorised_passes():
    assert kernels._WHOLE == binning.WHOLE and kernels._REGION == binning.REGION
    assert float(kernels._BAND) == edges._BAND and kernels._SETUP_ROUNDING == edges._SETUP_ROUNDING
    assert kernels._BOX_MARGIN == np.float32(rasterize_module._BOX_MARGIN)
    assert float(kernels._SCALE_FLOOR) == edges._SCALE_FLOOR


def test_degenerate_triangles_and_vertices_at_the_eye(monkeypatch):
    """Zero-area triangles, a vertex with w = 0 and NaN coordinates draw nothing on either path."""
    pos = torch.tensor(
        [
            [
                [0.0, 0.0, 0.5, 1.0],
                [0.5, 0.0, 0.5, 1.0],
                [0.0, 0.5, 0.5, 1.0],
                [0.25, 0.0, 0.5, 1.0],
                [0.3, 0.3, 0.0, 0.0],
                [float("nan"), 0.1, 0.5, 1.0],
            ]
        ]
    )
    tri = torch.tensor([[0, 1, 3], [0, 0, 2], [0, 1, 4], [0, 2, 5], [0, 1, 2]])
    compiled, vectorised = both_paths(monkeypatch, pos, tri, (32, 32))
    assert_bitwise(compiled, vectorised)
    assert set(compiled.face_id.unique().tolist()) == {-1, 4}


@pytest.mark.parametrize("bad", [[[0, 1, 3]], [[0, -1, 2]]])
def test_vertex_indices_out_of_range_are_refused(bad):
    pos = torch.tensor([[0.0, 0.0, 0.5, 1.0], [0.5, 0.0, 0.5, 1.0], [0.0, 0.5, 0.5, 1.0]])
    with pytest.raises(ValueError, match="vertex indices"):
        rasterize(pos, torch.tensor(bad), (8, 8))


@pytest.mark.parametrize("far", [3.0e9, 1.0e14, 1.0e20])
def test_corners_far_outside_the_image_are_clamped_before_their_bounds_become_integers(monkeypatch, far):
    """The loop rounds and clamps each corner's box bounds in float32 before converting them: a
    triangle reaching billions of pixels past the image (or past float32's integers) covers what the
    vectorised passes cover."""
    corners = [[-far, -0.3, 0.2], [far, -0.2, 0.4], [0.1, far, 0.5], [0.3, 0.4, 0.1], [-0.5, 0.6, 0.3]]
    pos = torch.tensor([[[x, y, z, 1.0] for x, y, z in corners]])
    faces = torch.tensor([[0, 1, 2], [0, 3, 4], [1, 3, 4]])
    compiled, vectorised = both_paths(monkeypatch, pos, faces, (48, 40))
    assert compiled.mask.any()
    assert_bitwise(compiled, vectorised)


def test_a_set_up_held_from_one_call_is_not_overwritten_by_the_next(meshes):
    """The loop hands its set-up arrays out again on the next call only when nothing holds a view of
    them; a caller keeping one call's set-ups sees them unchanged after another call."""
    vertices, faces = meshes["scan"]
    camera = orbit_camera(torch.tensor([30.0, 200.0]), torch.tensor([20.0, -15.0]), distance=1.6, fov=45.0)
    pos = transform_points(vertices, camera.mvp)

    def call(p):
        buffer = binning.DepthBuffer(p.shape[0], (64, 64), (binning.WHOLE, binning.WHOLE), faces.shape[0], "cpu")
        return kernels.rasterize_views(p, faces, (64, 64), False, buffer)

    first = call(pos[:1])
    kept = [t.clone() for t in first]
    second = call(pos[1:])  # another view: other set-ups
    assert not torch.equal(first[0], second[0])
    for held, copy in zip(first, kept):
        assert torch.equal(held, copy)
    del first, second
    again = call(pos[:1])  # nothing held now: the arrays may be reused, the result is the same
    for result, copy in zip(again, kept):
        assert torch.equal(result, copy)
