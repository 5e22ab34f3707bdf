"""Spheres, capsules and boxes against each other (but box on box, :mod:`gaussim.kernels.boxes`), compiled:
the answer of coal's narrow phase and contact patch without their calls.

coal answers sphere-sphere, sphere-capsule, sphere-box and capsule-capsule in closed form
(``details.h``, ``capsule_capsule.cpp``): these are the same formulas, in the same order of shape 1
(the robot's) and shape 2, so the same witness points, normal and gap. A capsule against a box goes
through coal's GJK on the capsule's segment inflated by its radius, whose answer is the exact
closest points of the segment and the box: here, the minimum of the squared distance to the box
along the segment, a convex quadratic between the places where the segment crosses the box's slabs.

A sphere touches at one point (coal's patch of a strictly convex shape). A capsule whose axis is
across the normal has a segment as support set (its ends within PATCH_TOLERANCE of the support
plane), a box a face, an edge or a corner. coal's patch of a segment and a face is the segment
clipped to the face; of two segments (a capsule's, a box's edge) one point or the ends of shape 1's
projected onto shape 2's, as the sign of their cross product says (coal tests ``>=`` where it meant
a determinant). A patch wider than PATCH_MIN_EXTENT gives its points, else the pair touches at its
witness point on the robot. What round-off could decide either way (a test within DECISION of its
threshold, near-parallel segments, a witness point that is not unique, cores that touch) goes to
coal. coal's GJK box support moves a box's negative sides out by 1e-10 of their half side once any
query in the process had a zero direction component (a function-static): its capsule-box answers
differ from these exact ones by that much.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..linalg import dot
from .pairs import ASK_COAL, DECISION, FAR, FOUND, PATCH_MIN_EXTENT, PATCH_TOLERANCE, order, place

SPHERE, CAPSULE, BOX = 0, 1, 2  # a side's shape, in the order a pair's routine takes them
# coal counts a pair as touching within this of the margin (CollisionRequest's
# collision_distance_threshold, Eigen's dummy precision) [m].
COAL_THRESHOLD = 1e-12
# Centres, or a capsule's segment and a box, closer than this leave the normal to coal [m].
COINCIDENT = 1e-9
# coal's closed form takes two capsules' segments for parallel below a * e - b^2 = EPSILON (its
# 100 machine epsilons); up to NEAR_PARALLEL * a * e (sin^2 of their angle) its closest points are
# ill-conditioned, and such pairs are coal's.
EPSILON = 100 * np.finfo(np.float64).eps
NEAR_PARALLEL = 1e-6
# A segment whose slope against the box's faces it lies over is below this has a range of closest
# points (a capsule flat on a face): its witness point is GJK's choice.
FLAT = 1e-9
# coal's eps in its contact patch (Eigen's dummy precision): shorter squared projections [m^2] are none.
PATCH_EPS = 1e-12
MAX_POINTS = 2  # a segment clipped to a face


@njit(cache=True)
def primitive_pairs(
    placements,
    side,
    local_rotation,
    local_translation,
    kind,
    dims,
    near,
    margin,
    answer,
    gaps,
    normals,
    points,
    sizes,
):  # type: ignore[no-untyped-def]
    """The compiled pass of :class:`gaussim.collision.primitives.PrimitivePairs` on pairs ``near``: for each,
    fills ``answer`` (FAR, FOUND or ASK_COAL), ``gaps`` (the gap when FAR or FOUND), and when FOUND its normal
    (from the other side to the robot's) and its ``sizes`` points on the robot's geometry (a patch ordered by
    their place on it, as :class:`gaussim.collision.narrow.NarrowPhase` orders them)."""
    R = np.empty((2, 3, 3))
    p = np.empty((2, 3))
    for k in range(near.shape[0]):
        i = near[k]
        place(placements, side, local_rotation, local_translation, i, R, p)
        answer[k], gaps[k], sizes[k] = _pair(kind[i], dims[i], R, p, margin, normals[k], points[k])


@njit(cache=True)
def _pair(kind, dims, R, p, margin, normal, points):  # type: ignore[no-untyped-def]
    """One pair, sides (R[s], p[s]) of ``kind[s]`` and ``dims[s]``, s = 0 the robot's: returns
    (answer, gap, number of points), the normal and points written into ``normal`` (3,) and
    ``points`` (MAX_POINTS, 3)."""
    a = 1 if kind[0] > kind[1] else 0  # the side the closed form takes first
    b = 1 - a
    w = np.empty((2, 3))  # the witness points on sides a and b
    n = np.empty(3)  # from side a to side b
    distance, unique = _closest(kind[a], kind[b], R[a], p[a], dims[a], R[b], p[b], dims[b], w, n)
    if np.isnan(distance):
        return ASK_COAL, 0.0, 0
    if distance - margin > COAL_THRESHOLD:
        return FAR, distance, 0
    witness = w[a]  # the robot's (side 0 is a, or b when a is side 1)
    towards = np.empty(3)  # coal's normal: from the robot's side to the other
    for j in range(3):
        towards[j] = n[j] if a == 0 else -n[j]
        normal[j] = -towards[j]
    count = _touching(kind, dims, R, p, towards, witness, points)
    if count < 0 or (count == 1 and not unique):
        return ASK_COAL, 0.0, 0
    return FOUND, distance, count


@njit(cache=True)
def _touching(kind, dims, R, p, towards, witness, points):  # type: ignore[no-untyped-def]
    """How many points a touching pair touches at, written into ``points``: 2, coal's patch
    (:func:`_patch`) in the robot's order, when it spans more than PATCH_MIN_EXTENT; else 1, the robot's
    ``witness`` point (coal's one point); -1 when coal is to answer (a test within DECISION)."""
    count = _patch(kind, dims, R, p, towards, witness, points)
    if count < 0:
        return -1
    if count == 2:
        extent = 0.0
        for j in range(3):
            extent = max(extent, abs(points[0, j] - points[1, j]))
        if abs(extent - PATCH_MIN_EXTENT) <= DECISION:
            return -1
        if extent > PATCH_MIN_EXTENT:
            order(points, 2, R[0], p[0])
            return 2
    points[0] = witness
    return 1


@njit(cache=True)
def _closest(kind_a, kind_b, Ra, pa, da, Rb, pb, db, w, n):  # type: ignore[no-untyped-def]
    """coal's closed form (or GJK's answer) for shapes a and b, ``kind_a <= kind_b``: returns (their
    distance [m], NaN when it is coal's to answer; whether the witness points are unique) and writes
    the witness points on a and b into ``w`` (2, 3) and the unit normal from a to b into ``n``."""
    if kind_a == SPHERE and kind_b == SPHERE:
        return _sphere_sphere(pa, da[0], pb, db[0], w, n), True
    if kind_a == SPHERE and kind_b == CAPSULE:
        return _sphere_capsule(pa, da[0], Rb, pb, db[0], db[1], w, n), True
    if kind_a == SPHERE:  # a box: coal's closed form takes the box first, and turns its normal
        distance = _box_sphere(Rb, pb, db, pa, da[0], w, n)
        for j in range(3):
            w[0, j], w[1, j] = w[1, j], w[0, j]
            n[j] = -n[j]
        return distance, True
    if kind_b == CAPSULE:
        return _capsule_capsule(Ra, pa, da[0], da[1], Rb, pb, db[0], db[1], w, n), True
    return _capsule_box(Ra, pa, da[0], da[1], Rb, pb, db, w, n)


@njit(cache=True)
def _ends(R, p, half_length):  # type: ignore[no-untyped-def]
    """A capsule's segment: its ends at +half_length and -half_length along its axis (rows 0, 1)."""
    ends = np.empty((2, 3))
    for j in range(3):
        ends[0, j] = p[j] + half_length * R[j, 2]
        ends[1, j] = p[j] - half_length * R[j, 2]
    return ends


@njit(cache=True)
def _surface_points(centre_a, ra, centre_b, rb, difference, length, w, n):  # type: ignore[no-untyped-def]
    """The unit normal along ``difference`` (b's core point minus a's, of norm ``length``) and the
    witness points ``ra`` and ``rb`` from the core points along it; the distance [m]."""
    for j in range(3):
        n[j] = difference[j] / length
        w[0, j] = centre_a[j] + ra * n[j]
        w[1, j] = centre_b[j] - rb * n[j]
    return length - ra - rb


@njit(cache=True)
def _sphere_sphere(ca, ra, cb, rb, w, n):  # type: ignore[no-untyped-def]
    """coal's ``sphereSphereDistance``."""
    difference = np.empty(3)
    for j in range(3):
        difference[j] = cb[j] - ca[j]
    length = np.sqrt(dot(difference, difference))
    if length <= COINCIDENT:
        return np.nan
    return _surface_points(ca, ra, cb, rb, difference, length, w, n)


@njit(cache=True)
def _sphere_capsule(c, r, R, p, radius, half_length, w, n):  # type: ignore[no-untyped-def]
    """coal's ``sphereCapsuleDistance``: the sphere against the closest point of the segment."""
    ends = _ends(R, p, half_length)
    v, u = np.empty(3), np.empty(3)
    for j in range(3):
        v[j] = ends[1, j] - ends[0, j]
        u[j] = c[j] - ends[0, j]
    c1, c2 = dot(u, v), dot(v, v)
    closest = np.empty(3)
    for j in range(3):
        if c1 <= 0:
            closest[j] = ends[0, j]
        elif c2 <= c1:
            closest[j] = ends[1, j]
        else:
            closest[j] = ends[0, j] + v[j] * (c1 / c2)
    return _sphere_sphere(c, r, closest, radius, w, n)


@njit(cache=True)
def _box_sphere(R, p, half, c, r, w, n):  # type: ignore[no-untyped-def]
    """coal's ``boxSphereDistance`` (after Ericson): the box's witness in w[0], the sphere's in w[1],
    the normal from the box to the sphere."""
    local = np.empty(3)
    for a in range(3):
        local[a] = (c[0] - p[0]) * R[0, a] + (c[1] - p[1]) * R[1, a] + (c[2] - p[2]) * R[2, a]
    box = p.copy()
    outside, axis, least = False, -1, np.inf
    for a in range(3):
        if local[a] < -half[a]:
            offset, outside = -half[a], True
        elif local[a] > half[a]:
            offset, outside = half[a], True
        else:
            offset = local[a]
            if not outside and half[a] - abs(local[a]) < least:
                axis, least = a, half[a] - abs(local[a])
        for j in range(3):
            box[j] += offset * R[j, a]
    for j in range(3):
        n[j] = box[j] - c[j]
    length = np.sqrt(dot(n, n))
    if outside:
        if length <= COINCIDENT:
            return np.nan
        distance = length - r
        for j in range(3):
            n[j] /= -length
    else:  # the centre inside: out through the nearest face
        distance = -least - r
        for j in range(3):
            n[j] = R[j, axis] if local[axis] >= 0 else -R[j, axis]
    for j in range(3):
        w[1, j] = c[j] - r * n[j]
        w[0, j] = w[1, j] - distance * n[j] if not outside or distance <= 0 else box[j]
    return distance


@njit(cache=True)
def _capsule_capsule(Ra, pa, ra, ha, Rb, pb, rb, hb, w, n):  # type: ignore[no-untyped-def]
    """coal's ``ShapeShapeDistance<Capsule, Capsule>`` (Ericson's closest points of two segments),
    NaN where it is ill-conditioned (NEAR_PARALLEL) or the segments meet."""
    d1, d2, r = np.empty(3), np.empty(3), np.empty(3)
    s1, s2 = np.empty(3), np.empty(3)  # the segments' starts, at -half length
    for j in range(3):
        d1[j] = 2 * ha * Ra[j, 2]
        d2[j] = 2 * hb * Rb[j, 2]
        s1[j] = pa[j] - d1[j] / 2
        s2[j] = pb[j] - d2[j] / 2
        r[j] = s1[j] - s2[j]
    a, b, c, e, f = dot(d1, d1), dot(d1, d2), dot(d1, r), dot(d2, d2), dot(d2, r)
    denominator = max(a * e - b * b, 0.0)
    if EPSILON < denominator < NEAR_PARALLEL * a * e:
        return np.nan
    s = _clamp(b * f - c * e, denominator) if denominator > EPSILON else 0.0
    t = b * s + f if denominator > EPSILON else f
    w1, w2 = np.empty(3), np.empty(3)
    for j in range(3):
        if t <= 0:
            w1[j] = s1[j] + _clamp(-c, a) * d1[j]
            w2[j] = s2[j]
        elif t >= e:
            w1[j] = s1[j] + _clamp(b - c, a) * d1[j]
            w2[j] = s2[j] + d2[j]
        else:
            w1[j] = s1[j] + s * d1[j]
            w2[j] = s2[j] + t / e * d2[j]
        r[j] = w2[j] - w1[j]
    length = np.sqrt(dot(r, r))
    if length <= COINCIDENT:
        return np.nan
    return _surface_points(w1, ra, w2, rb, r, length, w, n)


@njit(cache=True)
def _clamp(numerator, denominator):  # type: ignore[no-untyped-def]
    """numerator / denominator clamped to [0, 1] (coal's ``clamp``)."""
    if numerator <= 0:
        return 0.0
    if numerator >= denominator:
        return 1.0
    return numerator / denominator


@njit(cache=True)
def _capsule_box(Rc, pc, radius, half_length, R, p, half, w, n):  # type: ignore[no-untyped-def]
    """The capsule's segment against the box, as GJK answers it: the closest points, minimising the
    squared distance to the box (a sum of the squared excesses over its half sides) along the segment
    between its crossings of the box's slabs. Returns (distance or NaN when the segment reaches the
    box, whether the witness points are unique)."""
    ends = _ends(Rc, pc, half_length)
    start, along = np.empty(3), np.empty(3)  # the segment in the box's frame: start + t along
    for a in range(3):
        start[a] = along[a] = 0.0
        for j in range(3):
            start[a] += (ends[0, j] - p[j]) * R[j, a]
            along[a] += (ends[1, j] - ends[0, j]) * R[j, a]
    breaks = np.empty(8)  # 0, the crossings of the slabs' planes in order, 1
    breaks[0], count = 0.0, 1
    for a in range(3):
        if along[a] != 0.0:
            for sign in (-1.0, 1.0):
                t = (sign * half[a] - start[a]) / along[a]
                if 0.0 < t < 1.0:
                    j = count  # insertion sort: a handful of crossings
                    while j > 1 and t < breaks[j - 1]:
                        breaks[j] = breaks[j - 1]
                        j -= 1
                    breaks[j] = t
                    count += 1
    breaks[count] = 1.0
    count += 1
    best, best_t, flat = np.inf, 0.0, np.inf
    slope = FLAT * FLAT * dot(along, along)
    for m in range(count - 1):
        low, high = breaks[m], breaks[m + 1]
        middle = 0.5 * (low + high)
        numerator = curvature = 0.0
        for a in range(3):  # the slabs the segment is outside of between these breaks
            x = start[a] + middle * along[a]
            if abs(x) > half[a]:
                bound = half[a] if x > 0 else -half[a]
                numerator += (start[a] - bound) * along[a]
                curvature += along[a] * along[a]
        t = low if curvature == 0.0 else min(max(-numerator / curvature, low), high)
        value = _excess(start, along, half, t)
        if value < best:
            best, best_t = value, t
        if curvature <= slope:
            flat = min(flat, value)
    inside, difference = np.empty(3), np.empty(3)
    for a in range(3):
        inside[a] = start[a] + best_t * along[a]
        difference[a] = min(max(inside[a], -half[a]), half[a]) - inside[a]
    length = np.sqrt(dot(difference, difference))
    if length <= COINCIDENT:
        return np.nan, False
    core, box, towards = np.empty(3), np.empty(3), np.empty(3)
    for j in range(3):
        core[j], box[j], towards[j] = p[j], p[j], 0.0
        for a in range(3):
            core[j] += R[j, a] * inside[a]
            box[j] += R[j, a] * (inside[a] + difference[a])
            towards[j] += R[j, a] * difference[a]
    # a range of closest points: a flat stretch of the segment at the least squared distance
    unique = flat > best * (1 + 1e-12) + COINCIDENT * COINCIDENT
    return _surface_points(core, radius, box, 0.0, towards, length, w, n), unique


@njit(cache=True)
def _excess(start, along, half, t):  # type: ignore[no-untyped-def]
    """The squared distance to the box (half sides ``half``) of the point start + t along, in its frame."""
    total = 0.0
    for a in range(3):
        x = abs(start[a] + t * along[a]) - half[a]
        if x > 0:
            total += x * x
    return total


@njit(cache=True)
def _patch(kind, dims, R, p, towards, witness, points):  # type: ignore[no-untyped-def]
    """coal's contact patch of a touching pair (side 0 the robot's, ``towards`` its normal from side 0
    to side 1): writes its points, on the plane of the robot's ``witness`` point across the normal,
    into ``points``; returns their number (0 for coal's one point), -1 when it is coal's to answer."""
    if kind[0] == SPHERE or kind[1] == SPHERE:
        return 0  # strictly convex: one point
    sizes = np.empty(2, np.int64)
    direction = np.empty((2, 3))
    supports = np.empty((2, 8, 3))  # each side's support set: a segment's ends, or a box's corners
    for s in range(2):  # shape 1 supports along the normal, shape 2 against it
        for j in range(3):
            direction[s, j] = towards[j] if s == 0 else -towards[j]
        if kind[s] == CAPSULE:
            sizes[s] = _capsule_support(R[s], p[s], dims[s], direction[s], supports[s])
        else:
            sizes[s] = _box_support(R[s], p[s], dims[s], direction[s], supports[s])
    if sizes[0] < 0 or sizes[1] < 0:
        return -1
    if sizes[0] == 1 or sizes[1] == 1:
        return 0
    if sizes[0] == 2 and sizes[1] == 2:  # segments: a capsule's, a box's edge
        count = _segment_on_segment(supports[0], supports[1], towards, points)
    else:
        c = 0 if sizes[0] == 2 else 1
        if sizes[1 - c] != 4:  # a box thinner than the tolerance
            return -1
        face = _face(R[1 - c], p[1 - c], dims[1 - c], direction[1 - c])
        count = _segment_on_face(supports[c], face, towards, points)
    for m in range(max(count, 0)):  # onto the plane of the robot's witness point
        lift = 0.0
        for j in range(3):
            lift += (witness[j] - points[m, j]) * towards[j]
        for j in range(3):
            points[m, j] += lift * towards[j]
    return count


@njit(cache=True)
def _capsule_support(R, p, dims, direction, support):  # type: ignore[no-untyped-def]
    """The number of points of a capsule's support set along ``direction`` (coal's
    ``getShapeSupportSet``: 2 when both ends of its segment are within PATCH_TOLERANCE of the support
    plane, else 1), -1 when that test is within DECISION of its threshold. The 2 points go into
    ``support`` as coal places them: the segment's ends (the +half length end first) moved by the
    radius times the direction's part across the axis."""
    d0, d1, d2 = dot(R[:, 0], direction), dot(R[:, 1], direction), dot(R[:, 2], direction)
    radius, half_length = dims[0], dims[1]
    top = half_length if d2 > PATCH_EPS else (-half_length if d2 < -PATCH_EPS else 0.0)
    value = d2 * top + radius * (d0 * d0 + d1 * d1 + d2 * d2)
    across = radius * (d0 * d0 + d1 * d1)
    below = max(value - (across + d2 * half_length), value - (across - d2 * half_length))
    if abs(below - PATCH_TOLERANCE) <= DECISION:
        return -1
    if below > PATCH_TOLERANCE:
        return 1
    for m in range(2):
        sign = 1.0 if m == 0 else -1.0
        for j in range(3):
            support[m, j] = p[j] + sign * half_length * R[j, 2] + radius * (direction[j] - d2 * R[j, 2])
    return 2


@njit(cache=True)
def _box_support(R, p, half, direction, support):  # type: ignore[no-untyped-def]
    """The number of a box's corners within PATCH_TOLERANCE of its support plane along ``direction``
    (coal's ``getShapeSupportSet``), -1 when a corner is within DECISION of that tolerance; the
    corners go into ``support`` in coal's order (its 2 of an edge are a segment in that order)."""
    d = np.empty(3)
    for a in range(3):
        d[a] = dot(R[:, a], direction) * half[a]
    top = abs(d[0]) + abs(d[1]) + abs(d[2])
    count = 0
    for v in range(8):  # coal's corners: (+ + +), (- + +), (- - +), (+ - +), then the same at -z
        sx = 1.0 if v % 4 == 0 or v % 4 == 3 else -1.0
        sy = 1.0 if v % 4 < 2 else -1.0
        sz = 1.0 if v < 4 else -1.0
        below = top - (sx * d[0] + sy * d[1] + sz * d[2])
        if abs(below - PATCH_TOLERANCE) <= DECISION:
            return -1
        if below < PATCH_TOLERANCE:
            for j in range(3):
                support[count, j] = (
                    p[j] + sx * half[0] * R[j, 0] + sy * half[1] * R[j, 1] + sz * half[2] * R[j, 2]
                )
            count += 1
    return count


@njit(cache=True)
def _face(R, p, half, direction):  # type: ignore[no-untyped-def]
    """The corners (4, 3), in order around it, of the box's face that is its support set of 4 corners
    along ``direction``: across the axis along which the box reaches farthest."""
    along = np.empty(3)
    fixed = 0
    for a in range(3):
        along[a] = R[0, a] * direction[0] + R[1, a] * direction[1] + R[2, a] * direction[2]
        if abs(along[a]) * half[a] > abs(along[fixed]) * half[fixed]:
            fixed = a
    u, v = (fixed + 1) % 3, (fixed + 2) % 3
    face = np.empty((4, 3))
    for m in range(4):
        su = -1.0 if m == 0 or m == 3 else 1.0
        sv = -1.0 if m < 2 else 1.0
        sf = 1.0 if along[fixed] > 0 else -1.0
        for j in range(3):
            face[m, j] = (
                p[j] + sf * half[fixed] * R[j, fixed] + su * half[u] * R[j, u] + sv * half[v] * R[j, v]
            )
    return face


@njit(cache=True)
def _segment_on_segment(first, second, towards, points):  # type: ignore[no-untyped-def]
    """coal's patch of two segment support sets (shape 1's ends ``first``, shape 2's ``second``, rows
    0 and 1 in coal's order): one point when their cross product along ``towards`` is >= 0 (coal
    compares where it meant a determinant), else the ends of ``first`` projected onto ``second``
    across the normal, clamped to it; -1 when the segments are parallel to within DECISION."""
    u, v = np.empty(3), np.empty(3)
    for j in range(3):
        u[j] = first[1, j] - first[0, j]
        v[j] = second[1, j] - second[0, j]
    cross = (u[1] * v[2] - u[2] * v[1]) * towards[0]
    cross += (u[2] * v[0] - u[0] * v[2]) * towards[1]
    cross += (u[0] * v[1] - u[1] * v[0]) * towards[2]
    if abs(cross) <= DECISION * np.sqrt(dot(u, u) * dot(v, v)):
        return -1
    if cross > 0:
        return 0
    across_u, across_v = dot(u, towards), dot(v, towards)
    for j in range(3):  # the segments' directions in the patch plane
        u[j] -= across_u * towards[j]
        v[j] -= across_v * towards[j]
    length = dot(v, v)
    if length < PATCH_EPS or dot(u, u) < PATCH_EPS:
        return 0
    offset = np.empty(3)
    for m in range(2):
        for j in range(3):
            offset[j] = first[m, j] - second[0, j]
        t = min(max(dot(offset, v) / length, 0.0), 1.0)
        for j in range(3):
            points[m, j] = second[0, j] + t * (second[1, j] - second[0, j])
    for j in range(3):
        offset[j] = points[1, j] - points[0, j]
    across = dot(offset, towards)
    if dot(offset, offset) - across * across < PATCH_EPS:
        return 0
    return 2


@njit(cache=True)
def _segment_on_face(segment, face, towards, points):  # type: ignore[no-untyped-def]
    """coal's patch of a segment support set (ends ``segment``) and a box face's (corners ``face`` (4,
    3), in order around it): the segment clipped to the face seen along the normal ``towards``
    (Sutherland-Hodgman), 0 when it misses the face (coal's one point), -1 when an end is within
    DECISION of a side's line."""
    side, inward, edge = np.empty(3), np.empty(3), np.empty(3)
    for j in range(3):
        points[0, j], points[1, j] = segment[0, j], segment[1, j]
    # the face's orientation seen along the normal: the inside of each side is to its left
    for j in range(3):
        side[j] = face[1, j] - face[0, j]
        edge[j] = face[2, j] - face[1, j]
    turn = (side[1] * edge[2] - side[2] * edge[1]) * towards[0]
    turn += (side[2] * edge[0] - side[0] * edge[2]) * towards[1]
    turn += (side[0] * edge[1] - side[1] * edge[0]) * towards[2]
    orientation = 1.0 if turn > 0 else -1.0
    inside = np.empty(2)
    for k in range(4):
        for j in range(3):
            side[j] = face[(k + 1) % 4, j] - face[k, j]
        # the side's inward direction in the patch plane: towards x side, turned to the inside
        inward[0] = orientation * (towards[1] * side[2] - towards[2] * side[1])
        inward[1] = orientation * (towards[2] * side[0] - towards[0] * side[2])
        inward[2] = orientation * (towards[0] * side[1] - towards[1] * side[0])
        scale = np.sqrt(dot(inward, inward))
        for m in range(2):
            inside[m] = 0.0
            for j in range(3):
                inside[m] += (points[m, j] - face[k, j]) * inward[j]
            inside[m] /= scale
            if abs(inside[m]) <= DECISION:
                return -1
        if inside[0] < 0 and inside[1] < 0:
            return 0
        if inside[0] >= 0 and inside[1] >= 0:
            continue
        out = 0 if inside[0] < 0 else 1
        t = inside[1 - out] / (inside[1 - out] - inside[out])
        for j in range(3):
            points[out, j] = points[1 - out, j] + t * (points[out, j] - points[1 - out, j])
    return 2
