"""What fusion takes in and gives back for one camera frame.

`SiteObservation` is one frame of one camera of a site, already placed in the site frame: N people as
parallel arrays. `FrameOutcome` says what the tracker made of it: the track each detection joined
and whether the frame was used in order, used late (within the reordering window) or dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

FrameUse = Literal["used", "used_late", "dropped_late"]


@dataclass(frozen=True)
class SiteObservation:
    """One camera frame's people in the site frame.

    camera_id; capture_time (Unix s, the only clock of tracking); positions_m (N, 2) site-frame m,
    NaN rows for detections without a floor point (they join no track); distance_m (N,) from the
    camera's nadir (the position's uncertainty grows with it); scores (N,) in [0, 1].
    """

    camera_id: str
    capture_time: float
    positions_m: FloatArray
    distance_m: FloatArray
    scores: FloatArray

    def __post_init__(self) -> None:
        if not math.isfinite(self.capture_time):
            raise ValueError(f"capture_time must be a finite number, got {self.capture_time}")
        positions = np.asarray(self.positions_m, dtype=np.float64).reshape(-1, 2)
        n = len(positions)
        distance = np.asarray(self.distance_m, dtype=np.float64).reshape(-1)
        scores = np.asarray(self.scores, dtype=np.float64).reshape(-1)
        if distance.shape != (n,) or scores.shape != (n,):
            raise ValueError(f"SiteObservation of {n} positions with {distance.shape[0]} distances and "
                             f"{scores.shape[0]} scores")
        object.__setattr__(self, "positions_m", positions)
        object.__setattr__(self, "distance_m", distance)
        object.__setattr__(self, "scores", scores)

    def __len__(self) -> int:
        return len(self.positions_m)

    @classmethod
    def of(cls, camera_id: str, capture_time: float, positions_m: object,
           distance_m: object | None = None, scores: object | None = None) -> SiteObservation:
        """An observation from array-likes; distances default to 0 (at the nadir), scores to 1."""
        positions = np.asarray(positions_m, dtype=np.float64).reshape(-1, 2)
        n = len(positions)
        return cls(
            camera_id, float(capture_time), positions,
            np.zeros(n) if distance_m is None else np.asarray(distance_m, dtype=np.float64),
            np.ones(n) if scores is None else np.asarray(scores, dtype=np.float64),
        )

    @property
    def valid(self) -> NDArray[np.bool_]:
        """(N,) rows with a finite position and distance."""
        return np.isfinite(self.positions_m).all(axis=1) & np.isfinite(self.distance_m)


@dataclass(frozen=True)
class FrameOutcome:
    """What one observation did: `track_ids` (N,) the confirmed track each detection joined (None for
    a detection that started or fed a track not yet confirmed, had no floor point, or was dropped);
    `use` whether the frame was used in order, used late (the site's tracks replayed with it in
    capture_time order) or dropped for coming later than the reordering window."""

    track_ids: tuple[str | None, ...]
    use: FrameUse

    @classmethod
    def dropped(cls, n: int) -> FrameOutcome:
        return cls((None,) * n, "dropped_late")
