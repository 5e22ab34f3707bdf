"""Controllers: joint torques tau(state), shape (nv,), for runs driven from scene files."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pinocchio as pin

from .state import State

Controller = Callable[[State], np.ndarray | None]


def zero_torque(state: State) -> None:
    """No actuation."""
    return None


def constant_torque(tau: np.ndarray) -> Controller:
    """The same torque at every step (actuated joints, or all nv)."""
    tau = np.array(tau, dtype=float)

    def control(state: State) -> np.ndarray:
        return tau

    return control


class PDHold:
    """tau = kp (q_ref (-) q) - kd v on the actuated joints [N m]."""

    def __init__(self, model: pin.Model, q_ref: np.ndarray, kp: float, kd: float, actuated: slice) -> None:
        self.model, self.q_ref, self.kp, self.kd, self.actuated = model, np.asarray(q_ref), kp, kd, actuated

    def __call__(self, state: State) -> np.ndarray:
        error = pin.difference(self.model, state.q, self.q_ref)
        return (self.kp * error - self.kd * state.v)[self.actuated]
