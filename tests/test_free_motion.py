"""Without an active constraint a step is Pinocchio's forward dynamics plus semi-implicit Euler (floating
bases on R3 x SO(3))."""

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

    # the base on R3 x SO(3): its origin's world velocity R v_l is held while its frame turns (so ABA's
    # -w x v_l leaves), the origin moves by dt R v_l+, and v_l+ is re-expressed in the new frame
    model, data, dt = solo12.model, solo12.model.createData(), 1e-3
    a = pin.aba(model, data, q, v, np.concatenate([np.zeros(6), tau]))
    v_next = v + dt * a
    v_next[:3] += dt * np.cross(v[3:6], v[:3])
    R = pin.Quaternion(q[3:7]).matrix()
    q_next = pin.integrate(model, q, dt * v_next)
    q_next[:3] = q[:3] + dt * R @ v_next[:3]
    v_next[:3] = pin.Quaternion(q_next[3:7]).matrix().T @ R @ v_next[:3]
    np.testing.assert_allclose(state.v, v_next, atol=ABA_TOLERANCE, rtol=0)
    np.testing.assert_allclose(state.q, q_next, atol=ABA_TOLERANCE, rtol=0)
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
