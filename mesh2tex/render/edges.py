"""Exact coverage of pixel centres near triangle edges: what makes :func:`mesh2tex.render.rasterize`
watertight.

The fast passes evaluate each triangle's edge functions in float32, relative to a reference pixel,
scaled by :func:`band_scale` so that a value outside ``[-1, 1]`` (the *band*) has the sign of the
exact edge function. Pixels within the band of an edge (a small fraction of a pixel from it, or
exactly on it) are decided here, from the clip-space vertices alone, whichever triangle asks:

    E(r, c) = (v_j x v_k) . (U, V, W*H),   v = (x, y, w),   U = (2c + 1 - W) H,   V = (H - 2r - 1) W,

W*H times the edge function at the centre of pixel (row r, column c), whose sign is that of the NDC
one. Swapping the vertices negates E exactly, so the two triangles of a shared edge claim opposite
sides of it and no pixel centre falls between them. E is evaluated in float64 with a forward error
bound; where that cannot decide its sign (the centre lies on the edge, or within ~1e-14 of it),
exactly: every product split into float64 terms without error (Dekker), their sum distilled until
its sign is certain (rational arithmetic for coordinates beyond 2^±300). A centre exactly on an edge
belongs to the triangle that holds it shifted right by an infinitesimal, then down by a smaller one:
the edge is drawn when the triangle lies to its right, or below it when the edge is horizontal (the
top-left rule of GPUs). A centre on an edge shared by two triangles, or on a vertex shared by a fan
of them, is thus drawn exactly once; on a silhouette, centres on left and top outlines are drawn.
"""

from __future__ import annotations

import math
from fractions import Fraction

import torch

# The band's half-width relative to the plane's largest magnitude over the pixels it is evaluated at:
# float32 evaluation (two roundings of each coefficient, to float32 and by the scale, and two of the
# fma steps) errs by under 2^-22 of it.
_BAND = 2.0**-18
# float64 round-off of the set-up (products and their differences, the division by det, the
# rebasing; ~50 roundings of the products at most), relative to the products' largest magnitude.
_SETUP_ROUNDING = 2.0**-40
# A band half-width below this (0, NaN, or a plane out of float32's range) gets band scale 0.
_SCALE_FLOOR = 2.0**-100
# E in float64 errs by at most ~5 roundings (2^-50.7) of the sum of its terms' magnitudes.
_EXACT_ENOUGH = 2.0**-48
# Below this, float64 products may have underflowed and the error bound does not hold.
_TINY = 2.0**-900


def band_scale(
    params64: torch.Tensor, size: torch.Tensor, det: torch.Tensor, rows: torch.Tensor, cols: torch.Tensor
) -> torch.Tensor:
    """Per edge, the factor that puts the band of uncertain float32 values at ``[-1, 1]``.

    A float32 edge value ``lambda * scale`` with ``|value| > 1`` has the sign of the exact edge
    function. The half-width bounds, with a wide margin, the float32 rounding of the plane over the
    pixels it is evaluated at (its rounded coefficients, ``fma`` steps over up to 64 pixels from a
    reference pixel in the box, or 16 past it in a stencil) and the float64 round-off of the set-up.

    Args:
        params64: (12,N) float64 planes relative to each box origin (rows as in
            :func:`~mesh2tex.render.rasterize._edge_setup`).
        size: (N,) the largest magnitude of the triangle's clip-space coordinates.
        det: (N,) float64 determinant of the set-up.
        rows, cols: (N,) int64 box sizes.
    Returns:
        (3,N) float32 positive scale per edge; 0 where the edge's plane vanishes (its values are
        then all in the band and decided exactly).
    """
    # float32 suffices for a bound with this much margin. |value| + |step right| * reach + |step
    # down| * reach, edge by edge.
    value, right, down = params64.view(3, 4, -1)[:, :3].float().abs_()
    tau = torch.addcmul(torch.addcmul(value, right, (cols + 64).float()), down, (rows + 64).float())
    # An unnormalised coefficient is a difference of two products of coordinates: its round-off is
    # relative to the products (at most size^2), not to the difference.
    roundoff = (size.double().square() * _SETUP_ROUNDING / det.abs()).float()
    tau = torch.add(roundoff, tau, alpha=_BAND)
    # Where tau is 0, NaN or out of float32's range, every value is in the band (scale 0).
    return torch.where(tau > _SCALE_FLOOR, tau.reciprocal(), 0.0)


_SPLITTER = 134217729.0  # 2^27 + 1: splits a float64 into two halves of 26 bits (Dekker)
# Coordinates within these magnitudes (or zero) keep every product of the expansions below clear of
# underflow and overflow, so that they are exact.
_SAFE_LOW, _SAFE_HIGH = 2.0**-300, 2.0**300


def _two_product(a: torch.Tensor, b: torch.Tensor):
    """a * b = p + e exactly (Dekker's product; separate kernels, so no fused multiply-add)."""
    p = a * b
    c = a * _SPLITTER
    a_hi = c - (c - a)
    a_lo = a - a_hi
    c = b * _SPLITTER
    b_hi = c - (c - b)
    b_lo = b - b_hi
    return p, ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo


def _two_sum(a: torch.Tensor, b: torch.Tensor):
    """a + b = s + e exactly (Knuth's sum)."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def _distil(terms: torch.Tensor) -> torch.Tensor:
    """(m,n) float64 -> (m,n) with the same exact column sums: the first m - 1 rows are the
    round-off of a pairwise sum, the last row the rounded sum itself (error-free sums, in a tree)."""
    errors = []
    while terms.shape[0] > 1:
        odd = terms[terms.shape[0] - terms.shape[0] % 2 :]
        total, error = _two_sum(terms[0:-1:2], terms[1::2])
        errors.append(error)
        terms = torch.cat([total, odd])
    return torch.cat([*errors, terms])


def sign_of_sum(terms: torch.Tensor, passes: int = 64) -> torch.Tensor:
    """Exact sign of the sum of each column of (m,n) float64 ``terms`` (finite, clear of overflow).

    Each pass replaces the terms by their rounded sum and its round-off (exactly the same sum), so
    the round-off shrinks by ~2^-50 a pass, until the rounded sum outweighs it or all is zero.

    Returns:
        (n,) int64 in {-1, 0, 1}; 2 where ``passes`` did not settle.
    """
    sign = torch.full(terms.shape[1:], 2, dtype=torch.long, device=terms.device)
    todo = torch.arange(terms.shape[1], device=terms.device)
    for _ in range(passes):
        terms = _distil(terms)
        last, rest = terms[-1], terms[:-1].abs().sum(0)
        # The rounded sum of the others errs by far less than the margin.
        done = (last.abs() > rest * (1 + 2.0**-40)) | ((last == 0) & (rest == 0))
        sign[todo[done]] = torch.sign(last[done]).long()
        keep = torch.nonzero(~done).squeeze(1)
        if keep.numel() == 0:
            break
        terms, todo = terms[:, keep], todo[keep]
    return sign


def exact_edge_signs(coordinates: torch.Tensor, u: torch.Tensor, v: torch.Tensor, z: float):
    """Exact signs of E = A U + B V + C Z and of A and B, for edges from (x_j, y_j, w_j) to
    (x_k, y_k, w_k) with A = y_j w_k - w_j y_k, B = w_j x_k - x_j w_k, C = x_j y_k - y_j x_k.

    Args:
        coordinates: (6,n) float64 x_j, y_j, w_j, x_k, y_k, w_k.
        u, v: (n,) float64 integers; z: a positive integer (all below 2^53).
    Returns:
        sign_e, sign_a, sign_b: (n,) int64 in {-1, 0, 1}.
    """
    n = u.numel()
    # Far outside any sensible clip space (or NaN): rational arithmetic below, one by one.
    magnitude = coordinates.abs()
    unsafe = ((magnitude > _SAFE_HIGH) | ((magnitude < _SAFE_LOW) & (magnitude > 0)) | magnitude.isnan()).any(0)
    xj, yj, wj, xk, yk, wk = torch.where(unsafe, 0.0, coordinates)
    # The six products of A, B, C (the first three added, the others subtracted), each exactly as
    # p + e, then times its multiplier, exactly as four terms: E is the signed sum of 24 terms.
    p, e = _two_product(torch.stack([yj, wj, xj, wj, xj, yj]), torch.stack([wk, xk, yk, yk, wk, xk]))
    sign = torch.tensor([1.0, 1, 1, -1, -1, -1], dtype=p.dtype, device=p.device)[:, None]
    multiplier = torch.stack([u, v, torch.full_like(u, z)]).repeat(2, 1)
    terms = torch.cat([*_two_product(p, multiplier), *_two_product(e, multiplier)]) * sign.repeat(4, 1)
    # float32 coordinates make every e zero: drop the rows that are zero throughout.
    terms = terms[torch.nonzero(terms.ne(0).any(1)).squeeze(1)]
    sign_e = sign_of_sum(terms) if terms.shape[0] else torch.zeros(n, dtype=torch.long, device=u.device)
    # A and B (for the tie rule): their two products, exactly, side by side.
    ab = torch.stack([torch.cat([p[i], p[i + 1]]) for i in (0, 3)] + [torch.cat([e[i], e[i + 1]]) for i in (0, 3)])
    ab[1::2] *= -1
    sign_a, sign_b = sign_of_sum(ab).view(2, n)
    unsafe |= (sign_e == 2) | (sign_a == 2) | (sign_b == 2)
    fallback = torch.nonzero(unsafe).squeeze(1)
    if fallback.numel():
        values = coordinates[:, fallback].T.tolist()
        exact = [
            _fraction_signs(c, int(uu), int(vv), int(z))
            for c, uu, vv in zip(values, u[fallback].tolist(), v[fallback].tolist())
        ]
        exact = torch.tensor(exact, dtype=torch.long, device=u.device).view(-1, 3)
        sign_e[fallback], sign_a[fallback], sign_b[fallback] = exact.T
    return sign_e, sign_a, sign_b


def _fraction_signs(values: list[float], u: int, v: int, z: int) -> tuple[int, int, int]:
    """exact_edge_signs of one edge in rational arithmetic (NaN or infinite coordinates: 0)."""
    if not all(math.isfinite(t) for t in values):
        return 0, 0, 0
    xj, yj, wj, xk, yk, wk = (Fraction(t) for t in values)
    a = yj * wk - wj * yk
    b = wj * xk - xj * wk
    e = a * u + b * v + (xj * yk - yj * xk) * z

    def sign(t):
        return (t > 0) - (t < 0)

    return sign(e), sign(a), sign(b)


class EdgeTest:
    """Exact coverage of pixel centres by live triangles (those with a set-up), for the pixels the
    float32 filter leaves in the band.

    Args:
        pos: (B,V,4) clip-space vertices (any float dtype); tri: (T,3) int64 vertex indices.
        live: (L,) int64 (view * T + triangle) of each set-up.
        front: (L,) bool, the set-up's determinant is positive (counter-clockwise in NDC).
        resolution: (H, W).

    The corners of the set-ups it is asked about are gathered from ``pos`` when asked: few pixels
    need the test, so no per-set-up copy of every corner is kept.
    """

    def __init__(self, pos: torch.Tensor, tri: torch.Tensor, live: torch.Tensor, front: torch.Tensor, resolution):
        self.pos, self.tri, self.live, self.front = pos.detach(), tri, live, front
        self.H, self.W = int(resolution[0]), int(resolution[1])

    def corners(self, setup: torch.Tensor) -> torch.Tensor:
        """(4,3,n) clip-space corners of the set-ups ``setup`` (n,): component, corner, set-up."""
        pair = self.live.index_select(0, setup)
        T = self.tri.shape[0]
        view = torch.div(pair, T, rounding_mode="floor")
        vertex = self.tri.index_select(0, pair - view * T)  # (n,3)
        return self.pos[view[:, None], vertex].permute(2, 1, 0)  # (n,3,4) -> (4,3,n)

    def inside(self, setup: torch.Tensor, row: torch.Tensor, col: torch.Tensor) -> torch.Tensor:
        """Whether each pixel centre is covered by its triangle, exactly, with the top-left rule.

        Args:
            setup: (n,) int64 index into the live set-ups.
            row, col: (n,) int64 pixel (may lie outside the image: the answer is still exact).
        Returns:
            (n,) bool.
        """
        H, W = self.H, self.W
        c = self.corners(setup).double()  # (4,3,n)
        # Edge i joins corners j = i + 1 and k = i + 2: rows of (3,n) tensors, all edges at once.
        xj, yj, wj = (t.roll(-1, 0) for t in (c[0], c[1], c[3]))
        xk, yk, wk = (t.roll(-2, 0) for t in (c[0], c[1], c[3]))
        u = ((2 * col + 1 - W) * H).double()
        v = ((H - 2 * row - 1) * W).double()
        z = float(W * H)
        s = torch.where(self.front.index_select(0, setup), 1, -1)
        a1, a2, b1, b2, c1, c2 = yj * wk, wj * yk, wj * xk, xj * wk, xj * yk, yj * xk
        e = (a1 - a2) * u + (b1 - b2) * v + (c1 - c2) * z
        bound = (
            (a1.abs() + a2.abs()) * u.abs() + (b1.abs() + b2.abs()) * v.abs() + (c1.abs() + c2.abs()) * z
        ) * _EXACT_ENOUGH
        decided = (e.abs() > bound) & (bound > _TINY) & (bound < torch.inf)
        inside = (~decided | (e * s > 0)).all(0)
        # Exactly, for the pixels still in: few, on an edge or within ~1e-14 of one.
        edge, index = torch.nonzero(~decided & inside).T
        if index.numel() == 0:
            return inside
        coordinates = torch.stack([t[edge, index] for t in (xj, yj, wj, xk, yk, wk)])
        sign_e, sign_a, sign_b = exact_edge_signs(coordinates, u.index_select(0, index), v.index_select(0, index), z)
        side = s.index_select(0, index)
        # On the edge (E = 0): in when the inward normal (A, B) * side points right, or straight down.
        ok = (sign_e * side > 0) | ((sign_e == 0) & ((sign_a * side > 0) | ((sign_a == 0) & (sign_b * side < 0))))
        inside.index_fill_(0, index[~ok], False)
        return inside
