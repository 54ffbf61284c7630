"""The figures of a generation protocol run from its draws: the rows averaged over the draws, the gap
closed (the share of the untrained-to-oracle gap a row closes, on each column) and the diversity
figures against the photo set's and the material sampler's."""

from __future__ import annotations

import numpy as np

from mesh2tex.evaluation.paired import oracle_check
from mesh2tex.metrics.generation import gap_closed


def average_rows(per_repeat: list[dict[str, dict[str, float]]]) -> dict[str, dict]:
    """{row: metrics} of several draws -> the mean of every metric over the draws that have it (KID
    and FID only the first), and each row's object SWD per draw (``object_swd_per_draw``)."""
    rows = {}
    for row in per_repeat[0]:
        names = dict.fromkeys(k for r in per_repeat for k in r[row])
        rows[row] = {name: float(np.mean([r[row][name] for r in per_repeat if name in r[row]])) for name in names}
        rows[row]["object_swd_per_draw"] = [r[row]["object_swd"] for r in per_repeat]
    return rows


def generation_summary(per_repeat: list[dict], diversity: dict, photo_spread: float) -> dict:
    """The rows averaged over the draws, the gaps closed and the diversity figures of a protocol run."""
    rows = average_rows(per_repeat)
    summary = {name: {k: float(np.mean(v)) for k, v in d.items()} for name, d in diversity.items()}
    ref = summary["reference_materials"]

    def closed(row: str, column: str = "object_swd", table: dict = rows) -> float:
        return gap_closed(table["untrained"][column], table[row][column], table["oracle"][column])

    return {
        "rows": rows,
        "gap_closed": closed("trained"),
        # The same figure from each draw alone: how much one draw of latents and materials moves it.
        "gap_closed_per_draw": [closed("trained", table=r) for r in per_repeat],
        "gap_closed_histogram": closed("trained", "color_hist_tv"),
        "gap_closed_whole_image_swd": closed("trained", "swd"),
        # What reproducing the training textures exactly would close: about the most a generator can learn
        # from them alone.
        "gap_closed_training_materials": closed("training_materials"),
        "gap_closed_vs_photos": closed("trained", "object_swd_vs_photos"),
        # Columns some row beats the oracle on: such a column cannot rank textures.
        "oracle_loses": oracle_check({row: {"query": metrics} for row, metrics in rows.items()}),
        "diversity": {
            **summary,
            "photo_set_spread": photo_spread,
            "trained_spread_vs_photo_set": summary["trained"]["spread"] / max(photo_spread, 1e-9),
            "trained_spread_vs_materials": summary["trained"]["spread"] / max(ref["spread"], 1e-9),
            "trained_pairwise_vs_materials": summary["trained"]["pairwise"] / max(ref["pairwise"], 1e-9),
        },
    }
