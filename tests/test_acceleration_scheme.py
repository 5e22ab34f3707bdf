"""The acceleration scheme (Options(scheme="acceleration")) against closed forms: impacts with
restitution from any starting gap, Coulomb's law while sliding, the stop of a sliding block."""

import numpy as np
import pinocchio as pin
import pytest

import gaussim
from gaussim.bench.metrics import Recorder

from .conftest import G, at_height, frame_acceleration, step_velocity

RADIUS = 0.1  # robots/ball.urdf [m]
BOX_HALF_HEIGHT = 0.05  # robots/box.urdf [m]
STICK_SPEED = 1e-6  # [m/s]
RESTITUTION_RTOL = 1e-6  # the impulse is a QP's answer, to ProxQP's tolerance
MOREAU_ATOL = 1e-6  # [m/s]
COULOMB_RTOL = 1e-6  # f_t = mu f_n while sliding
ROD_INERTIA = 0.08333  # [kg m^2], about the rod's centre, across it
TIP_RADIUS = 0.01  # [m]
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
    sim, state = _cradle(cradle_balls, dt, (-2 * RADIUS - gap, 0.0, 2 * RADIUS))
    for _ in range(int(gap / dt) + 10):
        state = sim.step(state)
    speeds = state.v[[0, 6, 12]]
    np.testing.assert_allclose(speeds, [-1 / 3, 2 / 3, 2 / 3], atol=MOREAU_ATOL)
    assert speeds.sum() == pytest.approx(1.0, abs=MOREAU_ATOL)
    assert speeds @ speeds == pytest.approx(1.0, abs=MOREAU_ATOL)
    np.testing.assert_allclose(np.delete(state.v, [0, 6, 12]), 0.0, atol=1e-12)


@pytest.mark.parametrize("gap", [0.1e-3, 0.5e-3, 0.9e-3])
def test_an_impact_that_sets_a_contact_approaching_is_projected_again(cradle_balls, gap):
    """The balls of the cradle apart, the second ``gap`` from the third, less than a step's travel:
    the first impact sends the second ball at the third within the step, and that second approach is
    an impact too: elastic balls pass the whole velocity on, (0, 0, 1). (Left to the acceleration
    level's Baumgarte rows it ended (0, 0.19, 0.81), a third of the energy lost.)"""
    dt = 1e-3
    sim, state = _cradle(cradle_balls, dt, (-2 * RADIUS - 0.3e-3, 0.0, 2 * RADIUS + gap))
    for _ in range(10):
        state = sim.step(state)
    np.testing.assert_allclose(state.v[[0, 6, 12]], [0.0, 0.0, 1.0], atol=MOREAU_ATOL)


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


_ROD = f"""<?xml version="1.0"?>
<robot name="rod"><link name="world"/>
  <joint name="rod_joint" type="floating"><parent link="world"/><child link="rod"/></joint>
  <link name="rod">
    <inertial><mass value="1"/>
      <inertia ixx="1e-4" ixy="0" ixz="0" iyy="{ROD_INERTIA}" iyz="0" izz="{ROD_INERTIA}"/></inertial>
    <collision><origin xyz="0.5 0 0"/><geometry><sphere radius="{TIP_RADIUS}"/></geometry></collision>
  </link>
</robot>
"""


@pytest.fixture(scope="module")
def rod(tmp_path_factory) -> gaussim.Robot:
    """A free 1 kg, 1 m rod along its x axis with a small ball at its +x tip."""
    path = tmp_path_factory.mktemp("rod") / "rod.urdf"
    path.write_text(_ROD)
    return gaussim.load_robot(path)


def _sliding_rod(rod, slip, iterations=10):
    """The rod at 45 degrees, its tip on a mu = 1 ground, translating at ``slip`` m/s along x."""
    mu, theta = 1.0, np.pi / 4
    options = gaussim.Options(scheme="acceleration", friction_iterations=iterations)
    sim = gaussim.Simulator(gaussim.Scene(rod, ground=gaussim.Ground(friction=mu)), options)
    R = pin.rpy.rpyToMatrix(0, theta, 0)  # the tip down, at 0.5 (cos, 0, -sin) theta from the centre
    q = rod.neutral()
    q[2], q[3:7] = 0.5 * np.sin(theta) + TIP_RADIUS, pin.Quaternion(R).coeffs()
    v = np.zeros(6)
    v[:3] = R.T @ np.array([slip, 0.0, 0.0])  # the free flyer's velocity is in its own frame
    return sim, sim.reset(q, v), mu, theta


@pytest.mark.parametrize("slip", [1.0, -1.0])
def test_a_sliding_rod_meets_coulombs_law(rod, slip):
    """A rod at 45 degrees sliding on its tip with mu = 1 (the friction's moment loads the normal
    row: the lagged iteration's slope is 0.6, it stopped at f_t / f_n = 0.9955 after its 10 QPs):
    every step has f_t = mu f_n, against the slip, and the first (at rest in rotation: no drift) the
    normal force of the rigid rod, m g / (1 + m r_x^2 / I + sign(slip) mu m r_x r_z / I) for the
    contact point r from the centre."""
    sim, state, mu, theta = _sliding_rod(rod, slip)
    r_x, r_z = 0.5 * np.cos(theta), -0.5 * np.sin(theta) - TIP_RADIUS
    normal = G / (1 + r_x**2 / ROD_INERTIA + np.sign(slip) * mu * r_x * r_z / ROD_INERTIA)
    for k in range(20):
        state = sim.step(state)
        report = sim.last_step
        assert report.converged and not report.friction_unsettled
        (contact,) = report.contacts
        friction = contact.tangential_force
        assert np.linalg.norm(friction) == pytest.approx(mu * contact.normal_force, rel=COULOMB_RTOL)
        assert friction[0] * slip < 0 and abs(contact.gap) < 1e-6
        if k == 0:
            assert contact.normal_force == pytest.approx(normal, rel=COULOMB_RTOL)


def test_an_unsettled_sliding_friction_is_reported_and_counted(rod):
    """Two QPs are too few for the sliding rod's normal force: each step says so, is not converged,
    and the benchmark's recorder and a run log's summary count it."""
    sim, state, _, _ = _sliding_rod(rod, 1.0, iterations=2)
    recorder = Recorder(sim)
    log = gaussim.RunLog("rod", "", sim.options)
    log.start(state)
    for _ in range(3):
        state = recorder.step(state)
        report = sim.last_step
        assert report.friction_unsettled and not report.converged
        assert all(c.converged for c in report.certificates)  # each QP did
        log.record(state, np.zeros(6), report)
    assert recorder.unconverged == 3
    assert "steps not converged: 3" in log.summary()


def _cradle(balls: gaussim.Robot, dt: float, x: tuple[float, float, float]):
    """The three elastic, frictionless balls at x [m] along the row, in zero gravity, in the acceleration
    scheme, the first moving at 1 m/s toward the others: (simulator, state)."""
    scene = gaussim.Scene(
        balls, contacts=[("b0_0", "b1_0"), ("b1_0", "b2_0")], gravity=(0, 0, 0), self_contact=(0.0, 1.0)
    )
    sim = gaussim.Simulator(scene, gaussim.Options(scheme="acceleration", dt=dt))
    q = balls.neutral()
    q[[0, 7, 14]] = x
    v = np.zeros(18)
    v[0] = 1.0
    return sim, sim.reset(q, v)


# Sticking contacts against Pinocchio's constraintDynamics of the same points held, relative
PINOCCHIO_RTOL = 1e-9


def test_sticking_feet_equal_pinocchios_constraint_dynamics(solo12):
    """Solo-12 on its four feet, levelled so that each touches the ground at one point with zero gap,
    moving with its feet still (v in the null space of their Jacobians) under torques that hold it up
    plus a random part: where the feet stick (Pinocchio's forces in the friction pyramid), a step's
    acceleration and contact forces are those of constraintDynamics with the four points held
    (CONTACT_3D to the world, no Baumgarte terms: gap and contact velocities are zero)."""
    model, data = solo12.model, solo12.model.createData()
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    scene = gaussim.Scene(solo12, ground=gaussim.Ground(friction=1.0), contacts=[("*_FOOT_0", "ground")])
    probe = gaussim.Simulator(scene)  # its reports give each foot's lowest point and gap
    q = solo12.configuration("standing")

    def feet(q):
        probe.step(probe.reset(q))
        contacts = sorted(probe.last_step.contacts, key=lambda c: c.geometry)
        assert len(contacts) == 4
        joints = [
            solo12.collision_model.geometryObjects[solo12.geometry_id(c.geometry)].parentJoint
            for c in contacts
        ]
        pin.computeJointJacobians(model, data, q)
        points = [pin.SE3(np.eye(3), data.oMi[j].actInv(c.point)) for j, c in zip(joints, contacts)]
        J = np.vstack([pin.getFrameJacobian(model, data, j, p, lwa)[:3] for j, p in zip(joints, points)])
        return np.array([c.gap for c in contacts]), joints, points, J

    for _ in range(5):  # level the feet: Newton on their gaps by the leg joints
        gaps, joints, points, J = feet(q)
        q[7:] -= np.linalg.lstsq(J[2::3, 6:], gaps, rcond=None)[0]
    gaps, joints, points, J = feet(q)
    assert np.abs(gaps).max() < 1e-12
    # a torque that holds the standing robot with its weight shared by the feet, plus a random part
    g = pin.computeGeneralizedGravity(model, data, q)
    share = np.tile([0.0, 0.0, pin.computeTotalMass(model) * G / 4], 4)
    hold = share + np.linalg.lstsq(J[:, :6].T, g[:6] - J[:, :6].T @ share, rcond=None)[0]
    pin.forwardKinematics(model, data, q)
    held = pin.StdVec_RigidConstraintModel()
    for j, p in zip(joints, points):
        held.append(
            pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, model, j, p, 0, data.oMi[j] * p, lwa)
        )
    sim = gaussim.Simulator(scene, gaussim.Options(scheme="acceleration"))
    rng = np.random.default_rng(7)
    for _ in range(10):
        v = np.linalg.svd(J)[2][12:].T @ rng.normal(size=6) * 0.3
        tau = (g - J.T @ hold)[6:] + 0.1 * rng.normal(size=12)
        datas = pin.StdVec_RigidConstraintData()
        for c in held:
            datas.append(c.createData())
        reference = model.createData()
        pin.initConstraintDynamics(model, reference, held, datas)
        settings = pin.ProximalSettings(1e-14, 1e-12, 200)
        a_ref = pin.constraintDynamics(model, reference, q, v, np.r_[np.zeros(6), tau], held, datas, settings)
        f_ref = np.array([d.contact_force.linear for d in datas])
        assert f_ref[:, 2].min() > 1.0 and (np.linalg.norm(f_ref[:, :2], axis=1) < 0.5 * f_ref[:, 2]).all()

        state = sim.reset(q, v)
        after = sim.step(state, tau)
        a = (step_velocity(state, after) - v) / sim.options.dt + frame_acceleration(v)
        np.testing.assert_allclose(a, a_ref, atol=PINOCCHIO_RTOL * np.abs(a_ref).max())
        assert sim.last_step.impact is None
        forces = np.array([c.force for c in sorted(sim.last_step.contacts, key=lambda c: c.geometry)])
        np.testing.assert_allclose(forces, f_ref, atol=PINOCCHIO_RTOL * np.abs(f_ref).max())
