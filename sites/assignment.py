"""The assignment problem of fusion, in numpy: minimum-cost matching of tracks to detections.

`linear_sum_assignment(cost)` answers what `scipy.optimize.linear_sum_assignment` answers for a
finite cost matrix (R, C): rows and columns of a matching of min(R, C) pairs of least total cost,
rows ascending (where several matchings tie, it may pick another of them). When every row's
cheapest column is a different one, that is the answer; otherwise it is the Hungarian method with
row and column potentials (Kuhn-Munkres, in the O(n² m) form that adds one row at a time and grows
a shortest augmenting path to a free column), each step vectorised over the columns. Fusion's
matrices are small (tracks × detections of one frame), and the runtime then needs no scipy.

`pairwise_distance_m(a, b)` is the (N, M) Euclidean distance matrix of two point sets.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def linear_sum_assignment(cost: FloatArray) -> tuple[IntArray, IntArray]:
    """(K,) rows and (K,) columns, K = min(R, C), of a least-cost matching in `cost` (R, C), finite
    (ValueError otherwise); rows ascending."""
    matrix = np.asarray(cost, dtype=np.float64)
    if matrix.ndim != 2:
        raise ValueError(f"expected a 2-D cost matrix, got shape {matrix.shape}")
    if not np.isfinite(matrix).all():
        raise ValueError("the cost matrix must be finite")
    transposed = matrix.shape[0] > matrix.shape[1]
    c = matrix.T if transposed else matrix  # (n, m) with n <= m: every row gets a column
    n = c.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    nearest = c.argmin(axis=1)
    # Every row's cheapest column is its own: that matching costs the lower bound, so it is optimal
    # (fusion's usual case: people far apart). Otherwise, the Hungarian method.
    col_of_row = nearest if len(np.unique(nearest)) == n else _assign_rows(c)
    if not transposed:
        return np.arange(n, dtype=np.int64), col_of_row
    order = np.argsort(col_of_row, kind="stable")
    return col_of_row[order], np.arange(n, dtype=np.int64)[order]


def _assign_rows(c: FloatArray) -> IntArray:
    """(n,) the column of each row in a least-cost matching of `c` (n, m), n <= m."""
    n, m = c.shape
    # Index 0 of the column arrays is a virtual column holding the row being added.
    u = np.zeros(n + 1)                         # row potentials (1-based rows)
    v = np.zeros(m + 1)                         # column potentials
    row_of = np.zeros(m + 1, dtype=np.int64)    # 1-based row holding each column (0: free)
    came_from = np.zeros(m + 1, dtype=np.int64)
    for row in range(1, n + 1):
        row_of[0] = row
        column = 0
        slack = np.full(m + 1, np.inf)          # least reduced cost reaching each column so far
        visited = np.zeros(m + 1, dtype=bool)
        while True:
            visited[column] = True
            current = row_of[column]
            free = np.flatnonzero(~visited[1:]) + 1
            reduced = c[current - 1, free - 1] - u[current] - v[free]
            better = reduced < slack[free]
            slack[free[better]] = reduced[better]
            came_from[free[better]] = column
            nearest = free[np.argmin(slack[free])]
            delta = slack[nearest]
            seen = np.flatnonzero(visited)
            u[row_of[seen]] += delta            # distinct rows: each seen column holds its own
            v[seen] -= delta
            slack[free] -= delta
            column = int(nearest)
            if row_of[column] == 0:
                break
        while column:                           # flip the path back to the virtual column
            previous = int(came_from[column])
            row_of[column] = row_of[previous]
            column = previous
    col_of_row = np.zeros(n, dtype=np.int64)
    held = np.flatnonzero(row_of[1:]) + 1
    col_of_row[row_of[held] - 1] = held - 1
    return col_of_row


def pairwise_distance_m(a_m: FloatArray, b_m: FloatArray) -> FloatArray:
    """(N, M) Euclidean distances between points `a_m` (N, D) and `b_m` (M, D)."""
    delta = np.asarray(a_m, dtype=np.float64)[:, None, :] - np.asarray(b_m, dtype=np.float64)[None, :, :]
    return np.sqrt((delta * delta).sum(axis=-1))
