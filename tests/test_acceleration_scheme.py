"""The acceleration scheme (Options(scheme="acceleration")) against closed forms: impacts with
restitution from any starting gap, Coulomb's law while sliding, the stop of a sliding block."""

import numpy as np
import pytest

import gaussim

from .conftest import G, at_height

RADIUS = 0.1  # robots/ball.urdf [m]
BOX_HALF_HEIGHT = 0.05  # robots/box.urdf [m]
STICK_SPEED = 1e-6  # [m/s]
RESTITUTION_RTOL = 1e-6  # the impulse is a QP's answer, to ProxQP's tolerance
MOREAU_ATOL = 1e-6  # [m/s]
# starting gaps [m] across one step's travel at 1 m/s and dt = 1 ms: finely where the contact becomes
# active (1 mm, within Options.active_tolerance), and at random around it
GAPS = np.r_[np.linspace(0.999e-3, 1.002e-3, 31), np.random.default_rng(4).uniform(0.9e-3, 1.1e-3, 20)]

_FREE_BALL = """
  <joint name="{name}_joint" type="floating"><parent link="world"/><child link="{name}"/></joint>
  <link name="{name}">
    <inertial><mass value="1"/>
      <inertia ixx="0.004" ixy="0" ixz="0" iyy="0.004" iyz="0" izz="0.004"/></inertial>
    <collision><geometry><sphere radius="{radius}"/></geometry></collision>
  </link>"""


@pytest.fixture(scope="module")
def cradle_balls(tmp_path_factory) -> gaussim.Robot:
    """Three free 1 kg balls b0, b1, b2 (collision geometries b0_0, b1_0, b2_0)."""
    balls = "".join(_FREE_BALL.format(name=f"b{i}", radius=RADIUS) for i in range(3))
    path = tmp_path_factory.mktemp("cradle") / "cradle.urdf"
    path.write_text(f'<?xml version="1.0"?>\n<robot name="cradle"><link name="world"/>{balls}\n</robot>\n')
    return gaussim.load_robot(path)


def test_an_approaching_ball_rebounds_with_restitution_from_any_gap(ball):
    """A ball falling at 1 m/s onto a ground with e = 0.8: the first step whose velocity is not
    ballistic is the impact, and it leaves at e times its approach speed, whatever the starting gap.
    (Where the contact became active within Options.active_tolerance of closing, 1.000 to 1.001 mm
    here, the impulse-level rows had no restitution and the ball stopped dead in the air.)"""
    e, dt = 0.8, 1e-3
    scene = gaussim.Scene(ball, ground=gaussim.Ground(friction=0.8, restitution=e))
    sim = gaussim.Simulator(scene, gaussim.Options(scheme="acceleration", dt=dt))
    for gap in GAPS:
        state = sim.reset(at_height(ball, RADIUS + gap), np.array([0, 0, -1.0, 0, 0, 0]))
        for _ in range(5):
            before = state.v[2]
            state = sim.step(state)
            if abs(state.v[2] - (before - G * dt)) > 1e-9:
                break
        else:
            pytest.fail(f"gap {gap * 1e3:.7f} mm: no impact within 5 steps")
        assert sim.last_step.impact is not None
        rebound = state.v[2] + G * dt  # the impact's velocity, before the step's gravity
        assert rebound == pytest.approx(-e * before, rel=RESTITUTION_RTOL), f"gap {gap * 1e3:.7f} mm"


@pytest.mark.parametrize("gap", [0.0, 0.9999e-3, 1.0e-3, 1.0005e-3, 1.002e-3, *GAPS[31:36]])
def test_newtons_cradle_gives_moreaus_answer(cradle_balls, gap):
    """Three touching elastic balls in a row, the first thrown at the other two at 1 m/s: the impulsive
    Gauss projection of both contacts at once (Moreau) gives (-1/3, 2/3, 2/3), momentum and energy
    kept, as the velocity scheme does (it gave the plastic (1/3, 1/3, 1/3) in the gap window)."""
    dt = 1e-3
    scene = gaussim.Scene(
        cradle_balls,
        contacts=[("b0_0", "b1_0"), ("b1_0", "b2_0")],
        gravity=(0, 0, 0),
        self_contact=(0.0, 1.0),
    )
    sim = gaussim.Simulator(scene, gaussim.Options(scheme="acceleration", dt=dt))
    q = cradle_balls.neutral()
    q[[0, 7, 14]] = -2 * RADIUS - gap, 0.0, 2 * RADIUS
    v = np.zeros(18)
    v[0] = 1.0
    state = sim.reset(q, v)
    for _ in range(int(gap / dt) + 10):
        state = sim.step(state)
    speeds = state.v[[0, 6, 12]]
    np.testing.assert_allclose(speeds, [-1 / 3, 2 / 3, 2 / 3], atol=MOREAU_ATOL)
    assert speeds.sum() == pytest.approx(1.0, abs=MOREAU_ATOL)
    assert speeds @ speeds == pytest.approx(1.0, abs=MOREAU_ATOL)
    np.testing.assert_allclose(np.delete(state.v, [0, 6, 12]), 0.0, atol=1e-12)


@pytest.mark.parametrize("dt", [1e-2, 1e-3])
def test_a_sliding_block_stops_at_the_closed_form_time(box, dt):
    """A box sliding at 2 m/s with mu = 0.3 decelerates at mu g and stops at v0 / (mu g), up to one
    step, then stays: the step whose friction would reverse the slip sticks at once, its friction the
    force that stops it, within the cone. (Stuck rows that brought the slip down by Baumgarte's rate,
    a factor 0.6 a step, stopped it 2.1 % late at dt = 1 ms, 29 % at 10 ms.)"""
    mu, v0 = 0.3, 2.0
    sim = gaussim.Simulator(
        gaussim.Scene(box, ground=gaussim.Ground(friction=mu)), gaussim.Options(scheme="acceleration", dt=dt)
    )
    state = sim.reset(at_height(box, BOX_HALF_HEIGHT), np.array([v0, 0, 0, 0, 0, 0]))
    stop = v0 / (mu * G)
    while np.linalg.norm(state.v) > STICK_SPEED:
        state = sim.step(state)
        total = sim.last_step.total_contact_force()
        assert np.linalg.norm(total[:2]) <= mu * total[2] * (1 + 1e-9)
        assert state.t < 2 * stop, "it never stops"
    assert abs(state.t - stop) <= dt * (1 + 1e-9)
    for _ in range(10):
        state = sim.step(state)
        assert np.linalg.norm(state.v) < STICK_SPEED
