"""Compiled kernels of the contact rows (:mod:`gaussim.constraints.contact`), and the rules every
module's unilateral rows share (:func:`bound_of`, :func:`restricts`) with the joint limits' pass
(:mod:`gaussim.constraints.limits`) that reads them."""

from __future__ import annotations

import numpy as np
from numba import njit, vectorize

from ..linalg import cross, dot, solve
from .dynamics import point_jacobians_into, support_dot
from .solver import active_floor, bound_response

# A unilateral row's gap within this is contact at the velocity level (the row keeps it, closing none
# and pushing out none): a resting contact's gap carries the narrowphase's round-off, 1e-10 to 1e-9 m
# between capsules and boxes, which a closing row turned into gap / dt of jitter [m or rad].
GAP_TOLERANCE = 1e-8


@vectorize(["float64(int64, float64, float64, float64, float64, float64, boolean)"], cache=True)
def bound_of(level, dt, stabilisation, phi, rate, drift, unilateral):  # type: ignore[no-untyped-def]
    """:func:`gaussim.constraints.base.stabilised_bound` for a level code (its LEVELS), elementwise;
    callable from compiled code."""
    if level == 0:
        if unilateral and abs(phi) <= GAP_TOLERANCE:  # touching: its gap is the narrowphase's round-off
            return 0.0
        return -(1.0 / dt if phi >= 0 and unilateral else stabilisation / dt) * phi
    if level == 1:
        return 0.0
    gain = stabilisation / dt
    return -drift - 2.0 * gain * rate - gain * gain * phi


@njit(cache=True, inline="always")
def restricts(level, phi, rate, dt, margin, tolerance, threshold):  # type: ignore[no-untyped-def]
    """:func:`gaussim.constraints.base.is_active` for one constraint at a level code (its LEVELS);
    callable from compiled code."""
    closing = phi + dt * min(rate, 0.0)  # min(NaN, 0) is NaN: a NaN rate is inactive, as in numpy
    if level == 0:
        return closing <= margin
    return closing <= tolerance and (rate <= threshold or phi < -tolerance)


@njit(cache=True)
def restricting(level, phi, rate, dt, margin, tolerance, threshold):  # type: ignore[no-untyped-def]
    """:func:`restricts` of each constraint (phi, rate (k,)), shape (k,)."""
    result = np.empty(len(phi), np.bool_)
    for i in range(len(phi)):
        result[i] = restricts(level, phi[i], rate[i], dt, margin, tolerance, threshold)
    return result


@njit(cache=True)
def near_limits(q, v, idx_q, idx_v, signs, limits, level, settings, active, bound):  # type: ignore[no-untyped-def]
    """The joint limits that restrict x at ``level`` (:func:`restricts` of phi = sign (q[idx_q] - limit)
    and its rate sign v[idx_v]): their indices into ``active`` and their rows' bounds (:func:`bound_of`)
    into ``bound``; returns their number. ``settings``: (dt, margin, tolerance, threshold,
    stabilisation). (In scalars: this runs every step of a robot with limits.)"""
    dt, margin, tolerance, threshold, stabilisation = settings
    count = 0
    for i in range(len(signs)):
        phi = signs[i] * (q[idx_q[i]] - limits[i])
        rate = signs[i] * v[idx_v[i]]
        if restricts(level, phi, rate, dt, margin, tolerance, threshold):
            active[count] = i
            bound[count] = bound_of(level, dt, stabilisation, phi, rate, 0.0, True)
            count += 1
    return count


# Below this tangential speed a contact sticks: no sliding force at the acceleration level, no De
# Saxce shift (a lagged slip that small is the step's own error, which mu would amplify) [m/s].
SLIP_SPEED = 1e-4
# Below this free tangential speed a contact's pyramid takes the fixed basis of its normal, not the
# slip's direction: a resting contact's free slip is round-off (1e-17 to 1e-8 m/s in a settled bin),
# whose direction would turn its rows at every step, and so the active set of its QP [m/s].
ALIGN_SPEED = 1e-6


@njit(cache=True)
def unpacked(packed, m, nv):  # type: ignore[no-untyped-def]
    """Views of the buffer :func:`pyramids` fills: J (m, 3, nv), generators (R, 3), slip (m, 3),
    friction (m, 3)."""
    rows = (len(packed) - 3 * m * nv - 6 * m) // 3
    a = 3 * m * nv  # where each part ends
    b = a + 3 * rows
    c = b + 3 * m
    return (
        packed[:a].reshape((m, 3, nv)),
        packed[a:b].reshape((rows, 3)),
        packed[b:c].reshape((m, 3)),
        packed[c : c + 3 * m].reshape((m, 3)),
    )


@njit(cache=True)
def pyramids(  # type: ignore[no-untyped-def]
    joint_jacobians,
    masks,
    support_starts,
    support_columns,
    joints,
    other_joints,
    points,
    v,
    x_free,
    drift,
    normal,
    gap,
    mu,
    e,
    slips,
    stops,
    normal_forces,
    level,
    cos,
    sin,
    pyramid,
    bounds,
    rows,
    bound,
    packed,
    starts,
    read,
):
    """Every contact's rows, as :mod:`gaussim.constraints.contact` poses them, in one pass.

    Args:
        joint_jacobians, masks, support_starts, support_columns, joints, other_joints, points: what
            :func:`gaussim.dynamics.point_jacobians` reads (a contact's rows are zero off its
            joints' supports, and only those columns are computed).
        v: the velocity (nv,); x_free: the unconstrained solution (nv,);
        drift: Jdot v of the contacts at the acceleration level, else zeros, (m, 3).
        slips: the lagged slip of each contact (m, 3), NaN where there is none (use the current one).
        stops, normal_forces: acceleration-level sliding: contacts that stick instead, lagged lambda_n.
        level: 0 velocity, 1 impulse, 2 acceleration; pyramid: fixed basis and no De Saxce shift.
        bounds: (dt, stabilisation, restitution_threshold).

    Fills the first R rows of ``rows`` (m facets, nv) and ``bound`` (m facets,), the first entries of
    ``packed`` (the buffer :func:`unpacked` reads: point Jacobians, generators, slip used, friction
    force; room for m facets rows), ``starts`` (m + 1,) (the first row of each contact, then R) and
    ``read`` (m facets, 2) (the two joints each row reads);
    the caller allocates them, which costs less than a kernel's new arrays.

    Returns:
        R, and, when a contact gets an explicit friction force (acceleration-level sliding), which ones
        (m,) and that force's generalized force (nv,), else None and None.
    """
    dt, stabilisation, threshold = bounds
    m, nv, facets = len(joints), len(v), len(cos)
    acceleration = level == 2
    J = packed[: 3 * m * nv].reshape((m, 3, nv))  # the buffer's first part, whatever R is
    point_jacobians_into(
        J, joint_jacobians, masks, support_starts, support_columns, joints, other_joints, points
    )
    starts[0], sliding, any_sliding = 0, np.zeros(m, np.bool_), False
    contact_bound, slip_used, u, free = np.empty(m), np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3))
    for i in range(m):
        n0, n1, n2 = normal[i, 0], normal[i, 1], normal[i, 2]
        a, b = joints[i], other_joints[i]
        for j in range(3):
            u[i, j] = support_dot(J[i, j], v, support_starts, support_columns, a, b)
            free[i, j] = support_dot(J[i, j], x_free, support_starts, support_columns, a, b)
        u0, u1, u2 = u[i, 0], u[i, 1], u[i, 2]
        u_n = u0 * n0 + u1 * n1 + u2 * n2
        if acceleration or np.isnan(slips[i, 0]):  # the current slip
            slip_used[i, 0], slip_used[i, 1], slip_used[i, 2] = u0 - u_n * n0, u1 - u_n * n1, u2 - u_n * n2
        else:
            slip_used[i, 0], slip_used[i, 1], slip_used[i, 2] = slips[i, 0], slips[i, 1], slips[i, 2]
        speed = np.sqrt(slip_used[i, 0] ** 2 + slip_used[i, 1] ** 2 + slip_used[i, 2] ** 2)
        sliding[i] = acceleration and mu[i] > 0 and speed > SLIP_SPEED and not stops[i]
        any_sliding |= sliding[i]
        starts[i + 1] = starts[i] + (1 if mu[i] == 0 or sliding[i] else facets)
        contact_bound[i] = bound_of(level, dt, stabilisation, gap[i], 0.0, 0.0, True)
        if not acceleration:
            # restitution: an approaching contact that closes within the step leaves at -e u_n at least
            # (velocity level: under the free motion, as the margin finds contacts earlier; impulse level:
            # every contact here, is_active's closing test chose them); De Saxce shift mu |slip|
            closes = level == 1 or gap[i] + dt * (n0 * free[i, 0] + n1 * free[i, 1] + n2 * free[i, 2]) <= 0.0
            if e[i] > 0 and -u_n > threshold and closes:
                contact_bound[i] = max(contact_bound[i], -e[i] * u_n)
            if not pyramid:  # the De Saxce shift (none below SLIP_SPEED: such a contact sticks)
                contact_bound[i] -= mu[i] * _shift_speed(speed)
    total = starts[m]
    J, generators, slip, friction = unpacked(packed[: 3 * m * nv + 3 * total + 6 * m], m, nv)
    for i in range(m):
        for j in range(3):
            slip[i, j], friction[i, j] = slip_used[i, j], 0.0
    force = np.zeros(nv)
    for i in range(m):
        n0, n1, n2 = normal[i, 0], normal[i, 1], normal[i, 2]
        r, count = starts[i], starts[i + 1] - starts[i]
        if sliding[
            i
        ]:  # explicit Coulomb force opposite the slip, lambda_n iterated (gaussim.constraints.contact)
            speed = np.sqrt(slip[i, 0] ** 2 + slip[i, 1] ** 2 + slip[i, 2] ** 2)
            for j in range(3):
                friction[i, j] = -mu[i] * normal_forces[i] / speed * slip[i, j]
                for side in (joints[i], other_joints[i]):  # twice on a shared column, where J is 0
                    for c in range(support_starts[side], support_starts[side + 1]):
                        k = support_columns[c]
                        force[k] += friction[i, j] * J[i, j, k]
        if count == 1:  # the normal row alone
            generators[r, 0], generators[r, 1], generators[r, 2] = n0, n1, n2
        else:  # friction opposes the tangential velocity the contact would have without it
            # (acceleration level: the acceleration that keeps it, plus the one that stops it in the step)
            d0, d1, d2 = free[i, 0] + drift[i, 0], free[i, 1] + drift[i, 1], free[i, 2] + drift[i, 2]
            if acceleration:
                d0, d1, d2 = d0 + u[i, 0] / dt, d1 + u[i, 1] / dt, d2 + u[i, 2] / dt
            along = d0 * n0 + d1 * n1 + d2 * n2
            t0, t1, t2 = -d0 + along * n0, -d1 + along * n1, -d2 + along * n2
            norm = np.sqrt(t0**2 + t1**2 + t2**2)
            if pyramid or norm * (dt if acceleration else 1.0) <= ALIGN_SPEED:
                # a fixed basis: n x (the axis of n's smallest component)
                a0, a1, a2 = abs(n0), abs(n1), abs(n2)
                if a0 <= a1 and a0 <= a2:
                    t0, t1, t2 = cross(n0, n1, n2, 1.0, 0.0, 0.0)
                elif a1 <= a2:
                    t0, t1, t2 = cross(n0, n1, n2, 0.0, 1.0, 0.0)
                else:
                    t0, t1, t2 = cross(n0, n1, n2, 0.0, 0.0, 1.0)
                norm = np.sqrt(t0**2 + t1**2 + t2**2)
            t0, t1, t2 = t0 / norm, t1 / norm, t2 / norm
            s0, s1, s2 = cross(n0, n1, n2, t0, t1, t2)
            for k in range(count):
                generators[r + k, 0] = n0 + mu[i] * (cos[k] * t0 + sin[k] * s0)
                generators[r + k, 1] = n1 + mu[i] * (cos[k] * t1 + sin[k] * s1)
                generators[r + k, 2] = n2 + mu[i] * (cos[k] * t2 + sin[k] * s2)
        for k in range(count):
            read[r + k, 0], read[r + k, 1] = joints[i], other_joints[i]
            g = generators[r + k]
            rows[r + k] = 0.0
            for side in (joints[i], other_joints[i]):
                for c in range(support_starts[side], support_starts[side + 1]):
                    col = support_columns[c]
                    rows[r + k, col] = g[0] * J[i, 0, col] + g[1] * J[i, 1, col] + g[2] * J[i, 2, col]
            if acceleration:  # the row's drift; Baumgarte on the normal rate, the slip stopped in the step
                u_n = n0 * u[i, 0] + n1 * u[i, 1] + n2 * u[i, 2]
                slip_rate = g[0] * u[i, 0] + g[1] * u[i, 1] + g[2] * u[i, 2] - u_n
                row_drift = g[0] * drift[i, 0] + g[1] * drift[i, 1] + g[2] * drift[i, 2]
                normal_bound = bound_of(level, dt, stabilisation, gap[i], u_n, row_drift, True)
                bound[r + k] = normal_bound - slip_rate / dt
            else:
                bound[r + k] = contact_bound[i]
    if any_sliding:
        return total, sliding, force
    return total, None, None


@njit(cache=True)
def slips(
    packed,
    slip,
    starts,
    x,
    normal,
    mu,
    rows,
    bound,
    joints,
    other_joints,
    support_starts,
    support_columns,
    start,
):  # type: ignore[no-untyped-def]
    """(the slips (m, 3) of solution x for the contacts that refine their shift (one with a full
    pyramid) and are moving (a sticking contact has no shift to refine), the others' unchanged; the
    largest error of the shifted bounds: mu times the change of a contact's slip speed (all the
    shift reads; its cut below SLIP_SPEED adds at most mu SLIP_SPEED, which passes would not remove),
    less the slack its rows ``rows`` x >= ``bound`` leave at x (a bound that moves within its row's
    slack leaves x the solution). ``packed`` and ``starts`` are :func:`pyramids`', the rest what it
    reads, ``slip`` (m, 3) the slips the QP's shift used. Fills ``start`` (m, 3), the slips a next
    solve starts from: zero for the contacts that stick (those slips within SLIP_SPEED), NaN (the
    current one) for the others, and returns whether any sticks. (In scalars, no array per contact:
    this runs after every QP with friction.)"""
    J = unpacked(packed, len(normal), len(x))[0]
    result, residual, stuck = slip.copy(), 0.0, False
    for i in range(len(slip)):
        a, b = joints[i], other_joints[i]
        moving, speed, u0, u1, u2 = _moving_slip(
            J, slip, starts, x, normal, i, support_starts, support_columns, a, b
        )
        if moving:
            error = mu[i] * abs(np.sqrt(u0**2 + u1**2 + u2**2) - speed)
            if error > residual:
                slack = np.inf
                for r in range(starts[i], starts[i + 1]):
                    slack = min(
                        slack, support_dot(rows[r], x, support_starts, support_columns, a, b) - bound[r]
                    )
                residual = max(residual, error - max(slack, 0.0))
            result[i, 0], result[i, 1], result[i, 2] = u0, u1, u2
        sticks = result[i, 0] ** 2 + result[i, 1] ** 2 + result[i, 2] ** 2 <= SLIP_SPEED**2
        start[i, 0] = start[i, 1] = start[i, 2] = 0.0 if sticks else np.nan
        stuck |= sticks
    return result, residual, stuck


@njit(cache=True, inline="always")
def _moving_slip(J, slip, starts, x, normal, i, support_starts, support_columns, a, b):  # type: ignore[no-untyped-def]
    """(whether contact i refines its shift and its tangential velocity in solution x or its last
    slip is moving, that slip's speed, that velocity's 3 components)."""
    if starts[i + 1] - starts[i] == 1:
        return False, 0.0, 0.0, 0.0, 0.0
    u0, u1, u2 = (
        support_dot(J[i, 0], x, support_starts, support_columns, a, b),
        support_dot(J[i, 1], x, support_starts, support_columns, a, b),
        support_dot(J[i, 2], x, support_starts, support_columns, a, b),
    )
    along = u0 * normal[i, 0] + u1 * normal[i, 1] + u2 * normal[i, 2]
    u0, u1, u2 = u0 - along * normal[i, 0], u1 - along * normal[i, 1], u2 - along * normal[i, 2]
    speed = np.sqrt(slip[i, 0] ** 2 + slip[i, 1] ** 2 + slip[i, 2] ** 2)
    return speed > SLIP_SPEED or np.sqrt(u0**2 + u1**2 + u2**2) > SLIP_SPEED, speed, u0, u1, u2


@njit(cache=True)
def secant_moves(used, mapped, move, previous, scales, moved, residual):  # type: ignore[no-untyped-def]
    """:func:`gaussim.constraints.contact._secant` in scalars: fills ``residual`` (m, 3) with
    F(s) - s (``mapped`` - ``used``) and ``moved`` with each contact's step, that residual scaled by
    1 / (1 - a) within ``scales``, a the slope of its map along the last pass's ``move`` (whose
    residual was ``previous``; both empty at the first pass: no scaling)."""
    low, high = scales
    for i in range(used.shape[0]):
        r0, r1, r2 = mapped[i, 0] - used[i, 0], mapped[i, 1] - used[i, 1], mapped[i, 2] - used[i, 2]
        scale = 1.0
        if move.shape[0]:
            m0, m1, m2 = move[i, 0], move[i, 1], move[i, 2]
            length = m0 * m0 + m1 * m1 + m2 * m2
            if length > 0.0:  # F(s_k) - F(s_k-1) = residual + move - previous, along the move
                slope = (
                    (r0 + m0 - previous[i, 0]) * m0
                    + (r1 + m1 - previous[i, 1]) * m1
                    + (r2 + m2 - previous[i, 2]) * m2
                ) / length
                scale = min(max(1.0 / max(1.0 - slope, 1e-12), low), high)
        residual[i, 0], residual[i, 1], residual[i, 2] = r0, r1, r2
        moved[i, 0], moved[i, 1], moved[i, 2] = scale * r0, scale * r1, scale * r2


@njit(cache=True)
def newton_moves(H, A, C, z, floor, first, starts, packed, mu, used, mapped, scales, moved):  # type: ignore[no-untyped-def]
    """Replaces in ``moved`` (m, 3) the step of each contact that slides at the solution (its slip
    ``mapped``, from the slips ``used``) and holds a row active (its multiplier in ``z`` above
    ``floor`` times the largest) by a Newton step on the De Saxce fixed point of those contacts'
    shifts sigma = mu |slip| (see :func:`gaussim.constraints.contact._secant`): with their rows kept
    active, sigma_i maps to mu_i t_i^T J_i x(sigma), t_i the slip's direction, whose Jacobian is
    -mu_i R with R of :func:`~gaussim.kernels.solver.bound_response` (a contact's rows read
    x >= b - sigma_i), so the step solves (I + diag(mu) R) d = F(sigma) - sigma. A contact takes its
    d_i where that scales its residual within ``scales``, else keeps its ``moved`` (where the passes'
    active set changes, which the Jacobian does not see, d_i can point away from the residual). The
    problem (H, A, C) is the QP's; contact i's rows are rows first + starts[i] to first + starts[i + 1]
    of C; ``packed`` is :func:`pyramids`'. False, ``moved`` untouched, when H is not positive definite
    or I + diag(mu) R is singular."""
    m, nv = len(mu), H.shape[0]
    J = unpacked(packed, m, nv)[0]
    least = active_floor(z, floor)
    chosen, group = np.empty(m, np.int64), np.full(len(z), -1)
    k = 0
    for i in range(m):
        speed = np.sqrt(dot(mapped[i], mapped[i]))
        if starts[i + 1] - starts[i] == 1 or not speed > SLIP_SPEED:
            continue
        rows = range(first + starts[i], first + starts[i + 1])
        held = False
        for r in rows:
            held |= z[r] > least
        if held:
            for r in rows:
                group[r] = k
            chosen[k], k = i, k + 1
    if k == 0:
        return True
    V = np.zeros((k, nv))  # t_i^T J_i
    for j in range(k):
        i = chosen[j]
        speed = np.sqrt(dot(mapped[i], mapped[i]))
        for a in range(3):
            direction = mapped[i, a] / speed
            for c in range(nv):
                V[j, c] += direction * J[i, a, c]
    R = bound_response(H, A, C, z, floor, group, V)
    if R.shape[0] == 0:
        return False
    residual = np.empty(k)
    for j in range(k):
        i = chosen[j]
        residual[j] = mu[i] * (
            _shift_speed(np.sqrt(dot(mapped[i], mapped[i]))) - _shift_speed(np.sqrt(dot(used[i], used[i])))
        )
        for c in range(k):
            R[j, c] *= mu[i]
        R[j, j] += 1.0
    step = solve(R, residual.copy())
    if step is None:
        return False
    low, high = scales
    for j in range(k):
        i = chosen[j]
        scale = step[j] / residual[j] if residual[j] != 0.0 else 1.0
        if not low <= scale <= high:  # the secant's step stands
            continue
        speed = np.sqrt(dot(mapped[i], mapped[i]))
        target = max(_shift_speed(np.sqrt(dot(used[i], used[i]))) + scale * residual[j] / mu[i], 0.0)
        for a in range(3):
            moved[i, a] = mapped[i, a] / speed * target - used[i, a]
    return True


@njit(cache=True)
def shifted_bounds(bound, starts, mu, used, slip, result):  # type: ignore[no-untyped-def]
    """The bounds ``bound`` of contact rows (contact i's rows: ``starts[i]`` to ``starts[i + 1]``)
    posed with the De Saxce shift of the slips ``used`` (m, 3), moved to the shift of ``slip``
    (:func:`pyramids` subtracts mu |s| where |s| > SLIP_SPEED), into ``result``."""
    for i in range(len(mu)):
        change = mu[i] * (
            _shift_speed(np.sqrt(dot(used[i], used[i]))) - _shift_speed(np.sqrt(dot(slip[i], slip[i])))
        )
        for r in range(starts[i], starts[i + 1]):
            result[r] = bound[r] + change


@njit(cache=True, inline="always")
def _shift_speed(speed):  # type: ignore[no-untyped-def]
    """The speed a De Saxce shift takes from a slip of ``speed``: itself, 0 below SLIP_SPEED (the one
    rule of :func:`pyramids` and :func:`shifted_bounds`)."""
    return speed if speed > SLIP_SPEED else 0.0


@njit(cache=True)
def contact_row_ids(starts, key, per_contact):  # type: ignore[no-untyped-def]
    """Each row's id (R,): its contact's ``key`` times ``per_contact`` plus its place among the
    contact's rows (``starts``: :func:`pyramids`')."""
    ids = np.empty(starts[-1], np.int64)
    for i in range(len(starts) - 1):
        for r in range(starts[i], starts[i + 1]):
            ids[r] = key[i] * per_contact + r - starts[i]
    return ids
