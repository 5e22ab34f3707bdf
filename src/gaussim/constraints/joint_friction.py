"""Dry (Coulomb) friction in the joints, as the robot files give it (URDF ``<dynamics friction>``, MJCF
``frictionloss``, SDF ``<dynamics><friction>``: Pinocchio's ``model.friction``, f [N m or N] per
coordinate): a joint sticks while the torque that holds it stays within f, else it slides against it.

The friction is a generalized force the module applies outside the QP, never a row: a row holding a
joint still could contradict the others (a limit or a contact that must push the joint back), where a
finite friction only ever gives way. Its impulse p (|p_i| <= f_i dt at the velocity level, f_i at
the acceleration level) maximises the step's dual value psi(p), the QP's minimum with p applied:
concave, its gradient minus the coordinates' new velocities u (divided by dt at the acceleration
level), so that at its maximum a joint within its bound has u = 0 (it sticks) and one at its bound
moves against it (it slides). The step's passes (:meth:`JointFrictionModule.refine`) take Newton's
steps on psi: u answers p as W p while the rows a pass held active hold (:func:`_response`), so the
next impulses minimise 1/2 p'^T W p' + (u - W p)^T p' over the box (:func:`_box_minimum`); a step
that does not raise psi (the active rows changed on its way) is shortened, and a step that moves
the velocities by less than the QPs resolve them ends the passes. Each solve starts from the last
step's impulses. Impacts (the impulse level) take no friction: a finite force gives no impulse.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from ..kernels.bound import Bound
from .base import ConstraintModule, Context, Rows

if TYPE_CHECKING:  # assembly imports the constraint families
    from ..assembly import GaussProblem

box_minimum = Bound("solver.box_minimum")

# A Newton step shorter than this fraction of the bounds, or changing the velocities by less than the
# solvers' tolerance eps_abs (or the QPs' error seen on the way), ends the passes.
SETTLED = 1e-6
# An impulse this close to its bound (relative) is at it: the joint slides if it moves faster than
# MOVING [rad/s or m/s] (else it sticks at the verge: held by a limit or a contact, say).
AT_BOUND = 1e-6
MOVING = 1e-6
# The singular values of the active rows below this fraction of their largest count as dependent.
NULL_SPACE = 1e-9
# The box minimum's proximal shift (relative to W's largest diagonal entry; a floor where W is 0) and
# the gradient (relative to the linear term's largest) below which a coordinate held at its bound
# stays there.
REGULARISATION, SHIFT_FLOOR = 1e-12, 1e-300
RELEASE = 1e-12
# A Newton step must raise the dual value by this fraction of what its slope promised (Armijo), up to
# NOISE of its terms (round-off); else a shorter one is tried (a fraction of it within SHORTEST and
# LONGEST), down to MIN_STEP, which is taken as it is.
ARMIJO = 1e-4
NOISE = 1e-12
SHORTEST, LONGEST = 0.05, 0.9
MIN_STEP = 1.0 / 64


@dataclass
class JointFrictionReaction:
    """The friction torque of a joint coordinate [N m or N]: sliding (at its bound, the joint moving
    against it) or sticking (within its bound, or at it with the joint still)."""

    joint: str
    torque: float
    sliding: bool


@dataclass
class JointFrictionPoint:
    """An impulse the passes accepted: its coordinates' velocities u, the dual value psi there,
    Newton's direction from it and the rows psi was the value over (their key and bounds (b, l))."""

    impulse: np.ndarray
    u: np.ndarray
    value: float
    direction: np.ndarray
    rows_key: object
    bounds: tuple[np.ndarray, np.ndarray]


@dataclass
class JointFrictionIterate:
    """One solve's passes: the impulse the next pass applies, the last accepted point and the fraction
    of its Newton step the next pass tries, and the rows the last pass held active with the response W
    they gave (the passes of a solve share H)."""

    impulse: np.ndarray
    base: JointFrictionPoint | None = None
    step: float = 1.0
    response: tuple[tuple[object, np.ndarray], np.ndarray] | None = None  # ((rows' key, active), W)
    noise: float = 0.0  # how far the QPs' u missed W's prediction over the same rows: their error
    unseen: bool = False  # whether the impulse of the next pass is a step that moves u no more than that


@dataclass
class JointFrictionRows:
    """The module's record of one QP: the impulse on each coordinate (the module's order), the bound
    it is clipped to, and (once the QP is solved) whether each coordinate moves faster than MOVING."""

    impulse: np.ndarray
    bound: np.ndarray
    moving: np.ndarray | None = None


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
        per = 1.0 if ctx.level == "velocity" else ctx.options.dt  # u per x
        u = (x if ctx.level == "velocity" else ctx.v + per * x)[self.coordinates]
        record.moving = -u * np.sign(p) > MOVING  # against the friction
        assert ctx.solved is not None
        problem, lam = ctx.solved
        # the dual value psi(p), concave in p with gradient -u / per: its maximum over the box is the step
        curvature = 0.5 * x @ (problem.H @ x)
        value = curvature + problem.g @ x
        rounding = NOISE * (abs(curvature) + float(np.abs(problem.g * x).sum()))  # psi's round-off
        if ctx.level != "velocity":
            value -= p @ ctx.v[self.coordinates] / per
        base = lagged.base
        same = (
            base is not None
            and base.rows_key == problem.rows_key
            and np.array_equal(base.bounds[0], problem.b)
            and np.array_equal(base.bounds[1], problem.l)
        )
        # psi over the same rows as at base (another module's pass may move them) can be compared
        if base is not None and same and lagged.step > MIN_STEP:
            step, d = lagged.step, base.direction
            slope, there = -(base.u @ d) / per, -(u @ d) / per  # psi's slope along d at base and here
            if value < base.value + ARMIJO * step * slope - rounding:  # overshot
                # where the slope, linear between the two, vanishes (exact where psi is quadratic there)
                fraction = slope / (slope - there) if slope > there else 0.5
                lagged.step = step * min(max(fraction, SHORTEST), LONGEST)
                lagged.impulse = base.impulse + lagged.step * d
                rows.settled = False
                return True
        # u answers p through x, as the rows active in this pass hold (at the acceleration level u = v + dt a)
        active = np.concatenate([np.ones(len(problem.b), bool), lam[len(problem.b) :] > 0.0])
        key = (problem.rows_key, active)
        if lagged.response is None or not _same_key(lagged.response[0], key):  # else the same W
            lagged.response = (key, per * _response(problem, active, self.coordinates))
        elif base is not None and same:  # the same rows held as at base: u missed W's prediction
            missed = u - base.u - lagged.response[1] @ (p - base.impulse)  # by the QPs' error alone
            lagged.noise = max(lagged.noise, float(np.abs(missed).max()))
        W = lagged.response[1]
        resolution = max(ctx.options.eps_abs * per, 2.0 * lagged.noise)  # of u, by the QPs
        linear = u - W @ p
        # a joint the rows hold (W's row nearly 0) whose speed is below the QPs' resolution: its
        # friction stays (else round-off's sign would throw it to a bound, moving the rows' forces)
        held = np.diag(W) <= NULL_SPACE * max(float(np.max(np.diag(W))), 0.0)
        linear[held & (np.abs(u) <= max(resolution, ctx.options.eps_abs))] = 0.0  # u's drift: v's too
        nxt = _box_minimum(W, linear, record.bound, p)  # Newton's step on psi, within the box
        self._last = (ctx.level, nxt * self.bounds / record.bound)
        # settled: the impulses stay, or move the velocities by no more than the QPs resolve them after
        # this pass applied such a step (taken once: where rows hold a joint, its friction goes to its bound)
        direction = nxt - p
        unseen = bool(np.abs(W @ direction).max() <= resolution and abs(u @ direction) / per <= rounding)
        settled = bool(np.all(np.abs(direction) <= SETTLED * record.bound)) or (unseen and lagged.unseen)
        lagged.unseen = unseen and not settled
        rows.settled = settled
        if not settled:
            lagged.impulse, lagged.step = nxt, 1.0
            lagged.base = JointFrictionPoint(p, u, value, direction, problem.rows_key, (problem.b, problem.l))
        return not settled

    def reactions(
        self, rows: Rows[JointFrictionRows], multipliers: np.ndarray, scale: float
    ) -> list[JointFrictionReaction]:
        record = rows.data
        moving = np.ones(len(record.bound), bool) if record.moving is None else record.moving
        return [
            JointFrictionReaction(
                self.labels[k], float(scale * p), bool(abs(p) >= bound * (1.0 - AT_BOUND) and m)
            )
            for k, (p, bound, m) in enumerate(
                zip(record.impulse.tolist(), record.bound.tolist(), moving.tolist())
            )
        ]


def _same_key(a: tuple[object, np.ndarray], b: tuple[object, np.ndarray]) -> bool:
    return a[0] == b[0] and np.array_equal(a[1], b[1])


def _response(problem: GaussProblem, active: np.ndarray, coordinates: np.ndarray) -> np.ndarray:
    """How the velocities (or accelerations) of ``coordinates`` (k,) answer impulses (or forces) on them
    while the ``active`` rows of ``problem`` (of [A; C]) hold: the k x k block of Z (Z^T H Z)^-1 Z^T,
    Z a basis of the motions those rows A allow (their null space; rows that repeat others, as
    redundant contacts do, are read once: singular values within NULL_SPACE of the largest)."""
    p = problem
    rows = np.vstack([p.A, p.C])[active]
    if not len(rows):
        return np.linalg.inv(p.H)[np.ix_(coordinates, coordinates)]
    _, sigma, vt = np.linalg.svd(rows)
    rank = int(np.sum(sigma > NULL_SPACE * sigma[0])) if len(sigma) and sigma[0] > 0.0 else 0
    Z = vt[rank:].T  # (nv, nv - rank)
    if not Z.shape[1]:  # the rows hold every coordinate
        return np.zeros((len(coordinates), len(coordinates)))
    reduced = Z.T @ p.H @ Z
    spread = Z @ np.linalg.solve(reduced, Z[coordinates].T)  # Z (Z^T H Z)^-1 Z_S^T
    W = spread[coordinates]
    return 0.5 * (W + W.T)  # symmetric but for round-off


def _box_minimum(W: np.ndarray, c: np.ndarray, bound: np.ndarray, start: np.ndarray) -> np.ndarray:
    """argmin 1/2 p^T W p + c^T p over -bound <= p <= bound (W symmetric, positive semi-definite), by
    proximal rounds of the primal active-set method from ``start``
    (:func:`gaussim.kernels.solver.box_minimum`): W is singular where the active rows hold a joint."""
    shift = REGULARISATION * max(float(np.max(np.diag(W))), 0.0) + SHIFT_FLOOR
    p = np.empty(len(c))
    # p stays within the box: an unfinished minimum is the pass's next iterate (on a Cholesky failure,
    # W indefinite by round-off, none was seen from _response: p stays at the start)
    box_minimum.call(W, c, bound, start, shift, RELEASE * float(np.abs(c).max()), p)
    return p
