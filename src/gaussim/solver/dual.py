"""The dual active-set solve: DAQP on the Gauss problem before ProxQP is asked.

The Gauss problem's H = M is positive definite, which is the setting of a dual active-set method:
DAQP (Arnström, Bemporad, Axehill 2022) starts from the unconstrained minimum and adds the violated
rows one at a time, keeping a linearly independent working set. A contact's pyramid rows are
dependent (four facets span three directions, a pile's stacked contacts more), which an interior or
proximal method such as ProxQP pays for in iterations and refactorizations; an active-set method
leaves them out: a settled pile's island (120 coordinates, 336 rows) takes 140 iterations, 2 to 3.5
ms, from a cold start, and 15 from the last solve's working set, where ProxQP took 20 to 40 ms. Its
answer, like ProxQP's, is accepted only when gaussim's KKT check certifies it.
"""

from __future__ import annotations

import daqp
import numpy as np

from ..assembly import GaussProblem
from ..kernels.solver import kkt_residuals
from .certificate import Certificate, Solution, Status

_OPTIMAL = 1  # DAQP's exitflag of an optimal solution
_EQUALITY = 5  # DAQP's sense of an equality row
_UNBOUNDED = 1e30  # DAQP's infinite bound


def dual_active_set(
    problem: GaussProblem, eps_abs: float, tolerance: float, start: np.ndarray | None = None
) -> Solution | None:
    """DAQP's solution of ``problem`` (rows met to ``eps_abs``) when it is optimal and the relative KKT
    residual certifies it to ``tolerance``, else None (ProxQP then solves). ``start``: the multipliers
    of an earlier DAQP solution of a problem with as many rows, whose working set (its nonzero
    multipliers, independent rows) DAQP starts from; a start it cannot use is followed by a cold one."""
    p = problem
    n_eq, n_in = len(p.b), len(p.l)
    rows = np.vstack((p.A, p.C)) if n_eq else p.C
    upper = np.concatenate((p.b, np.full(n_in, _UNBOUNDED)))
    lower = np.concatenate((p.b, p.l))
    sense = np.zeros(n_eq + n_in, dtype=np.int32)
    sense[:n_eq] = _EQUALITY
    warm = start is not None and len(start) == n_eq + n_in
    x, _, flag, info = daqp.solve(
        p.H, p.g, rows, upper, lower, sense, primal_tol=eps_abs, dual_start=-start if warm else None
    )
    if flag != _OPTIMAL and warm:
        x, _, flag, info = daqp.solve(p.H, p.g, rows, upper, lower, sense, primal_tol=eps_abs)
    if flag != _OPTIMAL:
        return None
    multipliers = -np.asarray(info["lam"])  # DAQP's multiplier of a lower bound is <= 0
    residual, relative, primal, dual, gap = kkt_residuals(
        p.H, p.g, p.A, p.b, p.C, p.l, x, multipliers[:n_eq], multipliers[n_eq:]
    )
    if not relative <= tolerance:  # NaN fails too
        return None
    iterations, status = info["iterations"], Status.DUAL_ACTIVE_SET_SOLVED
    certificate = Certificate(status, iterations, primal, dual, gap, residual, relative)
    return Solution(np.asarray(x), multipliers, n_eq, certificate)
