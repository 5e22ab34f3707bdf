"""Cylinders on the ground, compiled: the answer of coal's narrow phase and contact patch without
their calls.

coal takes a cylinder's distance to a half-space at its support point in the direction d into the
ground (its rim point below the axis, on the lower cap: the exact deepest point), and its contact
patch from the cylinder's support set in d within PATCH_TOLERANCE (``support_functions.cpp``): the
cap, as ``getNumSamplesCurvedShapes`` (12) points of its rim, when its rim points r d_xy and -r d_xy
both lie within the tolerance of the support plane (a cylinder standing on a cap); else the points
r d_xy of both caps that do (d_xy as it stands, not normalised: a cylinder lying on its side, its
two ends); a patch of one point is the deepest point. The patch's points are projected along the
normal onto the plane through the deepest point, all at its gap. A test within DECISION of its
threshold, where coal's round-off may decide it the other way, is coal's.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .collision import _extent, _unbounded
from .pairs import ASK_COAL, DECISION, FAR, FOUND, PATCH_MIN_EXTENT, PATCH_TOLERANCE, order, place
from .primitives import COAL_THRESHOLD

# coal's sampling of a cap in a contact patch (ContactPatchRequest's default curved-shape samples).
CAP_SAMPLES = 12
# Below this, a component of the direction into the ground is zero to coal's cylinder support (Eigen's
# dummy precision): its support point is then the cap's centre or the middle of the side, with the
# half length or the radius times INFLATE (its preferred side in such ties).
ALIGNED = 1e-12
INFLATE = 1 + 1e-10


@njit(cache=True)
def ground_cylinders(
    placements,
    side,
    local_rotation,
    local_translation,
    dims,
    plane,
    near,
    margin,
    answer,
    gaps,
    normals,
    points,
    sizes,
):  # type: ignore[no-untyped-def]
    """The compiled pass of :class:`gaussim.collision.cylinders.GroundCylinders` on pairs ``near``: for each,
    fills ``answer`` (FAR, FOUND or ASK_COAL), ``gaps`` (the gap when FAR or FOUND), and when FOUND its normal
    (the ground's) and its ``sizes`` points on the cylinder (a patch ordered by their place on it, as
    :class:`gaussim.collision.narrow.NarrowPhase` orders them)."""
    R = np.empty((2, 3, 3))
    p = np.empty((2, 3))
    for k in range(near.shape[0]):
        i = near[k]
        place(placements, side, local_rotation, local_translation, i, R, p)
        answer[k], gaps[k], sizes[k] = _pair(R[0], p[0], dims[i], plane[i], margin, normals[k], points[k])


@njit(cache=True)
def _pair(R, c, dims, plane, margin, normal, points):  # type: ignore[no-untyped-def]
    """One cylinder (axes R, centre c, radius and half length ``dims``) and the ground ``plane`` (its
    normal n and height): returns (answer, gap, number of points), the normal and the points written
    into ``normal`` (3,) and ``points`` (CAP_SAMPLES, 3)."""
    r, h = dims[0], dims[1]
    d = np.empty(3)  # the direction into the ground, in the cylinder's frame
    for a in range(3):
        d[a] = -(R[0, a] * plane[0] + R[1, a] * plane[1] + R[2, a] * plane[2])
        normal[a] = plane[a]
    across = np.sqrt(d[0] * d[0] + d[1] * d[1])
    deepest = np.zeros(3)  # coal's support point: the rim below the axis, on the lower cap
    standing = max(abs(d[0]), abs(d[1])) <= ALIGNED  # straight: the cap's centre
    if not standing:
        deepest[0], deepest[1] = r * d[0] / across, r * d[1] / across
    half = INFLATE * h if standing else h  # coal inflates the half length of a cylinder standing straight
    if d[2] > ALIGNED:
        deepest[2] = half
    elif d[2] < -ALIGNED:
        deepest[2] = -half
    else:  # lying straight: the middle of the side, coal's radius inflated by INFLATE
        deepest[0], deepest[1] = INFLATE * deepest[0], INFLATE * deepest[1]
    z = h if d[2] > 0.0 else -h  # the cap coal samples
    world = np.empty(3)
    _to_world(R, c, deepest, world)
    gap = world[0] * plane[0] + world[1] * plane[1] + world[2] * plane[2] - plane[3]
    if gap - margin > COAL_THRESHOLD:
        return FAR, gap, 0
    support = d[0] * deepest[0] + d[1] * deepest[1] + d[2] * deepest[2]
    rim = r * across * across  # d . (r d_xy, 0)
    # the cap: both rim points +-r d_xy of the lower cap within the tolerance
    below, above = support - (abs(d[2]) * h - rim), support - (abs(d[2]) * h + rim)
    if abs(below - PATCH_TOLERANCE) <= DECISION or abs(above - PATCH_TOLERANCE) <= DECISION:
        return ASK_COAL, 0.0, 0
    count = 0
    local = np.empty(3)
    if below <= PATCH_TOLERANCE:
        for s in range(CAP_SAMPLES):
            angle = s * (2.0 * np.pi / CAP_SAMPLES)
            local[0], local[1], local[2] = r * np.cos(angle), r * np.sin(angle), z
            _to_world(R, c, local, points[s])
        count = CAP_SAMPLES
    else:  # the points r d_xy of each cap that lie within the tolerance (d_xy as it stands)
        for top in (-h, h):
            height = rim + d[2] * top
            if abs(support - height - PATCH_TOLERANCE) <= DECISION:
                return ASK_COAL, 0.0, 0
            if support - height <= PATCH_TOLERANCE:
                local[0], local[1], local[2] = r * d[0], r * d[1], top
                _to_world(R, c, local, points[count])
                count += 1
    if count >= 2:
        low, high = _unbounded()
        for s in range(count):  # onto the plane through the deepest point, along the normal
            offset = (points[s, 0] - world[0]) * plane[0] + (points[s, 1] - world[1]) * plane[1]
            offset += (points[s, 2] - world[2]) * plane[2]
            for a in range(3):
                points[s, a] -= offset * plane[a]
                low[a], high[a] = min(low[a], points[s, a]), max(high[a], points[s, a])
        extent = _extent(low, high)
        if abs(extent - PATCH_MIN_EXTENT) <= DECISION:
            return ASK_COAL, 0.0, 0
        if extent > PATCH_MIN_EXTENT:
            order(points, count, R, c)
            return FOUND, gap, count
    points[0] = world
    return FOUND, gap, 1


@njit(cache=True, inline="always")
def _to_world(R, c, local, out):  # type: ignore[no-untyped-def]
    """``out`` = R local + c."""
    for a in range(3):
        out[a] = R[a, 0] * local[0] + R[a, 1] * local[1] + R[a, 2] * local[2] + c[a]
