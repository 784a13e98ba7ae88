"""Synthetic trajectories for the tracker tests: people walking under overhead cameras of a site."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from sites import SiteObservation

Path = Callable[[float], tuple[float, float] | None]  # seconds since start -> site position, None: absent
START = 1_764_612_000.0


@dataclass(frozen=True)
class Cam:
    """A camera whose nadir is at `nadir_m` and who sees the floor within `radius_m` of it."""

    id: str
    nadir_m: tuple[float, float]
    radius_m: float


def line_walk(start: tuple[float, float], velocity: tuple[float, float], t0: float = 0.0,
              t1: float = 1e9) -> Path:
    """A person at `start` at `t0` walking at `velocity` m/s until `t1`, absent outside [t0, t1]."""

    def at(t: float) -> tuple[float, float] | None:
        if not t0 <= t <= t1:
            return None
        return start[0] + velocity[0] * (t - t0), start[1] + velocity[1] * (t - t0)

    return at


def frames(cams: list[Cam], people: list[Path], seconds: float, fps: float = 10.0,
           seed: int = 0, noise_base_m: float = 0.03, noise_per_m: float = 0.01,
           ) -> Iterator[tuple[SiteObservation, list[int]]]:
    """Each camera's frame at each step (cameras capture in step), with the person index of each row."""
    rng = np.random.default_rng(seed)
    for k in range(round(seconds * fps)):
        t = k / fps
        for cam in cams:
            rows, who, distances = [], [], []
            for index, path in enumerate(people):
                where = path(t)
                if where is None:
                    continue
                distance = float(np.hypot(where[0] - cam.nadir_m[0], where[1] - cam.nadir_m[1]))
                if distance > cam.radius_m:
                    continue
                sigma = noise_base_m + noise_per_m * distance
                rows.append(np.array(where) + rng.normal(0.0, sigma, 2))
                who.append(index)
                distances.append(distance)
            positions = np.array(rows).reshape(-1, 2)
            yield SiteObservation.of(cam.id, START + t, positions, distances), who
