"""The generator, the neural field psi, the discriminator and the texture renderer."""

from __future__ import annotations

import itertools

import pytest
import torch
from test_faceconv import cube_shape

from mesh2tex.nn.batch import collate_shapes
from mesh2tex.nn.discriminator import Discriminator, DiscriminatorConfig
from mesh2tex.nn.faceconv import ModulatedFaceConv
from mesh2tex.nn.field import (
    NeuralField,
    blend_vertex_features,
    local_coordinates,
    sorted_cdf_coordinates,
    vertex_features,
)
from mesh2tex.nn.generator import GeneratorConfig, TextureGenerator
from mesh2tex.nn.render_texture import rasterize_batch, render_field_views
from mesh2tex.render import RenderSettings, orbit_camera


def tiny_generator(coords: str = "raw", levels: int = 3, kind: str = "faceconv") -> TextureGenerator:
    cfg = GeneratorConfig(
        z_dim=16,
        w_dim=16,
        mapping_layers=2,
        input_features=4,
        encoder_channels=[8] * levels,
        synthesis_channels=[8] * levels,
        field_hidden=16,
        aux_latent_dim=8,
        field_coords=coords,
        kind=kind,
        nca_channels=6,
        nca_hidden=16,
        nca_steps=4,
        nca_condition=4,
    )
    return TextureGenerator(cfg)


def tiny_batch():
    return collate_shapes([cube_shape(3, seed=0), cube_shape(3, seed=1)])


def views(n_shapes=2, k=2):
    az = torch.arange(n_shapes * k, dtype=torch.float32) * 70.0 + 20.0
    return orbit_camera(az, torch.full_like(az, 25.0), distance=1.6).mvp


def test_generator_shapes_and_accepts_single_or_per_layer_ws():
    torch.manual_seed(0)
    gen, batch = tiny_generator(), tiny_batch()
    texture, ws = gen(batch, torch.randn(2, 16))
    assert ws.shape == (2, gen.num_ws, 16)
    assert texture.field_features.shape == (192, gen.field_dim) and texture.face_rgb.shape == (192, 3)
    a = gen.synthesize(batch, ws[:, 0], noise_mode="none")
    b = gen.synthesize(batch, ws, noise_mode="none")
    torch.testing.assert_close(a.face_rgb, b.face_rgb)
    with pytest.raises(ValueError):
        gen.synthesize(batch, ws[:1])
    last = gen.last_synthesis_parameters(2)
    assert last and all(any(p is q for q in gen.synthesis[-2:].parameters()) for p in last)
    assert sum(p.numel() for p in last) == sum(p.numel() for p in gen.synthesis[-2:].parameters())


def test_latent_changes_texture_and_shapes_get_their_own_style():
    torch.manual_seed(0)
    gen, batch = tiny_generator(), tiny_batch()
    z = torch.randn(2, 16)
    t1, _ = gen(batch, z, noise_mode="none")
    t2, _ = gen(batch, torch.stack([z[0], torch.randn(16)]), noise_mode="none")
    # Shape 0 keeps its latent: same texture; shape 1 changed latent: different texture.
    torch.testing.assert_close(t1.face_rgb[:96], t2.face_rgb[:96])
    assert (t1.face_rgb[96:] - t2.face_rgb[96:]).abs().max() > 1e-4


def test_sorted_cdf_coordinates_are_order_free_balanced_and_in_range():
    torch.manual_seed(0)
    bary = torch.distributions.Dirichlet(torch.ones(3)).sample((20000,))
    u = sorted_cdf_coordinates(bary)
    assert u.min() >= -1 and u.max() <= 1
    # Uniform points in a triangle map to (nearly) uniform coordinates: mean 0, variance 1/3 each.
    assert u.mean(0).abs().max() < 0.03 and (u.var(0) - 1 / 3).abs().max() < 0.03
    for perm in itertools.permutations(range(3)):
        torch.testing.assert_close(sorted_cdf_coordinates(bary[:, list(perm)]), u)
    raw = local_coordinates(bary, "raw")
    assert not torch.allclose(local_coordinates(bary[:, [1, 0, 2]], "raw"), raw)


def test_field_blends_mean_vertex_features():
    faces = torch.tensor([[0, 1, 2, 3], [1, 4, 5, 2]])
    feats = torch.tensor([[1.0, 0.0], [3.0, 2.0]])
    vf = vertex_features(feats, faces, 6)
    torch.testing.assert_close(vf[1], torch.tensor([2.0, 1.0]))  # shared by both faces
    torch.testing.assert_close(vf[4], torch.tensor([3.0, 2.0]))
    tri = torch.tensor([[0, 1, 2], [1, 4, 5]])
    blended = blend_vertex_features(vf, tri, torch.tensor([0]), torch.tensor([[0.5, 0.5, 0.0]]))
    torch.testing.assert_close(blended, torch.tensor([[1.5, 0.5]]))
    field = NeuralField(2, hidden=8, aux_dim=4)
    assert field(blended, torch.tensor([[0.5, 0.5, 0.0]])).shape == (1, 3)


def test_a_fresh_generator_starts_from_unsaturated_colours():
    # A saturated start (the plain init gives one colour near +-2 per channel for some seeds) leaves
    # short runs painting every shape that colour; the default output inits (psi's last layer and the
    # toRGB layers, whose blend psi adds to) start well inside [-1, 1].
    batch = tiny_batch()
    for seed in range(6):
        torch.manual_seed(seed)
        gen = TextureGenerator(
            GeneratorConfig(input_features=4, encoder_channels=[16] * 3, synthesis_channels=[16] * 3)
        )
        _, ws = gen(batch, torch.randn(2, gen.cfg.z_dim))
        out = render_field_views(gen, batch, ws, views(), (16, 16), torch.zeros(4, 3), noise_mode="none")
        colours = out.images.permute(0, 2, 3, 1)[out.mask[:, 0] > 0]
        assert colours.abs().max() < 0.8, f"seed {seed}: fresh colours up to {colours.abs().max():.2f}"
        assert colours.std(0).max() > 0, "the fresh field must still vary over the surface"


@pytest.mark.parametrize("coords", ["raw", "sorted_cdf"])
def test_render_and_gradients_reach_every_parameter(coords):
    torch.manual_seed(0)
    gen, batch = tiny_generator(coords), tiny_batch()
    mvp = views()
    d_field = Discriminator(16, DiscriminatorConfig(channel_base=64, channel_max=16))
    d_proxy = Discriminator(16, DiscriminatorConfig(channel_base=64, channel_max=16))
    background = torch.rand(4, 3) * 2 - 1
    _, ws = gen(batch, torch.randn(2, 16))
    out = render_field_views(gen, batch, ws, mvp, (16, 16), background, proxy=True)
    assert out.images.shape == (4, 3, 16, 16) and out.proxy.shape == (4, 3, 16, 16) and out.mask.shape == (4, 1, 16, 16)
    cover = out.mask[:, 0] > 0
    assert 0 < cover.float().mean() < 1
    # Background pixels keep the background colour exactly.
    bg = background[:, :, None, None].expand(4, 3, 16, 16)
    assert torch.equal(out.images.permute(0, 2, 3, 1)[~cover], bg.permute(0, 2, 3, 1)[~cover])
    loss = d_field(out.images).sum() + d_proxy(out.proxy).sum()
    loss.backward()
    for name, p in itertools.chain(
        gen.named_parameters(), d_field.named_parameters(prefix="d_field"), d_proxy.named_parameters(prefix="d_proxy")
    ):
        assert p.grad is not None and torch.isfinite(p.grad).all() and p.grad.abs().sum() > 0, name


def test_field_is_evaluated_only_at_covered_pixels(monkeypatch):
    torch.manual_seed(0)
    gen, batch = tiny_generator(), tiny_batch()
    seen = []
    original = gen.field.forward
    monkeypatch.setattr(gen.field, "forward", lambda f, b: seen.append(f.shape[0]) or original(f, b))
    mvp = views()
    samples = rasterize_batch(batch, mvp, (16, 16))
    _, ws = gen(batch, torch.randn(2, 16))
    render_field_views(gen, batch, ws, mvp, (16, 16), torch.zeros(4, 3), samples=samples)
    assert seen == [int(samples.mask.sum())]
    # Views of shape 1 point at shape 1's triangles.
    assert samples.triangle_id[2:][samples.mask[2:]].min() >= 192


def test_psi_colours_start_from_the_blended_proxy_colours():
    """With field_residual (the default), psi adds to the blend of the per-face (proxy) colours: a
    latent swap moves psi's colours about as much as the proxy's, which the proxy discriminator trains."""
    torch.manual_seed(0)
    gen, batch = tiny_generator(), tiny_batch()
    triangle_id = torch.arange(0, 384, 7)
    bary = torch.full((len(triangle_id), 3), 1 / 3)
    with torch.no_grad():
        torch.nn.init.zeros_(gen.field.head[-1].weight)
        torch.nn.init.zeros_(gen.field.head[-1].bias)  # psi's own output zero: what is left is the base
        texture, _ = gen(batch, torch.randn(2, 16), noise_mode="none")
        base = texture.colours(triangle_id, bary)
        corner = batch.triangles()[triangle_id]
        # the base at a triangle's centre is the mean of its three vertices' mean face colours
        from mesh2tex.nn.field import vertex_features

        vertex_rgb = vertex_features(texture.face_rgb, batch.quads, batch.num_vertices)
        torch.testing.assert_close(base, vertex_rgb[corner].mean(1))


def test_psi_reads_the_latent_not_only_the_geometry():
    """psi's input is F_c (latent-dependent) by default: two latents give different psi colours at
    the same surface points, and with no geometry channels the field features are exactly F_c."""
    torch.manual_seed(0)
    gen, batch = tiny_generator(), tiny_batch()
    assert gen.field_dim == gen.cfg.synthesis_channels[0]
    mvp = views()
    out = [
        render_field_views(
            gen, batch, gen.mapping(torch.randn(2, 16)), mvp, (16, 16), torch.zeros(4, 3), noise_mode="none"
        )
        for _ in range(2)
    ]
    cover = out[0].mask > 0
    assert (out[0].images - out[1].images).abs()[cover.expand_as(out[0].images)].mean() > 1e-3
    cfg = GeneratorConfig(
        z_dim=16,
        w_dim=16,
        mapping_layers=2,
        input_features=4,
        encoder_channels=[8] * 3,
        synthesis_channels=[8] * 3,
        field_hidden=16,
        aux_latent_dim=8,
        field_geometry_channels=2,
    )
    with_geometry = TextureGenerator(cfg)
    texture, _ = with_geometry(batch, torch.randn(2, 16))
    assert texture.field_features.shape == (192, 10)
    assert any(
        p is q for p in with_geometry.parameter_groups()["field"] for q in with_geometry.field_geometry.parameters()
    )


def test_nca_generator_follows_the_latent_and_trains_end_to_end():
    """generator.kind nca: different latents paint different textures, inference is deterministic, and
    gradients from both discriminators' inputs reach every parameter (the automaton included)."""
    torch.manual_seed(0)
    gen, batch = tiny_generator(kind="nca"), tiny_batch()
    assert gen.num_ws == 1 and len(gen.encoder.blocks) == 1
    ws = gen.mapping(torch.randn(2, 16))
    a = gen.synthesize(batch, ws, noise_mode="none")
    again = gen.synthesize(batch, ws, noise_mode="none")
    assert torch.equal(a.face_rgb, again.face_rgb)
    swapped = gen.synthesize(batch, ws.flip(0), noise_mode="none")
    f0 = int(batch.face_offsets[0][1])
    assert (a.face_rgb[:f0] - swapped.face_rgb[:f0]).abs().mean() > 1e-3
    assert (a.field_features[:f0] - swapped.field_features[:f0]).abs().mean() > 1e-3
    out = render_field_views(gen, batch, ws, views(), (16, 16), torch.zeros(4, 3), proxy=True)
    (out.images.square().mean() + out.proxy.square().mean()).backward()
    for name, p in gen.named_parameters():
        if name.startswith("mapping"):
            continue  # reached through ws, which this test feeds directly
        assert p.grad is not None and p.grad.abs().sum() > 0, name
    automaton = gen.synthesis
    assert set(map(id, gen.last_synthesis_parameters())) == set(
        map(id, list(automaton.nca.update.parameters()) + list(automaton.torgb.parameters()))
    )


def test_an_automaton_checkpoint_from_before_the_kinds_had_one_interface_still_loads():
    """Its keys were ``nca.*`` and ``nca_torgb.*`` of the generator; they load into today's
    ``synthesis.nca.*`` and ``synthesis.torgb.*`` with every weight in place."""
    cfg = GeneratorConfig(
        z_dim=16,
        w_dim=16,
        mapping_layers=2,
        input_features=4,
        encoder_channels=[8] * 2,
        synthesis_channels=[8] * 2,
        field_hidden=16,
        aux_latent_dim=8,
        kind="nca",
        nca_channels=4,
        nca_hidden=8,
        nca_steps=2,
        nca_condition=4,
    )
    torch.manual_seed(0)
    trained = TextureGenerator(cfg)
    former = {
        k.replace("synthesis.torgb.", "nca_torgb.").replace("synthesis.nca.", "nca."): v
        for k, v in trained.state_dict().items()
    }
    assert any(k.startswith("nca_torgb.") for k in former) and not any(k.startswith("synthesis.") for k in former)
    torch.manual_seed(1)
    loaded = TextureGenerator(cfg)
    loaded.load_state_dict(former)
    for name, value in trained.state_dict().items():
        assert torch.equal(loaded.state_dict()[name], value), name


def test_every_generator_kind_keeps_the_feature_synthesis_interface():
    """A kind is a FeatureSynthesis registered by name: its sizes known before it is built agree with
    what it builds, and the generator's texture has its channels."""
    from mesh2tex.nn.synthesis import SYNTHESIS_KINDS, FeatureSynthesis

    for kind, cls in SYNTHESIS_KINDS.items():
        cfg = GeneratorConfig(
            z_dim=16,
            w_dim=16,
            mapping_layers=2,
            input_features=4,
            encoder_channels=[8] * 3,
            synthesis_channels=[8] * 3,
            field_hidden=16,
            aux_latent_dim=8,
            kind=kind,
            nca_channels=4,
            nca_hidden=8,
            nca_steps=2,
            nca_condition=4,
        )
        gen = TextureGenerator(cfg)
        assert isinstance(gen.synthesis, FeatureSynthesis) and type(gen.synthesis) is cls
        assert (
            cls.sizes(cfg) == (gen.synthesis.num_ws, gen.synthesis.encoder_levels)
            and gen.num_ws == gen.synthesis.num_ws
        )
        assert len(gen.encoder.blocks) == gen.synthesis.encoder_levels
        assert gen.field_dim == gen.synthesis.channels and gen.last_synthesis_parameters()


def test_lit_renders_are_the_albedo_scaled_by_lambert_shading():
    """Lights shade psi and proxy colours alike: ambient 1 is the unlit render; otherwise each covered
    pixel's albedo (colour + 1) / 2 is scaled by a + (1 - a)|n.l| of its quad, never brightened, and the
    background is untouched; gradients still reach the generator."""
    from mesh2tex.render import LightConfig, Lights, quad_normals, random_lights

    torch.manual_seed(0)
    gen, batch = tiny_generator(), tiny_batch()
    mvp, background = views(), torch.rand(4, 3) * 2 - 1
    ws = gen.mapping(torch.randn(2, 16))
    samples = rasterize_batch(batch, mvp, (16, 16))
    texture = gen.synthesize(batch, ws, noise_mode="none")

    def render(lights):
        return render_field_views(
            gen, batch, ws, mvp, (16, 16), background, proxy=True, texture=texture, samples=samples, lights=lights
        )

    unlit = render(None)
    direction = torch.nn.functional.normalize(torch.randn(4, 3), dim=1)
    assert torch.allclose(render(Lights(direction, torch.ones(4))).images, unlit.images, atol=1e-6)
    ambient = torch.tensor([0.2, 0.4, 0.0, 0.6])
    lit = render(Lights(direction, ambient))
    cover = samples.mask  # (4, 16, 16)
    normals = quad_normals(batch.vertices, batch.quads)[samples.triangle_id[cover] // 2]
    view = torch.arange(4)[:, None, None].expand_as(cover)[cover]
    factor = ambient[view] + (1 - ambient[view]) * (normals * direction[view]).sum(1).abs()
    for name in ("images", "proxy"):
        got = (getattr(lit, name).permute(0, 2, 3, 1)[cover] + 1) / 2
        albedo = (getattr(unlit, name).permute(0, 2, 3, 1)[cover] + 1) / 2
        assert torch.allclose(got, albedo * factor[:, None], atol=1e-5), name
        assert torch.equal(
            getattr(lit, name).permute(0, 2, 3, 1)[~cover], getattr(unlit, name).permute(0, 2, 3, 1)[~cover]
        )
    assert (factor < 0.99).any(), "some pixels must be shaded"
    # The prior: directions are unit vectors within the configured elevations; ambient in range.
    cfg = LightConfig()
    drawn = random_lights(torch.full((256,), 30.0), cfg, torch.Generator().manual_seed(0))
    elevation = torch.rad2deg(torch.asin(drawn.direction[:, 1]))
    assert torch.allclose(drawn.direction.norm(dim=1), torch.ones(256), atol=1e-6)
    assert elevation.min() >= cfg.elevation_min - 1e-3 and elevation.max() <= cfg.elevation_max + 1e-3
    assert drawn.ambient.min() >= cfg.ambient_min and drawn.ambient.max() <= cfg.ambient_max
    out = render_field_views(
        gen,
        batch,
        gen.mapping(torch.randn(2, 16)),
        mvp,
        (16, 16),
        background,
        proxy=True,
        lights=Lights(direction, ambient),
    )
    (out.images.sum() + out.proxy.sum()).backward()
    assert all(p.grad is not None for p in gen.synthesis.parameters())


def test_the_diversity_term_pushes_two_latents_textures_apart_and_stops_at_its_target():
    """Mode seeking (loss.diversity_weight): the ratio is zero for a collapsed generator; a few steps of
    the term alone raise it; once it is over diversity_target the term adds no gradient."""
    from mesh2tex.losses.gan import GanLoss, GanLossConfig, GanScene, mode_seeking_ratio
    from mesh2tex.nn.render_texture import render_proxy_views

    torch.manual_seed(0)
    gen, batch = tiny_generator(), tiny_batch()
    mvp = views()
    samples = rasterize_batch(batch, mvp, (16, 16))
    background, z = torch.zeros(4, 3), torch.randn(2, 16)
    mask = samples.mask.unsqueeze(1).float()
    proxy = render_proxy_views(gen.synthesize(batch, gen.mapping(z), noise_mode="none"), batch, samples, background)
    assert float(mode_seeking_ratio(proxy, proxy, mask, z, torch.randn(2, 16)).detach()) == 0.0
    # the proxy path alone equals render_field_views' proxy images
    full = render_field_views(
        gen, batch, gen.mapping(z), mvp, (16, 16), background, proxy=True, samples=samples, noise_mode="none"
    )
    torch.testing.assert_close(proxy, full.proxy)

    shapes = [cube_shape(3, seed=0), cube_shape(3, seed=1)]
    scene = GanScene(shapes, batch, mvp, samples, background, None, RenderSettings(16, lighting="albedo"))
    torch.testing.assert_close(scene.object_mask, mask)

    def proxy_of(z_):
        return render_proxy_views(
            gen.synthesize(batch, gen.mapping(z_), noise_mode="none"), batch, samples, background
        ), mask

    class Zero(torch.nn.Module):  # a discriminator with no opinion: only the diversity term moves the generator
        def forward(self, x):
            return x.sum(dim=[1, 2, 3]) * 0.0

    def ratio():
        torch.manual_seed(1)
        with torch.no_grad():
            zs = torch.randn(8, 2, 16)
            return (
                sum(
                    float(mode_seeking_ratio(proxy_of(a)[0], proxy_of(b)[0], mask, a, b))
                    for a, b in zip(zs[:4], zs[4:])
                )
                / 4
            )

    loss = GanLoss(GanLossConfig(diversity_weight=1.0, diversity_target=10.0), gen, Zero(), Zero())
    opt = torch.optim.Adam(gen.parameters(), lr=1e-2)
    before = ratio()
    for _ in range(10):
        opt.zero_grad()
        logs = loss.accumulate_gradients("Gmain", scene, torch.randn(2, 16), torch.zeros(4, 3, 16, 16))
        opt.step()
    assert "mode_seeking" in logs and ratio() > 1.5 * before
    reached = GanLoss(GanLossConfig(diversity_weight=1.0, diversity_target=0.0), gen, Zero(), Zero())
    opt.zero_grad()
    reached.accumulate_gradients("Gmain", scene, torch.randn(2, 16), torch.zeros(4, 3, 16, 16))
    assert all(p.grad is None or float(p.grad.abs().max()) == 0.0 for p in gen.parameters())


def test_the_diversity_term_runs_from_its_start_every_interval_scaled_by_it():
    """loss.diversity_start / diversity_interval: lazy mode seeking, as lazy R1 (gain = interval)."""
    from mesh2tex.losses.gan import GanLoss, GanLossConfig

    lazy = GanLoss(GanLossConfig(diversity_weight=1.0, diversity_start=5, diversity_interval=4), None, None)
    assert [lazy.diversity_gain(i) for i in range(4, 14)] == [0, 4, 0, 0, 0, 4, 0, 0, 0, 4]
    assert [GanLoss(GanLossConfig(), None, None).diversity_gain(i) for i in range(3)] == [1, 1, 1]
    assert GanLoss(GanLossConfig(diversity_weight=0.0), None, None).diversity_gain(0) == 0
    with pytest.raises(ValueError, match="diversity_interval"):
        GanLossConfig(diversity_interval=0)


def test_gathers_repeat_to_the_bit_with_two_threads():
    """A training run repeats from its seed on a multi-core CPU: the layers whose rows many faces or
    pixels read (the styles of a modulated face convolution, the corner features psi blends) return
    identical gradients in every backward pass on two torch threads, even when the readers of one
    row are spread over the whole batch."""
    threads = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        torch.manual_seed(0)
        conv = ModulatedFaceConv(32, 32, 16)
        x = torch.randn(20000, 32, requires_grad=True)
        sample_index = torch.randint(0, 2, (20000,))  # faces of two samples, interleaved
        neighbors = torch.randint(-1, 20000, (20000, 9))
        w = torch.randn(2, 16, requires_grad=True)
        vertex_feats = torch.randn(8, 16, requires_grad=True)  # a cube's corners, seen by 50000 pixels
        triangles = torch.randint(0, 8, (12, 3))
        triangle_id = torch.randint(0, 12, (50000,))
        bary = torch.rand(50000, 3)
        weights = torch.randn(20000, 32), torch.randn(50000, 16)

        def gradients():
            for tensor in (x, w, vertex_feats):
                tensor.grad = None
            conv.zero_grad()
            out = conv(x, neighbors, w, sample_index, noise_mode="none")
            blended = blend_vertex_features(vertex_feats, triangles, triangle_id, bary)
            ((out * weights[0]).sum() + (blended * weights[1]).sum()).backward()
            return [x.grad.clone(), w.grad.clone(), vertex_feats.grad.clone()] + [
                p.grad.clone() for p in conv.parameters() if p.grad is not None
            ]

        first = gradients()
        for _ in range(4):
            assert all(torch.equal(a, b) for a, b in zip(first, gradients()))
    finally:
        torch.set_num_threads(threads)


def test_renders_have_no_thread_order_gathers():
    """Every row gather between the latent and a rendered pixel goes through take_rows: no x[index]
    node, whose gradient adds shared rows in thread order, is in the graph of a field or proxy render."""
    torch.manual_seed(0)
    gen, batch = tiny_generator(), tiny_batch()
    ws = gen.mapping(torch.randn(2, 16))
    out = render_field_views(gen, batch, ws, views(2, 2), (32, 32), torch.zeros(4, 3), proxy=True)
    seen, stack, names = set(), [out.images.sum().grad_fn, out.proxy.sum().grad_fn], set()
    while stack:
        node = stack.pop()
        if node is None or node in seen:
            continue
        seen.add(node)
        names.add(type(node).__name__)
        stack.extend(parent for parent, _ in node.next_functions)
    assert "IndexSelectBackward0" in names and not any(name.startswith("IndexBackward") for name in names)
