"""Point Jacobians and drifts against finite differences of Pinocchio's kinematics."""

import numpy as np
import pinocchio as pin
import pytest

import gaussim
from gaussim.bench.scenes import boxes
from gaussim.dynamics import (
    DynamicsStage,
    MassStructure,
    Supports,
    compute_dynamics,
    gauss_problem,
    point_drifts,
    point_jacobians,
    point_placements,
)

FD_STEP = 1e-7
FD_TOLERANCE = 1e-5


def test_point_jacobians_and_drifts_match_finite_differences(solo12):
    model = solo12.model
    data = model.createData()
    rng = np.random.default_rng(3)
    q = solo12.configuration("standing")
    v = rng.normal(size=model.nv)
    joints = [model.getJointId("FL_KFE"), model.getJointId("HR_HAA"), 1]
    masks, world = Supports.of(model), np.zeros(3, int)
    local = rng.normal(scale=0.1, size=(3, 3))

    def points(q_):
        pin.forwardKinematics(model, scratch, q_)
        return np.array([scratch.oMi[j].act(p) for j, p in zip(joints, local)])

    scratch = model.createData()
    compute_dynamics(model, data, q, v, np.zeros(model.nv), dt=1e-3, acceleration=True)
    p = points(q)
    placements = point_placements(data, joints, p)
    J = point_jacobians(data, masks, np.array(joints), world, p)
    drift = point_drifts(model, data, joints, placements)
    assert J.shape == (3, 3, model.nv) and drift.shape == (3, 3)

    q_next = pin.integrate(model, q, FD_STEP * v)
    np.testing.assert_allclose(J @ v, (points(q_next) - p) / FD_STEP, atol=FD_TOLERANCE)
    # Jdot v: derivative of the body-point velocity J(q) v along the motion at zero acceleration of the
    # Gauss problem's coordinates, where the base's world velocity R v_l is fixed: v_l turns at -w x v_l
    compute_dynamics(model, data, q_next, v, np.zeros(model.nv), dt=1e-3)
    J_next = point_jacobians(data, masks, np.array(joints), world, points(q_next))
    v_next = v.copy()
    v_next[:3] -= FD_STEP * np.cross(v[3:6], v[:3])
    np.testing.assert_allclose(drift, (J_next @ v_next - J @ v) / FD_STEP, atol=FD_TOLERANCE * 10)


def test_relative_point_jacobians_are_differences_of_the_two_bodies(solo12):
    """Two robot bodies at one point: the relative Jacobian is the difference of the two bodies'
    point Jacobians (their shared ancestors cancel)."""
    model = solo12.model
    data = model.createData()
    rng = np.random.default_rng(5)
    q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    compute_dynamics(model, data, q, rng.normal(size=model.nv), np.zeros(model.nv), dt=1e-3)
    masks = Supports.of(model)
    joints = np.array([model.getJointId("FL_KFE"), model.getJointId("FL_KFE")])
    others = np.array([model.getJointId("FR_KFE"), model.getJointId("FL_HAA")])
    p = rng.normal(size=(2, 3))
    relative = point_jacobians(data, masks, joints, others, p)
    difference = point_jacobians(data, masks, joints, np.zeros(2, int), p) - point_jacobians(
        data, masks, others, np.zeros(2, int), p
    )
    np.testing.assert_allclose(relative, difference, atol=1e-12)
    # the FL leg's own hip joint is shared with FL_KFE: no base columns remain in the relative rows
    assert np.abs(relative[1, :, :6]).max() < 1e-12


def test_dynamics_match_pinocchio(solo12):
    """Both levels' free Gauss problems, by both orders of the dynamics stage: M is CRBA's, x_free is
    ABA's acceleration a less the base frame's turn c = (-w x v_l, 0) (acceleration level) or
    v + dt (a - c) (velocity level), g = -M x_free, with F = tau - b."""
    model = solo12.model
    data = model.createData()
    rng = np.random.default_rng(4)
    q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    v, tau, dt = rng.normal(size=model.nv), rng.normal(size=model.nv), 1e-3
    ref = model.createData()
    for tau_given in (tau, np.concatenate([np.zeros(6), tau[6:]])):
        tau_ref = tau_given
        c = np.concatenate([-np.cross(v[3:6], v[:3]), np.zeros(model.nv - 3)])
        a = pin.aba(model, ref, q, v, tau_ref) - c
        F = tau_ref - pin.nonLinearEffects(model, ref, q, v) - pin.crba(model, ref, q) @ c
        acceleration = compute_dynamics(model, data, q, v, tau_given, dt=dt, acceleration=True)
        np.testing.assert_allclose(acceleration.M, pin.crba(model, ref, q), atol=1e-12)
        np.testing.assert_allclose(acceleration.x_free, a, atol=1e-9)
        np.testing.assert_allclose(acceleration.g, -F, atol=1e-9)
        cholesky_first = compute_dynamics(model, data, q, v, tau_given, dt=dt)
        stage = DynamicsStage(model, data)
        for _ in range(2):  # the first runs CRBA (as after a step that posed a problem), then ABA
            stage.free_motion(q, v, tau_given, dt)
        aba_first = stage.problem()
        for velocity in (cholesky_first, aba_first):
            np.testing.assert_allclose(velocity.x_free, v + dt * a, atol=1e-12)
            np.testing.assert_allclose(velocity.g, -(velocity.M @ v + dt * F), atol=1e-9)


def test_the_stage_takes_the_order_the_last_step_needed(solo12):
    """Free flight runs ABA alone; a step after one that posed a problem runs CRBA + RNEA + Cholesky
    at once; either way the problem, when asked for, is the same."""
    model = solo12.model
    stage, reference = DynamicsStage(model, model.createData()), model.createData()
    rng = np.random.default_rng(6)
    q, v, tau, dt = solo12.configuration("standing"), rng.normal(size=model.nv), rng.normal(size=18), 1e-3
    expected = compute_dynamics(model, reference, q, v, tau, dt)
    for posed_before in (True, False, True):
        x_free = stage.free_motion(q, v, tau, dt)
        assert (stage._dynamics is not None) == posed_before
        np.testing.assert_allclose(x_free, expected.x_free, atol=1e-12)
        if posed_before:
            continue  # this step poses nothing: the next runs ABA alone
        problem = stage.problem()
        np.testing.assert_allclose(problem.g, expected.g, atol=1e-9)
        np.testing.assert_allclose(problem.M, expected.M, atol=1e-12)


@pytest.mark.parametrize("which", ["talos", "arm_and_boxes", "boxes", "bodies"])
def test_the_structured_problem_is_pinocchios_dense_one(which, monkeypatch):
    """On M's joint structure (a branched robot with armature; a pendulum and free boxes, several
    trees whose M changes), and on the constant M of a world of free bodies (boxes with armature;
    bodies whose centre of mass is off their joint, with turned principal axes): the same M, free
    motion and linear term as Pinocchio's CRBA, RNEA and dense Cholesky, at both levels, at a
    configuration other than the one the constant M was taken at."""
    rng = np.random.default_rng(8)
    if which == "talos":
        model = gaussim.load_robot("talos").model
    elif which == "arm_and_boxes":
        free = {f"b{i}": gaussim.FreeBody.box(f"b{i}", (0.1, 0.2, 0.3), mass=1.0 + i) for i in range(4)}
        bodies = {"arm": gaussim.load_robot("pendulum"), **free}
        model = gaussim.Simulator(gaussim.Scene(bodies=bodies, ground=gaussim.Ground())).model
    else:
        model = gaussim.Simulator(boxes(6).scene).model
    if which == "bodies":
        for j in range(1, model.njoints):
            turn = pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3))
            principal = np.diag(rng.uniform(0.01, 0.05, 3))
            lever = rng.uniform(-0.05, 0.05, 3)
            model.inertias[j] = pin.Inertia(rng.uniform(0.5, 2.0), lever, turn @ principal @ turn.T)
    else:
        model.armature[:] = rng.uniform(0.0, 0.1, model.nv)
    monkeypatch.setattr("gaussim.dynamics.STRUCTURED_NV", 0)
    data, reference = model.createData(), model.createData()
    structure = MassStructure.of(model, data)
    assert structure is not None
    assert structure.constant == (which in ("boxes", "bodies"))
    q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    v, tau = rng.normal(size=model.nv), rng.normal(size=model.nv)
    for acceleration in (False, True):
        expected = compute_dynamics(model, reference, q, v, tau, 1e-3, acceleration)
        data.J[:] = np.nan  # the rows read the Jacobians this pass leaves
        got = compute_dynamics(model, data, q, v, tau, 1e-3, acceleration, None, structure)
        np.testing.assert_allclose(got.M, expected.M, rtol=0, atol=1e-12)
        np.testing.assert_allclose(got.x_free, expected.x_free, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(got.g, expected.g, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(data.J, reference.J, atol=1e-12)
    # posed first by a new structure (a step after ABA's free motion): M with the model's armature
    fresh = MassStructure.of(model, model.createData())
    data.J[:] = np.nan
    posed = gauss_problem(model, data, q, v, fresh)
    expected = gauss_problem(model, reference, q, v)
    np.testing.assert_allclose(posed.M, expected.M, rtol=0, atol=1e-12)
    np.testing.assert_allclose(posed.g, expected.g, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(data.J, reference.J, atol=1e-12)


def test_a_torque_of_another_size_is_refused(solo12):
    """The stage reads nv torques: a shorter array (the actuation stage pads them) is an error, not a
    read past its end."""
    model = solo12.model
    stage = DynamicsStage(model, model.createData())
    q, v = solo12.configuration("standing"), np.zeros(model.nv)
    with pytest.raises(gaussim.InvalidState, match=r"tau must have shape \(18,\), got \(12,\)"):
        stage.free_motion(q, v, np.zeros(12), 1e-3)
    with pytest.raises(gaussim.InvalidState, match=r"tau must have shape \(18,\), got \(12,\)"):
        compute_dynamics(model, model.createData(), q, v, np.zeros(12), 1e-3)


@pytest.mark.parametrize("tilt", [np.pi / 2, 1.2, 0.6, 0.2])
def test_a_cylinders_rim_drift_is_the_second_derivative_of_its_gap(tilt):
    """A cylinder touching the ground on its rim (on its side, or tilted like a rolling coin): the
    normal drift of its contact is phi'' of the rim's gap phi = n . C - r sqrt(1 - (n . a)^2) (C the
    lower cap's centre, a the axis) along a motion of zero acceleration, by finite differences. The
    material point's drift (the contact taken as a point of the body) is off by the rim's rolling:
    a cylinder on its side rolled into the ground at the acceleration level."""
    from gaussim.collision import Contacts
    from gaussim.constraints.base import Context
    from gaussim.constraints.contact import ContactModule, _drifts

    r, length = 0.1, 0.3
    cylinder = gaussim.FreeBody.cylinder("c", r, length, mass=1.0)
    scene = gaussim.Scene(bodies={"c": cylinder}, ground=gaussim.Ground())
    model, geometry = scene.robot.model, scene.robot.collision_model
    data, geometry_data = model.createData(), pin.GeometryData(geometry)
    module = ContactModule(model, 4, "accurate", geometry)
    n = np.array([0.0, 0.0, 1.0])

    def rim(q_):  # the gap, and the lower cap's centre, its axis and n . axis
        pin.forwardKinematics(model, data, q_)
        pin.updateGeometryPlacements(model, data, geometry, geometry_data)
        frame = geometry_data.oMg[0]
        a = frame.rotation[:, 2]
        s = n @ a
        cap = frame.translation - (np.sign(s) if abs(s) > 1e-3 else 1.0) * length / 2 * a  # one cap
        return n @ cap - r * np.sqrt(1 - s * s), cap, a, s

    q = pin.neutral(model)
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(tilt, 0.3, 0.5)).coeffs()
    v = np.random.default_rng(0).normal(scale=3.0, size=6)
    step = 1e-4
    gaps = [rim(pin.integrate(model, q, t * v))[0] for t in (-step, 0.0, step)]
    _, cap, a, s = rim(q)
    point = cap - r * (n - s * a) / np.sqrt(1 - s * s)  # the rim's lowest point
    pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
    one = np.ones(1)
    contacts = Contacts(
        ["c"], [geometry.geometryObjects[0].name], ["ground"], np.array([1]), np.array([0]),
        point[None], n[None], np.zeros(1), 0.5 * one, 0.0 * one,
    )  # fmt: skip
    ctx = Context(model, data, q, v, v, contacts, gaussim.Options(), "acceleration")
    drift = _drifts(ctx, contacts, module.radii, module.cylinders)[0]
    assert n @ drift == pytest.approx((gaps[0] - 2 * gaps[1] + gaps[2]) / step**2, rel=1e-5, abs=1e-5)
