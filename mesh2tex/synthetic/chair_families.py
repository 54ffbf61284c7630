"""The chair families of the varied world (``prepare synthetic --variety real``).

Each family is a design function ``(builder, rng) -> params`` for
:func:`mesh2tex.synthetic.shapes.shape_from_design`: it adds labelled solids (seat, back, leg, arm, base)
in metres, y up, the front towards +z, the floor at y = 0, and returns its design choices with a
``family`` key. Proportions are drawn from the catalogue ranges of ``docs/synthetic.md`` ("The varied
world"): seat heights 42-48 cm for dining and shell chairs, 40-53 cm for office chairs, and so on.
Curved parts are lofts from :mod:`mesh2tex.synthetic.sweeps`: tubes along Bezier curves and arcs,
backs bent around the sitter, shells that turn from seat into back, stuffed cushions.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mesh2tex.synthetic.shapes import _chair
from mesh2tex.synthetic.solids import box, rod, slab
from mesh2tex.synthetic.sweeps import (
    arc_points, band, bezier, curved_panel, cushion, loft, place_rings, resample, rounded_path, superellipse, transport_frames, tube,
)


def _post_z(z: float, recline: float, rise: float) -> float:
    return z - math.tan(math.radians(recline)) * rise


def _legs(builder, rng, width: float, depth: float, top_y: float, radius: float, rear: bool = True) -> dict:
    """Four (or only the two front) straight, tapered, maybe splayed legs under a seat; returns their layout."""
    u = rng.uniform
    inset, splay, taper = u(0.02, 0.05) + radius, u(0.0, 0.04), u(0.6, 1.0)
    square = bool(rng.random() < 0.3)
    xs, zs = width / 2 - inset, depth / 2 - inset
    for sz in ((-1, 1) if rear else (1,)):
        for sx in (-1, 1):
            builder.add("leg", rod((sx * (xs + splay), 0.0, sz * (zs + splay)), (sx * xs, top_y + 0.01, sz * zs), radius * taper, radius, square=square))
    return {"x": xs, "z": zs, "splay": splay}


def _four_legged(builder, rng) -> dict[str, Any]:
    """Dining and side chairs: four legs, rear legs that rise into back posts, curved panel, spindle or ladder backs."""
    u = rng.uniform
    width, depth, height, thick = u(0.42, 0.52), u(0.40, 0.50), u(0.43, 0.48), u(0.02, 0.045)
    back_height, recline = u(0.38, 0.55), u(4.0, 14.0)
    upholstered = bool(rng.random() < 0.4)
    frame_top = height - (u(0.04, 0.07) if upholstered else 0.0)
    builder.add("seat", slab(width, depth, thick, u(0.005, 0.06), (0, frame_top - thick / 2, 0)))
    if upholstered:
        builder.add("seat", cushion((width - 0.02, height - frame_top + 0.015, depth - 0.02), (0, (height + frame_top) / 2 - 0.005, 0.0), 6.0, 3.0))
    radius = u(0.014, 0.026)
    layout = _legs(builder, rng, width, depth, frame_top - thick, radius, rear=False)
    xs, zs, splay = layout["x"], layout["z"], layout["splay"]
    rear_z = -zs
    top_z = _post_z(rear_z, recline, back_height)
    for sx in (-1, 1):  # rear legs rising into the back posts
        points = bezier([(sx * (xs + splay), 0.0, rear_z - splay - 0.02), (sx * xs, frame_top - thick, rear_z),
                         (sx * xs, height + back_height * 0.5, _post_z(rear_z, recline, back_height * 0.5)), (sx * xs, height + back_height, top_z)], 24)
        builder.add("leg", tube(resample(points, 0.02), radius))  # the posts are the frame, like the legs
    back = str(rng.choice(["panel", "spindles", "ladder", "upholstered"]))
    span = 2 * xs + radius
    if back in ("panel", "upholstered"):
        panel_height = back_height * u(0.35, 0.6) if back == "panel" else back_height * u(0.6, 0.85)
        bottom_rise = back_height - panel_height - u(0.0, 0.04)
        panel_thick = u(0.015, 0.03) if back == "panel" else u(0.04, 0.07)
        builder.add("back", curved_panel(span, panel_height, panel_thick, u(0.01, 0.06), (0, height + bottom_rise, _post_z(rear_z, recline, bottom_rise) + panel_thick / 2),
                                         recline, top_round=u(4, 12)))
    else:
        rail_y = height + back_height - u(0.02, 0.06)
        rail_z = _post_z(rear_z, recline, rail_y - height)
        bow = u(0.0, 0.05)
        rail = bezier([(-xs, rail_y, rail_z), (0, rail_y + u(0.0, 0.05), rail_z - 2 * bow), (xs, rail_y, rail_z)], 20)
        builder.add("back", tube(rail, radius * u(0.8, 1.2)))
        if back == "spindles":
            count = int(rng.integers(3, 8))
            for k in range(count):
                x = -xs + 2 * xs * (k + 1) / (count + 1)
                z_top = bezier([(rail_z,), (rail_z - 2 * bow,), (rail_z,)], count + 2)[k + 1, 0]
                builder.add("back", rod((x, frame_top - 0.01, rear_z + 0.005), (x, rail_y, z_top), radius * 0.45, segments=8))
        else:
            for k in range(int(rng.integers(1, 4))):
                rise = (rail_y - height) * (k + 1) / 4
                builder.add("back", curved_panel(span, u(0.04, 0.08), u(0.012, 0.02), bow, (0, height + rise, _post_z(rear_z, recline, rise) + 0.008), recline, layers=3))
    arms = bool(rng.random() < 0.25)
    if arms:
        arm_y = height + u(0.18, 0.25)
        for sx in (-1, 1):
            x = sx * xs
            points = bezier([(x, arm_y, _post_z(rear_z, recline, arm_y - height)), (x, arm_y + 0.04, 0.0),
                             (x, arm_y + 0.02, zs + 0.02), (x, frame_top - 0.01, zs)], 24)
            builder.add("arm", tube(resample(points, 0.02), radius * 0.8))
    return {"family": "four_legged", "back": back, "arms": arms, "upholstered": upholstered, "width": round(width, 3),
            "depth": round(depth, 3), "seat_height": round(height, 3), "back_height": round(back_height, 3)}


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


def _office(builder, rng) -> dict[str, Any]:
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
    builder.add("back", curved_panel(width * u(0.85, 1.0), back_height, back_thick, bend, (0, height + gap, z_sides), recline,
                                     lumbar=u(0.0, 0.03), top_round=u(3, 10)))
    support_r = min(0.018, back_thick * 0.35)
    end_y = height + gap + 0.1
    end_z = _post_z(z_sides, recline, 0.1) - bend - back_thick / 2
    points = bezier([(0, under - 0.01, -0.05), (0, under - 0.02, -depth / 2 - 0.05), (0, height + gap, end_z - 0.01), (0, end_y, end_z)], 20)
    builder.add("back", tube(resample(points, 0.02), support_r))
    arms = bool(rng.random() < 0.6)
    if arms:
        arm_y = height + u(0.17, 0.24)
        for sx in (-1, 1):
            x = sx * (width / 2 + 0.03)
            points = bezier([(sx * 0.15, height - thick * 0.6, -0.05), (x, height - thick * 0.6, -0.05), (x, arm_y, -0.05)], 16)
            builder.add("arm", tube(resample(points, 0.015), 0.015))
            builder.add("arm", cushion((0.075, 0.035, u(0.22, 0.28)), (x, arm_y, -0.03), 5.0, 3.0, segments=20, layers=6))
    return {"family": "office", "arms": arms, "width": round(width, 3), "depth": round(depth, 3), "seat_height": round(height, 3),
            "back_height": round(back_height, 3), "base_reach": round(reach, 3)}


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
    builder.add("seat", cushion((total - 0.04, deck + 0.02 - feet, depth - 0.03), (0, (deck + 0.02 + feet) / 2, 0), 10.0, 8.0))
    inner = total - 2 * arm_w
    for k in range(seats):
        x = -inner / 2 + inner * (k + 0.5) / seats
        jog = 0.005 * (k % 2)  # neighbours differ a little: equal rounded faces crossing leave slivers
        builder.add("seat", cushion((inner / seats + 0.02, seat_thick + 0.02 - jog, depth - back_thick - 0.02 - 2 * jog), (x, deck + seat_thick / 2, (back_thick + 0.02) / 2 + jog),
                                    u(3.5, 6.0), u(2.2, 3.0)))
    if tub:  # a band swept around the seat: arms low at the front, the back high behind
        plan = bezier([(-total / 2 + arm_w / 2, 0, depth / 2 - 0.02), (-total / 2 + arm_w / 2, 0, -depth * 0.9),
                       (total / 2 - arm_w / 2, 0, -depth * 0.9), (total / 2 - arm_w / 2, 0, depth / 2 - 0.02)], 40)
        plan = resample(plan, 0.035)
        tangents = transport_frames(plan)[0]
        across = np.cross(tangents, [0.0, 1.0, 0.0])
        s = np.linspace(-1, 1, len(plan))
        heights = arm_y + (top - arm_y) * np.clip(1.6 * (1 - s**2), 0, 1)
        profiles = [np.column_stack([prof[:, 0], prof[:, 1] * (h - feet - 0.02) / 2 + (h + feet + 0.02) / 2])
                    for prof, h in zip([superellipse(arm_w / 2, 1.0, 6.0, 24)] * len(plan), heights)]
        rings = place_rings(np.stack(profiles), plan * [1, 0, 1], across, [0, 1.0, 0])
        k1, k2 = len(plan) // 4, len(plan) - 1 - len(plan) // 4
        builder.add("arm", loft(rings[: k1 + 1]))
        builder.add("back", loft(rings[k1 : k2 + 1]))
        builder.add("arm", loft(rings[k2:]))
        arms = "tub"
    else:
        recline = u(0.0, 12.0)
        block = cushion((inner + 0.04, top - deck + 0.05, back_thick), (0, 0, 0), 8.0, 5.0)
        builder.add("back", block.rotate((-recline, 0.0, 0.0)).translate((0.0, (top + deck - 0.05) / 2, -depth / 2 + back_thick / 2 + 0.02)))
        if rng.random() < 0.5:
            cushion_thick = u(0.1, 0.18)
            for k in range(seats):
                x = -inner / 2 + inner * (k + 0.5) / seats
                jog = 0.005 * (k % 2)
                pad = cushion((inner / seats, (top - height) * 0.9 - 2 * jog, cushion_thick - jog), (0, 0, 0), 4.0, 2.5)
                builder.add("back", pad.rotate((-recline - 6.0, 0.0, 0.0)).translate((x, height + (top - height) * 0.45 + jog, -depth / 2 + back_thick + cushion_thick / 2 - 0.02)))
        rolled = bool(rng.random() < 0.4)
        for sx in (-1, 1):
            x = sx * (total / 2 - arm_w / 2)
            arm_top = arm_y - (arm_w * 0.45 if rolled else 0.0)
            builder.add("arm", cushion((arm_w, arm_top - feet, depth), (x, (arm_top + feet) / 2, 0), 10.0, 6.0))
            if rolled:
                r = arm_w * 0.55
                roll = np.array([(sx * (total / 2 - r * 0.9), arm_y - r, z) for z in np.linspace(-depth / 2 + 0.04, depth / 2, 12)])
                builder.add("arm", tube(roll, r, segments=20))
        arms = "rolled" if rolled else "padded"
    if feet > 0:
        bun = rng.random() < 0.4
        xs, zs = total / 2 - 0.06, depth / 2 - 0.06
        for x in np.linspace(-xs, xs, 2 if seats < 3 else 3):
            for z in (-zs, zs):
                if bun:
                    builder.add("leg", cushion((0.07, feet + 0.04, 0.07), (x, (feet + 0.04) / 2, z), 2.2, 2.2, segments=16, layers=6))
                else:
                    builder.add("leg", rod((x, 0.0, z), (x, feet + 0.02, z), u(0.012, 0.02), 0.025, segments=12))
    return {"family": "armchair" if seats == 1 else "sofa", "seats": seats, "arms": arms, "width": round(total, 3), "depth": round(depth, 3),
            "seat_height": round(height, 3), "back_top": round(top, 3)}


def _armchair(builder, rng) -> dict[str, Any]:
    return _upholstered(builder, rng, 1)


def _sofa(builder, rng) -> dict[str, Any]:
    return _upholstered(builder, rng, int(rng.choice([2, 3])))


def _stool(builder, rng) -> dict[str, Any]:
    """Stools: low, counter or bar height; round or square seat; splayed legs with a foot ring, or a column on a disc."""
    u = rng.uniform
    height, thick = float(rng.choice([u(0.44, 0.50), u(0.60, 0.66), u(0.72, 0.78)])), u(0.03, 0.06)
    round_seat = bool(rng.random() < 0.65)
    size = u(0.32, 0.42)
    if round_seat:
        outline = superellipse(size / 2, size / 2, 2.0, 32)
    else:
        outline = superellipse(size / 2, size / 2, u(4.0, 10.0), 32)
    rings = np.stack([np.column_stack([outline[:, 0], np.full(32, y), outline[:, 1]]) for y in (height - thick, height)])
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
            builder.add("leg", tube(arc_points((0, ring_y, 0), r, 0, 360, 41, "xz")[:-1], radius * 0.8, segments=10, closed=True))
    else:
        builder.add("leg", rod((0, 0.02, 0), (0, height - thick + 0.01, 0), u(0.02, 0.035), segments=16))
        base_r = u(0.18, 0.24)
        disc = np.stack([np.column_stack([superellipse(r, r, 2.0, 32)[:, 0], np.full(32, y), superellipse(r, r, 2.0, 32)[:, 1]])
                         for r, y in ((base_r, 0.0), (base_r, 0.015), (base_r * 0.3, 0.05))])
        builder.add("base", loft(disc))
        if height > 0.55:
            r = u(0.14, 0.18)
            builder.add("leg", tube(arc_points((0, ring_y, 0), r, 0, 360, 41, "xz")[:-1], 0.01, segments=10, closed=True))
            for a in (0, 120, 240):
                d = np.array([math.sin(math.radians(a)), 0.0, math.cos(math.radians(a))])
                builder.add("leg", rod((0, ring_y, 0), d * r + [0, ring_y, 0], 0.009, segments=8))
    back = bool(height > 0.55 and rng.random() < 0.3)
    if back:
        z = -size / 2 + 0.03
        for sx in (-1, 1):
            builder.add("back", rod((sx * size * 0.25, height - 0.01, z), (sx * size * 0.25, height + 0.2, z - 0.03), 0.01, segments=8))
        builder.add("back", curved_panel(size * 0.8, u(0.08, 0.14), 0.02, 0.03, (0, height + u(0.12, 0.15), z - 0.005), 8.0, layers=4))
    return {"family": "stool", "support": style, "round": round_seat, "back": back, "size": round(size, 3), "seat_height": round(height, 3)}


def _bench(builder, rng) -> dict[str, Any]:
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
            builder.add("seat", box((0.05, thick * 0.5, depth - 0.02), (x, height - thick * 0.7 - thick * 0.25 + 0.005, 0)))
    else:
        builder.add("seat", slab(length, depth, thick, u(0.005, 0.05), (0, height - thick / 2, 0)))
    support = str(rng.choice(["legs", "trestle", "sled"]))
    under = height - thick / 2  # supports end inside the seat (slats float above its underside)
    inset = u(0.04, 0.15)
    xe = length / 2 - inset
    if support == "legs":
        r = u(0.015, 0.03)
        for sx in (-1, 1):
            for sz in (-1, 1):
                builder.add("leg", rod((sx * (xe + 0.02), 0, sz * (depth / 2 - 0.05)), (sx * xe, under + 0.01, sz * (depth / 2 - 0.06)), r, segments=12))
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
    back = bool(rng.random() < 0.35)
    if back:
        recline, back_height = u(5, 15), u(0.3, 0.45)
        z = -depth / 2 + 0.03
        for sx in (-1, 1):
            builder.add("back", rod((sx * xe, under, z), (sx * xe, height + back_height, _post_z(z, recline, back_height)), 0.02, segments=10))
        for k in range(int(rng.integers(1, 4))):
            rise = back_height * (0.35 + 0.6 * k / 3)
            builder.add("back", curved_panel(2 * xe + 0.06, u(0.05, 0.1), 0.025, u(0.0, 0.03), (0, height + rise, _post_z(z, recline, rise) + 0.012), recline, layers=3))
    return {"family": "bench", "support": support, "slats": slats, "back": back, "length": round(length, 3), "depth": round(depth, 3),
            "seat_height": round(height, 3)}


def _rocking(builder, rng) -> dict[str, Any]:
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
        builder.add("leg", tube(np.column_stack([np.full(len(runner_z), x), runner_y(runner_z), runner_z]), r_run, segments=10))
        builder.add("leg", rod((x, runner_y(zs) + 0.3 * r_run, zs), (sx * xs, height - thick + 0.01, zs), r_leg, segments=12))
        rear = bezier([(x, runner_y(-zs) + 0.3 * r_run, -zs), (sx * xs, height - thick, -zs), (sx * xs, height + back_height, _post_z(-zs, recline, back_height))], 24)
        builder.add("leg", tube(resample(rear, 0.02), r_leg))
    arms = bool(rng.random() < 0.7)
    if arms:
        arm_y = height + u(0.2, 0.26)
        for sx in (-1, 1):
            builder.add("arm", rod((sx * xs, height - 0.01, zs), (sx * xs, arm_y, zs + 0.01), r_leg * 0.8, segments=10))
            points = bezier([(sx * xs, arm_y, _post_z(-zs, recline, arm_y - height)), (sx * (xs + 0.04), arm_y + 0.02, 0.0), (sx * xs, arm_y, zs + 0.06)], 20)
            builder.add("arm", tube(resample(points, 0.02), u(0.015, 0.025)))
    rail_y = height + back_height - 0.02
    rail_z = _post_z(-zs, recline, back_height - 0.02)
    back = str(rng.choice(["spindles", "spindles", "panel"]))
    if back == "spindles":
        rail = bezier([(-xs, rail_y, rail_z), (0, rail_y + u(0.02, 0.08), rail_z - 0.08), (xs, rail_y, rail_z)], 20)
        builder.add("back", tube(rail, r_leg * 1.1))
        count = int(rng.integers(4, 9))
        for k in range(count):
            x = -xs + 2 * xs * (k + 1) / (count + 1)
            t = (k + 1) / (count + 1)
            builder.add("back", rod((x, height - 0.01, -zs + 0.005), (x, rail_y + 2 * t * (1 - t) * 0.03, rail_z - 2 * t * (1 - t) * 0.16), r_leg * 0.4, segments=8))
    else:
        bottom = back_height * u(0.1, 0.25)
        builder.add("back", curved_panel(2 * xs + r_leg, back_height - bottom, 0.02, u(0.02, 0.06), (0, height + bottom, _post_z(-zs, recline, bottom) + 0.01), recline))
    return {"family": "rocking", "back": back, "arms": arms, "width": round(width, 3), "depth": round(depth, 3), "seat_height": round(height, 3),
            "runner_radius": round(bow, 3)}


def _folding(builder, rng) -> dict[str, Any]:
    """Folding chairs: tubular legs crossed in an X on each side, one leg of each X rising into a back post."""
    u = rng.uniform
    width, depth, height = u(0.40, 0.46), u(0.38, 0.44), u(0.43, 0.47)
    thick, r = u(0.012, 0.025), u(0.009, 0.014)
    back_height, recline = u(0.32, 0.42), u(5.0, 14.0)
    xs = width / 2
    rail_y = height - thick - r * 0.5
    for sx in (-1, 1):
        x = sx * xs
        post_top = (x, height + back_height, _post_z(-depth / 2, recline, back_height + thick))
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
            builder.add("seat", box((width + 2 * r, thick, slat), (0, height - thick / 2, -depth / 2 + slat / 2 + k * (slat + 0.01 + 0.01 / (count - 1)))))
    panel = back_height * u(0.3, 0.5)
    rise = back_height - panel + thick
    builder.add("back", curved_panel(width + r, panel, u(0.012, 0.02), u(0.0, 0.04), (0, height + rise - thick, _post_z(-depth / 2, recline, rise) + 0.006), recline, layers=5))
    return {"family": "folding", "seat": seat, "width": round(width, 3), "depth": round(depth, 3), "seat_height": round(height, 3)}


def _shell(builder, rng) -> dict[str, Any]:
    """Shell chairs: one curved moulded seat-and-back on dowel legs, a wire frame, a sled or a pedestal."""
    u = rng.uniform
    width, depth, height = u(0.46, 0.56), u(0.42, 0.50), u(0.42, 0.46)
    back_height, recline, thick = u(0.34, 0.44), u(8.0, 18.0), u(0.012, 0.02)
    dish, armed = u(0.03, 0.07), bool(rng.random() < 0.3)
    lean = math.tan(math.radians(recline))
    curve = bezier([(0, height - 0.03, depth / 2 + 0.01), (0, height + 0.005, depth / 2 - 0.12), (0, height - 0.04, -depth / 2 + 0.02),
                    (0, height + back_height * 0.4, -depth / 2 - 0.05), (0, height + back_height, -depth / 2 - 0.05 - lean * back_height)], 60)
    curve = resample(curve, 0.025)
    tangents = transport_frames(curve)[0]
    up = np.cross([1.0, 0, 0], tangents)
    s = np.linspace(0.0, 1.0, len(curve))
    widths = width * (1 - 0.12 * np.exp(-((s - 0.55) / 0.12) ** 2))
    dishes = dish + (u(0.1, 0.16) if armed else 0.0) * np.exp(-((s - 0.6) / 0.18) ** 2)
    rings = place_rings(np.stack([band(w, thick, d) for w, d in zip(widths, dishes)]), curve, [1.0, 0, 0], up)
    split = int(np.argmax(np.abs(tangents[:, 1]) > np.abs(tangents[:, 2])))
    builder.add("seat", loft(rings[: split + 1]))
    builder.add("back", loft(rings[split:]))
    pan = np.flatnonzero((curve[:, 2] < depth / 2 - 0.06) & (curve[:, 2] > -depth / 2 + 0.08) & (np.arange(len(curve)) < split))
    half = 0.12
    mount = []
    for k in pan:
        uu = np.linspace(-half, half, 10)
        edge = dishes[k] * (2 * uu / widths[k]) ** 2 - thick / 2
        mount.append(np.concatenate([np.column_stack([uu, edge]), np.column_stack([uu[::-1], np.full(10, -thick - 0.03)])]))
    builder.add("leg", loft(place_rings(np.stack(mount), curve[pan], [1.0, 0, 0], up[pan])))
    anchors = curve[pan] - up[pan] * (thick + 0.015)
    front, rear = anchors[-1], anchors[0]  # the curve runs from the front lip backwards
    front, rear = (front, rear) if front[2] > rear[2] else (rear, front)
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
            mids = [f + t * (np.array([np.sign(f[0]) * half * 0.7, top[1], top[2]]) - f) for f, top in zip(feet, (front, front, rear, rear))]
            for a, b in ((0, 1), (2, 3), (0, 2), (1, 3), (0, 3), (1, 2)):
                builder.add("leg", rod(mids[a], mids[b], r * 0.8, segments=8))
    elif base == "sled":
        r = u(0.008, 0.012)
        for sx in (-1, 1):
            x = sx * width * 0.4
            outline = np.array([(sx * half * 0.7, front[1], front[2]), (x, front[1] - 0.05, front[2] + 0.02), (x, r, depth * 0.45),
                                (x, r, -depth * 0.45), (x, rear[1] - 0.05, rear[2] - 0.02), (sx * half * 0.7, rear[1], rear[2])])
            builder.add("leg", tube(rounded_path(outline, 0.05), r, segments=10))
    else:
        centre = anchors[len(anchors) // 2]
        builder.add("leg", rod((0, 0.02, centre[2]), (0, centre[1], centre[2]), u(0.02, 0.03), segments=16))
        base_r = u(0.2, 0.26)
        outline = superellipse(base_r, base_r, 2.0, 32)
        disc = np.stack([np.column_stack([outline[:, 0] * k, np.full(32, y), outline[:, 1] * k + centre[2]]) for k, y in ((1, 0.0), (1, 0.012), (0.25, 0.045))])
        builder.add("base", loft(disc))
    return {"family": "shell", "base": base, "armed": armed, "width": round(width, 3), "depth": round(depth, 3), "seat_height": round(height, 3)}


def _classic(builder, rng) -> dict[str, Any]:
    """Today's boxy chairs (``mesh2tex.synthetic.shapes``), kept as one family among the others."""
    return {"family": "classic", **_chair(builder, rng)}


# family name -> (design function, share of the varied world's chairs, parts it always has)
CHAIR_FAMILIES: dict[str, tuple] = {
    "four_legged": (_four_legged, 0.18, ("seat", "back", "leg")),
    "office": (_office, 0.14, ("seat", "back", "leg", "base")),
    "armchair": (_armchair, 0.12, ("seat", "back", "arm")),
    "sofa": (_sofa, 0.10, ("seat", "back", "arm")),
    "stool": (_stool, 0.10, ("seat", "leg")),
    "bench": (_bench, 0.07, ("seat", "leg")),
    "rocking": (_rocking, 0.07, ("seat", "back", "leg")),
    "folding": (_folding, 0.07, ("seat", "back", "leg")),
    "shell": (_shell, 0.07, ("seat", "back", "leg")),
    "classic": (_classic, 0.08, ("seat", "back", "leg")),
}

