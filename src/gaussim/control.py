"""Controllers for runs driven from scene files: joint torques tau(state), shape (nv,) (or a floating
robot's actuated coordinates, :attr:`Robot.actuated`), or a :class:`Command` that adds implicit
damping."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from .state import BodyState, State


class Command(NamedTuple):
    """A step's actuation: the joints get tau - damping v+, v+ the step's new velocity
    (``Simulator.step(state, *command)``)."""

    tau: np.ndarray | Mapping[str, np.ndarray] | None
    damping: np.ndarray | Mapping[str, np.ndarray] | None = None


# a controller reads a world's state, or (per body, in a scene of bodies) its body's
Controller = Callable[[State | BodyState], np.ndarray | Command | None]


def command(output: np.ndarray | Command | None) -> Command:
    """A controller's output as a :class:`Command`."""
    return output if isinstance(output, Command) else Command(output)


def zero_torque(state: State | BodyState) -> None:
    """No actuation."""
    return None


def constant_torque(tau: np.ndarray) -> Controller:
    """The same torque at every step (actuated joints, or all nv)."""
    tau = np.array(tau, dtype=float)

    def control(state: State | BodyState) -> np.ndarray:
        return tau

    return control


class PDHold:
    """A posture hold on the actuated joints [N m]: tau = kp (q_ref (-) q) - kd v.

    With the time step ``dt`` it is implicit: the step evaluates it at its end, tau = kp (q_ref (-) q+)
    - kd v+ to first order in dt, that is kp (q_ref (-) q) with damping kd + dt kp on v+ (a
    :class:`Command`); stable at any dt. Without, it is the explicit law, which diverges once
    (kd + dt kp) dt exceeds about twice a joint's inertia (Solo-12's lower legs at dt = 20 ms).
    """

    def __init__(
        self,
        model: pin.Model,
        q_ref: np.ndarray,
        kp: float,
        kd: float,
        actuated: slice | np.ndarray,
        dt: float | None = None,
    ) -> None:
        self.model, self.kp, self.kd, self.actuated = model, kp, kd, actuated
        self.q_ref = np.asarray(q_ref, dtype=float)  # native float64: Pinocchio reads the bytes as such
        size = len(np.arange(model.nv)[actuated])
        self.damping = None if dt is None else np.full(size, kd + dt * kp)

    def __call__(self, state: State | BodyState) -> np.ndarray | Command:
        error = pin.difference(self.model, state.q, self.q_ref)
        if self.damping is None:
            return (self.kp * error - self.kd * state.v)[self.actuated]
        return Command((self.kp * error)[self.actuated], self.damping)
