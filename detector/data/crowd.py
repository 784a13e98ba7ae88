"""The people of one frame: how many, where they stand or sit, their pose, size and clothes."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from detector.data import objects as obj
from detector.data.body import ARM_POSES, PersonSpec, seat_height_for
from detector.data.palettes import clothing_color, hair_color, skin_color
from detector.data.primitives import PATTERN_CHECKS, PATTERN_PLAIN, PATTERN_STRIPES, Material
from detector.data.scenes import Scene

FloatArray = NDArray[np.float64]

MAX_PEOPLE = 60
_PERSON_GAP_M = 0.55
_OBJECT_MARGIN_M = 0.25


def _rgb(color: FloatArray) -> tuple[float, float, float]:
    return float(color[0]), float(color[1]), float(color[2])


def sample_count(rng: np.random.Generator) -> int:
    """0-60 people: a few empty frames, mostly 1-25, some crowds."""
    r = rng.random()
    if r < 0.04:
        return 0
    if r < 0.55:
        return int(rng.integers(1, 11))
    if r < 0.85:
        return int(rng.integers(10, 26))
    return int(rng.integers(25, MAX_PEOPLE + 1))


def _clothes(rng: np.random.Generator) -> dict[str, Material | bool | str]:
    top_color = clothing_color(rng)
    pattern = rng.choice([PATTERN_PLAIN, PATTERN_STRIPES, PATTERN_CHECKS], p=[0.72, 0.18, 0.1])
    top = Material(_rgb(top_color), int(pattern), _rgb(clothing_color(rng)), float(rng.uniform(0.03, 0.12)))
    r = rng.random()
    if r < 0.4:
        bottom_color = np.array([0.05, 0.08, 0.18]) * rng.uniform(0.6, 2.0)  # denim
    elif r < 0.75:
        bottom_color = np.full(3, rng.uniform(0.01, 0.06))
    else:
        bottom_color = clothing_color(rng)
    shoes = np.full(3, 0.02) if rng.random() < 0.6 else clothing_color(rng)
    hair_style = str(rng.choice(["short", "long", "bald", "hat"], p=[0.5, 0.25, 0.1, 0.15]))
    return {
        "skin": Material(_rgb(skin_color(rng))),
        "hair": Material(_rgb(hair_color(rng))),
        "top": top,
        "bottom": Material(_rgb(np.clip(bottom_color, 0, 1))),
        "shoes": Material(_rgb(shoes)),
        "item": Material(_rgb(clothing_color(rng))),
        "hair_style": hair_style,
        "long_sleeves": bool(rng.random() < 0.6),
        "long_legs": bool(rng.random() < 0.85),
    }


def sample_person(rng: np.random.Generator, x: float, y: float, heading: float, pose: str) -> PersonSpec:
    """A person of random size, clothes and carried item at (x, y) facing `heading` in `pose`."""
    carried = "none"
    if pose != "sitting":
        carried = str(rng.choice(["none", "bag", "backpack", "box", "phone"],
                                 p=[0.55, 0.12, 0.15, 0.05, 0.13]))
    clothes = _clothes(rng)
    return PersonSpec(
        position_m=(x, y),
        heading_rad=heading,
        height_m=float(np.clip(rng.normal(1.71, 0.09), 1.5, 1.95)),
        width_scale=float(rng.uniform(0.85, 1.2)),
        pose=pose,
        phase_rad=float(rng.uniform(0, 2 * np.pi)),
        stride_rad=float(rng.uniform(0.25, 0.45)),
        lean_rad=float(rng.uniform(-0.12, 0.3) if pose == "sitting" else rng.uniform(-0.03, 0.1)),
        seat_height_m=0.46,
        carried=carried,
        arm_pose=str(rng.choice(ARM_POSES, p=[0.5, 0.15, 0.1, 0.15, 0.1])) if carried == "none" else "down",
        **clothes,  # type: ignore[arg-type]
    )


def place_people(rng: np.random.Generator, scene: Scene, count: int
                 ) -> tuple[list[PersonSpec], list[obj.Placed]]:
    """`count` people in `scene` (fewer if there is no room) and the chairs added for people who
    sit where the scene has no free seat."""
    x0, y0, x1, y1 = scene.walk_m
    reach = 30.0
    obstacles = np.array([o.footprint for o in scene.objects]).reshape(-1, 3)
    seats = [s for o in scene.objects for s in o.seats]
    free_seats = list(rng.permutation(len(seats)))
    taken: list[tuple[float, float]] = []
    people: list[PersonSpec] = []
    extra: list[obj.Placed] = []

    def free(x: float, y: float) -> bool:
        if not (x0 <= x <= x1 and y0 <= y <= y1):
            return False
        if len(obstacles) and np.any(np.hypot(obstacles[:, 0] - x, obstacles[:, 1] - y)
                                     < obstacles[:, 2] + _OBJECT_MARGIN_M):
            return False
        return all(np.hypot(px - x, py - y) >= _PERSON_GAP_M for px, py in taken)

    # Offices are worked in seated; elsewhere most people stand or walk.
    sit_share = 0.75 if scene.style == "office" else 0.35 if scene.kind == "indoor" else 0.1
    for _ in range(count):
        pose = str(rng.choice(["standing", "walking", "sitting"], p=[0.4 - sit_share / 2, 0.6 - sit_share / 2,
                                                                    sit_share]))
        if pose == "sitting" and free_seats:
            seat = seats[int(free_seats.pop())]
            if all(np.hypot(px - seat.x, py - seat.y) >= 0.45 for px, py in taken):
                spec = sample_person(rng, seat.x, seat.y, seat.yaw_rad, "sitting")
                people.append(replace(spec, seat_height_m=seat.height_m))
                taken.append((seat.x, seat.y))
                continue
        for _attempt in range(30):
            if taken and rng.random() < 0.3:  # join someone: groups and queues
                gx, gy = taken[int(rng.integers(len(taken)))]
                angle, dist = rng.uniform(0, 2 * np.pi), rng.uniform(0.6, 1.3)
                x, y = gx + dist * np.cos(angle), gy + dist * np.sin(angle)
            elif scene.kind == "indoor" and rng.random() < 0.6:
                x, y = rng.uniform(x0, x1), rng.uniform(y0, y1)
            elif scene.kind == "indoor":  # near the camera, where big rooms have few samples
                angle, dist = rng.uniform(0, 2 * np.pi), 6.0 * np.sqrt(rng.random())
                x, y = dist * np.cos(angle), dist * np.sin(angle)
            else:  # outdoor: denser near the camera, some out past 20 m
                angle = rng.uniform(0, 2 * np.pi)
                dist = reach * rng.random() ** 1.6
                x, y = dist * np.cos(angle), dist * np.sin(angle)
            if free(x, y):
                break
        else:
            continue
        heading = float(rng.uniform(0, 2 * np.pi))
        spec = sample_person(rng, float(x), float(y), heading, pose)
        if pose == "sitting":
            seat_h = seat_height_for(spec)
            chair_at = np.array([x, y]) + 0.07 * np.array([np.cos(heading), np.sin(heading)])
            frame = Material(_rgb(clothing_color(rng) * 0.5))
            extra.append(obj.chair(float(chair_at[0]), float(chair_at[1]), heading, seat_h,
                                   Material(_rgb(clothing_color(rng))), frame, bool(rng.random() < 0.8)))
            spec = replace(spec, seat_height_m=seat_h)
        people.append(spec)
        taken.append((float(x), float(y)))
    return people, extra
