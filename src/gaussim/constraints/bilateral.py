"""Bilateral constraints: frames anchored to the world and loop closures, as equality rows.

Point: phi = p_a - p_b = 0 with J = J_a - J_b (translation rows, world axes).
Orientation: phi = log3(R_a R_b^T) = 0 with the angular rows of J_a - J_b (world axes).
For an anchor, frame b is the fixed target.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..scene import Anchor, Bilateral
from .base import ConstraintModule, Context, Rows, stabilised_bound

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


@dataclass
class BilateralReaction:
    """Reaction of one bilateral constraint on its first frame, world axes: force (3,) [N] then,
    for a placement constraint, torque (3,) [N m]."""

    name: str
    wrench: np.ndarray


class _Side:
    """One frame of a bilateral constraint (or a fixed target when frame is None)."""

    def __init__(
        self, frame: int | None, position: np.ndarray | None = None, rotation: np.ndarray | None = None
    ):
        self.frame = frame
        self.position = position
        self.rotation = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)

    def kinematics(
        self, ctx: Context, acceleration: bool
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(position (3,), rotation (3, 3), Jacobian (6, nv), drift (6,))."""
        if self.frame is None:
            return self.position, self.rotation, np.zeros((6, ctx.model.nv)), np.zeros(6)  # type: ignore[return-value]
        placement = pin.updateFramePlacement(ctx.model, ctx.data, self.frame)
        J = pin.getFrameJacobian(ctx.model, ctx.data, self.frame, LWA).reshape(6, -1)  # (6,) for one dof
        drift = (
            pin.getFrameClassicalAcceleration(ctx.model, ctx.data, self.frame, LWA).vector
            if acceleration
            else np.zeros(6)
        )
        return placement.translation, placement.rotation, J, drift


class BilateralModule(ConstraintModule[list[int]]):
    """Rows of the anchors and loop closures the scene declares; each rows' ``data`` holds the number
    of rows of each constraint."""

    name = "bilateral"

    def __init__(self, robot_frame_id, bilaterals: tuple[Bilateral, ...]) -> None:
        self.constraints = []
        for b in bilaterals:
            if isinstance(b, Anchor):
                target = _Side(None, np.asarray(b.position, dtype=float), b.rotation)
                pair = (_Side(robot_frame_id(b.frame)), target, b.rotation is not None)
            else:
                pair = (_Side(robot_frame_id(b.frame_a)), _Side(robot_frame_id(b.frame_b)), b.orientation)
            self.constraints.append((b.name, *pair))

    def rows(self, ctx: Context) -> Rows[list[int]] | None:
        acceleration = ctx.level == "acceleration"
        J_rows, phis, drifts = [], [], []
        for _, a, b, orientation in self.constraints:
            p_a, R_a, J_a, d_a = a.kinematics(ctx, acceleration)
            p_b, R_b, J_b, d_b = b.kinematics(ctx, acceleration)
            phi = np.concatenate([p_a - p_b, pin.log3(R_a @ R_b.T)]) if orientation else p_a - p_b
            m = len(phi)
            J_rows.append((J_a - J_b)[:m])
            phis.append(phi)
            drifts.append((d_a - d_b)[:m])
        J, phi = np.vstack(J_rows), np.concatenate(phis)
        # every constraint's bounds in one call (the ufunc's call from Python costs more than its work)
        bound = stabilised_bound(ctx, phi, J @ ctx.v, np.concatenate(drifts), False)
        counts = [len(p) for p in phis]

        def labels() -> list[str]:
            return [f"{name} row {i}" for (name, *_), m in zip(self.constraints, counts) for i in range(m)]

        return Rows(J, bound, True, labels, counts)

    def reactions(
        self, rows: Rows[list[int]], multipliers: np.ndarray, scale: float
    ) -> list[BilateralReaction]:
        reports, start = [], 0
        for (name, *_), m in zip(self.constraints, rows.data):
            reports.append(BilateralReaction(name, scale * multipliers[start : start + m]))
            start += m
        return reports
