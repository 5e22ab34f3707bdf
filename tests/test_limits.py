"""Joint position limits as unilateral rows."""

from pathlib import Path

import numpy as np
import pinocchio as pin
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


def test_the_compiled_activity_rule_is_the_plain_one_at_every_level():
    """Which constraints restrict x (docs/FORMULATION.md section 2), compiled, against the rule stated
    with numpy on values around its thresholds (NaN included): at the velocity level phi + dt min(rate, 0)
    <= margin; at the impulse and acceleration levels that closing within the active tolerance, and a
    rate that does not separate or a violated phi. The joint limits' kernel gives the same rows."""
    from gaussim.kernels.contact import bound_of, near_limits, restricting

    dt, margin, tolerance, threshold = 1e-3, 2e-3, 1e-6, 1e-4
    values = np.array([-1.0, -1e-3, -1e-6, -1e-9, 0.0, 1e-9, 1e-6, 1e-4, 2e-3, 1.0, np.nan])
    phi, rate = (a.ravel() for a in np.meshgrid(values, 1e3 * values))
    closing = phi + dt * np.minimum(rate, 0.0)
    expected = {
        0: closing <= margin,
        1: (closing <= tolerance) & ((rate <= threshold) | (phi < -tolerance)),
    }
    expected[2] = expected[1]
    for level, want in expected.items():
        got = restricting(level, phi, rate, dt, margin, tolerance, threshold)
        np.testing.assert_array_equal(got, want)
        assert want.any() and not want.all()
    signs = np.where(np.arange(len(phi)) % 2, -1.0, 1.0)  # lower and upper limits
    q = np.arange(len(phi)) * 0.1
    limits, v = q - phi / signs, rate / signs  # sign (q - limit) = phi (to round-off), sign v = rate
    index = np.arange(len(phi), dtype=np.int64)
    active, bound = np.empty(len(phi), np.int64), np.empty(len(phi))
    stabilisation = 0.2
    settings = (dt, margin, tolerance, threshold, stabilisation)
    for level in (0, 2):
        count = near_limits(q, v, index, index, signs, limits, level, settings, active, bound)
        kept = signs * (q - limits)  # phi as the kernel rounds it
        plain = restricting(level, kept, rate, dt, margin, tolerance, threshold)
        assert active[:count].tolist() == np.flatnonzero(plain).tolist() and 0 < count < len(phi)
        chosen = active[:count]
        want = bound_of(level, dt, stabilisation, kept[chosen], rate[chosen], 0.0, True)
        np.testing.assert_array_equal(bound[:count], want)


# Limit torques against the closed forms of Pinocchio's RNEA (statics, or one joint held), relative
CLOSED_FORM_RTOL = 1e-8


@pytest.fixture(scope="module")
def limited_double_pendulum(tmp_path_factory) -> gaussim.Robot:
    """robots/double_pendulum.urdf with limits: shoulder [1, 2] rad, elbow [0.5, 2] rad (gravity pulls
    both towards their lower limits from above them)."""
    text = (Path(__file__).parent.parent / "robots" / "double_pendulum.urdf").read_text()
    text = text.replace('type="continuous"', 'type="revolute"')
    for origin, lower in (('<origin xyz="0 0 2"/>', 1.0), ('<origin xyz="0 0 -0.5"/>', 0.5)):
        axis = f'{origin}<axis xyz="0 1 0"/>'
        assert axis in text
        text = text.replace(axis, f'{axis}<limit lower="{lower}" upper="2" effort="100" velocity="100"/>')
    path = tmp_path_factory.mktemp("limits") / "double_pendulum_limited.urdf"
    path.write_text(text)
    return gaussim.load_robot(path)


@pytest.mark.parametrize("scheme", ["velocity", "acceleration"])
@pytest.mark.parametrize("dt", [1e-3, 1e-2])
def test_joints_resting_on_their_limits_carry_the_gravity_torque(limited_double_pendulum, scheme, dt):
    """Both joints started on their lower limits, which gravity pushes them into: they stay, and the
    limit torques are the gravity torques g(q) (M a = tau_limit - g(q) with a = 0)."""
    robot = limited_double_pendulum
    q = robot.model.lowerPositionLimit.copy()
    g = pin.computeGeneralizedGravity(robot.model, robot.model.createData(), q)
    sim = gaussim.Simulator(gaussim.Scene(robot, joint_limits=True), gaussim.Options(dt=dt, scheme=scheme))
    state = run(sim, sim.reset(q), round(1.0 / dt))
    np.testing.assert_allclose(state.q, q, atol=LIMIT_TOLERANCE)
    torques = {r.joint: (r.side, r.torque) for r in sim.last_step.limits}
    assert torques.keys() == {"shoulder", "elbow"}
    for i, joint in enumerate(("shoulder", "elbow")):
        side, torque = torques[joint]
        assert side == "lower"
        assert torque == pytest.approx(g[i], rel=CLOSED_FORM_RTOL)


@pytest.mark.parametrize("scheme", ["velocity", "acceleration"])
def test_an_elbow_held_by_its_limit_carries_the_closed_form_torque_while_the_shoulder_swings(
    limited_double_pendulum, scheme
):
    """The shoulder free and swinging, the elbow on its lower limit: at each step that starts with the
    elbow held (q2 at its limit, v2 = 0), the two links turn as one (a2 = 0), so M11 a1 = -b1 and the
    limit's torque is M21 a1 + b2 where that pushes (> 0), else zero and the elbow leaves its limit."""
    robot = limited_double_pendulum
    model = robot.model.copy()
    model.lowerPositionLimit[0], model.upperPositionLimit[0] = -10.0, 10.0
    free_shoulder = gaussim.as_robot((model, robot.collision_model))
    data = model.createData()
    sim = gaussim.Simulator(gaussim.Scene(free_shoulder, joint_limits=True), gaussim.Options(scheme=scheme))
    state = sim.reset(np.array([1.2, 0.5]), np.array([-1.0, 0.0]))
    held = released = 0
    for _ in range(500):
        before, state = state, sim.step(state)
        if abs(before.q[1] - 0.5) > 1e-9 or abs(before.v[1]) > 1e-9:
            continue
        M = pin.crba(model, data, before.q)
        b = pin.nonLinearEffects(model, data, before.q, before.v)
        a1 = -b[0] / M[0, 0]
        expected = M[1, 0] * a1 + b[1]
        torque = sum(r.torque for r in sim.last_step.limits if r.joint == "elbow")
        if expected > 0:
            held += 1
            assert torque == pytest.approx(expected, rel=CLOSED_FORM_RTOL)
        else:
            released += 1
            assert torque == 0.0 and state.q[1] > 0.5
    assert held > 100 and released >= 1
