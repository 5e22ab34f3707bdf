"""The certificate of a solve: its status, the solver's residuals and gaussim's own KKT check.

The check is independent of the solver: at a point (x, lambda_eq, lambda_in) of the Gauss problem

    min_x 1/2 x^T H x + g^T x   s.t.   A x = b,   C x >= l

it measures the stationarity residual |H x + g - A^T lambda_eq - C^T lambda_in|, the primal
violations |A x - b| and l - C x, the sign violation -lambda_in and the complementarity
|lambda_in (C x - l)|.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from ..assembly import GaussProblem
from ..constraints.base import real_floats
from ..exceptions import InvalidOptions
from ..kernels.bound import Bound

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
kkt_residuals = Bound("solver.kkt_residuals")
violates = Bound("solver.violates")

# A solution is accepted when its relative KKT residual (see Certificate) is below KKT_RTOL * eps_abs.
KKT_RTOL = 100.0


class Status(enum.Enum):
    """How one solve ended: ProxQP's or DAQP's status, or gaussim's word on it.

    Each value is the name a run log stores (its ``solver_status`` column), which ``str`` gives too.
    """

    SOLVED = "PROXQP_SOLVED"
    """ProxQP converged (and gaussim's KKT check certifies its answer)."""
    MAX_ITER_REACHED = "PROXQP_MAX_ITER_REACHED"
    """ProxQP stopped at its iteration cap, at a point the KKT check does not certify."""
    PRIMAL_INFEASIBLE = "PROXQP_PRIMAL_INFEASIBLE"
    """The admissible set is empty."""
    SOLVED_CLOSEST_PRIMAL_FEASIBLE = "PROXQP_SOLVED_CLOSEST_PRIMAL_FEASIBLE"
    """The admissible set is empty; ProxQP solved the closest feasible problem."""
    DUAL_INFEASIBLE = "PROXQP_DUAL_INFEASIBLE"
    """The problem is unbounded."""
    NOT_RUN = "PROXQP_NOT_RUN"
    """ProxQP did not solve."""
    CERTIFIED_AT_MAX_ITER = "GAUSSIM_CERTIFIED_AT_MAX_ITER"
    """ProxQP stopped at its iteration cap at a point the KKT check certifies: accepted."""
    DUAL_SOLVED = "GAUSSIM_DUAL_SOLVED"
    """gaussim's dual active-set method solved the problem (and the KKT check certifies its answer):
    ProxQP was not called."""
    DUAL_ACTIVE_SET_SOLVED = "DAQP_SOLVED"
    """DAQP's dual active-set method solved the problem (and gaussim's KKT check certifies its answer):
    ProxQP was not called."""
    KKT_CHECK_FAILED = "GAUSSIM_KKT_CHECK_FAILED"
    """ProxQP said solved, the KKT check disagrees."""
    PREVIOUS_SOLUTION_CERTIFIED = "GAUSSIM_PREVIOUS_SOLUTION_CERTIFIED"
    """The previous solution solves this problem to eps_abs by the KKT check: ProxQP was not called."""
    ACTIVE_SET_CERTIFIED = "GAUSSIM_ACTIVE_SET_CERTIFIED"
    """So does the solution on the previous solution's active set, one linear solve: ProxQP was not
    called."""
    FREE_MOTION_CERTIFIED = "GAUSSIM_FREE_MOTION_CERTIFIED"
    """The free motion meets every row (to eps_abs by the KKT check, no reaction): ProxQP was not
    called."""
    MULTIPLIERS_CERTIFIED = "GAUSSIM_MULTIPLIERS_CERTIFIED"
    """ProxQP's x with nonnegative multipliers of gaussim's making, where ProxQP's (one choice among
    many, of dependent rows) had a wrong sign."""

    def __str__(self) -> str:
        return self.value

    @property
    def converged(self) -> bool:
        """True for the statuses of an accepted solution."""
        return self in CONVERGED


# The statuses of an accepted solution: ProxQP's, or ProxQP stopped at its iteration cap at a point
# gaussim's KKT check certifies (redundant rows that conflict in round-off keep ProxQP's primal residual
# above eps_abs), or a solution built from the last one that the check certifies.
CONVERGED = (
    Status.SOLVED,
    Status.DUAL_SOLVED,
    Status.DUAL_ACTIVE_SET_SOLVED,
    Status.CERTIFIED_AT_MAX_ITER,
    Status.PREVIOUS_SOLUTION_CERTIFIED,
    Status.ACTIVE_SET_CERTIFIED,
    Status.MULTIPLIERS_CERTIFIED,
    Status.FREE_MOTION_CERTIFIED,
)
# The statuses that say the problem has no solution: no restart can help. Not DUAL_INFEASIBLE: the Gauss
# problem's H = M is positive definite, so it is never unbounded, and ProxQP's detection of it is false
# (allegro_left_hand collapsing: DUAL_INFEASIBLE at residuals of 5e-10); such an answer is recovered.
PRIMAL_INFEASIBLE = (Status.PRIMAL_INFEASIBLE, Status.SOLVED_CLOSEST_PRIMAL_FEASIBLE)
INFEASIBLE = PRIMAL_INFEASIBLE


@dataclass
class Certificate:
    """What the solver says about one solve, and gaussim's check of it.

    Attributes:
        status: how the solve ended (:class:`Status`).
        iterations: the solver's iterations in all: ProxQP's inner ones of each of its outer
            iterations, or DAQP's active-set changes.
        outer_iterations: ProxQP's outer iterations, the ones ``Options.max_iter`` caps.
        primal_residual: max constraint violation of the returned x.
        dual_residual: norm of the stationarity residual H x + g + A^T y + C^T z.
        duality_gap: the duality gap (ProxQP's, or gaussim's sum_i z_i s_i).
        kkt_residual: gaussim's own check of the returned point on the problem as posed: the largest
            of the primal violation, the stationarity residual |H x + g - A^T y - C^T z|, the sign
            violation of z and the complementarity |z_i (C x - l)_i|.
        relative_kkt_residual: the same with the stationarity residual and the sign violation
            relative to max(1, |g|_inf) and each complementarity relative to max(1, |z_i|); a
            solution is accepted when it is below KKT_RTOL * eps_abs.
        restarted: True when the warm-started answer failed that check and ProxQP was run again
            from a cold start.
    """

    status: Status
    iterations: int
    primal_residual: float
    dual_residual: float
    duality_gap: float
    kkt_residual: float = 0.0
    relative_kkt_residual: float = 0.0
    outer_iterations: int = 0
    restarted: bool = False

    @property
    def converged(self) -> bool:
        return self.status in CONVERGED


@dataclass
class Solution:
    """x, the multipliers [lambda_eq; lambda_in] of the equality and inequality rows (the reactions,
    >= 0 on inequality rows) and the certificate."""

    x: np.ndarray
    multipliers: np.ndarray
    n_eq: int
    certificate: Certificate

    @property
    def lambda_eq(self) -> np.ndarray:
        return self.multipliers[: self.n_eq]

    @property
    def lambda_in(self) -> np.ndarray:
        return self.multipliers[self.n_eq :]


def kkt_residual(problem: GaussProblem, x: np.ndarray, lambda_eq: np.ndarray, lambda_in: np.ndarray) -> float:
    """Largest violation of the KKT conditions of the Gauss problem at (x, lambda_eq, lambda_in >= 0)
    (see the module's docstring); NaN when any of them is not finite."""
    p = problem
    point = []  # a user's arrays may be of any make; the kernel reads these sizes and does not check them
    for name, a, size in (
        ("x", x, len(p.g)),
        ("lambda_eq", lambda_eq, len(p.b)),
        ("lambda_in", lambda_in, len(p.l)),
    ):
        a = real_floats(f"kkt_residual's {name}", a)
        if a.shape != (size,):
            raise InvalidOptions(f"kkt_residual's {name}", f"must have shape ({size},), got {a.shape}")
        point.append(a)
    return kkt_residuals.call(p.H, p.g, p.A, p.b, p.C, p.l, *point)[0]


def checked(
    problem: GaussProblem,
    x: np.ndarray,
    multipliers: np.ndarray,
    status: Status,
    tolerance: float,
    iterations: int = 0,
    screened: bool = True,
) -> Solution | None:
    """(x, multipliers) as a solution of ``status`` (after ``iterations`` of its solver) when the KKT
    check's relative residual certifies it to ``tolerance``, else None. ``screened``: a guess (the last
    solution, the free motion) is first refused at the first row it violates, without the full check;
    a solver's answer, which meets its rows to its tolerance, skips that pass over the rows."""
    p, n_eq = problem, len(problem.b)
    if screened and violates.call(p.C, p.l, x, tolerance):
        return None
    residual, relative, primal, dual, gap = kkt_residuals.call(
        p.H, p.g, p.A, p.b, p.C, p.l, x, multipliers[:n_eq], multipliers[n_eq:]
    )
    if not relative <= tolerance:  # NaN fails too
        return None
    certificate = Certificate(status, iterations, primal, dual, gap, residual, relative)
    return Solution(x, multipliers, n_eq, certificate)
