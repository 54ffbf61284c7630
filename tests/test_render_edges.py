"""The exact edge test behind the rasterizer's watertightness: its arithmetic agrees with rational
arithmetic, including sums that cancel exactly and centres exactly on edges."""

from fractions import Fraction

import numpy as np
import torch

from mesh2tex.render.edges import exact_edge_signs, sign_of_sum


def fraction_sign(values) -> int:
    total = sum(Fraction(v) for v in values)
    return (total > 0) - (total < 0)


def test_sign_of_sum_is_exact_under_cancellation():
    rng = np.random.default_rng(0)
    for trial in range(60):
        m = int(rng.integers(1, 30))
        terms = rng.normal(size=(m, 40)) * 2.0 ** rng.integers(-60, 60, size=(m, 40))
        if trial % 3 == 0:  # exact zeros, shuffled: x and -x
            half = terms[: (m + 1) // 2]
            terms = np.concatenate([half, -half])[rng.permutation(2 * len(half))]
        elif trial % 3 == 1:  # sums within rounding of zero
            terms = np.concatenate([terms, -terms.sum(0, keepdims=True)])
        terms = torch.tensor(terms)
        expected = [fraction_sign(column) for column in terms.T.tolist()]
        assert sign_of_sum(terms).tolist() == expected


def test_exact_edge_signs_agree_with_rational_arithmetic():
    rng = np.random.default_rng(1)
    W = H = 255
    n = 400
    for trial in range(8):
        coordinates = torch.tensor(rng.normal(size=(6, n)) * 2.0 ** rng.integers(-8, 8, size=(6, n)))
        if trial % 2:
            coordinates = coordinates.float().double()  # float32 clip coordinates: exact products
        col, row = (torch.tensor(rng.integers(-20, 275, size=n)) for _ in range(2))
        u = ((2 * col + 1 - W) * H).double()
        v = ((H - 2 * row - 1) * W).double()
        if trial >= 4:
            # Pixel centres exactly on the edge: the second vertex is a combination of the first and
            # of the centre's homogeneous point (u, v, W H), all integers (times a power of two), so
            # exact; for a few, a multiple of the first (a degenerate edge: E = A = B = 0).
            first = torch.tensor(rng.integers(-1000, 1000, size=(3, n)), dtype=torch.float64)
            alpha, beta = (torch.tensor(rng.integers(-3, 4, size=n), dtype=torch.float64) for _ in range(2))
            beta[: n // 10] = 0
            second = alpha * first + beta * torch.stack([u, v, torch.full_like(u, W * H)])
            on = torch.tensor(rng.random(n) < 0.5)
            scale = 2.0 ** float(rng.integers(-20, 4))
            coordinates[:3, on], coordinates[3:, on] = first[:, on] * scale, second[:, on] * scale
        if trial == 7:  # magnitudes beyond the error-free range: the rational fallback
            coordinates[:, :5] *= 2.0**400
        got = torch.stack(exact_edge_signs(coordinates, u, v, float(W * H))).T.tolist()
        for (xj, yj, wj, xk, yk, wk), uu, vv, signs in zip(coordinates.T.tolist(), u.tolist(), v.tolist(), got):
            a = [Fraction(yj) * Fraction(wk), -Fraction(wj) * Fraction(yk)]
            b = [Fraction(wj) * Fraction(xk), -Fraction(xj) * Fraction(wk)]
            c = [Fraction(xj) * Fraction(yk), -Fraction(yj) * Fraction(xk)]
            e = [t * int(uu) for t in a] + [t * int(vv) for t in b] + [t * W * H for t in c]
            assert signs == [fraction_sign(e), fraction_sign(a), fraction_sign(b)]
        if trial >= 4:  # the exact zeros were exercised, and the tie rule's signs of A and B
            assert sum(s[0] == 0 and s[1:] != [0, 0] for s in got) > n // 4
