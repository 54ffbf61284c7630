"""Chair families built around their seat (varied world): office chairs on a star base, upholstered
armchairs and sofas, moulded shells, stools (a seat alone).

Design functions ``(builder, rng) -> params`` as :mod:`mesh2tex.synthetic.chair_families` describes them.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mesh2tex.synthetic.chair_frames import post_z
from mesh2tex.synthetic.solids import box, rod
from mesh2tex.synthetic.sweeps import (
    arc_points,
    band,
    bezier,
    curved_panel,
    cushion,
    loft,
    place_rings,
    resample,
    rounded_path,
    superellipse,
    transport_frames,
    tube,
)


def _star_base(builder, rng, hub_y: float, spokes: int = 5) -> float:
    """An office chair's star base with casters; returns its reach (metres from the column)."""
    u = rng.uniform
    reach, phase = u(0.29, 0.35), u(0.0, 360.0 / spokes)
    builder.add("base", rod((0, hub_y - 0.04, 0), (0, hub_y + 0.04, 0), u(0.035, 0.05), segments=20))
    for k in range(spokes):
        a = math.radians(phase + 360.0 * k / spokes)
        d = np.array([math.sin(a), 0.0, math.cos(a)])
        points = bezier([(0, hub_y, 0), d * reach * 0.5 + [0, hub_y, 0], d * reach + [0, 0.075, 0]], 14)
        builder.add("base", tube(points, np.linspace(0.024, 0.014, len(points)), segments=10))
        tip = d * reach
        builder.add("base", rod(tip + [0, 0.045, 0], tip + [0, 0.085, 0], 0.012, segments=10))
        builder.add("base", cushion((0.05, 0.05, 0.045), tip + [0, 0.03, 0], 2.5, 2.2, segments=14, layers=6))
    return reach


def office(builder, rng) -> dict[str, Any]:
    """Office swivel chairs: star base on casters, gas column, cushioned seat, curved back on a support, T-arms."""
    u = rng.uniform
    width, depth, height, thick = u(0.46, 0.52), u(0.44, 0.50), u(0.42, 0.53), u(0.07, 0.11)
    reach = _star_base(builder, rng, 0.11)
    under = height - thick
    builder.add("leg", rod((0, 0.1, 0), (0, under - 0.02, 0), u(0.014, 0.02), segments=16))
    builder.add("leg", rod((0, 0.1, 0), (0, 0.1 + u(0.1, 0.2), 0), u(0.026, 0.034), segments=16))
    builder.add("leg", box((0.2, 0.05, 0.2), (0, under - 0.01, 0)))
    builder.add("seat", cushion((width, thick, depth), (0, height - thick / 2, 0), u(3.5, 7.0), u(2.5, 4.0)))
    back_height, back_thick, bend = u(0.42, 0.68), u(0.045, 0.08), u(0.02, 0.07)
    recline, gap = u(6.0, 16.0), u(0.04, 0.12)
    z_sides = -depth / 2 - u(0.0, 0.03)
    builder.add(
        "back",
        curved_panel(
            width * u(0.85, 1.0),
            back_height,
            back_thick,
            bend,
            (0, height + gap, z_sides),
            recline,
            lumbar=u(0.0, 0.03),
            top_round=u(3, 10),
        ),
    )
    support_r = min(0.018, back_thick * 0.35)
    end_y = height + gap + 0.1
    end_z = post_z(z_sides, recline, 0.1) - bend - back_thick / 2
    points = bezier(
        [
            (0, under - 0.01, -0.05),
            (0, under - 0.02, -depth / 2 - 0.05),
            (0, height + gap, end_z - 0.01),
            (0, end_y, end_z),
        ],
        20,
    )
    builder.add("back", tube(resample(points, 0.02), support_r))
    arms = bool(rng.random() < 0.6)
    if arms:
        arm_y = height + u(0.17, 0.24)
        for sx in (-1, 1):
            x = sx * (width / 2 + 0.03)
            points = bezier(
                [(sx * 0.15, height - thick * 0.6, -0.05), (x, height - thick * 0.6, -0.05), (x, arm_y, -0.05)], 16
            )
            builder.add("arm", tube(resample(points, 0.015), 0.015))
            builder.add(
                "arm", cushion((0.075, 0.035, u(0.22, 0.28)), (x, arm_y, -0.03), 5.0, 3.0, segments=20, layers=6)
            )
    return {
        "family": "office",
        "arms": arms,
        "width": round(width, 3),
        "depth": round(depth, 3),
        "seat_height": round(height, 3),
        "back_height": round(back_height, 3),
        "base_reach": round(reach, 3),
    }


def _upholstered(builder, rng, seats: int) -> dict[str, Any]:
    """Club armchairs (one seat) and sofas (two or three): plinth, seat cushions, back, padded or rolled arms, feet."""
    u = rng.uniform
    seat_width = u(0.5, 0.6) if seats == 1 else u(0.55, 0.7)
    arm_w, depth, height = u(0.12, 0.24), u(0.78, 0.95), u(0.40, 0.46)
    total = seats * seat_width + 2 * arm_w
    top, arm_y = u(0.70, 0.88), u(0.55, 0.66)
    feet = u(0.04, 0.14) if rng.random() < 0.75 else 0.0
    seat_thick = u(0.1, 0.16)
    deck = height - seat_thick
    tub = seats == 1 and rng.random() < 0.35
    back_thick = u(0.14, 0.22)
    builder.add(
        "seat", cushion((total - 0.04, deck + 0.02 - feet, depth - 0.03), (0, (deck + 0.02 + feet) / 2, 0), 10.0, 8.0)
    )
    inner = total - 2 * arm_w
    for k in range(seats):
        x = -inner / 2 + inner * (k + 0.5) / seats
        jog = 0.005 * (k % 2)  # neighbours differ a little: equal rounded faces crossing leave slivers
        builder.add(
            "seat",
            cushion(
                (inner / seats + 0.02, seat_thick + 0.02 - jog, depth - back_thick - 0.02 - 2 * jog),
                (x, deck + seat_thick / 2, (back_thick + 0.02) / 2 + jog),
                u(3.5, 6.0),
                u(2.2, 3.0),
            ),
        )
    if tub:  # a band swept around the seat: arms low at the front, the back high behind
        _tub_band(builder, total, arm_w, depth, arm_y, top, feet)
        arms = "tub"
    else:
        rolled = _back_and_arms(
            builder, rng, seats, total, inner, arm_w, depth, height, deck, top, arm_y, feet, back_thick
        )
        arms = "rolled" if rolled else "padded"
    _feet(builder, rng, seats, total, depth, feet)
    return {
        "family": "armchair" if seats == 1 else "sofa",
        "seats": seats,
        "arms": arms,
        "width": round(total, 3),
        "depth": round(depth, 3),
        "seat_height": round(height, 3),
        "back_top": round(top, 3),
    }


def _feet(builder, rng, seats: int, total: float, depth: float, feet: float) -> None:
    """Bun or peg feet under the plinth (none when feet is 0), a middle pair under three seats."""
    u = rng.uniform
    if feet > 0:
        bun = rng.random() < 0.4
        xs, zs = total / 2 - 0.06, depth / 2 - 0.06
        for x in np.linspace(-xs, xs, 2 if seats < 3 else 3):
            for z in (-zs, zs):
                if bun:
                    builder.add(
                        "leg",
                        cushion((0.07, feet + 0.04, 0.07), (x, (feet + 0.04) / 2, z), 2.2, 2.2, segments=16, layers=6),
                    )
                else:
                    builder.add("leg", rod((x, 0.0, z), (x, feet + 0.02, z), u(0.012, 0.02), 0.025, segments=12))


def _back_and_arms(
    builder,
    rng,
    seats: int,
    total: float,
    inner: float,
    arm_w: float,
    depth: float,
    height: float,
    deck: float,
    top: float,
    arm_y: float,
    feet: float,
    back_thick: float,
) -> bool:
    """A reclined back block (with loose back cushions on half of them) and padded or rolled arms; whether rolled."""
    u = rng.uniform
    recline = u(0.0, 12.0)
    block = cushion((inner + 0.04, top - deck + 0.05, back_thick), (0, 0, 0), 8.0, 5.0)
    builder.add(
        "back",
        block.rotate((-recline, 0.0, 0.0)).translate(
            (0.0, (top + deck - 0.05) / 2, -depth / 2 + back_thick / 2 + 0.02)
        ),
    )
    if rng.random() < 0.5:
        cushion_thick = u(0.1, 0.18)
        for k in range(seats):
            x = -inner / 2 + inner * (k + 0.5) / seats
            jog = 0.005 * (k % 2)
            pad = cushion((inner / seats, (top - height) * 0.9 - 2 * jog, cushion_thick - jog), (0, 0, 0), 4.0, 2.5)
            builder.add(
                "back",
                pad.rotate((-recline - 6.0, 0.0, 0.0)).translate(
                    (x, height + (top - height) * 0.45 + jog, -depth / 2 + back_thick + cushion_thick / 2 - 0.02)
                ),
            )
    rolled = bool(rng.random() < 0.4)
    for sx in (-1, 1):
        x = sx * (total / 2 - arm_w / 2)
        arm_top = arm_y - (arm_w * 0.45 if rolled else 0.0)
        builder.add("arm", cushion((arm_w, arm_top - feet, depth), (x, (arm_top + feet) / 2, 0), 10.0, 6.0))
        if rolled:
            r = arm_w * 0.55
            roll = np.array(
                [(sx * (total / 2 - r * 0.9), arm_y - r, z) for z in np.linspace(-depth / 2 + 0.04, depth / 2, 12)]
            )
            builder.add("arm", tube(roll, r, segments=20))
    return rolled


def _tub_band(builder, total: float, arm_w: float, depth: float, arm_y: float, top: float, feet: float) -> None:
    """A tub chair's arms and back as one band swept around the seat: low at the front, high behind."""
    plan = bezier(
        [
            (-total / 2 + arm_w / 2, 0, depth / 2 - 0.02),
            (-total / 2 + arm_w / 2, 0, -depth * 0.9),
            (total / 2 - arm_w / 2, 0, -depth * 0.9),
            (total / 2 - arm_w / 2, 0, depth / 2 - 0.02),
        ],
        40,
    )
    plan = resample(plan, 0.035)
    tangents = transport_frames(plan)[0]
    across = np.cross(tangents, [0.0, 1.0, 0.0])
    s = np.linspace(-1, 1, len(plan))
    heights = arm_y + (top - arm_y) * np.clip(1.6 * (1 - s**2), 0, 1)
    profiles = [
        np.column_stack([prof[:, 0], prof[:, 1] * (h - feet - 0.02) / 2 + (h + feet + 0.02) / 2])
        for prof, h in zip([superellipse(arm_w / 2, 1.0, 6.0, 24)] * len(plan), heights)
    ]
    rings = place_rings(np.stack(profiles), plan * [1, 0, 1], across, [0, 1.0, 0])
    k1, k2 = len(plan) // 4, len(plan) - 1 - len(plan) // 4
    builder.add("arm", loft(rings[: k1 + 1]))
    builder.add("back", loft(rings[k1 : k2 + 1]))
    builder.add("arm", loft(rings[k2:]))


def armchair(builder, rng) -> dict[str, Any]:
    return _upholstered(builder, rng, 1)


def sofa(builder, rng) -> dict[str, Any]:
    return _upholstered(builder, rng, int(rng.choice([2, 3])))


def shell(builder, rng) -> dict[str, Any]:
    """Shell chairs: one curved moulded seat-and-back on dowel legs, a wire frame, a sled or a pedestal."""
    u = rng.uniform
    width, depth, height = u(0.46, 0.56), u(0.42, 0.50), u(0.42, 0.46)
    back_height, recline, thick = u(0.34, 0.44), u(8.0, 18.0), u(0.012, 0.02)
    dish, armed = u(0.03, 0.07), bool(rng.random() < 0.3)
    lean = math.tan(math.radians(recline))
    curve = bezier(
        [
            (0, height - 0.03, depth / 2 + 0.01),
            (0, height + 0.005, depth / 2 - 0.12),
            (0, height - 0.04, -depth / 2 + 0.02),
            (0, height + back_height * 0.4, -depth / 2 - 0.05),
            (0, height + back_height, -depth / 2 - 0.05 - lean * back_height),
        ],
        60,
    )
    curve = resample(curve, 0.025)
    tangents = transport_frames(curve)[0]
    up = np.cross([1.0, 0, 0], tangents)
    s = np.linspace(0.0, 1.0, len(curve))
    widths = width * (1 - 0.12 * np.exp(-(((s - 0.55) / 0.12) ** 2)))
    dishes = dish + (u(0.1, 0.16) if armed else 0.0) * np.exp(-(((s - 0.6) / 0.18) ** 2))
    rings = place_rings(np.stack([band(w, thick, d) for w, d in zip(widths, dishes)]), curve, [1.0, 0, 0], up)
    split = int(np.argmax(np.abs(tangents[:, 1]) > np.abs(tangents[:, 2])))
    builder.add("seat", loft(rings[: split + 1]))
    builder.add("back", loft(rings[split:]))
    pan = np.flatnonzero(
        (curve[:, 2] < depth / 2 - 0.06) & (curve[:, 2] > -depth / 2 + 0.08) & (np.arange(len(curve)) < split)
    )
    half = 0.12
    mount = []
    for k in pan:
        uu = np.linspace(-half, half, 10)
        edge = dishes[k] * (2 * uu / widths[k]) ** 2 - thick / 2
        mount.append(
            np.concatenate([np.column_stack([uu, edge]), np.column_stack([uu[::-1], np.full(10, -thick - 0.03)])])
        )
    builder.add("leg", loft(place_rings(np.stack(mount), curve[pan], [1.0, 0, 0], up[pan])))
    anchors = curve[pan] - up[pan] * (thick + 0.015)
    front, rear = anchors[-1], anchors[0]  # the curve runs from the front lip backwards
    front, rear = (front, rear) if front[2] > rear[2] else (rear, front)
    base = _shell_base(builder, rng, width, depth, half, anchors, front, rear)
    return {
        "family": "shell",
        "base": base,
        "armed": armed,
        "width": round(width, 3),
        "depth": round(depth, 3),
        "seat_height": round(height, 3),
    }


def _shell_base(
    builder, rng, width: float, depth: float, half: float, anchors: np.ndarray, front: np.ndarray, rear: np.ndarray
) -> str:
    """The shell's base, fixed under its seat pan (anchors (K, 3), the front and rear ones): dowel or wire legs, a sled
    or a pedestal; its kind."""
    u = rng.uniform
    base = str(rng.choice(["dowel", "wire", "sled", "pedestal"]))
    if base in ("dowel", "wire"):
        r = u(0.014, 0.02) if base == "dowel" else u(0.006, 0.009)
        feet = []
        for top, sz in ((front, 1), (rear, -1)):
            for sx in (-1, 1):
                foot = (sx * width * 0.42, 0.0, sz * depth * 0.45)
                builder.add("leg", rod(foot, (sx * half * 0.7, top[1], top[2]), r, r * 1.1, segments=12))
                feet.append(np.array(foot))
        if base == "wire":  # a rectangle of stays at a third of the height joins the four legs
            t = 0.3
            mids = [
                f + t * (np.array([np.sign(f[0]) * half * 0.7, top[1], top[2]]) - f)
                for f, top in zip(feet, (front, front, rear, rear))
            ]
            for a, b in ((0, 1), (2, 3), (0, 2), (1, 3), (0, 3), (1, 2)):
                builder.add("leg", rod(mids[a], mids[b], r * 0.8, segments=8))
    elif base == "sled":
        r = u(0.008, 0.012)
        for sx in (-1, 1):
            x = sx * width * 0.4
            outline = np.array(
                [
                    (sx * half * 0.7, front[1], front[2]),
                    (x, front[1] - 0.05, front[2] + 0.02),
                    (x, r, depth * 0.45),
                    (x, r, -depth * 0.45),
                    (x, rear[1] - 0.05, rear[2] - 0.02),
                    (sx * half * 0.7, rear[1], rear[2]),
                ]
            )
            builder.add("leg", tube(rounded_path(outline, 0.05), r, segments=10))
    else:
        centre = anchors[len(anchors) // 2]
        builder.add("leg", rod((0, 0.02, centre[2]), (0, centre[1], centre[2]), u(0.02, 0.03), segments=16))
        base_r = u(0.2, 0.26)
        outline = superellipse(base_r, base_r, 2.0, 32)
        disc = np.stack(
            [
                np.column_stack([outline[:, 0] * k, np.full(32, y), outline[:, 1] * k + centre[2]])
                for k, y in ((1, 0.0), (1, 0.012), (0.25, 0.045))
            ]
        )
        builder.add("base", loft(disc))
    return base


def stool(builder, rng) -> dict[str, Any]:
    """Stools: low, counter or bar height; round or square seat; splayed legs with a foot ring, or a column on a
    disc."""
    u = rng.uniform
    height, thick = float(rng.choice([u(0.44, 0.50), u(0.60, 0.66), u(0.72, 0.78)])), u(0.03, 0.06)
    round_seat = bool(rng.random() < 0.65)
    size = u(0.32, 0.42)
    if round_seat:
        outline = superellipse(size / 2, size / 2, 2.0, 32)
    else:
        outline = superellipse(size / 2, size / 2, u(4.0, 10.0), 32)
    rings = np.stack(
        [np.column_stack([outline[:, 0], np.full(32, y), outline[:, 1]]) for y in (height - thick, height)]
    )
    builder.add("seat", loft(rings))
    style = str(rng.choice(["legs", "legs", "column"]))
    ring_y = height * u(0.28, 0.4)
    if style == "legs":
        count = int(rng.choice([3, 4])) if round_seat else 4
        top_r, foot_r, radius = size * 0.32, size * u(0.5, 0.7), u(0.012, 0.022)
        phase = u(0, 360) if round_seat else 45.0
        for k in range(count):
            a = math.radians(phase + 360.0 * k / count)
            d = np.array([math.sin(a), 0.0, math.cos(a)])
            builder.add("leg", rod(d * foot_r, d * top_r + [0, height - thick + 0.01, 0], radius, segments=12))
        if height > 0.55 or rng.random() < 0.4:
            r = foot_r + (top_r - foot_r) * ring_y / (height - thick + 0.01)
            builder.add(
                "leg",
                tube(arc_points((0, ring_y, 0), r, 0, 360, 41, "xz")[:-1], radius * 0.8, segments=10, closed=True),
            )
    else:
        builder.add("leg", rod((0, 0.02, 0), (0, height - thick + 0.01, 0), u(0.02, 0.035), segments=16))
        base_r = u(0.18, 0.24)
        disc = np.stack(
            [
                np.column_stack([superellipse(r, r, 2.0, 32)[:, 0], np.full(32, y), superellipse(r, r, 2.0, 32)[:, 1]])
                for r, y in ((base_r, 0.0), (base_r, 0.015), (base_r * 0.3, 0.05))
            ]
        )
        builder.add("base", loft(disc))
        if height > 0.55:
            r = u(0.14, 0.18)
            builder.add(
                "leg", tube(arc_points((0, ring_y, 0), r, 0, 360, 41, "xz")[:-1], 0.01, segments=10, closed=True)
            )
            for a in (0, 120, 240):
                d = np.array([math.sin(math.radians(a)), 0.0, math.cos(math.radians(a))])
                builder.add("leg", rod((0, ring_y, 0), d * r + [0, ring_y, 0], 0.009, segments=8))
    back = bool(height > 0.55 and rng.random() < 0.3)
    if back:
        z = -size / 2 + 0.03
        for sx in (-1, 1):
            builder.add(
                "back",
                rod((sx * size * 0.25, height - 0.01, z), (sx * size * 0.25, height + 0.2, z - 0.03), 0.01, segments=8),
            )
        builder.add(
            "back",
            curved_panel(size * 0.8, u(0.08, 0.14), 0.02, 0.03, (0, height + u(0.12, 0.15), z - 0.005), 8.0, layers=4),
        )
    return {
        "family": "stool",
        "support": style,
        "round": round_seat,
        "back": back,
        "size": round(size, 3),
        "seat_height": round(height, 3),
    }
