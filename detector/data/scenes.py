"""Random scenes: a camera (lens, altitude) and its static surroundings, indoor or outdoor.

A scene is fixed by (split, scene index): its random generator is seeded from those two only, and
its colours come from the split's half of the palette pools, so seen and unseen scenes never share
a layout or a palette. Indoor styles: rooms, classrooms, libraries, halls; outdoor: streets,
squares, parking lots. Open-plan offices (rows of desks facing across screens, monitors, office
chairs, most people seated) are drawn only when asked for (`style="office"`): adding them to the
random draw would change every existing scene of every seed. The camera's floor frame has the nadir
at the origin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from detector.data import objects as obj
from detector.data.environment import Environment
from detector.data.palettes import SPLITS, clothing_color, scene_color, scene_palette
from detector.data.primitives import PATTERN_GRAIN, Material, make_box, yaw_frame
from detector.data.surfaces import (
    WallPainter,
    darken_edges,
    floor_canvas,
    paint_facades,
    paint_room_walls,
    paint_stripe,
)
from detector.data.textures import floor_texture
from fisheye import CalibrationError, FisheyeCamera

FloatArray = NDArray[np.float64]

KINDS = ("indoor", "outdoor")
INDOOR_STYLES = ("room", "classroom", "library", "hall")
OUTDOOR_STYLES = ("street", "square", "parking")
# Styles rendered only on request: the draw above picks among the first tuples alone.
REQUESTED_STYLES = ("office",)
CALIBRATION_SIZE = 2048


@dataclass
class Scene:
    """A camera in its surroundings: `camera` (calibrated at CALIBRATION_SIZE), `environment`,
    `objects`, and `walk_m` (x0, y0, x1, y1), the floor area where people may stand."""

    scene_id: str
    split: str
    kind: str
    style: str
    camera: FisheyeCamera
    environment: Environment
    objects: list[obj.Placed]
    walk_m: tuple[float, float, float, float]


def mat(color: FloatArray) -> Material:
    return Material((float(color[0]), float(color[1]), float(color[2])))


def sample_camera(rng: np.random.Generator, camera_id: str, outdoor: bool, high: bool) -> FisheyeCamera:
    """A ceiling or pole camera: Kannala–Brandt coefficients and principal-point offsets around
    those of real 180-200° lenses, image circle filling 85-110 % of the frame's width. `high`
    allows mounts up to 8 m (outdoor poles, halls); otherwise 2.5-4 m ceilings."""
    r = rng.random()
    if outdoor:
        altitude = rng.uniform(2.8, 4.0) if r < 0.5 else rng.uniform(4.0, 8.0)
    elif high:
        altitude = rng.uniform(3.0, 4.0) if r < 0.5 else rng.uniform(4.0, 8.0)
    else:
        altitude = rng.uniform(2.5, 3.5) if r < 0.8 else rng.uniform(3.5, 4.0)
    size = CALIBRATION_SIZE
    while True:
        theta_max = rng.uniform(90.0, 100.0)
        kb = [1.0, rng.uniform(-0.05, 0.01), rng.uniform(-0.002, 0.004)]
        t = np.radians(theta_max)
        r_max = kb[0] * t + kb[1] * t ** 3 + kb[2] * t ** 5
        circle = rng.uniform(0.43, 0.5) if rng.random() < 0.85 else rng.uniform(0.5, 0.56)
        fx = circle * size / r_max
        try:
            return FisheyeCamera(
                id=camera_id,
                altitude_m=round(float(altitude), 3),
                image_size=(size, size),
                principal_point=(float(size / 2 - 0.5 + rng.uniform(-25, 25)),
                                 float(size / 2 - 0.5 + rng.uniform(-25, 25))),
                focal_px=(float(fx), float(fx * (1 + rng.uniform(-0.004, 0.004)))),
                kb=[round(k, 6) for k in kb],
                max_theta_deg=round(float(theta_max), 3),
            )
        except (ValueError, CalibrationError):
            continue


def _room(rng: np.random.Generator, size: tuple[float, float]) -> tuple[float, float, float, float]:
    """A rectangle of `size` (m) placed so the nadir lies inside it, away from the walls."""
    w, d = size
    x0 = -w * rng.uniform(0.25, 0.75)
    y0 = -d * rng.uniform(0.25, 0.75)
    return float(x0), float(y0), float(x0 + w), float(y0 + d)


def _free_spot(rng: np.random.Generator, room: tuple[float, float, float, float], radius: float,
               placed: list[obj.Placed]) -> tuple[float, float] | None:
    """A point of `room` at least `radius` from its walls and clear of the placed objects."""
    x0, y0, x1, y1 = room
    if x1 - x0 <= 2 * radius or y1 - y0 <= 2 * radius:
        return None
    for _ in range(20):
        x, y = rng.uniform(x0 + radius, x1 - radius), rng.uniform(y0 + radius, y1 - radius)
        if all(np.hypot(o.footprint[0] - x, o.footprint[1] - y) > o.footprint[2] + radius for o in placed):
            return float(x), float(y)
    return None


def _table_set(rng: np.random.Generator, x: float, y: float, yaw: float, length: float, depth: float,
               top: Material, legs: Material, seat: Material, sides: tuple[int, ...]) -> list[obj.Placed]:
    """A table with chairs along the given sides (+1 / -1 along the table's y axis)."""
    height = rng.uniform(0.72, 0.76)
    desk = obj.table(x, y, yaw, length, depth, height, top, legs)
    # Clutter on the table: papers, laptops, bags.
    for _ in range(rng.integers(0, 2 + int(length))):
        lx = rng.uniform(-length / 2 + 0.2, length / 2 - 0.2)
        ly = rng.uniform(-depth / 2 + 0.15, depth / 2 - 0.15)
        r = rng.random()
        size = (np.array([0.15, 0.11, 0.003]) if r < 0.5 else np.array([0.17, 0.12, 0.012]) if r < 0.8
                else np.array([0.18, 0.1, 0.12]))
        color = (np.full(3, 0.85) if r < 0.5 else np.full(3, rng.uniform(0.03, 0.5)) if r < 0.8
                 else clothing_color(rng))
        turn = yaw + rng.normal(0, 0.3)
        centre = np.array([x, y, 0.0]) + yaw_frame(yaw) @ np.array([lx, ly, height + size[2]])
        desk.primitives.append(make_box(centre, size, turn, mat(color)))
    out = [desk]
    count = max(1, int(length / 0.7))
    frame = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    for side in sides:
        for k in range(count):
            if rng.random() < 0.15:
                continue
            along = (k + 0.5) * length / count - length / 2
            local = np.array([along + rng.normal(0, 0.05), side * (depth / 2 + rng.uniform(0.2, 0.45))])
            cx, cy = np.array([x, y]) + frame @ local
            facing = yaw - side * np.pi / 2 + rng.normal(0, 0.2)
            out.append(obj.chair(float(cx), float(cy), float(facing), 0.46, seat, legs))
    return out


def _workstation(rng: np.random.Generator, x: float, y: float, yaw: float, width: float, depth: float,
                 top: Material, legs: Material, screen: Material, chair_seat: Material,
                 chair_frame: Material) -> list[obj.Placed]:
    """One office desk whose user faces `yaw` from (x, y)'s front side: monitors at the back edge,
    a keyboard and papers, and an office chair pushed in, pulled out or turned (15 % none)."""
    height = rng.uniform(0.72, 0.76)
    desk = obj.table(x, y, yaw, width, depth, height, top, legs)
    frame = yaw_frame(yaw)

    def on_desk(local: tuple[float, float, float], half: NDArray[np.float64], turn: float,
                material: Material) -> None:
        centre = np.array([x, y, 0.0]) + frame @ np.asarray(local, np.float64)
        desk.primitives.append(make_box(centre, half, yaw + turn, material))

    # The desk's local x runs along its width; its user sits on the -y side, facing +y.
    monitors = int(rng.choice([1, 1, 2]))
    for k in range(monitors):
        offset = (k - (monitors - 1) / 2) * 0.55 + rng.normal(0, 0.05)
        tall = rng.uniform(0.28, 0.38)
        on_desk((offset, depth / 2 - 0.18, height + 0.1 + tall / 2), np.array([0.26, 0.015, tall / 2]),
                rng.normal(0, 0.12), screen)
        on_desk((offset, depth / 2 - 0.12, height + 0.05), np.array([0.03, 0.03, 0.05]), 0.0, screen)
    on_desk((rng.normal(0, 0.05), -depth / 2 + 0.2, height + 0.012), np.array([0.22, 0.07, 0.012]),
            rng.normal(0, 0.1), mat(np.full(3, rng.uniform(0.05, 0.8))))
    for _ in range(rng.integers(0, 4)):  # papers, folders, cups
        r = rng.random()
        half = (np.array([0.15, 0.11, 0.003]) if r < 0.6 else np.array([0.12, 0.16, 0.03]) if r < 0.85
                else np.array([0.04, 0.04, 0.05]))
        color = np.full(3, rng.uniform(0.8, 0.95)) if r < 0.6 else clothing_color(rng)
        on_desk((rng.uniform(-width / 2 + 0.2, width / 2 - 0.2), rng.uniform(-depth / 2 + 0.12, depth / 4),
                 height + half[2]), half, rng.uniform(0, np.pi), mat(color))
    out = [desk]
    if rng.random() < 0.85:
        pulled = rng.uniform(0.25, 0.7)
        cx, cy = np.array([x, y]) + frame[:2, :2] @ np.array([rng.normal(0, 0.15), -depth / 2 - pulled])
        facing = yaw + np.pi / 2 + rng.normal(0, 0.5 if rng.random() < 0.7 else 1.5)
        out.append(obj.chair(float(cx), float(cy), float(facing), rng.uniform(0.44, 0.52), chair_seat,
                             chair_frame))
    return out


def _office_floor(rng: np.random.Generator, split: str, room: tuple[float, float, float, float],
                  top: Material, legs: Material) -> list[obj.Placed]:
    """Open-plan benching: rows of desk pairs facing each other across a screen, aisles between
    the rows, storage along a wall."""
    x0, y0, x1, y1 = room
    along_x = bool(rng.random() < 0.5)
    # Work in a frame where the rows run along u; (u, v) -> (x, y) swaps the axes for rows along y.
    u0, u1, v0, v1 = (x0, x1, y0, y1) if along_x else (y0, y1, x0, x1)
    width, depth = rng.uniform(1.2, 1.6), rng.uniform(0.7, 0.8)
    aisle = rng.uniform(1.4, 2.2)
    pitch = 2 * depth + aisle
    screen = mat(np.full(3, rng.uniform(0.03, 0.15)))
    fabric = mat(scene_color("rug", split, rng) * rng.uniform(0.6, 1.0))
    chair_seat = mat(scene_color("furniture", split, rng) * rng.uniform(0.3, 1.0))
    chair_frame = mat(np.full(3, rng.uniform(0.05, 0.3)))
    screen_h = rng.uniform(1.05, 1.35)
    items: list[obj.Placed] = []
    margin = rng.uniform(1.0, 2.0)
    for v in np.arange(v0 + margin + depth, v1 - margin - depth + 1e-6, pitch):
        n = int((u1 - u0 - 2 * margin) // width)
        if n < 1:
            continue
        start = u0 + (u1 - u0 - n * width) / 2
        for k in range(n):
            u = start + (k + 0.5) * width
            for side in (-1, 1):  # the two desks of a pair face each other across the screen at v
                w = v + side * depth / 2
                x, y = (u, w) if along_x else (w, u)
                # Its user sits on the aisle side, facing the screen: the desk's local +y points to v.
                yaw = (np.pi if side > 0 else 0.0) if along_x else (np.pi / 2 if side > 0 else -np.pi / 2)
                items += _workstation(rng, float(x), float(y), yaw, width, depth, top, legs, screen,
                                      chair_seat, chair_frame)
            # The screen in one piece a desk, so that the lens's clearance removes only those above it.
            centre = np.array([u, v, screen_h / 2] if along_x else [v, u, screen_h / 2])
            items.append(obj.Placed([make_box(centre, np.array([width / 2, 0.02, screen_h / 2]),
                                              0.0 if along_x else np.pi / 2, fabric)],
                                    (float(centre[0]), float(centre[1]), 0.05)))
    for _ in range(rng.integers(0, 4)):  # storage along the walls
        length = rng.uniform(0.8, 2.0)
        cx, cy, yaw = ((rng.uniform(x0 + 1, x1 - 1), y1 - 0.3, 0.0) if rng.random() < 0.5
                       else (x0 + 0.3, rng.uniform(y0 + 1, y1 - 1), np.pi / 2))
        if all(np.hypot(o.footprint[0] - cx, o.footprint[1] - cy) > o.footprint[2] + 0.6 for o in items):
            items.append(obj.cabinet(float(cx), float(cy), yaw, length, 0.5, rng.uniform(0.7, 1.9),
                                     mat(scene_color("furniture", split, rng))))
    return items


def _indoor(rng: np.random.Generator, split: str, style: str, altitude: float
            ) -> tuple[Environment, list[obj.Placed], tuple[float, float, float, float]]:
    sizes = {"room": (5, 12), "classroom": (7, 14), "library": (10, 25), "hall": (15, 45), "office": (8, 24)}
    lo, hi = sizes[style]
    room = _room(rng, (rng.uniform(lo, hi), rng.uniform(lo, hi)))
    x0, y0, x1, y1 = room
    kinds = {"room": ("tiles", "carpet", "wood"), "classroom": ("tiles", "carpet", "wood"),
             "library": ("carpet", "wood", "carpet"), "hall": ("tiles", "concrete", "wood"),
             "office": ("tiles", "carpet", "tiles")}
    floor_kind = str(rng.choice(kinds[style]))
    floor = floor_texture(floor_kind, scene_palette(floor_kind, split, rng), rng, rng.uniform(0.3, 0.6))
    second_kind = "carpet" if floor_kind != "carpet" else "tiles"
    second = floor_texture(second_kind, scene_palette(second_kind, split, rng), rng, 0.5)
    canvas = floor_canvas(room, 0.03)
    canvas.multiply_noise(rng, 0.08, 3, slice(0, 3))
    for _ in range(rng.integers(0, 3) if style in ("room", "hall") else 0):
        w, d = rng.uniform(1.5, 4), rng.uniform(1.2, 3)
        cx, cy = rng.uniform(x0 + w / 2, x1 - w / 2), rng.uniform(y0 + d / 2, y1 - d / 2)
        canvas.rect(cx - w / 2, cy - d / 2, cx + w / 2, cy + d / 2, np.array([1, 1, 1, 0, 1.0]))
    if rng.random() < 0.2:
        color = scene_color("rug", split, rng)
        y = rng.uniform(y0 + 1, y1 - 1)
        paint_stripe(canvas, np.array([x0, y]), np.array([x1, y]), 0.05, color, 0.8)
    lamps = []
    spacing = rng.uniform(2.0, 4.0)
    for lx in np.arange(x0 + spacing / 2, x1, spacing):
        for ly in np.arange(y0 + spacing / 2, y1, spacing):
            lamps.append((lx, ly, rng.uniform(0.1, 0.35)))
    canvas.multiply_light(np.array(lamps).reshape(-1, 3), spacing * 0.35)
    darken_edges(canvas, room, rng.uniform(0.15, 0.4), rng.uniform(0.2, 0.45))
    wall_h = altitude + rng.uniform(0.02, 0.4)
    paint = scene_color("wall", split, rng)
    walls = WallPainter(room, wall_h, 0.02, paint)
    wood = scene_color("wood", split, rng)
    paint_room_walls(walls, rng, paint, scene_color("wall", split, rng) * 0.8, wood, style == "classroom")
    env = Environment(
        indoor=True, room_m=room, wall_height_m=wall_h, floor=floor, floor_second=second,
        floor_overlay=canvas.texture(), walls=walls.texture(),
        ceiling_color=mat(np.clip(paint * 1.1, 0, 1)).color,
        sky_colors=((0.6, 0.7, 0.9), (0.3, 0.45, 0.8)),
    )
    top = Material(mat(wood).color, PATTERN_GRAIN, mat(wood * 0.6).color, 0.03)
    legs = mat(scene_color("furniture", split, rng) * 0.5)
    seat = mat(scene_color("furniture", split, rng))
    items: list[obj.Placed] = []
    if style == "classroom":
        rows, cols = rng.integers(3, 6), rng.integers(2, 4)
        gap_y = (y1 - y0 - 2.5) / rows
        gap_x = (x1 - x0 - 1.0) / cols
        for i in range(rows):
            for j in range(cols):
                cx = x0 + 0.5 + (j + 0.5) * gap_x
                cy = y0 + 2.0 + (i + 0.5) * gap_y
                length = min(gap_x * 0.8, rng.uniform(1.2, 2.4))
                items += _table_set(rng, float(cx), float(cy), 0.0, length, 0.6, top, legs, seat, (-1,))
    elif style == "library":
        split_x = x0 + (x1 - x0) * rng.uniform(0.35, 0.65)
        spacing_s = rng.uniform(1.8, 2.8)
        books = obj.books(scene_color("rug", split, rng), scene_color("furniture", split, rng),
                          rng.uniform(0.28, 0.4))
        for sy in np.arange(y0 + 1.5, y1 - 1.0, spacing_s):
            items.append(obj.shelf(float((x0 + split_x) / 2), float(sy), 0.0, (split_x - x0) * 0.8, 0.45,
                                   rng.uniform(1.2, 2.1), mat(wood), books))
        for _ in range(rng.integers(2, 6)):
            cx, cy = rng.uniform(split_x + 1.5, x1 - 1.5), rng.uniform(y0 + 1.5, y1 - 1.5)
            items += _table_set(rng, float(cx), float(cy), float(rng.choice([0, np.pi / 2])),
                                rng.uniform(1.4, 2.6), rng.uniform(0.8, 1.2), top, legs, seat, (-1, 1))
    elif style == "office":
        items += _office_floor(rng, split, room, top, legs)
    elif style == "room":
        for _ in range(rng.integers(2, 6)):
            length, depth = rng.uniform(1.2, 3.2), rng.uniform(0.7, 1.2)
            spot = _free_spot(rng, room, 0.5 * np.hypot(length, depth) + 0.8, items)
            if spot is not None:
                items += _table_set(rng, spot[0], spot[1], float(rng.choice([0, np.pi / 2])), length, depth,
                                    top, legs, seat, (-1, 1))
        for _ in range(rng.integers(0, 4)):  # desks against the walls
            length = rng.uniform(1.0, 1.8)
            along_x = rng.random() < 0.5
            if along_x:
                side = rng.choice([-1, 1])
                cx, cy, yaw = rng.uniform(x0 + 1, x1 - 1), (y1 - 0.4 if side > 0 else y0 + 0.4), 0.0
                sides: tuple[int, ...] = (-int(side),)
            else:
                side = rng.choice([-1, 1])
                cx, cy, yaw = (x1 - 0.4 if side > 0 else x0 + 0.4), rng.uniform(y0 + 1, y1 - 1), np.pi / 2
                sides = (int(side),)
            if all(np.hypot(o.footprint[0] - cx, o.footprint[1] - cy) > o.footprint[2] + 1.0 for o in items):
                items += _table_set(rng, float(cx), float(cy), yaw, length, 0.7, top, legs, seat, sides)
        for _ in range(rng.integers(1, 4)):
            along_x = rng.random() < 0.5
            length = rng.uniform(0.8, 2.0)
            if along_x:
                cx, cy, yaw = rng.uniform(x0 + 1, x1 - 1), y1 - 0.3, 0.0
            else:
                cx, cy, yaw = x0 + 0.3, rng.uniform(y0 + 1, y1 - 1), np.pi / 2
            if all(np.hypot(o.footprint[0] - cx, o.footprint[1] - cy) > o.footprint[2] + 0.6 for o in items):
                items.append(obj.cabinet(float(cx), float(cy), yaw, length, 0.5, rng.uniform(0.7, 1.1),
                                         mat(scene_color("furniture", split, rng))))
        if rng.random() < 0.4:
            items.append(obj.sofa(float(x1 - 0.6), float(rng.uniform(y0 + 1.5, y1 - 1.5)), np.pi,
                                  rng.uniform(1.4, 2.4), mat(scene_color("rug", split, rng))))
    else:  # hall
        pitch = rng.uniform(6, 10)
        round_ = bool(rng.random() < 0.5)
        for px in np.arange(x0 + pitch, x1 - 1, pitch):
            for py in np.arange(y0 + pitch, y1 - 1, pitch):
                if np.hypot(px, py) > 1.0:
                    items.append(obj.pillar(float(px), float(py), wall_h, rng.uniform(0.2, 0.4),
                                            mat(paint * 0.9), round_))
        for _ in range(rng.integers(0, 6)):
            items.append(obj.bench(float(rng.uniform(x0 + 1, x1 - 1)), float(rng.uniform(y0 + 1, y1 - 1)),
                                   float(rng.uniform(0, 2 * np.pi)), rng.uniform(1.2, 2.5),
                                   mat(wood), legs))
    for _ in range(rng.integers(0, 4)):
        px, py = float(rng.choice([x0 + 0.4, x1 - 0.4])), float(rng.uniform(y0 + 0.5, y1 - 0.5))
        items.append(obj.plant(px, py,
                               mat(scene_color("furniture", split, rng)),
                               mat(scene_color("foliage", split, rng)), rng.uniform(0.7, 1.6)))
    return env, items, (x0 + 0.3, y0 + 0.3, x1 - 0.3, y1 - 0.3)


def _outdoor(rng: np.random.Generator, split: str, style: str
             ) -> tuple[Environment, list[obj.Placed], tuple[float, float, float, float]]:
    items: list[obj.Placed] = []
    white = np.array([0.8, 0.8, 0.78])
    asphalt = floor_texture("asphalt", scene_palette("asphalt", split, rng), rng, 0.5)
    paving = floor_texture("paving", scene_palette("paving", split, rng), rng, rng.uniform(0.2, 0.5))
    grass = floor_texture("grass", scene_palette("grass", split, rng), rng, 0.5)
    facade = np.array([scene_color("facade", split, rng) for _ in range(4)])
    bark = mat(np.array([0.12, 0.08, 0.05]))
    leaves = mat(scene_color("foliage", split, rng))
    metal = mat(np.full(3, rng.uniform(0.05, 0.4)))
    cars = [mat(scene_color("car", split, rng)) for _ in range(4)]
    glass, tyre = mat(np.array([0.03, 0.04, 0.05])), mat(np.full(3, 0.02))
    if style == "street":
        road = rng.uniform(3.0, 7.0)
        walk = rng.uniform(2.5, 6.0)
        offset = rng.uniform(-(road + walk * 0.8), road * 0.3)
        room = (-rng.uniform(60, 150), offset - road - walk, rng.uniform(60, 150), offset + road + walk)
        floor, second = asphalt, paving
        canvas = floor_canvas((room[0], room[1], room[2], room[3]), 0.04)
        canvas.rect(room[0], room[1], room[2], offset - road, np.array([1, 1, 1, 0, 1.0]))
        canvas.rect(room[0], offset + road, room[2], room[3], np.array([1, 1, 1, 0, 1.0]))
        for edge in (offset - road, offset + road):
            paint_stripe(canvas, np.array([room[0], edge]), np.array([room[2], edge]), 0.2, white * 0.9, 0.8)
        dash = rng.uniform(2, 4)
        for x in np.arange(room[0], room[2], dash * 2.5):
            paint_stripe(canvas, np.array([x, offset]), np.array([x + dash, offset]), 0.12, white)
        cross = rng.uniform(-10, 10)
        for y in np.arange(offset - road + 0.3, offset + road - 0.3, 0.9):
            paint_stripe(canvas, np.array([cross - 2, y + 0.25]), np.array([cross + 2, y + 0.25]), 0.45,
                         white)
        for x in np.arange(room[0] + 5, room[2] - 5, rng.uniform(5, 9)):
            if abs(x - cross) > 4 and rng.random() < 0.5:
                side = rng.choice([-1, 1])
                yaw = float(rng.choice([0, np.pi]))
                items.append(obj.car(float(x), float(offset + side * (road - 1.2)), yaw,
                                     cars[rng.integers(4)], glass, tyre))
        for x in np.arange(room[0] + 3, room[2] - 3, rng.uniform(8, 20)):
            side = rng.choice([-1, 1])
            y = offset + side * (road + 0.5)
            if rng.random() < 0.5:
                items.append(obj.pole(float(x), float(y), rng.uniform(3, 6), 0.07, metal, None))
            else:
                items.append(obj.tree(float(x), float(y), rng.uniform(4, 7), rng.uniform(1.2, 2.2), bark,
                                      leaves, rng))
        walk_area = (room[0] + 1, room[1] + 0.3, room[2] - 1, room[3] - 0.3)
    else:
        half = rng.uniform(15, 40) if style == "square" else rng.uniform(20, 50)
        room = (-half * rng.uniform(0.6, 1.4), -half * rng.uniform(0.6, 1.4),
                half * rng.uniform(0.6, 1.4), half * rng.uniform(0.6, 1.4))
        canvas = floor_canvas(room, 0.04)
        if style == "square":
            floor, second = paving, grass
            for _ in range(rng.integers(0, 4)):
                w, d = rng.uniform(3, 10), rng.uniform(3, 10)
                cx, cy = rng.uniform(room[0], room[2]), rng.uniform(room[1], room[3])
                if np.hypot(cx, cy) > 4:
                    canvas.rect(cx - w / 2, cy - d / 2, cx + w / 2, cy + d / 2, np.array([1, 1, 1, 0, 1.0]))
            for _ in range(rng.integers(2, 10)):
                x, y = rng.uniform(room[0] + 2, room[2] - 2), rng.uniform(room[1] + 2, room[3] - 2)
                pick = rng.random()
                if np.hypot(x, y) < 3:
                    continue
                if pick < 0.4:
                    items.append(obj.bench(float(x), float(y), float(rng.uniform(0, 2 * np.pi)),
                                           rng.uniform(1.5, 2.5), mat(scene_color("wood", split, rng)),
                                           metal))
                elif pick < 0.7:
                    items.append(obj.tree(float(x), float(y), rng.uniform(4, 8), rng.uniform(1.5, 3), bark,
                                          leaves, rng))
                elif pick < 0.85:
                    items.append(obj.pole(float(x), float(y), rng.uniform(3, 6), 0.08, metal,
                                          mat(np.full(3, 0.9))))
                else:
                    items.append(obj.bin_(float(x), float(y), metal))
        else:
            floor, second = asphalt, paving
            bay_w, bay_l = rng.uniform(2.4, 2.8), rng.uniform(4.8, 5.5)
            aisle = rng.uniform(6, 8)
            rows_y = np.arange(room[1] + 2, room[3] - bay_l, 2 * bay_l + aisle)
            for ry in rows_y:
                for bx in np.arange(room[0] + 2, room[2] - 2, bay_w):
                    paint_stripe(canvas, np.array([bx, ry]), np.array([bx, ry + 2 * bay_l]), 0.12, white)
                    for half_row in (0, 1):
                        cy = ry + bay_l * (half_row + 0.5)
                        cx = bx + bay_w / 2
                        if rng.random() < 0.65 and np.hypot(cx, cy) > 3.0:
                            yaw = float(np.pi / 2 + rng.choice([0, np.pi]) + rng.normal(0, 0.04))
                            items.append(obj.car(float(cx), float(cy), yaw,
                                                 cars[rng.integers(4)], glass, tyre))
            for _ in range(rng.integers(0, 5)):
                x, y = rng.uniform(room[0] + 2, room[2] - 2), rng.uniform(room[1] + 2, room[3] - 2)
                if np.hypot(x, y) > 3:
                    items.append(obj.pole(float(x), float(y), rng.uniform(4, 7), 0.09, metal,
                                          mat(np.full(3, 0.9))))
        walk_area = (room[0] + 1, room[1] + 1, room[2] - 1, room[3] - 1)
    canvas.multiply_noise(rng, 0.15, 3, slice(0, 3))
    wall_h = rng.uniform(6, 25) if style != "parking" else rng.uniform(3, 12)
    sky = ((0.75, 0.8, 0.9), (0.35, 0.5, 0.85))
    walls = WallPainter(room, wall_h, 0.06, np.array(sky[0]))
    paint_facades(walls, rng, facade)
    env = Environment(
        indoor=False, room_m=room, wall_height_m=wall_h, floor=floor, floor_second=second,
        floor_overlay=canvas.texture(), walls=walls.texture(), ceiling_color=(0.5, 0.5, 0.5),
        sky_colors=sky,
    )
    return env, items, walk_area


STYLES = INDOOR_STYLES + OUTDOOR_STYLES + REQUESTED_STYLES


def build_scene(split: str, index: int, kind: str | None = None,
                camera: FisheyeCamera | None = None, style: str | None = None) -> Scene:
    """Scene `index` of `split`; `kind` forces indoor/outdoor, `style` one style of STYLES;
    `camera` replaces the scene's random one."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    rng = np.random.default_rng([SPLITS.index(split), int(index), 31337])
    drawn_kind = "indoor" if rng.random() < 0.55 else "outdoor"
    if style is not None:
        if style not in STYLES:
            raise ValueError(f"style must be one of {STYLES}, got {style!r}")
        kind = "outdoor" if style in OUTDOOR_STYLES else "indoor"
    kind = kind or drawn_kind
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    styles = INDOOR_STYLES if kind == "indoor" else OUTDOOR_STYLES
    drawn_style = str(styles[int(rng.integers(len(styles)))])
    style = style or drawn_style
    scene_id = f"{kind}-{style}-{split[0]}{index:04d}"
    cam = camera if camera is not None else sample_camera(rng, f"synth-{split[0]}{index:04d}",
                                                          kind == "outdoor", style == "hall")
    if kind == "indoor":
        env, items, walk = _indoor(rng, split, style, cam.altitude_m)
    else:
        env, items, walk = _outdoor(rng, split, style)
    # Nothing solid may stand where the lens is (pole cameras sit above the pole's foot).
    lens = np.array([0.0, 0.0, cam.altitude_m])
    items = [o for o in items if np.hypot(o.footprint[0], o.footprint[1]) > o.footprint[2] + 0.3
             and all(np.linalg.norm(p.center - lens) > p.radius_m + 0.1 for p in o.primitives)]
    return Scene(scene_id, split, kind, style, cam, env, items, walk)
