"""Compiled kernels of the integrator (:mod:`gaussim.integrator`): the displacement (with the free
bodies' midpoint turns), the floating bases' moves."""

from __future__ import annotations

import numpy as np
from numba import njit

from ..linalg import finite


@njit(cache=True)
def displacement(v, v_next, dt, velocity, free, out):  # type: ignore[no-untyped-def]
    """out = dt v_next, with each ``free`` base's turn (bases ``velocity``'s first coordinates) the
    rotation vector of the Cayley map of dt w_m, 2 atan(dt |w_m| / 2) w_m / |w_m|, w_m the midpoint
    of v's and v_next's angular velocities; False when v_next is not finite."""
    for i in range(len(v_next)):
        out[i] = dt * v_next[i]
    for k in range(len(free)):
        if free[k]:
            i = velocity[k] + 3
            m0, m1, m2 = (
                0.5 * (v[i] + v_next[i]),
                0.5 * (v[i + 1] + v_next[i + 1]),
                0.5 * (v[i + 2] + v_next[i + 2]),
            )
            speed = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
            if speed > 0.0:
                scale = 2.0 * np.arctan(0.5 * dt * speed) / speed
                out[i], out[i + 1], out[i + 2] = scale * m0, scale * m1, scale * m2
    return finite(v_next)


@njit(cache=True)
def move_bases(q, q_next, v, dt, configuration, velocity):  # type: ignore[no-untyped-def]
    """For each floating base: q_next's origin = q's + dt R v_l (R the frame of q), and v_l, in place,
    re-expressed in q_next's frame (R_next^T R v_l). In scalars: this runs every step."""
    for k in range(len(configuration)):
        p, i = configuration[k], velocity[k]
        x, y, z = _turned(q[p + 3 : p + 7], v[i], v[i + 1], v[i + 2], 1.0)
        q_next[p] = q[p] + dt * x
        q_next[p + 1] = q[p + 1] + dt * y
        q_next[p + 2] = q[p + 2] + dt * z
        v[i], v[i + 1], v[i + 2] = _turned(q_next[p + 3 : p + 7], x, y, z, -1.0)


@njit(cache=True, inline="always")
def _turned(quaternion, x, y, z, sign):  # type: ignore[no-untyped-def]
    """The vector (x, y, z) turned by the unit quaternion (qx, qy, qz, qw) (Pinocchio's order), or by
    its inverse for sign -1: v + 2 w (u x v) + 2 u x (u x v), u the quaternion's vector part."""
    ux, uy, uz, w = sign * quaternion[0], sign * quaternion[1], sign * quaternion[2], quaternion[3]
    cx, cy, cz = uy * z - uz * y, uz * x - ux * z, ux * y - uy * x
    return (
        x + 2.0 * (w * cx + uy * cz - uz * cy),
        y + 2.0 * (w * cy + uz * cx - ux * cz),
        z + 2.0 * (w * cz + ux * cy - uy * cx),
    )
