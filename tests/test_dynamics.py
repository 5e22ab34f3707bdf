"""Point Jacobians and drifts against finite differences of Pinocchio's kinematics."""

import numpy as np
import pinocchio as pin

from gaussim.dynamics import compute_dynamics, point_drift, point_jacobian

FD_STEP = 1e-7
FD_TOLERANCE = 1e-5


def _point(model, data, q, joint, local):
    pin.forwardKinematics(model, data, q)
    return data.oMi[joint].act(local)


def test_point_jacobian_and_drift_match_finite_differences(solo12):
    model = solo12.model
    data = model.createData()
    rng = np.random.default_rng(3)
    q = solo12.configuration("standing")
    v = rng.normal(size=model.nv)
    joint = model.getJointId("FL_KFE")
    local = np.array([0.01, -0.02, -0.16])
    compute_dynamics(model, data, q, v, np.zeros(model.nv), drifts=True)
    p = data.oMi[joint].act(local)
    J = point_jacobian(model, data, joint, p)
    drift = point_drift(model, data, joint, p)

    scratch = model.createData()

    def velocity(q_, v_):
        return (_point(model, scratch, pin.integrate(model, q_, FD_STEP * v_), joint, local) - _point(model, scratch, q_, joint, local)) / FD_STEP

    np.testing.assert_allclose(J @ v, velocity(q, v), atol=FD_TOLERANCE)
    # Jdot v: derivative of the point velocity J(q) v along the motion, at constant v
    q_next = pin.integrate(model, q, FD_STEP * v)
    compute_dynamics(model, data, q_next, v, np.zeros(model.nv), drifts=False)
    J_next = point_jacobian(model, data, joint, data.oMi[joint].act(local))
    np.testing.assert_allclose(drift, (J_next @ v - J @ v) / FD_STEP, atol=FD_TOLERANCE * 10)


def test_dynamics_match_pinocchio(solo12):
    model = solo12.model
    data = model.createData()
    rng = np.random.default_rng(4)
    q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    v, tau = rng.normal(size=model.nv), rng.normal(size=model.nv)
    dyn = compute_dynamics(model, data, q, v, tau, drifts=False)
    ref = model.createData()
    np.testing.assert_allclose(dyn.M, pin.crba(model, ref, q), atol=1e-12)
    np.testing.assert_allclose(np.linalg.solve(dyn.M, dyn.F), pin.aba(model, ref, q, v, tau), atol=1e-9)
