"""Compiled kernels of the collision stage: hulls on the ground plane (:mod:`gaussim.collision.ground`),
the travel bound of the margin schedule (:mod:`gaussim.collision.margin`), and how far a contact
point can close in a step (:class:`gaussim.collision.ContactDetector`)."""

from __future__ import annotations

import numpy as np
from numba import njit

from .dynamics import point_column

# A polyhedron on the ground found to touch at one point keeps that verdict while its orientation
# cannot have brought a vertex this much closer to the ground than the deepest one [m].
NARROW_SLACK = 2e-3


@njit(cache=True)
def ground_hulls(
    placements,
    joints,
    plane,
    columns,
    first,
    neighbours,
    sizes,
    deepest,
    narrow_at,
    turn2,
    rounding,
    directions,
    margin,
    patch,
    turns,
    diameters,
    pair,
):  # type: ignore[no-untyped-def]
    """The compiled pass of :func:`gaussim.collision.ground.touching` (the arrays of its ``Hulls``; updates
    ``deepest`` and ``narrow_at``): returns the contacts, hull by hull, as (pairs, points, normals, gaps),
    and the least gap of all the hulls. Hull k is carried by joint ``joints[k]`` (its placement one of
    ``placements``, see :mod:`gaussim.kernels.pairs`); its own vertices are the first ``sizes[k]``
    columns of ``columns[k]`` (the rest pad it to the largest hull). ``patch``: (PATCH_TOLERANCE,
    PATCH_MIN_EXTENT) of :mod:`gaussim.kernels.pairs`; ``turns`` [rad] (per
    declared pair) times ``diameters`` [m] (per hull): what hull k's turn within the step can bring its
    other vertices down by (``pair[k]`` is its declared pair): its patch reaches that
    deep where it exceeds PATCH_TOLERANCE, and keeps the outline of the resting patch and the deepest
    vertex (a resting body's patch stays as it was, which bounds jitter of the bound would make
    flicker).

    The deepest vertex is found by descent along the hull's edges from the last one: a vertex no
    neighbour of which is deeper is the deepest of a convex polyhedron (a linear function has no
    other local minimum on its vertex graph)."""
    count, size = columns.shape[0], columns.shape[2]
    base, extent = patch
    c = np.empty(4)  # the ground seen from the joint: (n^T R, n^T p - height)
    R, p = np.empty((3, 3)), np.empty(3)  # hull k's joint's placement
    order = np.empty(size, np.int64)
    heights = np.empty(size)  # of a widely touching hull's vertices: each of its scans reads them
    picked = np.empty(2 * directions.shape[1] + 1, np.int64)
    most = count * len(picked)  # at most: two outlines and the deepest
    pairs_out, points_out = np.empty(most, np.int64), np.empty((most, 3))
    normals_out, gaps_out = np.empty((most, 3)), np.empty(most)
    out = 0
    least = np.inf
    for k in range(count):
        placement, X = placements[joints[k]], columns[k]
        for a in range(3):
            p[a] = placement[3, a]
            for j in range(3):
                R[a, j] = placement[j, a]
        for j in range(3):
            c[j] = plane[k, 0] * R[0, j] + plane[k, 1] * R[1, j] + plane[k, 2] * R[2, j]
        c[3] = plane[k, 0] * p[0] + plane[k, 1] * p[1] + plane[k, 2] * p[2] + plane[k, 3]
        i = deepest[k]
        lowest = _height(c, X, i)
        descending = True
        while descending:
            descending = False
            for e in range(first[k, i], first[k, i + 1]):
                j = neighbours[k, e]
                height = _height(c, X, j)
                if height < lowest:
                    i, lowest, descending = j, height, True
                    break
        deepest[k] = i
        gap = lowest - rounding[k]
        least = min(least, gap)
        if gap > margin:
            continue
        tolerance = max(base, turns[pair[k]] * diameters[k])
        turned = (c[0] - narrow_at[k, 0]) ** 2 + (c[1] - narrow_at[k, 1]) ** 2 + (c[2] - narrow_at[k, 2]) ** 2
        narrow = turned <= turn2[k]  # False where no verdict was kept (NaN)
        if not narrow:
            _heights(c, X, sizes[k], heights)
            narrow = _spans_within(X, heights, sizes[k], lowest + tolerance + NARROW_SLACK, extent)
            for j in range(3):
                narrow_at[k, j] = c[j] if narrow else np.nan
        if narrow:
            picked[0], picks = i, 1
        else:
            outline = (R, p, X, heights, sizes[k], rounding[k], directions[k], margin)
            picks, n = _outline(*outline, (tolerance, extent), lowest, order, picked, 0, -1)
            if tolerance > base:  # a widened outline's extremes may all be high: the resting patch's
                picks, _ = _outline(*outline, (base, extent), lowest, order, picked, picks, n)  # too,
                picks = _pick(picked, picks, i)  # and the deepest, which neither need hold
        picked[:picks].sort()
        for t in range(picks):
            v = picked[t]
            pairs_out[out], gaps_out[out] = pair[k], _height(c, X, v) - rounding[k]
            for j in range(3):
                vertex = R[j, 0] * X[0, v] + R[j, 1] * X[1, v] + R[j, 2] * X[2, v] + p[j]
                points_out[out, j] = vertex - rounding[k] * plane[k, j]
                normals_out[out, j] = plane[k, j]
            out += 1
    return (pairs_out[:out], points_out[:out], normals_out[:out], gaps_out[:out]), least


@njit(cache=True, inline="always")
def _height(c, X, v):  # type: ignore[no-untyped-def]
    """The height of vertex v (a column of X) above the ground ``c`` seen from its joint."""
    return c[0] * X[0, v] + c[1] * X[1, v] + c[2] * X[2, v] + c[3]


@njit(cache=True)
def _heights(c, X, size, out):  # type: ignore[no-untyped-def]
    """The heights of the hull's ``size`` vertices above the ground ``c`` into ``out[:size]``, as
    :func:`_height` rounds them (one pass that vectorizes, which each scan of the vertices then reads)."""
    for v in range(size):
        out[v] = _height(c, X, v)


@njit(cache=True)
def _sublevel(heights, size, bound, order):  # type: ignore[no-untyped-def]
    """The number n of the hull's ``size`` vertices at most ``bound`` above the ground (their
    ``heights``), their indices written into ``order[:n]`` in ascending order (the outline's passes
    then read them alone, not the thousands of vertices of a mesh's hull)."""
    n = 0
    for v in range(size):
        if heights[v] <= bound:
            order[n] = v
            n += 1
    return n


@njit(cache=True)
def _spans_within(X, heights, size, bound, extent):  # type: ignore[no-untyped-def]
    """Whether the hull's ``size`` vertices at most ``bound`` above the ground (their ``heights``) span
    at most ``extent`` (their bounding box in the joint's frame); the search stops at the first
    vertex that makes them span more."""
    low, high = _unbounded()
    for v in range(size):
        if heights[v] <= bound:
            for j in range(3):
                low[j], high[j] = min(low[j], X[j, v]), max(high[j], X[j, v])
            if _extent(low, high) > extent:
                return False
    return True


@njit(cache=True)
def _within(heights, order, n, bound):  # type: ignore[no-untyped-def]
    """The number of the vertices ``order[:n]`` at most ``bound`` above the ground (their
    ``heights``), moved to the front of ``order`` in their order."""
    kept = 0
    for t in range(n):
        v = order[t]
        if heights[v] <= bound:
            order[kept] = v
            kept += 1
    return kept


@njit(cache=True)
def _pick(picked, picks, v):  # type: ignore[no-untyped-def]
    """Add vertex v to ``picked[:picks]`` unless there; returns the new count."""
    for t in range(picks):
        if picked[t] == v:
            return picks
    picked[picks] = v
    return picks + 1


@njit(cache=True)
def _outline(
    R, p, X, heights, size, rounding, directions, margin, patch, lowest, order, picked, picks, known
):  # type: ignore[no-untyped-def]
    """A hull touching widely (its joint at (R, p), its ``size`` vertices X at ``heights`` above the
    ground, the deepest at ``lowest``): adds to ``picked[:picks]`` its vertices within the patch
    tolerance of the deepest (or penetrating) that are extreme along ``directions`` (the second half
    the first's opposites), or the deepest alone when they span at most PATCH_MIN_EXTENT; returns the
    new count and the number n of the vertices it read, which it leaves in ``order[:n]`` in ascending
    order (a buffer of the largest hull's size). ``known``: -1, or the n of a call with a wider
    patch, whose vertices this one reads alone."""
    tolerance, extent = patch
    bound = max(0.0, min(margin, lowest - rounding + tolerance))
    # at least the deepest's own height: bound + rounding may round below it when the margin clamps
    bound = max(bound + rounding, lowest)
    n = _sublevel(heights, size, bound, order) if known < 0 else _within(heights, order, known, bound)
    half = directions.shape[0] // 2  # directions[half + d] is -directions[d]
    low, high = _unbounded()
    deepest, least = -1, np.inf
    most, reach = np.full(half, -1), np.full(half, -np.inf)  # the extremes along each direction
    fewest, back = np.full(half, -1), np.full(half, np.inf)  # and along its opposite
    for t in range(n):
        v = order[t]
        w0 = R[0, 0] * X[0, v] + R[0, 1] * X[1, v] + R[0, 2] * X[2, v] + p[0]
        w1 = R[1, 0] * X[0, v] + R[1, 1] * X[1, v] + R[1, 2] * X[2, v] + p[1]
        w2 = R[2, 0] * X[0, v] + R[2, 1] * X[1, v] + R[2, 2] * X[2, v] + p[2]
        low[0], high[0] = min(low[0], w0), max(high[0], w0)
        low[1], high[1] = min(low[1], w1), max(high[1], w1)
        low[2], high[2] = min(low[2], w2), max(high[2], w2)
        height = heights[v]
        if height < least:
            deepest, least = v, height
        for d in range(half):
            along = w0 * directions[d, 0] + w1 * directions[d, 1] + w2 * directions[d, 2]
            if along > reach[d]:
                most[d], reach[d] = v, along
            if along < back[d]:
                fewest[d], back[d] = v, along
    if _extent(low, high) <= extent:
        return _pick(picked, picks, deepest), n
    for d in range(half):
        picks = _pick(picked, picks, most[d])
        picks = _pick(picked, picks, fewest[d])
    return picks, n


@njit(cache=True, inline="always")
def _unbounded():  # type: ignore[no-untyped-def]
    """An empty bounding box: (low, high) = (+inf, -inf) in each of 3 coordinates."""
    low, high = np.empty(3), np.empty(3)
    for j in range(3):
        low[j], high[j] = np.inf, -np.inf
    return low, high


@njit(cache=True, inline="always")
def _extent(low, high):  # type: ignore[no-untyped-def]
    """The largest side of the bounding box (low, high), each (3,)."""
    return max(high[0] - low[0], high[1] - low[1], high[2] - low[2])


@njit(cache=True)
def in_pair_order(pairs, points, normals, gaps):  # type: ignore[no-untyped-def]
    """Sorts the contact points of several routines (their pieces concatenated: the declared pair of
    each, its point, normal and gap) by declared pair, in place and stably: a pair's points keep their
    order (a no-op when they are in order, as they are when the routines' pairs do not interleave)."""
    for i in range(1, pairs.shape[0]):
        if pairs[i] < pairs[i - 1]:
            break
    else:
        return
    order = np.argsort(pairs, kind="mergesort")
    pairs[:] = pairs[order]
    points[:] = points[order]
    normals[:] = normals[order]
    gaps[:] = gaps[order]


@njit(cache=True)
def joined(pairs_a, points_a, normals_a, gaps_a, pairs_b, points_b, normals_b, gaps_b):  # type: ignore[no-untyped-def]
    """Two routines' pieces (declared pair, point, normal and gap of each point) as one, sorted by
    declared pair as :func:`in_pair_order` sorts (one call where four concatenations and a sort
    were five)."""
    n, total = len(pairs_a), len(pairs_a) + len(pairs_b)
    pairs, gaps = np.empty(total, np.int64), np.empty(total)
    points, normals = np.empty((total, 3)), np.empty((total, 3))
    for k in range(total):
        i = k - n
        if k < n:
            pairs[k], gaps[k] = pairs_a[k], gaps_a[k]
            for j in range(3):
                points[k, j], normals[k, j] = points_a[k, j], normals_a[k, j]
        else:
            pairs[k], gaps[k] = pairs_b[i], gaps_b[i]
            for j in range(3):
                points[k, j], normals[k, j] = points_b[i, j], normals_b[i, j]
    in_pair_order(pairs, points, normals, gaps)
    return pairs, points, normals, gaps


@njit(cache=True)
def travel(
    starts, coordinates, levers, turn_starts, turn_coordinates, turn_levers, v, x, dt, x_scale, each, turns
):  # type: ignore[no-untyped-def]
    """The farthest a pair can close in a step: max_k dt sum_i levers[k, i] (|v_i| + x_scale |x_i|),
    the levers in CSR form (row starts, coordinates, values; see MarginSchedule.levers); each pair's
    sum, times dt, is written into ``each``, and the same sums of the turn levers (CSR too: the most
    each pair can turn) into ``turns`` (one call: this runs every step that may detect)."""
    _bounds(turn_starts, turn_coordinates, turn_levers, v, x, dt, x_scale, turns)
    return dt * _bounds(starts, coordinates, levers, v, x, dt, x_scale, each)


@njit(cache=True, inline="always")
def _bounds(starts, coordinates, levers, v, x, dt, x_scale, each):  # type: ignore[no-untyped-def]
    """:func:`travel`'s sums of one CSR matrix of levers into ``each``; returns the largest, over dt."""
    farthest = 0.0
    for k in range(len(starts) - 1):
        total = 0.0
        for j in range(starts[k], starts[k + 1]):
            i = coordinates[j]
            total += levers[j] * (abs(v[i]) + x_scale * abs(x[i]))
        each[k] = dt * total
        farthest = max(farthest, total)
    return farthest


@njit(cache=True)
def closing(J, masks, starts, columns, joints, other_joints, points, normals, mu, v, x, dt, x_scale, out):  # type: ignore[no-untyped-def]
    """How far each contact point can close on its pair in a step, into ``out`` (m,) [m]: dt (c(v) +
    c(x_scale x)), c(w) = max(0, mu |u_t(w)| - n . u(w)), u(w) the point's velocity relative to the
    other side at joint velocity w and u_t its part along the contact plane: the velocity-level rows
    of a contact with gap g (its normal row and its friction pyramid's, whose bounds the De Saxce
    shift only lowers) all hold at w once g / dt + n . u(w) >= mu |u_t(w)|. The point velocities are
    read from the joint Jacobians J (6, nv) as :func:`~gaussim.kernels.dynamics.point_jacobians_into`
    reads them (``masks``, ``starts``, ``columns``: :class:`gaussim.dynamics.Supports`)."""
    for i in range(len(joints)):
        a, b = joints[i], other_joints[i]
        uv, ux = np.zeros(3), np.zeros(3)
        for joint in (a, b):
            for c in range(starts[joint], starts[joint + 1]):
                k = columns[c]
                moving = masks[a, k] - masks[b, k]  # 0 on the chain the two share
                if moving == 0.0:
                    continue
                column = point_column(J, k, points[i])
                for j in range(3):
                    uv[j] += moving * column[j] * v[k]
                    ux[j] += moving * column[j] * x[k]
        total = 0.0
        for u, scale in ((uv, 1.0), (ux, x_scale)):
            along = scale * (normals[i, 0] * u[0] + normals[i, 1] * u[1] + normals[i, 2] * u[2])
            slip = 0.0
            for j in range(3):
                slip += (scale * u[j] - along * normals[i, j]) ** 2
            total += max(0.0, mu[i] * np.sqrt(slip) - along)
        out[i] = dt * total
