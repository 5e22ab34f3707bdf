"""Stage 1, dynamics and kinematics (Pinocchio): M(q), F = tau - b(q, v), Jacobians, drifts."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
_IDENTITY = np.eye(3)


@dataclass
class Dynamics:
    """The free system M a = F at the current (q, v).

    Attributes:
        M: joint-space inertia, shape (nv, nv), symmetric positive definite.
        F: generalized force tau - b(q, v), shape (nv,) [N or N m].
        a_free: unconstrained acceleration M^-1 F, shape (nv,) (Pinocchio's ABA).
    """

    M: np.ndarray
    F: np.ndarray
    a_free: np.ndarray


def compute_dynamics(
    model: pin.Model, data: pin.Data, q: np.ndarray, v: np.ndarray, tau: np.ndarray, drifts: bool
) -> Dynamics:
    """Compute M, b, placements and joint Jacobians in one Pinocchio pass.

    With ``drifts`` the spatial accelerations at a = 0 are computed too, for the acceleration-level
    constraint terms Jdot v (see :func:`point_drifts`).
    """
    a_free = pin.aba(model, data, q, v, tau).copy()
    pin.computeAllTerms(model, data, q, v)
    if drifts:
        pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
    pin.updateFramePlacements(model, data)
    return Dynamics(data.M.copy(), tau - data.nle, a_free)


def point_placements(data: pin.Data, joints: list[int], points: Sequence[np.ndarray]) -> list[pin.SE3]:
    """Placements, relative to their joints, of world-aligned frames at world ``points`` (m, 3) [m]."""
    return [pin.SE3(_IDENTITY, data.oMi[j].actInv(p)) for j, p in zip(joints, points)]


def point_jacobians(
    model: pin.Model, data: pin.Data, joints: list[int], placements: list[pin.SE3]
) -> np.ndarray:
    """Jacobians of the world velocities of body points, shape (m, 3, nv).

    Args:
        placements: the points as :func:`point_placements` gives them.
    """
    return np.array([pin.getFrameJacobian(model, data, j, M, LWA)[:3] for j, M in zip(joints, placements)])


def point_drifts(
    model: pin.Model, data: pin.Data, joints: list[int], placements: list[pin.SE3]
) -> np.ndarray:
    """Classical accelerations of body points at zero joint acceleration (Jdot v), shape (m, 3) [m/s^2].

    Needs the spatial accelerations of a forward pass with a = 0 (``compute_dynamics(drifts=True)``).
    """
    return np.array(
        [pin.getFrameClassicalAcceleration(model, data, j, M, LWA).linear for j, M in zip(joints, placements)]
    )
