"""A tensor of the wrong shape fails at the public call, with a message that names the argument, the shape it
needs and the shape it has (mesh2tex.checks), instead of an index error deep inside."""

from __future__ import annotations

import pytest
import torch

from mesh2tex.checks import check_shape
from mesh2tex.nn.faceconv import FaceConv, ModulatedFaceConv, face_pool, face_unpool
from mesh2tex.render import interpolate, rasterize, sample_texture


def test_check_shape_sizes_alternatives_and_types():
    sizes = check_shape(torch.zeros(5, 3), "f: x", ("F", 3))
    assert sizes == {"F": (5, "x")}
    check_shape(torch.zeros(5, 9), "f: n", ("F", 9), sizes=sizes)
    with pytest.raises(ValueError, match=r"f: n must have shape \[F, 9\] \(F = 5 from x\), got \[4, 9\]"):
        check_shape(torch.zeros(4, 9), "f: n", ("F", 9), sizes=sizes)
    check_shape(torch.zeros(7, 4), "g: pos", ("B", "V", 4), ("V", 4))
    with pytest.raises(ValueError, match=r"g: pos must have shape \[B, V, 4\] or \[V, 4\], got \[7, 3\]"):
        check_shape(torch.zeros(7, 3), "g: pos", ("B", "V", 4), ("V", 4))
    check_shape(torch.zeros(2, 6), "h: x", (None, 6))
    with pytest.raises(TypeError, match="h: x must be a torch.Tensor of shape \\[\\*, 6\\], got list"):
        check_shape([[0.0] * 6], "h: x", (None, 6))


def _triangle():
    pos = torch.tensor([[[-0.5, -0.5, 0.0, 1.0], [0.5, -0.5, 0.0, 1.0], [0.0, 0.5, 0.0, 1.0]]])
    return pos, torch.tensor([[0, 1, 2]])


def test_rasterize_and_interpolate_name_the_wrong_argument():
    pos, tri = _triangle()
    raster = rasterize(pos, tri, (8, 8))
    assert interpolate(torch.rand(3, 2), raster, tri).shape == (1, 8, 8, 2)
    with pytest.raises(ValueError, match=r"rasterize: pos must have shape \[B, V, 4\] or \[V, 4\], got \[1, 3, 3\]"):
        rasterize(pos[..., :3], tri, (8, 8))
    with pytest.raises(ValueError, match=r"rasterize: tri must have shape \[T, 3\], got \[3\]"):
        rasterize(pos, tri[0], (8, 8))
    with pytest.raises(ValueError, match="rasterize: resolution must be"):
        rasterize(pos, tri, (8,))
    with pytest.raises(
        ValueError, match=r"interpolate: attr must have shape \[V, C\] or \[1, V, C\] or \[B, V, C\], got \[3\]"
    ):
        interpolate(torch.rand(3), raster, tri)
    with pytest.raises(ValueError, match=r"sample_texture: uv must have shape \[B, H, W, 2\]"):
        sample_texture(torch.rand(3, 4, 4), torch.rand(1, 8, 8, 3))


def test_face_convolutions_name_the_wrong_argument():
    faces, neighbors = 6, torch.randint(-1, 6, (6, 9))
    conv = FaceConv(4, 8)
    assert conv(torch.rand(faces, 4), neighbors).shape == (faces, 8)
    with pytest.raises(ValueError, match=r"FaceConv: x must have shape \[F, 4\], got \[6, 5\]"):
        conv(torch.rand(faces, 5), neighbors)
    with pytest.raises(
        ValueError, match=r"FaceConv: neighbors must have shape \[F, 9\] \(F = 6 from x\), got \[5, 9\]"
    ):
        conv(torch.rand(faces, 4), neighbors[:5])
    modulated = ModulatedFaceConv(4, 8, w_dim=16)
    sample_index = torch.zeros(faces, dtype=torch.long)
    assert modulated(torch.rand(faces, 4), neighbors, torch.rand(1, 16), sample_index).shape == (faces, 8)
    with pytest.raises(ValueError, match=r"ModulatedFaceConv: w must have shape \[B, 16\], got \[1, 8\]"):
        modulated(torch.rand(faces, 4), neighbors, torch.rand(1, 8), sample_index)
    with pytest.raises(
        ValueError, match=r"ModulatedFaceConv: sample_index must have shape \[F\] \(F = 6 from x\), got \[3\]"
    ):
        modulated(torch.rand(faces, 4), neighbors, torch.rand(1, 16), sample_index[:3])
    pool = torch.tensor([0, 0, 1, 1, 2, 2])
    assert face_pool(torch.rand(faces, 3), pool, 3).shape == (3, 3)
    with pytest.raises(ValueError, match=r"face_pool: pool must have shape \[F\] \(F = 6 from x\), got \[5\]"):
        face_pool(torch.rand(faces, 3), pool[:5], 3)
    with pytest.raises(ValueError, match=r"face_unpool: neighbors_fine must have shape \[F, 9\], got \[6, 8\]"):
        face_unpool(torch.rand(3, 3), pool, neighbors[:, :8])
