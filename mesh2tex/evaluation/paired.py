"""Methods compared query by query: mean scores, the full method against every other method (wins,
paired differences, Wilcoxon signed-rank tests), the oracle check and the flat-colour targets.

A method's entry is ``{"per_query": [rows], "query": mean scores, "seconds": s}``; a row holds
``"query"`` (its name) and score columns named ``'<seen|unseen> <metric>'``
(:data:`mesh2tex.evaluation.METRICS`); :func:`mesh2tex.evaluation.metric_direction` says which way is better.
"""

from __future__ import annotations

import math

from scipy.stats import wilcoxon

from mesh2tex.evaluation.compare import metric_direction


def mean_scores(rows: list[dict]) -> dict[str, float]:
    """Mean over the rows (queries) of every score column ('seen ...', 'unseen ...'), NaNs skipped."""
    columns = [k for k in (rows[0] if rows else {}) if k.startswith(("seen ", "unseen "))]
    means = {}
    for column in columns:
        values = [
            r[column] for r in rows if column in r and isinstance(r[column], (int, float)) and not math.isnan(r[column])
        ]
        if values:
            means[column] = sum(values) / len(values)
    return means


def scored_metrics(entry: dict) -> dict[str, float]:
    """{column: mean value} of one method's scores that rank methods (finite values only)."""
    return {
        name: float(value)
        for name, value in entry.get("query", {}).items()
        if metric_direction(name) != 0 and isinstance(value, (int, float)) and math.isfinite(value)
    }


def compare_to_full(methods: dict) -> dict:
    """For every other method (ablation or baseline): per column whether the full method's mean is
    better, the count of wins, and the paired view of the same queries (``query_wins``: [full better,
    queries]; ``query_tests``: mean difference, Wilcoxon p)."""
    if "full" not in methods:
        return {}
    full = scored_metrics(methods["full"])
    full_rows = methods["full"].get("per_query", [])
    comparison = {}
    for name, entry in methods.items():
        if name == "full":
            continue
        other = scored_metrics(entry)
        other_rows = entry.get("per_query", [])
        margin = {m: (full[m] - other[m]) * metric_direction(m) for m in full if m in other}
        comparison[name] = {
            "full_better": {m: d > 0 for m, d in margin.items()},
            "wins": sum(d > 0 for d in margin.values()),
            "ties": sum(d == 0 for d in margin.values()),
            "metrics": len(margin),
            "query_wins": paired_query_wins(full_rows, other_rows),
            "query_tests": paired_query_tests(full_rows, other_rows),
        }
    return comparison


def paired_query_differences(full_rows: list[dict], other_rows: list[dict]) -> dict[str, list[float]]:
    """Per score column, the differences full - other over the queries both ran, signed so that a
    positive value means the full method is better (for lower-is-better columns: other - full)."""
    others = {row["query"]: row for row in other_rows}
    differences: dict[str, list[float]] = {}
    for row in full_rows:
        other = others.get(row["query"])
        if other is None:
            continue
        for metric, value in row.items():
            direction = metric_direction(metric) if isinstance(value, (int, float)) else 0
            if direction and metric in other and math.isfinite(value) and math.isfinite(other[metric]):
                differences.setdefault(metric, []).append((value - other[metric]) * direction)
    return differences


def paired_query_wins(full_rows: list[dict], other_rows: list[dict]) -> dict[str, list[int]]:
    """Per metric, [queries where the full method is strictly better, queries compared]: the paired view
    of the same queries, less sensitive than a mean to one query's large margin."""
    return {
        metric: [sum(d > 0 for d in values), len(values)]
        for metric, values in paired_query_differences(full_rows, other_rows).items()
    }


def paired_query_tests(full_rows: list[dict], other_rows: list[dict]) -> dict[str, dict]:
    """Per metric: the mean paired difference (positive: the full method is better) and the two-sided
    p-value of the Wilcoxon signed-rank test of the differences (exact for small, untied samples).

    The p-value says how often differences at least this one-sided would arise if neither method were
    better on such queries: with 6 queries it cannot go below 0.031, so a table of 6 queries can
    show a trend but not settle a comparison. ``p_wilcoxon`` is None when every difference is 0 or
    fewer than 2 queries were compared.
    """
    tests = {}
    for metric, values in paired_query_differences(full_rows, other_rows).items():
        p_value = None
        if len(values) >= 2 and any(v != 0 for v in values):
            p_value = float(wilcoxon(values).pvalue)
        tests[metric] = {"mean_difference": sum(values) / len(values), "p_wilcoxon": p_value, "pairs": len(values)}
    return tests


def oracle_check(methods: dict) -> list[str]:
    """The columns where the ground truth (``oracle``) does not score at least as well as every other
    method: each one is a broken metric or comparison. Empty when it wins everywhere."""
    if "oracle" not in methods:
        return []
    oracle = scored_metrics(methods["oracle"])
    lost = []
    for column, value in oracle.items():
        others = [scored_metrics(e).get(column) for n, e in methods.items() if n != "oracle"]
        others = [v for v in others if v is not None]
        if others and any((v - value) * metric_direction(column) > 0 for v in others):
            lost.append(column)
    return lost


def flat_colour_targets(methods: dict, method: str = "full") -> dict:
    """How ``method`` does against the flat mean colour, query by query (the issue's targets): the
    ratio of mean per-part ΔE (seen and unseen), the share of queries with a lower ΔE, and the share
    with a higher low-pass PSNR (seen)."""
    if method not in methods or "flat_colour" not in methods:
        return {}
    mine, flat = methods[method], methods["flat_colour"]
    wins = paired_query_wins(mine["per_query"], flat["per_query"])
    out = {}
    for side in ("seen", "unseen"):
        column = f"{side} part_delta_e"
        if column in mine["query"] and column in flat["query"] and flat["query"][column] > 0:
            out[f"{side} part_delta_e ratio"] = mine["query"][column] / flat["query"][column]
            if column in wins:
                out[f"{side} part_delta_e below"] = wins[column]
    if "seen lowpass_psnr" in wins:
        out["seen lowpass_psnr above"] = wins["seen lowpass_psnr"]
    return out
