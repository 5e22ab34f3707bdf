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
