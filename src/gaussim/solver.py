"""Stage 5, the ProxQP solve: one dense QP object, reused while the problem keeps its size."""

from __future__ import annotations

import math
import sys
import types
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from .assembly import GaussProblem
from .exceptions import GaussimWarning, InfeasibleConstraints, SolverError
from .linalg import backward, cholesky, dot, forward, matvec
from .options import Options


def _portable_proxsuite() -> types.ModuleType:
    """proxsuite, with its build without AVX2 or AVX-512 kernels when this process has not loaded
    it yet. Measured (ProxQP 0.8, the QPs of a Solo-12 landing, 20 fresh QP objects each): its AVX-512
    build answers 16 of 60 problems differently from one object to the next in the last bits, its
    AVX2 build 56, its portable build none, at the same cost (45 to 50 us an init and solve), so runs
    repeat bit for bit. proxsuite picks its build at import by asking its ``instructionset`` module;
    this answers "neither" for that one import. Loaded already, or when proxsuite asks its module
    something else, the build proxsuite chose is used: two builds in one process abort it."""
    if "proxsuite" in sys.modules:
        return sys.modules["proxsuite"]
    plain = types.ModuleType("proxsuite.instructionset")
    plain.has_AVX512F = plain.has_AVX2 = lambda: False  # type: ignore[attr-defined]
    sys.modules["proxsuite.instructionset"] = plain
    try:
        import proxsuite
    except AttributeError:  # it asked before loading any build
        proxsuite = None
    finally:
        del sys.modules["proxsuite.instructionset"]
    if proxsuite is None:
        import proxsuite
    return proxsuite


proxsuite = _portable_proxsuite()
_proxqp = proxsuite.proxqp
_STATUS = {status: status.name for status in _proxqp.QPSolverOutput.__members__.values()}
_SOLVED = _proxqp.QPSolverOutput.PROXQP_SOLVED  # compared by identity: hashing the enum costs more
# A row violated by more than this at ProxQP's last point, or an inequality within it of its bound, is
# named as involved in an infeasibility.
INFEASIBLE_ROW_TOLERANCE = 1e-6
INFEASIBLE = ("PROXQP_PRIMAL_INFEASIBLE", "PROXQP_SOLVED_CLOSEST_PRIMAL_FEASIBLE", "PROXQP_DUAL_INFEASIBLE")
# A solution is accepted when its relative KKT residual (see Certificate) is below KKT_RTOL * eps_abs.
KKT_RTOL = 100.0
# The statuses of an accepted solution: ProxQP's, or ProxQP stopped at its iteration cap at a point
# gaussim's KKT check certifies (measured: a 1e4 kg box on a 1 kg one, whose redundant contact rows
# conflict by ~1e-9 m/s in round-off, so that ProxQP cannot bring its primal residual below eps_abs).
CONVERGED = (
    "PROXQP_SOLVED",
    "GAUSSIM_CERTIFIED_AT_MAX_ITER",
    "GAUSSIM_PREVIOUS_SOLUTION_CERTIFIED",
    "GAUSSIM_ACTIVE_SET_CERTIFIED",
)
# Rounds of iterative refinement of the active-set solve (see _warm): each divides the error of a
# multiplier direction of curvature c by 1 + c / (ACTIVE_SET_SHIFT max diag G).
ACTIVE_SET_REFINEMENTS = 2
# The relative shift that makes the active rows' Delassus matrix G positive definite when those rows
# are dependent (a sticking contact's four pyramid rows span three directions).
ACTIVE_SET_SHIFT = 1e-12
# In ProxQP's answer, an inequality row is active when its multiplier exceeds this fraction of the
# largest one: ProxQP leaves multipliers of 1e-172 on inactive rows (measured: Talos at dt = 0.02),
# which would make them equalities. (The last solution keeps every positive multiplier's row: with
# this floor there, Talos with 16 friction facets met a QP that neither ProxQP nor its active set
# solves.)
ACTIVE_SET_FLOOR = 1e-12
# ProxQP's outer-iteration cap for a warm-started solve. A warm start needs 0 to 30 iterations
# (measured over the shipped scenes and the stress stacks); one that needs more is better solved
# again from a cold start. Measured on a box stack whose redundant contact rows conflict by 1e-9 m/s
# (bounds gap/dt with round-off gaps): warm-started, ProxQP ran its 10000 outer iterations with up to
# 1500 inner ones each (1.4 million, 77 s); capped at 100 it stops in 3 ms at a certified point.
WARM_START_ITERATIONS = 100
# ProxQP's cap on the inner iterations of each outer one (its default is 1500). Where a problem cannot
# reach eps_abs, the inner loop may exhaust that cap at each outer iteration (measured: Solo-12 at
# dt = 0.02, 1.48 million iterations, 10 s, for one step's cold solve); the inner solves that converge
# take a few iterations.
INNER_ITERATIONS = 100


def kkt_residual(problem: GaussProblem, x: np.ndarray, lambda_eq: np.ndarray, lambda_in: np.ndarray) -> float:
    """Largest violation of the KKT conditions of the Gauss problem at (x, lambda_eq, lambda_in >= 0):
    the stationarity residual |H x + g - A^T lambda_eq - C^T lambda_in|, the primal violations
    |A x - b| and l - C x, the sign violation -lambda_in and the complementarity |lambda_in (C x - l)|;
    NaN when any of them is not finite."""
    p = problem
    return _kkt_residuals(p.H, p.g, p.A, p.b, p.C, p.l, x, lambda_eq, lambda_in)[0]


@njit(cache=True)
def _kkt_residuals(H, g, A, b, C, l, x, y, z):  # type: ignore[no-untyped-def]
    """(the residual of :func:`kkt_residual`, the same with each term relative to its size, the
    primal violation, the stationarity residual, the duality gap sum_i z_i s_i): the relative
    residual takes the stationarity residual and the sign violation -z_i (both in the units of g)
    relative to max(1, |g|_inf), a complementarity |z_i s_i| relative to max(1, |z_i|), which makes it
    the slack of a row with a large multiplier (a heavy body's contact). All NaN when any term is not
    finite."""
    primal = relative = gap = 0.0
    complementarity = 0.0
    finite = True
    size = 1.0
    for i in range(len(g)):
        size = max(size, abs(g[i]))
    stationarity = matvec(H, x) + g
    for i in range(len(b)):
        for k in range(len(g)):  # loops, not array expressions: those allocate a temporary each
            stationarity[k] -= y[i] * A[i, k]
        violation = abs(dot(A[i], x) - b[i])
        primal, finite = max(primal, violation), finite and np.isfinite(violation) and np.isfinite(y[i])
    for i in range(len(l)):
        for k in range(len(g)):
            stationarity[k] -= z[i] * C[i, k]
        slack = dot(C[i], x) - l[i]
        gap += z[i] * slack
        primal = max(primal, -slack)
        complementarity = max(complementarity, -z[i], abs(z[i] * slack))
        relative = max(relative, -z[i] / size, abs(z[i] * slack) / max(1.0, abs(z[i])))
        finite = finite and np.isfinite(slack) and np.isfinite(z[i])
    dual = 0.0
    for i in range(len(g)):
        dual, finite = max(dual, abs(stationarity[i])), finite and np.isfinite(stationarity[i])
    worst = max(primal, complementarity, dual)
    relative = max(relative, primal, dual / size)
    if not finite:
        return np.nan, np.nan, np.nan, np.nan, np.nan
    return worst, relative, primal, dual, abs(gap)


@njit(cache=True)
def _read(H, g, A, b, C, l, x, y, z):  # type: ignore[no-untyped-def]
    """(x, the multipliers [-y; -z], the residuals of :func:`_kkt_residuals` there), copied out of
    ProxQP's results."""
    n_eq, n_in = len(b), len(l)
    x, multipliers = x.copy(), np.empty(n_eq + n_in)
    multipliers[:n_eq], multipliers[n_eq:] = -y[:n_eq], -z[:n_in]
    return (x, multipliers, *_kkt_residuals(H, g, A, b, C, l, x, multipliers[:n_eq], multipliers[n_eq:]))


@njit(cache=True, fastmath={"reassoc", "contract"})
def _warm(H, g, A, b, C, l, x, multipliers, tolerance, floor, x_out, multipliers_out):  # type: ignore[no-untyped-def]
    """(how, the residuals of :func:`_kkt_residuals`) for the first of two candidates built from the
    last solution (x, multipliers) that the relative KKT residual certifies (<= ``tolerance``): that
    solution itself (how 1), then the solution of the problem with the rows it held active (its
    equalities and the inequalities with a multiplier above ``floor`` times the largest, and > 0) as
    equalities (how 2, written into ``x_out`` and ``multipliers_out``): one linear solve, an
    active-set method's step, exact when the active set did not change (a contact that keeps
    sticking, a limit that keeps holding). how 0: neither is certified.

    The active-set solve: x = H^-1 (K^T lam - g), K the active rows and r their right-hand sides,
    with G lam = r + K H^-1 g, G = K H^-1 K^T the rows' Delassus matrix, shifted by ACTIVE_SET_SHIFT
    max diag G and refined ACTIVE_SET_REFINEMENTS times (dependent rows make G singular; their
    multipliers' split is then one of many, which the check accepts when it is >= 0)."""
    n_eq, nv = len(b), len(g)
    residuals = _kkt_residuals(H, g, A, b, C, l, x, multipliers[:n_eq], multipliers[n_eq:])
    if residuals[1] <= tolerance:
        return 1, residuals
    inequality = multipliers[n_eq:]
    least = floor * inequality.max() if len(inequality) else 0.0  # what an active row's exceeds
    active = np.flatnonzero(inequality > max(least, 0.0))
    k = n_eq + len(active)
    K, r = np.empty((k, nv)), np.empty(k)
    K[:n_eq], r[:n_eq] = A, b
    for i in range(len(active)):
        K[n_eq + i], r[n_eq + i] = C[active[i]], l[active[i]]
    L = cholesky(H, 0.0)
    if L is None:
        return 0, residuals
    W = forward(L, K)  # the rows of K L^-T, (k, nv)
    h = forward(L, g.copy().reshape((1, nv)))[0]  # L^-1 g
    G, rhs, largest = np.empty((k, k)), r, 0.0
    for i in range(k):
        for j in range(i + 1):
            G[i, j] = G[j, i] = dot(W[i], W[j])
        rhs[i] += dot(W[i], h)
        largest = max(largest, G[i, i])
    LG = cholesky(G, ACTIVE_SET_SHIFT * largest)
    if LG is None:
        return 0, residuals
    lam = np.zeros(k)
    for _ in range(ACTIVE_SET_REFINEMENTS):
        step = rhs - matvec(G, lam)
        lam += backward(LG, forward(LG, step.reshape((1, k)))[0])
    y = -h  # W^T lam - h, then L^-T of it
    for i in range(k):
        for j in range(nv):
            y[j] += lam[i] * W[i, j]
    x_out[:] = backward(L, y)
    multipliers_out[:] = 0.0
    multipliers_out[:n_eq] = lam[:n_eq]
    for i in range(len(active)):
        multipliers_out[n_eq + active[i]] = lam[n_eq + i]
    residuals = _kkt_residuals(H, g, A, b, C, l, x_out, multipliers_out[:n_eq], multipliers_out[n_eq:])
    return 2 if residuals[1] <= tolerance else 0, residuals


@dataclass
class Certificate:
    """What ProxQP says about one solve.

    Attributes:
        status: ProxQP's status name (``PROXQP_SOLVED`` when converged), or gaussim's:
            ``GAUSSIM_CERTIFIED_AT_MAX_ITER`` (ProxQP reached its iteration cap at a point the KKT check
            below certifies: accepted), ``GAUSSIM_KKT_CHECK_FAILED`` (ProxQP said solved, the check
            disagrees), ``GAUSSIM_PREVIOUS_SOLUTION_CERTIFIED`` (the previous solution solves this
            problem to eps_abs by the KKT check below: ProxQP was not called),
            ``GAUSSIM_ACTIVE_SET_CERTIFIED`` (so does the solution on the previous solution's active
            set, one linear solve: ProxQP was not called).
        iterations: ProxQP's iterations in all: the inner ones of each of its outer iterations.
        outer_iterations: ProxQP's outer iterations, the ones ``Options.max_iter`` caps.
        primal_residual: max constraint violation of the returned x.
        dual_residual: norm of the stationarity residual H x + g + A^T y + C^T z.
        duality_gap: ProxQP's duality gap.
        kkt_residual: gaussim's own check of the returned point on the problem as posed: the largest
            of the primal violation, the stationarity residual |H x + g - A^T y - C^T z|, the sign
            violation of z and the complementarity |z_i (C x - l)_i|.
        relative_kkt_residual: the same with the stationarity residual and the sign violation
            relative to max(1, |g|_inf) and each complementarity relative to max(1, |z_i|); a
            solution is accepted when it is below KKT_RTOL * eps_abs.
        restarted: True when the warm-started answer failed that check and ProxQP was run again
            from a cold start.
    """

    status: str
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


# A free motion faster than this [m/s or rad/s] comes from absurd inputs, not from the solver's settings.
EXTREME_REACH = 1e8


def _reach(problem: GaussProblem) -> float:
    """The size of the problem's free solution, |g| / max diag(H) (inf for non-finite data)."""
    scale = float(np.abs(np.diagonal(problem.H)).max(initial=0.0))
    size = float(np.abs(problem.g).max(initial=0.0))
    return size / scale if scale > 0 and math.isfinite(size) else math.inf


class GaussSolver:
    """Dense ProxQP, allocated once per problem size and warm-started from the previous result."""

    def __init__(self, options: Options) -> None:
        self.options = options
        self._qp: Any = None  # proxsuite.proxqp.dense.QP
        self._dims: tuple[int, int, int] | None = None
        self._results: tuple[Any, ...] = ()  # the QP object's x, y, z and info
        self._cap = 0  # the QP object's iteration cap
        self._last: tuple[np.ndarray, np.ndarray] = (np.zeros(0), np.zeros(0))  # x, multipliers
        self._candidate = self._last  # the buffers of the active-set candidate (see _warm)
        self._warned = False  # about an iterate kept by on_failure='report'

    def solve(self, problem: GaussProblem) -> Solution:
        """Solve the Gauss problem; raise :class:`SolverError` as ``Options.on_failure`` says."""
        solution = self._solve(problem)
        self._last = solution.x, solution.multipliers  # where the next solve starts (see _warm)
        return solution

    def _solve(self, problem: GaussProblem) -> Solution:
        p = problem
        dims, equalities, inequalities = _sides(p)
        if dims != self._dims:
            self._fresh(p, dims, equalities, inequalities)
            solution = self._run(problem)
        else:
            warm = self._warm(problem, *self._last, 0.0)
            if warm is not None:
                return warm
            self._qp.update(p.H, p.g, *equalities, *inequalities)  # the upper bounds stay +inf
            solution = self._run(problem, WARM_START_ITERATIONS)
        if self._certified(solution):  # converged, finite and certified: nothing more to check
            return solution
        if solution.certificate.status not in INFEASIBLE:
            solution = self._recover(problem, dims, equalities, inequalities)
        self._check(problem, solution)
        return solution

    def _recover(
        self, problem: GaussProblem, dims: tuple[int, int, int], equalities: tuple, inequalities: tuple
    ) -> Solution:
        """After an answer the KKT check refused (not an infeasibility), the first certified of:

        1. a cold start in a new QP object: ProxQP 0.8, warm-started, may return the previous solution
           after 0 iterations when only the bounds changed (measured: a stale contact force on a ball
           that left the ground), and a warm start from a much different problem can stall or diverge
           (measured: a box stack whose contact patches changed size; the QP object kept NaNs after);
        2. that answer solved on the rows it holds active (multipliers above ACTIVE_SET_FLOOR of the
           largest; see :func:`_warm`): measured on Talos at dt = 0.02, ProxQP stops at a relative
           residual of 1.5e-6 and the active set gives 8e-17;
        3. a cold start at eps_abs / KKT_RTOL: ProxQP's own test passes at residuals the check's
           relative one can exceed (measured: a block on an incline with 16 friction facets, 1.4e-7
           at eps_abs 1e-9 against the accepted 1e-7; 1.4e-11 at 1e-11, in 1160 iterations).

        Else the cold start's answer, its status GAUSSIM_KKT_CHECK_FAILED when ProxQP said solved."""
        p = problem
        self._fresh(p, dims, equalities, inequalities)
        solution = self._run(problem)
        solution.certificate.restarted = True
        if self._certified(solution):
            return solution
        rescued = self._warm(problem, solution.x, solution.multipliers, ACTIVE_SET_FLOOR)
        if rescued is not None:
            rescued.certificate.iterations = solution.certificate.iterations
            rescued.certificate.outer_iterations = solution.certificate.outer_iterations
            rescued.certificate.restarted = True
            return rescued
        self._fresh(p, dims, equalities, inequalities)
        settings, eps = self._qp.settings, self.options.eps_abs
        settings.eps_abs = settings.eps_duality_gap_abs = eps / KKT_RTOL
        tight = self._run(problem)
        settings.eps_abs = settings.eps_duality_gap_abs = eps  # the next solves' tolerance
        tight.certificate.restarted = True
        if self._certified(tight):
            return tight
        if solution.certificate.converged:
            solution.certificate.status = "GAUSSIM_KKT_CHECK_FAILED"
        return solution

    def _fresh(
        self, p: GaussProblem, dims: tuple[int, int, int], equalities: tuple, inequalities: tuple
    ) -> None:
        """A new QP object for the problem's sizes, initialised with it."""
        self._qp, self._cap = self._new(*dims), 0
        _initialise(self._qp, p, equalities, inequalities)
        self._dims = dims
        results = self._qp.results  # views that every solve of this QP object writes into
        self._candidate = np.empty(dims[0]), np.empty(dims[1] + dims[2])  # what _warm writes into
        self._results = results.x, results.y, results.z, results.info

    def _warm(
        self, problem: GaussProblem, x: np.ndarray, multipliers: np.ndarray, floor: float
    ) -> Solution | None:
        """A solution built from (x, multipliers), the last solution or ProxQP's answer that failed
        the check, with its rows active whose multipliers exceed ``floor`` times the largest (see
        :func:`_warm`), when gaussim's relative KKT residual certifies it to eps_abs
        (stricter than the KKT_RTOL eps_abs at which ProxQP's answers are accepted), else None.
        Measured on Solo-12 standing: the last solution solves 76% of the steps' problems, its active
        set the other 24% (3000 steps); a call costs 1.7 us when the last solution holds, 7.7 us when
        the active set is solved, against 12.8 us for ProxQP's warm-started update and solve of the
        same problem."""
        p = problem
        candidate = self._candidate
        how, (residual, relative, primal, dual, gap) = _warm(
            p.H, p.g, p.A, p.b, p.C, p.l, x, multipliers, self.options.eps_abs, floor, *candidate
        )
        if not how:
            return None
        if how == 2:  # the next call writes into the same buffers: the solution gets copies
            x, multipliers = candidate[0].copy(), candidate[1].copy()
        certificate = Certificate(CONVERGED[1 + how], 0, primal, dual, gap, residual, relative)
        return Solution(x, multipliers, len(p.b), certificate)

    def _run(self, problem: GaussProblem, cap: int | None = None) -> Solution:
        """Solve with at most ``cap`` outer iterations (default and largest: Options.max_iter)."""
        cap = min(cap or self.options.max_iter, self.options.max_iter)
        if cap != self._cap:  # a settings write costs as much as a small update: only on a change
            self._qp.settings.max_iter = self._cap = cap
        self._qp.solve()
        x, y, z, info = self._results
        p = problem
        # copies (ProxQP's arrays are overwritten by the next solve); the multipliers are -y, -z
        x, multipliers, residual, relative, _, _, _ = _read(p.H, p.g, p.A, p.b, p.C, p.l, x, y, z)
        status = info.status
        certificate = Certificate(  # ProxQP's info gives Python ints and floats
            "PROXQP_SOLVED" if status is _SOLVED else _STATUS[status],
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
        iteration cap; a certified stop at the cap gets the status GAUSSIM_CERTIFIED_AT_MAX_ITER."""
        c = solution.certificate
        if not c.relative_kkt_residual <= KKT_RTOL * self.options.eps_abs:  # NaN fails too
            return False
        if c.status == "PROXQP_MAX_ITER_REACHED":
            c.status = CONVERGED[1]
        return c.converged

    def _new(self, n: int, n_eq: int, n_in: int) -> Any:
        qp = _proxqp.dense.QP(n, n_eq, n_in)
        settings = qp.settings
        settings.eps_abs = self.options.eps_abs
        settings.eps_rel = 0.0
        settings.verbose = False
        # Warm start from the previous result, with the duality-gap check on: without it ProxQP 0.8
        # may accept the previous solution after 0 iterations when only the bounds changed.
        settings.initial_guess = _proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
        settings.check_duality_gap = True
        settings.eps_duality_gap_abs = self.options.eps_abs
        settings.eps_duality_gap_rel = 0.0
        settings.primal_infeasibility_solving = False
        settings.max_iter_in = INNER_ITERATIONS
        return qp

    def _check(self, problem: GaussProblem, solution: Solution) -> None:
        c = solution.certificate
        finite = math.isfinite(c.kkt_residual)  # NaN or inf anywhere in x or the multipliers shows there
        if c.status in ("PROXQP_PRIMAL_INFEASIBLE", "PROXQP_SOLVED_CLOSEST_PRIMAL_FEASIBLE"):
            x, shift = self._closest_feasible(problem)
            rows = self._involved(problem, x)
            raise InfeasibleConstraints(
                f"the admissible set is empty ({c.status}); conflicting rows: {', '.join(rows) or 'unknown'}"
                f"; the smallest change of their bounds that admits a motion is {shift:.3g} (2-norm)",
                rows,
                c,
            )
        reach = _reach(problem)
        extreme = (
            f"; the free motion reaches |x| ~ {reach:.1e} (m/s or rad/s): a torque, gain or scene value far "
            "beyond any robot's, no solver setting, is the cause; check the inputs"
            if reach > EXTREME_REACH
            else ""
        )
        if not finite:
            raise SolverError(f"ProxQP returned a non-finite solution ({c.status}){extreme}", c)
        if not c.converged and self.options.on_failure == "raise":
            raise SolverError(
                f"ProxQP did not converge: {c.status} after {c.outer_iterations} outer iterations, "
                f"{c.iterations} in all (primal residual {c.primal_residual:.2e}, dual residual "
                f"{c.dual_residual:.2e}, duality gap {c.duality_gap:.2e})"
                + (extreme or "; raise Options.max_iter or eps_abs, or set on_failure='report'"),
                c,
            )
        if not c.converged and not self._warned:
            self._warned = True
            warnings.warn(
                f"ProxQP did not converge ({c.status}, KKT residual {c.kkt_residual:.2e}): "
                "on_failure='report' kept its iterate, which need not be the Gauss principle's motion; each "
                "such step is counted (StepReport.converged, the run log's summary); not repeated",
                GaussimWarning,
                stacklevel=2,
            )

    def _closest_feasible(self, problem: GaussProblem) -> tuple[np.ndarray, float]:
        """ProxQP's closest-feasible solution of an infeasible problem (the x that needs the smallest
        change of the bounds, in the least-squares sense) and the size of that change."""
        p = problem
        dims, equalities, inequalities = _sides(p)
        qp = self._new(*dims)
        qp.settings.primal_infeasibility_solving = True
        qp.settings.initial_guess = _proxqp.InitialGuess.NO_INITIAL_GUESS
        qp.settings.max_iter = self.options.max_iter
        _initialise(qp, p, equalities, inequalities)
        qp.solve()
        x = np.array(qp.results.x)
        shift = np.concatenate([p.A @ x - p.b, np.minimum(p.C @ x - p.l, 0.0)])
        return x, float(np.linalg.norm(shift))

    @staticmethod
    def _involved(problem: GaussProblem, x: np.ndarray) -> list[str]:
        """The rows behind an infeasibility, at the closest-feasible point x: the violated ones, and the
        inequalities at their bound (a joint limit that holds while the anchor it blocks is violated)."""
        names = []
        eq = np.abs(problem.A @ x - problem.b)
        names += [n for n, r in zip(problem.labels(True), eq) if r > INFEASIBLE_ROW_TOLERANCE]
        ineq = problem.l - problem.C @ x
        names += [n for n, r in zip(problem.labels(False), ineq) if r > -INFEASIBLE_ROW_TOLERANCE]
        return names


def _sides(p: GaussProblem) -> tuple[tuple[int, int, int], tuple, tuple]:
    """The problem's sizes (n, n_eq, n_in) and its (A, b) and (C, l) as ProxQP takes them (None, None
    for an empty side)."""
    dims = (len(p.g), len(p.b), len(p.l))
    return dims, (p.A, p.b) if dims[1] else (None, None), (p.C, p.l) if dims[2] else (None, None)


def _initialise(qp: Any, p: GaussProblem, equalities: tuple, inequalities: tuple) -> None:
    """Initialise a new QP object with the problem (every inequality row is one-sided: u = +inf)."""
    upper = np.full(len(p.l), np.inf) if len(p.l) else None
    qp.init(p.H, p.g, *equalities, *inequalities, upper)
