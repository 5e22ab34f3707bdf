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
    constraint terms Jdot v (see :func:`point_drifts`).
    """
    pin.computeAllTerms(model, data, q, v)
    if drifts:
        pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
    pin.updateFramePlacements(model, data)
    return Dynamics(data.M.copy(), tau - data.nle)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product along the last axis of (..., 3) arrays (numpy's ``cross`` costs ~20 us a call)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def point_jacobians(model: pin.Model, data: pin.Data, joints: list[int], points: np.ndarray) -> np.ndarray:
    """Jacobians of the world velocities of points fixed to ``joints``' bodies, shape (m, 3, nv).

    Args:
        points: current world positions of the points, shape (m, 3) [m].
    """
    J = np.array([pin.getJointJacobian(model, data, j, LWA) for j in joints])
    r = points - np.array([data.oMi[j].translation for j in joints])
    # v_p = v_o + w x r = v_o - r x w, column by column
    return J[:, :3] - cross(r[:, None, :], J[:, 3:].transpose(0, 2, 1)).transpose(0, 2, 1)


def point_drifts(model: pin.Model, data: pin.Data, joints: list[int], points: np.ndarray) -> np.ndarray:
    """Classical accelerations of body points at zero joint acceleration (Jdot v), shape (m, 3) [m/s^2].

    Needs the spatial accelerations of a forward pass with a = 0 (``compute_dynamics(drifts=True)``).
    """
    velocity = np.array([pin.getVelocity(model, data, j, LWA).vector for j in joints])
    acceleration = np.array([pin.getAcceleration(model, data, j, LWA).vector for j in joints])
    r = points - np.array([data.oMi[j].translation for j in joints])
    w = velocity[:, 3:]
    v_point = velocity[:, :3] + cross(w, r)
    return acceleration[:, :3] + cross(acceleration[:, 3:], r) + cross(w, v_point)
