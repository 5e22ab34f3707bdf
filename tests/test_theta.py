"""Moreau-Jean's theta (Options.theta): q+ = q (+) dt ((1 - theta) v + theta v+).

References: closed forms under constant forces (free fall, rolling down an incline without slip, a
box sliding to rest under Coulomb friction), which theta 0.5, the trapezoidal rule, follows exactly
and semi-implicit Euler (theta 1) with a known lag; an impact must land as at theta 1 (no sinking,
no rebound), since a blend would carry the approach into the next configuration.
"""

from __future__ import annotations

import numpy as np
import pytest

import gaussim
from gaussim.world import FreeBody

from .conftest import G, at_height

RADIUS = 0.1  # robots/ball.urdf
EXACT = 1e-9  # [m] what theta 0.5 leaves of a constant-force trajectory over 1 s (round-off)


@pytest.mark.parametrize("theta", [0.5, 0.75, 1.0])
def test_free_fall_moves_by_the_theta_blend_of_the_two_velocities(ball, theta):
    """z_k = z0 - g dt^2 k (k - 1 + 2 theta) / 2: exact (g t^2 / 2) at theta 0.5."""
    dt, steps = 1e-2, 100
    sim = gaussim.Simulator(gaussim.Scene(ball), gaussim.Options(dt=dt, theta=theta))
    state = sim.reset(at_height(ball, 10.0))
    for _ in range(steps):
        state = sim.step(state)
    assert state.v[2] == pytest.approx(-G * steps * dt, abs=1e-12)
    assert state.q[2] == pytest.approx(10.0 - G * dt**2 * steps * (steps - 1 + 2 * theta) / 2, abs=1e-12)


@pytest.mark.parametrize("dt", [1e-3, 1e-2])
def test_a_ball_rolls_down_an_incline_exactly_at_theta_one_half(ball, dt):
    """30 deg, mu 0.5, from rest, 1 s: the distance 5/14 g sin(theta) t^2 to round-off, the centre on
    its support; theta 1 lags by the first-order 5/14 g sin(theta) t dt."""
    incline = np.radians(30.0)
    normal = np.array([-np.sin(incline), 0.0, np.cos(incline)])
    q0 = ball.neutral()
    q0[:3] = RADIUS * normal
    distances = {}
    for theta in (0.5, 1.0):
        scene = gaussim.Scene(ball, ground=gaussim.Ground(friction=0.5, normal=tuple(normal)))
        sim = gaussim.Simulator(scene, gaussim.Options(dt=dt, theta=theta))
        state = sim.reset(q0)
        for _ in range(round(1.0 / dt)):
            state = sim.step(state)
            assert abs(RADIUS - state.q[:3] @ normal) < 1e-9
        distances[theta] = float(np.linalg.norm(state.q[:3] - q0[:3]))
    a = 5 / 7 * G * np.sin(incline)
    assert distances[0.5] == pytest.approx(a / 2, abs=EXACT)
    assert distances[1.0] - a / 2 == pytest.approx(a * dt / 2, rel=1e-6)


def test_a_box_slides_to_rest_exactly_at_theta_one_half():
    """A 10 cm box launched at 2 m/s on ground of friction 0.5 decelerates at mu g: at theta 0.5 its
    centre follows v0 t - mu g t^2 / 2 exactly until it stops (its friction rows, steady while it
    slides, are no impact), then stays at v0^2 / (2 mu g)."""
    mu, v0, dt = 0.5, 2.0, 1e-3
    box = FreeBody.box("box", (0.1, 0.1, 0.1), mass=1.0)
    scene = gaussim.Scene(bodies={"box": box}, ground=gaussim.Ground(friction=mu))
    sim = gaussim.Simulator(scene, gaussim.Options(dt=dt, theta=0.5))
    state = sim.reset({"box": gaussim.pose(z=0.05)}, {"box": np.array([v0, 0, 0, 0, 0, 0])})
    stop = v0 / (mu * G)
    while state.t < stop - dt:
        state = sim.step(state)
        t = state.t
        assert state.q[0] == pytest.approx(v0 * t - mu * G * t**2 / 2, abs=EXACT)
    for _ in range(100):
        state = sim.step(state)
    assert state.q[0] == pytest.approx(v0**2 / (2 * mu * G), abs=1e-3 * dt)
    assert abs(state.q[2] - 0.05) < 1e-9


@pytest.mark.parametrize("dt", [1e-3, 1e-2])
def test_an_impact_lands_as_at_theta_one(ball, dt):
    """A ball dropped from 0.5 m lands inelastically at theta 0.5 as at theta 1: the step of the
    impact moves it by dt v+ (a blend would sink it by u dt / 2, which stabilisation would push out at
    a speed that does not vanish with dt: a rebound); neither sinks nor leaves the ground after."""
    paths = {}
    for theta in (0.5, 1.0):
        sim = gaussim.Simulator(
            gaussim.Scene(ball, ground=gaussim.Ground()), gaussim.Options(dt=dt, theta=theta)
        )
        state = sim.reset(at_height(ball, RADIUS + 0.5))
        heights = []
        for _ in range(round(1.0 / dt)):
            state = sim.step(state)
            heights.append(state.q[2] - RADIUS)
        paths[theta] = np.array(heights)
    for heights in paths.values():
        landed = int(np.argmax(heights < 1e-9))
        assert landed > 0
        assert heights.min() > -1e-9, "no sinking"
        assert heights[landed:].max() < 1e-9, "no rebound"
    # before the impact theta 0.5 falls as g t^2 / 2 (theta 1 ahead of it by g t dt / 2)
    t = dt * np.arange(1, len(paths[0.5]) + 1)
    falling = 0.5 - G * t**2 / 2 > 0.0
    np.testing.assert_allclose(paths[0.5][falling][:-1], (0.5 - G * t**2 / 2)[falling][:-1], atol=1e-12)


def test_a_limit_stops_a_joint_as_at_theta_one(pendulum):
    """A pendulum swung into its upper limit at 3 rad/s: the step of the impact moves the joint by dt
    v+, so theta 0.5 overshoots the limit no more than theta 1 does."""
    upper = pendulum.model.upperPositionLimit[0]
    for theta in (0.5, 1.0):
        sim = gaussim.Simulator(gaussim.Scene(pendulum, joint_limits=True), gaussim.Options(theta=theta))
        state = sim.reset(np.array([0.0]), np.array([3.0]))
        excess = []
        for _ in range(1000):
            state = sim.step(state)
            excess.append(state.q[0] - upper)
        assert max(excess) <= 1e-6
        assert max(excess) > -0.01, "the pendulum reaches the limit"


@pytest.mark.parametrize(
    ("given", "message"),
    [
        ({"theta": 0.4}, "theta: must be in [0.5, 1], got 0.4"),
        ({"theta": 1.5}, "theta: must be in [0.5, 1], got 1.5"),
        ({"theta": "half"}, "theta: must be in [0.5, 1], got 'half'"),
        ({"theta": 0.5, "scheme": "acceleration"}, "theta: must be 1 with scheme 'acceleration'"),
    ],
)
def test_a_theta_out_of_range_is_named(given, message):
    with pytest.raises(gaussim.InvalidOptions, match=message.replace("[", r"\[")):
        gaussim.Options(**given)


def test_the_command_line_sets_theta_and_names_a_bad_one(tmp_path, capsys):
    """``gaussim run --theta`` overrides the scene's; the run log keeps it; a value out of range is
    refused with exit code 2 and the field named, without a traceback."""
    from gaussim.cli import EXIT_BAD_INPUT, EXIT_OK, main

    out = tmp_path / "ball.runlog"
    argv = ["run", "ball_bounce", "--theta", "0.5", "--duration", "0.05", "--out", str(out), "--quiet"]
    assert main(argv) == EXIT_OK
    assert gaussim.RunLog.load(out).options.theta == 0.5
    assert (
        main(["run", "ball_bounce", "--theta", "2", "--out", str(tmp_path / "bad"), "--quiet"])
        == EXIT_BAD_INPUT
    )
    err = capsys.readouterr().err
    assert "theta: must be in [0.5, 1], got 2.0" in err and "Traceback" not in err
