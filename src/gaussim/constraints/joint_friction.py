"""Dry (Coulomb) friction in the joints, as the robot files give it (URDF ``<dynamics friction>``, MJCF
``frictionloss``, SDF ``<dynamics><friction>``: Pinocchio's ``model.friction``, f [N m or N] per
coordinate): a joint sticks while the torque that holds it stays within f, else it slides against it.

The friction is a generalized force the module applies outside the QP, never a row: a row holding a
joint still could contradict the others (a limit or a contact that must push the joint back), where a
finite friction only ever gives way. Its impulse p_i (f dt at most at the velocity level, f at the
acceleration level) is the fixed point of the step's passes (:meth:`JointFrictionModule.refine`):
the next impulses are those that leave the coordinates' new velocities u at 0 where |p_i| stays within
its bound (sticking) and moving against p_i = bound elsewhere (sliding), as u answers p while the rows
the pass held active hold (u + W (p' - p), :func:`_response`): the minimum of
1/2 p'^T W p' + (u - W p)^T p' over the box |p'| <= bound (:func:`_box_minimum`). A pass that moves
no impulse has reached it. Each solve starts from the last step's
impulses. Impacts (the impulse level) take no friction: a finite force gives no impulse.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from ..assembly import GaussProblem
from ..portable import portable_proxsuite
from .base import ConstraintModule, Context, Rows

proxqp = portable_proxsuite().proxqp

# A pass whose impulses move less than this fraction of their bounds has reached the fixed point.
SETTLED = 1e-6
# An impulse this close to its bound (relative) is at it: the joint slides.
AT_BOUND = 1e-6


@dataclass
class JointFrictionReaction:
    """The friction torque of a joint coordinate [N m or N]: sticking (within its bound) or sliding."""

    joint: str
    torque: float
    sliding: bool


@dataclass
class JointFrictionIterate:
    """One solve's passes: each coordinate's impulse, and the rows the last pass held active with the
    response W it gave (the passes of a solve share H)."""

    impulse: np.ndarray
    response: tuple[np.ndarray, np.ndarray] | None = None


@dataclass(frozen=True)
class JointFrictionRows:
    """The module's record of one QP: the impulse on each coordinate (the module's order) and the
    bound it is clipped to."""

    impulse: np.ndarray
    bound: np.ndarray


class JointFrictionModule(ConstraintModule[JointFrictionRows]):
    """The dry friction of the coordinates whose ``model.friction`` is positive, as a force."""

    name = "joint_friction"

    def __init__(self, model: pin.Model) -> None:
        self.coordinates = np.flatnonzero(model.friction > 0.0).astype(np.int64)
        self.bounds = model.friction[self.coordinates].astype(float)
        owner = np.zeros(model.nv, dtype=np.int64)
        for j in range(1, model.njoints):
            joint = model.joints[j]
            owner[joint.idx_v : joint.idx_v + joint.nv] = j
        self.labels = [
            model.names[int(owner[i])] + ("" if model.joints[int(owner[i])].nv == 1 else f"[{i}]")
            for i in self.coordinates
        ]
        self._none = np.zeros((0, model.nv))
        self._last: tuple[str, np.ndarray] | None = None  # the last solve's (level, friction force)

    def rows(self, ctx: Context) -> Rows[JointFrictionRows] | None:
        if not len(self.coordinates) or ctx.level == "impulse":
            return None
        bound = self._bounds(ctx)
        lagged: JointFrictionIterate | None = ctx.lagged.get(id(self))
        if lagged is None:  # a solve's first pass: the last step's force
            start = self._last[1] * bound / self.bounds if self._last and self._last[0] == ctx.level else None
            lagged = JointFrictionIterate(np.zeros(len(bound)) if start is None else start)
            ctx.lagged[id(self)] = lagged
        force = np.zeros(ctx.model.nv)
        force[self.coordinates] = lagged.impulse
        return Rows(
            self._none, np.zeros(0), True, list, JointFrictionRows(lagged.impulse.copy(), bound), force
        )

    def _bounds(self, ctx: Context) -> np.ndarray:
        """Each coordinate's bound on its impulse: f, or f dt at the velocity level."""
        return self.bounds * (ctx.options.dt if ctx.level == "velocity" else 1.0)

    def refine(
        self, ctx: Context, rows: Rows[JointFrictionRows], x: np.ndarray, multipliers: np.ndarray
    ) -> bool:
        lagged: JointFrictionIterate = ctx.lagged[id(self)]
        record, p = rows.data, rows.data.impulse
        u = (x if ctx.level == "velocity" else ctx.v + ctx.options.dt * x)[self.coordinates]
        assert ctx.solved is not None
        # u answers p through x, as the rows active in this pass hold (at the acceleration level u = v + dt a)
        problem, lam = ctx.solved
        active = np.concatenate([np.ones(len(problem.b), bool), lam[len(problem.b) :] > 0.0])
        if lagged.response is None or not np.array_equal(lagged.response[0], active):  # else the same W
            W = _response(problem, active, self.coordinates)
            lagged.response = (active, W * (1.0 if ctx.level == "velocity" else ctx.options.dt))
        W = lagged.response[1]
        nxt = _inside(W, u, p, record.bound)
        if nxt is None:
            nxt = _box_minimum(W, u - W @ p, record.bound, ctx.options.eps_abs)
        self._last = (ctx.level, nxt * self.bounds / record.bound)
        settled = bool(np.all(np.abs(nxt - p) <= SETTLED * record.bound))
        rows.settled = settled
        if not settled:
            lagged.impulse = nxt
        return not settled

    def reactions(
        self, rows: Rows[JointFrictionRows], multipliers: np.ndarray, scale: float
    ) -> list[JointFrictionReaction]:
        record = rows.data
        return [
            JointFrictionReaction(self.labels[k], float(scale * p), bool(abs(p) >= bound * (1.0 - AT_BOUND)))
            for k, (p, bound) in enumerate(zip(record.impulse.tolist(), record.bound.tolist()))
        ]


def _response(problem: GaussProblem, active: np.ndarray, coordinates: np.ndarray) -> np.ndarray:
    """How the velocities (or accelerations) of ``coordinates`` (k,) answer impulses (or forces) on them
    while the ``active`` rows of ``problem`` (of [A; C]) hold: the k x k block of
    H^-1 - H^-1 A^T (A H^-1 A^T)^+ A H^-1 over those rows A."""
    p = problem
    rows = np.vstack([p.A, p.C])[active]
    selected = np.eye(len(p.H))[:, coordinates]
    spread = np.linalg.solve(p.H, np.hstack([selected, rows.T]))  # H^-1 [S^T, A^T]
    free, moved = spread[:, : len(coordinates)], spread[:, len(coordinates) :]
    if not len(rows):
        return free[coordinates]
    coupling = rows @ moved  # A H^-1 A^T, singular where contacts are redundant
    held = moved @ np.linalg.lstsq(coupling, rows @ free, rcond=None)[0]
    return (free - held)[coordinates]


def _inside(W: np.ndarray, u: np.ndarray, p: np.ndarray, bound: np.ndarray) -> np.ndarray | None:
    """The box's minimum (see :func:`_box_minimum`) when the coordinates at their bound in ``p`` stay
    there and the others come to rest within theirs (Newton's step on those, p_f - W_ff^-1 u'_f, u' the
    velocities with the bound ones' impulses kept), else None: the minimum of one active set."""
    at = np.abs(p) >= bound * (1.0 - AT_BOUND)
    free = ~at
    nxt = p.copy()
    try:
        if free.any():
            nxt[free] = p[free] - np.linalg.solve(W[np.ix_(free, free)], u[free])
    except np.linalg.LinAlgError:  # a coordinate the active rows hold still: W singular
        return None
    moved = u + W @ (nxt - p)  # the velocities at nxt
    if np.all(np.abs(nxt[free]) < bound[free]) and np.all(moved[at] * np.sign(p[at]) <= 0.0):
        return nxt
    return None


def _box_minimum(W: np.ndarray, c: np.ndarray, bound: np.ndarray, eps_abs: float) -> np.ndarray:
    """argmin 1/2 p^T W p + c^T p over -bound <= p <= bound (W symmetric, positive semi-definite), by
    ProxQP."""
    k = len(c)
    qp = _BOXES.get(k)
    if qp is None:
        qp = _BOXES[k] = proxqp.dense.QP(k, 0, k)
        qp.settings.eps_rel, qp.settings.verbose = 0.0, False
        qp.init(np.eye(k), np.zeros(k), None, None, np.eye(k), -np.ones(k), np.ones(k))
    qp.settings.eps_abs = eps_abs * 1e-3
    qp.update(0.5 * (W + W.T), c, None, None, None, -bound, bound)
    qp.solve()
    return np.clip(qp.results.x, -bound, bound)


# a box QP per size, made once (a QP's making costs more than its solve)
_BOXES: dict[int, Any] = {}
