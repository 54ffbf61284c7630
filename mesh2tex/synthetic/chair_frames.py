"""Chair families on legs and frames (varied world): four-legged, benches, rocking and folding chairs.

Design functions ``(builder, rng) -> params`` as :mod:`mesh2tex.synthetic.chair_families` describes them.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mesh2tex.synthetic.solids import box, rod, slab
from mesh2tex.synthetic.sweeps import (
    bezier,
    curved_panel,
    cushion,
    resample,
    rounded_path,
    tube,
)


def post_z(z: float, recline: float, rise: float) -> float:
    return z - math.tan(math.radians(recline)) * rise


def legs(builder, rng, width: float, depth: float, top_y: float, radius: float, rear: bool = True) -> dict:
    """Four (or only the two front) straight, tapered, maybe splayed legs under a seat; returns their layout."""
    u = rng.uniform
    inset, splay, taper = u(0.02, 0.05) + radius, u(0.0, 0.04), u(0.6, 1.0)
    square = bool(rng.random() < 0.3)
    xs, zs = width / 2 - inset, depth / 2 - inset
    for sz in (-1, 1) if rear else (1,):
        for sx in (-1, 1):
            builder.add(
                "leg",
                rod(
                    (sx * (xs + splay), 0.0, sz * (zs + splay)),
                    (sx * xs, top_y + 0.01, sz * zs),
                    radius * taper,
                    radius,
                    square=square,
                ),
            )
    return {"x": xs, "z": zs, "splay": splay}


def four_legged(builder, rng) -> dict[str, Any]:
    """Dining and side chairs: four legs, rear legs that rise into back posts, curved panel, spindle or ladder backs."""
    u = rng.uniform
    width, depth, height, thick = u(0.42, 0.52), u(0.40, 0.50), u(0.43, 0.48), u(0.02, 0.045)
    back_height, recline = u(0.38, 0.55), u(4.0, 14.0)
    upholstered = bool(rng.random() < 0.4)
    frame_top = height - (u(0.04, 0.07) if upholstered else 0.0)
    builder.add("seat", slab(width, depth, thick, u(0.005, 0.06), (0, frame_top - thick / 2, 0)))
    if upholstered:
        builder.add(
            "seat",
            cushion(
                (width - 0.02, height - frame_top + 0.015, depth - 0.02),
                (0, (height + frame_top) / 2 - 0.005, 0.0),
                6.0,
                3.0,
            ),
        )
    radius = u(0.014, 0.026)
    layout = legs(builder, rng, width, depth, frame_top - thick, radius, rear=False)
    xs, zs, splay = layout["x"], layout["z"], layout["splay"]
    rear_z = -zs
    top_z = post_z(rear_z, recline, back_height)
    for sx in (-1, 1):  # rear legs rising into the back posts
        points = bezier(
            [
                (sx * (xs + splay), 0.0, rear_z - splay - 0.02),
                (sx * xs, frame_top - thick, rear_z),
                (sx * xs, height + back_height * 0.5, post_z(rear_z, recline, back_height * 0.5)),
                (sx * xs, height + back_height, top_z),
            ],
            24,
        )
        builder.add("leg", tube(resample(points, 0.02), radius))  # the posts are the frame, like the legs
    back = _four_legged_back(builder, rng, xs, radius, height, frame_top, back_height, recline, rear_z)
    arms = _four_legged_arms(builder, rng, xs, zs, radius, height, frame_top, recline, rear_z)
    return {
        "family": "four_legged",
        "back": back,
        "arms": arms,
        "upholstered": upholstered,
        "width": round(width, 3),
        "depth": round(depth, 3),
        "seat_height": round(height, 3),
        "back_height": round(back_height, 3),
    }


def _four_legged_arms(
    builder, rng, xs: float, zs: float, radius: float, height: float, frame_top: float, recline: float, rear_z: float
) -> bool:
    """Arms on a quarter of the chairs: tubes from the back posts over the seat's sides down to its front; whether there
    are."""
    u = rng.uniform
    arms = bool(rng.random() < 0.25)
    if arms:
        arm_y = height + u(0.18, 0.25)
        for sx in (-1, 1):
            x = sx * xs
            points = bezier(
                [
                    (x, arm_y, post_z(rear_z, recline, arm_y - height)),
                    (x, arm_y + 0.04, 0.0),
                    (x, arm_y + 0.02, zs + 0.02),
                    (x, frame_top - 0.01, zs),
                ],
                24,
            )
            builder.add("arm", tube(resample(points, 0.02), radius * 0.8))
    return arms


def _four_legged_back(
    builder,
    rng,
    xs: float,
    radius: float,
    height: float,
    frame_top: float,
    back_height: float,
    recline: float,
    rear_z: float,
) -> str:
    """The back between the rear posts (at x = +-xs, z = rear_z at the seat): a panel, an upholstered panel, spindles or
    a ladder under a top rail; its kind."""
    u = rng.uniform
    back = str(rng.choice(["panel", "spindles", "ladder", "upholstered"]))
    span = 2 * xs + radius
    if back in ("panel", "upholstered"):
        panel_height = back_height * u(0.35, 0.6) if back == "panel" else back_height * u(0.6, 0.85)
        bottom_rise = back_height - panel_height - u(0.0, 0.04)
        panel_thick = u(0.015, 0.03) if back == "panel" else u(0.04, 0.07)
        builder.add(
            "back",
            curved_panel(
                span,
                panel_height,
                panel_thick,
                u(0.01, 0.06),
                (0, height + bottom_rise, post_z(rear_z, recline, bottom_rise) + panel_thick / 2),
                recline,
                top_round=u(4, 12),
            ),
        )
    else:
        rail_y = height + back_height - u(0.02, 0.06)
        rail_z = post_z(rear_z, recline, rail_y - height)
        bow = u(0.0, 0.05)
        rail = bezier([(-xs, rail_y, rail_z), (0, rail_y + u(0.0, 0.05), rail_z - 2 * bow), (xs, rail_y, rail_z)], 20)
        builder.add("back", tube(rail, radius * u(0.8, 1.2)))
        if back == "spindles":
            count = int(rng.integers(3, 8))
            for k in range(count):
                x = -xs + 2 * xs * (k + 1) / (count + 1)
                z_top = bezier([(rail_z,), (rail_z - 2 * bow,), (rail_z,)], count + 2)[k + 1, 0]
                builder.add(
                    "back", rod((x, frame_top - 0.01, rear_z + 0.005), (x, rail_y, z_top), radius * 0.45, segments=8)
                )
        else:
            for k in range(int(rng.integers(1, 4))):
                rise = (rail_y - height) * (k + 1) / 4
                builder.add(
                    "back",
                    curved_panel(
                        span,
                        u(0.04, 0.08),
                        u(0.012, 0.02),
                        bow,
                        (0, height + rise, post_z(rear_z, recline, rise) + 0.008),
                        recline,
                        layers=3,
                    ),
                )
    return back


def bench(builder, rng) -> dict[str, Any]:
    """Benches: long slab or slatted seat on legs, trestle panels or tubular sled frames; some with a back."""
    u = rng.uniform
    length, depth, height, thick = u(0.9, 1.6), u(0.30, 0.45), u(0.42, 0.48), u(0.03, 0.06)
    slats = bool(rng.random() < 0.4)
    if slats:
        count = int(rng.integers(3, 6))
        gap = u(0.008, 0.02)
        slat = (depth - gap * (count - 1)) / count
        for k in range(count):
            z = -depth / 2 + slat / 2 + k * (slat + gap)
            builder.add("seat", box((length, thick * 0.7, slat), (0, height - thick * 0.35, z)))
        for x in (-length * 0.3, 0.0, length * 0.3):
            builder.add(
                "seat", box((0.05, thick * 0.5, depth - 0.02), (x, height - thick * 0.7 - thick * 0.25 + 0.005, 0))
            )
    else:
        builder.add("seat", slab(length, depth, thick, u(0.005, 0.05), (0, height - thick / 2, 0)))
    support, under, xe = _bench_support(builder, rng, length, depth, height, thick)
    back = _bench_back(builder, rng, depth, height, under, xe)
    return {
        "family": "bench",
        "support": support,
        "slats": slats,
        "back": back,
        "length": round(length, 3),
        "depth": round(depth, 3),
        "seat_height": round(height, 3),
    }


def _bench_back(builder, rng, depth: float, height: float, under: float, xe: float) -> bool:
    """A back on a third of the benches: two posts and one to three curved rails; whether there is one."""
    u = rng.uniform
    back = bool(rng.random() < 0.35)
    if back:
        recline, back_height = u(5, 15), u(0.3, 0.45)
        z = -depth / 2 + 0.03
        for sx in (-1, 1):
            builder.add(
                "back",
                rod(
                    (sx * xe, under, z),
                    (sx * xe, height + back_height, post_z(z, recline, back_height)),
                    0.02,
                    segments=10,
                ),
            )
        for k in range(int(rng.integers(1, 4))):
            rise = back_height * (0.35 + 0.6 * k / 3)
            builder.add(
                "back",
                curved_panel(
                    2 * xe + 0.06,
                    u(0.05, 0.1),
                    0.025,
                    u(0.0, 0.03),
                    (0, height + rise, post_z(z, recline, rise) + 0.012),
                    recline,
                    layers=3,
                ),
            )
    return back


def _bench_support(builder, rng, length: float, depth: float, height: float, thick: float) -> tuple[str, float, float]:
    """The bench's support: four legs (with an H of stretchers when long), two trestle panels or tubular sleds; (its
    kind, the height the supports reach, their x)."""
    u = rng.uniform
    support = str(rng.choice(["legs", "trestle", "sled"]))
    under = height - thick / 2  # supports end inside the seat (slats float above its underside)
    inset = u(0.04, 0.15)
    xe = length / 2 - inset
    if support == "legs":
        r = u(0.015, 0.03)
        for sx in (-1, 1):
            for sz in (-1, 1):
                builder.add(
                    "leg",
                    rod(
                        (sx * (xe + 0.02), 0, sz * (depth / 2 - 0.05)),
                        (sx * xe, under + 0.01, sz * (depth / 2 - 0.06)),
                        r,
                        segments=12,
                    ),
                )
        if length > 1.2:  # an H of stretchers: one along each end, one between them
            y = u(0.1, 0.2)
            share = y / (under + 0.01)
            x, z = xe + 0.02 * (1 - share), depth / 2 - 0.05 - 0.01 * share
            for sx in (-1, 1):
                builder.add("leg", rod((sx * x, y, -z), (sx * x, y, z), r * 0.6, segments=10))
            builder.add("leg", rod((-x, y + 0.003, 0), (x, y + 0.003, 0), r * 0.6, segments=10))
    elif support == "trestle":
        panel_t = u(0.03, 0.06)
        for sx in (-1, 1):
            builder.add("leg", box((panel_t, under + 0.01, depth * u(0.75, 0.95)), (sx * xe, (under + 0.01) / 2, 0)))
        builder.add("leg", box((2 * xe, 0.04, 0.03), (0, under * u(0.3, 0.6), 0)))
    else:
        r = u(0.01, 0.016)
        zf, zb, corner = depth / 2 - 0.03, -depth / 2 + 0.03, 0.06
        for sx in (-1, 1):
            x = sx * xe
            outline = [(x, under + 0.005, zf), (x, r, zf + 0.01), (x, r, zb - 0.01), (x, under + 0.005, zb)]
            builder.add("leg", tube(rounded_path(outline, corner), r, segments=10))
    return support, under, xe


def rocking(builder, rng) -> dict[str, Any]:
    """Rocking chairs: legs standing on two curved runners, a tall spindle or panel back, usually arms."""
    u = rng.uniform
    width, depth, height, thick = u(0.45, 0.55), u(0.42, 0.50), u(0.38, 0.45), u(0.025, 0.045)
    back_height, recline = u(0.55, 0.75), u(12.0, 22.0)
    builder.add("seat", slab(width, depth, thick, u(0.01, 0.06), (0, height - thick / 2, 0)))
    r_leg, r_run = u(0.014, 0.022), u(0.014, 0.022)
    xs, zs = width / 2 - 0.03, depth / 2 - 0.04
    bow, run = u(1.0, 1.8), depth * u(1.5, 2.0)
    centre_z = -u(0.0, 0.08)
    runner_z = np.linspace(centre_z - run * 0.55, centre_z + run * 0.45, 24)
    lift = 0.02

    def runner_y(z):
        return r_run + lift + bow - np.sqrt(bow**2 - (np.asarray(z) - centre_z) ** 2)

    for sx in (-1, 1):
        x = sx * (xs + 0.01)
        builder.add(
            "leg", tube(np.column_stack([np.full(len(runner_z), x), runner_y(runner_z), runner_z]), r_run, segments=10)
        )
        builder.add(
            "leg", rod((x, runner_y(zs) + 0.3 * r_run, zs), (sx * xs, height - thick + 0.01, zs), r_leg, segments=12)
        )
        rear = bezier(
            [
                (x, runner_y(-zs) + 0.3 * r_run, -zs),
                (sx * xs, height - thick, -zs),
                (sx * xs, height + back_height, post_z(-zs, recline, back_height)),
            ],
            24,
        )
        builder.add("leg", tube(resample(rear, 0.02), r_leg))
    arms = bool(rng.random() < 0.7)
    if arms:
        arm_y = height + u(0.2, 0.26)
        for sx in (-1, 1):
            builder.add("arm", rod((sx * xs, height - 0.01, zs), (sx * xs, arm_y, zs + 0.01), r_leg * 0.8, segments=10))
            points = bezier(
                [
                    (sx * xs, arm_y, post_z(-zs, recline, arm_y - height)),
                    (sx * (xs + 0.04), arm_y + 0.02, 0.0),
                    (sx * xs, arm_y, zs + 0.06),
                ],
                20,
            )
            builder.add("arm", tube(resample(points, 0.02), u(0.015, 0.025)))
    back = _rocking_back(builder, rng, xs, zs, r_leg, height, back_height, recline)
    return {
        "family": "rocking",
        "back": back,
        "arms": arms,
        "width": round(width, 3),
        "depth": round(depth, 3),
        "seat_height": round(height, 3),
        "runner_radius": round(bow, 3),
    }


def _rocking_back(
    builder, rng, xs: float, zs: float, r_leg: float, height: float, back_height: float, recline: float
) -> str:
    """The rocking chair's back between its rear posts: spindles under a bowed top rail, or a curved panel; its kind."""
    u = rng.uniform
    rail_y = height + back_height - 0.02
    rail_z = post_z(-zs, recline, back_height - 0.02)
    back = str(rng.choice(["spindles", "spindles", "panel"]))
    if back == "spindles":
        rail = bezier([(-xs, rail_y, rail_z), (0, rail_y + u(0.02, 0.08), rail_z - 0.08), (xs, rail_y, rail_z)], 20)
        builder.add("back", tube(rail, r_leg * 1.1))
        count = int(rng.integers(4, 9))
        for k in range(count):
            x = -xs + 2 * xs * (k + 1) / (count + 1)
            t = (k + 1) / (count + 1)
            builder.add(
                "back",
                rod(
                    (x, height - 0.01, -zs + 0.005),
                    (x, rail_y + 2 * t * (1 - t) * 0.03, rail_z - 2 * t * (1 - t) * 0.16),
                    r_leg * 0.4,
                    segments=8,
                ),
            )
    else:
        bottom = back_height * u(0.1, 0.25)
        builder.add(
            "back",
            curved_panel(
                2 * xs + r_leg,
                back_height - bottom,
                0.02,
                u(0.02, 0.06),
                (0, height + bottom, post_z(-zs, recline, bottom) + 0.01),
                recline,
            ),
        )
    return back


def folding(builder, rng) -> dict[str, Any]:
    """Folding chairs: tubular legs crossed in an X on each side, one leg of each X rising into a back post."""
    u = rng.uniform
    width, depth, height = u(0.40, 0.46), u(0.38, 0.44), u(0.43, 0.47)
    thick, r = u(0.012, 0.025), u(0.009, 0.014)
    back_height, recline = u(0.32, 0.42), u(5.0, 14.0)
    xs = width / 2
    rail_y = height - thick - r * 0.5
    for sx in (-1, 1):
        x = sx * xs
        post_top = (x, height + back_height, post_z(-depth / 2, recline, back_height + thick))
        up = [(x, 0.0, depth / 2 + 0.04), (x, rail_y, -depth / 2), post_top]
        builder.add("leg", tube(rounded_path(up, 0.05), r))
        builder.add("leg", rod((x, 0.0, -depth / 2 - 0.04), (x, rail_y, depth / 2), r, segments=12))
        builder.add("leg", rod((x, rail_y, -depth / 2 - 0.01), (x, rail_y, depth / 2 + 0.01), r, segments=12))
    for z in (depth / 2 + 0.04, -depth / 2 - 0.04):
        builder.add("leg", rod((-xs, r, z), (xs, r, z), r * 0.9, segments=10))
    seat = str(rng.choice(["solid", "slats"]))
    if seat == "solid":
        builder.add("seat", slab(width + 2 * r, depth, thick, u(0.005, 0.04), (0, height - thick / 2, 0)))
    else:
        count = int(rng.integers(3, 6))
        slat = depth / count - 0.01
        for k in range(count):
            builder.add(
                "seat",
                box(
                    (width + 2 * r, thick, slat),
                    (0, height - thick / 2, -depth / 2 + slat / 2 + k * (slat + 0.01 + 0.01 / (count - 1))),
                ),
            )
    panel = back_height * u(0.3, 0.5)
    rise = back_height - panel + thick
    builder.add(
        "back",
        curved_panel(
            width + r,
            panel,
            u(0.012, 0.02),
            u(0.0, 0.04),
            (0, height + rise - thick, post_z(-depth / 2, recline, rise) + 0.006),
            recline,
            layers=5,
        ),
    )
    return {
        "family": "folding",
        "seat": seat,
        "width": round(width, 3),
        "depth": round(depth, 3),
        "seat_height": round(height, 3),
    }
