"""Compiled kernels of the dynamics stage (:mod:`gaussim.dynamics`): the free motion's linear term, the
floating bases' terms, point Jacobians."""

from __future__ import annotations

import numpy as np
from numba import njit

from ..linalg import cross, dot, finite, solve3


@njit(cache=True, fastmath={"reassoc", "contract"})
def factored_terms(M, U, D, parents, subtree, v, tau, nle, dt, acceleration, bases, inertias, rigid, x):  # type: ignore[no-untyped-def]
    """The free motion x (nv,) and the linear term g (returned; None when tau is not finite) of a dense
    M with its factors M = U D U^T (Pinocchio's cholesky::decompose, on the joint tree ``parents``,
    ``subtree``, see :func:`structured_solve`): f = M v + dt F at the velocity level, F at the
    acceleration level, F = tau - nle; x = M^-1 f, the floating ``bases`` posed as
    :func:`floating_terms` poses them; g = -M x (-f without bases), in one call."""
    n = len(v)
    f = np.empty(n)
    for i in range(n):
        if not np.isfinite(tau[i]):
            return None
        f[i] = tau[i] - nle[i]
    if not acceleration:
        for i in range(n):
            f[i] = dot(M[i], v) + dt * f[i]
    factored_solve(U, D, parents, subtree, f, x)
    if not len(bases):  # x = M^-1 f is the solution: g = -f
        for i in range(n):
            f[i] = -f[i]
        return f
    floating_terms(v, x, dt, acceleration, bases, inertias, rigid)
    for i in range(n):
        f[i] = -dot(M[i], x)
    return f


@njit(cache=True)
def free_velocity(v, a_free, dt, out, bases, inertias, rigid):  # type: ignore[no-untyped-def]
    """out = v + dt a_free, the next velocity when nothing restricts the motion, with the floating bases
    posed as :func:`floating_terms` poses them; returns the reach sum_i |v_i| + |out_i| (see
    gaussim.dynamics.DynamicsStage.reach), NaN when out is not finite."""
    for i in range(len(v)):
        out[i] = v[i] + dt * a_free[i]
    floating_terms(v, out, dt, False, bases, inertias, rigid)
    reach = 0.0
    for i in range(len(v)):
        reach += abs(v[i]) + abs(out[i])
    return reach if finite(out) else np.nan


# Newton iterations of a rigid base's midpoint gyroscopic term stop below this relative change.
_MIDPOINT_TOLERANCE = 1e-15


@njit(cache=True)
def floating_terms(v, x, dt, acceleration, bases, inertias, rigid):  # type: ignore[no-untyped-def]
    """Pose the free solution x of the floating ``bases`` (first velocity indices) as
    :class:`gaussim.dynamics.FloatingBases` says, in place: x = v + dt a (velocity level) or x = a
    (``acceleration`` level) from ABA's a, time step ``dt`` [s]. ``inertias`` (k, 3, 3) and ``rigid``
    (k,) as there."""
    h = 1.0 if acceleration else dt
    for k in range(len(bases)):
        i = bases[k]
        w0, w1, w2 = v[i + 3], v[i + 4], v[i + 5]
        x[i] += h * (w1 * v[i + 2] - w2 * v[i + 1])  # + w x v_l: the frame's turn leaves the acceleration
        x[i + 1] += h * (w2 * v[i] - w0 * v[i + 2])
        x[i + 2] += h * (w0 * v[i + 1] - w1 * v[i])
        if rigid[k]:
            t0, t1, t2 = x[i + 3], x[i + 4], x[i + 5]
            if acceleration:
                u0, u1, u2 = midpoint_turn(inertias[k], w0, w1, w2, dt * t0, dt * t1, dt * t2, dt)
                x[i + 3], x[i + 4], x[i + 5] = u0 / dt, u1 / dt, u2 / dt
            else:
                u0, u1, u2 = midpoint_turn(inertias[k], w0, w1, w2, t0 - w0, t1 - w1, t2 - w2, dt)
                x[i + 3], x[i + 4], x[i + 5] = w0 + u0, w1 + u1, w2 + u2


@njit(cache=True)
def midpoint_turn(I, w0, w1, w2, u0, u1, u2, dt):  # type: ignore[no-untyped-def]
    """The change u of a rigid body's angular velocity w [rad/s] in a step dt [s] with the gyroscopic
    term at the midpoint, I u = dt tau - dt w_m x I w_m, w_m = w + u / 2, from the explicit change u
    (whose torque is dt tau = I u + dt w x I w); Newton's method on the 3 x 3 system. In scalars, as
    tuples."""
    a0, a1, a2 = _times(I, u0, u1, u2)
    b0, b1, b2 = _times(I, w0, w1, w2)
    c0, c1, c2 = cross(w0, w1, w2, b0, b1, b2)
    rhs0, rhs1, rhs2 = a0 + dt * c0, a1 + dt * c1, a2 + dt * c2
    K = np.empty((3, 3))
    for _ in range(20):
        m0, m1, m2 = w0 + 0.5 * u0, w1 + 0.5 * u1, w2 + 0.5 * u2
        n0, n1, n2 = _times(I, m0, m1, m2)
        a0, a1, a2 = _times(I, u0, u1, u2)
        c0, c1, c2 = cross(m0, m1, m2, n0, n1, n2)
        r0, r1, r2 = a0 + dt * c0 - rhs0, a1 + dt * c1 - rhs1, a2 + dt * c2 - rhs2
        # d r / d u = I + dt / 2 ([w_m]x I - [I w_m]x), column by column
        for c in range(3):
            e0, e1, e2 = cross(
                1.0 if c == 0 else 0.0, 1.0 if c == 1 else 0.0, 1.0 if c == 2 else 0.0, n0, n1, n2
            )
            f0, f1, f2 = cross(m0, m1, m2, I[0, c], I[1, c], I[2, c])
            K[0, c] = I[0, c] + 0.5 * dt * (e0 + f0)
            K[1, c] = I[1, c] + 0.5 * dt * (e1 + f1)
            K[2, c] = I[2, c] + 0.5 * dt * (e2 + f2)
        s0, s1, s2 = solve3(K, r0, r1, r2)
        u0, u1, u2 = u0 - s0, u1 - s1, u2 - s2
        size = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2) + np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
        if np.sqrt(s0 * s0 + s1 * s1 + s2 * s2) <= _MIDPOINT_TOLERANCE * size:
            break
    return u0, u1, u2


@njit(cache=True, inline="always")
def _times(I, x0, x1, x2):  # type: ignore[no-untyped-def]
    """I x for I (3, 3) and x = (x0, x1, x2), as a tuple."""
    return (
        I[0, 0] * x0 + I[0, 1] * x1 + I[0, 2] * x2,
        I[1, 0] * x0 + I[1, 1] * x1 + I[1, 2] * x2,
        I[2, 0] * x0 + I[2, 1] * x1 + I[2, 2] * x2,
    )


@njit(cache=True)
def mirrored(upper, subtree, M):  # type: ignore[no-untyped-def]
    """M (nv, nv) mirrored from the upper triangle of ``upper`` (Pinocchio's data.M after its C++
    CRBA) on M's joint structure, the only entries read and written: ``subtree[i]`` is how many
    coordinates from i on move with coordinate i (Pinocchio's nvSubtree_fromRow)."""
    for i in range(len(subtree)):
        for j in range(i, i + subtree[i]):
            M[i, j] = M[j, i] = upper[i, j]


@njit(cache=True)
def structured_terms(upper, subtree, v, tau, nle, dt, M, f):  # type: ignore[no-untyped-def]
    """M :func:`mirrored` from ``upper`` on its joint structure, and f there (:func:`momentum_terms`)."""
    mirrored(upper, subtree, M)
    return momentum_terms(M, subtree, v, tau, nle, dt, f)


@njit(cache=True)
def momentum_terms(M, subtree, v, tau, nle, dt, f):  # type: ignore[no-untyped-def]
    """f = M v + dt F (F at dt = 0), F = tau - nle, on M's joint structure; False when tau is not
    finite."""
    for i in range(len(nle)):
        if not np.isfinite(tau[i]):
            return False
        f[i] = tau[i] - nle[i]
    if dt > 0:
        Mv = structured_product(M, subtree, v)
        for i in range(len(f)):
            f[i] = Mv[i] + dt * f[i]
    return True


@njit(cache=True)
def armed(M, U, D, parents, subtree, armature):  # type: ignore[no-untyped-def]
    """A constant M and its factors U, D (:func:`structured_factor`) with the model's armature:
    ``armature`` = (the model's, the one M holds, M's diagonal without it); where the model's differs
    (an implicit damping came or went), M's diagonal takes it and M is factored again."""
    now, held, bare = armature
    changed = False
    for i in range(len(now)):
        if now[i] != held[i]:
            held[i], M[i, i], changed = now[i], bare[i] + now[i], True
    if changed:
        structured_factor(M, parents, subtree, U, D)


@njit(cache=True)
def constant_terms(
    M, U, D, parents, subtree, armature, v, tau, nle, dt, acceleration, bases, inertias, rigid, x
):  # type: ignore[no-untyped-def]
    """The free motion x (nv,) and the linear term g = -M x (returned; None when tau is not finite) of
    a constant M on its structure and factors U, D (:func:`structured_factor`): f as
    :func:`momentum_terms`, x = M^-1 f, the floating ``bases`` posed as :func:`floating_terms`
    poses them, in one call, after :func:`armed`."""
    armed(M, U, D, parents, subtree, armature)
    f = np.empty(len(v))
    if not momentum_terms(M, subtree, v, tau, nle, 0.0 if acceleration else dt, f):
        return None
    factored_solve(U, D, parents, subtree, f, x)
    floating_terms(v, x, dt, acceleration, bases, inertias, rigid)
    return -structured_product(M, subtree, x)


@njit(cache=True)
def structured_product(M, subtree, x):  # type: ignore[no-untyped-def]
    """M x for M on its joint structure (see :func:`structured_terms`): O(its nonzeros)."""
    y = np.zeros(len(x))
    for i in range(len(x)):
        y[i] += M[i, i] * x[i]
        for j in range(i + 1, i + subtree[i]):
            y[i] += M[i, j] * x[j]
            y[j] += M[i, j] * x[i]
    return y


@njit(cache=True)
def structured_solve(M, parents, subtree, f, U, D, x):  # type: ignore[no-untyped-def]
    """x = M^-1 f by M = U D U^T, U unit upper triangular with M's sparsity (Featherstone's LTDL, in
    Pinocchio's cholesky::decompose order; ``parents[i]``: the coordinate moving coordinate i's joint
    before it, -1 at a root, Pinocchio's parents_fromRow); ``U`` (nv, nv) and ``D`` (nv,) are
    overwritten on the structure only (:func:`structured_factor`, then :func:`factored_solve`)."""
    structured_factor(M, parents, subtree, U, D)
    factored_solve(U, D, parents, subtree, f, x)


@njit(cache=True)
def structured_factor(M, parents, subtree, U, D):  # type: ignore[no-untyped-def]
    """M = U D U^T on M's structure, into ``U`` and ``D`` (see :func:`structured_solve`)."""
    nv = len(D)
    for j in range(nv - 1, -1, -1):
        end = j + subtree[j]
        D[j] = M[j, j]
        for k in range(j + 1, end):
            D[j] -= U[j, k] * D[k] * U[j, k]
        i = parents[j]
        while i >= 0:
            total = M[i, j]
            for k in range(j + 1, end):
                total -= U[i, k] * D[k] * U[j, k]
            U[i, j] = total / D[j]
            i = parents[i]


@njit(cache=True)
def factored_solve(U, D, parents, subtree, f, x):  # type: ignore[no-untyped-def]
    """x = M^-1 f on the factors M = U D U^T of :func:`structured_factor`."""
    nv = len(f)
    for j in range(nv):
        x[j] = f[j]
    for j in range(nv - 1, -1, -1):  # U y = f
        for k in range(j + 1, j + subtree[j]):
            x[j] -= U[j, k] * x[k]
    for j in range(nv):
        x[j] /= D[j]
    for j in range(nv):  # U^T x = y
        i = parents[j]
        while i >= 0:
            x[j] -= U[i, j] * x[i]
            i = parents[i]


@njit(cache=True)
def frame_accelerations(v, bases, out):  # type: ignore[no-untyped-def]
    """Each base's -w x v_l into ``out`` at its linear velocity coordinates (``bases``: their first
    index), zero elsewhere (see :meth:`gaussim.dynamics.FloatingBases.frame_acceleration`)."""
    out[:] = 0.0
    for i in bases:
        w0, w1, w2, u0, u1, u2 = v[i + 3], v[i + 4], v[i + 5], v[i], v[i + 1], v[i + 2]
        out[i], out[i + 1], out[i + 2] = w2 * u1 - w1 * u2, w0 * u2 - w2 * u0, w1 * u0 - w0 * u1


@njit(cache=True)
def negated_product(M, x):  # type: ignore[no-untyped-def]
    """-M x."""
    result = np.empty(M.shape[0])
    for i in range(M.shape[0]):
        result[i] = -dot(M[i], x)
    return result


@njit(cache=True)
def point_jacobians_into(out, J, masks, starts, columns, joints, other_joints, points):  # type: ignore[no-untyped-def]
    """:func:`gaussim.dynamics.point_jacobians` from the joint Jacobians J (6, nv), written into
    ``out`` (m, 3, nv): zero but on the columns of the two joints' supports (``masks``, ``starts``,
    ``columns``: :class:`gaussim.dynamics.Supports`)."""
    for i in range(len(joints)):
        a, b = joints[i], other_joints[i]
        out[i] = 0.0
        for joint in (a, b):
            for c in range(starts[joint], starts[joint + 1]):
                k = columns[c]
                moving = masks[a, k] - masks[b, k]  # 0 on the chain the two share
                x, y, z = point_column(J, k, points[i])
                out[i, 0, k], out[i, 1, k], out[i, 2, k] = moving * x, moving * y, moving * z


@njit(cache=True, inline="always")
def point_column(J, k, point):  # type: ignore[no-untyped-def]
    """Column k of the Jacobian of the world velocity of ``point`` (3,) moving with a body whose
    joint Jacobian holds column k of J (6, nv, WORLD): v_O + w x p."""
    px, py, pz = point[0], point[1], point[2]
    return (
        J[0, k] + J[4, k] * pz - J[5, k] * py,
        J[1, k] + J[5, k] * px - J[3, k] * pz,
        J[2, k] + J[3, k] * py - J[4, k] * px,
    )


@njit(cache=True, inline="always")
def support_dot(row, x, starts, columns, a, b):  # type: ignore[no-untyped-def]
    """row . x for a row that is zero off the supports of joints a and b (a point Jacobian's row: a
    column both hold is zero in it, so counting it twice adds nothing)."""
    total = 0.0
    for c in range(starts[a], starts[a + 1]):
        total += row[columns[c]] * x[columns[c]]
    for c in range(starts[b], starts[b + 1]):
        total += row[columns[c]] * x[columns[c]]
    return total


@njit(cache=True)
def unloaded(J, multipliers, velocity, free):  # type: ignore[no-untyped-def]
    """Clear ``free[k]`` for each base k (its velocity at ``velocity[k]``) that a row of J with a
    nonzero multiplier reads."""
    for r in range(len(multipliers)):
        if multipliers[r] == 0.0:
            continue
        for k in range(len(velocity)):
            if free[k]:
                for i in range(velocity[k], velocity[k] + 6):
                    if J[r, i] != 0.0:
                        free[k] = False
                        break


@njit(cache=True)
def loaded(joints, multipliers, of_joint, free):  # type: ignore[no-untyped-def]
    """Clear ``free[k]`` for each base k (``of_joint``: each joint's base, -1 for none) that one of the
    two joints ``joints[r]`` of a row with a nonzero multiplier is."""
    for r in range(len(multipliers)):
        if multipliers[r] != 0.0:
            for j in (joints[r, 0], joints[r, 1]):
                if of_joint[j] >= 0:
                    free[of_joint[j]] = False
