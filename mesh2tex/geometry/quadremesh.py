"""Quad remeshing with QuadriFlow (the pyQuadriFlow package) into a hierarchy of genuinely coarser levels.

QuadriFlow turns a triangle mesh into a pure-quad mesh of about a requested face count. On the
coarse levels of real shapes it fails in a typical way: parts thinner than a quad (chair legs,
wheels' spokes, a car's mirrors) cannot be represented, so it drops them, returns a few faces or
nothing. :func:`remesh_hierarchy` therefore gives every level a surface QuadriFlow can remesh at
that level's resolution:

- level 0 (the finest): the repaired input when it is closed and in one piece, otherwise a closed
  re-make of it (:mod:`mesh2tex.geometry.levelset`: distance field, thickened by one grid step,
  marching cubes), which fuses intersecting parts, closes holes and gives open sheets a thickness;
- every coarser level ``l``: a closed re-make of the input at that level's own resolution, with
  grid spacing and thickening half the level's quad edge ``e_l = sqrt(area / target_l)``, so that
  thin parts become tubes a few quads round and gaps narrower than a quad close.

Each result is checked (:func:`quad_mesh_problem`): face count within bounds (level 0 within
0.7-1.4 of the target, a coarser level between 1/8 and 1/2 of the finer level's count), no quad
repeating a vertex, no edge on more than two quads, and every part of the input within reach of
the quads. A count out of bounds is retried once with the request scaled by target / obtained.
When QuadriFlow still gives nothing usable at a coarse level, surface-net quads of the same
re-make are taken (:func:`mesh2tex.geometry.levelset.surface_net_quads`: always closed, manifold and
pure-quad, their count steered by the grid spacing), and the level carries a warning. A level that
nothing can make raises :class:`QuadRemeshError` with every attempt's reason.

QuadriFlow runs in a forked child process where the platform allows it, so that a crash inside the
C++ library or a run past ``timeout`` ends one attempt, not the whole batch (:mod:`mesh2tex.geometry.quadriflow`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from mesh2tex.geometry.clean import isotropic_remesh, triangle_areas
from mesh2tex.geometry.hierarchy import orient_coherently
from mesh2tex.geometry.levelset import marching_cubes, solid_field, surface_net_quads, surface_samples
from mesh2tex.geometry.prepared import quads_to_triangles
from mesh2tex.geometry.quadriflow import BudgetExceeded, QuadRemeshError, quadriflow


@dataclass
class Budget:
    """The time and memory one shape's remeshing may take: a deadline every attempt checks (an attempt
    is never given more than what is left), and an address-space limit for each QuadriFlow process."""

    seconds: float | None = None  # wall-clock seconds for all attempts of all levels (None: no limit)
    memory_gb: float | None = None  # address space of each forked QuadriFlow process, GiB (None: no limit)
    started: float = field(default_factory=time.monotonic)

    def check(self) -> None:
        """BudgetExceeded when the time is spent."""
        if self.seconds is not None and time.monotonic() - self.started >= self.seconds:
            raise BudgetExceeded(f"preparation ran past its time budget of {self.seconds:g} s")

    def timeout(self, timeout: float | None) -> float | None:
        """The seconds one attempt may take: ``timeout``, or what is left of the budget when that is less."""
        if self.seconds is None:
            return timeout
        left = max(0.0, self.seconds - (time.monotonic() - self.started))
        return left if timeout is None else min(timeout, left)


def signed_volume(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """Signed volume enclosed by triangles (positive when a closed surface faces outwards)."""
    v = np.asarray(vertices, dtype=np.float64)[triangles]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def triangles_to_quads(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split each triangle into three quads (corner, two edge midpoints, centroid); a pure-quad mesh.

    Args:
        vertices: (V, 3); triangles: (T, 3) int.
    Returns:
        (V + E + T, 3) float64 vertices and (3T, 4) int64 quads, oriented as the triangles.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    t = len(triangles)
    edges = np.stack([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]], axis=1).reshape(-1, 2)
    unique_edges, edge_index = np.unique(np.sort(edges, axis=1), axis=0, return_inverse=True)
    edge_index = edge_index.reshape(t, 3) + len(vertices)  # midpoint vertex of edges (01, 12, 20)
    centroid_index = np.arange(t) + len(vertices) + len(unique_edges)
    new_vertices = np.concatenate([vertices, vertices[unique_edges].mean(axis=1), vertices[triangles].mean(axis=1)])
    quads = np.concatenate(
        [
            np.stack([triangles[:, 0], edge_index[:, 0], centroid_index, edge_index[:, 2]], axis=1),
            np.stack([triangles[:, 1], edge_index[:, 1], centroid_index, edge_index[:, 0]], axis=1),
            np.stack([triangles[:, 2], edge_index[:, 2], centroid_index, edge_index[:, 1]], axis=1),
        ]
    )
    return new_vertices, quads


# level 0 within these factors of its target; a coarser level between 1/8 and 1/2 of the finer level's faces
LEVEL0_BOUNDS = (0.7, 1.4)
COARSER_RATIO = (2.0, 8.0)
# QuadriFlow's run time grows with its input; at 6144 quads more triangles than this add nothing
QUADRIFLOW_INPUT_TRIANGLES = 30_000
# the share of the input's surface samples that must lie within reach of a level's quads
COVERAGE_QUANTILE = 0.99
# the closed re-makes: grid spacing, and thickening of the coarse levels, in quad edges of the level
REMAKE_SPACING = 0.5
REMAKE_OFFSET = 1.0


def is_closed_single_part(faces: np.ndarray) -> bool:
    """True when every edge of (T, 3) ``faces`` lies on exactly two triangles and they form one connected piece."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return False
    edges = np.sort(np.stack([f, np.roll(f, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    _, inverse, counts = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
    if not np.all(counts == 2):
        return False
    inverse = inverse.reshape(-1)
    order = np.argsort(inverse, kind="stable")
    face = (np.arange(len(edges)) // 3)[order]
    graph = coo_matrix((np.ones(len(face) // 2), (face[0::2], face[1::2])), shape=(len(f), len(f)))
    return connected_components(graph, directed=False)[0] == 1


def quad_mesh_problem(
    vertices: np.ndarray,
    quads: np.ndarray,
    min_faces: float,
    max_faces: float,
    coverage_points: np.ndarray | None = None,
    coverage_margin: float = 0.0,
) -> str | None:
    """Why a quad mesh is unusable as a level, or None when it is fine.

    Checks: not empty; ``min_faces <= F <= max_faces``; no quad with a repeated vertex; every edge
    on exactly two quads (every surface remeshed here is closed, so a boundary edge is a hole); and,
    with ``coverage_points`` (P, 3) on the surface that was remeshed, that :data:`COVERAGE_QUANTILE`
    of them lie within ``coverage_margin`` plus one quad edge (``sqrt(area / F)``) of the mesh's
    vertices, edge midpoints or quad centres (no part left out).

    Args:
        vertices: (V, 3) float; quads: (F, 4) int.
    """
    n = len(quads)
    if n == 0:
        return "empty result"
    if not (min_faces <= n <= max_faces):
        return f"{n} faces, outside the bounds {int(np.ceil(min_faces))}-{int(max_faces)}"
    q = np.asarray(quads, dtype=np.int64)
    v = np.asarray(vertices, dtype=np.float64)
    ordered = np.sort(q, axis=1)
    if np.any(ordered[:, 1:] == ordered[:, :-1]):
        return "quads with a repeated vertex"
    edges = np.sort(np.stack([q, np.roll(q, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    if counts.max() > 2:
        return f"{int((counts > 2).sum())} edges on more than two quads"
    if counts.min() < 2:
        return f"{int((counts < 2).sum())} boundary edges: holes in the remesh of a closed surface"
    if coverage_points is not None and len(coverage_points):
        edge = float(np.sqrt(triangle_areas(v, quads_to_triangles(q)).sum() / n))
        probes = np.concatenate(
            [v[np.unique(q)], v[q].mean(axis=1), (v[q] + v[np.roll(q, -1, axis=1)]).reshape(-1, 3) / 2.0]
        )
        distance, _ = cKDTree(probes).query(coverage_points, k=1)
        reach = float(np.quantile(distance, COVERAGE_QUANTILE))
        if reach > coverage_margin + edge:
            return (
                f"parts of the shape left out ({100 * COVERAGE_QUANTILE:.0f} % of the surface within {reach:.3g}, "
                f"more than {coverage_margin + edge:.3g})"
            )
    return None


@dataclass
class LevelResult:
    """One level of a hierarchy and how it was made."""

    vertices: np.ndarray  # (V, 3) float64
    quads: np.ndarray  # (F, 4) int64, coherently oriented outwards
    target: int  # the nominal face count of the level
    method: str  # e.g. "quadriflow(input, seed=0)" or "surface nets(closed re-make, spacing=0.031, offset=0.028)"
    attempts: list[dict] = field(default_factory=list)  # every try: method, faces, problem, seconds
    warnings: list[str] = field(default_factory=list)  # a fallback was used, or the count left its aim
    seconds: float = 0.0  # the whole level: re-makes and every attempt


class _Surfaces:
    """The input, its surface samples and its closed re-makes at the resolutions the levels ask for (cached)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self.vertices, self.faces = vertices, faces
        self.area = float(triangle_areas(vertices, faces).sum())
        self._samples: tuple[float, np.ndarray, cKDTree] | None = None
        self._quadriflow_input: tuple[np.ndarray, np.ndarray] | None = None

    def quadriflow_input(self, edge: float) -> tuple[np.ndarray, np.ndarray]:
        """The repaired input remeshed to even triangles of about ``edge`` (:func:`clean.isotropic_remesh`)."""
        if self._quadriflow_input is None:
            self._quadriflow_input = isotropic_remesh(self.vertices, self.faces, edge)
        return self._quadriflow_input

    def samples(self, spacing: float) -> tuple[np.ndarray, cKDTree]:
        """Surface samples at most ``spacing`` apart (finer ones are reused) and their k-d tree."""
        if self._samples is None or self._samples[0] > spacing:
            points = surface_samples(self.vertices, self.faces, spacing)
            self._samples = (spacing, points, cKDTree(points))
        return self._samples[1], self._samples[2]

    def project(self, points: np.ndarray, spacing: float) -> np.ndarray:
        """(N, 3) points moved onto the nearest input surface sample (samples at most ``spacing`` apart)."""
        samples, tree = self.samples(spacing)
        _, nearest = tree.query(np.asarray(points, dtype=np.float64), k=1)
        return samples[nearest]

    def field(self, spacing: float, offset: float):
        points, tree = self.samples(spacing / 2.0)
        return solid_field(points, spacing, offset, tree=tree)

    def remake(self, spacing: float, offset: float, edge: float) -> tuple[np.ndarray, np.ndarray]:
        """Marching-cubes triangles of the closed solid, remeshed to even triangles of about ``edge`` for QuadriFlow."""
        v, t = marching_cubes(self.field(spacing, offset))
        if len(t) > 4 * QUADRIFLOW_INPUT_TRIANGLES // 10:
            return isotropic_remesh(v, t, edge)
        return v, t


def _coverage_points(vertices: np.ndarray, faces: np.ndarray, edge: float, count: int = 8192) -> np.ndarray:
    """(P, 3) points spread over the surface a level is remeshed from (at most ``count``, a fixed subset)."""
    points = surface_samples(vertices, faces, spacing=edge / 2.0)
    if len(points) > count:
        points = points[np.random.default_rng(0).choice(len(points), count, replace=False)]
    return points


def _attempt(
    attempts: list[dict],
    method: str,
    make,
    bounds: tuple[float, float],
    coverage: np.ndarray | None,
    budget: Budget | None = None,
):
    """Run one way of making a level; record it; return (vertices, quads) when it passes, else None.
    BudgetExceeded, before it starts, when ``budget``'s time is spent."""
    if budget is not None:
        budget.check()
    start = time.perf_counter()
    try:
        out_v, out_q = make()
        problem = quad_mesh_problem(out_v, out_q, bounds[0], bounds[1], coverage)
    except QuadRemeshError as error:
        out_v, out_q, problem = None, None, str(error)
    attempts.append(
        {
            "method": method,
            "faces": 0 if out_q is None else int(len(out_q)),
            "problem": problem,
            "seconds": round(time.perf_counter() - start, 3),
        }
    )
    return None if problem is not None else (out_v, out_q)


def _corrected(request: int, obtained: int, bounds: tuple[float, float]) -> int:
    """The request that should land inside ``bounds`` given that ``request`` gave ``obtained`` faces."""
    aim = np.sqrt(bounds[0] * bounds[1])
    return int(round(np.clip(request * aim / max(obtained, 1), request / 4.0, request * 4.0)))


def remesh_hierarchy(
    vertices: np.ndarray,
    faces: np.ndarray,
    face_counts: list[int],
    seed: int = 0,
    extra_seeds: int = 1,
    timeout: float | None = 300.0,
    isolate: bool = True,
    budget: Budget | None = None,
) -> list[LevelResult]:
    """Quad meshes of decreasing face counts for one triangle mesh (level 0 the finest); see the module docstring.

    Args:
        vertices: (V, 3) float, normalised (bbox diagonal 1); faces: (T, 3) int, repaired (clean.clean_mesh).
        face_counts: targets, finest first, e.g. [6144, 1536, 384, 96, 24].
        seed: QuadriFlow's seed; ``extra_seeds`` more are tried before a fallback.
        timeout: seconds per QuadriFlow attempt (only when ``isolate``).
        isolate: run QuadriFlow in a forked child process.
        budget: the time and memory the whole hierarchy may take (:class:`Budget`; default none).
    Returns:
        one :class:`LevelResult` per target, each strictly coarser than the one before
        (face-count ratio within :data:`COARSER_RATIO`).
    Raises:
        QuadRemeshError: a level could not be made (the message lists every attempt and its reason);
        BudgetExceeded: the budget's time was spent.
    """
    budget = budget or Budget()
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    surfaces = _Surfaces(vertices, faces)
    seeds = list(range(seed, seed + 1 + extra_seeds))
    levels: list[LevelResult] = []
    area = surfaces.area
    for level, target in enumerate(face_counts):
        level_start = time.perf_counter()
        attempts: list[dict] = []
        warnings: list[str] = []
        bounds, request = _level_request(target, len(levels[-1].quads) if levels else None)
        edge = float(np.sqrt(area / max(request, 1)))
        spacing = REMAKE_SPACING * edge
        sources = _level_sources(surfaces, faces, level, edge, spacing)

        chosen, method = _quadriflow_level(
            sources, seeds, request, bounds, attempts, level > 0, budget, timeout, isolate, edge
        )
        if chosen is None:
            chosen, method = _surface_net_level(surfaces, request, bounds, attempts, budget)
            if chosen is not None:
                warnings.append(
                    f"QuadriFlow gave no usable level at {request} faces; surface-net quads of the closed re-make "
                    "instead"
                )
        if chosen is None:
            reasons = "; ".join(f"{a['method']}: {a['problem']}" for a in attempts)
            raise QuadRemeshError(f"no quad mesh for level {level} ({target} faces): {reasons}")
        out_v, out_q = chosen
        if level == 0 and "closed re-make" in method:
            # the re-make is thicker than the input by the offset: its quads go back onto the input surface
            out_v = surfaces.project(out_v, spacing / 2.0)
            method += ", projected onto the input"
        count = len(out_q)
        if level == 0 and not (0.85 * target <= count <= 1.18 * target):
            warnings.append(f"{count} faces, {count / target:.2f} of the requested {target}")
        levels.append(
            LevelResult(
                out_v,
                orient_coherently(out_v, out_q),
                int(target),
                method,
                attempts,
                warnings,
                round(time.perf_counter() - level_start, 3),
            )
        )
        if level == 0:
            area = float(triangle_areas(out_v, quads_to_triangles(out_q)).sum())
    return levels


def _level_request(target: int, finer: int | None) -> tuple[tuple[float, float], int]:
    """The face-count bounds a level must fall in and the count asked of QuadriFlow: level 0 (``finer`` None)
    near its target; a coarser level within :data:`COARSER_RATIO` of the ``finer`` level's count."""
    if finer is None:
        return (LEVEL0_BOUNDS[0] * target, LEVEL0_BOUNDS[1] * target), int(target)
    bounds = (finer / COARSER_RATIO[1], finer / COARSER_RATIO[0])
    return bounds, int(round(np.clip(target, bounds[0] * 1.4, bounds[1] / 1.4)))


def _level_sources(surfaces: _Surfaces, faces: np.ndarray, level: int, edge: float, spacing: float) -> list:
    """[(label, make the surface QuadriFlow remeshes)]: the input itself (level 0 of a closed single part),
    then the closed re-make at ``spacing``."""
    offset = spacing if level == 0 else REMAKE_OFFSET * edge
    sources = []
    if level == 0 and is_closed_single_part(faces):
        sources.append(("input", lambda: surfaces.quadriflow_input(edge)))
    sources.append(
        (f"closed re-make, spacing={spacing:.3g}, offset={offset:.3g}", lambda: surfaces.remake(spacing, offset, edge))
    )
    return sources


def _quadriflow_level(
    sources: list,
    seeds: list[int],
    request: int,
    bounds: tuple[float, float],
    attempts: list[dict],
    coarse: bool,
    budget: Budget,
    timeout: float | None,
    isolate: bool,
    edge: float,
) -> tuple:
    """QuadriFlow on each source surface in turn (the last one with every seed) until a result passes the
    checks: (vertices, quads) and the attempt's label, or (None, ""). A count out of bounds is asked once
    more, scaled; a coarse level far from its aim too, the nearer result kept."""
    chosen, method = None, ""
    for index, (name, make_source) in enumerate(sources):
        last = index == len(sources) - 1
        budget.check()
        start = time.perf_counter()
        try:
            mesh = make_source()
        except (ValueError, RuntimeError) as error:
            attempts.append(
                {
                    "method": f"make {name}",
                    "faces": 0,
                    "problem": f"{error.__class__.__name__}: {error}",
                    "seconds": round(time.perf_counter() - start, 3),
                }
            )
            continue
        coverage = _coverage_points(*mesh, edge)
        for s in seeds if last else seeds[:1]:
            tries = [(request, f"quadriflow({name}, seed={s})")]
            for ask, label in tries:
                result = _attempt(
                    attempts,
                    label,
                    lambda: quadriflow(
                        *mesh, ask, s, timeout=budget.timeout(timeout), isolate=isolate, memory_gb=budget.memory_gb
                    ),
                    bounds,
                    coverage,
                    budget,
                )
                if result is not None:
                    got = len(result[1])
                    if chosen is None or abs(np.log(got / request)) < abs(np.log(len(chosen[1]) / request)):
                        chosen, method = result, label
                    # a cheap coarse level far from its aim is asked once more, the nearer result kept
                    if coarse and len(tries) == 1 and not (0.6 * request <= got <= request / 0.6):
                        again = int(round(ask * request / got))
                        tries.append((again, f"quadriflow({name}, {again} requested, seed={s})"))
                        continue
                    break
                got = attempts[-1]["faces"]
                if got and not (bounds[0] <= got <= bounds[1]) and len(tries) == 1:
                    again = _corrected(ask, got, bounds)
                    tries.append((again, f"quadriflow({name}, {again} requested, seed={s})"))
            if chosen is not None:
                break
        if chosen is not None:
            break
    return chosen, method


def _surface_net_level(
    surfaces: _Surfaces, request: int, bounds: tuple[float, float], attempts: list[dict], budget: Budget | None = None
):
    """Surface-net quads of the closed re-make, the grid spacing steered towards ``request`` faces.

    The count falls roughly with the square of the spacing; up to six spacings are tried, stopping
    once the count is within 0.8-1.25 of the request. Returns ((V, 3), (F, 4)) and the method name of
    the passing result nearest the request, or (None, "") when none passes.
    """
    spacing = float(np.sqrt(1.5 * surfaces.area / max(request, 1)))
    best = None
    for _ in range(6):
        offset = 0.9 * spacing
        label = f"surface nets(closed re-make, spacing={spacing:.3g}, offset={offset:.3g})"
        # the surface nets are the solid's boundary by construction: nothing of it can be left out
        result = _attempt(
            attempts, label, lambda: surface_net_quads(surfaces.field(spacing, offset)), bounds, None, budget
        )
        got = attempts[-1]["faces"]
        if result is not None:
            miss = abs(np.log(got / request))
            if best is None or miss < best[0]:
                best = (miss, result, label)
            if miss < np.log(1.25):
                break
        if not got:
            spacing /= 2.0
            continue
        spacing *= float(np.clip(np.sqrt(got / request), 0.5, 2.0))
    return (best[1], best[2]) if best is not None else (None, "")
