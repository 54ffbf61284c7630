"""The markdown reports of ``mesh2tex evaluate``: of ``--protocols`` (the protocols and methods by
name, one table per protocol, a row per method, seen then unseen columns, the oracle check and the
paired comparisons with the full method) and of ``--generation`` (:func:`generation_markdown`: the
rows against the fresh photo set, the gap closed and the diversity)."""

from __future__ import annotations

import math
import statistics

from mesh2tex.evaluation.compare import METRIC_TITLES, METRICS, metric_direction
from mesh2tex.evaluation.paired import flat_colour_targets, oracle_check, scored_metrics

# the generation protocol's rows and the words for its splits (mesh2tex.evaluation.generation runs them)
GENERATION_ROWS = (
    "trained",
    "untrained",
    "oracle",
    "oracle_unlit",
    "ground_truth",
    "training_materials",
    "flat_colour",
    "mean_texture",
)
SPLITS = {"held_out": "held-out", "train": "training"}  # split -> the word for its shapes

PROTOCOLS = ("unconditional", "known_pose", "unknown_pose", "other_shape")
TRANSFER_PROTOCOLS = PROTOCOLS[1:]
# The simple methods beside every transfer (none optimises anything): the ground truth itself, the
# photo's mean colour everywhere, the generator's mean texture (w_avg), and the photo back-projected.
BASELINES = ("oracle", "flat_colour", "mean_texture", "backprojection")
# Methods judged beside them only when asked for (``--baselines ...,automaton``): they fit something
# to the photo, at a transfer's cost. ``automaton``: a mesh automaton fitted to the photo, no GAN
# (:func:`mesh2tex.transfer.automaton.fit_automaton`).
EXTRA_METHODS = ("automaton",)


METHOD_TITLES = {
    "oracle": "ground-truth texture (oracle)",
    "flat_colour": "flat mean colour of the photo",
    "mean_texture": "generator's mean texture (w_avg)",
    "backprojection": "photo back-projection",
    "automaton": "automaton fitted to the photo (no GAN)",
    **{
        "full": "full method",
        "no_noc": "w/o NOC",
        "no_patches": "w/o patches",
        "no_refine": "w/o surface features (no refine)",
        "paper": "the paper's losses (no colour loss, unlit, lr 0.01)",
    },
}


def _paired_note(test: dict | None) -> str:
    """' (mean +0.47, p 0.69)': the paired difference (positive: full better) and its Wilcoxon p-value."""
    if not test:
        return ""
    p_value = test.get("p_wilcoxon")
    return f" (mean {test['mean_difference']:+.3g}" + ("" if p_value is None else f", p {p_value:.2g}") + ")"


def _fmt(value, name: str) -> str:
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        return "-" if value is None else str(value)
    if name.startswith("kid"):
        return f"{value * 100:.3g}"  # x1e2, as the paper's tables
    return f"{value:.4g}"


def _column_title(column: str) -> str:
    side, _, metric = column.partition(" ")
    arrow = " ↑" if metric_direction(column) > 0 else " ↓"
    return f"{side} {METRIC_TITLES.get(metric, metric)}{arrow}"


def transfer_table(methods: dict, order: list[str]) -> list[str]:
    """Markdown rows of one transfer protocol: a row per method, seen columns then unseen columns; the
    best value among the methods other than the oracle in bold."""
    present = set().union(*(m["query"] for m in methods.values()))
    columns = [f"{side} {metric}" for side in ("seen", "unseen") for metric in METRICS if f"{side} {metric}" in present]
    best = {}
    for column in columns:
        values = [scored_metrics(e).get(column) for n, e in methods.items() if n != "oracle"]
        values = [v for v in values if v is not None]
        if values:
            best[column] = max(values) if metric_direction(column) > 0 else min(values)
    lines = [
        "| method | " + " | ".join(_column_title(c) for c in columns) + " | seconds |",
        "| --- |" + " --- |" * (len(columns) + 1),
    ]
    for name in order:
        if name not in methods:
            continue
        scores = methods[name]["query"]
        cells = []
        for column in columns:
            text = _fmt(scores.get(column), column)
            cells.append(
                f"**{text}**"
                if name != "oracle" and scores.get(column) is not None and scores.get(column) == best.get(column)
                else text
            )
        lines.append(
            f"| {METHOD_TITLES.get(name, name)} | " + " | ".join(cells) + f" | {methods[name]['seconds']:.0f} |"
        )
    return lines


PROTOCOL_TITLES = {
    "known_pose": "exact geometry, known pose",
    "unknown_pose": "exact geometry, unknown pose (pose network)",
    "other_shape": "transfer to another shape of the category",
}


def protocols_markdown(result: dict) -> str:
    """The results as markdown: one table per protocol (rows: the oracle, the baselines, the ablations
    of the paper's Table 8 and the full method), then the paired comparisons with the full method."""
    lines = ["# mesh2tex evaluate --protocols", ""]
    s = {
        **result["settings"],
        **result["settings"].get("transfer", {}),
    }  # the transfer's settings nested, or (older runs) beside
    lines.append(
        f"World `{result['world']}`, GAN `{result['gan']}`; {result['counts']['queries']} queries; "
        f"transfer {s['latent_iters']} + {s['refine_iters']} iterations at {s['resolution']} px, "
        f"style scales {s.get('scales', '?')}, patches {s['patch_size']} px at "
        f"{s.get('patch_scales') or s.get('scales', '?')} "
        f"scales. KID is shown x1e2. KID/FID features: {result['features']}."
    )
    lines.append("")
    if "unconditional" in result["protocols"]:
        entry = result["protocols"]["unconditional"]
        metrics = {k: v for k, v in entry["metrics"].items() if metric_direction(k) != 0}
        lines += [
            "## unconditional generation (held-out shapes vs the world's photos)",
            "",
            "| " + " | ".join(metrics) + " |",
            "|" + " --- |" * len(metrics),
            "| " + " | ".join(_fmt(v, k) for k, v in metrics.items()) + " |",
            "",
        ]
    for protocol in TRANSFER_PROTOCOLS:
        if protocol in result["protocols"]:
            lines += _protocol_lines(protocol, result["protocols"][protocol], result["comparison"].get(protocol, {}), s)
    return "\n".join(lines) + "\n"


def _protocol_lines(protocol: str, entry: dict, comparisons: dict, s: dict) -> list[str]:
    """One transfer protocol's section: how it was scored, its table, the oracle check, the pose errors,
    the targets against the flat colour and the paired comparisons; ``s`` the transfer's settings."""
    methods = entry["methods"]
    lines = [
        f"## {PROTOCOL_TITLES[protocol]} (`{protocol}`)",
        "",
        "Every method rendered alike (`mesh2tex.evaluation.render_for_comparison`, lighting "
        f"`{s.get('lighting', 'photo')}`) "
        f"at the photo's view (seen) and {s.get('unseen_views', 4)} views it does not show (unseen, mean), "
        "against what the world photographs there; "
        + (
            "scored on the object pixels both the world's shape and the prepared one cover. "
            if protocol != "other_shape"
            else "each image on its own object pixels, parts matched by label. "
        )
        + f"Low-pass PSNR after a Gaussian blur of σ = {s.get('lowpass_sigma', 3.0):g} px; object SWD x1e3. "
        "Bold: the best method other than the oracle.",
        "",
    ]
    order = [*BASELINES, *EXTRA_METHODS, "paper", "no_noc", "no_patches", "no_refine", "full"]
    lines += transfer_table(methods, order)
    lost = oracle_check(methods)
    lines += [
        "",
        "The oracle wins every column."
        if not lost
        else f"**The oracle does not win: {', '.join(lost)}** (a broken metric or comparison).",
    ]
    if protocol != "known_pose":
        lines += _pose_lines(entry["queries"])
    lines += _flat_colour_lines(methods)
    for name, c in comparisons.items():
        if name != "oracle":
            lines += ["", _comparison_line(name, c)]
    return lines + [""]


def _pose_lines(queries: list[dict]) -> list[str]:
    """The mean pose errors of a protocol whose pose was found (none without queries), and the azimuth
    error up to the photographed shapes' own symmetries where the run measured it."""
    errors = [q["azimuth_error"] for q in queries]
    if not errors:
        return []
    searched = [q["network_azimuth_error"] for q in queries if "network_azimuth_error" in q]
    how = "Pose network + silhouette search" if searched else "Pose network"
    line = (
        f"{how}: mean azimuth error {sum(errors) / len(errors):.1f} deg, "
        f"mean elevation error {sum(q['elevation_error'] for q in queries) / len(errors):.1f} deg"
    )
    if searched:
        line += f" (the network's bins alone: mean azimuth error {sum(searched) / len(searched):.1f} deg)"
    line += "."
    symmetric = [q["symmetric_azimuth_error"] for q in queries if "symmetric_azimuth_error" in q]
    if len(symmetric) == len(errors):
        turned = sum(q["symmetries"] > 1 for q in queries)
        line += (
            f" Up to the shapes' own symmetries ({turned} of {len(errors)} photos show a shape that looks the"
            f" same turned): mean {sum(symmetric) / len(symmetric):.1f} deg, median"
            f" {statistics.median(symmetric):.1f} deg, {sum(e <= 15 for e in symmetric)} of {len(symmetric)}"
            " within 15 deg."
        )
    return ["", line]


def _flat_colour_lines(methods: dict) -> list[str]:
    """The full method against the flat colour of the photo (:func:`flat_colour_targets`), when measured."""
    targets = flat_colour_targets(methods)
    if not targets:
        return []
    parts = []
    for side in ("seen", "unseen"):
        if f"{side} part_delta_e ratio" in targets:
            below = targets.get(f"{side} part_delta_e below")
            parts.append(
                f"{side} per-part ΔE {targets[f'{side} part_delta_e ratio']:.2f} of the flat colour's"
                + (f", lower on {below[0]} of {below[1]} queries" if below else "")
            )
    if "seen lowpass_psnr above" in targets:
        w, n = targets["seen lowpass_psnr above"]
        parts.append(f"seen low-pass PSNR higher on {w} of {n}")
    return ["", "Full method against the flat colour: " + "; ".join(parts) + "."]


def _comparison_line(name: str, c: dict) -> str:
    """The paired comparison of the full method with method ``name``: columns won, and wins per query."""
    lost = [m for m, better in c["full_better"].items() if not better]
    return (
        f"Full method better than {METHOD_TITLES.get(name, name)} on {c['wins']} of {c['metrics']} columns"
        + (f", {c['ties']} tied" if c["ties"] else "")
        + (f" (not better on: {', '.join(lost)})." if lost else ".")
        + (
            ""
            if not c.get("query_wins")
            else " Per query, full better on "
            + ", ".join(
                f"{m} in {w} of {n}" + _paired_note(c.get("query_tests", {}).get(m))
                for m, (w, n) in c["query_wins"].items()
            )
            + "."
        )
    )


GENERATION_ROW_LABELS = {
    "oracle": "oracle (world's sampler, a draw per view)",
    "oracle_unlit": "oracle, unlit",
    "ground_truth": "each shape's own ground truth",
    "training_materials": "the training shapes' materials (a generator that reproduced them)",
    "flat_colour": "flat colour (the photo set's mean, baseline)",
    "mean_texture": "generator's mean texture (w_avg, baseline)",
}


def label_of(row: str) -> str:
    """A row's name in the markdown table."""
    return GENERATION_ROW_LABELS.get(row, row)


def generation_markdown(result: dict) -> str:
    """The rows and the diversity of a :func:`run_generation_protocol` result as markdown."""
    rows = result["rows"]
    fresh = "object_swd_vs_photos" in rows["trained"]  # False for results from before the fresh photo set
    names = (
        ["object_swd", "swd"]
        + [k for k in rows["trained"] if k.startswith(("kid", "fid")) and not k.endswith("_std")]
        + ["color_hist_tv"]
        + (["object_swd_vs_photos"] if fresh else [])
    )
    lighting = (
        "the generator's rows lit by each view's light, as the oracle"
        if result.get("generator_lit")
        else "the generator's rows unlit, as it was trained"
    )
    draws = result.get("settings", {}).get("repeats", 1)
    averaged = (
        f", each the mean of {draws} draws of the latents, the oracle's materials and the fresh photo set (KID and "
        f"FID: the first draw)"
        if draws > 1
        else ""
    )
    reference = (
        "distances to a fresh photo set (the training shapes at their photos' cameras and lights, a new material of "
        f"the world's sampler on each photo){averaged}, the last column to the training photos; lower is better"
        if fresh
        else "distances to the training photos; lower is better"
    )
    lines = [
        f"Generation protocol on {len(result['shapes'])} {SPLITS[result.get('split', 'held_out')]} shapes at "
        f"{result['resolution']} px "
        f"(checkpoint iteration {result['iteration']}; {lighting}); {reference}.",
        "",
        "| row | " + " | ".join(names) + " |",
        "| --- |" + " --- |" * len(names),
    ]
    for row in GENERATION_ROWS:
        if row not in rows:  # results from before the baseline rows
            continue
        values = [rows[row].get(n, float("nan")) for n in names]
        lines.append(f"| {label_of(row)} | " + " | ".join(f"{v:.4g}" for v in values) + " |")
    for column in result.get("oracle_loses", []):
        winners = [
            f"{label_of(row)} {rows[row][column]:.4g}"
            for row in GENERATION_ROWS
            if row in rows and row != "oracle" and rows[row][column] < rows["oracle"][column]
        ]
        lines += [
            "",
            f"The oracle ({rows['oracle'][column]:.4g}) does not win `{column}`, so it does not rank textures: "
            + "; ".join(winners)
            + ".",
        ]
    lines += ["", _gap_line(result, fresh), ""] + _diversity_lines(result)
    return "\n".join(lines) + "\n"


def _share(value: float) -> str:
    return f"{value:.2f}" if math.isfinite(value) else "undefined (the oracle does not beat the untrained generator)"


def _across(value) -> str:  # None: read back from generation.json, where NaN is null
    return f"{value:.2f}" if value is not None and math.isfinite(value) else "undefined (one training shape)"


def _gap_line(result: dict, fresh: bool) -> str:
    """The gap closed on each distance, with the single draws and (``fresh``) the training materials' figure."""
    per_draw = result.get("gap_closed_per_draw", [])
    spread = f" (single draws: {', '.join(f'{v:.2f}' for v in per_draw)})" if len(per_draw) > 1 else ""
    line = (
        "Gap closed (log object SWD, untrained 0 -> oracle 1; higher is better): "
        f"**{_share(result['gap_closed'])}**{spread}; "
        f"on the colour histogram {_share(result['gap_closed_histogram'])}; on the whole-image SWD "
        f"{_share(result['gap_closed_whole_image_swd'])}"
    )
    if fresh:
        line += (
            ". Reproducing the training textures exactly would close "
            f"{_share(result['gap_closed_training_materials'])}. "
            f"Against the training photos instead (the protocol's reference before the fresh photo set; the oracle "
            f"can lose there): {_share(result['gap_closed_vs_photos'])}"
        )
    return line


def _diversity_lines(result: dict) -> list[str]:
    """The diversity table (trained, untrained and the references) and its ratios."""
    d = result["diversity"]
    return [
        "| diversity (higher is more varied) | colour spread (Delta E) | mean pairwise Delta E |",
        "| --- | --- | --- |",
        f"| trained, {result['settings']['latents']} latents per shape | {d['trained']['spread']:.2f} | "
        f"{d['trained']['pairwise']:.2f} |",
        f"| untrained | {d['untrained']['spread']:.2f} | {d['untrained']['pairwise']:.2f} |",
        f"| world's material sampler, same shapes and pose (reference) | {d['reference_materials']['spread']:.2f} | "
        f"{d['reference_materials']['pairwise']:.2f} |",
        f"| photo set, across shapes (reference) | {_across(d['photo_set_spread'])} | |",
        "",
        f"Trained diversity: colour spread {_across(d['trained_spread_vs_photo_set'])} of the photo set's, "
        f"{d['trained_spread_vs_materials']:.2f} of the material sampler's; pairwise Delta E "
        f"{d['trained_pairwise_vs_materials']:.2f} of the material sampler's.",
    ]
