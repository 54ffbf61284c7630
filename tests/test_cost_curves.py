"""The cost-curve benchmark's exponent fit, verdicts and table (no benchmark is run)."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from cost_curves import Sweep, fit_exponent, fit_sweep, table, verdict  # noqa: E402


@pytest.mark.parametrize("power", [0.0, 0.5, 1.0, 2.0])
def test_fit_recovers_the_exponent_of_an_exact_power_law(power):
    sizes = np.array([1_000, 10_000, 100_000, 1_000_000])
    assert fit_exponent(sizes, 3e-4 * sizes**power) == pytest.approx(power, abs=1e-9)


def test_fit_needs_two_distinct_sizes():
    assert np.isnan(fit_exponent([100], [1.0]))
    assert np.isnan(fit_exponent([100, 100], [1.0, 2.0]))


def test_fit_is_least_squares_over_noisy_points():
    sizes = np.array([10.0, 100.0, 1000.0])
    # one point 10 % high: the slope moves a little, not to the two-point slope of either pair
    assert 1.0 < fit_exponent(sizes, sizes * [1.0, 1.0, 1.1]) < 1.05


@pytest.mark.parametrize(
    "exponent, kind",
    [
        (0.05, "flat"),
        (0.5, "sublinear"),
        (1.02, "linear"),
        (1.5, "superlinear"),
        (2.0, "quadratic"),
        (3.1, "worse than quadratic"),
    ],
)
def test_verdict_names_the_growth(exponent, kind):
    line = verdict(exponent, "faces")
    assert line.startswith(kind) and line.endswith(f"in faces: exponent {exponent:.2f}")


def test_table_lists_each_size_and_the_fitted_verdicts():
    sweep = Sweep("triangles", [{"triangles": t} for t in (10, 100, 1000)])
    sweep.results = [
        {
            "status": "ok",
            "params": {"triangles": t},
            "size": t,
            "seconds": 0.01 * t,
            "cores": 1.0,
            "peak_mb": 300 + t * t / 10,
            "added_mb": t * t / 10,
        }
        for t in (10, 100)
    ]
    sweep.results.append({"status": "timed out after 900 s", "params": {"triangles": 1000}})
    text = table("prepare", sweep)
    assert "prepare over triangles" in text and "timed out after 900 s" in text
    assert "time:   linear in triangles: exponent 1.00" in text
    assert "memory: quadratic in triangles: exponent 2.00" in text
    fit = fit_sweep(sweep)
    assert fit["time_exponent"] == pytest.approx(1.0) and fit["added_memory_exponent"] == pytest.approx(2.0)
