"""Face convolutions: hand computations on a tiny quad mesh, demodulation, pooling, unpooling, batching."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from mesh2tex.geometry.prepared import PreparedShape
from mesh2tex.nn.batch import collate_shapes
from mesh2tex.nn.faceconv import (
    LRELU_GAIN,
    FaceConv,
    FaceResNetBlock,
    FullyConnected,
    ModulatedFaceConv,
    bias_act,
    face_pool,
    face_unpool,
    gather_neighborhood,
    neighborhood_matmul,
    row_sums,
)


def quad_neighborhoods(quads: np.ndarray) -> np.ndarray:
    """(F, 9) neighbourhoods of a quad mesh: the face, then edge and corner neighbours alternating,
    edge first (across edge (q0,q1)), -1 where missing (corner faces at valence-3 vertices)."""
    edge_faces: dict[tuple[int, int], list[int]] = {}
    vertex_faces: dict[int, list[int]] = {}
    for f, q in enumerate(quads):
        for i in range(4):
            edge_faces.setdefault(tuple(sorted((int(q[i]), int(q[(i + 1) % 4])))), []).append(f)
            vertex_faces.setdefault(int(q[i]), []).append(f)
    out = np.full((len(quads), 9), -1, dtype=np.int64)
    for f, q in enumerate(quads):
        out[f, 0] = f
        edge_nbrs = set()
        for i in range(4):
            others = [g for g in edge_faces[tuple(sorted((int(q[i]), int(q[(i + 1) % 4]))))] if g != f]
            if others:
                out[f, 1 + 2 * i] = others[0]
                edge_nbrs.add(others[0])
        for i in range(4):
            v = int(q[(i + 1) % 4])
            corner = [g for g in vertex_faces[v] if g != f and g not in edge_nbrs]
            if len(corner) == 1:
                out[f, 2 + 2 * i] = corner[0]
    return out


def cube_shape(levels: int = 3, features: int = 4, seed: int = 0) -> PreparedShape:
    """A cube of 6 * 4^(levels-1) quads at the finest level, coarsened 2x2 -> 1 per level.

    Bounding-box diagonal 1, centred at the origin; face features: the face normal and a random column.
    """
    rng = np.random.default_rng(seed)
    half = 0.5 / math.sqrt(3.0)
    sides = [(axis, sign) for axis in range(3) for sign in (-1.0, 1.0)]
    verts_l, quads_l, pools = [], [], []
    for level in range(levels):
        n = 2 ** (levels - 1 - level)
        index: dict[tuple[int, int, int], int] = {}
        verts, quads = [], []

        def vid(p):
            key = tuple(int(round(c * n)) for c in p)
            if key not in index:
                index[key] = len(verts)
                verts.append(np.array(p) * 2 * half - half)
            return index[key]

        for axis, sign in sides:
            u_axis, v_axis = [a for a in range(3) if a != axis]
            for i in range(n):
                for j in range(n):
                    corners = []
                    for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1)):
                        p = [0.0, 0.0, 0.0]
                        p[axis] = 1.0 if sign > 0 else 0.0
                        p[u_axis], p[v_axis] = (i + di) / n, (j + dj) / n
                        corners.append(vid(p))
                    quads.append(corners if sign > 0 else corners[::-1])
        verts_l.append(np.array(verts, dtype=np.float32))
        quads_l.append(np.array(quads, dtype=np.int64))
        if level < levels - 1:
            m = n // 2
            pools.append(
                np.array(
                    [s * m * m + (i // 2) * m + j // 2 for s in range(6) for i in range(n) for j in range(n)],
                    dtype=np.int64,
                )
            )
    normals = np.repeat(
        np.array([[s if a == axis else 0.0 for a in range(3)] for axis, s in sides], dtype=np.float32),
        4 ** (levels - 1),
        axis=0,
    )
    face_features = np.concatenate([normals, rng.normal(size=(len(normals), features - 3)).astype(np.float32)], axis=1)
    noc = (verts_l[0] - verts_l[0].min(0)) / np.ptp(verts_l[0], axis=0)
    return PreparedShape(
        vertices=verts_l,
        quads=quads_l,
        neighbors=[quad_neighborhoods(q) for q in quads_l],
        pool=pools,
        face_features=face_features,
        feature_names=["nx", "ny", "nz"] + [f"r{i}" for i in range(features - 3)],
        noc=noc.astype(np.float32),
    )


def test_cube_fixture_is_a_closed_quad_hierarchy():
    shape = cube_shape(3)
    assert shape.face_counts == [96, 24, 6]
    # 8 cube corners are valence 3, each misses one corner neighbour for the 3 faces around it.
    assert (shape.neighbors[0] == -1).sum() == 24
    for level in range(2):
        assert np.bincount(shape.pool[level]).tolist() == [4] * shape.face_counts[level + 1]


def test_face_conv_matches_hand_computation():
    shape = cube_shape(2)
    neighbors = torch.as_tensor(shape.neighbors[0])
    torch.manual_seed(0)
    x = torch.randn(shape.face_counts[0], 3)
    conv = FaceConv(3, 2, activation="linear")
    with torch.no_grad():
        conv.bias.copy_(torch.tensor([0.5, -1.0]))
    out = conv(x, neighbors)
    w = conv.weight * conv.weight_gain
    for f in [0, 5, 17, shape.face_counts[0] - 1]:
        expected = conv.bias.clone()
        for k in range(9):
            n = int(neighbors[f, k])
            if n >= 0:  # missing neighbours read zeros
                expected = expected + w[:, k, :] @ x[n]
        torch.testing.assert_close(out[f], expected, rtol=1e-5, atol=1e-5)


def test_missing_neighbors_read_zeros():
    x = torch.arange(6.0).reshape(3, 2) + 1
    neighbors = torch.tensor([[0, 1, -1, 2, -1, -1, -1, -1, -1]] * 3)
    patches = gather_neighborhood(x, neighbors)
    assert patches.shape == (3, 9, 2)
    assert torch.equal(patches[0, 2], torch.zeros(2)) and torch.equal(patches[0, 3], x[2])


def test_modulated_conv_equals_per_sample_weights_and_demodulation_keeps_unit_variance():
    torch.manual_seed(1)
    shape = cube_shape(4)  # 384 faces
    batch = collate_shapes([shape, cube_shape(4, seed=1)])
    conv = ModulatedFaceConv(64, 64, w_dim=16, activation="linear", use_noise=False, clamp=None)
    w = torch.randn(2, 16) * 3
    x = torch.randn(batch.num_faces(0), 64)
    out = conv(x, batch.neighbors[0], w, batch.shape_index[0])
    # Per-sample explicit weight: w'_{b,o,k,c} = w_{o,k,c} s_{b,c} / norm.
    styles = conv.affine(w)
    weight = conv.weight * conv.weight_gain
    for b in range(2):
        wb = weight * styles[b].view(1, 1, -1)
        wb = wb / wb.square().sum(dim=(1, 2), keepdim=True).add(1e-8).sqrt()
        sel = batch.shape_index[0] == b
        ref = gather_neighborhood(x, batch.neighbors[0])[sel].flatten(1) @ wb.flatten(1).t()
        torch.testing.assert_close(out[sel], ref, rtol=1e-4, atol=1e-4)
    # Interior faces (all 9 neighbours present) of unit-variance input give unit-variance output.
    full = (batch.neighbors[0] >= 0).all(1)
    assert abs(out[full].var().item() - 1.0) < 0.15
    # Without demodulation, strong styles blow the variance up.
    raw = ModulatedFaceConv(64, 64, w_dim=16, activation="linear", use_noise=False, demodulate=False, clamp=None)
    raw.load_state_dict(conv.state_dict())
    assert raw(x, batch.neighbors[0], w, batch.shape_index[0])[full].var().item() > 2.0


def test_pooling_and_unpooling():
    shape = cube_shape(3)
    pool = torch.as_tensor(shape.pool[0])
    x = torch.randn(96, 5)
    mx = face_pool(x, pool, 24, "max")
    mean = face_pool(x, pool, 24, "mean")
    for c in range(24):
        torch.testing.assert_close(mx[c], x[pool == c].max(0).values)
        torch.testing.assert_close(mean[c], x[pool == c].mean(0))
    coarse = torch.randn(24, 5)
    up = face_unpool(coarse, pool)  # no blur: a copy
    assert torch.equal(up, coarse[pool])
    blurred = face_unpool(coarse, pool, torch.as_tensor(shape.neighbors[0]))
    # A constant field stays constant under the normalised blur; a varying one is smoothed.
    torch.testing.assert_close(
        face_unpool(torch.ones(24, 5), pool, torch.as_tensor(shape.neighbors[0])), torch.ones(96, 5)
    )
    assert blurred.var() < up.var()


def test_resnet_block_and_gradients_reach_parameters():
    shape = cube_shape(2)
    block = FaceResNetBlock(4, 8)
    out = block(torch.as_tensor(shape.face_features), torch.as_tensor(shape.neighbors[0]))
    assert out.shape == (24, 8)
    out.square().sum().backward()
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in block.parameters())


def test_collate_offsets_indices_and_keeps_missing():
    a, b = cube_shape(2), cube_shape(3)
    with pytest.raises(ValueError):
        collate_shapes([a, b])  # different level counts
    a, b = cube_shape(3), cube_shape(3, seed=2)
    batch = collate_shapes([a, b])
    assert batch.num_faces(0) == 192 and batch.num_vertices == 2 * len(a.vertices[0])
    assert torch.equal(
        batch.neighbors[0][96:][b.neighbors[0] >= 0], torch.as_tensor(b.neighbors[0][b.neighbors[0] >= 0]) + 96
    )
    assert (batch.neighbors[0][96:][b.neighbors[0] < 0] == -1).all()
    assert torch.equal(batch.pool[0][96:], torch.as_tensor(b.pool[0]) + 24)
    assert torch.equal(batch.quads[96:], torch.as_tensor(b.quads[0]) + len(a.vertices[0]))
    assert batch.shape_index[1].tolist() == [0] * 24 + [1] * 24
    assert torch.equal(batch.shape_triangles(1), torch.as_tensor(b.triangles(0)))


def test_derived_geometry_is_computed_once_and_agrees_with_the_offsets():
    """The batch's and the prepared shape's derived geometry (triangles, per-shape ranges, each vertex's
    shape) is what the offsets say, and a second call returns the same object instead of deriving it again."""
    a, b = cube_shape(3), cube_shape(3, seed=2)
    batch = collate_shapes([a, b])
    faces, vertices = len(a.quads[0]), len(a.vertices[0])
    assert batch.face_ranges == [(0, faces), (faces, 2 * faces)] and batch.vertex_ranges == [
        (0, vertices),
        (vertices, 2 * vertices),
    ]
    assert batch.vertex_shape.tolist() == [0] * vertices + [1] * vertices
    for s in (0, 1):
        first = 2 * batch.face_ranges[s][0]
        local = batch.triangles()[first : first + 2 * faces] - batch.vertex_ranges[s][0]
        assert torch.equal(batch.shape_triangles(s), local)
        assert batch.shape_triangles(s) is batch.shape_triangles(s)
        assert torch.equal(
            batch.shape_vertices(s), batch.vertices[batch.vertex_ranges[s][0] : batch.vertex_ranges[s][1]]
        )
    assert batch.triangles() is batch.triangles() and a.triangles(0) is a.triangles(0)
    moved = batch.to("cpu")
    assert moved.triangles() is not batch.triangles() and torch.equal(moved.triangles(), batch.triangles())


def test_fused_activation_equals_the_separate_operations_to_second_order():
    """The LeakyReLU path of bias_act runs in one buffer with its own backward: values, gradients and
    the gradients of gradients (R1, path length) are those of the plain operations, clamp included,
    on contiguous and on channels-last activations (the discriminator's)."""
    torch.manual_seed(3)
    for shape, clamp, layout in (
        ((6, 5), None, torch.contiguous_format),
        ((3, 4, 5, 5), 1.0, torch.contiguous_format),
        ((3, 4, 5, 5), 1.0, torch.channels_last),
        ((3, 4, 5, 5), 100.0, torch.channels_last),
    ):
        x = torch.randn(shape).contiguous(memory_format=layout).requires_grad_(True)
        b = torch.randn(shape[1], requires_grad=True)
        g = torch.randn(shape)
        results = []
        for fused in (True, False):
            if fused:
                y = bias_act(x, b, "lrelu", gain=0.5**0.5, clamp=clamp)
            else:
                y = torch.nn.functional.leaky_relu(x + b.reshape([1, -1] + [1] * (x.dim() - 2)), 0.2) * (
                    LRELU_GAIN * 0.5**0.5
                )
                y = y if clamp is None else y.clamp(-clamp, clamp)
            gx, gb = torch.autograd.grad(y, [x, b], g, create_graph=True)
            second = torch.autograd.grad((gx.square() * x).sum() + gb.square().sum(), [x, b], allow_unused=True)
            results.append([y, gx, gb] + [torch.zeros_like(t) if s is None else s for s, t in zip(second, (x, b))])
        assert clamp in (None, 100.0) or (results[0][0].abs() == clamp).any()  # the clamp did bite
        for fused, plain in zip(*results):
            assert torch.equal(fused, plain)
    xd = torch.randn(2, 3, 4, 4, dtype=torch.float64, requires_grad=True)
    bd = torch.randn(3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradgradcheck(lambda x, b: bias_act(x, b, "lrelu", clamp=1.5), (xd, bd))


def test_narrow_face_convolution_multiplies_before_gathering_with_the_same_result():
    shape = cube_shape(3)
    neighbors = torch.as_tensor(shape.neighbors[0])  # with missing corner neighbours
    torch.manual_seed(4)
    x = torch.randn(shape.face_counts[0], 6, dtype=torch.float64, requires_grad=True)
    weight = torch.randn(2, 9, 6, dtype=torch.float64, requires_grad=True)  # 6 -> 2: products first
    out = neighborhood_matmul(x, neighbors, weight)
    torch.testing.assert_close(out, gather_neighborhood(x, neighbors).flatten(1) @ weight.flatten(1).t())
    assert torch.autograd.gradgradcheck(lambda x, w: neighborhood_matmul(x, neighbors, w), (x, weight))


def test_row_sums_and_unpooling_are_twice_differentiable():
    shape = cube_shape(3)
    pool, neighbors = torch.as_tensor(shape.pool[0]), torch.as_tensor(shape.neighbors[0])
    torch.manual_seed(5)
    coarse = torch.randn(24, 3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradgradcheck(lambda x: face_unpool(x, pool, neighbors), (coarse,))
    index = torch.randint(0, 24, (40, 5))
    weight = torch.rand(40, 5, dtype=torch.float64)
    torch.testing.assert_close(row_sums(coarse, index, weight), (coarse[index] * weight[..., None]).sum(1))
    assert torch.autograd.gradgradcheck(lambda x: row_sums(x, index, weight), (coarse,))


def test_fully_connected_shared_columns_equal_the_concatenated_input():
    torch.manual_seed(6)
    layer = FullyConnected(7, 4, activation="lrelu")
    x, shared = torch.randn(10, 5), torch.randn(1, 2)
    torch.testing.assert_close(layer(x, shared=shared), layer(torch.cat([x, shared.expand(10, -1)], dim=1)))
