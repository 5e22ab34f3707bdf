"""Bilateral constraints: the QP equals a direct KKT solve of FORMULATION.md section 4."""

import numpy as np
import pinocchio as pin
import pytest

import gaussim

KKT_TOLERANCE = 1e-8
# Anchor drift while shaking at joint speeds up to ~5 rad/s: the stabilisation bounds it by
# O(|w|^2 r dt^2 / stabilisation) = 25 * 0.2 * 1e-6 / 0.2 = 2.5e-5 m (FORMULATION.md section 5, drift) [m].
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
        a = (next_state.v - state.v) / o.dt
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
