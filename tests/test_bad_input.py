"""Every bad input gets a clear error that names the cause (one test per class)."""

import numpy as np
import pytest

import gaussim

from .conftest import at_height


@pytest.fixture
def sim(ball):
    return gaussim.Simulator(gaussim.Scene(ball, ground=gaussim.Ground()))


def test_wrong_shapes(sim, ball):
    with pytest.raises(gaussim.InvalidState, match=r"q must have shape \(7,\)"):
        sim.reset(np.zeros(3))
    with pytest.raises(gaussim.InvalidState, match=r"v must have shape \(6,\)"):
        sim.reset(at_height(ball, 1.0), np.zeros(7))
    state = sim.reset(at_height(ball, 1.0))
    with pytest.raises(gaussim.InvalidState, match=r"tau must have shape \(6,\) or \(0,\)"):
        sim.step(state, np.zeros(2))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_state_and_torque(sim, ball, bad):
    q = at_height(ball, 1.0)
    q[0] = bad
    with pytest.raises(gaussim.InvalidState, match=r"q has non-finite entries at \[0\]"):
        sim.reset(q)
    v = np.zeros(6)
    v[4] = bad
    with pytest.raises(gaussim.InvalidState, match=r"v has non-finite entries at \[4\]"):
        sim.reset(at_height(ball, 1.0), v)
    tau = np.zeros(6)
    tau[2] = bad
    with pytest.raises(gaussim.InvalidState, match=r"tau has non-finite entries at \[2\]"):
        sim.step(sim.reset(at_height(ball, 1.0)), tau)
    with pytest.raises(gaussim.InvalidState, match=r"tau has non-finite entries at \[2\]"):
        sim.full_torque(tau)


def test_non_finite_actuated_torque_names_its_entry(solo12):
    """The torques of a floating robot's actuated joints (nv - 6,) are checked where the dynamics
    read them; the error names the entry of the array the user gave."""
    sim = gaussim.Simulator(gaussim.Scene(solo12))
    state = sim.reset(solo12.configuration("standing"))
    tau = np.zeros(12)
    tau[7] = np.nan
    with pytest.raises(gaussim.InvalidState, match=r"tau has non-finite entries at \[7\]"):
        sim.step(state, tau)
    assert sim.last_step is None


def test_non_finite_velocity_never_reaches_the_state(sim, ball, monkeypatch):
    """A non-finite free motion (forced here: a broken dynamics stage) stops the step with a
    SolverError; the state given stays valid and no new state is made."""
    from gaussim.dynamics import DynamicsStage

    real = DynamicsStage.free_motion

    def broken(self, *args):
        return np.full_like(real(self, *args), np.nan)

    state = sim.reset(at_height(ball, 1.0))  # free flight: the free motion is the next velocity
    monkeypatch.setattr(DynamicsStage, "free_motion", broken)
    with pytest.raises(gaussim.SolverError, match="non-finite velocity"):
        sim.step(state)
    assert np.isfinite(state.q).all() and sim.last_step is None
