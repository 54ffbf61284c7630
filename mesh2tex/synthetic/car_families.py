"""The car families of the varied world (``prepare synthetic --variety real``).

A car is a **lofted body**: rounded cross-sections (superellipses) along the length, whose width,
floor and belt line follow smooth curves (a rounded nose and tail, a hood sloping to the bumper,
bumpers lifted for the approach angles), and a **cabin** lofted on top of it from rounded trapezoids
(the side windows lean in) whose roof line rises along the windscreen and falls along the rear
window. Wheel wells are cut into the body; four wheels with hubs stand in them, joined by axles; head
and tail lights sit on the body's surface where a ray along the length meets it.

Each family draws its dimensions from the catalogue ranges of ``docs/synthetic.md`` ("The varied
world"); lengths along z with the front at +z, metres, wheels on y = 0. Parts: body, cabin, wheel,
hub, headlight, taillight (as in :mod:`mesh2tex.synthetic.shapes`).
"""

from __future__ import annotations

from typing import Any

import manifold3d as mf
import numpy as np

from mesh2tex.synthetic.shapes import _car
from mesh2tex.synthetic.solids import box, rod
from mesh2tex.synthetic.sweeps import loft, superellipse

# Ranges per family: overall length, width and height (m); wheelbase as a share of the length; wheel
# radius and ground clearance (m); belt line as a share of the height; the cabin along the length as
# shares t in [0, 1] from the tail: (rear window foot, roof rear, roof front, windscreen foot); how far
# the hood falls to the nose, as a share of the body's height.
STYLES: dict[str, dict[str, tuple]] = {
    "sedan": dict(
        length=(4.5, 5.0),
        width=(1.78, 1.88),
        height=(1.40, 1.50),
        wheelbase=(0.57, 0.61),
        wheel=(0.31, 0.34),
        clearance=(0.13, 0.17),
        belt=(0.60, 0.66),
        cabin=((0.15, 0.21), (0.31, 0.36), (0.52, 0.56), (0.67, 0.71)),
        hood=(0.15, 0.3),
    ),
    "hatchback": dict(
        length=(3.8, 4.35),
        width=(1.68, 1.80),
        height=(1.42, 1.52),
        wheelbase=(0.61, 0.66),
        wheel=(0.29, 0.32),
        clearance=(0.13, 0.17),
        belt=(0.58, 0.64),
        cabin=((0.02, 0.05), (0.12, 0.2), (0.52, 0.57), (0.67, 0.71)),
        hood=(0.15, 0.3),
    ),
    "suv": dict(
        length=(4.4, 4.95),
        width=(1.82, 1.98),
        height=(1.62, 1.80),
        wheelbase=(0.58, 0.62),
        wheel=(0.35, 0.39),
        clearance=(0.20, 0.26),
        belt=(0.58, 0.64),
        cabin=((0.02, 0.04), (0.06, 0.1), (0.6, 0.65), (0.72, 0.76)),
        hood=(0.05, 0.15),
    ),
    "van": dict(
        length=(4.8, 5.4),
        width=(1.90, 2.05),
        height=(1.85, 2.10),
        wheelbase=(0.60, 0.64),
        wheel=(0.32, 0.35),
        clearance=(0.16, 0.20),
        belt=(0.46, 0.54),
        cabin=((0.01, 0.03), (0.03, 0.06), (0.74, 0.8), (0.85, 0.9)),
        hood=(0.05, 0.2),
    ),
    "pickup": dict(
        length=(5.2, 5.9),
        width=(1.85, 2.05),
        height=(1.75, 1.95),
        wheelbase=(0.57, 0.62),
        wheel=(0.37, 0.41),
        clearance=(0.22, 0.28),
        belt=(0.58, 0.64),
        cabin=((0.40, 0.45), (0.42, 0.47), (0.58, 0.61), (0.68, 0.72)),
        hood=(0.0, 0.1),
    ),
    "sports": dict(
        length=(4.2, 4.6),
        width=(1.80, 1.95),
        height=(1.15, 1.30),
        wheelbase=(0.57, 0.60),
        wheel=(0.32, 0.35),
        clearance=(0.09, 0.12),
        belt=(0.58, 0.66),
        cabin=((0.10, 0.16), (0.36, 0.42), (0.52, 0.56), (0.62, 0.66)),
        hood=(0.3, 0.45),
    ),
}


def _smoothstep(a: float, b: float, t):
    x = np.clip((np.asarray(t, dtype=np.float64) - a) / (b - a), 0.0, 1.0)
    return x * x * (3 - 2 * x)


class _Body:
    """The body's cross-section as a function of t in [0, 1] (tail to nose): half-width, centre height, half-height."""

    def __init__(
        self,
        rng: np.random.Generator,
        length: float,
        width: float,
        clearance: float,
        belt: float,
        hood: float,
        cabin_front: float,
    ):
        u = rng.uniform
        self.length, self.width, self.clearance, self.belt = length, width, clearance, belt
        self.hood_drop, self.tail_drop = hood * (belt - clearance), u(0.0, 0.15) * (belt - clearance)
        self.cabin_front = cabin_front
        self.plan_exponent, self.exponent = u(3.0, 6.0), u(3.5, 6.0)

    def z(self, t):
        return (np.asarray(t) - 0.5) * self.length

    def top(self, t):
        return (
            self.belt
            - self.tail_drop * (1 - _smoothstep(0.0, 0.12, t))
            - self.hood_drop * _smoothstep(self.cabin_front, 1.0, t) ** 1.3
        )

    def bottom(self, t):
        return self.clearance + 0.08 * (1 - _smoothstep(0.0, 0.1, t)) ** 2 + 0.1 * _smoothstep(0.9, 1.0, t) ** 2

    def section(self, t):
        t = np.asarray(t, dtype=np.float64)
        end = 1 - 0.15 * np.abs(2 * t - 1) ** 8  # the last stations shrink: a rounded nose and tail
        plan = 0.8 + 0.2 * (1 - np.abs(2 * t - 1) ** self.plan_exponent) ** (1 / self.plan_exponent)
        top, bottom = self.top(t), self.bottom(t)
        return self.width / 2 * plan * end, (top + bottom) / 2, (top - bottom) / 2 * end

    def rings(self, stations: int = 30, points: int = 32) -> np.ndarray:
        t = (1 - np.cos(np.linspace(0.0, np.pi, stations))) / 2  # denser at the ends
        rings = []
        for ti in t:
            half_width, centre, half_height = self.section(ti)
            ring = superellipse(half_width, half_height, self.exponent, points)
            rings.append(np.column_stack([ring[:, 0], ring[:, 1] + centre, np.full(points, self.z(ti))]))
        return np.stack(rings)

    def surface_z(self, x: float, y: float, front: bool) -> float:
        """The z where a ray along the length at (x, y), from outside, first meets the body (nose or tail)."""

        def inside(t):
            half_width, centre, half_height = self.section(t)
            return abs(x / half_width) ** self.exponent + abs((y - centre) / half_height) ** self.exponent <= 1

        low, high = (0.5, 1.0) if front else (0.5, 0.0)
        for _ in range(40):
            mid = (low + high) / 2
            low, high = (mid, high) if inside(mid) else (low, mid)
        return float(self.z(low))


def _cabin(body: _Body, rng, stations: tuple, roof: float, points: int = 28) -> mf.Manifold:
    """The cabin lofted on the body: rounded trapezoids whose roof rises between the window feet."""
    u = rng.uniform
    rear_foot, roof_rear, roof_front, front_foot = stations
    tumble, exponent = u(0.12, 0.25), u(4.0, 7.0)
    rings = []
    for t in np.linspace(rear_foot, front_foot, 22):
        rise = min(_smoothstep(rear_foot, roof_rear, t), 1 - _smoothstep(roof_front, front_foot, t))
        belt = float(body.top(t))
        bottom, top = belt - 0.2, belt + max(roof * rise, 0.03)
        half_width = float(body.section(t)[0]) * 0.9 - 0.02
        ring = superellipse(half_width, (top - bottom) / 2, exponent, points)
        lean = 1 - tumble * np.clip(ring[:, 1] / ((top - bottom) / 2), 0, 1)  # the windows lean in towards the roof
        rings.append(
            np.column_stack([ring[:, 0] * lean, ring[:, 1] + (top + bottom) / 2, np.full(points, float(body.z(t)))])
        )
    return loft(np.stack(rings))


def _car_family(style: str):
    ranges = STYLES[style]

    def design(builder, rng: np.random.Generator) -> dict[str, Any]:
        u = rng.uniform
        length, width, height = (u(*ranges[k]) for k in ("length", "width", "height"))
        wheel_radius, clearance = u(*ranges["wheel"]), u(*ranges["clearance"])
        clearance = min(clearance, 0.75 * wheel_radius)  # the axles (at wheel height) run inside the body
        belt = height * u(*ranges["belt"])
        stations = tuple(u(*r) for r in ranges["cabin"])
        body = _Body(rng, length, width, clearance, belt, u(*ranges["hood"]), stations[3])
        solid = loft(body.rings())
        if style == "pickup":  # an open bed behind the cabin
            wall = 0.07
            z_front = float(body.z(stations[0])) - 0.05
            z_back = -length / 2 + 0.15
            bed_floor = clearance + (belt - clearance) * u(0.3, 0.45)
            solid = solid - box(
                (width * 0.8 - 2 * wall, 2.0, z_front - z_back), (0, bed_floor + 1.0, (z_front + z_back) / 2)
            )
        wheelbase = length * u(*ranges["wheelbase"])
        front_axle = length / 2 - (length - wheelbase) * u(0.42, 0.52)
        axles = (front_axle - wheelbase, front_axle)
        wheel_width = u(0.19, 0.28)
        wheel_x = width / 2 - wheel_width / 2 - u(0.01, 0.04)
        for z in axles:
            well = rod((-width, wheel_radius, z), (width, wheel_radius, z), wheel_radius * 1.12, segments=28)
            solid = solid - (well - box((2 * (wheel_x - wheel_width / 2 - 0.04), 4, 4), (0, 0, z)))
        builder.add("body", solid)
        builder.add("cabin", _cabin(body, rng, stations, height - belt))
        if style == "sports" and rng.random() < 0.4:  # a rear wing on two posts
            t = 0.04
            y, z = float(body.top(t)), float(body.z(t))
            builder.add("body", box((width * 0.75, 0.025, 0.22), (0, y + 0.12, z + 0.05)))
            for sx in (-1, 1):
                builder.add("body", box((0.03, 0.16, 0.08), (sx * width * 0.25, y + 0.04, z + 0.05)))
        hub_share = u(0.5, 0.7)
        for z in axles:
            builder.add(
                "wheel", rod((-wheel_x, wheel_radius, z), (wheel_x, wheel_radius, z), wheel_radius * 0.25, segments=12)
            )
            for sx in (-1, 1):
                outer, inner = sx * (wheel_x + wheel_width / 2), sx * (wheel_x - wheel_width / 2)
                builder.add("wheel", rod((inner, wheel_radius, z), (outer, wheel_radius, z), wheel_radius, segments=28))
                builder.add(
                    "hub",
                    rod(
                        (inner, wheel_radius, z),
                        (outer + sx * 0.012, wheel_radius, z),
                        wheel_radius * hub_share,
                        segments=20,
                    ),
                )
        size = (u(0.14, 0.26), u(0.04, 0.08), 0.07)
        for front, part, t in ((True, "headlight", 0.97), (False, "taillight", 0.03)):
            half_width, centre, half_height = body.section(t)
            y = float(centre + half_height * u(0.1, 0.4))
            for sx in (-1, 1):
                x = sx * float(half_width - size[0] * 1.1)
                z = body.surface_z(x, y, front) + (-0.02 if front else 0.02)
                builder.add(part, mf.Manifold.sphere(1.0, 16).scale(size).translate((x, y, z)))
        return {
            "family": style,
            "length": round(length, 3),
            "width": round(width, 3),
            "height": round(height, 3),
            "wheelbase": round(wheelbase, 3),
            "wheel_radius": round(wheel_radius, 3),
        }

    design.__name__ = f"_{style}"
    return design


def _classic(builder, rng) -> dict[str, Any]:
    """Today's cars (``mesh2tex.synthetic.shapes``: convex hulls of side profiles), kept as one family."""
    return {"family": "classic", **_car(builder, rng)}


# family name -> (design function, share of the varied world's cars, parts every car of the family has)
_PARTS = ("body", "cabin", "wheel", "hub", "headlight", "taillight")
CAR_FAMILIES: dict[str, tuple] = {
    "sedan": (_car_family("sedan"), 0.22, _PARTS),
    "hatchback": (_car_family("hatchback"), 0.18, _PARTS),
    "suv": (_car_family("suv"), 0.20, _PARTS),
    "van": (_car_family("van"), 0.10, _PARTS),
    "pickup": (_car_family("pickup"), 0.12, _PARTS),
    "sports": (_car_family("sports"), 0.12, _PARTS),
    "classic": (_classic, 0.06, _PARTS),
}
