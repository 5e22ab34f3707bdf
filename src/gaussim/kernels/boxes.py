"""Box against box, compiled: the separating-axis test and, for a face on a face, its contact patch
clipped on the reference face (after ODE's ``dBoxBox`` and MuJoCo's ``box_box``), the answer of
coal's narrow phase and contact patch without their calls; what it cannot answer exactly goes to coal.

For two boxes the largest separation along the 15 axes (3 face normals each, 9 edge cross products)
is a lower bound on their distance and, when they overlap, minus their penetration depth (the
minimum translation of two polytopes is along one of those axes). When that axis is a face's normal
the boxes' support sets along it (their vertices within PATCH_TOLERANCE of their support planes)
clipped to each other are coal's contact patch; when the incident points reach that separation it
is also their distance. A corner over the other box's face is a patch of one point, coal's witness
point: the corner, or its foot on the robot's face. When an edge axis separates them most, two edges
touch at the closest points of their lines, coal's witness points, with coal's patch of the two edges
(its rule for two segments, :func:`gaussim.kernels.primitives._patch`), or, where each box still
presents a face (or 3 of its corners) along that axis (a box settling tilted on another), the two
clipped along it (:func:`_faces`, coal's Sutherland-Hodgman on the projected support sets). Pairs on a
patch of more points narrower than PATCH_MIN_EXTENT (one point, which coal's witness decides), on a
patch two of whose points round to the same 0.1 mm in the robot's order (coal's order of them is its
own), with a test within DECISION of its threshold, or apart at a distance the patch does not reach go
to coal.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..linalg import cross, dot
from .pairs import ASK_COAL, DECISION, FAR, FOUND, PATCH_MIN_EXTENT, PATCH_TOLERANCE, order, place
from .primitives import BOX, NEAR_PARALLEL, _box_support, _touching

# An edge-edge axis is taken over a face's normal only when it separates the boxes by this much
# more: nearly parallel faces have edge axes that agree with the face's to round-off [m].
EDGE_PREFERENCE = 1e-9
# The incident points reach the separation within this when it is the boxes' distance [m].
REACHED = 1e-12
# Two patch points closer than this are one (a corner on the reference face's edge, clipped) [m].
SAME_POINT = 1e-9
MAX_POINTS = 8  # a patch's points: two quadrilaterals clipped to each other
BOXES = np.array([BOX, BOX])  # the kinds of the primitives' patch (its sides)


@njit(cache=True)
def box_pairs(
    placements,
    side,
    local_rotation,
    local_translation,
    half,
    thin,
    near,
    margin,
    answer,
    gaps,
    normals,
    points,
    sizes,
):  # type: ignore[no-untyped-def]
    """The compiled test of :class:`gaussim.collision.boxes.BoxPairs` on pairs ``near``: for each, fills
    ``answer`` (FAR, FOUND or ASK_COAL), ``gaps`` (a lower bound when FAR, the gap of a patch), and for a
    patch its normal (from the other box to the robot's) and its ``sizes`` points on the robot's box (ordered
    by their place on it, as :class:`gaussim.collision.narrow.NarrowPhase` orders them)."""
    R = np.empty((2, 3, 3))
    p = np.empty((2, 3))
    work = _workspace()
    for k in range(near.shape[0]):
        i = near[k]
        place(placements, side, local_rotation, local_translation, i, R, p)
        if thin[i]:
            answer[k] = ASK_COAL
            continue
        answer[k], gaps[k], sizes[k] = _box_box(R, p, half[i], margin, normals[k], points[k], work)


@njit(cache=True)
def _workspace():  # type: ignore[no-untyped-def]
    """The buffers :func:`_box_box` works in, allocated once per call of :func:`box_pairs` (a pair's
    test allocating its own took most of its time): (T, the two boxes' axes as rows (2, 3, 3); vectors
    (4, 3): d, an axis, n, the reference face's centre; the signs of a box's corners (8, 3) and their
    buffers (8, 3), (8,), (8,) int; the clipped polygon, in two buffers (2, 16, 3), and its vertices'
    margins (16,))."""
    signs = np.empty((8, 3))
    for v in range(8):
        for a in range(3):
            signs[v, a] = 1.0 if (v >> (2 - a)) & 1 else -1.0
    corners = (signs, np.empty((8, 3)), np.empty(8), np.empty(8, np.int64))
    return np.empty((2, 3, 3)), np.empty((4, 3)), corners, np.empty((2, 16, 3)), np.empty(16)


@njit(cache=True)
def _box_box(R, p, half, margin, normal, points, work):  # type: ignore[no-untyped-def]
    """Boxes 0 (the robot's) and 1 at (R[s] (columns: axes), p[s]), half sides ``half[s]``: returns
    (answer, gap, number of points), the normal and points written into ``normal`` (3,) and
    ``points`` (MAX_POINTS, 3); ``work``: :func:`_workspace`."""
    T, vectors, corners, clipped, inside = work
    d, axis, n, centre = vectors[0], vectors[1], vectors[2], vectors[3]
    for a in range(3):
        d[a] = p[0, a] - p[1, a]
    for s in range(2):  # T[s, a]: axis a of box s (contiguous)
        for a in range(3):
            for j in range(3):
                T[s, a, j] = R[s, j, a]
    best, axis_box, axis_index = -np.inf, -1, -1
    for s in range(2):
        for a in range(3):
            t0, t1, t2 = T[s, a, 0], T[s, a, 1], T[s, a, 2]
            separation = abs(d[0] * t0 + d[1] * t1 + d[2] * t2) - _reach(T, half, t0, t1, t2)
            if separation > best:
                best, axis_box, axis_index = separation, s, a
    if best > margin:  # a face axis separates them: the edge axes need not be tried
        return FAR, best, 0
    edge_best = edge_next = -np.inf  # the largest edge separation, and the next one
    edges = (-1, -1)
    for a in range(3):
        for b in range(3):
            axis[0], axis[1], axis[2] = cross(
                T[0, a, 0], T[0, a, 1], T[0, a, 2], T[1, b, 0], T[1, b, 1], T[1, b, 2]
            )
            length = np.sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2])
            if length < 1e-6:  # parallel edges: their axis is a face's
                continue
            for j in range(3):
                axis[j] /= length
            t0, t1, t2 = axis[0], axis[1], axis[2]
            separation = abs(d[0] * t0 + d[1] * t1 + d[2] * t2) - _reach(T, half, t0, t1, t2)
            if separation > edge_best:
                edge_best, edge_next, edges = separation, edge_best, (a, b)
            else:
                edge_next = max(edge_next, separation)
    lower = max(best, edge_best)
    if lower > margin:
        return FAR, lower, 0
    if edge_best > best + EDGE_PREFERENCE:
        if edge_best - edge_next <= DECISION:
            return ASK_COAL, lower, 0  # two edge axes about as good: coal's EPA picks one
        return _edge_edge(R, p, T, half, edges[0], edges[1], d, lower, normal, points, work)
    flip = -1.0 if dot(d, T[axis_box, axis_index]) < 0 else 1.0
    for j in range(3):
        n[j] = flip * T[axis_box, axis_index, j]  # from box 1 towards box 0
    robot_support = dot(n, p[0]) - _extent(T, 0, half, n[0], n[1], n[2])
    other_support = dot(n, p[1]) + _extent(T, 1, half, n[0], n[1], n[2])
    gap = robot_support - other_support
    # the reference face (of the axis' box, facing the other) and the other box's support set
    ref = axis_box
    inc = 1 - ref
    out = -1.0 if ref == 0 else 1.0  # the reference face's outward normal: out n
    for j in range(3):
        centre[j] = p[ref, j] + half[ref][axis_index] * (out * n[j])
    u, w = T[ref, (axis_index + 1) % 3], T[ref, (axis_index + 2) % 3]
    hu, hw = half[ref][(axis_index + 1) % 3], half[ref][(axis_index + 2) % 3]
    size = _support_polygon(R[inc], p[inc], half[inc], -out, n, corners, clipped[0])
    if size == 0:
        return ASK_COAL, lower, 0
    at, count = _clip(clipped, size, centre, u, hu, w, hw, inside)
    if count == 0:
        return ASK_COAL, lower, 0
    polygon = clipped[at]
    # each clipped point is a point of the incident box over the reference face: the nearest is at
    # the boxes' distance when it reaches the separation
    reached = np.inf
    for j in range(count):
        along = 0.0
        for a in range(3):
            along += (polygon[j, a] - centre[a]) * (out * n[a])
        reached = min(reached, along)
    if gap > 0 and reached - gap > REACHED:
        return ASK_COAL, lower, 0
    kept, widest = _on_plane(polygon, count, n, robot_support, points)
    if widest <= PATCH_MIN_EXTENT and size > 1:
        return ASK_COAL, lower, 0  # one point, which coal's witness decides
    if order(points, kept, R[0], p[0]):  # two points tied: coal's order of them is its own
        return ASK_COAL, lower, 0
    normal[:] = n
    return FOUND, gap, kept


@njit(cache=True)
def _edge_edge(R, p, T, half, a, b, d, lower, normal, points, work):  # type: ignore[no-untyped-def]
    """Box 0's edge along its axis ``a`` against box 1's along its axis ``b``, whose axis separates the
    boxes most (by ``lower``: their least overlap): returns (answer, gap, number of points) as
    :func:`_box_box`. The edges are each box's support edge along the normal n (their cross product,
    from box 1 towards box 0); coal's witness points are the closest points of their lines, when each
    lies inside its edge by DECISION and the lines are not nearly parallel; its patch is the
    primitives' (coal's support sets of the two boxes along n: edges, or a face within PATCH_TOLERANCE),
    or, where both boxes present a face along n, the faces' clipped patch (:func:`_faces`)."""
    n = np.empty(3)
    e, f = T[0, a], T[1, b]
    n[0], n[1], n[2] = cross(e[0], e[1], e[2], f[0], f[1], f[2])
    n /= np.sqrt(dot(n, n))
    if dot(d, n) < 0:
        n = -n
    cosine = dot(e, f)
    sine2 = 1.0 - cosine * cosine
    if sine2 <= NEAR_PARALLEL:
        return ASK_COAL, lower, 0
    c0, c1 = p[0].copy(), p[1].copy()  # the support edges' centres
    for c in range(3):
        if c != a:
            c0 -= np.sign(dot(n, T[0, c])) * half[0][c] * T[0, c]
        if c != b:
            c1 += np.sign(dot(n, T[1, c])) * half[1][c] * T[1, c]
    r = c0 - c1
    along_e, along_f = dot(e, r), dot(f, r)
    s = (cosine * along_f - along_e) / sine2  # the closest points: c0 + s e, c1 + t f
    t = (along_f - cosine * along_e) / sine2
    if abs(s) > half[0][a] - DECISION or abs(t) > half[1][b] - DECISION:
        return ASK_COAL, lower, 0  # a corner, not the edge's inside, is nearest
    witness = c0 + s * e
    towards = -n  # coal's normal: from the robot's box to the other
    supports = np.empty((8, 3))
    own = _box_support(R[0], p[0], half[0], towards, supports)
    other = _box_support(R[1], p[1], half[1], n, supports)
    if own < 0 or other < 0:
        return ASK_COAL, lower, 0  # a test within DECISION
    if own >= 3 and other >= 3:  # a face (or 3 of its corners) on each side: not an edge's patch
        count = _faces(R, p, half, n, work, points)
    else:
        count = _touching(BOXES, half, R, p, towards, witness, points)
    if count <= 0:
        return ASK_COAL, lower, 0
    normal[:] = n
    return FOUND, dot(n, r) + s * dot(n, e) - t * dot(n, f), count


@njit(cache=True)
def _faces(R, p, half, n, work, points):  # type: ignore[no-untyped-def]
    """The patch of two boxes that each present a face along the edge axis n (from box 1 towards box 0;
    both faces within PATCH_TOLERANCE of it): box 1's face clipped by the planes along n through the
    edges of box 0's (coal clips the two support polygons projected along n, Sutherland-Hodgman), on
    box 0's support plane, without repeats, in the robot's order (:func:`order`). Returns the number of
    points written into ``points``, 0 when coal is to answer (a support that is no face, fewer than 3
    points, a patch not clearly wider than PATCH_MIN_EXTENT, two points whose order keys round alike)."""
    _, _, corners, clipped, inside = work
    face = np.empty((4, 3))
    sides = _support_polygon(R[0], p[0], half[0], -1.0, n, corners, face)
    if sides < 3:
        return 0
    k = _support_polygon(R[1], p[1], half[1], 1.0, n, corners, clipped[0])
    if k < 3:
        return 0
    centre = np.zeros(3)
    for j in range(sides):
        for a in range(3):
            centre[a] += face[j, a] / sides
    side = np.empty(3)
    at = 0
    for j in range(sides):
        start, end = face[j], face[(j + 1) % sides]
        side[0], side[1], side[2] = cross(
            end[0] - start[0], end[1] - start[1], end[2] - start[2], n[0], n[1], n[2]
        )
        if (centre[0] - start[0]) * side[0] + (centre[1] - start[1]) * side[1] + (
            centre[2] - start[2]
        ) * side[2] > 0:
            for a in range(3):
                side[a] = -side[a]  # outwards
        k = _cut(clipped[at], k, start, 1.0, side, 0.0, inside, clipped[1 - at])
        at = 1 - at
        if k < 3:
            return 0
    polygon = clipped[at]
    support = np.inf
    for j in range(sides):
        support = min(support, dot(n, face[j]))
    kept, widest = _on_plane(polygon, k, n, support, points)
    if kept < 3 or widest <= PATCH_MIN_EXTENT + DECISION:
        return 0
    if order(points, kept, R[0], p[0]):
        return 0
    return kept


@njit(cache=True)
def _on_plane(polygon, count, n, support, points):  # type: ignore[no-untyped-def]
    """The first ``count`` points of ``polygon`` moved along the unit n onto the plane n . x =
    ``support``, without repeats (within SAME_POINT), into ``points``: (their number, the widest of
    their extents along the world axes)."""
    kept = 0
    for j in range(count):
        lift = support - dot(n, polygon[j])
        repeated = False
        for m in range(kept):
            squared = 0.0
            for a in range(3):
                squared += (points[m, a] - (polygon[j, a] + n[a] * lift)) ** 2
            if np.sqrt(squared) <= SAME_POINT:
                repeated = True
        if not repeated:
            for a in range(3):
                points[kept, a] = polygon[j, a] + n[a] * lift
            kept += 1
    widest = 0.0
    for a in range(3):
        low = high = points[0, a]
        for j in range(kept):
            low, high = min(low, points[j, a]), max(high, points[j, a])
        widest = max(widest, high - low)
    return kept, widest


@njit(cache=True, inline="always")
def _reach(T, half, a0, a1, a2):  # type: ignore[no-untyped-def]
    """The sum of both boxes' half extents (``half[s]``) along the unit axis (a0, a1, a2) (their axes
    as rows ``T[s]``)."""
    return _extent(T, 0, half, a0, a1, a2) + _extent(T, 1, half, a0, a1, a2)


@njit(cache=True, inline="always")
def _extent(T, s, half, a0, a1, a2):  # type: ignore[no-untyped-def]
    """Box s's half extent along the unit axis (a0, a1, a2) (its axes as rows of ``T[s]``, its half
    sides ``half[s]``): components, not views of the arrays, which cost more than the arithmetic."""
    return (
        half[s, 0] * abs(T[s, 0, 0] * a0 + T[s, 0, 1] * a1 + T[s, 0, 2] * a2)
        + half[s, 1] * abs(T[s, 1, 0] * a0 + T[s, 1, 1] * a1 + T[s, 1, 2] * a2)
        + half[s, 2] * abs(T[s, 2, 0] * a0 + T[s, 2, 1] * a1 + T[s, 2, 2] * a2)
    )


@njit(cache=True)
def _support_polygon(R, p, half, sign, n, corners, polygon):  # type: ignore[no-untyped-def]
    """The number k of the box's vertices within PATCH_TOLERANCE of its support plane along
    ``sign`` n, written into ``polygon[:k]`` in order around the face, 3 corners of a face, edge or
    vertex they make; 0 when they make none of those (a box thinner than the tolerance) or a vertex is
    within DECISION of the tolerance. ``corners``: the corners' signs and buffers (see
    :func:`_workspace`)."""
    signs, points, heights, chosen = corners
    for v in range(8):
        for a in range(3):
            points[v, a] = (
                p[a]
                + R[a, 0] * signs[v, 0] * half[0]
                + R[a, 1] * signs[v, 1] * half[1]
                + R[a, 2] * signs[v, 2] * half[2]
            )
        heights[v] = (
            points[v, 0] * (sign * n[0]) + points[v, 1] * (sign * n[1]) + points[v, 2] * (sign * n[2])
        )
    top = heights.max()
    k = 0
    for v in range(8):
        if abs(heights[v] - (top - PATCH_TOLERANCE)) <= DECISION:  # coal's round-off may count it in or out
            return 0
        if heights[v] >= top - PATCH_TOLERANCE:
            chosen[k] = v
            k += 1
    if k <= 3:  # a vertex, an edge, 3 corners of a face: any order goes around them
        for j in range(k):
            for a in range(3):
                polygon[j, a] = points[chosen[j], a]
        return k
    if k != 4:
        return 0
    fixed = -1
    for a in range(3):
        same = True
        for j in range(1, 4):
            same = same and signs[chosen[j], a] == signs[chosen[0], a]
        if same:
            fixed = a
    if fixed < 0:
        return 0
    a, b = (fixed + 1) % 3, (fixed + 2) % 3
    for j, (sa, sb) in enumerate(((-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0))):
        for t in range(4):
            v = chosen[t]
            if signs[v, a] == sa and signs[v, b] == sb:
                for c in range(3):
                    polygon[j, c] = points[v, c]
    return 4


@njit(cache=True)
def _clip(polygons, k, centre, u, hu, w, hw, inside):  # type: ignore[no-untyped-def]
    """The part of the polygon ``polygons[0, :k]`` (a segment when k = 2, a point when k = 1) over the
    rectangle centred at ``centre`` with half sides ``hu``, ``hw`` along unit ``u``, ``w``: (which of
    the two buffers ``polygons`` holds it, its number of points); points keep their place (they are
    only cut along the rectangle's sides)."""
    at = 0
    for axis, bound in ((u, hu), (w, hw)):
        for sign in (1.0, -1.0):
            k = _cut(polygons[at], k, centre, sign, axis, bound, inside, polygons[1 - at])
            at = 1 - at
            if k == 0:
                return at, 0
    return at, k


@njit(cache=True)
def _cut(polygon, k, centre, sign, axis, bound, inside, out):  # type: ignore[no-untyped-def]
    """The part of ``polygon[:k]`` where (x - centre) . (sign axis) <= bound (Sutherland-Hodgman; a
    segment or a point when k is 2 or 1), written into ``out``: returns its number of points."""
    for j in range(k):
        along = 0.0
        for a in range(3):
            along += (polygon[j, a] - centre[a]) * (sign * axis[a])
        inside[j] = bound - along
    count = 0
    if k <= 2:
        for j in range(k):
            if inside[j] >= 0:
                for a in range(3):
                    out[count, a] = polygon[j, a]
                count += 1
        if k == 2 and inside[0] * inside[1] < 0:
            t = inside[0] / (inside[0] - inside[1])
            if inside[0] < 0:
                for a in range(3):
                    out[1, a] = out[0, a]
            crossing = 1 if inside[0] >= 0 else 0
            for a in range(3):
                out[crossing, a] = polygon[0, a] + t * (polygon[1, a] - polygon[0, a])
            count = 2
        return count
    for j in range(k):
        nxt = (j + 1) % k
        if inside[j] >= 0:
            for a in range(3):
                out[count, a] = polygon[j, a]
            count += 1
        if inside[j] * inside[nxt] < 0:
            t = inside[j] / (inside[j] - inside[nxt])
            for a in range(3):
                out[count, a] = polygon[j, a] + t * (polygon[nxt, a] - polygon[j, a])
            count += 1
    return count
