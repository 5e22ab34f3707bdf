"""Dry (Coulomb) friction in the joints, as the robot files give it (URDF ``<dynamics friction>``, MJCF
``frictionloss``, SDF ``<dynamics><friction>``: Pinocchio's ``model.friction``, f [N m or N] per
coordinate): a joint sticks while the torque that holds it stays within f, else it slides against it.

For the coordinates with f > 0, each QP of a step holds the sticking ones still, one bilateral row
e_i^T x = bound each (x_i = 0 at the velocity level, v_i + dt x_i = 0 at the acceleration level), and
applies f against the sliding ones outside the QP (a generalized force; an impulse f dt at the velocity
level); its passes (:meth:`JointFrictionModule.refine`) make slide a sticking coordinate whose
multiplier exceeds f (dt f at the velocity level), towards where that multiplier would not hold it,
and stick for the rest of the step a sliding one that the force turned back. Impacts (the impulse level)
take no friction: a finite force gives no impulse.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from .base import ConstraintModule, Context, Rows

# A multiplier this much beyond the friction bound (relative) makes its coordinate slide.
OVER = 1e-9


@dataclass
class JointFrictionReaction:
    """The friction torque of a joint coordinate [N m or N]: sticking (within its bound) or sliding."""

    joint: str
    torque: float
    sliding: bool


@dataclass
class JointFrictionIterate:
    """One solve's passes: the sliding coordinates (index among the module's) with the sign of the
    friction force on each, and those that stick for the rest of the step."""

    sliding: dict[int, float] = field(default_factory=dict)
    stopped: set[int] = field(default_factory=set)


@dataclass(frozen=True)
class JointFrictionRows:
    """The module's record of one QP's rows: its sticking coordinates (one row each, in order) and its
    sliding ones (indices among the module's), and the force applied on the sliding ones (nv,)."""

    sticking: np.ndarray
    sliding: np.ndarray
    force: np.ndarray | None


class JointFrictionModule(ConstraintModule[JointFrictionRows]):
    """Rows of the dry friction of the coordinates whose ``model.friction`` is positive."""

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

    def rows(self, ctx: Context) -> Rows[JointFrictionRows] | None:
        if not len(self.coordinates) or ctx.level == "impulse":
            return None
        lagged: JointFrictionIterate = ctx.lagged.get(id(self), JointFrictionIterate())
        sliding = np.array(sorted(set(lagged.sliding) - lagged.stopped), dtype=np.int64)
        sticking = np.setdiff1d(np.arange(len(self.coordinates)), sliding)
        nv = ctx.model.nv
        J = np.zeros((len(sticking), nv))
        J[np.arange(len(sticking)), self.coordinates[sticking]] = 1.0
        bound = np.zeros(len(sticking))
        if ctx.level == "acceleration":  # v + dt a = 0
            bound = -ctx.v[self.coordinates[sticking]] / ctx.options.dt
        force = None
        if len(sliding):
            force = np.zeros(nv)
            signs = np.array([lagged.sliding[int(k)] for k in sliding])
            force[self.coordinates[sliding]] = signs * self._bounds(ctx)[sliding]
        record = JointFrictionRows(sticking, sliding, force)
        coordinates = self.coordinates[sticking]

        def labels() -> list[str]:
            return [f"joint friction {self.labels[k]}" for k in sticking]

        return Rows(J, bound, True, labels, record, force, ids=lambda: coordinates)

    def _bounds(self, ctx: Context) -> np.ndarray:
        """Each coordinate's bound on its multiplier: f, or the impulse f dt at the velocity level."""
        return self.bounds * (ctx.options.dt if ctx.level == "velocity" else 1.0)

    def refine(
        self, ctx: Context, rows: Rows[JointFrictionRows], x: np.ndarray, multipliers: np.ndarray
    ) -> bool:
        record, bounds = rows.data, self._bounds(ctx)
        lagged = ctx.lagged.setdefault(id(self), JointFrictionIterate())
        v_next = x if ctx.level == "velocity" else ctx.v + ctx.options.dt * x
        changed = False
        for k in record.sliding.tolist():  # turned back by its friction: it sticks
            if v_next[self.coordinates[k]] * lagged.sliding[k] > 0.0:
                lagged.stopped.add(k)
                changed = True
        for k, lam in zip(record.sticking.tolist(), multipliers.tolist()):
            if abs(lam) > bounds[k] * (1.0 + OVER) and k not in lagged.stopped:
                lagged.sliding[k] = float(np.sign(lam))  # f at most, towards where lam held it
                changed = True
        rows.settled = not changed
        return changed

    def reactions(
        self, rows: Rows[JointFrictionRows], multipliers: np.ndarray, scale: float
    ) -> list[JointFrictionReaction]:
        record = rows.data
        found = [
            (int(k), JointFrictionReaction(self.labels[k], float(scale * lam), False))
            for k, lam in zip(record.sticking, multipliers)
        ]
        if record.force is not None:
            force = record.force[self.coordinates]
            found += [
                (int(k), JointFrictionReaction(self.labels[k], float(scale * force[k]), True))
                for k in record.sliding
            ]
        return [reaction for _, reaction in sorted(found, key=lambda pair: pair[0])]
