"""One camera frame's detections of one person merged on the floor plane, before fusion.

A detector often answers twice for one person in an overhead fisheye view (head and body boxes of one
walker at the rim, where the person is stretched along the radius): the two boxes overlap too little
for the image-space NMS to drop one, yet their floor positions lie a few decimetres apart. Here the
detections of one frame are suppressed greedily by score on the floor plane: a detection within
`radius_m` of a kept, higher-scoring one is the same person. The radius grows with the distance from
the camera's nadir, as the floor position's error does (`radius_base_m + radius_per_m · distance`),
except between two confident detections (score ≥ `sure_score`): two people walking side by side are
two confident detections half a metre apart, a duplicate is seldom confident twice.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sites.assignment import pairwise_distance_m

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def merge_on_floor(positions_m: FloatArray, distance_m: FloatArray, scores: FloatArray,
                   radius_base_m: float, radius_per_m: float, sure_score: float = 1.0) -> IntArray:
    """Floor-plane NMS of one camera frame: positions (N, 2) m (finite), distance from the nadir (N,) m,
    scores (N,) -> (N,) the row of the detection that stands for each one (its own row if it is kept).

    Detections are taken by decreasing score (ties: the earlier row); one is dropped, and stood for by
    the kept one, when a kept detection lies within the larger of the two's radii
    (`radius_base_m + radius_per_m · distance_m`), or within `radius_base_m` when both scores are
    at least `sure_score`."""
    n = len(positions_m)
    kept_for = np.full(n, -1, dtype=np.int64)
    if n == 0:
        return kept_for
    radius = radius_base_m + radius_per_m * distance_m                    # (N,)
    radius_pair = np.maximum(radius[:, None], radius[None, :])                # (N, N)
    sure = scores >= sure_score
    radius_pair = np.where(sure[:, None] & sure[None, :], radius_base_m, radius_pair)
    near = pairwise_distance_m(positions_m, positions_m) <= radius_pair                     # (N, N)
    for index in np.argsort(-scores, kind="stable"):
        if kept_for[index] < 0:
            kept_for[near[index] & (kept_for < 0)] = index
    return kept_for
