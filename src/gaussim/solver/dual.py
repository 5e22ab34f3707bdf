"""The dual active-set solve: gaussim's compiled method on sparse rows, or DAQP, before ProxQP is asked.

The Gauss problem's H = M is positive definite, which is the setting of a dual active-set method:
it starts from the unconstrained minimum and adds the violated rows one at a time, keeping a linearly
independent working set and its LDL^T factors. gaussim's own (:class:`SparseDualActiveSet`, the
kernels of :mod:`gaussim.kernels.dual`) keeps each row sparse in least-distance form, which a pile's
rows, each reading two bodies' 12 of the island's coordinates, make cheaper to set up than DAQP's dense
rows (Arnström, Bemporad, Axehill 2022; :class:`DaqpActiveSet`, ``Options(solver="daqp")``). A contact's
pyramid rows are dependent (four facets span three directions, a pile's stacked contacts more),
which an interior or proximal method such as ProxQP pays for in iterations and refactorizations; an
active-set method leaves them out: a settled pile's island (120 coordinates, 336 rows) takes 140
iterations, 2 to 3.5 ms, from a cold start, where ProxQP took 20 to 40 ms. Each island keeps its
solver's workspace: a problem that differs from the last one only in its bounds (the friction passes of
one step, which shift the normal rows' bounds) is solved on the factors and working set it left; a new
one starts from the last working set, its rows matched by their ids (:attr:`GaussProblem.row_ids`).
The answer, like ProxQP's, is accepted only when gaussim's KKT check certifies it.
"""

from __future__ import annotations

from typing import Any

import daqp
import numpy as np

from ..assembly import GaussProblem
from ..kernels.bound import Bound
from ..kernels.dual import OPTIMAL
from .certificate import Solution, Status, checked

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
dual_iterations = Bound("dual.dual_iterations")
envelope_cholesky = Bound("dual.envelope_cholesky")
free_products = Bound("dual.free_products")
primal_answer = Bound("dual.primal_answer")
start_set = Bound("dual.start_set")
transformed_rows = Bound("dual.transformed_rows")
matched_values = Bound("solver.matched_values")

_OPTIMAL = 1  # DAQP's exitflag of an optimal solution
_EQUALITY = 5  # DAQP's sense of an equality row
_UNBOUNDED = 1e30  # DAQP's infinite bound


# A row joins the working set when its pivot exceeds this fraction of its squared norm: a smaller one is
# a combination of the set's rows up to round-off (a sticking contact's fourth pyramid facet).
DEPENDENCE = 1e-10
# The compiled method's cap on iterations from one start (a pile's cold start takes about 100).
ITERATIONS = 1000


class SparseDualActiveSet:
    """gaussim's dual active-set method (:mod:`gaussim.kernels.dual`) for the problems of one island:
    the factors and sparse rows of the problem it holds, and the working set of its last solve."""

    def __init__(self, eps_abs: float, tolerance: float) -> None:
        self.eps_abs, self.tolerance = eps_abs, tolerance
        self._key: object = None  # the rows_key of the problem whose factors it holds
        self._n_eq = 0  # how many of its rows are equalities
        self._g: np.ndarray | None = None  # the g of the free products it holds
        self._ids = np.zeros(0, dtype=np.int64)  # the row ids of those rows
        self._arrays: tuple[np.ndarray, ...] = ()  # the factors and rows (see _setup)
        self._set: tuple[np.ndarray, ...] = ()  # the working set (see _setup)
        self._size = -1  # the working set's size, -1 when it holds no solve's
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # the last solution's row ids, multipliers

    def holds(self, problem: GaussProblem) -> bool:
        """Whether it holds the factors of ``problem``'s rows and the working set of a solve on them (a
        later friction pass of the same step)."""
        return self._size >= 0 and self._factored(problem)

    def _factored(self, p: GaussProblem) -> bool:
        """Whether its factors and sparse rows are ``p``'s (the key of the problem they were set up for
        spares comparing H and the rows)."""
        return self._key is not None and p.rows_key == self._key and len(p.b) == self._n_eq

    def solve(self, problem: GaussProblem) -> Solution | None:
        """The method's solution of ``problem`` (rows met to eps_abs) when it finds one and the relative
        KKT residual certifies it to ``tolerance``, else None (ProxQP then solves)."""
        p = problem
        n_eq = len(p.b)
        lower = np.ascontiguousarray(np.concatenate((p.b, p.l)) if n_eq else p.l, dtype=float)
        if not self._factored(p) and not self._setup(p, n_eq):
            return None
        # bit for bit: a tenth of array_equal's cost, and equal bits give the same products
        if self._g is None or self._g.tobytes() != p.g.tobytes():
            self._g = np.array(p.g, dtype=float)
            L, first, _, ptr, idx, val, _, z0, e = self._arrays
            free_products.call(L, first, self._g, ptr, idx, val, z0, e)
        flag, iterations = 0, 0
        if self._size >= 0:  # the working set the last solve on these rows left
            flag, iterations = self._run(lower, n_eq, self._size)
        start = None if flag == OPTIMAL else matched_start(self._last, p.row_ids)
        if start is not None:
            flag, iterations = self._run(lower, n_eq, self._started(start, n_eq))
        if flag != OPTIMAL:
            flag, iterations = self._run(lower, n_eq, self._started(np.zeros(len(lower)), n_eq))
        if flag != OPTIMAL:
            return None
        L, first = self._arrays[:2]
        W, _, _, _, lam, _, z = self._set[:7]
        x, multipliers = np.empty(len(p.g)), np.empty(len(lower))
        primal_answer.call(L, first, z, self._size, W, lam, x, multipliers)
        solution = checked(p, x, multipliers.copy(), Status.DUAL_SOLVED, self.tolerance, iterations, False)
        if solution is None:  # refused: neither its working set nor its multipliers start the next
            self._size = -1
        else:
            self._last = (self._ids, multipliers)
        return solution

    def _setup(self, p: GaussProblem, n_eq: int) -> bool:
        """Factor H and put the rows [A; C] (the first ``n_eq`` equalities) in least-distance form;
        False when H is not positive definite."""
        H = np.ascontiguousarray(p.H, dtype=float)
        rows = np.ascontiguousarray(np.vstack((p.A, p.C)) if n_eq else p.C, dtype=float)
        (m, n), self._size, self._g = rows.shape, -1, None
        L, first, parent = np.empty((n, n)), np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
        self._key = None
        if not envelope_cholesky.call(H, L, first, parent):
            return False
        ptr, idx, val = np.empty(m + 1, dtype=np.int64), np.empty(m * n, dtype=np.int64), np.empty(m * n)
        masks, mark = np.empty(m, dtype=np.int64), np.full(n, -1, dtype=np.int64)
        transformed_rows.call(L, first, parent, rows, ptr, idx, val, masks, np.zeros(n), mark)
        self._arrays = (L, first, parent, ptr, idx, val, masks, np.empty(n), np.empty(m))
        # the working set: rows W, factors Lw, Dw and each factor row's first column, multipliers, place
        # of each row, z, scratch
        W, Lw, Dw, lam = np.empty(n, dtype=np.int64), np.empty((n, n)), np.empty(n), np.empty(n)
        F, pos = np.empty(n, dtype=np.int64), np.full(m, -1, dtype=np.int64)
        self._set = (W, Lw, Dw, F, lam, pos, np.empty(n), np.zeros((5, n)))
        self._key, self._ids, self._n_eq = p.rows_key, p.row_ids, n_eq
        return True

    def _started(self, start: np.ndarray, n_eq: int) -> int:
        """The size of a working set made from the multipliers ``start`` (see start_set)."""
        ptr, idx, val, masks = self._arrays[3:7]
        W, Lw, Dw, F, lam, pos, _, work = self._set
        return int(
            start_set.call(ptr, idx, val, masks, n_eq, start, DEPENDENCE, W, Lw, Dw, F, lam, pos, *work[2:4])
        )

    def _run(self, lower: np.ndarray, n_eq: int, size: int) -> tuple[int, int]:
        """(status, iterations) of the method from a working set of ``size`` rows, whose size it keeps
        when the method ends optimal (else none is kept)."""
        ptr, idx, val, masks, z0, e = self._arrays[3:]
        W, Lw, Dw, F, lam, pos, z, work = self._set
        self._size = -1  # the set is changed in place: none is kept until the method says optimal
        flag, iterations, size = dual_iterations.call(
            ptr,
            idx,
            val,
            masks,
            e,
            lower,
            n_eq,
            self.eps_abs,
            DEPENDENCE,
            ITERATIONS,
            size,
            W,
            Lw,
            Dw,
            F,
            lam,
            pos,
            z0,
            z,
            work,
        )
        if flag == OPTIMAL:
            self._size = size
        return flag, iterations


class DaqpActiveSet:
    """DAQP's workspace for the problems of one island, and the problem it holds."""

    def __init__(self, eps_abs: float, tolerance: float) -> None:
        self.eps_abs, self.tolerance = eps_abs, tolerance
        self._model: Any = None  # daqp.Model
        self._held: tuple[np.ndarray, ...] = ()  # copies of the model's H, g and rows
        self._key: object = None  # the rows_key of the problem they are
        self._ids: np.ndarray | None = None  # the row ids of the problem the workspace holds
        # the last solution's row ids and multipliers: the working set a new problem starts from
        self._last: tuple[np.ndarray, np.ndarray] | None = None

    def holds(self, problem: GaussProblem) -> bool:
        """Whether its workspace holds ``problem``'s rows (a later friction pass of the same step)."""
        return self._model is not None and problem.rows_key == self._key

    def solve(self, problem: GaussProblem) -> Solution | None:
        """DAQP's solution of ``problem`` (rows met to eps_abs) when it is optimal and the relative
        KKT residual certifies it to ``tolerance``, else None (ProxQP then solves)."""
        p = problem
        n_eq, n_in = len(p.b), len(p.l)
        rows = np.vstack((p.A, p.C)) if n_eq else p.C
        upper = np.concatenate((p.b, np.full(n_in, _UNBOUNDED)), dtype=float)
        lower = np.concatenate((p.b, p.l), dtype=float)
        try:  # DAQP refuses some inputs (a module's rows of integers): ProxQP then solves
            flag, x, info = self._solve(p, rows, upper, lower)
        except (TypeError, ValueError, RuntimeError):
            flag, x, info = 0, None, None
        if flag != _OPTIMAL:
            self._model = None
            return None
        # DAQP's multipliers of lower bounds are <= 0 (and its inactive rows' -0: 0 - (-0) is +0)
        multipliers = np.zeros(n_eq + n_in) - np.asarray(info["lam"])
        # the rows of the workspace that solved it: the held ones, or a new setup's
        self._last = None if self._ids is None else (self._ids, multipliers)
        status, iterations = Status.DUAL_ACTIVE_SET_SOLVED, info["iterations"]
        return checked(p, np.array(x), multipliers.copy(), status, self.tolerance, iterations, False)

    def _solve(
        self, p: GaussProblem, rows: np.ndarray, upper: np.ndarray, lower: np.ndarray
    ) -> tuple[int, Any, Any]:
        """(exitflag, x, info) of DAQP on ``p``: on the held factors when only the bounds changed,
        else from the last working set, else from a cold start."""
        if self._model is not None and self._holds(p, rows):
            self._model.update(bupper=upper, blower=lower)
            x, _, flag, info = self._model.solve()
            if flag == _OPTIMAL:
                return flag, x, info
        start = self._start(p)
        if start is not None:
            flag, x, info = self._setup(p, rows, upper, lower, start)
            if flag == _OPTIMAL:
                return flag, x, info
        return self._setup(p, rows, upper, lower, None)

    def _start(self, p: GaussProblem) -> np.ndarray | None:
        """DAQP's dual start for ``p``: :func:`matched_start` in DAQP's sign."""
        start = matched_start(self._last, p.row_ids)
        return None if start is None else -start

    def _holds(self, p: GaussProblem, rows: np.ndarray) -> bool:
        """Whether the workspace holds ``p``'s H, g and ``rows`` (the key of the problem it was set up
        for spares comparing H and the rows)."""
        if p.rows_key == self._key:
            return bool(np.array_equal(self._held[1], p.g))
        return _same(self._held, (p.H, p.g, rows))

    def _setup(
        self, p: GaussProblem, rows: np.ndarray, upper: np.ndarray, lower: np.ndarray, start: Any
    ) -> tuple[int, Any, Any]:
        """(exitflag, x, info) of a new workspace for ``p`` (its working set from the multipliers
        ``start``, or none), which is kept."""
        held = tuple(np.array(a, dtype=float, order="C") for a in (p.H, p.g, rows))  # DAQP reads buffers
        sense = np.zeros(len(lower), dtype=np.int32)
        sense[: len(p.b)] = _EQUALITY
        model = daqp.Model()
        settings = model.settings
        settings["primal_tol"] = self.eps_abs
        model.settings = settings
        flag, _ = model.setup(*held, upper, lower, sense, dual_start=start)
        if flag < 0:  # rows DAQP finds inconsistent as they stand (dependent equalities that conflict)
            return flag, None, None
        x, _, flag, info = model.solve()
        self._model, self._held, self._key, self._ids = model, held, p.rows_key, p.row_ids
        return flag, x, info


def _same(held: tuple[np.ndarray, ...], arrays: tuple[np.ndarray, ...]) -> bool:
    """Whether ``arrays`` equal the ``held`` ones, entry for entry."""
    return all(a.shape == b.shape and np.array_equal(a, b) for a, b in zip(held, arrays))


def matched_start(last: tuple[np.ndarray, np.ndarray] | None, new: np.ndarray) -> np.ndarray | None:
    """A dual start for the rows of ids ``new``: the multipliers that the ``last`` solution (its row ids,
    multipliers) gave the rows it had (matched by their ids, :attr:`GaussProblem.row_ids`: contacts come
    and go, and a patch's points shift the rows after them), zero for the others; None when it held none
    of them active."""
    if last is None or not len(last[1]):
        return None
    start = np.empty(len(new))
    return start if matched_values.call(*last, new, start) else None
