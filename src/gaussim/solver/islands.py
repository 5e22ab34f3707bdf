"""Islands: the Gauss problem split into the independent problems of the bodies that touch.

The model's trees (the subtrees hanging from the universe: a free body, a robot) share no entries of
M; a row couples the trees whose velocities it reads. The connected components of that graph, the
islands, are independent QPs: each is solved on its own coordinates and rows, warm-started from its
own last solution, so a step's cost grows with the bodies in contact, not with their square or cube;
a tree that no row reads keeps its free motion (the minimum of its part of the functional).
"""

from __future__ import annotations

from collections import OrderedDict
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from ..assembly import GaussProblem
from ..kernels.bound import Bound
from ..options import Options
from .certificate import Certificate
from .proxqp import GaussSolver, warm_certificate

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
islands = Bound("solver.islands")
members = Bound("solver.members")
warm_islands = Bound("solver.warm_islands")

# How many islands' solvers (QP objects and last solutions) are kept for warm starts: islands form and
# split as bodies touch and part.
KEPT_SOLVERS = 256


def joint_trees(model: pin.Model) -> np.ndarray:
    """The tree of each joint, shape (njoints,): the index of its ancestor among the universe's
    children (0, 1, ... in joint order), -1 for the universe."""
    root = np.full(model.njoints, -1, dtype=np.int64)
    count = 0
    for j in range(1, model.njoints):
        parent = model.parents[j]
        if parent == 0:
            root[j], count = count, count + 1
        else:
            root[j] = root[parent]
    return root


def trees(model: pin.Model) -> np.ndarray:
    """The tree of each velocity coordinate, shape (nv,) (its joint's, see :func:`joint_trees`)."""
    root = joint_trees(model)
    tree = np.zeros(model.nv, dtype=np.int64)
    for j in range(1, model.njoints):
        joint = model.joints[j]
        tree[joint.idx_v : joint.idx_v + joint.nv] = root[j]
    return tree


class _Layout(NamedTuple):
    """The islands of one split as its compiled pass reads them.

    A split whose islands the pass answered all is kept for the next one: while the islands stay the
    same (a resting pile, a robot on its feet), each solver's last solution is its slice of ``last_x``
    and ``last_m``, which the pass updates in place, so the next split needs no lookup of its islands'
    members, solvers and last solutions.

    Attributes:
        key: (the number of equality rows, the island of each tree and of each row as bytes).
        parts: the coordinates, equality rows and inequality rows of each island, and where each
            island's run starts: (cols, col_start, eqs, eq_start, ineqs, ineq_start).
        solvers: each island's solver and sizes (coordinates, equality rows, inequality rows).
        tried: which islands have a last solution of these sizes to start from, shape (n,).
        last_x, last_m: the tried islands' last x and multipliers [eq; ineq], in island order.
        how, residuals: what the pass writes per island (see warm_islands), shapes (n,), (n, 5).
    """

    key: tuple[int, bytes, bytes]
    parts: tuple[np.ndarray, ...]
    solvers: list[tuple[GaussSolver, tuple[int, int, int]]]
    tried: np.ndarray
    last_x: np.ndarray
    last_m: np.ndarray
    how: np.ndarray
    residuals: np.ndarray


class IslandSolver:
    """Solves a Gauss problem island by island (see the module's docstring)."""

    def __init__(self, model: pin.Model, options: Options) -> None:
        self.options = options
        self.tree, self.joint_tree = trees(model), joint_trees(model)
        self.n_trees = int(self.tree.max(initial=-1)) + 1
        self._none = np.zeros(model.nv)  # no force applied outside the QP
        self._solvers: OrderedDict[tuple[int, ...] | None, GaussSolver] = OrderedDict()
        self._kept: _Layout | None = None  # the last split's, while each island's pass answered it

    def solve(
        self, problem: GaussProblem, x_free: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, tuple[Certificate, ...]]:
        """(x, the multipliers [lambda_eq; lambda_in], one certificate per island) of ``problem``,
        whose unconstrained minimum is ``x_free``."""
        p = problem
        if self.n_trees > 1:
            applied = self._none if p.applied is None else p.applied
            read = _row_joints(p)
            island_of_tree, island_of_row, n = islands.call(
                p.A, p.C, read, self.joint_tree, applied, self.tree, self.n_trees
            )
            # several islands, or one that leaves a tree out; and no row that reads no coordinate
            if (n > 1 or island_of_tree.min() < 0) and n and island_of_row.min(initial=0) >= 0:
                return self._split(p, x_free, island_of_tree, island_of_row, n)
        solution = self._solver(None).solve(problem, x_free)
        return solution.x, solution.multipliers, (solution.certificate,)

    def _split(
        self,
        p: GaussProblem,
        x_free: np.ndarray,
        island_of_tree: np.ndarray,
        island_of_row: np.ndarray,
        n: int,
    ) -> tuple[np.ndarray, np.ndarray, tuple[Certificate, ...]]:
        """:meth:`solve` island by island: the islands whose last solution or its active set solves
        their problem in one compiled pass (:func:`~gaussim.kernels.solver.warm_islands`), the others
        each by its solver."""
        x, multipliers = x_free.copy(), np.zeros(len(p.b) + len(p.l))
        n_eq = len(p.b)
        key = (n_eq, island_of_tree.tobytes(), island_of_row.tobytes())
        kept = self._kept
        layout = (
            kept
            if kept is not None and kept.key == key
            else self._layout(key, island_of_tree, island_of_row, n)
        )
        self._kept = None
        cols, col_start, eqs, eq_start, ineqs, ineq_start = layout.parts
        how, residuals, last_x, last_m = layout.how, layout.residuals, layout.last_x, layout.last_m
        if layout.tried.any():
            problem = (p.H, p.g, p.A, p.b, p.C, p.l)
            warm_islands.call(
                *problem,
                layout.parts,
                layout.tried,
                last_x,
                last_m,
                self.options.eps_abs,
                how,
                residuals,
                x,
                multipliers,
            )
        certificates, x_at, m_at = [], 0, 0
        for i, (solver, (nx, ne, ni)) in enumerate(layout.solvers):
            if how[i]:
                if layout is not kept:  # a kept layout's solvers hold their slices of last_x, last_m
                    solver.keep(last_x[x_at : x_at + nx], last_m[m_at : m_at + ne + ni], (nx, ne, ni))
                certificates.append(warm_certificate(int(how[i]), residuals[i].tolist()))
            else:
                c = cols[col_start[i] : col_start[i + 1]]
                eq, ineq = eqs[eq_start[i] : eq_start[i + 1]], ineqs[ineq_start[i] : ineq_start[i + 1]]
                solution = solver.solve(p.island(c, eq, ineq), x_free[c], warm=not layout.tried[i])
                x[c] = solution.x
                multipliers[eq], multipliers[n_eq + ineq] = solution.lambda_eq, solution.lambda_in
                certificates.append(solution.certificate)
            if layout.tried[i]:
                x_at, m_at = x_at + nx, m_at + ne + ni
        if how.all():  # every solver's last solution is its slice of last_x, last_m: kept for the next
            self._kept = layout
        return x, multipliers, tuple(certificates)

    def _layout(
        self, key: tuple[int, bytes, bytes], island_of_tree: np.ndarray, island_of_row: np.ndarray, n: int
    ) -> _Layout:
        """The :class:`_Layout` of the islands ``island_of_tree`` and ``island_of_row`` (see
        :func:`~gaussim.kernels.solver.islands`), their solvers' last solutions gathered."""
        n_eq = key[0]
        parts = (
            *members.call(island_of_tree[self.tree], n),
            *members.call(island_of_row[:n_eq], n),
            *members.call(island_of_row[n_eq:], n),
        )
        _, col_start, _, eq_start, _, ineq_start = parts
        trees, tree_start = members.call(island_of_tree, n)
        solvers, lasts = [], []
        for i in range(n):
            solver = self._solver(tuple(trees[tree_start[i] : tree_start[i + 1]].tolist()))
            dims = (
                int(col_start[i + 1] - col_start[i]),
                int(eq_start[i + 1] - eq_start[i]),
                int(ineq_start[i + 1] - ineq_start[i]),
            )
            solvers.append((solver, dims))
            lasts.append(solver.last(dims))
        tried = np.array([last is not None for last in lasts])
        last_x = np.concatenate([last[0] for last in lasts if last is not None] or [np.zeros(0)])
        last_m = np.concatenate([last[1] for last in lasts if last is not None] or [np.zeros(0)])
        return _Layout(key, parts, solvers, tried, last_x, last_m, np.zeros(n, np.int64), np.empty((n, 5)))

    def _solver(self, key: tuple[int, ...] | None) -> GaussSolver:
        """The solver of the island of trees ``key`` (None: the whole problem), last used first."""
        solver = self._solvers.get(key)
        if solver is not None:
            self._solvers.move_to_end(key)
            return solver
        solver = self._solvers[key] = GaussSolver(self.options)
        if len(self._solvers) > KEPT_SOLVERS:
            self._solvers.popitem(last=False)
        return solver


def _row_joints(p: GaussProblem) -> np.ndarray:
    """The two joints each row of [A; C] reads, shape (rows, 2), where its module says (-1: scan the
    row)."""
    if len(p.blocks) == 1 and p.blocks[0][1].joints is not None:  # the contacts alone: their own array
        return p.blocks[0][1].joints
    read = np.full((len(p.b) + len(p.l), 2), -1, dtype=np.int64)
    for _, rows, part in p.blocks:
        if rows.joints is not None:
            read[part] = rows.joints
    return read
