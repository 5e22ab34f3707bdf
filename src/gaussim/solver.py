"""Stage 5, the ProxQP solve: one dense QP object, reused while the problem keeps its size."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import proxsuite

from .assembly import GaussProblem
from .exceptions import InfeasibleConstraints, SolverError
from .options import Options

_proxqp = proxsuite.proxqp
# A row whose residual exceeds this at ProxQP's closest-feasible point is named as conflicting.
INFEASIBLE_ROW_TOLERANCE = 1e-6


@dataclass
class Certificate:
    """What ProxQP says about one solve.

    Attributes:
        status: ProxQP status name (``PROXQP_SOLVED`` when converged).
        iterations: ProxQP iterations.
        primal_residual: max constraint violation of the returned x.
        dual_residual: norm of the stationarity residual H x + g + A^T y + C^T z.
        duality_gap: ProxQP's duality gap.
        setup_time, solve_time: ProxQP's own timings [s].
    """

    status: str
    iterations: int
    primal_residual: float
    dual_residual: float
    duality_gap: float
    setup_time: float
    solve_time: float

    @property
    def converged(self) -> bool:
        return self.status == "PROXQP_SOLVED"


@dataclass
class Solution:
    """x, the multipliers (reactions, >= 0 on inequality rows) and the certificate."""

    x: np.ndarray
    lambda_eq: np.ndarray
    lambda_in: np.ndarray
    certificate: Certificate


class GaussSolver:
    """Dense ProxQP, allocated once per problem size and warm-started from the previous result."""

    def __init__(self, options: Options) -> None:
        self.options = options
        self._qp: Any = None  # proxsuite.proxqp.dense.QP
        self._dims: tuple[int, int, int] | None = None
        self._upper = np.zeros(0)

    def solve(self, problem: GaussProblem) -> Solution:
        """Solve the Gauss problem; raise :class:`SolverError` as ``Options.on_failure`` says."""
        dims = (len(problem.g), len(problem.b), len(problem.l))
        args = (
            problem.H,
            problem.g,
            problem.A if dims[1] else None,
            problem.b if dims[1] else None,
            problem.C if dims[2] else None,
            problem.l if dims[2] else None,
            self._upper if dims[2] else None,
        )
        if dims != self._dims or self._qp is None:
            self._qp = self._new(*dims)
            self._upper = np.full(dims[2], np.inf)  # every inequality row is one-sided
            args = (*args[:-1], self._upper if dims[2] else None)
            self._qp.init(*args)
            self._dims = dims
        else:
            self._qp.update(*args)
        self._qp.solve()
        result = self._qp.results
        info = result.info
        certificate = Certificate(
            info.status.name,
            int(info.iter),
            float(info.pri_res),
            float(info.dua_res),
            float(info.duality_gap),
            float(info.setup_time),
            float(info.solve_time),
        )
        solution = Solution(result.x.copy(), -result.y.copy(), -result.z.copy(), certificate)
        self._check(problem, solution)
        return solution

    def _new(self, n: int, n_eq: int, n_in: int) -> Any:
        qp = _proxqp.dense.QP(n, n_eq, n_in)
        settings = qp.settings
        settings.eps_abs = self.options.eps_abs
        settings.eps_rel = 0.0
        settings.max_iter = self.options.max_iter
        settings.verbose = False
        # Warm start from the previous result, with the duality-gap check on: without it ProxQP 0.8
        # may accept the previous solution after 0 iterations when only the bounds changed.
        settings.initial_guess = _proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
        settings.check_duality_gap = True
        settings.eps_duality_gap_abs = self.options.eps_abs
        settings.eps_duality_gap_rel = 0.0
        settings.primal_infeasibility_solving = True
        return qp

    def _check(self, problem: GaussProblem, solution: Solution) -> None:
        c = solution.certificate
        finite = (
            np.isfinite(solution.x).all()
            and np.isfinite(solution.lambda_eq).all()
            and np.isfinite(solution.lambda_in).all()
        )
        if c.status in ("PROXQP_PRIMAL_INFEASIBLE", "PROXQP_SOLVED_CLOSEST_PRIMAL_FEASIBLE"):
            rows = self._violated(problem, solution.x)
            raise InfeasibleConstraints(
                f"the admissible set is empty ({c.status}); conflicting rows: {', '.join(rows) or 'unknown'}",
                rows,
                c,
            )
        if not finite:
            raise SolverError(f"ProxQP returned a non-finite solution ({c.status})", c)
        if not c.converged and self.options.on_failure == "raise":
            raise SolverError(
                f"ProxQP did not converge: {c.status} after {c.iterations} iterations "
                f"(primal residual {c.primal_residual:.2e}, dual residual {c.dual_residual:.2e}, "
                f"duality gap {c.duality_gap:.2e}); raise Options.max_iter or eps_abs, "
                "or set on_failure='report'",
                c,
            )

    @staticmethod
    def _violated(problem: GaussProblem, x: np.ndarray) -> list[str]:
        names = []
        eq = np.abs(problem.A @ x - problem.b)
        names += [n for n, r in zip(problem.labels(True), eq) if r > INFEASIBLE_ROW_TOLERANCE]
        ineq = problem.l - problem.C @ x
        names += [n for n, r in zip(problem.labels(False), ineq) if r > INFEASIBLE_ROW_TOLERANCE]
        return names
