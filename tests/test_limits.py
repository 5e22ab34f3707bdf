"""Joint position limits as unilateral rows."""

import numpy as np
import pytest

import gaussim

from .conftest import run

LIMIT_TOLERANCE = 1e-6  # [rad]


@pytest.mark.parametrize("scheme", ["velocity", "acceleration"])
def test_pendulum_never_exceeds_its_limit(pendulum, scheme):
    sim = gaussim.Simulator(gaussim.Scene(pendulum, joint_limits=True), gaussim.Options(scheme=scheme))
    upper = pendulum.model.upperPositionLimit[0]
    excess, torques = [], []

    def record(state):
        excess.append(state.q[0] - upper)
        report = sim.last_step
        torques.extend(r.torque for r in report.limits + (report.impact.limits if report.impact else []))

    run(sim, sim.reset(np.array([0.0]), np.array([3.0])), 1000, each=record)
    assert max(excess) <= LIMIT_TOLERANCE
    assert max(excess) > -0.01, "the pendulum reaches the limit"
    assert min(torques) < -1.0, "the upper limit stops the pendulum"
    assert max(torques) <= 1e-12, "and only ever pushes back"


def test_limit_holds_against_a_torque(pendulum):
    sim = gaussim.Simulator(gaussim.Scene(pendulum, joint_limits=True))
    state = run(sim, sim.reset(np.array([0.4])), 500, tau=np.array([20.0]))
    assert state.q[0] == pytest.approx(0.5, abs=LIMIT_TOLERANCE)
    # statics: limit torque + 20 N m - m g l sin(q) = 0
    (reaction,) = sim.last_step.limits
    assert reaction.side == "upper"
    assert reaction.torque == pytest.approx(-(20.0 - 9.81 * np.sin(0.5)), rel=1e-6)


def test_limits_are_not_built_unless_declared(pendulum):
    sim = gaussim.Simulator(gaussim.Scene(pendulum))
    state = run(sim, sim.reset(np.array([0.4])), 200, tau=np.array([20.0]))
    assert state.q[0] > 0.5
    assert [m.name for m in sim.modules] == []
