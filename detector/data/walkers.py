"""People walking through a site: who enters when, by which door, where they go, pause and leave.

Each person follows a route of legs between waypoints at their own walking speed (1.0-1.5 m/s):
in through a door (or already inside when the sequence starts), to one to three places in the
room (some near the zones), pausing at some of them, and out through a door (or still inside at
the end). Some arrive as groups of two or three who walk side by side. A route is kept only when it
stays clear of the furniture and keeps 0.55 m from everyone already planned who is not in its
group (and 0.5 m from those who are), so bodies never pass through each other.

`sample_walkers` plans everyone from (seed, plan, steps); `Walker.state(step)` answers where a
person stands at a step, facing which way, walking or standing, and their gait phase.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from detector.data.site_world import SiteWorld

FloatArray = NDArray[np.float64]

_STRIDE_M = 1.4  # one gait cycle (two steps) at a normal walk
_GAP_M = 0.55  # closest two people who are not walking together come
_CLEAR_M = 0.3  # room kept between a person and furniture
_DOOR_INSET_M = 0.35  # where a person appears or vanishes in a doorway
_GROUP_SPACING_M = 0.65
_GROUP_GAP_M = 0.5  # closest two people walking together come (a sharp turn would cross their paths)


@dataclass(frozen=True)
class WalkerState:
    """One person at one step: `position_m` (2,) site frame, `heading_rad` counter-clockwise from
    +x, `walking` or standing, and the gait `phase_rad`."""

    position_m: tuple[float, float]
    heading_rad: float
    walking: bool
    phase_rad: float


@dataclass(frozen=True)
class Walker:
    """A planned person: `track_id` (1-based), per step `positions_m` (T, 2) (NaN while outside the
    site), `headings_rad` (T,), `walking` (T,) and `phase_rad` (T,)."""

    track_id: int
    positions_m: FloatArray
    headings_rad: FloatArray
    walking: NDArray[np.bool_]
    phase_rad: FloatArray

    def present(self, step: int) -> bool:
        return bool(np.isfinite(self.positions_m[step, 0]))

    def state(self, step: int) -> WalkerState:
        x, y = self.positions_m[step]
        return WalkerState((float(x), float(y)), float(self.headings_rad[step]), bool(self.walking[step]),
                           float(self.phase_rad[step]))


@dataclass(frozen=True)
class _Route:
    """Waypoints (K, 2) with the pause (s) at each, a start time (s) and a speed (m/s)."""

    points: FloatArray
    pauses: FloatArray
    start_s: float
    speed_mps: float
    # Per end (first, last): the axis (0: x, 1: y) across the wall of the doorway it is in, or None.
    door_axes: tuple[int | None, int | None] = (None, None)


def _sample_route(points: FloatArray, pauses: FloatArray, speed: float, start_s: float, times: FloatArray
                  ) -> tuple[FloatArray, NDArray[np.bool_], FloatArray]:
    """Positions (T, 2) (NaN before the start and after the end), walking flags (T,) and distance
    walked (T,) at `times` of a route walked at `speed` with `pauses` at its waypoints."""
    # Knots: arrive at each waypoint, then leave it after its pause.
    knot_t, knot_p, knot_d = [start_s], [points[0]], [0.0]
    t, walked = start_s + pauses[0], 0.0
    knot_t.append(t)
    knot_p.append(points[0])
    knot_d.append(walked)
    for k in range(1, len(points)):
        length = float(np.hypot(*(points[k] - points[k - 1])))
        t += length / speed
        walked += length
        knot_t += [t, t + pauses[k]]
        knot_p += [points[k], points[k]]
        knot_d += [walked, walked]
        t += pauses[k]
    kt, kp, kd = np.array(knot_t), np.array(knot_p), np.array(knot_d)
    inside = (times >= kt[0]) & (times <= kt[-1])
    x = np.interp(times, kt, kp[:, 0])
    y = np.interp(times, kt, kp[:, 1])
    distance = np.interp(times, kt, kd)
    positions = np.where(inside[:, None], np.stack([x, y], axis=1), np.nan)
    speed_now = np.gradient(distance, times) if len(times) > 1 else np.zeros_like(times)
    return positions, inside & (speed_now > 0.2 * speed), distance


class _Planner:
    """Draws routes in a site world and keeps those that collide with nothing already planned."""

    def __init__(self, world: SiteWorld, times: FloatArray, rng: np.random.Generator) -> None:
        self.world = world
        self.times = times
        self.rng = rng
        self.tracks: list[FloatArray] = []
        x0, y0, x1, y1 = world.plan.room_m
        self.area = (x0 + 0.6, y0 + 0.6, x1 - 0.6, y1 - 0.6)
        self.doors = [d.threshold_m(world.plan.room_m, _DOOR_INSET_M) for d in world.plan.doors]
        self.door_axes = [0 if d.wall in ("west", "east") else 1 for d in world.plan.doors]
        self.lines = [(np.array(a), np.array(b)) for a, b in world.plan.lines.values()]
        self.zone_centres = [np.mean(np.array(p), axis=0) for p in world.plan.zones.values()]

    def _clear_point(self, p: FloatArray) -> bool:
        x0, y0, x1, y1 = self.area
        if not (x0 <= p[0] <= x1 and y0 <= p[1] <= y1):
            return False
        obstacles = self.world.obstacles
        if len(obstacles) and np.any(np.hypot(*(obstacles[:, :2] - p).T) < obstacles[:, 2] + _CLEAR_M + 0.2):
            return False
        # Nobody stops on a counting line: a pause there would count nothing and look odd.
        return all(_segment_distance(p, a, b) > 1.0 for a, b in self.lines)

    def _clear_leg(self, a: FloatArray, b: FloatArray) -> bool:
        obstacles = self.world.obstacles
        return all(_segment_distance(o[:2], a, b) > o[2] + _CLEAR_M for o in obstacles)

    def waypoint(self) -> FloatArray | None:
        for _ in range(30):
            if self.zone_centres and self.rng.random() < 0.4:
                centre = self.zone_centres[int(self.rng.integers(len(self.zone_centres)))]
                p = centre + self.rng.normal(0.0, 0.8, 2)
            else:
                x0, y0, x1, y1 = self.area
                p = np.array([self.rng.uniform(x0, x1), self.rng.uniform(y0, y1)])
            if self._clear_point(p):
                return p
        return None

    def route(self, start_s: float, inside: bool, leave: bool) -> _Route | None:
        rng = self.rng
        points: list[FloatArray] = []
        axes: list[int | None] = [None, None]
        if inside:
            first = self.waypoint()
            if first is None:
                return None
            points.append(first)
        else:
            entry = int(rng.integers(len(self.doors)))
            points.append(self.doors[entry])
            axes[0] = self.door_axes[entry]
        for _ in range(int(rng.integers(1, 4))):
            p = self.waypoint()
            if p is None or not self._clear_leg(points[-1], p):
                return None
            points.append(p)
        if leave:
            exit_ = int(rng.integers(len(self.doors)))
            if not self._clear_leg(points[-1], self.doors[exit_]):
                return None
            points.append(self.doors[exit_])
            axes[1] = self.door_axes[exit_]
        pauses = np.where(rng.random(len(points)) < 0.45, rng.uniform(1.0, 6.0, len(points)), 0.0)
        pauses[0] = rng.uniform(2.0, 8.0) if inside else 0.0
        if leave:
            pauses[-1] = 0.0
        return _Route(np.array(points), pauses, start_s, float(rng.uniform(1.0, 1.5)), (axes[0], axes[1]))

    def companion_clear(self, route: _Route) -> bool:
        """A companion's shifted waypoints (its first and last may be doorways) and legs are clear."""
        last = len(route.points) - 1
        return all(self._clear_point(p) or k in (0, last) for k, p in enumerate(route.points)) and \
            all(self._clear_leg(a, b) for a, b in zip(route.points[:-1], route.points[1:], strict=True))

    def fits(self, positions: list[FloatArray]) -> bool:
        """True when none of `positions` (each (T, 2)) comes within _GAP_M of a planned track."""
        for mine in positions:
            for other in self.tracks:
                gap = np.hypot(*(mine - other).T)
                if np.nanmin(np.where(np.isfinite(gap), gap, np.inf)) < _GAP_M:
                    return False
        return True


def _apart(members: list[Walker], gap_m: float) -> bool:
    """True when no two of `members` ever come within `gap_m` of each other."""
    for k, one in enumerate(members):
        for other in members[k + 1:]:
            gap = np.hypot(*(one.positions_m - other.positions_m).T)
            if np.any(gap[np.isfinite(gap)] < gap_m):
                return False
    return True


def _segment_distance(p: FloatArray, a: FloatArray, b: FloatArray) -> float:
    ab = b - a
    along = float(np.clip((p - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0))
    return float(np.hypot(*(p - (a + along * ab))))


def _offset_route(route: _Route, side_m: float, delay_s: float) -> _Route:
    """A companion's route: the same waypoints shifted `side_m` to the left of each leg."""
    points = route.points.copy()
    for k in range(len(points)):
        a = route.points[max(k - 1, 0)]
        b = route.points[min(k + 1, len(points) - 1)]
        direction = (b - a) / max(float(np.hypot(*(b - a))), 1e-9)
        points[k] = route.points[k] + side_m * np.array([-direction[1], direction[0]])
    # Side by side in a doorway means along the wall: they come in (or go out) through it together.
    for k, axis in ((0, route.door_axes[0]), (len(points) - 1, route.door_axes[1])):
        if axis is not None:
            along = 1 - axis
            points[k, axis] = route.points[k, axis]
            points[k, along] = route.points[k, along] + np.sign(side_m) * min(abs(side_m), 0.5)
    return _Route(points, route.pauses, route.start_s + delay_s, route.speed_mps, route.door_axes)


def _walker(track_id: int, route: _Route, times: FloatArray, phase0: float) -> Walker:
    positions, walking, distance = _sample_route(route.points, route.pauses, route.speed_mps, route.start_s,
                                                 times)
    steps = np.diff(positions, axis=0, prepend=positions[:1])
    headings = np.arctan2(steps[:, 1], steps[:, 0])
    # Standing still keeps the last heading of a walk (or faces the first leg).
    first_leg = route.points[min(1, len(route.points) - 1)] - route.points[0]
    last = float(np.arctan2(first_leg[1], first_leg[0]))
    for k in range(len(times)):
        if walking[k] and np.hypot(*steps[k]) > 1e-6:
            last = float(headings[k])
        headings[k] = last
    phases = phase0 + 2 * np.pi * distance / _STRIDE_M
    return Walker(track_id, positions, headings, walking, phases)


def sample_walkers(world: SiteWorld, steps: int, fps: float, seed: int, people: int | None = None
                   ) -> list[Walker]:
    """Routes of `people` persons (default: 18 per minute, at least 10) over `steps` steps at `fps`."""
    seconds = steps / fps
    wanted = people if people is not None else max(10, round(18 * seconds / 60))
    rng = np.random.default_rng([int(seed), 9001])
    times = np.arange(steps) / fps
    planner = _Planner(world, times, rng)
    walkers: list[Walker] = []
    attempts = 0
    while len(walkers) < wanted and attempts < 400:
        attempts += 1
        inside = bool(rng.random() < 0.3) or not walkers
        start = 0.0 if inside else float(rng.uniform(0.0, max(seconds - 8.0, 0.5)))
        route = planner.route(start, inside, leave=bool(rng.random() < 0.7))
        if route is None:
            continue
        size = min(int(rng.choice([1, 1, 1, 2, 2, 3])), wanted - len(walkers))
        group = [route] + [_offset_route(route, side * _GROUP_SPACING_M, float(rng.uniform(0.0, 0.5)))
                           for side in (1.0, -1.0)[: size - 1]]
        members = [_walker(len(walkers) + i + 1, r, times, float(rng.uniform(0, 2 * np.pi)))
                   for i, r in enumerate(group)]
        if not all(np.isfinite(m.positions_m[:, 0]).any() for m in members):
            continue
        if not all(planner.companion_clear(r) for r in group[1:]):
            continue
        if not planner.fits([m.positions_m for m in members]) or not _apart(members, _GROUP_GAP_M):
            continue
        planner.tracks += [m.positions_m for m in members]
        walkers += members
    return walkers
