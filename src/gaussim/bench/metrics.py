"""What a benchmark run measures at every step, and its per-run summary.

The contact metrics are those of ContactBench (Le Lidec et al., "Contact models in robotics: a
comparative analysis", T-RO 2024), evaluated on each contact after the step, with u = J v+ its
velocity, f its force, n its normal, mu its friction coefficient:

- Signorini residual |f_n (u_n + gap / dt)| [W]: a contact pushes only while it ends the step closed
  (u_n + gap / dt is the rate at which the step closes its gap; the velocity scheme closes it exactly);
- cone violation max(0, |f_t| - mu f_n) [N]: the force lies in the Coulomb cone;
- maximal-dissipation gap f_t . u_t + mu f_n |u_t| [W]: a sliding contact's friction opposes its slip
  at full strength (0 when it does, up to 2 mu f_n |u_t| when it pushes along).

The wall time of each step alone is timed (reading the reports for these metrics is not).
"""

from __future__ import annotations

import time

import numpy as np

from ..control import Controller, command
from ..simulator import Simulator
from ..state import State


class Recorder:
    """Steps a simulator and keeps the per-step metrics.

    Args:
        sim: the simulator; its scene gives each contact's friction coefficient.
    """

    def __init__(self, sim: Simulator) -> None:
        self.sim = sim
        scene = sim.scene
        # an obstacle's own coefficient; a robot geometry touched by another has the scene's self-contact one
        self.friction = {o.name: o.friction for o in scene.obstacles}
        self.self_friction = scene.self_contact[0]
        self.seconds: list[float] = []
        self.penetration = self.signorini = self.cone = self.dissipation = self.kkt_residual = 0.0
        self.iterations = self.unconverged = 0

    def run(self, state: State, duration: float, controller: Controller | None = None) -> State:
        """Step from ``state`` for ``duration`` simulated seconds; return the last state."""
        for _ in range(self.sim.options.steps(duration)):
            state = self.step(state, controller)
        return state

    def step(self, state: State, controller: Controller | None = None) -> State:
        actuation = command(controller(state) if controller is not None else None)
        start = time.perf_counter()
        state = self.sim.step(state, *actuation)
        self.seconds.append(time.perf_counter() - start)
        self._contacts(state)
        return state

    def _contacts(self, state: State) -> None:
        report = self.sim.last_step
        assert report is not None
        self.iterations += report.iterations
        self.kkt_residual = max(self.kkt_residual, report.max_residual)
        self.unconverged += not report.converged
        contacts = report.contacts
        if not contacts:
            return
        J = report.contact_jacobian
        assert J is not None
        u = (J @ state.v).reshape(-1, 3)
        dt = self.sim.options.dt
        for c, velocity in zip(contacts, u):
            mu = self.friction.get(c.obstacle, self.self_friction)
            f_n, u_n = c.normal_force, float(velocity @ c.normal)
            f_t, u_t = c.force - f_n * c.normal, velocity - u_n * c.normal
            self.penetration = max(self.penetration, -c.gap)
            self.signorini = max(self.signorini, abs(f_n * (u_n + c.gap / dt)))
            self.cone = max(self.cone, float(np.linalg.norm(f_t)) - mu * f_n)
            self.dissipation = max(self.dissipation, float(f_t @ u_t) + mu * f_n * float(np.linalg.norm(u_t)))

    def absorb(self, other: Recorder) -> None:
        """Count the steps ``other`` recorded as this one's (a case made of several runs)."""
        self.seconds += other.seconds
        self.iterations += other.iterations
        self.unconverged += other.unconverged
        for name in ("penetration", "signorini", "cone", "dissipation", "kkt_residual"):
            setattr(self, name, max(getattr(self, name), getattr(other, name)))

    def summary(self) -> dict[str, float]:
        """The per-run metrics: the contact metrics' maxima, ProxQP iterations per step, the largest KKT
        residual of a step's QPs, the steps whose QPs did not converge (reported, with
        ``Options.on_failure = "report"``), and the wall time per step (median, p90) [us] and per
        simulated second [s]."""
        seconds = np.array(self.seconds)
        return {
            "penetration": self.penetration,
            "signorini": self.signorini,
            "cone": max(self.cone, 0.0),
            "dissipation": self.dissipation,
            "iterations": self.iterations / len(seconds),
            "kkt_residual": self.kkt_residual,
            "unconverged_steps": float(self.unconverged),
            "us_per_step": float(np.median(seconds)) * 1e6,
            "us_per_step_p90": float(np.percentile(seconds, 90)) * 1e6,
            "wall_per_sim_s": float(seconds.sum()) / (len(seconds) * self.sim.options.dt),
        }
