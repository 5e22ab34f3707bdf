"""Without an active constraint a step is Pinocchio's forward dynamics plus semi-implicit Euler."""

import numpy as np
import pinocchio as pin
import pytest

import gaussim

from .conftest import at_height

ABA_TOLERANCE = 1e-10


@pytest.mark.parametrize("scheme", ["velocity", "acceleration"])
def test_free_step_equals_aba(solo12, scheme):
    scene = gaussim.Scene(solo12, ground=gaussim.Ground(), joint_limits=True)
    sim = gaussim.Simulator(scene, gaussim.Options(scheme=scheme, dt=1e-3))
    rng = np.random.default_rng(0)
    q = solo12.configuration("standing")
    q[2] = 1.0  # far above the ground: no contact can be reached
    v = rng.normal(size=solo12.model.nv)
    tau = rng.normal(size=solo12.model.nv - 6)
    state = sim.step(sim.reset(q, v), tau)

    model, data = solo12.model, solo12.model.createData()
    a = pin.aba(model, data, q, v, np.concatenate([np.zeros(6), tau]))
    v_next = v + 1e-3 * a
    np.testing.assert_allclose(state.v, v_next, atol=ABA_TOLERANCE, rtol=0)
    np.testing.assert_allclose(state.q, pin.integrate(model, q, 1e-3 * v_next), atol=ABA_TOLERANCE, rtol=0)
    assert sim.last_step.certificates == (), "no QP is needed when nothing restricts the motion"
    assert sim.last_step.contacts == []


def test_free_fall_of_a_ball(ball):
    sim = gaussim.Simulator(gaussim.Scene(ball), gaussim.Options(dt=1e-3))
    state = sim.reset(at_height(ball, 10.0))
    for _ in range(100):
        state = sim.step(state)
    # semi-implicit Euler: v_k = -g k dt, z_k = z0 - g dt^2 k (k + 1) / 2
    assert state.v[2] == pytest.approx(-9.81 * 0.1, abs=1e-12)
    assert state.q[2] == pytest.approx(10.0 - 9.81 * 1e-6 * 100 * 101 / 2, abs=1e-12)
    assert state.t == pytest.approx(0.1)
