import numpy as np
import pytest
from scipy.optimize import linprog
from scipy.optimize import nnls as scipy_nnls

from fisheye.least_squares import InfeasibleConstraintsError, constrained_lstsq, least_distance, nnls


@pytest.mark.parametrize("seed", range(5))
def test_nnls_matches_scipy(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(40):
        M, N = rng.integers(1, 15), rng.integers(1, 8)
        A, b = rng.normal(size=(M, N)), rng.normal(size=M)
        x = nnls(A, b)
        assert x.shape == (N,) and (x >= 0).all()
        reference = scipy_nnls(A, b)[0]
        assert np.linalg.norm(A @ x - b) == pytest.approx(np.linalg.norm(A @ reference - b), abs=1e-9)


def test_nnls_table() -> None:
    np.testing.assert_allclose(nnls(np.eye(3), [1.0, -2.0, 3.0]), [1.0, 0.0, 3.0])
    np.testing.assert_allclose(nnls(np.zeros((0, 2)), np.zeros(0)), [0.0, 0.0])
    with pytest.raises(ValueError, match="b must have shape"):
        nnls(np.eye(2), np.zeros(3))


def _kkt_holds(A: np.ndarray, b: np.ndarray, G: np.ndarray, h: np.ndarray, x: np.ndarray) -> bool:
    """x is optimal iff it is feasible and −∇ = Aᵀ(b − Ax) is a non-negative combination of the
    active constraints' normals."""
    slack = G @ x - h
    if slack.min() < -1e-9:
        return False
    active = slack < 1e-7
    gradient = A.T @ (A @ x - b)
    if not active.any():
        return bool(np.linalg.norm(gradient) < 1e-7)
    multipliers = nnls(G[active].T, gradient)
    return bool(np.linalg.norm(G[active].T @ multipliers - gradient) < 1e-6)


@pytest.mark.parametrize("seed", range(5))
def test_constrained_lstsq_is_optimal_or_reports_infeasible(seed: int) -> None:
    rng = np.random.default_rng(seed)
    infeasible = 0
    for _ in range(40):
        A, b = rng.normal(size=(20, 4)), rng.normal(size=20)
        G, h = rng.normal(size=(12, 4)), rng.normal(size=12) - 1.0
        feasible = linprog(np.zeros(4), A_ub=-G, b_ub=-h, bounds=[(None, None)] * 4).status == 0
        if not feasible:
            infeasible += 1
            with pytest.raises(InfeasibleConstraintsError):
                constrained_lstsq(A, b, G, h)
            continue
        assert _kkt_holds(A, b, G, h, constrained_lstsq(A, b, G, h))
    assert infeasible < 40


def test_constrained_lstsq_without_active_constraints_is_plain_least_squares() -> None:
    rng = np.random.default_rng(9)
    A, b = rng.normal(size=(10, 3)), rng.normal(size=10)
    x = constrained_lstsq(A, b, -np.eye(3), np.full(3, -1e6))
    np.testing.assert_allclose(x, np.linalg.lstsq(A, b, rcond=None)[0], atol=1e-10)


def test_constrained_lstsq_hand_case() -> None:
    # min (x − 2)² + (y + 1)² subject to y ≥ 0 and x ≤ 1: (1, 0).
    x = constrained_lstsq(np.eye(2), [2.0, -1.0], [[0.0, 1.0], [-1.0, 0.0]], [0.0, -1.0])
    np.testing.assert_allclose(x, [1.0, 0.0], atol=1e-12)


def test_least_distance_and_rank() -> None:
    np.testing.assert_allclose(least_distance([[1.0, 1.0]], [2.0]), [1.0, 1.0])
    np.testing.assert_allclose(least_distance(np.zeros((0, 2)), np.zeros(0)), [0.0, 0.0])
    with pytest.raises(InfeasibleConstraintsError):
        least_distance([[1.0], [-1.0]], [1.0, 1.0])
    with pytest.raises(ValueError, match="full column rank"):
        constrained_lstsq(np.ones((4, 2)), np.zeros(4), np.zeros((1, 2)), [-1.0])
