"""Implicit damping (``Simulator.step(..., damping=D)``) and the implicit PD hold built on it."""

import numpy as np
import pinocchio as pin
import pytest

import gaussim
from gaussim.control import Command, PDHold, command
from gaussim.scenefile import SceneFileError

from .conftest import at_height, frame_acceleration, step_velocity


@pytest.mark.parametrize("scheme", ["velocity", "acceleration"])
def test_damping_is_applied_at_the_new_velocity(solo12, scheme):
    """v+ solves M (v+ - v + dt c) = dt (tau - b(q, v) - D v+): backward Euler in the damping, for both
    schemes (in free flight nothing else acts; c, the base frame's turn, and v+ as the step posed it:
    see conftest.step_velocity)."""
    dt = 0.02
    sim = gaussim.Simulator(gaussim.Scene(solo12), gaussim.Options(dt=dt, scheme=scheme))
    rng = np.random.default_rng(0)
    q = at_height(solo12, 5.0)
    q[7:] = solo12.configuration("standing")[7:]
    v = rng.normal(size=solo12.model.nv)
    tau, D = rng.normal(size=12), rng.uniform(0.1, 2.0, size=12)
    before = sim.reset(q, v)
    after = sim.step(before, tau, D)
    v_next = step_velocity(before, after)
    model, data = solo12.model, solo12.model.createData()
    M = pin.crba(model, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    full_tau, full_D = np.r_[np.zeros(6), tau], np.r_[np.zeros(6), D]
    residual = M @ (v_next - v + dt * frame_acceleration(v)) - dt * (
        full_tau - pin.nonLinearEffects(model, data, q, v) - full_D * v_next
    )
    assert np.abs(residual).max() < 1e-9
    assert np.allclose(sim.full_torque(tau, D, after.v), full_tau - full_D * after.v)


def test_dropping_the_damping_restores_the_robot(solo12):
    """A step without damping after damped ones is the undamped step (the armature is restored)."""
    q = at_height(solo12, 5.0)
    v = np.random.default_rng(1).normal(size=solo12.model.nv)
    damped = gaussim.Simulator(gaussim.Scene(solo12))
    state = damped.reset(q, v)
    damped.step(state, None, np.full(12, 3.0))
    plain = gaussim.Simulator(gaussim.Scene(solo12))
    plain.step(plain.reset(q, v))  # the same path through the dynamics stage (CRBA, then ABA)
    assert np.array_equal(damped.step(state).v, plain.step(state).v)


@pytest.mark.parametrize("tau", [None, np.zeros(12), np.zeros(18)])
def test_torque_and_damping_are_padded_each_by_its_own_size(solo12, tau):
    """tau and D are each padded on the floating base whatever the other's size (a kernel that padded D
    at tau's offset read past its end when tau was None: garbage, a spurious 'damping must be >= 0')."""
    q = at_height(solo12, 5.0)
    v = np.random.default_rng(2).normal(size=solo12.model.nv)
    steps = []
    for damping in (np.full(12, 3.0), np.r_[np.zeros(6), np.full(12, 3.0)], None):
        sim = gaussim.Simulator(gaussim.Scene(solo12))
        steps.append(sim.step(sim.reset(q, v), tau, damping).v)
    assert np.array_equal(steps[0], steps[1])
    assert np.abs(steps[0][6:] - steps[2][6:]).max() > 1e-3  # and the damping acts


@pytest.mark.parametrize(
    ("damping", "message"),
    [
        (np.full(12, -1.0), r"damping must be finite and >= 0"),
        (np.full(12, np.nan), r"damping must be finite and >= 0"),
        (np.ones(5), r"damping must have shape \(18,\) or \(12,\)"),
    ],
)
def test_bad_damping_is_refused(solo12, damping, message):
    sim = gaussim.Simulator(gaussim.Scene(solo12))
    with pytest.raises(gaussim.InvalidState, match=message):
        sim.step(sim.reset(at_height(solo12, 1.0)), None, damping)


def test_implicit_pd_holds_where_the_explicit_one_diverges(solo12):
    """Solo-12 hanging in the air at dt = 20 ms under a stiff posture hold: the explicit law diverges
    (kd dt is several times the lower legs' inertia), the implicit one settles on its target."""
    dt, q_ref = 0.02, solo12.configuration("standing")
    scene = gaussim.Scene(solo12, gravity=(0.0, 0.0, 0.0))
    q0 = q_ref.copy()
    q0[7:] += 0.3
    finals = {}
    for implicit in (False, True):
        sim = gaussim.Simulator(scene, gaussim.Options(dt=dt))
        hold = PDHold(solo12.model, q_ref, 5.0, 0.2, slice(6, 18), dt if implicit else None)
        state = sim.reset(q0)
        try:
            for _ in range(100):
                state = sim.step(state, *command(hold(state)))
            finals[implicit] = np.abs(pin.difference(solo12.model, state.q, q_ref)[6:]).max()
        except gaussim.GaussimError:
            finals[implicit] = np.inf
    assert finals[True] < 1e-2
    assert not finals[False] < 1.0  # diverged (or raised)


def test_pd_command_and_scene_file_switch(tmp_path):
    text = (
        '[robot]\nname = "pendulum"\n[control]\ntype = "pd"\nkp = 4.0\nkd = 0.5\n{extra}'
        "[options]\ndt = 0.01\n"
    )
    path = tmp_path / "s.toml"
    path.write_text(text.format(extra=""))
    spec = gaussim.load_scene(path)
    out = spec.controller(gaussim.State(0.0, np.array([0.2]), np.array([1.0])))
    assert isinstance(out, Command) and np.allclose(out.tau, [-0.8]) and np.allclose(out.damping, [0.54])
    path.write_text(text.format(extra="implicit = false\n"))
    explicit = gaussim.load_scene(path).controller(gaussim.State(0.0, np.array([0.2]), np.array([1.0])))
    assert np.allclose(explicit, [-0.8 - 0.5])
    path.write_text(text.format(extra='implicit = "yes"\n'))
    with pytest.raises(SceneFileError, match=r"control.implicit: must be true or false"):
        gaussim.load_scene(path)


def test_damping_after_an_impact_acts_on_the_new_velocity(ball):
    """Acceleration scheme: a ball hits the ground at u = 2 m/s (restitution e = 0.5) under a vertical
    damping d = 5 m [N s/m]: the impact leaves at e u, and the damping acts on that velocity, not
    the approach's. The flight then follows the backward Euler closed form of m v' = -m g - d v:
    v_k = (e u + g / lambda) (1 + lambda dt)^-k - g / lambda, lambda = d / m."""
    e, u, rate = 0.5, 2.0, 5.0
    sim = gaussim.Simulator(
        gaussim.Scene(ball, ground=gaussim.Ground(restitution=e)), gaussim.Options(scheme="acceleration")
    )
    dt, g = sim.options.dt, 9.81
    D = np.zeros(6)
    D[2] = rate * ball.mass
    state = sim.reset(at_height(ball, 0.1), np.array([0, 0, -u, 0, 0, 0]))
    for k in range(1, 51):
        state = sim.step(state, damping=D)
        assert (sim.last_step.impact is not None) == (k == 1)
        expected = (e * u + g / rate) * (1 + rate * dt) ** -k - g / rate
        assert state.v[2] == pytest.approx(expected, abs=1e-9)
