"""What the examples share (not an example itself): their command lines' checks (a duration or a
time step > 0; a gaussim error told in one line), a run recorded step by step into a run log and its
replay page, and an open-loop trot for Solo-12."""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

import gaussim
from gaussim.cli import told
from gaussim.control import Command, PDHold
from gaussim.state import BodyState
from gaussim.viewer import Viewer


def positive(text: str) -> float:
    """An argparse type: a finite number > 0 (a duration, a time step)."""
    value = float(text)  # argparse tells a ValueError as "invalid positive value"
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


def run(main: Callable[[], int | None]) -> None:
    """Exit with ``main()``'s status; a gaussim error or a failed write is told in one line on stderr
    with the gaussim command's exit status (2 for a user's mistake, 1 for a failed simulation or write)."""
    try:
        status = main()
    except (OSError, gaussim.GaussimError) as err:
        message, status = told(err)
        print(f"{Path(sys.argv[0]).name}: {message}", file=sys.stderr)
    sys.exit(status)


class Recording:
    """Steps a simulator and logs every step (:class:`gaussim.RunLog`), for its replay page.

    Args:
        sim: the simulator.
        state: the initial state.
    """

    def __init__(self, sim: gaussim.Simulator, state: gaussim.State) -> None:
        self.sim = sim
        self.log = gaussim.RunLog(sim.scene.robot.name, "", sim.options)
        self.log.start(state, sim.scene.gravity)

    def step(self, state: gaussim.State, tau: object = None, damping: object = None) -> gaussim.State:
        """``sim.step(state, tau, damping)``, recorded with the torque the joints felt."""
        state = self.sim.step(state, tau, damping)
        report = self.sim.last_step
        assert report is not None
        self.log.record(state, self.sim.full_torque(tau, damping, state.v), report)
        return state

    def save(self, out: Path) -> tuple[Path, Path]:
        """Write the run log ``out.npz`` and its replay page ``out.html`` (every body, the contact
        forces); returns their paths."""
        out.parent.mkdir(parents=True, exist_ok=True)
        self.log.finish(True)
        log = self.log.save(out.with_suffix(".npz"))
        with Viewer(self.sim.scene, live=False) as viewer:  # a page needs no server
            viewer.replay(self.log)
            page = viewer.save_html(out.with_suffix(".html"))
        return log, page


class Trot:
    """An open-loop trot for Solo-12: the diagonal leg pairs (FL, HR) and (FR, HL) swing in turn at
    ``frequency``, each hip sweeping +-``stride`` [rad] about the standing posture and each knee
    folding by up to ``lift`` [rad] while its foot swings forward; joint PD targets with implicit
    damping (:class:`gaussim.control.PDHold`), the gait faded in over ``ramp`` [s].

    Args:
        robot: Solo-12 (its "standing" configuration is the posture).
        dt: the time step [s] (the PD drive is implicit: stable at any dt).
        kp, kd: PD gains [N m/rad], [N m s/rad].
    """

    # per leg: its first actuated coordinate (HAA, then HFE, KFE), the sign of a knee folding, phase
    LEGS = {"FL": (0, -1.0, 0.0), "FR": (3, -1.0, np.pi), "HL": (6, 1.0, np.pi), "HR": (9, 1.0, 0.0)}

    def __init__(
        self,
        robot: gaussim.Robot,
        dt: float,
        *,
        frequency: float = 2.0,
        stride: float = 0.3,
        lift: float = 0.5,
        kp: float = 8.0,
        kd: float = 0.25,
        ramp: float = 0.5,
    ) -> None:
        self.standing = robot.configuration("standing")
        self.frequency, self.stride, self.lift, self.ramp = frequency, stride, lift, ramp
        self.hold = PDHold(robot.model, self.standing.copy(), kp, kd, robot.actuated, dt)

    def __call__(self, t: float, state: BodyState) -> Command:
        """The torque and implicit damping, each (12,), at time ``t`` [s] for the robot's state."""
        reference = self.hold.q_ref
        reference[:] = self.standing
        fade = min(1.0, t / self.ramp)
        for first, fold, phase in self.LEGS.values():
            angle = 2 * np.pi * self.frequency * t + phase
            reference[7 + first + 1] -= fade * self.stride * np.sin(angle)  # + moves the foot back
            reference[7 + first + 2] += fade * fold * self.lift * max(0.0, np.cos(angle))  # swing
        return self.hold(state)  # type: ignore[arg-type]
