"""The dual active-set solve: DAQP on the Gauss problem before ProxQP is asked.

The Gauss problem's H = M is positive definite, which is the setting of a dual active-set method:
DAQP (Arnström, Bemporad, Axehill 2022) starts from the unconstrained minimum and adds the violated
rows one at a time, keeping a linearly independent working set and its LDL^T factors. A contact's
pyramid rows are dependent (four facets span three directions, a pile's stacked contacts more),
which an interior or proximal method such as ProxQP pays for in iterations and refactorizations; an
active-set method leaves them out: a settled pile's island (120 coordinates, 336 rows) takes 140
iterations, 2 to 3.5 ms, from a cold start, where ProxQP took 20 to 40 ms. Each island keeps its DAQP
workspace: a problem that differs from the last one only in its bounds (the friction passes of one
step, which shift the normal rows' bounds) is solved on the factors it left, about 0.1 ms there; a
new one starts from the last working set, its rows matched by their ids (:attr:`GaussProblem.row_ids`),
0.5 to 1 ms. The answer, like ProxQP's, is accepted only
when gaussim's KKT check certifies it.
"""

from __future__ import annotations

from typing import Any

import daqp
import numpy as np

from ..assembly import GaussProblem
from .certificate import Solution, Status, checked

_OPTIMAL = 1  # DAQP's exitflag of an optimal solution
_EQUALITY = 5  # DAQP's sense of an equality row
_UNBOUNDED = 1e30  # DAQP's infinite bound


class DualActiveSet:
    """DAQP's workspace for the problems of one island, and the problem it holds."""

    def __init__(self, eps_abs: float, tolerance: float) -> None:
        self.eps_abs, self.tolerance = eps_abs, tolerance
        self._model: Any = None  # daqp.Model
        self._held: tuple[np.ndarray, ...] = ()  # copies of the model's H, g and rows
        self._key: object = None  # the rows_key of the problem they are
        self._ids: np.ndarray | None = None  # the row ids of the problem the workspace holds
        # the last solution's row ids and multipliers: the working set a new problem starts from
        self._last: tuple[np.ndarray, np.ndarray] | None = None

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
        return checked(p, np.array(x), multipliers.copy(), status, self.tolerance, iterations)

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
        """DAQP's dual start for ``p``: the last solution's multipliers of the rows of ``p`` that it had
        (matched by their ids, :attr:`GaussProblem.row_ids`: contacts come and go, and a patch's points
        shift the rows after them), in DAQP's sign; None when it held none of them active."""
        if self._last is None or not len(self._last[1]):
            return None
        ids, multipliers = self._last
        order = np.argsort(ids, kind="stable")
        ids, multipliers = ids[order], multipliers[order]
        new = p.row_ids
        at = np.minimum(np.searchsorted(ids, new), len(ids) - 1)
        start = np.where(ids[at] == new, -multipliers[at], 0.0)
        return start if start.any() else None

    def _holds(self, p: GaussProblem, rows: np.ndarray) -> bool:
        """Whether the workspace holds ``p``'s H, g and ``rows`` (the key of the problem it was set up
        for spares comparing H and the rows)."""
        if p.rows_key is self._key:
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
