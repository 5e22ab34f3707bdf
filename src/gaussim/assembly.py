"""Stage 4, assembly: stack the modules' rows into one Gauss problem

    min_x 1/2 x^T M x + g^T x   s.t.   A x = b,   l <= C x

with g = -(M v + dt F) (velocity level), -M v (impulse level) or -F (acceleration level).
"""

from __future__ import annotations

import warnings
from dataclasses import InitVar, dataclass, field
from functools import cache, cached_property

import numpy as np

from .constraints.base import ROW_ID_BITS, ConstraintModule, Rows, real_floats
from .exceptions import GaussimWarning, InvalidOptions
from .kernels.bound import Bound, c_int

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
cut = Bound("solver.cut")
within = Bound("solver.within")


@dataclass
class GaussProblem:
    """A dense convex QP in ProxQP's form and the blocks of rows it came from.

    Attributes:
        H: Hessian M, shape (nv, nv).
        g: linear term, shape (nv,).
        A, b: equality rows (n_eq, nv), (n_eq,).
        C, l: inequality rows (n_in, nv), lower bounds (n_in,) (upper bounds are +inf).
        blocks: (module, rows, the slice of its multipliers in [lambda_eq; lambda_in]).
        applied: the generalized force the modules apply outside the QP (in g), shape (nv,), or None.
        source: for an island's problem (:meth:`island`), the problem it was cut from and its
            equality and inequality rows there (the row names are the source's).
        rows_key: stands for the values of H, A and C: a problem with an equal key (==) has the same
            ones (its g, b and l may differ: a friction pass's bounds), so a solver that holds
            factors of them need not compare them. An island's is its source's key and its cut.

    Arrays that are not C-ordered float64 (a problem of a user's making) are copied into such ones,
    which the solver's kernels read, and their shapes checked (:class:`InvalidOptions`);
    ``checked=True`` (assemble's and an island's own) skips both.
    """

    H: np.ndarray
    g: np.ndarray
    A: np.ndarray
    b: np.ndarray
    C: np.ndarray
    l: np.ndarray
    blocks: list[tuple[ConstraintModule, Rows, slice]]
    applied: np.ndarray | None = None
    source: tuple[GaussProblem, np.ndarray, np.ndarray] | None = None
    rows_key: object = field(default_factory=object, repr=False, compare=False)
    checked: InitVar[bool] = False

    def __post_init__(self, checked: bool) -> None:
        if not checked:  # the solver's kernels are bound to C-ordered floats (gaussim.kernels.bound)
            self._check()

    def _check(self) -> None:
        """Make a user's arrays C-ordered floats, and refuse a wrong shape by field: the kernels read
        the shapes they expect and do not check them."""
        H, g, A, b, C, l = (
            real_floats(f"GaussProblem.{name}", getattr(self, name))
            for name in ("H", "g", "A", "b", "C", "l")
        )
        if H.ndim != 2 or H.shape[0] != H.shape[1]:
            raise InvalidOptions("GaussProblem.H", f"must be a square matrix, got shape {H.shape}")
        n = len(H)
        for name, a, fits, want in (
            ("g", g, g.shape == (n,), f"({n},)"),
            ("A", A, A.ndim == 2 and A.shape[1] == n, f"(rows, {n})"),
            ("b", b, b.shape == (len(A),), f"({len(A)},)"),
            ("C", C, C.ndim == 2 and C.shape[1] == n, f"(rows, {n})"),
            ("l", l, l.shape == (len(C),), f"({len(C)},)"),
        ):
            if not fits:
                raise InvalidOptions(f"GaussProblem.{name}", f"must have shape {want}, got {a.shape}")
        self.H, self.g, self.A, self.b, self.C, self.l = H, g, A, b, C, l
        if self.applied is not None:
            self.applied = real_floats("GaussProblem.applied", self.applied)
            if self.applied.shape != (n,):
                raise InvalidOptions(
                    "GaussProblem.applied", f"must have shape ({n},), got {self.applied.shape}"
                )

    def labels(self, equality: bool) -> list[str]:
        """Row names of the equality or inequality rows, in order."""
        if self.source is not None:
            source, eq, ineq = self.source
            names = source.labels(equality)
            return [names[i] for i in (eq if equality else ineq)]
        return [label for _, rows, _ in self.blocks if rows.equality == equality for label in rows.labels()]

    @cached_property
    def row_ids(self) -> np.ndarray:
        """Each row of [A; C]'s identity from step to step, shape (n_eq + n_in,): its module's tag
        (:func:`module_tag`) and its id among the module's rows (:attr:`Rows.ids`, else its place);
        rows of no block (a problem made by hand) are named by their place."""
        if self.source is not None:
            source, eq, ineq = self.source
            return source.row_ids[np.concatenate((eq, len(source.b) + ineq))]
        ids = np.arange(len(self.b) + len(self.l), dtype=np.int64)
        for module, rows, part in self.blocks:
            ids[part] = (module_tag(module) << ROW_ID_BITS) | _own_ids(module, rows)
        return ids

    def island(self, cols: np.ndarray, eq: np.ndarray, ineq: np.ndarray) -> GaussProblem:
        """The problem on the coordinates ``cols`` and the equality and inequality rows ``eq``,
        ``ineq`` (an island: no other row reads those coordinates, and H couples them to no other)."""
        H, g, A, b, C, l = cut.call(self.H, self.g, self.A, self.b, self.C, self.l, cols, eq, ineq)
        key = (self.rows_key, cols.tobytes(), eq.tobytes(), ineq.tobytes())  # the same cut of the same rows
        return GaussProblem(H, g, A, b, C, l, [], None, (self, eq, ineq), key, True)


def _own_ids(module: ConstraintModule, rows: Rows) -> np.ndarray:
    """The ids of a module's ``rows`` (:attr:`Rows.ids`), or their places where the module gives none
    or ids that are not one integer in [0, 2**ROW_ID_BITS) per row (with a warning, which Python's
    filters show once: the solver then starts its rows from their places)."""
    count = len(rows)
    if rows.ids is not None:
        given = np.asarray(rows.ids())
        if given.shape == (count,) and given.dtype.kind in "iu":
            own = c_int(given)  # a uint64 above int64's range turns negative
            if within.call(own, 2**ROW_ID_BITS):
                return own
        warnings.warn(
            f"module '{getattr(module, 'name', type(module).__name__)}': Rows.ids must give one integer in "
            f"[0, 2**{ROW_ID_BITS}) per row ({count}), got {given.dtype} of shape {given.shape}; "
            "its rows are named by their places (a warm start of the solver only)",
            GaussimWarning,
            stacklevel=2,
        )
    return np.arange(count, dtype=np.int64)


_TAGS: dict[int, int] = {}  # id(module) -> its tag
# The most modules tagged apart (the bits an int64 row id leaves above ROW_ID_BITS).
MAX_TAGS = 2 ** (62 - ROW_ID_BITS)


def module_tag(module: ConstraintModule) -> int:
    """A small integer that tells ``module`` from the others in row ids (:attr:`GaussProblem.row_ids`)
    while it lives (by identity: a user's module may define __eq__)."""
    tag = _TAGS.get(id(module))
    if tag is None:
        if len(_TAGS) >= MAX_TAGS:  # modules of many simulators: tags are only compared within one
            _TAGS.clear()
        tag = _TAGS[id(module)] = len(_TAGS)
    return tag


def assemble(
    H: np.ndarray,
    g: np.ndarray,
    parts: list[tuple[ConstraintModule, Rows]],
    previous: GaussProblem | None = None,
) -> GaussProblem:
    """Stack rows: equalities into (A, b), inequalities into (C, l), remembering where each block's
    multipliers go; a force a module applies outside the QP enters the linear term g. ``previous``:
    the last problem of the same solve (same H), whose stacked rows are kept when every block's J is
    the same array as there (a friction pass that moved bounds alone; :class:`Rows` are not modified
    once returned). The rows' arrays are the kernels' C-ordered floats: a user's module's are made so
    and checked first (:func:`~gaussim.constraints.base.checked_rows`)."""
    equalities: list[tuple[ConstraintModule, Rows]] = []
    inequalities: list[tuple[ConstraintModule, Rows]] = []
    for part in parts:  # one pass: this runs every QP
        (equalities if part[1].equality else inequalities).append(part)
    blocks, end, applied = [], 0, None
    for module, rows in equalities + inequalities:  # the order of [lambda_eq; lambda_in]
        first, end = end, end + len(rows.bound)
        blocks.append((module, rows, slice(first, end)))
        if rows.force is not None:
            g = g - rows.force
            applied = rows.force if applied is None else applied + rows.force
    b, l = _bounds(equalities), _bounds(inequalities)
    if previous is not None and _same_rows(previous, blocks, H):
        return GaussProblem(
            H, g, previous.A, b, previous.C, l, blocks, applied, None, previous.rows_key, True
        )
    A, C = _stack(equalities, len(g)), _stack(inequalities, len(g))
    return GaussProblem(H, g, A, b, C, l, blocks, applied, None, object(), True)


def _same_rows(previous: GaussProblem, blocks: list, H: np.ndarray) -> bool:
    """Whether ``blocks`` hold, in order, the very J arrays of ``previous``'s blocks, over its H."""
    return (
        previous.H is H
        and len(blocks) == len(previous.blocks)
        and all(
            new[1].J is old[1].J and new[1].equality == old[1].equality
            for new, old in zip(blocks, previous.blocks)
        )
    )


def _bounds(chosen: list[tuple[ConstraintModule, Rows]]) -> np.ndarray:
    if len(chosen) == 1:
        return chosen[0][1].bound
    if not chosen:
        return _none(0)[1]
    return np.concatenate([rows.bound for _, rows in chosen])


def _stack(chosen: list[tuple[ConstraintModule, Rows]], nv: int) -> np.ndarray:
    if len(chosen) == 1:
        return chosen[0][1].J
    if not chosen:
        return _none(nv)[0]
    return np.vstack([rows.J for _, rows in chosen])


@cache
def _none(nv: int) -> tuple[np.ndarray, np.ndarray]:
    """No rows (read-only, shared)."""
    J, bound = np.zeros((0, nv)), np.zeros(0)
    J.flags.writeable = bound.flags.writeable = False
    return J, bound
