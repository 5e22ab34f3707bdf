"""The solve: one dense ProxQP object, reused while the problem keeps its size, after the active set.

Each QP is first tried on what the last one left (:mod:`.active_set`), then warm-started in ProxQP;
an answer gaussim's KKT check refuses is recovered by cold starts (:meth:`GaussSolver._recover`), and a
failure is reported (:mod:`.diagnosis`).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..assembly import GaussProblem
from ..exceptions import GaussimWarning
from ..kernels.bound import Bound
from ..options import Options
from ..portable import portable_proxsuite
from .active_set import ACTIVE_SET_FLOOR, ACTIVE_SET_UP_TO, active_set_candidate
from .certificate import (
    INFEASIBLE,
    KKT_RTOL,
    PRIMAL_INFEASIBLE,
    Certificate,
    Solution,
    Status,
    checked,
)
from .diagnosis import failure, infeasibility
from .dual import DaqpActiveSet, SparseDualActiveSet

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
read_results = Bound("solver.read_results")

proxqp = portable_proxsuite().proxqp


_STATUS = {output: Status(name) for name, output in proxqp.QPSolverOutput.__members__.items()}
_SOLVED = proxqp.QPSolverOutput.PROXQP_SOLVED  # compared by identity: hashing the enum costs more
# ProxQP's outer-iteration cap for a warm-started solve. A warm start needs 0 to 30 iterations over the
# shipped scenes and the stress stacks; one that needs more is better solved again from a cold start
# (redundant contact rows that conflict in round-off made a warm start run its 10000 outer iterations).
WARM_START_ITERATIONS = 100
# ProxQP's cap on the inner iterations of each outer one (its default is 1500). Where a problem cannot
# reach eps_abs, the inner loop may exhaust that cap at each outer iteration; the inner solves that
# converge take a few iterations.
INNER_ITERATIONS = 100
# Up to this many coordinates and rows, the dense backend factorizes ProxQP's primal-dual system, which
# takes half the iterations of the primal one ProxQP picks for more rows than coordinates (a robot's
# contacts); larger, each refactorization of that system costs more than the iterations it saves (a
# pile's 120 coordinates and 320 rows: 0.4 s a solve).
PRIMAL_DUAL_UP_TO = 200
# The dual active-set method tried before ProxQP, by Options.solver
DUAL_SOLVERS: dict[str, type[SparseDualActiveSet | DaqpActiveSet]] = {
    "dual": SparseDualActiveSet,
    "daqp": DaqpActiveSet,
}
# The status of a candidate of active_set_candidate, by its ``how``.
_FROM_LAST = {1: Status.PREVIOUS_SOLUTION_CERTIFIED, 2: Status.ACTIVE_SET_CERTIFIED}


class GaussSolver:
    """Dense ProxQP, allocated once per problem size and warm-started from the previous result."""

    def __init__(self, options: Options) -> None:
        self.options = options
        self._qp: Any = None  # proxsuite.proxqp.dense.QP
        self._dims: tuple[int, int, int] | None = None  # the QP object's sizes
        self._solved: tuple[int, int, int] | None = None  # the last problem's sizes
        self._results: tuple[Any, ...] = ()  # the QP object's x, y, z and info
        self._cap = 0  # the QP object's iteration cap
        self._last: tuple[np.ndarray, np.ndarray] = (np.zeros(0), np.zeros(0))  # x, multipliers
        self._candidate = self._last  # the buffers of the active-set candidate (see _warm)
        eps = options.eps_abs
        dual: type[SparseDualActiveSet | DaqpActiveSet] | None = DUAL_SOLVERS.get(options.solver)
        self._dual = None if dual is None else dual(eps, KKT_RTOL * eps)
        self._warned = False  # about an iterate kept by on_failure='report'

    def solve(self, problem: GaussProblem, x_free: np.ndarray | None = None, warm: bool = True) -> Solution:
        """Solve the Gauss problem, whose unconstrained minimum is ``x_free`` when given; raise
        :class:`SolverError` as ``Options.on_failure`` says. ``warm`` False: the last solution's
        candidates (:meth:`_warm`) were tried already (:meth:`last`)."""
        dims = (len(problem.g), len(problem.b), len(problem.l))
        solution = self._solve(problem, x_free, dims, warm)
        self.keep(solution.x, solution.multipliers, dims)
        return solution

    def last(self, dims: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray] | None:
        """The last solution (x, multipliers) when the last problem had the sizes ``dims`` and its
        active set is solved on (see :meth:`_warm` and ACTIVE_SET_UP_TO), else None."""
        if dims != self._solved or not self._on_active_set(dims[0]):
            return None
        return self._last

    def _on_active_set(self, n: int) -> bool:
        """Whether a problem of ``n`` coordinates is solved on its last active set (see
        ACTIVE_SET_UP_TO), not only checked at its last solution."""
        return n <= ACTIVE_SET_UP_TO or self._dual is None

    def keep(self, x: np.ndarray, multipliers: np.ndarray, dims: tuple[int, int, int]) -> None:
        """Start the next solve from the solution (x, multipliers) of a problem of sizes ``dims`` (arrays
        the caller may go on updating in place: an :class:`~.islands.IslandSolver`'s kept layout)."""
        self._last, self._solved = (x, multipliers), dims

    def _solve(
        self, problem: GaussProblem, x_free: np.ndarray | None, dims: tuple[int, int, int], warm: bool = True
    ) -> Solution:
        p = problem
        # a later friction pass on the rows whose factors the dual method holds: on those and its
        # working set first, where the candidates factor the rows afresh
        method = self._dual
        held = method is not None and method.holds(p)
        if method is not None and held and (dual := method.solve(problem)) is not None:
            return dual
        if warm and dims == self._solved:
            last = self._warm(problem, *self._last, 0.0, self._on_active_set(dims[0]))
            if last is not None:
                return last
        free = None if x_free is None else _free_motion(problem, x_free, self.options.eps_abs)
        if free is not None:
            return free
        if method is not None and not held and (dual := method.solve(problem)) is not None:
            return dual
        _, equalities, inequalities = _sides(p)
        if dims != self._dims:
            self._fresh(p, dims, equalities, inequalities)
            solution = self._run(problem)
        else:
            self._qp.update(p.H, p.g, *equalities, *inequalities)  # the upper bounds stay +inf
            solution = self._run(problem, WARM_START_ITERATIONS)
        if self._certified(solution):  # converged, finite and certified: nothing more to check
            return solution
        if solution.certificate.status not in INFEASIBLE:
            # the active set of the refused answer first: a linear solve or a few, where a cold start
            # of a settled pile's QP (120 coordinates, 400 rows) takes 70 to 330 ms
            rescued = self._warm(problem, solution.x, solution.multipliers, ACTIVE_SET_FLOOR)
            if rescued is not None:
                return _mended(rescued, solution)
            solution = self._recover(problem, dims, equalities, inequalities)
        self._check(problem, solution)
        return solution

    def _recover(
        self, problem: GaussProblem, dims: tuple[int, int, int], equalities: tuple, inequalities: tuple
    ) -> Solution:
        """After an answer the KKT check refused (not an infeasibility) and whose own active set did
        not solve the problem (:meth:`_solve` tries that first), the first certified of:

        1. a cold start in a new QP object: ProxQP 0.8, warm-started, may return the previous solution
           after 0 iterations when only the bounds changed (a stale contact force on a ball that left
           the ground), and a warm start from a much different problem can stall or diverge (a box
           stack whose contact patches changed size; the QP object kept NaNs after);
        2. that answer solved on the rows it holds active (multipliers above ACTIVE_SET_FLOOR of the
           largest; see :mod:`.active_set`): ProxQP may stop at a relative residual the check refuses
           where the active set is exact;
        3. a cold start at eps_abs / KKT_RTOL: ProxQP's own test passes at residuals the check's
           relative one can exceed;
        4. that answer's x with nonnegative multipliers of gaussim's (:meth:`_remultiplied`), where
           ProxQP's, one choice among many of dependent rows, have a wrong sign.

        Else the cold start's answer, its status KKT_CHECK_FAILED when ProxQP said solved."""
        p = problem
        self._fresh(p, dims, equalities, inequalities)
        solution = self._run(problem)
        solution.certificate.restarted = True
        if self._certified(solution):
            return solution
        rescued = self._warm(problem, solution.x, solution.multipliers, ACTIVE_SET_FLOOR)
        if rescued is not None:
            return _mended(rescued, solution)
        self._fresh(p, dims, equalities, inequalities)
        settings, eps = self._qp.settings, self.options.eps_abs
        settings.eps_abs = settings.eps_duality_gap_abs = eps / KKT_RTOL
        tight = self._run(problem)
        settings.eps_abs = settings.eps_duality_gap_abs = eps  # the next solves' tolerance
        tight.certificate.restarted = True
        if self._certified(tight):
            return tight
        rescued = self._remultiplied(problem, tight)
        if rescued is not None:
            return _mended(rescued, tight)
        if solution.certificate.converged:
            solution.certificate.status = Status.KKT_CHECK_FAILED
        return solution

    def _fresh(
        self, p: GaussProblem, dims: tuple[int, int, int], equalities: tuple, inequalities: tuple
    ) -> None:
        """A new QP object for the problem's sizes, initialised with it."""
        self._qp, self._cap = self._new(*dims), 0
        _initialise(self._qp, p, equalities, inequalities)
        self._dims = dims
        results = self._qp.results  # views that every solve of this QP object writes into
        self._results = results.x, results.y, results.z, results.info

    def _warm(
        self, problem: GaussProblem, x: np.ndarray, multipliers: np.ndarray, floor: float, solve: bool = True
    ) -> Solution | None:
        """A solution built from (x, multipliers), the last solution or ProxQP's answer that failed
        the check, with its rows active whose multipliers exceed ``floor`` times the largest (see
        :mod:`.active_set`; with ``solve`` False, only (x, multipliers) itself), when gaussim's
        relative KKT residual certifies it to eps_abs (stricter than the KKT_RTOL eps_abs at which
        ProxQP's answers are accepted), else None. On a robot standing, the last solution or its active
        set solves most steps' problems, at a fraction of a solver's call."""
        p = problem
        if not solve:
            return checked(p, x, multipliers, Status.PREVIOUS_SOLUTION_CERTIFIED, self.options.eps_abs)
        candidate = self._candidate
        if len(candidate[0]) != len(x) or len(candidate[1]) != len(multipliers):
            candidate = self._candidate = np.empty_like(x), np.empty_like(multipliers)
        how, residuals = active_set_candidate.call(
            p.H, p.g, p.A, p.b, p.C, p.l, x, multipliers, self.options.eps_abs, floor, *candidate
        )
        if not how:
            return None
        if how == 2:  # the next call writes into the same buffers: the solution gets copies
            x, multipliers = candidate[0].copy(), candidate[1].copy()
        return Solution(x, multipliers, len(p.b), warm_certificate(how, residuals))

    def _remultiplied(self, problem: GaussProblem, solution: Solution) -> Solution | None:
        """``solution``'s x with multipliers of gaussim's making, when the KKT check certifies them as
        it does ProxQP's answers, else None. With more dependent rows than unknowns (a pile's
        contacts), the multipliers of x are one choice among many and ProxQP's may hold a wrong sign
        where x itself is optimal. Nonnegative ones are the least-squares solution of the stationarity
        A^T lambda_eq + C_k^T lambda_k = H x + g over lambda_k >= 0, k the rows within the check's
        tolerance of their bound (the others' are 0): a small bounded QP, solved by ProxQP at
        eps_abs / KKT_RTOL."""
        p, x, tolerance = problem, solution.x, KKT_RTOL * self.options.eps_abs
        near = np.flatnonzero(p.C @ x - p.l <= tolerance)
        n_eq, k = len(p.b), len(near)
        E = np.vstack([p.A, p.C[near]]).T  # (nv, n_eq + k): each row's force direction
        stationarity = p.H @ x + p.g
        # solved for lambda / |H x + g|: a least-squares residual is the square root of the QP's
        # accuracy, which is then relative to 1
        size = max(float(np.abs(stationarity).max(initial=0.0)), np.finfo(float).tiny)
        multipliers = np.zeros(n_eq + len(p.l))
        if n_eq + k:
            qp = self._new(n_eq + k, 0, k)
            qp.settings.eps_abs = qp.settings.eps_duality_gap_abs = self.options.eps_abs / KKT_RTOL
            signs = np.hstack([np.zeros((k, n_eq)), np.eye(k)])  # lambda_k >= 0, lambda_eq free
            bounds = (signs, np.zeros(k), np.full(k, np.inf)) if k else (None, None, None)
            qp.init(E.T @ E, -(E.T @ stationarity) / size, None, None, *bounds)
            qp.solve()
            multipliers[:n_eq] = size * qp.results.x[:n_eq]
            multipliers[n_eq + near] = size * np.maximum(qp.results.x[n_eq:], 0.0)  # its bound, met to eps
        return checked(problem, x.copy(), multipliers, Status.MULTIPLIERS_CERTIFIED, tolerance)

    def _run(self, problem: GaussProblem, cap: int | None = None) -> Solution:
        """Solve with at most ``cap`` outer iterations (default and largest: Options.max_iter)."""
        cap = min(cap or self.options.max_iter, self.options.max_iter)
        if cap != self._cap:  # a settings write costs as much as a small update: only on a change
            self._qp.settings.max_iter = self._cap = cap
        self._qp.solve()
        x, y, z, info = self._results
        p = problem
        # copies (ProxQP's arrays are overwritten by the next solve); the multipliers are -y, -z
        x, multipliers, residual, relative, _, _, _ = read_results.call(p.H, p.g, p.A, p.b, p.C, p.l, x, y, z)
        status = info.status
        certificate = Certificate(  # ProxQP's info gives Python ints and floats
            Status.SOLVED if status is _SOLVED else _STATUS[status],
            info.iter,
            info.pri_res,
            info.dua_res,
            info.duality_gap,
            residual,
            relative,
            info.iter_ext,
        )
        return Solution(x, multipliers, len(p.b), certificate)

    def _certified(self, solution: Solution) -> bool:
        """True when the KKT check certifies the solution and ProxQP converged or stopped at its
        iteration cap; a certified stop at the cap gets the status CERTIFIED_AT_MAX_ITER."""
        c = solution.certificate
        if not c.relative_kkt_residual <= KKT_RTOL * self.options.eps_abs:  # NaN fails too
            return False
        if c.status is Status.MAX_ITER_REACHED:
            c.status = Status.CERTIFIED_AT_MAX_ITER
        return c.converged

    def _new(self, n: int, n_eq: int, n_in: int) -> Any:
        """A dense QP object (its factorization chosen by size, see PRIMAL_DUAL_UP_TO) with gaussim's
        settings."""
        backends = proxqp.dense.DenseBackend
        backend = backends.PrimalDualLDLT if n + n_eq + n_in <= PRIMAL_DUAL_UP_TO else backends.Automatic
        qp = proxqp.dense.QP(n, n_eq, n_in, False, proxqp.dense.HessianType.Dense, backend)
        settings = qp.settings
        settings.eps_abs = self.options.eps_abs
        settings.eps_rel = 0.0
        settings.verbose = False
        # Warm start from the previous result, with the duality-gap check on: without it ProxQP 0.8
        # may accept the previous solution after 0 iterations when only the bounds changed.
        settings.initial_guess = proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
        settings.check_duality_gap = True
        settings.eps_duality_gap_abs = self.options.eps_abs
        settings.eps_duality_gap_rel = 0.0
        settings.primal_infeasibility_solving = False
        # H = M is positive definite, so a Gauss problem is never unbounded: ProxQP's dual-infeasibility
        # test, which stopped allegro_right_hand's fall with a false PROXQP_DUAL_INFEASIBLE, stays off
        settings.eps_dual_inf = 1e-14
        settings.max_iter_in = INNER_ITERATIONS
        return qp

    def _check(self, problem: GaussProblem, solution: Solution) -> None:
        """Raise for an infeasible problem, a non-finite solution or (``Options.on_failure='raise'``)
        an unconverged one; warn once about an unconverged iterate kept."""
        c = solution.certificate
        if c.status in PRIMAL_INFEASIBLE:
            raise infeasibility(problem, c, self._closest_feasible(problem))
        error = failure(problem, c, self.options.on_failure == "raise")
        if error is not None:
            raise error
        if not c.converged and not self._warned:
            self._warned = True
            warnings.warn(
                f"ProxQP did not converge ({c.status}, KKT residual {c.kkt_residual:.2e}): "
                "on_failure='report' kept its iterate, which need not be the Gauss principle's motion; each "
                "such step is counted (StepReport.converged, the run log's summary); not repeated",
                GaussimWarning,
                stacklevel=2,
            )

    def _closest_feasible(self, problem: GaussProblem) -> np.ndarray:
        """ProxQP's closest-feasible solution of an infeasible problem: the x that needs the smallest
        change of the bounds, in the least-squares sense."""
        p = problem
        dims, equalities, inequalities = _sides(p)
        qp = self._new(*dims)
        qp.settings.primal_infeasibility_solving = True
        qp.settings.initial_guess = proxqp.InitialGuess.NO_INITIAL_GUESS
        qp.settings.max_iter = self.options.max_iter
        _initialise(qp, p, equalities, inequalities)
        qp.solve()
        return np.array(qp.results.x)


def _mended(rescued: Solution, source: Solution) -> Solution:
    """``rescued``, a solution gaussim made from ProxQP's answer ``source``, with that solve's
    iterations and restart."""
    c, solved = rescued.certificate, source.certificate
    c.iterations, c.outer_iterations = solved.iterations, solved.outer_iterations
    c.restarted = solved.restarted
    return rescued


def _free_motion(problem: GaussProblem, x_free: np.ndarray, tolerance: float) -> Solution | None:
    """The free motion, with no reaction, where it meets every row (a contact within its margin that
    the step does not reach: exactly the motion of the body alone), when the KKT check certifies it to
    ``tolerance``; else None."""
    none = np.zeros(len(problem.b) + len(problem.l))
    return checked(problem, np.array(x_free, dtype=float), none, Status.FREE_MOTION_CERTIFIED, tolerance)


def warm_certificate(how: int, residuals: Sequence[float]) -> Certificate:
    """The certificate of a candidate of active_set_candidate (its ``how``, 1 or 2, and ``residuals``:
    the residual, the relative one, the primal and dual residuals and the gap)."""
    residual, relative, primal, dual, gap = residuals
    return Certificate(_FROM_LAST[how], 0, primal, dual, gap, residual, relative)


def _sides(p: GaussProblem) -> tuple[tuple[int, int, int], tuple, tuple]:
    """The problem's sizes (n, n_eq, n_in) and its (A, b) and (C, l) as ProxQP takes them (None, None
    for an empty side)."""
    dims = (len(p.g), len(p.b), len(p.l))
    return dims, (p.A, p.b) if dims[1] else (None, None), (p.C, p.l) if dims[2] else (None, None)


def _initialise(qp: Any, p: GaussProblem, equalities: tuple, inequalities: tuple) -> None:
    """Initialise a new QP object with the problem (every inequality row is one-sided: u = +inf)."""
    upper = np.full(len(p.l), np.inf) if len(p.l) else None
    qp.init(p.H, p.g, *equalities, *inequalities, upper)
