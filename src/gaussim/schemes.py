"""The two time-stepping schemes: from a step's free motion and contacts to its new velocity v+.

velocity scheme (default), the discrete Gauss principle (Moreau-Jean time stepping):
    v+ = argmin 1/2 (w - v_free)^T M (w - v_free)  over the velocity-level rows,  v_free = v + dt a_free
    (M posed only when a module can produce rows; else v+ = v_free)

acceleration scheme, the paper's:
    if v is not admissible (an impact): v = argmin 1/2 (w - v)^T M (w - v) over the impulse-level rows
    a  = argmin 1/2 a^T M a - a^T F  over the acceleration-level rows (second-order tangent sets)
    v+ = v + dt a
"""

from __future__ import annotations

import numpy as np

from .actuation import Actuation
from .collision import Contacts
from .dynamics import DynamicsStage
from .gauss import GaussStage
from .report import StepReport
from .state import State

# A velocity violating an impulse-level row by more than this is an impact [m/s or rad/s].
IMPACT_TOLERANCE = 1e-9


class VelocityScheme:
    """v+ from the velocity-level Gauss problem (see the module's docstring)."""

    acceleration = False

    def __init__(
        self, dynamics: DynamicsStage, gauss: GaussStage, actuation: Actuation, always: bool
    ) -> None:
        # always: a module poses rows without contacts (limits, bilaterals), so every step has a QP
        self.dynamics, self.gauss, self.always = dynamics, gauss, always
        self.dt = gauss.options.dt

    def next_velocity(
        self, state: State, tau: np.ndarray, x_free: np.ndarray, contacts: Contacts, report: StepReport
    ) -> np.ndarray:
        if not (len(contacts.gap) or self.always):  # nothing can restrict the motion: no problem to pose
            return x_free
        report.mark("")
        dyn = self.dynamics.problem()  # its M, when the free motion skipped it, timed as dynamics
        report.mark("dynamics")
        return self.gauss.minimise("velocity", state.q, state.v, dyn, contacts, report, 1 / self.dt)


class AccelerationScheme:
    """v+ = v + dt a, after the impulsive projection of an impact (see the module's docstring)."""

    acceleration = True

    def __init__(
        self, dynamics: DynamicsStage, gauss: GaussStage, actuation: Actuation, always: bool
    ) -> None:
        self.dynamics, self.gauss, self.actuation = dynamics, gauss, actuation
        self.options = gauss.options

    def next_velocity(
        self, state: State, tau: np.ndarray, x_free: np.ndarray, contacts: Contacts, report: StepReport
    ) -> np.ndarray:
        dt = self.options.dt
        dyn = self.dynamics.problem()
        v = self.impact(state, dyn.M, contacts, report)
        if v is not state.v:  # the damping acts on the velocity after the impact
            self.dynamics.free_motion(state.q, v, self.actuation.after_impact(tau, state.v, v), dt, True)
            dyn = self.dynamics.problem()
        return v + dt * self.gauss.minimise("acceleration", state.q, v, dyn, contacts, report, 1.0)

    def impact(self, state: State, M: np.ndarray, contacts: Contacts, report: StepReport) -> np.ndarray:
        """The impulsive Gauss projection of v while v violates an impulse-level row, else v itself.

        A projection can set a contact it did not hold approaching (a ball struck towards the next one,
        within a step): it is projected again, so no approach faster than ``restitution_threshold`` is
        left to the acceleration level's Baumgarte rows, which stopped it plastically (slower ones are
        inelastic, and a projection's own rows are met only to the QP's tolerance). Each projection's
        impulses are in ``report.impact``, the next ones in its own ``impact``."""
        gauss = self.gauss
        v, last, tolerance = state.v, report, IMPACT_TOLERANCE
        for _ in range(len(contacts.gap) + 1):  # each projection makes a contact separate, or ends
            ctx = gauss.context("impulse", state.q, v, v, contacts)
            parts = gauss.rows(ctx)
            if not any(np.any(rows.J @ v < rows.bound - tolerance) for _, rows in parts if not rows.equality):
                break
            tolerance = max(IMPACT_TOLERANCE, self.options.restitution_threshold)
            last.impact = StepReport(state.t, report.timed)
            last = last.impact
            v = gauss.solve(ctx, M, -(M @ v), parts, last, 1.0)
            report.certificates += last.certificates
        return v


Scheme = VelocityScheme | AccelerationScheme
SCHEMES: dict[str, type[Scheme]] = {"velocity": VelocityScheme, "acceleration": AccelerationScheme}
