"""Polyhedra and spheres against a ground plane (a half-space), all such pairs in one compiled pass.

The deepest vertex along the ground's normal is the exact closest point of a convex polyhedron to a
half-space (the support point coal's narrow phase finds), and a sphere is the ball of its radius (its
``rounding``) around a one-vertex hull, so these pairs need no narrow-phase call each.
"""

from __future__ import annotations

from typing import NamedTuple

import coal
import numpy as np
import pinocchio as pin
from numba import njit

from .contacts import PATCH_MIN_EXTENT, PATCH_TOLERANCE, Piece, one_pair
from .pairs import JointPlacements, Pair

# A flat face on the ground is supported by the vertices extreme along these many directions of
# the tangent plane (every 360/n degrees): the corners of a box, the outline of a sole.
SUPPORT_DIRECTIONS = 8
# A polyhedron on the ground found to touch at one point keeps that verdict while its orientation
# cannot have brought a vertex this much closer to the ground than the deepest one [m].
NARROW_SLACK = 2e-3


class Hulls(NamedTuple):
    """The P hulls of a :class:`GroundHulls`, padded to the same number V of vertices, as the compiled
    pass reads them.

    Attributes:
        plane: the ground plane (n, -height) of each pair: its product with a joint placement gives
            the signed distance of the joint frame's points to the ground, shape (P, 4).
        columns: the vertices in their joint's frame, homogeneous, as columns, shape (P, 4, V) [m]
            (padded with copies of the first).
        first, neighbours: the edges of each hull as adjacency lists: the neighbours of vertex i of
            hull k are ``neighbours[k, first[k, i] : first[k, i + 1]]``, shapes (P, V + 1), (P, E).
        rounding: the radius of a sphere (around its one vertex), else 0, shape (P,) [m].
        turn2: the squared turn of the ground normal seen from the body that keeps a one-point
            verdict, shape (P,).
        deepest: where each search for the deepest vertex starts (updated by each pass), (P,).
        narrow_at: the ground normal, in the joint frame, of each one-point verdict, NaN where none
            is kept (updated by each pass), shape (P, 3).
    """

    plane: np.ndarray
    columns: np.ndarray
    first: np.ndarray
    neighbours: np.ndarray
    rounding: np.ndarray
    turn2: np.ndarray
    deepest: np.ndarray
    narrow_at: np.ndarray


class GroundHulls:
    """All the pairs of a polyhedron (a box or a mesh's convex hull) or a sphere with a ground plane.

    A polyhedron touches at its deepest vertex alone while the vertices near the ground span less
    than PATCH_MIN_EXTENT. That verdict is computed with NARROW_SLACK more tolerance and kept while
    the ground normal seen from the body stays within ``turn`` of where it was decided: two vertices'
    heights differ by at most 2 r |u - u0| more when that normal moves from u0 to u (r: the largest
    distance of a vertex from their mean), so a turn that small cannot bring another vertex close.
    A polyhedron that touches more widely touches at the vertices of its support outline, each with
    its own gap (:meth:`_on_ground`).

    Args:
        pairs: the declared pairs of the scene.
        index: which of them this routine answers, each a box, convex or sphere on a :class:`Ground`.
    """

    def __init__(self, pairs: list[Pair], index: list[int]) -> None:
        self.index = np.array(index, dtype=int)
        self.pairs = [pairs[k] for k in index]
        self.joints = [pair.joint for pair in self.pairs]
        self.placements = JointPlacements(self.joints)
        self.hulls = _hulls(self.pairs)
        self.directions = [_support_directions(np.asarray(p.obstacle.normal)) for p in self.pairs]  # type: ignore[union-attr]

    def detect(self, data: pin.Data, margin: float) -> tuple[list[Piece], float]:
        """The contacts of the hulls within ``margin`` [m] of the ground at the placements held in
        ``data``, and the least gap of all the hulls [m]."""
        one, wide, least = touching(*self.placements(data), self.hulls, margin, self.index)
        pieces = [one] if len(one[0]) else []
        for h in wide.tolist():
            points, gaps = self._on_ground(h, data.oMi[self.joints[h]].homogeneous, margin)
            pieces.append(one_pair(int(self.index[h]), self.hulls.plane[h, :3], points, gaps))
        return pieces, least

    def _on_ground(self, hull: int, placement: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray]:
        """Hull ``hull`` (its joint's placement (4, 4)) on the ground: its vertices within PATCH_TOLERANCE
        of the deepest one (or penetrating), reduced to the vertices of their support outline: (points
        (k, 3), gaps (k,)), each with its own gap; the deepest vertex alone when they span less than
        PATCH_MIN_EXTENT."""
        columns = self.hulls.columns[hull]
        heights = self.hulls.plane[hull] @ placement @ columns
        near = np.flatnonzero(heights <= max(0.0, min(margin, float(heights.min()) + PATCH_TOLERANCE)))
        world, heights = (placement[:3] @ columns[:, near]).T, heights[near]
        if np.ptp(world, axis=0).max() <= PATCH_MIN_EXTENT:
            deepest = int(np.argmin(heights))
            return world[deepest : deepest + 1], heights[deepest : deepest + 1]
        chosen = sorted(set(np.argmax(world @ self.directions[hull].T, axis=0).tolist()))
        return world[chosen], heights[chosen]


def touching(
    rotations: tuple[np.ndarray, ...],
    translations: tuple[np.ndarray, ...],
    hulls: Hulls,
    margin: float,
    index: np.ndarray,
) -> tuple[Piece, np.ndarray, float]:
    """One compiled pass over the hulls (:func:`_ground_hulls`, which updates ``hulls.deepest`` and
    ``hulls.narrow_at``) at their joints' placements (P rotations (3, 3), translations (3,)), for the
    contacts within ``margin`` [m]; ``index``: the declared pair of each hull, shape (P,).

    Returns: the hulls that touch at their deepest vertex alone (a :data:`Piece`), the hulls that
    touch more widely (w,), and the least gap of all the hulls [m]."""
    count = len(index)  # at most one point each: the kernel fills these and says how many
    pairs, points, normals = np.empty(count, np.int64), np.empty((count, 3)), np.empty((count, 3))
    gaps, wide = np.empty(count), np.empty(count, np.int64)
    k, w, least = _ground_hulls(
        rotations,
        translations,
        hulls.plane,
        hulls.columns,
        hulls.first,
        hulls.neighbours,
        hulls.deepest,
        hulls.narrow_at,
        hulls.turn2,
        hulls.rounding,
        margin,
        index,
        pairs,
        points,
        normals,
        gaps,
        wide,
    )
    if k < count:
        pairs, points, normals, gaps = pairs[:k], points[:k], normals[:k], gaps[:k]
    return (pairs, points, normals, gaps), wide[:w], least


@njit(cache=True)
def _ground_hulls(
    rotations,
    translations,
    plane,
    columns,
    first,
    neighbours,
    deepest,
    narrow_at,
    turn2,
    rounding,
    margin,
    pair,
    pairs_out,
    points_out,
    normals_out,
    gaps_out,
    wide_out,
):  # type: ignore[no-untyped-def]
    """The compiled pass of :func:`touching` (the arrays of :class:`Hulls`; updates ``deepest`` and
    ``narrow_at``): fills the first k entries of the ``*_out`` arrays with the one-point contacts and
    the first w of ``wide_out`` with the hulls that touch more widely; returns (k, w, the least gap
    of all the hulls).

    The deepest vertex is found by descent along the hull's edges from the last one: a vertex no
    neighbour of which is deeper is the deepest of a convex polyhedron (a linear function has no
    other local minimum on its vertex graph)."""
    count, size = columns.shape[0], columns.shape[2]
    gaps, points = np.empty(count), np.empty((count, 3))
    narrow = np.zeros(count, np.bool_)
    touching = np.zeros(count, np.bool_)
    c = np.empty(4)  # the ground seen from the joint: (n^T R, n^T p - height)
    for k in range(count):
        R, p, X = rotations[k], translations[k], columns[k]
        for j in range(3):
            c[j] = plane[k, 0] * R[0, j] + plane[k, 1] * R[1, j] + plane[k, 2] * R[2, j]
        c[3] = plane[k, 0] * p[0] + plane[k, 1] * p[1] + plane[k, 2] * p[2] + plane[k, 3]
        i = deepest[k]
        lowest = c[0] * X[0, i] + c[1] * X[1, i] + c[2] * X[2, i] + c[3]
        descending = True
        while descending:
            descending = False
            for e in range(first[k, i], first[k, i + 1]):
                j = neighbours[k, e]
                height = c[0] * X[0, j] + c[1] * X[1, j] + c[2] * X[2, j] + c[3]
                if height < lowest:
                    i, lowest, descending = j, height, True
                    break
        deepest[k], gaps[k] = i, lowest - rounding[k]
        for j in range(3):
            points[k, j] = R[j, 0] * X[0, i] + R[j, 1] * X[1, i] + R[j, 2] * X[2, i] + p[j]
            points[k, j] -= rounding[k] * plane[k, j]
        touching[k] = gaps[k] <= margin
        if not touching[k]:
            continue
        turned = (c[0] - narrow_at[k, 0]) ** 2 + (c[1] - narrow_at[k, 1]) ** 2 + (c[2] - narrow_at[k, 2]) ** 2
        if turned <= turn2[k]:  # False where no verdict was kept (NaN)
            narrow[k] = True
            continue
        low, high = np.full(3, np.inf), np.full(3, -np.inf)
        for i in range(size):
            if (
                c[0] * X[0, i] + c[1] * X[1, i] + c[2] * X[2, i] + c[3]
                <= lowest + PATCH_TOLERANCE + NARROW_SLACK
            ):
                for j in range(3):
                    low[j], high[j] = min(low[j], X[j, i]), max(high[j], X[j, i])
        narrow[k] = (high - low).max() <= PATCH_MIN_EXTENT
        for j in range(3):
            narrow_at[k, j] = c[j] if narrow[k] else np.nan
    one = w = 0
    least = np.inf
    for k in range(count):
        least = min(least, gaps[k])
        if touching[k] and narrow[k]:
            pairs_out[one], gaps_out[one] = pair[k], gaps[k]
            points_out[one], normals_out[one] = points[k], plane[k, :3]
            one += 1
        elif touching[k]:
            wide_out[w] = k
            w += 1
    return one, w, least


def _hulls(pairs: list[Pair]) -> Hulls:
    """The :class:`Hulls` of polyhedra and spheres ``pairs`` on the ground."""
    polyhedra = [_vertices(pair.shape) for pair in pairs]
    size = max((len(vertices) for vertices, _ in polyhedra), default=0)
    columns = []
    for pair, (vertices, _) in zip(pairs, polyhedra):
        vertices = vertices @ pair.local.rotation.T + pair.local.translation
        vertices = np.vstack([vertices, np.repeat(vertices[:1], size - len(vertices), axis=0)])
        columns.append(np.vstack([vertices.T, np.ones(size)]))
    first = np.zeros((len(pairs), size + 1), dtype=np.int64)
    neighbours = np.zeros((len(pairs), max((sum(map(len, e)) for _, e in polyhedra), default=0)), np.int64)
    for k, (_, edges) in enumerate(polyhedra):
        counts = [len(e) for e in edges]
        first[k, 1 : len(counts) + 1] = np.cumsum(counts)
        first[k, len(counts) + 1 :] = first[k, len(counts)]  # padding has no neighbours
        neighbours[k, : sum(counts)] = [j for e in edges for j in e]
    reach = [np.linalg.norm(v - v.mean(axis=0), axis=1).max() for v, _ in polyhedra]
    return Hulls(
        plane=np.array([[*p.obstacle.normal, -p.obstacle.height] for p in pairs]).reshape(-1, 4),  # type: ignore[union-attr]
        columns=np.array(columns).reshape(len(pairs), 4, size),
        first=first,
        neighbours=neighbours,
        rounding=np.array(
            [float(p.shape.radius) if isinstance(p.shape, coal.Sphere) else 0.0 for p in pairs]
        ),
        turn2=np.array([(NARROW_SLACK / (2.0 * r)) ** 2 if r > 0 else np.inf for r in reach]),
        deepest=np.zeros(len(pairs), dtype=np.int64),
        narrow_at=np.full((len(pairs), 3), np.nan),
    )


def _support_directions(n: np.ndarray) -> np.ndarray:
    """SUPPORT_DIRECTIONS unit directions of the plane of normal ``n`` (3,), shape (SUPPORT_DIRECTIONS, 3)."""
    t1 = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
    t1 /= np.linalg.norm(t1)
    angles = 2 * np.pi * np.arange(SUPPORT_DIRECTIONS) / SUPPORT_DIRECTIONS
    return np.outer(np.cos(angles), t1) + np.outer(np.sin(angles), np.cross(n, t1))


def _vertices(shape: coal.CollisionGeometry) -> tuple[np.ndarray, list[list[int]]]:
    """Vertices of a box or convex polyhedron in its own frame, shape (V, 3), and the vertices each
    shares an edge with; else (a sphere) its centre (its radius is the hull's rounding)."""
    if isinstance(shape, coal.Box):
        half = np.asarray(shape.halfSide)
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
        return corners * half, [[i ^ 1, i ^ 2, i ^ 4] for i in range(8)]  # corner i = 4 x + 2 y + z
    if isinstance(shape, coal.ConvexBase):
        points = np.asarray(shape.points())
        return points, [list(shape.neighbors(i)) for i in range(len(points))]
    return np.zeros((1, 3)), [[]]
