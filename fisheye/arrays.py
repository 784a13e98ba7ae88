"""Shape checks shared by the geometry functions."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def as_points(values: ArrayLike, dims: int, name: str) -> NDArray[np.float64]:
    """A new float64 array of shape (N, dims); an empty input gives (0, dims).

    Raises ValueError naming `name` when the input cannot be read as N points of `dims` numbers.
    """
    array = np.array(values, dtype=np.float64)
    if array.size == 0:
        return np.zeros((0, dims))
    if array.ndim != 2 or array.shape[1] != dims:
        raise ValueError(f"{name} must have shape (N, {dims}), got {array.shape}")
    return array
