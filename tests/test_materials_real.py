"""Materials of the varied world (mesh2tex.synthetic.real_materials): deterministic for a seed, with the
spectra they claim (wood and brushed metal grained along one direction, a fabric's weave periodic),
band-limited to what the world's renders resolve, chosen per part as a real chair or car has them;
the boxy world's materials unchanged."""

import hashlib
import json

import numpy as np
import pytest

from mesh2tex.synthetic.materials import UpFacing
from mesh2tex.synthetic.physical_patterns import (
    AtScale,
    BrushedMetal,
    DarkGlass,
    Fabric,
    Grain,
    Leather,
    Painted,
    Rubber,
    Seams,
)
from mesh2tex.synthetic.real_materials import metres_per_unit, real_material
from mesh2tex.synthetic.variety import generate_varied_shape
from mesh2tex.synthetic.world import WorldSpec, make_material, make_shape

PATTERNS = {
    "grain": lambda seed: Grain((0.8, 0.6, 0.4), (0.5, 0.3, 0.2), (0.0, 1.0, 0.0), seed=seed),
    "fabric": lambda seed: Fabric((0.2, 0.3, 0.5), seed=seed),
    "leather": lambda seed: Leather((0.4, 0.2, 0.1), seed=seed),
    "seams": lambda seed: Seams(Fabric((0.6, 0.6, 0.6), seed=seed), panel=0.2, channels=0.1),
    "brushed": lambda seed: BrushedMetal((0.7, 0.7, 0.72), (1.0, 0.0, 0.0), seed=seed),
    "painted": lambda seed: Painted((0.7, 0.1, 0.1), seed=seed),
    "rubber": lambda seed: Rubber(seed=seed),
    "glass": lambda seed: DarkGlass((0.1, 0.12, 0.15)),
}


def _points(n=500, seed=0):
    rng = np.random.default_rng(seed)
    normals = rng.normal(size=(n, 3))
    return rng.uniform(-0.5, 0.5, (n, 3)), normals / np.linalg.norm(normals, axis=1, keepdims=True)


def _plane(pattern, spacing: float, size: int = 64, normal=(1.0, 0.0, 0.0)) -> np.ndarray:
    """The pattern's brightness on a size x size grid (rows along y, columns along z) in the plane x = 0.01 m."""
    y, z = np.meshgrid(np.arange(size) * spacing, np.arange(size) * spacing, indexing="ij")
    points = np.stack([np.full(y.size, 0.01), y.ravel(), z.ravel()], axis=1)
    return pattern(points, np.tile(normal, (len(points), 1))).mean(axis=1).reshape(size, size)


def _power(image: np.ndarray) -> np.ndarray:
    window = np.hanning(image.shape[0])[:, None] * np.hanning(image.shape[1])[None, :]
    power = np.abs(np.fft.fft2((image - image.mean()) * window)) ** 2
    power[0, 0] = 0
    return power


@pytest.mark.parametrize("kind", sorted(PATTERNS))
def test_every_material_is_deterministic_for_a_seed_and_in_range(kind):
    points, normals = _points()
    first = PATTERNS[kind](3)(points, normals)
    assert np.array_equal(first, PATTERNS[kind](3)(points, normals))
    assert first.shape == (500, 3) and first.min() >= 0 and first.max() <= 1
    json.dumps(PATTERNS[kind](3).describe())
    if kind != "glass":  # glass has no seed: a gradient
        assert not np.array_equal(first, PATTERNS[kind](4)(points, normals))


@pytest.mark.parametrize("kind", ["grain", "brushed"])
def test_wood_and_brushed_metal_are_grained_along_their_axis(kind):
    """Their power lies across the grain: the image varies along the rows (y) for a grain along z, and the other way
    round."""
    along_z = (
        Grain((0.8, 0.6, 0.4), (0.5, 0.3, 0.2), (0.0, 0.0, 1.0), seed=1)
        if kind == "grain"
        else BrushedMetal((0.7, 0.7, 0.72), (0.0, 0.0, 1.0), across=400.0, seed=1)
    )
    power = _power(_plane(along_z, 0.001))
    f = np.abs(np.fft.fftfreq(64))
    across = power[f[:, None] > f[None, :]].sum()  # frequencies mostly along y, across the grain
    along = power[f[None, :] > f[:, None]].sum()
    assert along < 0.1 * across


def test_a_fabrics_weave_is_periodic_at_its_thread_spacing():
    fabric = Fabric((0.5, 0.4, 0.3), threads=500.0, heather=0.0, nap=1e-3, seed=2)
    u, v = np.random.default_rng(0).uniform(0, 0.05, (2, 200))
    assert np.allclose(fabric.weave(u + 2 / 500.0, v), fabric.weave(u, v))  # over-under repeats every two threads
    assert np.allclose(fabric.weave(u, v + 2 / 500.0), fabric.weave(u, v))
    spacing = 1 / 500.0 / 8  # 8 samples per thread, 8 threads across
    power = _power(_plane(fabric, spacing, normal=(1.0, 0.0, 0.0)))
    frequency = np.fft.fftfreq(64, d=spacing)  # cycles per metre
    radius = np.hypot(frequency[:, None], frequency[None, :])
    peak = radius.ravel()[power.argmax()]
    # half or one thread frequency
    assert peak == pytest.approx(250.0, rel=0.05) or peak == pytest.approx(500.0, rel=0.05)


def test_detail_finer_than_the_band_limit_fades_to_its_mean():
    """At the world's band limit a chair's 1.7 mm weave is not drawn: no point-sampled speckle, the same mean colour."""
    sharp, limited = (
        Fabric((0.5, 0.4, 0.3), threads=600.0, heather=0.0, seed=2),
        Fabric((0.5, 0.4, 0.3), threads=600.0, heather=0.0, seed=2, limit=53.0),
    )
    a, b = _plane(sharp, 0.0002, 128), _plane(limited, 0.0002, 128)
    assert b.std() < 0.1 * a.std()
    assert b.mean() == pytest.approx(a.mean(), rel=0.05)
    seam = Seams(Painted((0.6, 0.6, 0.6), peel_contrast=0.0, finish_contrast=0.0), panel=0.2, width=0.005, limit=53.0)
    # rows along y; seams at x only: the plane x = 0.01 crosses none
    line = _plane(seam, 0.001, 200, normal=(0.0, 0.0, 1.0))
    assert line.std() < 1e-6
    points = np.stack([np.linspace(-0.1, 0.1, 2001), np.zeros(2001), np.zeros(2001)], axis=1)
    profile = seam(points, np.tile([0.0, 0.0, 1.0], (2001, 1)))[:, 0]
    assert profile.min() < 0.55 and profile[1000] == pytest.approx(0.6, abs=0.01)  # a seam at x = +-0.1, none mid-panel


def test_materials_sit_at_the_shapes_physical_scale():
    for category, low, high in (("chair", 0.6, 3.0), ("car", 4.0, 7.0)):
        for seed in range(4):
            shape = generate_varied_shape(category, np.random.default_rng([5, seed]), "real")
            assert low < metres_per_unit(shape, category) < high
    pattern = Painted((0.5, 0.5, 0.5), peel=10.0, peel_contrast=0.2, seed=1)
    points, normals = _points()
    assert np.allclose(AtScale(pattern, 2.0)(points, normals), AtScale(pattern, 1.0)(points * 2.0, normals))


def test_parts_get_the_materials_a_real_object_has():
    spec = WorldSpec(category="car", variety="real", shapes=8)
    for index in range(4):
        material = make_material(spec, index)
        assert isinstance(material.parts["body"].pattern, Painted)
        assert isinstance(material.parts["wheel"].pattern, Rubber)
        cabin = material.parts["cabin"].pattern
        assert isinstance(cabin, UpFacing) and isinstance(cabin.sides, DarkGlass)
    kinds = {"leg": set(), "seat": set()}
    for seed in range(24):
        rng = np.random.default_rng([9, seed])
        for family in ("sofa", "four_legged", "shell"):
            shape = generate_varied_shape("chair", np.random.default_rng([9, seed]), "real", family)
            material = real_material("chair", rng, shape)
            kinds["leg"].add(type(material.parts["leg"].pattern).__name__)
            seat = material.parts["seat"].pattern
            kinds["seat"].add(type(seat).__name__)
            if family == "sofa":
                assert isinstance(seat, Seams) and isinstance(seat.cover, (Fabric, Leather))
    assert kinds["leg"] <= {"Grain", "BrushedMetal", "Painted"} and {"Grain", "BrushedMetal"} <= kinds["leg"]
    assert {"Seams", "Grain", "Painted"} <= kinds["seat"]


def test_a_varied_worlds_material_is_the_same_with_or_without_its_shape():
    spec = WorldSpec(category="chair", variety="real", shapes=8)
    points, normals = _points()
    parts = np.zeros(len(points), dtype=np.int64)
    a, b = make_material(spec, 2), make_material(spec, 2, make_shape(spec, 2))
    assert a.describe() == b.describe() and np.array_equal(a(points, normals, parts), b(points, normals, parts))


def test_the_boxy_worlds_materials_are_unchanged():
    # Digest of the boxy world's first materials for seed 0, recorded before the varied world's materials existed.
    digest = hashlib.sha256()
    for category in ("chair", "car"):
        spec = WorldSpec(category=category)
        for index in range(3):
            shape, material = make_shape(spec, index), make_material(spec, index)
            digest.update(json.dumps(material.describe(), sort_keys=True).encode())
            up = np.tile([0.0, 1.0, 0.0], (len(shape.vertices), 1))
            parts = np.zeros(len(shape.vertices), int) + (0 if category == "chair" else 5)
            digest.update(np.round(material(shape.vertices, up, parts), 6).tobytes())
    assert digest.hexdigest()[:16] == "a5559b5344c7a4e6"
