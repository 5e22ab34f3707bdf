"""The reference scenes of the benchmark, each with an analytic reference and the error against it.

Every case runs for a fixed simulated time (shorter with ``quick``), whatever the time step, and
returns the :class:`~gaussim.bench.metrics.Recorder` summary plus ``error`` (its own, defined in
``ERRORS``) and the case's other measurements.
"""

from __future__ import annotations

import dataclasses
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..options import Options
from ..robot import ROBOTS_DIR, Robot, load_robot
from ..scene import Ground, Scene
from ..scenefile import load_scene
from ..simulator import Simulator
from ..state import State
from .metrics import Recorder

G = 9.81
SCENES_DIR = ROBOTS_DIR / "scenes"
BOX_HALF_HEIGHT = 0.05  # robots/box.urdf is 0.1 m high
BOX_SIDE = 0.2  # [m], the cubes of two_boxes
LANDING = 0.3  # [s] a standing robot's landing, before its measured window


def standing_window(quick: bool) -> float:
    """How long [s] a standing robot is measured after its landing."""
    return 0.2 if quick else 1.0


_FREE_BODY = """
  <joint name="{name}_joint" type="floating"><parent link="world"/><child link="{name}"/></joint>
  <link name="{name}">
    <inertial>
      <mass value="{mass}"/><inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/>
    </inertial>{collision}
  </link>"""


def free_bodies(
    path: Path, name: str, bodies: Sequence[tuple[str, float, Sequence[float], str | None]]
) -> Robot:
    """A robot of free bodies, each (name, mass [kg], principal inertia (3,) [kg m^2] about its origin,
    collision geometry as URDF XML or None), written as a URDF at ``path`` (each body's geometry is
    ``<name>_0``; its centre of mass is the origin of its floating joint)."""
    links = "".join(
        _FREE_BODY.format(
            name=body,
            mass=mass,
            ixx=inertia[0],
            iyy=inertia[1],
            izz=inertia[2],
            collision=""
            if geometry is None
            else f"\n    <collision><geometry>{geometry}</geometry></collision>",
        )
        for body, mass, inertia, geometry in bodies
    )
    path.write_text(f'<?xml version="1.0"?>\n<robot name="{name}"><link name="world"/>{links}\n</robot>\n')
    return load_robot(path)


def two_boxes(path: Path, bottom: float, top: float) -> Robot:
    """Two free cubes named bottom and top, of masses ``bottom`` and ``top`` [kg], written as a URDF
    at ``path`` (their collision geometries are bottom_0 and top_0)."""
    cube = f'<box size="{BOX_SIDE} {BOX_SIDE} {BOX_SIDE}"/>'
    cubes = [
        (body, mass, [mass * BOX_SIDE**2 / 6] * 3, cube) for body, mass in (("bottom", bottom), ("top", top))
    ]
    return free_bodies(path, "pair", cubes)


_ROD = """
  <joint name="{joint}" type="revolute"><parent link="{parent}"/><child link="{link}"/>
    <origin xyz="0 0 {z}"/><axis xyz="0 1 0"/>
    <limit lower="{lower}" upper="{upper}" effort="1000" velocity="10000"/></joint>
  <link name="{link}">
    <inertial><origin xyz="0 0 -0.25"/><mass value="{mass}"/>
      <inertia ixx="{i}" ixy="0" ixz="0" iyy="{i}" iyz="0" izz="{i_axial}"/></inertial>
    <collision><origin xyz="0 0 -0.25"/>
      <geometry><cylinder radius="0.02" length="0.5"/></geometry></collision>
  </link>"""


def arm(path: Path, masses: tuple[float, float], elbow: tuple[float, float]) -> Robot:
    """A two-link arm, two 0.5 m rods of ``masses`` [kg] hinged about y from a pivot 2 m up (q = 0
    hangs straight down), the shoulder free and the elbow within ``elbow`` [rad], written as a URDF
    at ``path``; its tip frame is ``tip``."""
    rods = "".join(
        _ROD.format(
            joint=joint,
            parent=parent,
            link=link,
            z=z,
            mass=mass,
            i=mass * 0.25 / 12,
            i_axial=mass * 2e-4,
            lower=lower,
            upper=upper,
        )
        for joint, parent, link, z, mass, (lower, upper) in (
            ("shoulder", "base", "upper", 2.0, masses[0], (-10.0, 10.0)),
            ("elbow", "upper", "lower", -0.5, masses[1], elbow),
        )
    )
    tip = (
        '<joint name="tip" type="fixed"><parent link="lower"/><child link="tip"/>'
        '<origin xyz="0 0 -0.5"/></joint><link name="tip"/>'
    )
    path.write_text(f'<?xml version="1.0"?>\n<robot name="arm"><link name="base"/>{rods}{tip}\n</robot>\n')
    return load_robot(path)


@dataclass(frozen=True)
class Case:
    """A reference scene: ``run(options, quick)`` returns its metrics; ``error`` says what the
    ``error`` metric measures."""

    name: str
    error: str
    run: Callable[[Options, bool], dict[str, float]]


def _recorder(scene: Scene, options: Options) -> tuple[Simulator, Recorder]:
    sim = Simulator(scene, options)
    return sim, Recorder(sim)


def _ball(restitution: float) -> Callable[[Options, bool], dict[str, float]]:
    def run(options: Options, quick: bool) -> dict[str, float]:
        ball = load_robot("ball", floating_base=True)
        sim, rec = _recorder(Scene(ball, ground=Ground(friction=0.8, restitution=restitution)), options)
        height = 1.0
        q = ball.neutral()
        radius = q[2] = _ball_radius(ball)
        q[2] += height
        state = sim.reset(q)
        if restitution == 0:  # drop, then rest: the error is the resting penetration
            state = rec.run(state, 1.0 if quick else 2.0)
            metrics = rec.summary()
            return {**metrics, "error": max(0.0, radius - state.q[2])}
        apex = rebound_apex(rec.step, state, radius, 2.0)  # bounce: the first rebound against e^2 h
        return {**rec.summary(), "error": abs(apex - restitution**2 * height), "apex": apex}

    return run


def rebound_apex(step: Callable[[State], State], state: State, radius: float, until: float) -> float:
    """The height of a falling ball's (``radius``) lowest point at the top of its first rebound,
    stepping with ``step`` until then or until the time ``until`` [s] (-inf when it never rises)."""
    apex, rising = -np.inf, False
    while state.t < until:
        state = step(state)
        rising = rising or state.v[2] > 0
        if rising:
            apex = max(apex, state.q[2] - radius)
            if state.v[2] < 0:
                break
    return apex


def _ball_radius(ball: Robot) -> float:
    geometry = ball.collision_model.geometryObjects[0].geometry
    return float(geometry.radius)


def _sliding(heading_deg: float, mu: float = 0.5) -> Callable[[Options, bool], dict[str, float]]:
    def run(options: Options, quick: bool) -> dict[str, float]:
        box = load_robot("box", floating_base=True)
        sim, rec = _recorder(Scene(box, ground=Ground(friction=mu)), options)
        heading = np.radians(heading_deg)
        q = box.neutral()
        q[2] = BOX_HALF_HEIGHT
        state = sim.reset(q, np.array([np.cos(heading), np.sin(heading), 0, 0, 0, 0]))
        lift = 0.0
        for _ in range(round(0.4 / options.dt)):  # it stops after 1 / (mu g) = 0.2 s
            state = rec.step(state)
            lift = max(lift, abs(state.q[2] - BOX_HALF_HEIGHT))
        reference = 1.0 / (2 * mu * G)
        distance = float(np.linalg.norm(state.q[:2]))
        drift = abs(float(np.arctan2(state.q[1], state.q[0])) - heading)
        return {**rec.summary(), "error": abs(distance / reference - 1), "heading_drift": drift, "lift": lift}

    return run


def on_incline(theta: float, height: float) -> tuple[np.ndarray, np.ndarray]:
    """The normal (3,) of an incline of ``theta`` [rad] through the origin (it falls toward -x) and
    the free-flyer configuration (7,) of a body resting on it whose origin is ``height`` [m] above
    its lowest face, that face on the incline."""
    normal = np.array([-np.sin(theta), 0.0, np.cos(theta)])
    q = np.concatenate([height * normal, pin.Quaternion(pin.rpy.rpyToMatrix(0, -theta, 0)).coeffs()])
    return normal, q


def _incline(offset: float, mu: float = 0.5) -> Callable[[Options, bool], dict[str, float]]:
    """A block on an incline of slope mu + offset: it must stick (offset < 0) or slide at
    g (sin - mu cos)."""

    def run(options: Options, quick: bool) -> dict[str, float]:
        box = load_robot("box", floating_base=True)
        theta = np.arctan(mu + offset)
        normal, q = on_incline(theta, BOX_HALF_HEIGHT)
        sim, rec = _recorder(Scene(box, ground=Ground(friction=mu, normal=tuple(normal))), options)
        state = rec.run(sim.reset(q), 0.5 if quick else 1.0)
        travel = float(np.linalg.norm(state.q[:3] - q[:3]))
        if offset < 0:  # sticks: any travel is creep
            return {**rec.summary(), "error": travel, "decided_right": float(travel < 1e-4)}
        expected = 0.5 * G * (np.sin(theta) - mu * np.cos(theta)) * state.t**2
        error = abs(travel / expected - 1)
        return {**rec.summary(), "error": error, "decided_right": float(error < 0.5)}

    return run


def _scene_file(
    name: str, measure: Callable[..., dict[str, float]]
) -> Callable[[Options, bool], dict[str, float]]:
    """A shipped scene file run with the benchmark's options (its own options are the defaults)."""

    def run(options: Options, quick: bool) -> dict[str, float]:
        spec = load_scene(SCENES_DIR / f"{name}.toml")
        sim, rec = _recorder(spec.scene, options)
        return measure(spec, sim, rec, quick)

    return run


# Where a case has no analytic trajectory, its reference is gaussim itself at a sixteenth of the
# default time step with a tight ProxQP tolerance (self-consistency), compared at REFERENCE_TIME.
REFERENCE_DIVISOR = 16
REFERENCE_EPS = 1e-12
REFERENCE_TIME = 1.0  # [s]


@cache
def self_reference(scene: str) -> np.ndarray:
    """The configuration at REFERENCE_TIME of the shipped scene file ``scene`` (run without its
    controller: the cases that use this have none) simulated by gaussim at the default dt /
    REFERENCE_DIVISOR and eps_abs REFERENCE_EPS."""
    spec = load_scene(SCENES_DIR / f"{scene}.toml")
    options = options_with(dt=Options().dt / REFERENCE_DIVISOR, eps_abs=REFERENCE_EPS)
    sim = Simulator(spec.scene, options)
    state = sim.reset(spec.initial.q, spec.initial.v)
    for _ in range(round(REFERENCE_TIME / options.dt)):
        state = sim.step(state)
    return state.q


def _trajectory(spec, sim, rec, quick, measure) -> dict[str, float]:  # type: ignore[no-untyped-def]
    """Run a scene file for 1 s (``quick``) or 10 s, calling ``measure(state)`` after each step; the
    summary plus ``trajectory_error``, |q (-) q_reference| at REFERENCE_TIME against
    :func:`self_reference`, and ``energy_gain``, the largest rise of the mechanical energy above its
    initial value, relative to the largest kinetic energy of the run."""
    model, data = sim.model, sim.model.createData()
    name = Path(spec.path).stem
    state = sim.reset(spec.initial.q, spec.initial.v)
    energy = pin.computeMechanicalEnergy(model, data, state.q, state.v)
    gain, error, kinetic = 0.0, np.nan, 0.0
    for _ in range(round((1.0 if quick else 10.0) / sim.options.dt)):
        state = rec.step(state)
        measure(state)
        gain = max(gain, pin.computeMechanicalEnergy(model, data, state.q, state.v) - energy)
        kinetic = max(kinetic, data.kinetic_energy)
        if abs(state.t - REFERENCE_TIME) < sim.options.dt / 2:
            error = float(np.linalg.norm(pin.difference(model, self_reference(name), state.q)))
    return {**rec.summary(), "trajectory_error": error, "energy_gain": gain / max(kinetic, 1e-12)}


def _pendulum_limits(spec, sim, rec, quick) -> dict[str, float]:  # type: ignore[no-untyped-def]
    model = spec.robot.model
    lower, upper = model.lowerPositionLimit[0], model.upperPositionLimit[0]
    violation = [0.0]

    def measure(state: State) -> None:
        violation[0] = max(violation[0], state.q[0] - upper, lower - state.q[0])

    return {**_trajectory(spec, sim, rec, quick, measure), "error": violation[0]}


def _fourbar(spec, sim, rec, quick) -> dict[str, float]:  # type: ignore[no-untyped-def]
    model = spec.robot.model
    data = model.createData()
    tip, anchor = model.getFrameId("tip"), model.getFrameId("anchor")
    drift = [0.0]

    def measure(state: State) -> None:
        pin.framesForwardKinematics(model, data, state.q)
        gap = float(np.linalg.norm(data.oMf[tip].translation - data.oMf[anchor].translation))
        drift[0] = max(drift[0], gap)

    return {**_trajectory(spec, sim, rec, quick, measure), "error": drift[0]}


def _standing(spec, sim, rec, quick) -> dict[str, float]:  # type: ignore[no-untyped-def]
    """A legged robot standing under its PD hold: LANDING seconds, then a window of 1 s (0.2 s with
    ``quick``): the contact forces' vertical sum against m g at the end, the largest horizontal
    displacement over the window of a material point that touched at its start, per second, the
    deepest penetration in it."""
    state = sim.reset(spec.initial.q, spec.initial.v)
    state = rec.run(state, LANDING, spec.controller)
    # the contact points, and where they are on their bodies: a foot that rocks or rolls does not slip
    robot, data = spec.robot, spec.robot.model.createData()
    pin.forwardKinematics(robot.model, data, state.q)
    touching = [
        (c.point, robot.collision_model.geometryObjects[robot.geometry_id(c.geometry)].parentJoint)
        for c in sim.last_step.contacts
    ]
    local = [(joint, data.oMi[joint].actInv(point)) for point, joint in touching]
    seconds = standing_window(quick)
    standing = 0.0  # the deepest penetration in the window
    for _ in range(max(1, round(seconds / sim.options.dt))):
        state = rec.step(state, spec.controller)
        standing = max(standing, max((-c.gap for c in sim.last_step.contacts), default=0.0))
    weight = spec.robot.mass * G
    total = sim.last_step.total_contact_force()
    pin.forwardKinematics(robot.model, data, state.q)
    moved = [data.oMi[joint].act(point) - start for (joint, point), (start, _) in zip(local, touching)]
    slip = max((float(np.linalg.norm(d[:2])) for d in moved), default=0.0) / seconds
    return {
        **rec.summary(),
        "error": abs(total[2] - weight) / weight,
        "slip_per_s": slip,
        "standing_penetration": standing,
    }


def _stack(ratio: float) -> Callable[[Options, bool], dict[str, float]]:
    """A light box (1 kg) under a heavy one (``ratio`` kg), 0.2 m cubes resting: penetration and
    sinking of the top box after 0.5 s."""

    def run(options: Options, quick: bool) -> dict[str, float]:
        with tempfile.TemporaryDirectory() as folder:
            robot = two_boxes(Path(folder) / "pair.urdf", 1.0, ratio)
        contacts = [("bottom_0", "ground"), ("top_0", "bottom_0")]
        sim, rec = _recorder(Scene(robot, ground=Ground(friction=0.8), contacts=contacts), options)
        side = BOX_SIDE
        q = robot.neutral()
        q[2], q[9] = side / 2, 1.5 * side
        state = rec.run(sim.reset(q), 0.5)
        settled = state.q[9]
        state = rec.run(state, 0.5 if quick else 2.0)
        penetration = max(rec.penetration, side - (state.q[9] - state.q[2]))
        return {**rec.summary(), "error": penetration, "sinking": abs(state.q[9] - settled)}

    return run


def _world_velocity(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The world velocity [m/s] of a free body's origin from its free-flyer q (7,) and v (6,):
    Pinocchio's v[:3] is in the body frame."""
    return pin.XYZQUATToSE3(q[:7]).rotation @ v[:3]


def rolling_velocity(speed: float, radius: float, direction: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """The free-flyer velocity (6,) of a ball of ``radius`` [m] at the identity orientation rolling
    without slip at ``speed`` [m/s] along the unit ``direction`` on a plane of unit ``normal``: its
    contact point, at -radius normal from the centre, is at rest (w x (-r n) = -v)."""
    linear = speed * np.asarray(direction, dtype=float)
    return np.concatenate([linear, np.cross(normal, linear) / radius])


def _rolling_flat(options: Options, quick: bool) -> dict[str, float]:
    """A ball rolling without slip at 3 m/s on flat ground (mu 0.8) for 2 s: rolling is free motion
    under the contact (no rolling resistance), so its speed must stay; ``slip_speed`` [m/s] is its
    contact point's at the end, the summary's ``penetration`` how deep it sank."""
    ball = load_robot("ball", floating_base=True)
    sim, rec = _recorder(Scene(ball, ground=Ground(friction=0.8)), options)
    radius, speed, normal = _ball_radius(ball), 3.0, np.array([0.0, 0.0, 1.0])
    q = ball.neutral()
    q[2] = radius
    state = rec.run(
        sim.reset(q, rolling_velocity(speed, radius, np.array([1.0, 0, 0]), normal)), 0.5 if quick else 2.0
    )
    R = pin.XYZQUATToSE3(state.q[:7]).rotation
    centre = R @ state.v[:3]
    slip = centre + np.cross(R @ state.v[3:], -radius * normal)
    return {
        **rec.summary(),
        "error": abs(float(np.linalg.norm(centre)) / speed - 1),
        "slip_speed": float(np.linalg.norm(slip)),
    }


INCLINE_DEG = 30.0


def _rolling_incline(options: Options, quick: bool) -> dict[str, float]:
    """A ball released from rest on a 30 degree incline (the ground's normal tilted, as the block's
    incline), mu 0.5: it rolls without slip (the friction it needs is 2/7 tan(theta) < mu) and travels
    5/14 g sin(theta) t^2."""
    ball = load_robot("ball", floating_base=True)
    theta = np.radians(INCLINE_DEG)
    normal, q = on_incline(theta, _ball_radius(ball))
    sim, rec = _recorder(Scene(ball, ground=Ground(friction=0.5, normal=tuple(normal))), options)
    state = rec.run(sim.reset(q), 0.5 if quick else 1.0)
    travel = float(np.linalg.norm(state.q[:3] - q[:3]))
    return {**rec.summary(), "error": abs(travel / rolling_travel(theta, state.t) - 1), "travel": travel}


def rolling_travel(theta: float, t: float) -> float:
    """How far [m] a solid ball rolling without slip down an incline of ``theta`` [rad] goes from rest
    in ``t`` [s]: its acceleration is g sin(theta) / (1 + I / (m r^2)) = 5/7 g sin(theta)."""
    return 5 / 14 * G * np.sin(theta) * t**2


ODE_TOLERANCE = 1e-12  # rtol = atol of the ODE references


def dop853(rhs: Callable[[float, np.ndarray], np.ndarray], y0: np.ndarray, times: np.ndarray) -> np.ndarray:
    """The states (n, len(y0)) at ``times`` (n,) [s] of y' = rhs(t, y) from y(0) = ``y0``, integrated by
    scipy's DOP853 at rtol = atol = ODE_TOLERANCE (scipy comes with ``pip install -e '.[bench]'``)."""
    try:
        from scipy.integrate import solve_ivp
    except ImportError as err:
        raise ImportError(
            "the ODE references of gaussim.bench need scipy: pip install -e '.[bench]'"
        ) from err
    solution = solve_ivp(
        rhs, (0.0, times[-1]), y0, method="DOP853", t_eval=times, rtol=ODE_TOLERANCE, atol=ODE_TOLERANCE
    )
    if not solution.success:
        raise RuntimeError(f"the DOP853 reference failed: {solution.message}")
    return solution.y.T


def _spinning_free(options: Options, quick: bool) -> dict[str, float]:
    """A ball in zero gravity, no ground, moving at 3 m/s along x and spinning at 30 rad/s about z:
    its world momentum and its kinetic energy must stay (the largest relative changes over 1 s)."""
    ball = load_robot("ball", floating_base=True)
    sim, rec = _recorder(Scene(ball, gravity=(0.0, 0.0, 0.0)), options)
    model, data = sim.model, sim.model.createData()
    velocity = np.array([3.0, 0, 0])
    state = sim.reset(ball.neutral(), np.array([*velocity, 0, 0, 30.0]))
    energy = pin.computeKineticEnergy(model, data, state.q, state.v)
    momentum = energy_change = 0.0
    for _ in range(round((0.2 if quick else 1.0) / options.dt)):
        state = rec.step(state)
        momentum = max(momentum, float(np.linalg.norm(_world_velocity(state.q, state.v) - velocity)))
        change = pin.computeKineticEnergy(model, data, state.q, state.v) / energy - 1
        energy_change = max(energy_change, abs(change))
    return {
        **rec.summary(),
        "error": momentum / float(np.linalg.norm(velocity)),
        "energy_change": energy_change,
    }


# The torque-free body of intermediate_axis: its principal inertia [kg m^2] (mass 1 kg).
PRINCIPAL_INERTIA = (1.0, 2.0, 2.5)


def free_rotation(
    inertia: Sequence[float] | np.ndarray, w0: np.ndarray, times: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The torque-free rotation of a rigid body of principal ``inertia`` (3,) [kg m^2] from the
    identity with body angular velocity ``w0`` (3,) [rad/s]: its quaternions (x, y, z, w) and body
    angular velocities at ``times`` (n,) [s], shapes (n, 4) and (n, 3), from Euler's equations
    I w' = -w x I w and q' = q (x) (w, 0) / 2 integrated by :func:`dop853`."""
    I = np.asarray(inertia, dtype=float)

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        w, vector, scalar = y[:3], y[3:6], y[6]
        return np.concatenate(
            [-np.cross(w, I * w) / I, (scalar * w + np.cross(vector, w)) / 2, [-vector @ w / 2]]
        )

    y0 = np.concatenate([w0, [0.0, 0.0, 0.0, 1.0]])
    states = dop853(rhs, y0, times)
    return states[:, 3:], states[:, :3]


def _intermediate_axis(w0: tuple[float, float, float]) -> Callable[[Options, bool], dict[str, float]]:
    """A torque-free body (PRINCIPAL_INERTIA, its centre of mass at its joint) in zero gravity spinning
    near its intermediate axis from ``w0`` [rad/s] (body frame), 5 s (1 s with ``quick``), against
    :func:`free_rotation`: ``error`` is the attitude error [rad] at the end, with the relative error
    of the angular velocity there and the largest relative energy and world angular momentum drifts."""

    def run(options: Options, quick: bool) -> dict[str, float]:
        with tempfile.TemporaryDirectory() as folder:
            body = free_bodies(Path(folder) / "body.urdf", "body", [("body", 1.0, PRINCIPAL_INERTIA, None)])
        sim, rec = _recorder(Scene(body, gravity=(0.0, 0.0, 0.0)), options)
        I, w = np.array(PRINCIPAL_INERTIA), np.array(w0)
        state = sim.reset(body.neutral(), np.array([0, 0, 0, *w]))
        energy, momentum = w @ (I * w) / 2, I * w
        energy_drift = momentum_drift = 0.0
        for _ in range(round((1.0 if quick else 5.0) / options.dt)):
            state = rec.step(state)
            w = state.v[3:]
            energy_drift = max(energy_drift, abs(w @ (I * w) / 2 / energy - 1))
            world = pin.XYZQUATToSE3(state.q).rotation @ (I * w)
            momentum_drift = max(
                momentum_drift, float(np.linalg.norm(world - momentum) / np.linalg.norm(momentum))
            )
        quaternions, omegas = free_rotation(I, np.array(w0), np.array([0.0, state.t]))
        R = pin.Quaternion(quaternions[-1]).matrix()
        attitude = float(np.linalg.norm(pin.log3(R.T @ pin.XYZQUATToSE3(state.q).rotation)))
        return {
            **rec.summary(),
            "error": attitude,
            "omega_error": float(np.linalg.norm(w - omegas[-1]) / np.linalg.norm(omegas[-1])),
            "energy_drift": energy_drift,
            "momentum_drift": momentum_drift,
        }

    return run


CRADLE_REFERENCE = (-1 / 3, 2 / 3, 2 / 3)  # [m/s]


def _newtons_cradle(options: Options, quick: bool) -> dict[str, float]:
    """Three equal balls (robots/ball.urdf's) touching in a row along x, zero gravity, frictionless
    contacts with e = 1, the first at 1 m/s toward the others; after 0.2 s their velocities against
    CRADLE_REFERENCE, ``error`` the largest [m/s], with the relative momentum and energy errors.

    The reference is Moreau's simultaneous impact, the answer of a time-stepping scheme: both contacts
    are closed in the step of the impact, so one impulsive Gauss problem with Newton's law
    J v+ >= -e J v- on each (the far contact has J v- = 0) gives (-1/3, 2/3, 2/3), keeping momentum and
    energy. A real cradle gives (0, 0, 1): its impacts run in sequence, as elastic waves through the
    balls, which a rigid simultaneous-impact law does not model (with gaps wider than |v| dt the
    scheme also meets them in sequence).
    """
    ball = load_robot("ball", floating_base=True)
    radius, mass = _ball_radius(ball), ball.mass
    inertia = ball.model.inertias[1].inertia.diagonal()
    sphere = f'<sphere radius="{radius}"/>'
    with tempfile.TemporaryDirectory() as folder:
        robot = free_bodies(
            Path(folder) / "cradle.urdf", "cradle", [(b, mass, inertia, sphere) for b in "abc"]
        )
    contacts = [("a_0", "b_0"), ("b_0", "c_0")]
    scene = Scene(robot, contacts=contacts, gravity=(0.0, 0.0, 0.0), self_contact=(0.0, 1.0))
    sim, rec = _recorder(scene, options)
    q, v = robot.neutral(), np.zeros(robot.model.nv)
    q[[0, 7, 14]] = 0.0, 2 * radius, 4 * radius
    v[0] = 1.0
    state = rec.run(sim.reset(q, v), 0.2)
    velocities = np.array([_world_velocity(state.q[7 * k :], state.v[6 * k :]) for k in range(3)])
    reference = np.array([[u, 0.0, 0.0] for u in CRADLE_REFERENCE])
    energy = pin.computeKineticEnergy(sim.model, sim.model.createData(), state.q, state.v)
    return {
        **rec.summary(),
        "error": float(np.abs(velocities - reference).max()),
        "momentum_error": float(np.linalg.norm(mass * velocities.sum(axis=0) - [mass, 0, 0]) / mass),
        "energy_error": abs(energy / (mass / 2) - 1),
    }


TALL_BOX = (0.1, 0.4)  # [m] the tipping box's width (x and y) and height (z)
TIPPED = 0.2  # [rad] the tilt from the incline's normal at which a box has tipped


def tipping_angle(width: float, height: float) -> float:
    """The incline [rad] beyond which a box of ``width`` and ``height`` [m] standing on it (with the
    friction to stick) tips over its lower edge: there its centre of mass passes over that edge,
    tan(theta) = width / height."""
    return float(np.arctan(width / height))


def _tipping(options: Options, quick: bool) -> dict[str, float]:
    """A 0.1 x 0.1 x 0.4 m box (1 kg) at rest on an incline (mu 1, more than the tan(theta) it needs
    to stick), the incline found by bisection on [0.5, 1.5] times :func:`tipping_angle` at which it
    tips (its tilt passes TIPPED within 2 s): ``error`` is that angle's relative error, its floor the
    bisection's resolution 1/2048 (10 halvings; 1/128, 6, with ``quick``), which it reaches when every
    run is decided right; the metrics are those of all the runs."""
    width, height = TALL_BOX
    inertia = [(width**2 + height**2) / 12] * 2 + [width**2 / 6]
    with tempfile.TemporaryDirectory() as folder:
        box = free_bodies(
            Path(folder) / "tall.urdf",
            "tall",
            [("tall", 1.0, inertia, f'<box size="{width} {width} {height}"/>')],
        )
    recorders = []

    def tips(theta: float) -> bool:
        normal, q = on_incline(theta, height / 2)
        sim, rec = _recorder(Scene(box, ground=Ground(friction=1.0, normal=tuple(normal))), options)
        recorders.append(rec)
        state = sim.reset(q)
        for _ in range(round(2.0 / options.dt)):
            state = rec.step(state)
            axis = pin.XYZQUATToSE3(state.q).rotation[:, 2]
            if np.arccos(min(1.0, float(axis @ normal))) > TIPPED:
                return True
        return False

    expected = tipping_angle(width, height)
    low, high = 0.5 * expected, 1.5 * expected
    for _ in range(6 if quick else 10):
        middle = (low + high) / 2
        low, high = (low, middle) if tips(middle) else (middle, high)
    found = (low + high) / 2
    first, *others = recorders
    for rec in others:
        first.absorb(rec)
    return {**first.summary(), "error": abs(found / expected - 1), "threshold_deg": float(np.degrees(found))}


PENDULUM_START = (1.2, -0.6, 0.0, 2.0)  # (q1, q2 [rad], v1, v2 [rad/s]) of double_pendulum


def pendulum_reference(
    model: pin.Model, start: Sequence[float] | np.ndarray, times: np.ndarray
) -> np.ndarray:
    """The joint angles and velocities (n, 4) [rad, rad/s] at ``times`` (n,) [s] of
    robots/double_pendulum.urdf's ``model`` (continuous joints: q holds (cos, sin) per joint) from the
    angles and velocities ``start`` (4,):
    Pinocchio's ``aba`` (M(q) a = -b(q, v)) integrated by :func:`dop853`."""
    return dop853(pendulum_rhs(model), np.asarray(start, dtype=float), times)


def pendulum_rhs(model: pin.Model) -> Callable[[float, np.ndarray], np.ndarray]:
    """d/dt (angles, velocities) of the double pendulum ``model`` by Pinocchio's ``aba``."""
    data = model.createData()
    zero = np.zeros(2)

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        return np.concatenate([y[2:], pin.aba(model, data, angles_to_q(y[:2]), y[2:], zero)])

    return rhs


def angles_to_q(angles: np.ndarray) -> np.ndarray:
    """The configuration (cos, sin per joint) of continuous joints at ``angles`` [rad]."""
    return np.column_stack([np.cos(angles), np.sin(angles)]).ravel()


def _double_pendulum(options: Options, quick: bool) -> dict[str, float]:
    """robots/double_pendulum.urdf, no contacts or limits, from PENDULUM_START for 2 s (0.5 s with
    ``quick``) against :func:`pendulum_reference`: ``error`` is the RMS joint angle error [rad] over
    the steps, ``energy_drift`` the largest change of the mechanical energy relative to the largest
    kinetic energy of the reference."""
    robot = load_robot("double_pendulum")
    sim, rec = _recorder(Scene(robot), options)
    model, data = sim.model, sim.model.createData()
    start = np.array(PENDULUM_START)
    state = sim.reset(angles_to_q(start[:2]), start[2:])
    energy = pin.computeMechanicalEnergy(model, data, state.q, state.v)
    configurations, drift = [], 0.0
    for _ in range(round((0.5 if quick else 2.0) / options.dt)):
        state = rec.step(state)
        configurations.append(state.q)
        drift = max(drift, abs(pin.computeMechanicalEnergy(model, data, state.q, state.v) - energy))
    times = options.dt * np.arange(1, len(configurations) + 1)
    reference = pendulum_reference(model, start, times)
    errors = [pin.difference(model, angles_to_q(r[:2]), q) for r, q in zip(reference, configurations)]
    kinetic = max(pin.computeKineticEnergy(model, data, angles_to_q(r[:2]), r[2:]) for r in reference)
    return {
        **rec.summary(),
        "error": float(np.sqrt(np.mean(np.square(errors)))),
        "energy_drift": drift / kinetic,
    }


CASES: dict[str, Case] = {
    case.name: case
    for case in [
        Case("ball_rest", "resting penetration [m]", _ball(0.0)),
        Case("ball_bounce", "|apex - e^2 h| [m], e = 0.5, h = 1 m", _ball(0.5)),
        *(
            Case(f"sliding_{h}", f"relative error of the stopping distance, heading {h} deg", _sliding(h))
            for h in (0, 15, 30, 45)
        ),
        Case("incline_stick", "creep [m] at mu = tan(theta) + 0.01", _incline(-0.01)),
        Case("incline_slide", "relative error of the travel at mu = tan(theta) - 0.01", _incline(0.01)),
        Case(
            "pendulum_limits",
            "largest limit violation [rad]",
            _scene_file("pendulum_limits", _pendulum_limits),
        ),
        Case("fourbar", "largest loop-closure drift [m]", _scene_file("fourbar", _fourbar)),
        *(
            Case(f"stack_{r:g}", f"largest penetration [m], 1 kg under {r:g} kg", _stack(r))
            for r in (1, 10, 100, 1000)
        ),
        Case("solo12", "|sum f_z - m g| / m g", _scene_file("solo12_standing", _standing)),
        Case("talos", "|sum f_z - m g| / m g", _scene_file("talos_standing", _standing)),
        Case(
            "rolling_flat", "relative speed change of a ball rolling at 3 m/s for 2 s, mu 0.8", _rolling_flat
        ),
        Case(
            "rolling_incline",
            "relative error of a rolling ball's travel against 5/14 g sin(theta) t^2, 30 deg, mu 0.5",
            _rolling_incline,
        ),
        Case("spinning_free", "largest relative world momentum error, 3 m/s, 30 rad/s spin", _spinning_free),
        Case(
            "intermediate_axis",
            "attitude error [rad] at 5 s against DOP853, I = (1, 2, 2.5), w0 = (0.01, 1, 0.01) rad/s",
            _intermediate_axis((0.01, 1.0, 0.01)),
        ),
        Case(
            "intermediate_axis_fast",
            "attitude error [rad] at 5 s against DOP853, I = (1, 2, 2.5), w0 = (0.01, 5, 0.01) rad/s"
            " (it flips at 4.2 s)",
            _intermediate_axis((0.01, 5.0, 0.01)),
        ),
        Case("newtons_cradle", "largest velocity error [m/s] against (-1/3, 2/3, 2/3)", _newtons_cradle),
        Case("tipping", "relative error of the tipping incline, tan(theta) = 0.1 / 0.4", _tipping),
        Case(
            "double_pendulum", "RMS joint angle error [rad] over 2 s against DOP853 of aba", _double_pendulum
        ),
    ]
}
QUICK_CASES = ("ball_rest", "ball_bounce", "sliding_30", "incline_stick", "stack_100", "solo12")


def options_with(**knobs: object) -> Options:
    """Default options with ``knobs`` changed (validated by Options)."""
    return dataclasses.replace(Options(), **knobs)  # type: ignore[arg-type]
