"""One person's track in the site frame: a constant-velocity Kalman state, its life and its history.

State `x` = [x, y, vx, vy] (m, m/s) with covariance `P` (4, 4); prediction and update are OpenCV's
Kalman filter (`cv2.KalmanFilter`, run on each track's state), the process noise a white
acceleration. A track is tentative until it has been seen at `min_hits` distinct capture times; it gets its
number (its public id) when it is confirmed, so ids count people, not noise.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])  # the position part of the state
HISTORY_LENGTH = 32


def transition(dt_s: float) -> FloatArray:
    """(4, 4) constant-velocity transition over `dt_s`."""
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt_s
    return F


def process_noise(dt_s: float, accel_var: float) -> FloatArray:
    """(4, 4) process noise of a piecewise-constant white acceleration of variance `accel_var`
    (m/s²)² over `dt_s`, per axis [[dt⁴/4, dt³/2], [dt³/2, dt²]]·var."""
    per_axis = np.array([[dt_s**4 / 4, dt_s**3 / 2], [dt_s**3 / 2, dt_s**2]]) * accel_var
    Q = np.zeros((4, 4))
    for axis in (0, 1):
        index = np.ix_([axis, axis + 2], [axis, axis + 2])
        Q[index] = per_axis
    return Q


class KalmanStep:
    """OpenCV's Kalman filter as a function of a track's (x, P): one per fusion state (not shared
    across threads), its matrices set for each call. OpenCV may keep and later write into the very
    buffers it is given, so it is given copies: a track's arrays are shared with its snapshots."""

    def __init__(self) -> None:
        self._filter = cv2.KalmanFilter(4, 2, 0, cv2.CV_64F)
        self._filter.measurementMatrix = H.copy()

    def motion(self, F: FloatArray, Q: FloatArray) -> None:
        """Set the transition and process noise of the next `predict` calls."""
        self._filter.transitionMatrix = F.copy()
        self._filter.processNoiseCov = Q.copy()

    def predict(self, x: FloatArray, P: FloatArray) -> tuple[FloatArray, FloatArray]:
        self._filter.statePost = x.reshape(4, 1).copy()
        self._filter.errorCovPost = P.copy()
        self._filter.predict()
        state = np.array(self._filter.statePre, dtype=np.float64).reshape(4)
        return state, np.array(self._filter.errorCovPre, dtype=np.float64)

    def update(self, x: FloatArray, P: FloatArray, z_m: FloatArray,
               R: FloatArray) -> tuple[FloatArray, FloatArray]:
        self._filter.statePre = x.reshape(4, 1).copy()
        self._filter.errorCovPre = P.copy()
        self._filter.measurementNoiseCov = R.copy()
        self._filter.correct(z_m.reshape(2, 1).astype(np.float64))
        state = np.array(self._filter.statePost, dtype=np.float64).reshape(4)
        return state, np.array(self._filter.errorCovPost, dtype=np.float64)


@dataclass
class Track:
    """A person: Kalman state, when and by which cameras they were seen, time spent in each zone."""

    x: FloatArray
    P: FloatArray
    first_seen: float
    last_seen: float
    number: int | None = None
    hits: int = 1
    cameras_seen: dict[str, float] = field(default_factory=dict)
    dwell_s: dict[str, float] = field(default_factory=dict)
    # Per counting line: the side (+1 left, -1 right) and position where the track last stood clear of it.
    line_anchors: dict[str, tuple[int, FloatArray]] = field(default_factory=dict)
    # Per counting line: since when (capture time) the track stands clear on the other side of its anchor.
    line_leaving: dict[str, float] = field(default_factory=dict)
    # Crossings (line id, +1 in / -1 out) made while tentative, counted when the track is confirmed.
    pending_crossings: list[tuple[str, int]] = field(default_factory=list)
    history: deque[tuple[float, float, float]] = field(default_factory=lambda: deque(maxlen=HISTORY_LENGTH))

    @classmethod
    def start(cls, xy_m: FloatArray, noise_m2: float, speed_var: float, t: float, camera_id: str) -> Track:
        """A tentative track at `xy_m` (2,), standing still with an uncertain velocity."""
        P = np.diag([noise_m2, noise_m2, speed_var, speed_var])
        track = cls(x=np.array([xy_m[0], xy_m[1], 0.0, 0.0]), P=P, first_seen=t, last_seen=t,
                    cameras_seen={camera_id: t})
        track.history.append((t, float(xy_m[0]), float(xy_m[1])))
        return track

    @property
    def confirmed(self) -> bool:
        return self.number is not None

    @property
    def position_m(self) -> FloatArray:
        return self.x[:2]

    @property
    def last_position_m(self) -> FloatArray:
        """(2,) m where the last update put the track (its state since then is a prediction)."""
        _, x_m, y_m = self.history[-1]
        return np.array([x_m, y_m])

    @property
    def velocity_mps(self) -> FloatArray:
        return self.x[2:]

    def predict(self, kalman: KalmanStep) -> None:
        """Move the state on by the motion `kalman` was last given."""
        self.x, self.P = kalman.predict(self.x, self.P)

    def update(self, kalman: KalmanStep, z_m: FloatArray, noise_m2: float, t: float, camera_id: str) -> None:
        """Fold in one position `z_m` (2,) m of variance `noise_m2` seen by `camera_id` at `t`."""
        self.x, self.P = kalman.update(self.x, self.P, z_m, noise_m2 * np.eye(2))
        if t > self.last_seen:
            self.hits += 1
        self.last_seen = max(self.last_seen, t)
        self.cameras_seen[camera_id] = t
        self.history.append((t, float(self.x[0]), float(self.x[1])))

    def cameras_now(self, window_s: float) -> list[str]:
        """Cameras that saw the track within `window_s` of its last sighting, by id."""
        return sorted(c for c, seen in self.cameras_seen.items() if seen >= self.last_seen - window_s)

    def copy(self) -> Track:
        """An independent twin (the tracker snapshots every track before each frame, so this is
        cheap: `x` and `P` are shared, since predict and update replace them, never change them)."""
        twin = object.__new__(Track)
        twin.__dict__.update(self.__dict__)
        twin.cameras_seen = dict(self.cameras_seen)
        twin.dwell_s = dict(self.dwell_s)
        twin.line_anchors = dict(self.line_anchors)
        twin.line_leaving = dict(self.line_leaving)
        twin.pending_crossings = list(self.pending_crossings)
        twin.history = self.history.copy()
        return twin
