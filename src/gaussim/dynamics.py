"""Stage 1, dynamics and kinematics (Pinocchio): M(q), F = tau - b(q, v), Jacobians, drifts."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


@dataclass
class Dynamics:
    """The free system M a = F at the current (q, v).

    Attributes:
        M: joint-space inertia, shape (nv, nv), symmetric positive definite.
        F: generalized force tau - b(q, v), shape (nv,) [N or N m].
    """

    M: np.ndarray
    F: np.ndarray


def compute_dynamics(
    model: pin.Model, data: pin.Data, q: np.ndarray, v: np.ndarray, tau: np.ndarray, drifts: bool
) -> Dynamics:
    """Compute M, b, placements and joint Jacobians in one Pinocchio pass.

    With ``drifts`` the spatial accelerations at a = 0 are computed too, for the acceleration-level
    constraint terms Jdot v (see :func:`point_drift`).
    """
    pin.computeAllTerms(model, data, q, v)
    if drifts:
        pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
    pin.updateFramePlacements(model, data)
    return Dynamics(data.M.copy(), tau - data.nle)


def _skew(r: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def point_jacobian(model: pin.Model, data: pin.Data, joint: int, point: np.ndarray) -> np.ndarray:
    """Jacobian of the world velocity of a point fixed to ``joint``'s body, shape (3, nv).

    Args:
        point: current world position of the point, shape (3,) [m].
    """
    J = pin.getJointJacobian(model, data, joint, LWA)
    r = point - data.oMi[joint].translation
    return J[:3] - _skew(r) @ J[3:]


def point_drift(model: pin.Model, data: pin.Data, joint: int, point: np.ndarray) -> np.ndarray:
    """Classical acceleration of a body point at zero joint acceleration (Jdot v), shape (3,) [m/s^2]."""
    velocity = pin.getVelocity(model, data, joint, LWA)
    acceleration = pin.getAcceleration(model, data, joint, LWA)
    r = point - data.oMi[joint].translation
    w = velocity.angular
    v_point = velocity.linear + np.cross(w, r)
    return acceleration.linear + np.cross(acceleration.angular, r) + np.cross(w, v_point)
