"""Compiled kernels the collision routines share (:mod:`gaussim.collision`): the joints' placements read
where Pinocchio keeps them, the bounding-sphere broad phase, a pair's two sides placed in the world, and
a patch's points put in a stable order.

Every kernel reads the placements of all the model's joints as one array (njoints, 4, 3): row j holds
the three columns of joint j's rotation, then its translation
(:class:`gaussim.collision.pairs.JointPlacements`, a view of ``data.oMi`` itself). One array, whatever
the scene, is one signature, which the build compiles ahead (:mod:`.prebuild`)."""

from __future__ import annotations

import numpy as np
from numba import njit

# Surface points within this distance of the support plane belong to a contact patch [m].
PATCH_TOLERANCE = 1e-3
# A contact patch narrower than this is one point (the rounded foot of a mesh hull touches on a
# ring of nearby vertices; several points there would only add redundant rows) [m].
PATCH_MIN_EXTENT = 2e-2
# A support-set, clipping or patch-width test this close to its threshold, where coal's round-off may
# decide it the other way, is coal's [m].
DECISION = 1e-9

# Answers of a pair family's kernel per pair: farther apart than the margin, points found, or coal's to
# answer.
FAR, FOUND, ASK_COAL = 0, 1, 2


@njit(cache=True)
def place(placements, side, local_rotation, local_translation, i, R, p):  # type: ignore[no-untyped-def]
    """Both sides of pair ``i`` in the world: (R[s] (columns: its axes), p[s]) for s = 0 (the robot's)
    and 1, its joint ``side[i, s]``'s placement (``placements``, see the module's docstring) times its
    own (``local_rotation[i, s]``, ``local_translation[i, s]``)."""
    for s in range(2):
        X = placements[side[i, s]]  # X[c, a]: row a of the rotation's column c; X[3]: the translation
        for a in range(3):  # loops: a BLAS call per 3 x 3 product costs more than its arithmetic
            p[s, a] = X[3, a]
            for b in range(3):
                R[s, a, b] = 0.0
                p[s, a] += X[b, a] * local_translation[i, s, b]
                for c in range(3):
                    R[s, a, b] += X[c, a] * local_rotation[i, s, c, b]


@njit(cache=True)
def sphere_gaps(placements, side, centers, radius, obstacle_radius, boxes, margin, gaps):  # type: ignore[no-untyped-def]
    """The compiled pass of :meth:`gaussim.collision.narrow.BoundingSpheres.gaps`: each pair's centres in
    the world, the distance of the two spheres into ``gaps``, and within ``margin`` the larger of that and
    the distance of the robot geometry's sphere to the obstacle's box (``boxes``: its half sides and its
    three axes, in the frame of the obstacle's joint, from the centre the spheres share)."""
    d = np.empty(3)  # the robot sphere's centre less the obstacle's, in the world
    for i in range(gaps.shape[0]):
        squared = 0.0
        for a in range(3):
            d[a] = 0.0
            for s in range(2):
                X = placements[side[i, s]]
                x = (
                    X[3, a]
                    + X[0, a] * centers[i, s, 0]
                    + X[1, a] * centers[i, s, 1]
                    + X[2, a] * centers[i, s, 2]
                )
                d[a] += x if s == 0 else -x
            squared += d[a] * d[a]
        gaps[i] = np.sqrt(squared) - radius[i] - obstacle_radius[i]
        if gaps[i] <= margin and np.isfinite(obstacle_radius[i]):  # not a ground's
            X, outside = placements[side[i, 1]], 0.0
            for b in range(3):  # along the box's axis b: R boxes[i, 1 + b]
                along = 0.0
                for a in range(3):
                    axis = (
                        X[0, a] * boxes[i, 1 + b, 0]
                        + X[1, a] * boxes[i, 1 + b, 1]
                        + X[2, a] * boxes[i, 1 + b, 2]
                    )
                    along += d[a] * axis
                beyond = max(abs(along) - boxes[i, 0, b], 0.0)
                outside += beyond * beyond
            gaps[i] = max(gaps[i], np.sqrt(outside) - radius[i])


@njit(cache=True)
def nearby(apart, margin):  # type: ignore[no-untyped-def]
    """The pairs within ``margin`` (their gaps ``apart`` (P,) at most it), ascending, and the least gap
    of the others (inf when none is farther)."""
    near = np.empty(apart.shape[0], np.int64)
    count, least = 0, np.inf
    for i in range(apart.shape[0]):
        if apart[i] > margin:
            least = min(least, apart[i])
        else:  # NaN too: the narrow phase decides
            near[count] = i
            count += 1
    return near[:count], least


@njit(cache=True)
def gathered(owner, near, answer, gaps, normals, points, sizes, least):  # type: ignore[no-untyped-def]
    """What a pair family's kernel answered for the pairs ``near`` (:func:`nearby`; ``answer``,
    ``gaps``, ``normals``, ``points``, ``sizes`` as its kernel fills them): the points found as one
    piece (the declared pair ``owner`` of each, its point, normal and gap; pair by pair in their order),
    the pairs (indices into ``near``'s array) asked of coal, and the least of ``least`` and the gaps of
    the pairs answered."""
    total, asked = 0, 0
    for k in range(near.shape[0]):
        if answer[k] == FOUND:
            total += sizes[k]
        elif answer[k] == ASK_COAL:
            asked += 1
    pairs, found = np.empty(total, np.int64), np.empty((total, 3))
    towards, apart = np.empty((total, 3)), np.empty(total)
    coal = np.empty(asked, np.int64)
    out, asked = 0, 0
    for k in range(near.shape[0]):
        if answer[k] == ASK_COAL:
            coal[asked] = near[k]
            asked += 1
            continue
        least = min(least, gaps[k])
        if answer[k] != FOUND:
            continue
        for j in range(sizes[k]):
            pairs[out], apart[out] = owner[near[k]], gaps[k]
            for a in range(3):
                found[out, a], towards[out, a] = points[k, j, a], normals[k, a]
            out += 1
    return (pairs, found, towards, apart), coal, least


@njit(cache=True)
def point_keys(owner, max_points, keys):  # type: ignore[no-untyped-def]
    """Each point's key into ``keys`` (its declared pair ``owner`` (sorted) times ``max_points``
    plus its rank among that pair's points, at most ``max_points - 1``), and (the first point of each
    pair, their counts)."""
    m = len(owner)
    starts, runs = np.empty(m, np.int64), 0
    for i in range(m):
        if i == 0 or owner[i] != owner[i - 1]:
            starts[runs], runs = i, runs + 1
        keys[i] = owner[i] * max_points + min(i - starts[runs - 1], max_points - 1)
    counts = np.empty(runs, np.int64)
    for r in range(runs):
        counts[r] = (starts[r + 1] if r + 1 < runs else m) - starts[r]
    return starts[:runs], counts


@njit(cache=True)
def order(points, count, R, p):  # type: ignore[no-untyped-def]
    """Sorts the first ``count`` points by their coordinates on the robot's geometry (at R, p), rounded
    to 0.1 mm, x first (the order of :meth:`gaussim.collision.narrow.NarrowPhase._patch`); returns
    whether two of them round alike (coal's order of those is then its own)."""
    keys = np.empty((count, 3))
    for j in range(count):
        for c in range(3):
            keys[j, c] = np.rint(
                (
                    (points[j, 0] - p[0]) * R[0, c]
                    + (points[j, 1] - p[1]) * R[1, c]
                    + (points[j, 2] - p[2]) * R[2, c]
                )
                * 1e4
            )
    for j in range(1, count):  # insertion sort: a handful of points
        m = j
        while m > 0 and _before(keys[m], keys[m - 1]):
            for a in range(3):
                keys[m, a], keys[m - 1, a] = keys[m - 1, a], keys[m, a]
                points[m, a], points[m - 1, a] = points[m - 1, a], points[m, a]
            m -= 1
    for j in range(1, count):
        if not _before(keys[j - 1], keys[j]):
            return True
    return False


@njit(cache=True)
def _before(a, b):  # type: ignore[no-untyped-def]
    """Whether key ``a`` sorts before ``b`` (x, then y, then z)."""
    for j in range(3):
        if a[j] != b[j]:
            return a[j] < b[j]
    return False


@njit(cache=True)
def support_gaps(placements, side, vertices, start, rounding, centers, boxes, obstacle_radius, margin, gaps):  # type: ignore[no-untyped-def]
    """Within ``margin``, the larger of ``gaps[i]`` and the separation, along the three axes of the
    obstacle's box (``boxes``, ``centers`` as :func:`sphere_gaps` reads them), of the box and the robot
    shape's vertices ``vertices[start[i]:start[i + 1]]`` (in the frame of its joint; the shape lies
    within ``rounding[i]`` of their hull): a separating axis, a lower bound on the pair's gap. A pair
    without vertices, or against a ground, keeps its gap."""
    c, u, local = np.empty(3), np.empty(3), np.empty(3)
    for i in range(gaps.shape[0]):
        if gaps[i] > margin or start[i] == start[i + 1] or not np.isfinite(obstacle_radius[i]):
            continue
        X, Y = placements[side[i, 0]], placements[side[i, 1]]
        for a in range(3):  # the box's centre in the world
            c[a] = (
                Y[3, a] + Y[0, a] * centers[i, 1, 0] + Y[1, a] * centers[i, 1, 1] + Y[2, a] * centers[i, 1, 2]
            )
        separation = -np.inf
        for b in range(3):
            axis = boxes[i, 1 + b]
            for a in range(3):  # the box's axis b in the world, then in the robot joint's frame
                u[a] = Y[0, a] * axis[0] + Y[1, a] * axis[1] + Y[2, a] * axis[2]
            offset = (
                X[3, 0] * u[0] + X[3, 1] * u[1] + X[3, 2] * u[2] - (c[0] * u[0] + c[1] * u[1] + c[2] * u[2])
            )
            for j in range(3):
                local[j] = X[j, 0] * u[0] + X[j, 1] * u[1] + X[j, 2] * u[2]
            low, high = np.inf, -np.inf
            for v in range(start[i], start[i + 1]):
                height = vertices[v, 0] * local[0] + vertices[v, 1] * local[1] + vertices[v, 2] * local[2]
                low, high = min(low, height), max(high, height)
            half = boxes[i, 0, b]
            separation = max(separation, low + offset - half, -half - (high + offset))
        gaps[i] = max(gaps[i], separation - rounding[i])
