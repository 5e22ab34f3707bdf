"""Floating bases on R3 x SO(3): free bodies keep their momentum, balls roll on their support.

References: conservation laws of a torque-free rigid body, the closed form of rolling without slip
(a = 5/7 g sin(theta) for a solid ball), and scipy's DOP853 at rtol 1e-12 on Euler's equations.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import gaussim
from gaussim.bench.cases import free_rotation

from .conftest import G

SCHEMES = ("velocity", "acceleration")
RADIUS, MASS, INERTIA = 0.1, 1.0, 0.004  # robots/ball.urdf
# Round-off over 1e4 steps: the world momentum is kept to this, relative.
MOMENTUM_TOLERANCE = 1e-9
# A torque-free body's energy and world angular momentum, relative: the midpoint rule keeps both.
CONSERVATION_TOLERANCE = 1e-10
# The ulps a step may round a kept energy by (relative, per step): the energy bound after k steps.
ROUNDING_ULPS = 8
TOP_INERTIA = np.diag([1.0, 2.0, 2.5])  # [kg m^2]

_TOP = """<?xml version="1.0"?>
<robot name="top"><link name="body"><inertial><origin xyz="0 0 0"/><mass value="1"/>
<inertia ixx="1" ixy="0" ixz="0" iyy="2" iyz="0" izz="2.5"/></inertial></link></robot>
"""


@pytest.fixture(scope="module")
def top(tmp_path_factory) -> gaussim.Robot:
    path = tmp_path_factory.mktemp("top") / "top.urdf"
    path.write_text(_TOP)
    return gaussim.load_robot(path, floating_base=True)


def world(q: np.ndarray, local: np.ndarray) -> np.ndarray:
    """A free-flyer's body-frame vector (3,) in the world frame."""
    return pin.Quaternion(q[3:7]).matrix() @ local


@pytest.mark.parametrize("scheme", SCHEMES)
@pytest.mark.parametrize("dt", [1e-4, 1e-3, 1e-2, 5e-2])
def test_a_spinning_free_ball_keeps_its_momentum_and_energy(ball, scheme, dt):
    """Zero gravity, 3 m/s and 30 rad/s about an axis across the motion, 1 s: the world velocity
    stays 3 m/s along x (Pinocchio's explicit -w x v_l grew it by (1 + (w dt)^2)^(N/2))."""
    sim = gaussim.Simulator(gaussim.Scene(ball, gravity=(0, 0, 0)), gaussim.Options(dt=dt, scheme=scheme))
    state = sim.reset(ball.neutral(), np.array([3.0, 0, 0, 0, 30.0, 0]))
    energy = 0.5 * MASS * 9.0 + 0.5 * INERTIA * 900.0
    for k in range(1, round(1.0 / dt) + 1):
        state = sim.step(state)
        kinetic = 0.5 * MASS * state.v[:3] @ state.v[:3] + 0.5 * INERTIA * state.v[3:] @ state.v[3:]
        # exact in exact arithmetic: each step may round it by a few ulps (the explicit term's growth,
        # (1 + (w dt)^2)^(k / 2) - 1, is 4.5e-5 after 10 steps at dt 1e-4)
        assert kinetic <= energy * (1 + ROUNDING_ULPS * k * np.finfo(float).eps)
    momentum = MASS * world(state.q, state.v[:3])
    assert np.linalg.norm(momentum - [3.0, 0, 0]) / 3.0 < MOMENTUM_TOLERANCE
    np.testing.assert_allclose(state.q[:3], [3.0 * state.t, 0, 0], atol=1e-9 * state.t)


@pytest.mark.parametrize("scheme", SCHEMES)
@pytest.mark.parametrize("w0", [(0.01, 1.0, 0.01), (0.01, 5.0, 0.01)])
def test_a_torque_free_body_near_its_intermediate_axis_keeps_energy_and_momentum(top, scheme, w0):
    """Inertia (1, 2, 2.5), spun near the intermediate axis (the fast spin flips at 4.2 s), moving at
    (0.3, 0.2, 0.1) m/s, 5 s at dt 1e-3: energy, world angular and linear momentum kept (explicit
    gyroscopic terms drifted by 4e-3 at 5 rad/s)."""
    dt, duration = 1e-3, 5.0
    sim = gaussim.Simulator(gaussim.Scene(top, gravity=(0, 0, 0)), gaussim.Options(dt=dt, scheme=scheme))
    state = sim.reset(top.neutral(), np.array([0.3, 0.2, 0.1, *w0]))
    L0, energy = TOP_INERTIA @ state.v[3:], 0.5 * state.v[3:] @ TOP_INERTIA @ state.v[3:]
    p0 = state.v[:3].copy()
    for _ in range(round(duration / dt)):
        state = sim.step(state)
        L = world(state.q, TOP_INERTIA @ state.v[3:])
        assert np.linalg.norm(L - L0) / np.linalg.norm(L0) < CONSERVATION_TOLERANCE
        assert abs(0.5 * state.v[3:] @ TOP_INERTIA @ state.v[3:] / energy - 1) < CONSERVATION_TOLERANCE
        assert np.linalg.norm(world(state.q, state.v[:3]) - p0) < MOMENTUM_TOLERANCE


@pytest.mark.parametrize("w0", [(0.01, 1.0, 0.01), (0.01, 5.0, 0.01)])
def test_a_torque_free_body_follows_eulers_equations_to_second_order(top, w0):
    """The attitude after 5 s against DOP853 at rtol 1e-12 of Euler's equations: the error falls by 4
    when dt halves (the midpoint rule is second order), through the flip of the fast spin."""
    quaternions, _ = free_rotation(np.diag(TOP_INERTIA), np.array(w0), np.array([5.0]))
    reference = pin.Quaternion(quaternions[-1]).matrix()
    errors = []
    for dt in (2e-3, 1e-3):
        sim = gaussim.Simulator(gaussim.Scene(top, gravity=(0, 0, 0)), gaussim.Options(dt=dt))
        state = sim.reset(top.neutral(), np.array([0, 0, 0, *w0]))
        for _ in range(round(5.0 / dt)):
            state = sim.step(state)
        errors.append(np.linalg.norm(pin.log3(reference.T @ pin.Quaternion(state.q[3:7]).matrix())))
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.1)
    assert errors[1] < 1e-4  # [rad]


def _rolling(ball: gaussim.Robot, scheme: str, dt: float, normal: np.ndarray, mu: float, v0: float):
    scene = gaussim.Scene(ball, ground=gaussim.Ground(friction=mu, normal=tuple(normal)))
    sim = gaussim.Simulator(scene, gaussim.Options(dt=dt, scheme=scheme))
    q = ball.neutral()
    q[:3] = RADIUS * normal
    along = np.cross([0.0, 1.0, 0.0], normal)  # down the slope (x on flat ground)
    v = np.concatenate([v0 * along, v0 / RADIUS * np.array([0.0, 1.0, 0.0])])  # no slip
    return sim, sim.reset(q, v), q


@pytest.mark.parametrize("scheme", SCHEMES)
@pytest.mark.parametrize(("dt", "speed_tolerance", "depth"), [(1e-3, 1e-3, 1e-6), (1e-2, 1e-2, 1e-4)])
def test_a_ball_rolls_on_flat_ground_at_constant_speed(ball, scheme, dt, speed_tolerance, depth):
    """3 m/s rolling without slip, mu 0.8, 2 s: no force along the ground, so the speed is kept and
    the centre stays at r (the SE(3) exponential lowered it by v^2 dt^2 / (2 r) a step)."""
    normal = np.array([0.0, 0.0, 1.0])
    sim, state, _ = _rolling(ball, scheme, dt, normal, 0.8, 3.0)
    for _ in range(round(2.0 / dt)):
        state = sim.step(state)
        assert RADIUS - state.q[2] < depth
    assert abs(np.linalg.norm(world(state.q, state.v[:3])) / 3.0 - 1) < speed_tolerance
    np.testing.assert_allclose(state.q[0], 3.0 * state.t, rtol=speed_tolerance)


@pytest.mark.parametrize("scheme", SCHEMES)
@pytest.mark.parametrize(("dt", "tolerance"), [(1e-3, 5e-3), (1e-2, 5e-2)])
def test_a_ball_rolls_down_an_incline_as_the_closed_form_says(ball, scheme, dt, tolerance):
    """30 deg, mu 0.5 (it rolls: tan(30 deg) < 7/2 mu), from rest, 1 s: distance 5/14 g sin(theta) t^2;
    the centre stays on its support."""
    theta = np.radians(30.0)
    normal = np.array([-np.sin(theta), 0.0, np.cos(theta)])
    sim, state, q0 = _rolling(ball, scheme, dt, normal, 0.5, 0.0)
    for _ in range(round(1.0 / dt)):
        state = sim.step(state)
        assert RADIUS - (state.q[:3] @ normal) < 1e-6
    distance = float(np.linalg.norm(state.q[:3] - q0[:3]))
    assert distance == pytest.approx(5 / 14 * G * np.sin(theta) * state.t**2, rel=tolerance)


@pytest.mark.parametrize("scheme", SCHEMES)
@pytest.mark.parametrize(("dt", "tolerance"), [(1e-3, 5e-3), (1e-2, 5e-2)])
def test_a_cylinder_on_its_side_rolls_down_an_incline_as_the_closed_form_says(scheme, dt, tolerance):
    """A solid cylinder (r 0.1 m) lying across a 30 deg slope, mu 0.5 (it rolls: tan(30 deg) < 3 mu),
    from rest, 1 s: distance g sin(theta) t^2 / 3 (a = g sin(theta) / (1 + 1/2)), its axis on its
    support. At the acceleration level the drift of its contacts, read as points of the body, let it
    roll into the slope: 0.13 m at dt = 2e-2, 2.5 mm at 1e-3, its contact force gone."""
    theta, r = np.radians(30.0), 0.1
    normal = np.array([-np.sin(theta), 0.0, np.cos(theta)])
    cylinder = gaussim.FreeBody.cylinder("c", r, 0.3, mass=1.0)
    scene = gaussim.Scene(bodies={"c": cylinder}, ground=gaussim.Ground(friction=0.5, normal=tuple(normal)))
    sim = gaussim.Simulator(scene, gaussim.Options(dt=dt, scheme=scheme))
    start = r * normal
    state = sim.reset({"c": pin.SE3(pin.rpy.rpyToMatrix(np.pi / 2, 0.0, 0.0), start)})  # its axis along y
    for _ in range(round(1.0 / dt)):
        state = sim.step(state)
        assert abs(state.q[:3] @ normal - r) < 1e-6
    distance = float(np.linalg.norm(state.q[:3] - start))
    assert distance == pytest.approx(G * np.sin(theta) * state.t**2 / 3, rel=tolerance)
    force = sim.last_step.forces_between("c", "ground")
    assert force @ normal == pytest.approx(G * np.cos(theta), rel=1e-6)  # m g cos(theta), m = 1 kg
