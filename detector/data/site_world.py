"""A site for synthetic sequences: one room seen by several overlapping cameras that share its frame.

A `SitePlan` is the floor plan in the site frame: the room (an axis-aligned rectangle), its doors,
the cameras (camera files with `site` and `site_pose`), and the zones and counting lines the
service is given. `build_site_world` dresses the plan for rendering: floor and wall textures,
painted doors, furniture kept clear of the doors and the walking area's middle. Every camera
renders the same world through its posed rays (`rays.posed_grid`), so a person or a table is where
one camera sees it in every other camera too.

`--site FILE` (YAML or JSON) holds the plan's fields: `id`, `room_m: [x0, y0, x1, y1]`, `cameras`
(camera files, each with `site_pose`), `doors` (`wall`: west/east/south/north, `at_m`: the door
centre's coordinate along that wall, `width_m`), `zones` (`{id: [[x, y], ...]}`) and `lines`
(`{id: {from_m: [x, y], to_m: [x, y]}}`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from detector.data import objects as obj
from detector.data.environment import Environment
from detector.data.palettes import scene_color, scene_palette
from detector.data.primitives import PATTERN_GRAIN, Material
from detector.data.scenes import CALIBRATION_SIZE, Scene, mat
from detector.data.surfaces import WallPainter, darken_edges, floor_canvas, paint_room_walls
from detector.data.textures import floor_texture
from fisheye import FisheyeCamera, SitePose, camera_to_dict, load_camera

FloatArray = NDArray[np.float64]

WALLS = ("west", "east", "south", "north")
SEQUENCE_SPLIT = "unseen"  # sequences are for evaluation: colours from the palettes training never saw
_DOOR_HEIGHT_M = 2.1


@dataclass(frozen=True)
class Door:
    """A door in `wall` (WALLS) centred at `at_m` along it (x for south/north, y for west/east)."""

    wall: str
    at_m: float
    width_m: float = 1.2

    def __post_init__(self) -> None:
        if self.wall not in WALLS:
            raise ValueError(f"door wall must be one of {WALLS}, got {self.wall!r}")

    def threshold_m(self, room_m: tuple[float, float, float, float], inset_m: float) -> FloatArray:
        """(2,) the floor point `inset_m` inside the room in front of the door."""
        x0, y0, x1, y1 = room_m
        return np.array({
            "west": (x0 + inset_m, self.at_m), "east": (x1 - inset_m, self.at_m),
            "south": (self.at_m, y0 + inset_m), "north": (self.at_m, y1 - inset_m),
        }[self.wall])


@dataclass(frozen=True)
class SitePlan:
    """The floor plan of a site in its frame (metres): see the module docstring."""

    site_id: str
    room_m: tuple[float, float, float, float]
    cameras: list[FisheyeCamera]
    doors: list[Door]
    zones: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    lines: dict[str, tuple[tuple[float, float], tuple[float, float]]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if len(self.cameras) < 1 or any(c.site_pose is None for c in self.cameras):
            raise ValueError("a site plan needs cameras, each with a site_pose")
        if len({c.id for c in self.cameras}) != len(self.cameras):
            raise ValueError("the site's camera ids must differ")
        if not self.doors:
            raise ValueError("a site plan needs at least one door")

    def camera_record(self, camera: FisheyeCamera) -> dict[str, Any]:
        """A camera's file as a dict, with the site it belongs to."""
        return {**camera_to_dict(camera), "site": self.site_id}

    def to_dict(self) -> dict[str, Any]:
        """The site as the sequence's annotations carry it: zones and lines as the service takes them."""
        return {
            "id": self.site_id,
            "room_m": list(self.room_m),
            "doors": [{"wall": d.wall, "at_m": d.at_m, "width_m": d.width_m} for d in self.doors],
            "zones": {name: {"polygon_m": [list(p) for p in polygon]}
                      for name, polygon in self.zones.items()},
            "lines": {name: {"from_m": list(a), "to_m": list(b)} for name, (a, b) in self.lines.items()},
        }


def _lens(camera_id: str, altitude_m: float, pose: SitePose, offset_px: tuple[float, float]) -> FisheyeCamera:
    """A 190° ceiling lens whose image circle nearly fills the frame, calibrated at 2048 px."""
    kb = [1.0, -0.02, 0.001]
    theta_max = math.radians(95.0)
    r_max = kb[0] * theta_max + kb[1] * theta_max ** 3 + kb[2] * theta_max ** 5
    fx = 0.47 * CALIBRATION_SIZE / r_max
    centre = CALIBRATION_SIZE / 2 - 0.5
    return FisheyeCamera(
        id=camera_id, altitude_m=altitude_m, image_size=(CALIBRATION_SIZE, CALIBRATION_SIZE),
        principal_point=(centre + offset_px[0], centre + offset_px[1]), focal_px=(fx, fx * 1.002),
        kb=kb, max_theta_deg=95.0, site_pose=pose,
    )


def default_plan() -> SitePlan:
    """The built-in site: a 15 m x 9 m hall, two 3 m-high cameras 6.5 m apart turned 35° from each
    other, a door in the west wall with a counting line 1.5 m inside it, a door in the north wall
    with its own line, and three zones (the entrance, the middle where both cameras overlap, a
    counter in the south-east corner)."""
    cameras = [
        _lens("hall-west", 3.0, SitePose(x_m=-3.25, y_m=0.3, yaw_deg=0.0), (6.0, -9.0)),
        _lens("hall-east", 3.1, SitePose(x_m=3.25, y_m=-0.3, yaw_deg=35.0), (-11.0, 4.0)),
    ]
    return SitePlan(
        site_id="synth-hall",
        room_m=(-7.5, -4.5, 7.5, 4.5),
        cameras=cameras,
        doors=[Door("west", 0.0, 1.4), Door("north", 4.0, 1.2)],
        zones={
            "entrance": [(-7.5, -2.0), (-4.5, -2.0), (-4.5, 2.0), (-7.5, 2.0)],
            "middle": [(-2.0, -2.5), (2.0, -2.5), (2.0, 2.5), (-2.0, 2.5)],
            "counter": [(4.0, -4.5), (7.5, -4.5), (7.5, -1.5), (4.0, -1.5)],
        },
        # Looking from `from_m` to `to_m` the door is on the left: walking in counts `in`.
        lines={
            "west-door": ((-6.0, -1.2), (-6.0, 1.2)),
            "north-door": ((2.9, 3.0), (5.1, 3.0)),
        },
    )


def load_plan(path: str | Path) -> SitePlan:
    """A site plan from a YAML or JSON file (the module docstring's fields)."""
    document = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    if not isinstance(document, dict):
        raise ValueError(f"{path}: a site file is a mapping")
    site_id = str(document["id"])
    cameras = [load_camera({k: v for k, v in record.items() if k != "site"})
               for record in document["cameras"]]
    room = tuple(float(v) for v in document["room_m"])
    if len(room) != 4 or room[0] >= room[2] or room[1] >= room[3]:
        raise ValueError(f"{path}: room_m must be [x0, y0, x1, y1] with x0 < x1 and y0 < y1")
    lines = {name: (tuple(line["from_m"]), tuple(line["to_m"]))
             for name, line in (document.get("lines") or {}).items()}
    return SitePlan(
        site_id=site_id,
        room_m=(room[0], room[1], room[2], room[3]),
        cameras=cameras,
        doors=[Door(str(d["wall"]), float(d["at_m"]), float(d.get("width_m", 1.2)))
               for d in document["doors"]],
        zones={name: [(float(x), float(y)) for x, y in polygon]
               for name, polygon in (document.get("zones") or {}).items()},
        lines=lines,
    )


@dataclass(frozen=True)
class SiteWorld:
    """A plan dressed for rendering: `scene` (its environment and fixed objects; its camera is the
    plan's first), `obstacles` (K, 3) footprint circles (x, y, radius m) people walk round, and
    `walk_m` the floor area where people may stand."""

    plan: SitePlan
    scene: Scene
    obstacles: FloatArray


def _wall_span(plan: SitePlan, door: Door) -> tuple[float, float]:
    """The door's (s0, s1) along the unrolled walls (see `environment.Environment.walls`)."""
    x0, y0, x1, y1 = plan.room_m
    width, depth = x1 - x0, y1 - y0
    half = door.width_m / 2
    centre = {"south": door.at_m - x0, "east": width + door.at_m - y0,
              "north": width + depth + x1 - door.at_m, "west": 2 * width + depth + y1 - door.at_m}[door.wall]
    return centre - half, centre + half


def _furniture(rng: np.random.Generator, plan: SitePlan, keep_clear: list[FloatArray]) -> list[obj.Placed]:
    """Tables with chairs, benches, cabinets and plants along the walls, off the doors' approaches."""
    x0, y0, x1, y1 = plan.room_m
    top = Material(mat(scene_color("wood", SEQUENCE_SPLIT, rng)).color, PATTERN_GRAIN,
                   mat(scene_color("wood", SEQUENCE_SPLIT, rng) * 0.6).color, 0.03)
    legs = mat(scene_color("furniture", SEQUENCE_SPLIT, rng) * 0.5)
    seat = mat(scene_color("furniture", SEQUENCE_SPLIT, rng))
    candidates: list[obj.Placed] = [
        obj.cabinet(float(x1 - 0.35), float(y0 + 1.8), np.pi / 2, 2.4, 0.5, 1.0,
                    mat(scene_color("furniture", SEQUENCE_SPLIT, rng))),
        obj.bench(float(x0 + 2.5), float(y1 - 0.5), 0.0, 1.8, mat(scene_color("wood", SEQUENCE_SPLIT, rng)),
                  legs),
        obj.bench((-1.0), float(y0 + 0.5), 0.0, 2.0, mat(scene_color("wood", SEQUENCE_SPLIT, rng)), legs),
        obj.table(float(x0 + 1.6), float(y0 + 1.2), 0.0, 1.6, 0.8, 0.74, top, legs),
        obj.chair(float(x0 + 1.2), float(y0 + 0.5), np.pi / 2, 0.46, seat, legs),
        obj.chair(float(x0 + 2.0), float(y0 + 0.5), np.pi / 2, 0.46, seat, legs),
    ]
    for px, py in ((x1 - 0.4, y1 - 0.4), (x0 + 0.4, y1 - 0.4), (x1 - 0.4, y0 + 0.4)):
        candidates.append(obj.plant(float(px), float(py), mat(scene_color("furniture", SEQUENCE_SPLIT, rng)),
                                    mat(scene_color("foliage", SEQUENCE_SPLIT, rng)), rng.uniform(0.8, 1.5)))
    lenses = [np.array([c.site_pose.x_m, c.site_pose.y_m]) for c in plan.cameras if c.site_pose]
    out = []
    for item in candidates:
        centre, radius = np.array(item.footprint[:2]), item.footprint[2]
        if all(np.hypot(*(centre - p)) > radius + 1.6 for p in keep_clear) and \
                all(np.hypot(*(centre - p)) > radius + 0.5 for p in lenses):
            out.append(item)
    return out


def build_site_world(plan: SitePlan, seed: int) -> SiteWorld:
    """Textures, doors and furniture of `plan`; the colours and furniture depend on `seed` only."""
    rng = np.random.default_rng([int(seed), 4242])
    room = plan.room_m
    altitude = max(c.altitude_m for c in plan.cameras)
    floor_kind = str(rng.choice(("tiles", "wood", "concrete")))
    floor = floor_texture(floor_kind, scene_palette(floor_kind, SEQUENCE_SPLIT, rng), rng,
                          rng.uniform(0.3, 0.6))
    second = floor_texture("carpet", scene_palette("carpet", SEQUENCE_SPLIT, rng), rng, 0.5)
    canvas = floor_canvas(room, 0.03)
    canvas.multiply_noise(rng, 0.08, 3, slice(0, 3))
    spacing = 3.0
    lamps = [(lx, ly, rng.uniform(0.1, 0.3)) for lx in np.arange(room[0] + 1.5, room[2], spacing)
             for ly in np.arange(room[1] + 1.5, room[3], spacing)]
    canvas.multiply_light(np.array(lamps).reshape(-1, 3), spacing * 0.35)
    darken_edges(canvas, room, rng.uniform(0.15, 0.4), rng.uniform(0.2, 0.45))
    wall_h = altitude + rng.uniform(0.1, 0.4)
    paint = scene_color("wall", SEQUENCE_SPLIT, rng)
    walls = WallPainter(room, wall_h, 0.02, paint)
    wood = scene_color("wood", SEQUENCE_SPLIT, rng)
    paint_room_walls(walls, rng, paint, scene_color("wall", SEQUENCE_SPLIT, rng) * 0.8, wood, False)
    for door in plan.doors:  # a dark opening in a frame: the way in and out
        s0, s1 = _wall_span(plan, door)
        walls.framed(s0 - 0.06, 0.0, s1 + 0.06, _DOOR_HEIGHT_M + 0.06, np.full(3, 0.04), paint * 0.5, 0.06)
    env = Environment(
        indoor=True, room_m=room, wall_height_m=wall_h, floor=floor, floor_second=second,
        floor_overlay=canvas.texture(), walls=walls.texture(),
        ceiling_color=mat(np.clip(paint * 1.1, 0, 1)).color,
        sky_colors=((0.6, 0.7, 0.9), (0.3, 0.45, 0.8)),
    )
    keep_clear = [d.threshold_m(room, 0.8) for d in plan.doors]
    items = _furniture(rng, plan, keep_clear)
    walk = (room[0] + 0.3, room[1] + 0.3, room[2] - 0.3, room[3] - 0.3)
    scene = Scene(f"site-{plan.site_id}-{seed}", SEQUENCE_SPLIT, "indoor", "hall", plan.cameras[0], env,
                  items, walk)
    obstacles = np.array([o.footprint for o in items], dtype=np.float64).reshape(-1, 3)
    return SiteWorld(plan, scene, obstacles)
