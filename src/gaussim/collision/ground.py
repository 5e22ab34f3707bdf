"""Polyhedra, spheres and capsules against a ground plane (a half-space), all such pairs in one compiled pass.

The deepest vertex along the ground's normal is the exact closest point of a convex polyhedron to a
half-space (the support point coal's narrow phase finds), and a sphere is the ball of its radius (its
``rounding``) around a one-vertex hull, a capsule around a two-vertex one, so these pairs need no
narrow-phase call each.
"""

from __future__ import annotations

from typing import NamedTuple

import coal
import numpy as np
import pinocchio as pin

from ..kernels.bound import Bound
from ..kernels.collision import NARROW_SLACK
from .contacts import PATCH_MIN_EXTENT, PATCH_TOLERANCE, Piece
from .pairs import JointPlacements, Pair, vertices

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
ground_hulls = Bound("collision.ground_hulls")

# A flat face on the ground is supported by the vertices extreme along these many directions of
# the tangent plane (every 360/n degrees): the corners of a box, the outline of a sole.
SUPPORT_DIRECTIONS = 8


class Hulls(NamedTuple):
    """The P hulls of a :class:`GroundHulls`, padded to the same number V of vertices, as the compiled
    pass reads them.

    Attributes:
        plane: the ground plane (n, -height) of each pair: its product with a joint placement gives
            the signed distance of the joint frame's points to the ground, shape (P, 4).
        columns: the vertices in their joint's frame, homogeneous, as columns, shape (P, 4, V) [m]
            (padded with copies of the first).
        sizes: each hull's own number of vertices (those columns come first), shape (P,).
        first, neighbours: the edges of each hull as adjacency lists: the neighbours of vertex i of
            hull k are ``neighbours[k, first[k, i] : first[k, i + 1]]``, shapes (P, V + 1), (P, E).
        rounding: the radius of a sphere (around its one vertex) or a capsule (around its two), else
            0, shape (P,) [m].
        directions: the SUPPORT_DIRECTIONS directions of each ground's plane, the second half the
            first's opposites, shape (P, D, 3).
        turn2: the squared turn of the ground normal seen from the body that keeps a one-point
            verdict, shape (P,).
        deepest: where each search for the deepest vertex starts (updated by each pass), (P,).
        narrow_at: the ground normal, in the joint frame, of each one-point verdict, NaN where none
            is kept (updated by each pass), shape (P, 3).
    """

    plane: np.ndarray
    columns: np.ndarray
    sizes: np.ndarray
    first: np.ndarray
    neighbours: np.ndarray
    rounding: np.ndarray
    directions: np.ndarray
    turn2: np.ndarray
    deepest: np.ndarray
    narrow_at: np.ndarray


class GroundHulls:
    """All the pairs of a polyhedron (a box or a mesh's convex hull), a sphere or a capsule with a
    ground plane.

    A polyhedron touches at its deepest vertex alone while the vertices near the ground span less
    than PATCH_MIN_EXTENT. That verdict is computed with NARROW_SLACK more tolerance and kept while
    the ground normal seen from the body stays within ``turn`` of where it was decided: two vertices'
    heights differ by at most 2 r |u - u0| more when that normal moves from u0 to u (r: the largest
    distance of a vertex from their mean), so a turn that small cannot bring another vertex close.
    A polyhedron that touches more widely touches at its vertices within PATCH_TOLERANCE of the
    deepest one (or penetrating), reduced to the vertices of their support outline (the extreme ones
    along SUPPORT_DIRECTIONS directions of the ground's plane), each with its own gap; the deepest
    alone when they span less than PATCH_MIN_EXTENT.

    Args:
        pairs: the declared pairs of the scene.
        index: which of them this routine answers, each a box, convex, sphere or capsule on a
            :class:`Ground`.
    """

    def __init__(self, pairs: list[Pair], index: list[int]) -> None:
        self.index = np.array(index, dtype=int)
        self.pairs = [pairs[k] for k in index]
        self.joints = np.array([pair.joint for pair in self.pairs], dtype=np.int64)
        self.placements = JointPlacements(int(self.joints.max(initial=0)) + 1)
        self.hulls = _hulls(self.pairs)
        # twice the farthest vertex from the mean, at least each hull's diameter (all pairs of a mesh's
        # thousands of vertices, padded to the largest hull, took gigabytes: b1_z1, centauro)
        vertices = self.hulls.columns[:, :3, :]
        offsets = vertices - vertices.mean(axis=2, keepdims=True)
        self.diameters = 2.0 * np.sqrt((offsets**2).sum(axis=1)).max(axis=1, initial=0.0)

    def detect(self, data: pin.Data, margin: float, turns: np.ndarray) -> tuple[list[Piece], float]:
        """The contacts of the hulls within ``margin`` [m] of the ground at the placements held in
        ``data`` (each patch as deep as its pair's turn in ``turns`` [rad] times the hull's diameter,
        where that exceeds PATCH_TOLERANCE: see :class:`~.driver.Routine`), and the least gap of all
        the hulls [m]."""
        placements = self.placements(data)
        found, least = touching(
            placements, self.joints, self.hulls, margin, self.index, turns, self.diameters
        )
        return ([found] if len(found[0]) else []), least


def touching(
    placements: np.ndarray,
    joints: np.ndarray,
    hulls: Hulls,
    margin: float,
    index: np.ndarray,
    turns: np.ndarray,
    diameters: np.ndarray,
) -> tuple[Piece, float]:
    """One compiled pass over the hulls (:func:`~gaussim.kernels.collision.ground_hulls`, which updates
    ``hulls.deepest`` and ``hulls.narrow_at``) at the placements of their joints ``joints`` (P,) among
    ``placements`` (see :class:`~.pairs.JointPlacements`), for the contacts within ``margin`` [m], each
    hull's patch max(PATCH_TOLERANCE, its pair's turn in ``turns`` [rad] times its diameter in
    ``diameters`` (P,) [m]) deep; ``index``: the declared pair of each hull, shape (P,).
    Returns: the contacts of the hulls (a :data:`Piece`, hull by hull) and the least gap of all the
    hulls [m]."""
    return ground_hulls.call(  # type: ignore[no-any-return]
        placements,
        joints,
        hulls.plane,
        hulls.columns,
        hulls.first,
        hulls.neighbours,
        hulls.sizes,
        hulls.deepest,
        hulls.narrow_at,
        hulls.turn2,
        hulls.rounding,
        hulls.directions,
        margin,
        (PATCH_TOLERANCE, PATCH_MIN_EXTENT),
        turns,
        diameters,
        index,
    )


def _hulls(pairs: list[Pair]) -> Hulls:
    """The :class:`Hulls` of polyhedra and spheres ``pairs`` on the ground."""
    polyhedra = [vertices(pair.shape) for pair in pairs]
    size = max((len(points) for points, _ in polyhedra), default=0)
    columns = []
    for pair, (points, _) in zip(pairs, polyhedra):
        points = points @ pair.local.rotation.T + pair.local.translation
        points = np.vstack([points, np.repeat(points[:1], size - len(points), axis=0)])
        columns.append(np.vstack([points.T, np.ones(size)]))
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
        sizes=np.array([len(vertices) for vertices, _ in polyhedra], dtype=np.int64),
        first=first,
        neighbours=neighbours,
        rounding=np.array(
            [float(p.shape.radius) if isinstance(p.shape, coal.Sphere | coal.Capsule) else 0.0 for p in pairs]
        ),
        directions=np.array(
            [_support_directions(np.asarray(p.obstacle.normal)) for p in pairs]  # type: ignore[union-attr]
        ).reshape(len(pairs), SUPPORT_DIRECTIONS, 3),
        turn2=np.array([(NARROW_SLACK / (2.0 * r)) ** 2 if r > 0 else np.inf for r in reach]),
        deepest=np.zeros(len(pairs), dtype=np.int64),
        narrow_at=np.full((len(pairs), 3), np.nan),
    )


def _support_directions(n: np.ndarray) -> np.ndarray:
    """SUPPORT_DIRECTIONS unit directions of the plane of normal ``n`` (3,), shape (SUPPORT_DIRECTIONS, 3):
    the second half the first's exact opposites (one pass finds the extremes along both)."""
    t1 = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
    t1 /= np.linalg.norm(t1)
    angles = 2 * np.pi * np.arange(SUPPORT_DIRECTIONS // 2) / SUPPORT_DIRECTIONS
    half = np.outer(np.cos(angles), t1) + np.outer(np.sin(angles), np.cross(n, t1))
    return np.vstack([half, -half])
