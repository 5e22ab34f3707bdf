"""The ProxQP wrapper: warm starts that cannot go stale, certificates that are checked."""

import numpy as np
import pytest

import gaussim
from gaussim.assembly import GaussProblem
from gaussim.solver import GaussSolver, kkt_residual


def _problem(lower: float) -> GaussProblem:
    """min 1/2 |x|^2 + 9.81e-3 x_3  s.t.  x_3 >= lower: a ball's normal velocity under gravity."""
    C = np.array([[0.0, 0.0, 1.0]])
    return GaussProblem(
        np.eye(3), np.array([0, 0, 9.81e-3]), np.zeros((0, 3)), np.zeros(0), C, np.array([lower]), []
    )


def test_warm_start_is_not_stale_when_only_bounds_change():
    solver = GaussSolver(gaussim.Options())
    resting = solver.solve(_problem(0.0))
    assert resting.lambda_in[0] == pytest.approx(9.81e-3, abs=1e-7)
    freed = solver.solve(_problem(-0.5))  # same H, g, C: only the bound moved
    assert freed.x[2] == pytest.approx(-9.81e-3, rel=1e-9)
    assert abs(freed.lambda_in[0]) < 1e-12
    assert freed.certificate.restarted, "ProxQP 0.8 returns the stale warm start here"
    assert freed.certificate.kkt_residual < 1e-12


def test_kkt_residual_measures_complementarity():
    problem = _problem(-0.5)
    x = np.array([0.0, 0.0, 0.0])
    assert kkt_residual(problem, x, np.zeros(0), np.array([9.81e-3])) == pytest.approx(0.5 * 9.81e-3)
    assert kkt_residual(problem, np.array([0, 0, -9.81e-3]), np.zeros(0), np.zeros(1)) == 0.0


def test_kkt_residual_is_nan_when_anything_is_not_finite():
    """A NaN in the solution, a multiplier or a bound must not hide behind a max."""
    problem = _problem(-0.5)
    solution = np.array([0, 0, -9.81e-3])
    assert kkt_residual(problem, solution, np.zeros(0), np.zeros(1)) == 0.0
    assert np.isnan(kkt_residual(problem, np.array([np.nan, 0, 0]), np.zeros(0), np.zeros(1)))
    assert np.isnan(kkt_residual(problem, solution, np.zeros(0), np.array([np.nan])))
    assert np.isnan(kkt_residual(_problem(np.nan), solution, np.zeros(0), np.zeros(1)))
    anchored = GaussProblem(np.eye(3), problem.g, np.eye(3)[:1], np.zeros(1), problem.C, problem.l, [])
    assert kkt_residual(anchored, solution, np.zeros(1), np.zeros(1)) == 0.0
    assert np.isnan(kkt_residual(anchored, solution, np.array([np.inf]), np.zeros(1)))
