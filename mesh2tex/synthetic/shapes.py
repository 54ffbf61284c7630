"""Procedural chairs and cars: watertight triangle meshes whose faces remember which part they belong to.

Every shape is the boolean union (manifold3d) of simple solids (rounded slabs, boxes, tapered
cylinders, revolved profiles, convex hulls of extruded side profiles). A union of closed solids is
closed, so every result is watertight and two-manifold, which is what ``prepare shapes`` needs.
manifold3d tracks each input solid through the union (``original_id``), so each output triangle
keeps the label of the part it came from (``seat``, ``leg``, ``body``, ``wheel``...); the material
library (:mod:`mesh2tex.synthetic.materials`) colours the shape part by part.

Frame of every result: y up, the object's front faces +z, bounding-box centre at the origin and
bounding-box diagonal 1 (the normalised frame of prepared shapes), so NOC = position + 0.5.
A chair stands on y = min y; a car's wheels touch y = min y.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any, Callable

import manifold3d as mf
import numpy as np

from mesh2tex.geometry.features import noc_coordinates
from mesh2tex.synthetic.solids import (
    PART_NAMES,
    PartBuilder,
    box,
    hull,
    panel,
    place,
    prism_hull,
    rod,
    rotation_x,
    slab,
)

CATEGORIES: tuple[str, ...] = ("chair", "car")


@dataclass
class SyntheticShape:
    """A watertight triangle mesh with a part label per face.

    vertices:   (V, 3) float64, normalised frame (bbox centre 0, diagonal 1), y up, front +z
    faces:      (T, 3) int64, counter-clockwise seen from outside; sorted by part
    face_parts: (T,) int64, index into PART_NAMES
    params:     the sampled design choices (JSON-serialisable), e.g. {"legs": "pedestal", ...}
    """

    category: str
    vertices: np.ndarray
    faces: np.ndarray
    face_parts: np.ndarray
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def part_names(self) -> list[str]:
        """Names of the parts present, in PART_NAMES order."""
        return [PART_NAMES[i] for i in np.unique(self.face_parts)]

    @functools.cached_property
    def noc(self) -> np.ndarray:
        """(V, 3) float32 NOC of the vertices (``mesh2tex.geometry.features.noc_coordinates``), computed once."""
        return noc_coordinates(self.vertices)


def generate_shape(category: str, rng: np.random.Generator) -> SyntheticShape:
    """One random shape of ``category`` ('chair' or 'car'), drawn from ``rng`` only (deterministic)."""
    if category not in _GENERATORS:
        raise ValueError(f"unknown category {category!r}; choose one of {', '.join(CATEGORIES)}")
    return shape_from_design(category, _GENERATORS[category], rng)


def shape_from_design(
    category: str,
    design: Callable[[PartBuilder, np.random.Generator], dict[str, Any]],
    rng: np.random.Generator,
    repair: Callable | None = None,
) -> SyntheticShape:
    """The shape that ``design`` (which adds labelled solids to a builder and returns its design choices)
    draws from ``rng``: the union of its parts, normalised, redrawn while unusable. ``repair``, when
    given, maps the union's (vertices, faces, face_parts) to cleaned ones, or None to redraw."""
    # A random design can rarely leave a sliver edge (two parts nearly touching) or a part that
    # floats free; such a draw is replaced by the next one, so the result stays deterministic.
    for _ in range(_MAX_DRAWS):
        builder = PartBuilder()
        params = design(builder, rng)
        vertices, faces, face_parts = builder.union()
        if repair is not None:
            repaired = repair(vertices, faces, face_parts)
            if repaired is None:
                continue
            vertices, faces, face_parts = repaired
        vertices = normalise(vertices)
        if _is_usable(vertices, faces):
            return SyntheticShape(category, vertices, faces, face_parts, params)
    raise RuntimeError(f"no usable {category} in {_MAX_DRAWS} draws")  # a bug in a generator, not bad luck


_MAX_DRAWS = 20
MIN_EDGE = 1e-5  # in the normalised frame; mesh files keep 8 decimals, so such edges survive


def _is_usable(vertices: np.ndarray, faces: np.ndarray) -> bool:
    """One connected piece with no edge shorter than MIN_EDGE."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    if np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1).min() < MIN_EDGE:
        return False
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(len(vertices),) * 2)
    return connected_components(graph, directed=False)[0] == 1


def normalise(vertices: np.ndarray) -> np.ndarray:
    """(V, 3) -> (V, 3): bounding-box centre to the origin, bounding-box diagonal to 1."""
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    return (vertices - (low + high) / 2) / np.linalg.norm(high - low)


# ----------------------------------------------------------------------------------------------
# Chairs (units: metres before normalisation)


def _chair(builder: PartBuilder, rng: np.random.Generator) -> dict[str, Any]:
    u = rng.uniform
    legs = str(rng.choice(["four", "four", "pedestal", "sled"], p=[0.35, 0.2, 0.3, 0.15]))
    back = str(rng.choice(["solid", "slats_vertical", "slats_horizontal", "frame"]))
    arms = str(rng.choice(["none", "posts", "panels"], p=[0.5, 0.3, 0.2]))
    width, depth = u(0.40, 0.62), u(0.38, 0.56)
    if arms == "panels":
        width += 0.1  # arm panels sit on the seat's sides
    seat_height, seat_thick = u(0.38, 0.50), u(0.035, 0.11)
    seat_radius = u(0.0, 0.12) if rng.random() < 0.6 else 0.0
    seat_top = seat_height
    seat_bottom = seat_height - seat_thick
    builder.add("seat", slab(width, depth, seat_thick, seat_radius, (0, seat_height - seat_thick / 2, 0)))

    params_extra = _chair_legs(builder, rng, legs, width, depth, seat_bottom, seat_radius)
    params = {
        "legs": legs,
        "back": back,
        "arms": arms,
        "width": round(width, 3),
        "depth": round(depth, 3),
        "seat_height": round(seat_height, 3),
    }
    params.update(params_extra)

    # The back, built upright at the origin, then tilted and moved to the seat's rear edge.
    back_width = width * u(0.8, 1.0) - (0.1 if arms == "panels" else 0.0)
    back_height, back_thick = u(0.32, 0.58), u(0.025, 0.06)
    tilt = u(0.0, 16.0)
    pieces = _chair_back_pieces(rng, back, back_width, back_height, back_thick, params)
    back_solid = mf.Manifold.batch_boolean(pieces, mf.OpType.Add)
    back_z = -depth / 2 + back_thick / 2
    builder.add("back", place(back_solid, rotation_x(-tilt), (0, seat_top - 0.015, back_z)))
    params["back_tilt_degrees"] = round(tilt, 1)

    if arms != "none":
        _chair_arms(builder, rng, arms, width, depth, seat_top, seat_bottom, back_z, tilt)
    return params


def _chair_legs(
    builder: PartBuilder,
    rng: np.random.Generator,
    legs: str,
    width: float,
    depth: float,
    seat_bottom: float,
    seat_radius: float,
) -> dict[str, Any]:
    """The chair's legs under the seat (four legs with an optional H of stretchers, a pedestal on a star
    or a disc, or sled runners); returns the parameters to record (the pedestal's base)."""
    u = rng.uniform
    params_extra: dict[str, Any] = {}
    leg_radius = u(0.015, 0.03)
    square_legs = bool(rng.random() < 0.4)
    if legs == "four":
        inset = u(0.0, 0.05) + leg_radius + seat_radius * 0.3
        splay = u(0.0, 0.05)
        taper = u(0.55, 1.0)
        xs, zs = width / 2 - inset, depth / 2 - inset
        corners = [(sx, sz) for sx in (-1, 1) for sz in (-1, 1)]
        for sx, sz in corners:
            top = (sx * xs, seat_bottom + 0.01, sz * zs)
            foot = (sx * (xs + splay), 0.0, sz * (zs + splay))
            builder.add("leg", rod(foot, top, leg_radius * taper, leg_radius, square=square_legs))
        if rng.random() < 0.5:  # an H of stretchers between the legs
            y = u(0.1, 0.22)
            spread = splay * (1 - y / (seat_bottom + 0.01))  # the legs' outward offset at height y
            x, z, r = xs + spread, zs + spread, leg_radius * 0.6
            for sx in (-1, 1):
                builder.add("leg", rod((sx * x, y, -z), (sx * x, y, z), r, square=square_legs))
            builder.add("leg", rod((-x, y, 0), (x, y, 0), r, square=square_legs))
    elif legs == "pedestal":
        column = u(0.025, 0.05)
        base_style = str(rng.choice(["star", "disc"]))
        builder.add("leg", rod((0, 0.03, 0), (0, seat_bottom + 0.01, 0), column, segments=20))
        if base_style == "star":
            spokes = int(rng.integers(4, 6))
            reach = u(0.24, 0.32)
            phase = u(0, 360 / spokes)
            for k in range(spokes):
                a = math.radians(phase + 360 * k / spokes)
                tip = (reach * math.sin(a), 0.035, reach * math.cos(a))
                builder.add("base", rod((0, 0.05, 0), tip, 0.022, 0.016, square=True))
                builder.add("base", rod((tip[0], 0.0, tip[2]), (tip[0], 0.05, tip[2]), 0.022, segments=12))
        else:
            radius = u(0.2, 0.28)
            profile = mf.CrossSection(
                [np.array([[0, 0], [radius, 0], [radius * 0.9, 0.03], [column * 1.6, 0.09], [0, 0.09]])]
            )
            disc = mf.Manifold.revolve(profile, 32)  # revolved around y, then y became z
            builder.add("base", place(disc, np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]), (0, 0, 0)))
        builder.add("leg", slab(width * 0.5, depth * 0.5, 0.03, 0.02, (0, seat_bottom - 0.01, 0)))
        params_extra = {"base": base_style}
    else:  # sled: two floor runners joined to the seat by uprights
        r = leg_radius * 0.8
        xs = width / 2 - u(0.02, 0.06)
        zf, zb = depth / 2 - 0.02, -depth / 2 + 0.02
        for sx in (-1, 1):
            x = sx * xs
            builder.add("leg", rod((x, r, zf + 0.04), (x, r, zb - 0.04), r, segments=12))
            builder.add("leg", rod((x, r, zf), (x, seat_bottom + 0.01, zf - 0.02), r, segments=12))
            builder.add("leg", rod((x, r, zb), (x, seat_bottom + 0.01, zb + 0.02), r, segments=12))
    return params_extra


def _chair_back_pieces(
    rng: np.random.Generator, back: str, back_width: float, back_height: float, back_thick: float, params: dict
) -> list:
    """The back's pieces, built upright at the origin: a panel, or posts and a top rail with vertical or
    horizontal slats or an upholstered pad (``params["back_pieces"]`` counts them)."""
    u = rng.uniform
    pieces: list[mf.Manifold] = []
    if back == "solid":
        pieces.append(panel(back_width, back_height + 0.02, back_thick, u(0.0, 0.15)))
    else:
        post = u(0.018, 0.03)
        rail = u(0.04, 0.1)
        for sx in (-1, 1):
            pieces.append(box((2 * post, back_height, back_thick), (sx * (back_width / 2 - post), back_height / 2, 0)))
        pieces.append(box((back_width, rail, back_thick), (0, back_height - rail / 2, 0)))
        inner_width = back_width - 4 * post
        if back == "slats_vertical":
            count = int(rng.integers(2, 7))
            slat = min(u(0.02, 0.06), inner_width / (count + 1) * 0.9)
            for k in range(count):
                x = -inner_width / 2 + inner_width * (k + 1) / (count + 1)
                pieces.append(
                    box((slat, back_height - rail + 0.02, back_thick * 0.6), (x, (back_height - rail) / 2, 0))
                )
        elif back == "slats_horizontal":
            count = int(rng.integers(1, 4))
            for k in range(count):
                y = (back_height - rail) * (k + 1) / (count + 1)
                pieces.append(box((inner_width + 0.01, u(0.03, 0.07), back_thick * 0.6), (0, y, 0)))
        else:  # frame holding an upholstered pad
            pad_height = (back_height - rail) * u(0.5, 0.85)
            pieces.append(
                box((inner_width + 0.01, pad_height, back_thick * 1.3), (0, (back_height - rail) / 2 + 0.02, 0))
            )
        params["back_pieces"] = len(pieces) - 3  # slats, or the pad of a frame back
    return pieces


def _chair_arms(
    builder: PartBuilder,
    rng: np.random.Generator,
    arms: str,
    width: float,
    depth: float,
    seat_top: float,
    seat_bottom: float,
    back_z: float,
    tilt: float,
) -> None:
    """Arm rests on posts, or arm panels on the seat's sides, from the front of the seat to the tilted back."""
    u = rng.uniform
    arm_height = seat_top + u(0.17, 0.26)
    arm_width, arm_thick = u(0.035, 0.08), u(0.025, 0.045)
    front = depth / 2 - u(0.0, 0.08)
    back_at_arm = back_z - math.tan(math.radians(tilt)) * (arm_height - seat_top)
    length = front - back_at_arm
    for sx in (-1, 1):
        x = sx * (width / 2 - arm_width / 2)
        if arms == "posts":
            builder.add("arm", box((arm_width, arm_thick, length), (x, arm_height, back_at_arm + length / 2)))
            builder.add(
                "arm",
                rod((x, seat_top - 0.01, front - 0.05), (x, arm_height, front - 0.04), arm_width * 0.35, segments=12),
            )
        else:
            panel_height = arm_height - seat_bottom + 0.02
            # Slightly wider than the seat: flush faces would leave slivers in the union.
            builder.add(
                "arm",
                box(
                    (0.1, panel_height, length),
                    (sx * (width / 2 - 0.045), seat_bottom - 0.02 + panel_height / 2, back_at_arm + length / 2),
                ),
            )


# ----------------------------------------------------------------------------------------------
# Cars (units: metres before normalisation; length along z, front at +z)

_CAR_STYLES = ("sedan", "hatchback", "suv", "pickup", "sports", "van")


def _car(builder: PartBuilder, rng: np.random.Generator) -> dict[str, Any]:
    u = rng.uniform
    style = str(rng.choice(_CAR_STYLES))
    length = u(3.6, 4.9)
    width = u(1.6, 1.95)
    clearance = {"suv": u(0.28, 0.38), "pickup": u(0.3, 0.4), "sports": u(0.1, 0.15)}.get(style, u(0.15, 0.24))
    body_height = {"suv": u(0.65, 0.85), "pickup": u(0.65, 0.8), "sports": u(0.38, 0.48), "van": u(0.6, 0.8)}.get(
        style, u(0.5, 0.65)
    )
    cabin_height = {"sports": u(0.3, 0.4), "van": u(0.75, 1.0), "suv": u(0.5, 0.65)}.get(style, u(0.4, 0.55))
    hood = {"sports": u(0.34, 0.42), "van": u(0.08, 0.15), "pickup": u(0.26, 0.32)}.get(style, u(0.24, 0.32))
    trunk = {"sedan": u(0.16, 0.24), "sports": u(0.12, 0.2), "pickup": u(0.3, 0.38)}.get(style, u(0.0, 0.04))
    windshield = {"sports": u(1.6, 2.2), "van": u(0.3, 0.6), "suv": u(0.5, 0.8)}.get(style, u(0.9, 1.5))  # run / rise
    rear_window = {"sedan": u(0.7, 1.2), "sports": u(1.2, 1.8), "hatchback": u(0.25, 0.5)}.get(style, u(0.0, 0.15))
    wheel_radius = u(0.29, 0.4) if style in ("suv", "pickup") else u(0.26, 0.34)
    wheel_width = u(0.18, 0.28)
    clearance = min(clearance, 0.8 * wheel_radius)  # the axles (at wheel height) must run inside the body

    z0, z1 = -length / 2, length / 2
    y0, y1 = clearance, clearance + body_height
    nose, tail = u(0.1, 0.35) * body_height, u(0.05, 0.2) * body_height
    body_profile = np.array(
        [
            (z0 + 0.12, y0),
            (z1 - 0.18, y0),  # bottom, the ends lifted a little
            (z1, y0 + body_height * u(0.25, 0.45)),
            (z1 - nose * 2.2, y1),  # front bumper and nose
            (z0 + tail, y1),
            (z0, y1 - body_height * u(0.1, 0.3)),
            (z0, y0 + body_height * 0.2),
        ]
    )
    bevel = u(0.04, 0.1)
    body = prism_hull(body_profile, width / 2, bevel)

    cabin_rear, top = _car_cabin(
        builder, u, width, y1, z0, z1, length, trunk, hood, cabin_height, windshield, rear_window
    )

    if style == "pickup":  # an open cargo bed behind the cabin
        wall = 0.06
        bed = box(
            (width - 2 * wall - 2 * bevel, body_height * 0.7, cabin_rear - z0 - 2 * wall),
            (0, y1 - body_height * 0.35 + 0.01, (z0 + cabin_rear) / 2),
        )
        body = body - bed

    _car_body_and_wheels(builder, u, body, length, width, wheel_radius, wheel_width)

    _car_lights(builder, u, body_profile, y0, body_height, width, bevel)
    return {
        "style": style,
        "length": round(length, 3),
        "width": round(width, 3),
        "height": round(top, 3),
        "wheel_radius": round(wheel_radius, 3),
    }


def _car_cabin(
    builder: PartBuilder,
    u,
    width: float,
    y1: float,
    z0: float,
    z1: float,
    length: float,
    trunk: float,
    hood: float,
    cabin_height: float,
    windshield: float,
    rear_window: float,
) -> tuple[float, float]:
    """The cabin (a hull on the body's top, y1) between the trunk and the hood; (its rear z, its top y)."""
    cabin_rear = z0 + trunk * length
    cabin_front = z1 - hood * length
    top = y1 + cabin_height
    run_front = windshield * cabin_height
    run_rear = rear_window * cabin_height
    if cabin_front - run_front - (cabin_rear + run_rear) < 0.4:  # keep a roof at least 0.4 m long
        scale = max(cabin_front - cabin_rear - 0.4, 0.1) / max(run_front + run_rear, 1e-6)
        run_front, run_rear = run_front * scale, run_rear * scale
    cabin_profile = np.array(
        [
            (cabin_rear, y1 - 0.05),
            (cabin_front, y1 - 0.05),
            (cabin_front - run_front, top),
            (cabin_rear + run_rear, top),
        ]
    )
    inset_bottom, inset_top = u(0.02, 0.08), u(0.1, 0.2)
    cabin_points = []
    for (z, y), inset in zip(cabin_profile, (inset_bottom, inset_bottom, inset_top, inset_top)):
        for sign in (-1.0, 1.0):
            cabin_points.append((sign * (width / 2 - inset), y, z))
    builder.add("cabin", hull(cabin_points))
    return cabin_rear, top


def _car_body_and_wheels(
    builder: PartBuilder, u, body: mf.Manifold, length: float, width: float, wheel_radius: float, wheel_width: float
) -> None:
    """The body with its wheel wells cut, then the wheels and hubs on axles (one piece)."""
    # Wheel wells cut from the body, then the wheels, joined by axles so the shape stays one piece.
    wheelbase = length * u(0.56, 0.66)
    overhang = u(-0.04, 0.04) * length
    wheel_x = width / 2 - wheel_width / 2 + u(-0.02, 0.04)
    for z in (-wheelbase / 2 + overhang, wheelbase / 2 + overhang):
        well = rod((-width, wheel_radius, z), (width, wheel_radius, z), wheel_radius * 1.1, segments=28)
        body = body - (well - box((2 * (wheel_x - wheel_width / 2 - 0.04), 4, 4), (0, 0, z)))
    builder.add("body", body)
    for z in (-wheelbase / 2 + overhang, wheelbase / 2 + overhang):
        builder.add(
            "wheel", rod((-wheel_x, wheel_radius, z), (wheel_x, wheel_radius, z), wheel_radius * 0.25, segments=12)
        )
        for sx in (-1, 1):
            outer = sx * (wheel_x + wheel_width / 2)
            inner = sx * (wheel_x - wheel_width / 2)
            builder.add("wheel", rod((inner, wheel_radius, z), (outer, wheel_radius, z), wheel_radius, segments=28))
            hub_radius = wheel_radius * u(0.5, 0.7)
            builder.add(
                "hub", rod((inner, wheel_radius, z), (outer + sx * 0.012, wheel_radius, z), hub_radius, segments=20)
            )


def _car_lights(
    builder: PartBuilder, u, body_profile: np.ndarray, y0: float, body_height: float, width: float, bevel: float
) -> None:
    """Head and tail lights on the body's front and rear faces."""
    # Head and tail lights: flattened spheres half sunk into the front and rear faces.
    light_y = y0 + body_height * u(0.45, 0.7)
    light_size = (u(0.16, 0.3), u(0.05, 0.1), 0.08)
    front_z = _profile_z_at(body_profile, light_y, front=True)
    rear_z = _profile_z_at(body_profile, y0 + body_height * u(0.55, 0.75), front=False)
    for sx in (-1, 1):
        x = sx * (width / 2 - bevel - light_size[0] * 0.7)
        builder.add("headlight", mf.Manifold.sphere(1.0, 16).scale(light_size).translate((x, light_y, front_z - 0.01)))
        builder.add(
            "taillight",
            mf.Manifold.sphere(1.0, 16).scale(light_size).translate((x, y0 + body_height * 0.65, rear_z + 0.01)),
        )


def _profile_z_at(profile_zy: np.ndarray, y: float, front: bool) -> float:
    """The z where a horizontal line at height ``y`` leaves the convex side profile (front or rear end)."""
    best = None
    closed = np.vstack([profile_zy, profile_zy[:1]])
    for (za, ya), (zb, yb) in zip(closed[:-1], closed[1:]):
        if (ya - y) * (yb - y) <= 0 and ya != yb:
            z = za + (y - ya) / (yb - ya) * (zb - za)
            if best is None or (z > best if front else z < best):
                best = z
    return float(best if best is not None else (profile_zy[:, 0].max() if front else profile_zy[:, 0].min()))


_GENERATORS: dict[str, Callable[[PartBuilder, np.random.Generator], dict[str, Any]]] = {"chair": _chair, "car": _car}
