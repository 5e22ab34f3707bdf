"""Joint position limits from the URDF: q_min <= q <= q_max as unilateral rows on 1-dof joints.

Lower limit: phi = q - q_min >= 0, row  +e_i^T x >= bound;  upper: phi = q_max - q, row -e_i^T x >= bound.
Only limits the joint can reach within the step (plus ``Options.limit_margin``) produce rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..kernels.bound import Bound
from .base import LEVELS, ConstraintModule, Context, Rows

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
near_limits = Bound("contact.near_limits")


@dataclass
class LimitReaction:
    """The generalized force a joint limit applies [N m or N] (an impulse [N m s] in impact reports)."""

    joint: str
    side: str
    torque: float


class LimitModule(ConstraintModule[np.ndarray]):
    """Rows of the joint limits of the 1-dof joints with finite limits; each rows' ``data`` holds the
    indices of the limits they hold."""

    name = "limit"

    def __init__(self, model: pin.Model) -> None:
        idx_q, idx_v, signs, bounds, labels = [], [], [], [], []
        for joint_id in range(1, model.njoints):
            joint = model.joints[joint_id]
            if joint.nq != 1 or joint.nv != 1:
                continue
            iq, iv = joint.idx_q, joint.idx_v
            for sign, value, side in (
                (1.0, model.lowerPositionLimit[iq], "lower"),
                (-1.0, model.upperPositionLimit[iq], "upper"),
            ):
                if np.isfinite(value) and abs(value) < 1e10:
                    idx_q.append(iq)
                    idx_v.append(iv)
                    signs.append(sign)
                    bounds.append(value)
                    labels.append((model.names[joint_id], side))
        self.idx_q, self.idx_v = np.array(idx_q, dtype=np.int64), np.array(idx_v, dtype=np.int64)
        self.signs, self.limits = np.array(signs, dtype=float), np.array(bounds, dtype=float)
        self.labels = labels
        # the active limits' indices and bounds (filled by near_limits)
        self._active, self._bound = np.empty(len(signs), dtype=np.int64), np.empty(len(signs))

    def rows(self, ctx: Context) -> Rows[np.ndarray] | None:
        if not len(self.signs):
            return None
        o = ctx.options
        settings = (o.dt, o.limit_margin, o.active_tolerance, o.restitution_threshold, o.stabilisation)
        count = near_limits.call(
            ctx.q, ctx.v, self.idx_q, self.idx_v, self.signs, self.limits, LEVELS[ctx.level], settings,
            self._active, self._bound,
        )  # fmt: skip
        if not count:
            return None
        # copies: the buffers are the next call's
        active, bound = self._active[:count].copy(), self._bound[:count].copy()
        J = np.zeros((count, ctx.model.nv))
        for row, i in enumerate(active.tolist()):  # a few rows: cheaper than numpy's fancy indexing
            J[row, self.idx_v[i]] = self.signs[i]

        def labels() -> list[str]:
            return [f"limit {self.labels[i][0]} {self.labels[i][1]}" for i in active]

        return Rows(J, bound, False, labels, active, ids=lambda: active)

    def reactions(self, rows: Rows[np.ndarray], multipliers: np.ndarray, scale: float) -> list[LimitReaction]:
        return [
            LimitReaction(self.labels[i][0], self.labels[i][1], float(scale * lam * self.signs[i]))
            for i, lam in zip(rows.data, multipliers)
        ]
