"""The mesh cellular automaton: perception, update rule, readouts, meshes, masks, rendering and baking."""

import numpy as np
import pytest
import torch

from mesh2tex.errors import InputError
from mesh2tex.geometry.primitives import (
    cube_sphere,
    density_subdivisions,
    load_surface,
    mean_edge_length,
    read_surface,
    subdivide_quads,
    unit_surface,
)
from mesh2tex.geometry.regions import region_weights
from mesh2tex.nn.cell_graph import build_cell_graph, perceive, perceive_edges, spherical_harmonics
from mesh2tex.nn.nca import AutomatonTexture, MeshNCA, NCAConfig
from mesh2tex.nn.render_texture import render_states
from mesh2tex.render import orbit_camera
from mesh2tex.render.uv import bake_surface_colours


def grid_mesh(n: int):
    """An n x n vertex grid with unit spacing in the xy plane, as quads."""
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    vertices = np.stack([jj.ravel(), ii.ravel(), np.zeros(n * n)], axis=1).astype(np.float32)
    index = np.arange(n * n).reshape(n, n)
    quads = np.stack([index[:-1, :-1], index[:-1, 1:], index[1:, 1:], index[1:, :-1]], axis=-1).reshape(-1, 4)
    return vertices, quads


def interior(n: int) -> np.ndarray:
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    return ((ii > 0) & (ii < n - 1) & (jj > 0) & (jj < n - 1)).ravel()


def test_order0_perception_on_a_grid_is_the_discrete_laplacian():
    n = 7
    vertices, quads = grid_mesh(n)
    graph = build_cell_graph(vertices, quads)
    values = torch.randn(n, n)
    z = perceive(values.reshape(1, -1, 1), graph, order=0, nominal_valence=4.0)[0, :, 0].reshape(n, n)
    laplacian = values[:-2, 1:-1] + values[2:, 1:-1] + values[1:-1, :-2] + values[1:-1, 2:] - 4 * values[1:-1, 1:-1]
    assert torch.allclose(z[1:-1, 1:-1], laplacian, atol=1e-5)


def test_order1_perception_of_a_ramp_is_twice_its_gradient():
    n = 6
    vertices, quads = grid_mesh(n)
    graph = build_cell_graph(vertices, quads)
    a, b = 0.7, -0.3
    ramp = torch.from_numpy(a * vertices[:, 0] + b * vertices[:, 1]).reshape(1, -1, 1)
    z = perceive(ramp, graph, order=1, nominal_valence=4.0)[0]  # (V, 4): Y_0, then (y, z, x)
    inner = torch.from_numpy(interior(n))
    assert torch.allclose(z[inner, 0], torch.zeros(int(inner.sum())), atol=1e-5)  # a ramp has no Laplacian
    assert torch.allclose(z[inner, 1], torch.full((int(inner.sum()),), 2 * b), atol=1e-5)
    assert torch.allclose(z[inner, 2], torch.zeros(int(inner.sum())), atol=1e-5)
    assert torch.allclose(z[inner, 3], torch.full((int(inner.sum()),), 2 * a), atol=1e-5)


@pytest.mark.parametrize("order", [0, 1, 2])
def test_sparse_perception_equals_the_edge_list_definition(order):
    vertices, quads = cube_sphere(6)
    graph = build_cell_graph(vertices, quads, "edges+diagonals")
    state = torch.randn(2, graph.num_cells, 5)
    for angle in (0.0, 0.4):
        assert torch.allclose(
            perceive(state, graph, order, 4.0, angle), perceive_edges(state, graph, order, 4.0, angle), atol=1e-5
        )


def test_orientation_rotates_the_edge_directions_about_the_normal():
    vertices, quads = grid_mesh(4)
    graph = build_cell_graph(vertices, quads)
    d0, d90 = graph.directions(0.0), graph.directions(np.pi / 2)
    n = graph.normals[graph.receiver]
    assert torch.allclose(d90, torch.linalg.cross(n, d0), atol=1e-6)
    assert torch.allclose(spherical_harmonics(d0, 2)[:, 0], torch.ones(d0.shape[0]))


def test_update_rule_has_the_papers_parameter_count():
    assert MeshNCA(NCAConfig(channels=16, hidden=128, sh_order=1)).rule_parameters() == 12_432


def test_update_rate_is_the_share_of_cells_that_change():
    model = MeshNCA(NCAConfig(channels=4, update_rate=0.5))
    torch.nn.init.constant_(model.update[2].bias, 1.0)  # every cell that fires changes
    vertices, quads = cube_sphere(130)  # 101k cells
    graph = build_cell_graph(vertices, quads)
    state = torch.zeros(1, graph.num_cells, 4)
    changed = (model.step(state, graph, generator=torch.Generator().manual_seed(0)) != state).any(-1).float().mean()
    assert graph.num_cells > 100_000
    assert abs(float(changed) - 0.5) < 0.005


def test_seeded_rollouts_are_reproducible_and_the_identity_at_start():
    vertices, quads = cube_sphere(5)
    graph = build_cell_graph(vertices, quads)
    torch.manual_seed(1)
    model = MeshNCA()
    state = model.seed_state(1, graph.num_cells)
    assert torch.equal(model.rollout(state, graph, 3), state)  # the last layer starts at zero
    torch.nn.init.normal_(model.update[2].weight, std=0.1)
    runs = [model.rollout(state, graph, 5, generator=torch.Generator().manual_seed(7)) for _ in range(2)]
    assert torch.equal(runs[0], runs[1])
    assert not torch.equal(runs[0], model.rollout(state, graph, 5, generator=torch.Generator().manual_seed(8)))


@pytest.mark.parametrize("readout", ["linear", "lppn"])
def test_gradients_reach_every_parameter_through_rollout_and_render(readout):
    vertices, quads = cube_sphere(4)
    graph = build_cell_graph(vertices, quads)
    torch.manual_seed(0)
    model = MeshNCA(NCAConfig(channels=8, hidden=16, readout=readout))
    torch.nn.init.normal_(model.update[2].weight, std=0.05)
    state = model.rollout(
        model.seed_state(1, graph.num_cells, generator=torch.Generator().manual_seed(0)) + 0.1, graph, 3
    )
    views = render_states(model, state, graph, orbit_camera(torch.tensor([0.0, 120.0]), 20.0, distance=3.2).mvp, 32)
    ((views.images - 0.3) ** 2 * views.mask).mean().backward()
    for name, p in model.named_parameters():
        assert p.grad is not None and p.grad.abs().sum() > 0, name


def test_graft_blends_the_updates_of_two_models_by_the_mask():
    vertices, quads = cube_sphere(4)
    graph = build_cell_graph(vertices, quads)
    torch.manual_seed(0)
    a, b = MeshNCA(NCAConfig(update_rate=1.0)), MeshNCA(NCAConfig(update_rate=1.0))
    for m in (a, b):
        torch.nn.init.normal_(m.update[2].weight, std=0.1)
    state = torch.randn(1, graph.num_cells, 16) * 0.1
    alpha = torch.from_numpy(region_weights("x > 0", graph.positions.numpy()))
    grafted = a.step(state, graph, graft=(b, alpha))
    left, right = alpha == 0, alpha == 1
    assert torch.allclose(grafted[0, left], a.step(state, graph)[0, left], atol=1e-6)
    assert torch.allclose(grafted[0, right], b.step(state, graph)[0, right], atol=1e-6)


@pytest.mark.parametrize("readout", ["linear", "lppn"])
def test_a_grafted_growth_is_read_by_each_sides_own_readout(readout):
    """Cells grown by the grafted model take its colours (a child fine-tuned from a parent learns its own
    readout); the two readouts blend where the mask does, and renders, baking and vertex colours agree."""
    vertices, quads = cube_sphere(4)
    graph = build_cell_graph(vertices, quads)
    torch.manual_seed(0)
    a, b = MeshNCA(NCAConfig(readout=readout)), MeshNCA(NCAConfig(readout=readout))
    state = torch.randn(1, graph.num_cells, 16) * 0.3
    alpha = torch.from_numpy(region_weights("smoothstep(0.2, 0.6, x)", graph.positions.numpy())).float()
    triangle_id = torch.arange(0, len(graph.triangles), 3)
    bary = torch.rand(len(triangle_id), 3)
    bary = bary / bary.sum(1, keepdim=True)
    with torch.no_grad():
        grafted = a.colours(state, graph.triangles, triangle_id, bary, graft=(b, alpha))
        own, other = (
            a.colours(state, graph.triangles, triangle_id, bary),
            b.colours(state, graph.triangles, triangle_id, bary),
        )
        weight = (alpha[graph.triangles[triangle_id]] * bary).sum(1, keepdim=True)
        torch.testing.assert_close(grafted, (1 - weight) * own + weight * other)
        left, right = (weight == 0).squeeze(1), (weight == 1).squeeze(1)
        assert left.any() and right.any()
        torch.testing.assert_close(grafted[left], own[left])
        torch.testing.assert_close(grafted[right], other[right])
        vertex = a.vertex_colours(state, graft=(b, alpha))
        torch.testing.assert_close(
            vertex,
            (1 - alpha[None, :, None]) * a.vertex_colours(state) + alpha[None, :, None] * b.vertex_colours(state),
        )
        mvp = orbit_camera(torch.tensor([100.0, 280.0]), 10.0, distance=3.2).mvp
        views = render_states(a, state.expand(2, -1, -1), graph, mvp, 24, graft=(b, alpha))
        plain = render_states(a, state.expand(2, -1, -1), graph, mvp, 24)
        assert (views.images[0] - plain.images[0]).abs().max() > 1e-3  # the +x side (alpha 1) is read by b
        torch.testing.assert_close(views.images[1], plain.images[1])  # the -x side (alpha 0) by a


def test_cube_sphere_is_closed_outward_and_subdivision_welds():
    vertices, quads = cube_sphere(5)
    assert vertices.shape == (6 * 25 + 2, 3) and quads.shape == (150, 4)
    edges = np.sort(np.stack([quads, np.roll(quads, -1, 1)], -1).reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)  # closed: every edge shared by two quads
    graph = build_cell_graph(vertices, quads)
    assert float((graph.normals * graph.positions).sum(-1).min()) > 0.99
    fine_v, fine_q = subdivide_quads(vertices, quads)
    assert fine_v.shape[0] == vertices.shape[0] + len(counts) + quads.shape[0]  # every midpoint once
    fine_edges = np.sort(np.stack([fine_q, np.roll(fine_q, -1, 1)], -1).reshape(-1, 2), axis=1)
    assert np.all(np.unique(fine_edges, axis=0, return_counts=True)[1] == 2)


def test_load_surface_normalises_to_the_unit_ball(tmp_path):
    import trimesh

    trimesh.creation.box((4.0, 2.0, 1.0)).export(tmp_path / "box.obj")
    vertices, faces = load_surface(str(tmp_path / "box.obj"))
    assert faces.shape[1] == 3
    assert np.isclose(np.linalg.norm(vertices, axis=1).max(), 1.0)
    assert load_surface("sphere:3")[1].shape == (54, 4)
    with pytest.raises(InputError, match="sphere:N"):
        load_surface("sphere:x")


def _edge_counts(faces: np.ndarray) -> np.ndarray:
    edges = np.sort(np.stack([faces, np.roll(faces, -1, 1)], -1).reshape(-1, 2), axis=1)
    return np.unique(edges, axis=0, return_counts=True)[1]


def test_subdivision_keeps_the_surface_and_closed_meshes_closed(tmp_path):
    import trimesh

    # Quads: the cube-sphere's grid pushed out to the cube has planar quads lying on the cube's faces.
    vertices, quads = cube_sphere(3)
    vertices = vertices / np.abs(vertices).max(axis=1, keepdims=True)
    fine_v, fine_q = subdivide_quads(vertices, quads)
    np.testing.assert_allclose(np.abs(fine_v).max(axis=1), 1.0, atol=1e-6)  # every new vertex on the cube
    assert np.all(_edge_counts(fine_q) == 2)
    cube = trimesh.Trimesh(fine_v, np.concatenate([fine_q[:, :3], fine_q[:, [0, 2, 3]]]), process=False)
    assert np.isclose(cube.area, 24.0) and np.isclose(cube.volume, 8.0, rtol=1e-5)  # outward, nothing added or lost

    # Triangles (a mesh file): load_surface's splits put new vertices on the original triangles.
    trimesh.creation.icosphere(1).export(tmp_path / "ico.obj")
    coarse_v, coarse_f = load_surface(str(tmp_path / "ico.obj"))
    for level in (1, 2):
        fine_v, fine_f = load_surface(str(tmp_path / "ico.obj"), subdivide=level)
        assert fine_f.shape == (coarse_f.shape[0] * 4**level, 3)
        triangles = np.repeat(coarse_v[coarse_f][None], len(fine_v), 0).reshape(-1, 3, 3)
        points = np.repeat(fine_v, len(coarse_f), 0)
        distance = np.linalg.norm(trimesh.triangles.closest_point(triangles, points) - points, axis=1).reshape(
            len(fine_v), -1
        )
        assert distance.min(axis=1).max() < 1e-5  # each new vertex lies on an original triangle
        fine = trimesh.Trimesh(fine_v, fine_f, process=False)
        assert fine.is_watertight and np.isclose(fine.volume, trimesh.Trimesh(coarse_v, coarse_f).volume, rtol=1e-5)
        assert np.isclose(mean_edge_length(fine_v, fine_f), mean_edge_length(coarse_v, coarse_f) / 2**level, rtol=0.05)


def test_a_surface_read_once_gives_each_subdivision_without_being_changed(tmp_path):
    """infer nca reads the mesh once, measures it, then subdivides the same arrays: they must come out unchanged."""
    import trimesh

    trimesh.creation.icosphere(1).export(tmp_path / "ico.obj")
    for spec in (str(tmp_path / "ico.obj"), "sphere:3"):
        surface = read_surface(spec)
        kept = [array.copy() for array in surface]
        for level in (0, 1, 2):
            vertices, faces = unit_surface(*surface, subdivide=level, name=spec)
            assert faces.shape[0] == kept[1].shape[0] * 4**level and np.isclose(
                np.linalg.norm(vertices, axis=1).max(), 1.0
            )
        assert all(np.array_equal(a, b) and a.dtype == b.dtype for a, b in zip(surface, kept))
    with pytest.raises(InputError, match="flat.obj: the mesh has no extent"):
        unit_surface(np.zeros((3, 3)), np.array([[0, 1, 2]]), name="flat.obj")


def test_density_rule_picks_the_split_count_nearest_the_training_spacing():
    assert [density_subdivisions(r, 1.0) for r in (0.3, 1.0, 1.4, 1.5, 2.0, 2.9, 3.0, 8.0, 100.0)] == [
        0,
        0,
        0,
        1,
        1,
        2,
        2,
        3,
        3,
    ]
    assert density_subdivisions(5.0, 0.0) == 0  # a model without the record: the mesh as it is
    # sphere:8 has edges 4x the training sphere's (sphere:32): two splits bring them level.
    target = mean_edge_length(*load_surface("sphere"))
    coarse = load_surface("sphere:8")
    level = density_subdivisions(mean_edge_length(*coarse), target)
    assert level == 2
    fine = load_surface("sphere:8", subdivide=level)
    assert fine[0].shape[0] == load_surface("sphere")[0].shape[0]
    assert abs(np.log2(mean_edge_length(*fine) / target)) < 0.5


def test_region_weights_from_expressions_and_files(tmp_path):
    positions = np.array([[-0.5, 0.0, 0.0], [0.5, 0.2, 0.0], [0.0, 0.9, 0.1]])
    assert region_weights("x > 0", positions).tolist() == [0.0, 1.0, 0.0]
    assert np.allclose(region_weights("clip(y * 2, 0, 1)", positions), [0.0, 0.4, 1.0])
    np.save(tmp_path / "mask.npy", np.array([0.2, 0.5, 2.0]))
    assert np.allclose(region_weights(str(tmp_path / "mask.npy"), positions), [0.2, 0.5, 1.0])
    for bad in ("__import__('os').system('true')", "x.real", "open('f')", "x >"):
        with pytest.raises(InputError, match="graft mask"):
            region_weights(bad, positions)
    with pytest.raises(InputError, match="3 vertices"):
        np.save(tmp_path / "short.npy", np.zeros(2))
        region_weights(str(tmp_path / "short.npy"), positions)


@pytest.mark.parametrize("readout", ["linear", "lppn"])
def test_baked_texels_equal_the_readout(readout):
    vertices, quads = cube_sphere(3)
    graph = build_cell_graph(vertices, quads)
    torch.manual_seed(0)
    model = MeshNCA(NCAConfig(channels=6, hidden=8, readout=readout))
    state = torch.rand(1, graph.num_cells, 6) * 1.6 - 0.8

    grown = AutomatonTexture(model, state, graph.triangles)
    with torch.no_grad():
        _, faces, uv, texture, covered = bake_surface_colours(graph.positions, graph.triangles, grown, 64, dilate=0)
        from mesh2tex.render import uv_rasterize

        raster = uv_rasterize(uv, faces, (64, 64))
        expected = model.colours(state, graph.triangles, raster.face_id[0][covered], raster.bary[0][covered]).clamp(
            -1, 1
        )
    baked = torch.from_numpy(texture)[covered].float() / 127.5 - 1
    assert covered.float().mean() > 0.3
    assert (baked - expected).abs().max() <= 1.0 / 255 + 1e-6


def test_points_read_the_state_of_their_own_sample():
    """colours(state, ..., sample): a point of sample b is coloured from state b, as if b were the only state."""
    vertices, quads = cube_sphere(2)
    graph = build_cell_graph(vertices, quads)
    torch.manual_seed(0)
    model = MeshNCA(NCAConfig(channels=6, hidden=8))
    state = torch.rand(3, graph.num_cells, 6) * 1.6 - 0.8
    triangle_id = torch.randint(0, graph.triangles.shape[0], (50,))
    bary = torch.distributions.Dirichlet(torch.ones(3)).sample((50,))
    sample = torch.randint(0, 3, (50,))
    with torch.no_grad():
        mixed = model.colours(state, graph.triangles, triangle_id, bary, sample)
        for b in range(3):
            alone = model.colours(state[b : b + 1], graph.triangles, triangle_id, bary)
            torch.testing.assert_close(mixed[sample == b], alone[sample == b])
