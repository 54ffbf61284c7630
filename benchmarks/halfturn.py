"""Do the NOC network or the mesh's creases tell an object's front from its back where the silhouettes do
not? For ``outside_transfer.py --noc-halfturn``: the NOC network's map of the photo against the mesh's NOC
rendered at a pose and at that pose turned half round (the same elevation), at the true pose and at the found
one. For ``--crease-halfturn``: the crease agreement (:func:`mesh2tex.transfer.crease_agreement`, which the
pose search weighs) at the true pose and at its half turn.

A pose found half a turn round (a car's front for its back) matches the photo's silhouette nearly as well
as the right one; if the NOC network's map matched the right pose's NOC better, it could judge between the
two. The summary counts, per variant: the photos whose true pose the NOC map matches better than its half
turn; of the poses found half a turn round, those the NOC map would turn back; of the poses found right,
those it would turn round wrongly. Then the photos whose true pose the creases score above its half turn,
and for every run the poses found half a turn round and those the search's own crease check turned.
"""

from __future__ import annotations

import numpy as np

from mesh2tex.transfer import crease_agreement, normals_at_pose, predict_noc, view_at_pose


def halfturn_errors(noc_checkpoint, photo, shape, found, true_azimuth: float, distance, fov, cfg, device) -> dict:
    """The mean L1 distance (summed over x, y, z) between the NOC network's map of ``photo`` and the mesh's NOC
    at the true azimuth, at it turned by 180 degrees, at the ``found`` pose and at that turned, each at the
    found elevation, over the pixels both the photo's mask and the render cover."""
    noc = predict_noc(noc_checkpoint, photo, device)

    def error(azimuth: float) -> float:
        view = view_at_pose(shape, azimuth % 360.0, found.elevation, distance, fov, cfg)
        both = (photo.mask[0, 0] > 0.5) & (view.mask[0, 0] > 0.5)
        return float((noc - view.noc).abs().sum(-1)[both].mean()) if bool(both.any()) else float("nan")

    return {
        "noc_true": error(true_azimuth),
        "noc_true_turned": error(true_azimuth + 180.0),
        "noc_found": error(found.azimuth),
        "noc_found_turned": error(found.azimuth + 180.0),
    }


def crease_halfturn(photo, shape, true_azimuth: float, elevation: float, distance, fov, cfg) -> dict:
    """The crease agreement of ``photo`` with the mesh at the true azimuth and at it turned by 180 degrees,
    both at ``elevation``."""
    return {
        f"creases_true{turn}": crease_agreement(
            photo, *normals_at_pose(shape, (true_azimuth + add) % 360.0, elevation, distance, fov, cfg)
        )
        for turn, add in (("", 0.0), ("_turned", 180.0))
    }


def print_halfturn(rows: list[dict], variants: list[str]) -> None:
    """The summary of the module docstring, one line per variant (a pose more than 150 degrees off, up to
    the mesh's symmetries, counts as found half a turn round; one within 30 degrees as found right)."""
    for variant in variants:
        chosen = [r for r in rows if r["variant"] == variant and "noc_true" in r]
        if not chosen:
            continue
        truth = sum(r["noc_true"] < r["noc_true_turned"] for r in chosen)
        off = [r for r in chosen if r["pose_error"] > 150]
        right = [r for r in chosen if r["pose_error"] <= 30]
        back = sum(r["noc_found_turned"] < r["noc_found"] for r in off)
        wrong = sum(r["noc_found_turned"] < r["noc_found"] for r in right)
        gap = np.median([abs(r["noc_true"] - r["noc_true_turned"]) for r in chosen])
        print(
            f"NOC half turn, {variant}: the true pose nearer than its half turn on {truth} of {len(chosen)} "
            f"(median gap {gap:.3f}); found half a turn round {len(off)}, the NOC map would turn back {back}; "
            f"found right {len(right)}, it would turn round {wrong}"
        )
    for variant in variants:
        chosen = [r for r in rows if r["variant"] == variant and "creases_true" in r]
        if chosen:
            truth = sum(r["creases_true"] > r["creases_true_turned"] for r in chosen)
            print(f"creases, {variant}: the true pose above its half turn on {truth} of {len(chosen)}")
    for variant in variants:
        chosen = [r for r in rows if r["variant"] == variant and "turned" in r]
        if chosen:
            turned = [r for r in chosen if r["turned"]]
            print(
                f"half turns, {variant}: found half a turn round {sum(r['pose_error'] > 150 for r in chosen)} of "
                f"{len(chosen)}; the search's creases turned {len(turned)} poses, "
                f"{sum(r['pose_error'] <= 30 for r in turned)} of them to within 30 degrees"
            )
