"""Scene objects built from primitives: tables, chairs, shelves, cabinets, sofas, plants, pillars,
cars, benches, poles, trees, bins.

Each builder returns a `Placed` object: its primitives, a footprint circle (x, y, radius m) that
keeps people out of it, and the seats it offers (x, y, facing, seat height) to sitting people.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from detector.data.primitives import (
    PATTERN_BOOKS,
    PATTERN_GRAIN,
    PATTERN_STRIPES,
    Material,
    Primitive,
    make_box,
    make_cylinder,
    make_ellipsoid,
    yaw_frame,
)

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Seat:
    """Where a person may sit: pelvis floor point `x, y`, facing `yaw_rad`, seat `height_m`."""

    x: float
    y: float
    yaw_rad: float
    height_m: float


@dataclass
class Placed:
    """An object's primitives, its footprint circle and its seats."""

    primitives: list[Primitive]
    footprint: tuple[float, float, float]
    seats: list[Seat] = field(default_factory=list)


def _at(x: float, y: float, yaw: float, local: tuple[float, float, float]) -> FloatArray:
    return np.array([x, y, 0.0]) + yaw_frame(yaw) @ np.asarray(local, dtype=np.float64)


def table(x: float, y: float, yaw: float, length: float, depth: float, height: float,
          top: Material, legs: Material) -> Placed:
    prims: list[Primitive] = [make_box(_at(x, y, yaw, (0, 0, height - 0.02)),
                                       np.array([length / 2, depth / 2, 0.02]), yaw, top)]
    for sx in (-1, 1):
        for sy in (-1, 1):
            foot = _at(x, y, yaw, (sx * (length / 2 - 0.06), sy * (depth / 2 - 0.06), 0))
            prims.append(make_box(foot + np.array([0, 0, (height - 0.04) / 2]),
                                  np.array([0.025, 0.025, (height - 0.04) / 2]), yaw, legs))
    return Placed(prims, (x, y, 0.5 * np.hypot(length, depth)))


def chair(x: float, y: float, yaw: float, seat_height: float, seat: Material, frame: Material,
          with_back: bool = True) -> Placed:
    """A chair facing `yaw` whose seat centre is at (x, y)."""
    half = 0.23
    prims: list[Primitive] = [make_box(_at(x, y, yaw, (0, 0, seat_height - 0.035)),
                                       np.array([half, half, 0.035]), yaw, seat)]
    if with_back:
        prims.append(make_box(_at(x, y, yaw, (-half + 0.03, 0, seat_height + 0.25)),
                              np.array([0.03, half, 0.22]), yaw, seat))
    for sx in (-1, 1):
        for sy in (-1, 1):
            foot = _at(x, y, yaw, (sx * (half - 0.03), sy * (half - 0.03), 0))
            prims.append(make_box(foot + np.array([0, 0, (seat_height - 0.07) / 2]),
                                  np.array([0.015, 0.015, (seat_height - 0.07) / 2]), yaw, frame))
    pelvis = _at(x, y, yaw, (-0.07, 0, 0))
    return Placed(prims, (x, y, 0.33), [Seat(float(pelvis[0]), float(pelvis[1]), yaw, seat_height)])


def shelf(x: float, y: float, yaw: float, length: float, depth: float, height: float,
          body: Material, books: Material) -> Placed:
    prims: list[Primitive] = [
        make_box(_at(x, y, yaw, (0, 0, height / 2)), np.array([length / 2, depth / 2, height / 2]),
                 yaw, books),
        make_box(_at(x, y, yaw, (0, 0, height + 0.015)), np.array([length / 2 + 0.02, depth / 2 + 0.02,
                                                                    0.015]), yaw, body),
    ]
    return Placed(prims, (x, y, 0.5 * np.hypot(length, depth)))


def cabinet(x: float, y: float, yaw: float, length: float, depth: float, height: float,
            body: Material) -> Placed:
    prims: list[Primitive] = [make_box(_at(x, y, yaw, (0, 0, height / 2)),
                                       np.array([length / 2, depth / 2, height / 2]), yaw, body)]
    return Placed(prims, (x, y, 0.5 * np.hypot(length, depth)))


def sofa(x: float, y: float, yaw: float, length: float, cover: Material) -> Placed:
    prims: list[Primitive] = [
        make_box(_at(x, y, yaw, (0, 0, 0.22)), np.array([0.42, length / 2, 0.22]), yaw, cover),
        make_box(_at(x, y, yaw, (-0.35, 0, 0.55)), np.array([0.1, length / 2, 0.3]), yaw, cover),
    ]
    for side in (-1, 1):
        prims.append(make_box(_at(x, y, yaw, (0, side * (length / 2 + 0.08), 0.32)),
                              np.array([0.42, 0.09, 0.32]), yaw, cover))
    seats = []
    for k in range(max(1, int(length / 0.7))):
        off = (k + 0.5) * length / max(1, int(length / 0.7)) - length / 2
        p = _at(x, y, yaw, (0.0, off, 0))
        seats.append(Seat(float(p[0]), float(p[1]), yaw, 0.44))
    return Placed(prims, (x, y, 0.5 * np.hypot(1.0, length + 0.3)), seats)


def bench(x: float, y: float, yaw: float, length: float, wood: Material, frame: Material) -> Placed:
    seat_mat = Material(wood.color, PATTERN_GRAIN, frame.color, 0.05)
    prims: list[Primitive] = [
        make_box(_at(x, y, yaw, (0, 0, 0.44)), np.array([0.22, length / 2, 0.03]), yaw, seat_mat),
        make_box(_at(x, y, yaw, (-0.22, 0, 0.7)), np.array([0.03, length / 2, 0.15]), yaw, seat_mat),
    ]
    for side in (-1, 1):
        prims.append(make_box(_at(x, y, yaw, (0, side * (length / 2 - 0.1), 0.21)),
                              np.array([0.2, 0.03, 0.21]), yaw, frame))
    seats = []
    count = max(1, int(length / 0.65))
    for k in range(count):
        p = _at(x, y, yaw, (0.0, (k + 0.5) * length / count - length / 2, 0))
        seats.append(Seat(float(p[0]), float(p[1]), yaw, 0.47))
    return Placed(prims, (x, y, 0.5 * np.hypot(0.5, length)), seats)


def plant(x: float, y: float, pot: Material, leaves: Material, size: float) -> Placed:
    prims: list[Primitive] = [
        make_cylinder(np.array([x, y, 0.0]), np.array([x, y, 0.4 * size]), 0.2 * size, pot),
        make_ellipsoid(np.array([x, y, 0.75 * size]), np.array([0.35, 0.35, 0.45]) * size,
                       np.eye(3), leaves),
    ]
    return Placed(prims, (x, y, 0.4 * size))


def pillar(x: float, y: float, height: float, radius: float, body: Material, round_: bool) -> Placed:
    if round_:
        prim: Primitive = make_cylinder(np.array([x, y, 0.0]), np.array([x, y, height]), radius, body)
    else:
        prim = make_box(np.array([x, y, height / 2]), np.array([radius, radius, height / 2]), 0.0, body)
    return Placed([prim], (x, y, radius * 1.5))


def car(x: float, y: float, yaw: float, paint: Material, glass: Material, tyre: Material,
        length: float = 4.3) -> Placed:
    width = 1.8
    prims: list[Primitive] = [
        make_box(_at(x, y, yaw, (0, 0, 0.62)), np.array([length / 2, width / 2, 0.36]), yaw, paint),
        make_box(_at(x, y, yaw, (-0.15, 0, 1.18)), np.array([length * 0.27, width / 2 - 0.1, 0.22]),
                 yaw, glass),
        make_box(_at(x, y, yaw, (-0.15, 0, 1.41)), np.array([length * 0.22, width / 2 - 0.14, 0.02]),
                 yaw, paint),
    ]
    for sx in (-1, 1):
        for sy in (-1, 1):
            hub = _at(x, y, yaw, (sx * length * 0.32, sy * (width / 2 - 0.05), 0.32))
            side = yaw_frame(yaw) @ np.array([0.0, 0.11, 0.0])
            prims.append(make_cylinder(hub - side, hub + side, 0.32, tyre))
    return Placed(prims, (x, y, 0.5 * np.hypot(length, width)))


def pole(x: float, y: float, height: float, radius: float, body: Material, lamp: Material | None
         ) -> Placed:
    prims: list[Primitive] = [make_cylinder(np.array([x, y, 0.0]), np.array([x, y, height]), radius, body)]
    if lamp is not None:
        prims.append(make_ellipsoid(np.array([x, y, height + 0.1]), np.array([0.25, 0.25, 0.12]),
                                    np.eye(3), lamp))
    return Placed(prims, (x, y, radius + 0.15))


def tree(x: float, y: float, height: float, crown: float, bark: Material, leaves: Material,
         rng: np.random.Generator) -> Placed:
    prims: list[Primitive] = [make_cylinder(np.array([x, y, 0.0]), np.array([x, y, height * 0.7]),
                                            0.08 + 0.03 * height / 4, bark)]
    for _ in range(3):
        offset = rng.normal(0, crown * 0.25, 3)
        centre = np.array([x, y, height - crown * 0.7]) + offset
        prims.append(make_ellipsoid(centre, crown * rng.uniform(0.55, 0.8, 3), yaw_frame(rng.uniform(0, 6)),
                                    leaves))
    return Placed(prims, (x, y, 0.5))


def bin_(x: float, y: float, body: Material) -> Placed:
    prim = make_cylinder(np.array([x, y, 0.0]), np.array([x, y, 0.9]), 0.25, body)
    return Placed([prim], (x, y, 0.35))


def books(color: FloatArray, other: FloatArray, shelf_m: float) -> Material:
    """Rows of book spines of mixed colours on shelves `shelf_m` apart."""
    return Material((float(color[0]), float(color[1]), float(color[2])), PATTERN_BOOKS,
                    (float(other[0]), float(other[1]), float(other[2])), shelf_m)


def striped(color: FloatArray, stripe: FloatArray, period_m: float) -> Material:
    """A material with horizontal bands (shelves of books, façade courses)."""
    return Material((float(color[0]), float(color[1]), float(color[2])), PATTERN_STRIPES,
                    (float(stripe[0]), float(stripe[1]), float(stripe[2])), period_m)
