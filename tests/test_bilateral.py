"""Bilateral constraints: the QP equals a direct KKT solve of docs/FORMULATION.md section 4."""

import numpy as np
import pinocchio as pin
import pytest

import gaussim

from .conftest import frame_acceleration, step_velocity

KKT_TOLERANCE = 1e-8
# Energy oscillation of semi-implicit Euler at dt = 1 ms on a swinging linkage, relative.
ENERGY_RTOL = 0.01
# Anchor drift while shaking at joint speeds up to ~5 rad/s: the stabilisation bounds it by
# O(|w|^2 r dt^2 / stabilisation) = 25 * 0.2 * 1e-6 / 0.2 = 2.5e-5 m (docs/FORMULATION.md section 5) [m].
DRIFT_TOLERANCE = 5e-5
FEET = ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]


def _anchored(solo12, scheme):
    q = solo12.configuration("standing")
    data = solo12.model.createData()
    pin.framesForwardKinematics(solo12.model, data, q)
    anchors = [gaussim.Anchor(f, data.oMf[solo12.frame_id(f)].translation.copy()) for f in FEET]
    scene = gaussim.Scene(solo12, bilaterals=anchors)
    return gaussim.Simulator(scene, gaussim.Options(scheme=scheme)), q


def test_acceleration_and_forces_equal_direct_kkt(solo12):
    sim, q = _anchored(solo12, "acceleration")
    rng = np.random.default_rng(1)
    state = sim.reset(q, 0.1 * rng.normal(size=solo12.model.nv))
    o = sim.options
    k = o.stabilisation / o.dt
    model, data = solo12.model, solo12.model.createData()
    for _ in range(20):
        tau = rng.normal(size=12)
        tau_full = np.concatenate([np.zeros(6), tau])
        # the direct solve: [M -J^T; J 0] [a; lambda] = [tau - b; -Jdot v - 2k J v - k^2 phi]
        pin.computeAllTerms(model, data, state.q, state.v)
        pin.forwardKinematics(model, data, state.q, state.v, np.zeros(model.nv))
        pin.updateFramePlacements(model, data)
        J = np.vstack(
            [pin.getFrameJacobian(model, data, solo12.frame_id(f), pin.LOCAL_WORLD_ALIGNED)[:3] for f in FEET]
        )
        drift = np.concatenate(
            [
                pin.getFrameClassicalAcceleration(
                    model, data, solo12.frame_id(f), pin.LOCAL_WORLD_ALIGNED
                ).linear
                for f in FEET
            ]
        )
        phi = np.concatenate(
            [
                data.oMf[solo12.frame_id(f)].translation - a.position
                for f, a in zip(FEET, sim.scene.bilaterals)
            ]
        )
        rhs = -drift - 2 * k * (J @ state.v) - k**2 * phi
        n, m = model.nv, J.shape[0]
        K = np.block([[data.M, -J.T], [J, np.zeros((m, m))]])
        solution = np.linalg.solve(K, np.concatenate([tau_full - data.nle, rhs]))
        a_ref, lam_ref = solution[:n], solution[n:]

        next_state = sim.step(state, tau)
        a = (step_velocity(state, next_state) - state.v) / o.dt + frame_acceleration(state.v)
        np.testing.assert_allclose(a, a_ref, atol=KKT_TOLERANCE * max(1, np.abs(a_ref).max()))
        lam = np.concatenate([r.wrench for r in sim.last_step.bilaterals])
        np.testing.assert_allclose(lam, lam_ref, atol=KKT_TOLERANCE * max(1, np.abs(lam_ref).max()))
        assert sim.last_step.converged
        assert sim.last_step.max_residual < o.eps_abs * 10
        state = next_state


@pytest.mark.parametrize("scheme", ["velocity", "acceleration"])
def test_anchors_hold_with_bounded_drift(solo12, scheme):
    sim, q = _anchored(solo12, scheme)
    state = sim.reset(q)
    for _ in range(1000):
        # a PD hold of the standing posture plus a shake keeps the mechanism moving
        tau = 5.0 * (q[7:] - state.q[7:]) - 0.1 * state.v[6:] + 0.5 * np.sin(20 * state.t)
        state = sim.step(state, tau)
        assert sim.last_step.max_residual < 1e-8
    data = solo12.model.createData()
    pin.framesForwardKinematics(solo12.model, data, state.q)
    for f, anchor in zip(FEET, sim.scene.bilaterals):
        assert np.linalg.norm(data.oMf[solo12.frame_id(f)].translation - anchor.position) < DRIFT_TOLERANCE


@pytest.mark.parametrize("scheme", ["velocity", "acceleration"])
def test_four_bar_loop_closure_holds_and_conserves_energy(scheme):
    robot = gaussim.load_robot("fourbar")
    scene = gaussim.Scene(robot, bilaterals=[gaussim.LoopClosure("tip", "anchor")])
    sim = gaussim.Simulator(scene, gaussim.Options(scheme=scheme, dt=1e-3))
    t0 = 0.3
    state = sim.reset(np.array([t0, -t0, t0 + np.pi]))
    model, data = robot.model, robot.model.createData()

    def energy(s):
        return pin.computeKineticEnergy(model, data, s.q, s.v) + pin.computePotentialEnergy(model, data, s.q)

    e0, drift, error = energy(state), 0.0, 0.0
    for _ in range(2000):
        state = sim.step(state)
        pin.framesForwardKinematics(model, data, state.q)
        gap = data.oMf[robot.frame_id("tip")].translation - data.oMf[robot.frame_id("anchor")].translation
        drift = max(drift, np.linalg.norm(gap))
        error = max(error, abs(energy(state) - e0))
    assert drift < DRIFT_TOLERANCE
    # the mechanism swings like a pendulum: semi-implicit Euler keeps its energy within O(dt) of the
    # start, no secular gain or loss
    assert error < ENERGY_RTOL * abs(e0)
    assert abs(state.q[0] - t0) > 0.1, "it moved"


def test_placement_anchor_holds_a_box(box):
    target = pin.SE3(pin.rpy.rpyToMatrix(0.1, 0.2, 0.3), np.array([0.0, 0.0, 1.0]))
    scene = gaussim.Scene(box, bilaterals=[gaussim.Anchor("box", target.translation, target.rotation)])
    sim = gaussim.Simulator(scene)
    q = np.concatenate([target.translation, pin.Quaternion(target.rotation).coeffs()])
    state = sim.reset(q)
    for _ in range(500):
        state = sim.step(state)
    np.testing.assert_allclose(state.q, q, atol=1e-9)
    (reaction,) = sim.last_step.bilaterals
    np.testing.assert_allclose(reaction.wrench, [0, 0, box.mass * 9.81, 0, 0, 0], atol=1e-6)


@pytest.mark.parametrize("scheme", ["velocity", "acceleration"])
def test_placement_anchor_turns_a_box_to_its_target(box, scheme):
    """A box held at its target position but turned 0.37 rad away from its target orientation: the
    error e = log3(R R_target^T) keeps its axis and shrinks as the stabilisation says. Velocity
    scheme: the rows ask omega = -(s / dt) e, so e shrinks by 1 - s per step exactly. Acceleration
    scheme: omega' = -2 k omega - k^2 e (k = s / dt) integrated by the step's semi-implicit Euler."""
    target = pin.rpy.rpyToMatrix(0.1, 0.2, 0.3)
    position = np.array([0.0, 0.0, 1.0])
    scene = gaussim.Scene(box, bilaterals=[gaussim.Anchor("box", position, target)])
    sim = gaussim.Simulator(scene, gaussim.Options(scheme=scheme))
    dt, s = sim.options.dt, sim.options.stabilisation
    state = sim.reset(np.r_[position, 0, 0, 0, 1])
    e0 = pin.log3(np.eye(3) @ target.T)
    angle, rate = np.linalg.norm(e0), 0.0  # along the axis of e0
    for _ in range(60):
        state = sim.step(state)
        if scheme == "velocity":
            angle *= 1 - s
        else:
            rate += dt * (-2 * s / dt * rate - (s / dt) ** 2 * angle)
            angle += dt * rate
        R = pin.Quaternion(state.q[3:7]).normalized().matrix()
        np.testing.assert_allclose(pin.log3(R @ target.T), angle * e0 / np.linalg.norm(e0), atol=1e-9)
        np.testing.assert_allclose(state.q[:3], position, atol=1e-9)
    assert angle < 1e-2 * np.linalg.norm(e0), "it converged"


# A four-bar linkage of unequal links, a crank-rocker (the crank turns fully): crank, coupler, rocker
# and ground [m]. Its loop closure is not linear in q (the parallelogram of robots/fourbar.urdf is), so
# the closure's drift and its Jdot v are not zero.
CRANK, COUPLER, ROCKER, GROUND = 0.2, 0.5, 0.4, 0.6
# Acceleration scheme against Pinocchio's constraintDynamics with the same Baumgarte gains, relative
PINOCCHIO_RTOL = 1e-9
LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


@pytest.fixture(scope="module")
def crank_rocker(tmp_path_factory) -> gaussim.Robot:
    """The crank-rocker in the x-z plane: revolute joints about y, 1 kg rods (I = m L^2 / 12), the
    frame ``tip`` at the rocker's end to be joined to the frame ``anchor`` on the ground."""

    def link(name: str, length: float) -> str:
        inertia = length**2 / 12
        return (
            f'<link name="{name}"><inertial><origin xyz="{length / 2} 0 0"/><mass value="1"/>'
            f'<inertia ixx="1e-4" ixy="0" ixz="0" iyy="{inertia}" iyz="0" izz="{inertia}"/></inertial></link>'
        )

    def joint(name: str, parent: str, child: str, x: float) -> str:
        return (
            f'<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{x} 0 0"/><axis xyz="0 1 0"/>'
            '<limit lower="-100" upper="100" effort="1" velocity="1"/></joint>'
        )

    urdf = (
        '<?xml version="1.0"?><robot name="crank_rocker"><link name="ground"/><link name="anchor"/>'
        f'<joint name="anchor_joint" type="fixed"><parent link="ground"/><child link="anchor"/>'
        f'<origin xyz="{GROUND} 0 0"/></joint>'
        + joint("crank_joint", "ground", "crank", 0.0)
        + link("crank", CRANK)
        + joint("coupler_joint", "crank", "coupler", CRANK)
        + link("coupler", COUPLER)
        + joint("rocker_joint", "coupler", "rocker", COUPLER)
        + link("rocker", ROCKER)
        + '<link name="tip"/><joint name="tip_joint" type="fixed"><parent link="rocker"/>'
        f'<child link="tip"/><origin xyz="{ROCKER} 0 0"/></joint></robot>'
    )
    path = tmp_path_factory.mktemp("crank_rocker") / "crank_rocker.urdf"
    path.write_text(urdf)
    with pytest.warns(gaussim.GaussimWarning, match="no collision geometry"):
        return gaussim.load_robot(path)


def _closed(crank: float) -> np.ndarray:
    """The crank-rocker's closed configuration at a crank angle [rad] (one of its two branches)."""
    a = np.array([CRANK * np.cos(crank), -CRANK * np.sin(crank)])  # (x, z): a turn about y
    b = np.array([GROUND, 0.0])
    d = np.linalg.norm(b - a)
    along = (COUPLER**2 - ROCKER**2 + d**2) / (2 * d)
    e = (b - a) / d
    p = a + along * e + np.sqrt(COUPLER**2 - along**2) * np.array([-e[1], e[0]])

    def angle(u: np.ndarray) -> float:  # of a vector (x, z), turning about y
        return float(np.arctan2(-u[1], u[0]))

    coupler, rocker = angle(p - a), angle(b - p)
    return np.array([crank, coupler - crank, rocker - coupler])


def _pinocchio(model, frames, kind, q, v, tau, k):
    """Pinocchio's constraintDynamics of one rigid constraint between two frames (ids; 0 is a world
    frame) with Baumgarte gains (k^2, 2 k): the acceleration and the constraint's force on the first."""
    (fa, pa), (fb, pb) = ((model.frames[f].parentJoint, model.frames[f].placement) for f in frames)
    constraint = pin.RigidConstraintModel(kind, model, fa, pa, fb, pb, LWA)
    constraint.setBaumgarteCorrectorParameters(pin.BaumgarteCorrectorParameters(k * k, 2 * k))
    models, datas = pin.StdVec_RigidConstraintModel(), pin.StdVec_RigidConstraintData()
    models.append(constraint)
    datas.append(constraint.createData())
    data = model.createData()
    pin.initConstraintDynamics(model, data, models, datas)
    a = pin.constraintDynamics(model, data, q, v, tau, models, datas, pin.ProximalSettings(1e-14, 1e-12, 200))
    return a.copy(), datas[0].contact_force.vector.copy()


def test_a_loop_closure_equals_pinocchios_constraint_dynamics(crank_rocker):
    """The crank-rocker closed by a LoopClosure, driven by random torques: each acceleration-scheme
    step's a and closure force equal Pinocchio's constraintDynamics at the step's state (a CONTACT_3D
    constraint with the same Baumgarte gains), drift included."""
    robot, model = crank_rocker, crank_rocker.model
    scene = gaussim.Scene(robot, bilaterals=[gaussim.LoopClosure("tip", "anchor")])
    sim = gaussim.Simulator(scene, gaussim.Options(scheme="acceleration"))
    k = sim.options.stabilisation / sim.options.dt
    frames = (robot.frame_id("tip"), robot.frame_id("anchor"))
    rng = np.random.default_rng(0)
    state = sim.reset(_closed(0.3), np.array([3.0, -2.0, 1.0]))  # off the loop's velocities
    for _ in range(200):
        tau = rng.normal(size=3)
        after = sim.step(state, tau)
        a_ref, f_ref = _pinocchio(model, frames, pin.ContactType.CONTACT_3D, state.q, state.v, tau, k)
        a = (after.v - state.v) / sim.options.dt
        np.testing.assert_allclose(a, a_ref, atol=PINOCCHIO_RTOL * np.abs(a_ref).max())
        (closure,) = sim.last_step.bilaterals
        np.testing.assert_allclose(closure.wrench, f_ref[:3], atol=PINOCCHIO_RTOL * np.abs(f_ref).max())
        state = after


@pytest.mark.parametrize("scheme", ["velocity", "acceleration"])
def test_a_crank_rockers_closure_drift_stays_bounded(crank_rocker, scheme):
    """10 s of the crank-rocker turning at about 3 rad/s under gravity: the closure's drift stays
    within its bound O(|v|^2 dt^2 / stabilisation) (measured 6.7e-5 m, velocity scheme, and 1.4e-4 m,
    acceleration scheme, from the first second to the last) and does not grow."""
    robot, model = crank_rocker, crank_rocker.model
    data = model.createData()
    q = _closed(0.3)
    pin.computeJointJacobians(model, data, q)
    pin.framesForwardKinematics(model, data, q)
    loop = np.linalg.svd(pin.getFrameJacobian(model, data, robot.frame_id("tip"), LWA)[:3])[2][-1]
    scene = gaussim.Scene(robot, bilaterals=[gaussim.LoopClosure("tip", "anchor")])
    sim = gaussim.Simulator(scene, gaussim.Options(scheme=scheme))
    state = sim.reset(q, 3.0 * loop)
    drift = []
    for _ in range(10000):
        state = sim.step(state)
        pin.framesForwardKinematics(model, data, state.q)
        tip, anchor = (data.oMf[robot.frame_id(f)].translation for f in ("tip", "anchor"))
        drift.append(np.linalg.norm(tip - anchor))
    assert max(drift) < 2e-4
    assert max(drift[-1000:]) < 1.1 * max(drift[:1000]), "no growth"


@pytest.mark.parametrize("orientation", [False, True])
def test_a_panda_anchor_equals_pinocchios_constraint_dynamics(orientation):
    """Panda's hand anchored at its own pose, its point (3 rows) or its placement (6 rows), from states
    moving along the anchor and random torques: the acceleration scheme's a and the anchor's wrench
    (force, then torque, world axes at the frame) equal Pinocchio's CONTACT_3D / CONTACT_6D ones."""
    robot = gaussim.load_robot("panda")
    model, data = robot.model, robot.model.createData()
    hand = robot.frame_id("panda_hand")
    kind = pin.ContactType.CONTACT_6D if orientation else pin.ContactType.CONTACT_3D
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = np.clip(pin.randomConfiguration(model), model.lowerPositionLimit, model.upperPositionLimit)
        pin.computeJointJacobians(model, data, q)
        pin.framesForwardKinematics(model, data, q)
        rows = 6 if orientation else 3
        J = pin.getFrameJacobian(model, data, hand, LWA)[:rows]
        v = np.linalg.svd(J)[2][rows:].T @ rng.normal(size=model.nv - rows)
        tau = 5.0 * rng.normal(size=model.nv)
        pose = data.oMf[hand]
        anchor = gaussim.Anchor(
            "panda_hand", pose.translation.copy(), pose.rotation.copy() if orientation else None
        )
        sim = gaussim.Simulator(
            gaussim.Scene(robot, bilaterals=[anchor]), gaussim.Options(scheme="acceleration")
        )
        state = sim.reset(q, v)
        after = sim.step(state, tau)
        # the anchor's target as a frame of the world (frame 0's placement is the identity)
        model_with_target = model.copy()
        target = model_with_target.addFrame(pin.Frame("target", 0, 0, pose, pin.FrameType.OP_FRAME))
        k = sim.options.stabilisation / sim.options.dt
        a_ref, f_ref = _pinocchio(model_with_target, (hand, target), kind, q, v, tau, k)
        np.testing.assert_allclose(
            (after.v - state.v) / sim.options.dt, a_ref, atol=PINOCCHIO_RTOL * np.abs(a_ref).max()
        )
        (reaction,) = sim.last_step.bilaterals
        np.testing.assert_allclose(reaction.wrench, f_ref[:rows], atol=PINOCCHIO_RTOL * np.abs(f_ref).max())
