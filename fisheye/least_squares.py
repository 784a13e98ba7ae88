"""Small dense least-squares solvers for calibration fits (numpy only; no scipy at run time).

`nnls` is Lawson and Hanson's active-set method; `constrained_lstsq` solves least squares under
linear inequality constraints (their LSI problem) by reducing it to a least-distance problem, which
is one NNLS (Lawson & Hanson, *Solving Least Squares Problems*, 1974, chapters 23 and 20).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


class InfeasibleConstraintsError(ValueError):
    """No point satisfies every inequality constraint."""


def nnls(A: ArrayLike, b: ArrayLike, max_iterations: int | None = None) -> FloatArray:
    """argmin ||A x − b|| subject to x ≥ 0, for A (M, N) and b (M,) -> x (N,)."""
    matrix = np.asarray(A, dtype=np.float64)
    target = np.asarray(b, dtype=np.float64).reshape(-1)
    M, N = matrix.shape
    if target.shape != (M,):
        raise ValueError(f"b must have shape ({M},), got {target.shape}")
    tolerance = 10 * np.finfo(np.float64).eps * max(M, N) * max(1.0, float(np.abs(matrix).sum(axis=0).max(
        initial=0.0)))
    x = np.zeros(N)
    passive = np.zeros(N, dtype=bool)
    gradient = matrix.T @ target
    for _ in range(max_iterations or 3 * N + 10):
        free = ~passive & (gradient > tolerance)
        if not free.any():
            break
        passive[int(np.argmax(np.where(free, gradient, -np.inf)))] = True
        while True:
            trial = np.zeros(N)
            trial[passive] = np.linalg.lstsq(matrix[:, passive], target, rcond=None)[0]
            if trial[passive].min() > 0:
                break
            # Step from x towards the trial point until the first passive variable reaches zero.
            blocking = passive & (trial <= 0)
            alpha = float(np.min(x[blocking] / (x[blocking] - trial[blocking])))
            x = x + alpha * (trial - x)
            passive &= x > tolerance
            x[~passive] = 0.0
            if not passive.any():
                trial = np.zeros(N)
                break
        x = trial
        gradient = matrix.T @ (target - matrix @ x)
    return x


def least_distance(E: ArrayLike, f: ArrayLike) -> FloatArray:
    """argmin ||z|| subject to E z ≥ f, for E (M, N) and f (M,) -> z (N,).

    Raises InfeasibleConstraintsError when no z satisfies the constraints.
    """
    constraints = np.asarray(E, dtype=np.float64)
    bounds = np.asarray(f, dtype=np.float64).reshape(-1)
    M, N = constraints.shape
    if M == 0 or bounds.max() <= 0:
        return np.zeros(N)  # z = 0 is feasible
    stacked = np.vstack([constraints.T, bounds[None, :]])  # (N + 1, M)
    unit = np.zeros(N + 1)
    unit[N] = 1.0
    u = nnls(stacked, unit)
    residual = stacked @ u - unit
    if np.linalg.norm(residual) < 1e-12 or abs(residual[N]) < 1e-12:
        raise InfeasibleConstraintsError("the inequality constraints have no common solution")
    return -residual[:N] / residual[N]


def constrained_lstsq(A: ArrayLike, b: ArrayLike, G: ArrayLike, h: ArrayLike) -> FloatArray:
    """argmin ||A x − b|| subject to G x ≥ h, for A (M, N) of full column rank, b (M,),
    G (K, N) and h (K,) -> x (N,).

    With A = Q R, ||A x − b|| = ||z|| + const for z = R x − Qᵀb, and the constraints become
    G R⁻¹ z ≥ h − G R⁻¹ Qᵀ b: a least-distance problem in z.
    """
    matrix = np.asarray(A, dtype=np.float64)
    target = np.asarray(b, dtype=np.float64).reshape(-1)
    constraints = np.asarray(G, dtype=np.float64).reshape(-1, matrix.shape[1])
    bounds = np.asarray(h, dtype=np.float64).reshape(-1)
    Q, R = np.linalg.qr(matrix)
    if np.linalg.matrix_rank(R) < matrix.shape[1]:
        raise ValueError("A must have full column rank")
    projected = Q.T @ target
    E = np.linalg.solve(R.T, constraints.T).T  # G R⁻¹
    z = least_distance(E, bounds - E @ projected)
    return np.linalg.solve(R, z + projected)
