"""Stage 2, contact detection (coal): per declared pair, the contact points, normals and gaps."""

from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin
from numba import njit

from .exceptions import ContactError
from .linalg import finite
from .scene import Box, ContactPair, Ground, Scene, Sphere

# Surface points within this distance of the support plane belong to a contact patch [m].
PATCH_TOLERANCE = 1e-3
# A contact patch narrower than this is one point (the rounded foot of a mesh hull touches on a
# ring of nearby vertices; several points there would only add redundant rows) [m].
PATCH_MIN_EXTENT = 2e-2
# A flat face on the ground is supported by the vertices extreme along these many directions of
# the tangent plane (every 360/n degrees): the corners of a box, the outline of a sole.
SUPPORT_DIRECTIONS = 8
# A polyhedron on the ground found to touch at one point keeps that verdict while its orientation
# cannot have brought a vertex this much closer to the ground than the deepest one [m].
NARROW_SLACK = 2e-3


@dataclass
class Contacts:
    """The m contact points of one step, as arrays (one entry per point).

    Attributes:
        names: ``"geometry/obstacle#k"``, stable while a patch keeps its size.
        geometry, obstacle: robot collision geometry and obstacle of each point.
        joint: Pinocchio joint carrying the robot geometry, shape (m,).
        other_joint: joint carrying the obstacle when it is a robot geometry, else 0 (the world), (m,).
        point: points on the robot surface, world frame, shape (m, 3) [m].
        normal: unit normals from the obstacle towards the robot, shape (m, 3).
        gap: signed distances along the normal, negative when penetrating, shape (m,) [m].
        friction, restitution: coefficients of the obstacle, shape (m,).
    """

    names: list[str]
    geometry: list[str]
    obstacle: list[str]
    joint: np.ndarray
    other_joint: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    gap: np.ndarray
    friction: np.ndarray
    restitution: np.ndarray

    def __len__(self) -> int:
        return len(self.names)

    def select(self, keep: np.ndarray) -> Contacts:
        """The contacts where the boolean mask ``keep`` (m,) is true."""
        chosen = np.flatnonzero(keep).tolist()
        return Contacts(
            [self.names[i] for i in chosen],
            [self.geometry[i] for i in chosen],
            [self.obstacle[i] for i in chosen],
            self.joint[keep],
            self.other_joint[keep],
            self.point[keep],
            self.normal[keep],
            self.gap[keep],
            self.friction[keep],
            self.restitution[keep],
        )


NO_CONTACTS = Contacts(
    [], [], [], np.zeros(0, int), np.zeros(0, int), *(np.zeros((0, 3)),) * 2, *(np.zeros(0),) * 3
)


class _Pair:
    """Everything about one declared pair that does not change during a run."""

    def __init__(self, scene: Scene, pair: ContactPair) -> None:
        geometries = scene.robot.collision_model.geometryObjects
        geometry = geometries[pair.geometry]
        self.shape = _convex(geometry.geometry)
        self.local = geometry.placement
        self.joint = int(geometry.parentJoint)
        self.name = pair.name
        self.friction, self.restitution = pair.friction, pair.restitution
        self.geometry = geometry.name
        self.other_joint, self.other_local = 0, None
        if pair.other is not None:  # another robot geometry: it moves, so its placement is per step
            other = geometries[pair.other]
            self.obstacle: Ground | Box | Sphere | None = None
            self.obstacle_name = other.name
            self.obstacle_shape = _convex(other.geometry)
            self.other_joint, self.other_local = int(other.parentJoint), other.placement
            self.obstacle_tf = coal.Transform3s()
        else:
            obstacle = scene.obstacles[pair.obstacle]  # type: ignore[index]
            self.obstacle = obstacle
            self.obstacle_name = obstacle.name
            self.obstacle_shape = obstacle.shape()
            self.obstacle_tf = coal.Transform3s(obstacle.placement())
        if isinstance(self.obstacle, Ground):
            self.obstacle_radius = np.inf
            self.obstacle_center = np.zeros(3)
        else:
            self.obstacle_shape.computeLocalAABB()
            self.obstacle_radius = self.obstacle_shape.aabb_radius
            self.obstacle_local_center = np.asarray(self.obstacle_shape.aabb_center)
            if self.obstacle is not None:
                self.obstacle_center = self.obstacle.placement().act(self.obstacle_local_center)
        self.radius = self.shape.aabb_radius
        self.center = np.asarray(self.shape.aabb_center)
        # Polyhedra against the ground: the vertices of a wide patch, each with its own gap; a sphere
        # is the ball of its radius around a one-vertex hull
        polyhedron = _vertices(self.shape) if isinstance(self.obstacle, Ground) else None
        self.vertices: np.ndarray | None = polyhedron[0] if polyhedron else None
        self.edges: list[list[int]] = polyhedron[1] if polyhedron else []
        self.rounding = float(self.shape.radius) if isinstance(self.shape, coal.Sphere) else 0.0
        if self.vertices is not None and isinstance(self.obstacle, Ground):
            self.ground_normal = n = np.asarray(self.obstacle.normal)
            t1 = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
            t1 /= np.linalg.norm(t1)
            angles = 2 * np.pi * np.arange(SUPPORT_DIRECTIONS) / SUPPORT_DIRECTIONS
            self.directions = np.outer(np.cos(angles), t1) + np.outer(np.sin(angles), np.cross(n, t1))
        self.names = [f"{self.name}#0"]  # contact names "name#k", grown on demand

    def contact_names(self, count: int) -> list[str]:
        """The names of this pair's first ``count`` contact points."""
        while len(self.names) < count:
            self.names.append(f"{self.name}#{len(self.names)}")
        return self.names[:count]


class _GroundHulls:
    """All the pairs of a polyhedron (a box or a mesh's convex hull) or a sphere with a ground plane,
    handled in one compiled pass (:func:`_ground_hulls`): the deepest vertex along the ground's normal
    is the exact closest point of a convex polyhedron to a half-space (the support point coal's narrow
    phase finds), and a sphere is the ball of its radius (its ``rounding``) around a one-vertex hull,
    so these pairs need no narrow-phase call each (a sphere's cost 30 us a step through coal).

    A polyhedron touches at its deepest vertex alone while the vertices near the ground span less
    than PATCH_MIN_EXTENT. That verdict is computed with NARROW_SLACK more tolerance and kept while
    the ground normal seen from the body stays within ``turn`` of where it was decided: two vertices'
    heights differ by at most 2 r |u - u0| more when that normal moves from u0 to u (r: the largest
    distance of a vertex from their mean), so a turn that small cannot bring another vertex close.
    """

    def __init__(self, pairs: list[_Pair]) -> None:
        self.index = np.array([k for k, pair in enumerate(pairs) if pair.vertices is not None], dtype=int)
        chosen = [pairs[k] for k in self.index]
        self.pairs = chosen
        self.joints = [pair.joint for pair in chosen]
        size = max((len(pair.vertices) for pair in chosen), default=0)  # type: ignore[arg-type]
        # the vertices in their joint's frame, homogeneous, as columns, shape (P, 4, size); padded with
        # copies of the first, so that every hull has `size` of them
        columns = []
        for pair in chosen:
            vertices = pair.vertices @ pair.local.rotation.T + pair.local.translation  # type: ignore[operator]
            vertices = np.vstack([vertices, np.repeat(vertices[:1], size - len(vertices), axis=0)])
            columns.append(np.vstack([vertices.T, np.ones(size)]))
        self.columns = np.array(columns).reshape(len(chosen), 4, size)
        # the ground plane (n, -height) of each pair: its product with a joint placement gives the
        # signed distance of the joint frame's points to the ground, shape (P, 4)
        self.plane = np.array([[*p.ground_normal, -p.obstacle.height] for p in chosen]).reshape(-1, 4)  # type: ignore[union-attr]
        self.rounding = np.array([p.rounding for p in chosen])
        reach = [np.linalg.norm(p.vertices - p.vertices.mean(axis=0), axis=1).max() for p in chosen]  # type: ignore[operator]
        self.turn2 = np.array([(NARROW_SLACK / (2.0 * r)) ** 2 if r > 0 else np.inf for r in reach])
        self.narrow_at = np.full((len(chosen), 3), np.nan)  # ground normal, joint frame, of each verdict
        # the edges of each hull as adjacency lists: the neighbours of vertex i of hull k are
        # neighbours[k, first[k, i] : first[k, i + 1]]
        self.first = np.zeros((len(chosen), size + 1), dtype=np.int64)
        self.neighbours = np.zeros(
            (len(chosen), max((sum(map(len, p.edges)) for p in chosen), default=0)), np.int64
        )
        for k, pair in enumerate(chosen):
            counts = [len(e) for e in pair.edges]
            self.first[k, 1 : len(counts) + 1] = np.cumsum(counts)
            self.first[k, len(counts) + 1 :] = self.first[k, len(counts)]  # padding has no neighbours
            self.neighbours[k, : sum(counts)] = [j for e in pair.edges for j in e]
        self.deepest = np.zeros(len(chosen), dtype=np.int64)  # where each search for the deepest starts
        self._data: pin.Data | None = None
        self._views: tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]] = ((), ())

    def detect(self, data: pin.Data, margin: float) -> tuple[tuple[np.ndarray, ...], np.ndarray, float]:
        """The hulls within ``margin`` of the ground: of those that touch at their deepest vertex alone
        (their pairs (k,), deepest vertices in the world (k, 3), normals (k, 3), gaps (k,)), the hulls
        that touch more widely (w,), and the least gap of all the hulls [m]."""
        count = len(self.pairs)  # at most one point each: the kernel fills these and says how many
        pairs, points, normals = np.empty(count, np.int64), np.empty((count, 3)), np.empty((count, 3))
        gaps, wide = np.empty(count), np.empty(count, np.int64)
        k, w, least = _ground_hulls(
            *self._placements(data),
            self.plane,
            self.columns,
            self.first,
            self.neighbours,
            self.deepest,
            self.narrow_at,
            self.turn2,
            self.rounding,
            margin,
            self.index,
            pairs,
            points,
            normals,
            gaps,
            wide,
        )
        if k < count:
            pairs, points, normals, gaps = pairs[:k], points[:k], normals[:k], gaps[:k]
        return (pairs, points, normals, gaps), wide[:w], least

    def _placements(self, data: pin.Data) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
        """(rotations, translations) of the hulls' joints: views of Pinocchio's arrays inside
        ``data.oMi`` itself, which follow every kinematics pass on that data (made once per data)."""
        if self._data is not data:
            oMi = data.oMi
            self._views = (
                tuple(oMi[j].rotation for j in self.joints),
                tuple(oMi[j].translation for j in self.joints),
            )
            self._data = data  # keeps the memory the views read alive
        return self._views


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
    """The compiled pass of :class:`_GroundHulls` (updates ``deepest`` and ``narrow_at``): fills the
    first k entries of the ``*_out`` arrays with what :meth:`_GroundHulls.detect` returns and the
    first w of ``wide_out``; returns (k, w, the least gap of all the hulls).

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


class ContactDetector:
    """Finds the contact points of the scene's declared pairs that are closer than ``margin``.

    A polyhedron on a ground plane touches at its deepest vertex, or, when its vertices near the
    ground span more than PATCH_MIN_EXTENT, at the vertices of their support outline, each with its
    own gap (see :class:`_GroundHulls`). Every other pair goes through coal's narrow phase (the
    deepest point, the normal and the gap) and its contact patch (the points within PATCH_TOLERANCE
    of the support plane): a patch narrower than PATCH_MIN_EXTENT is one point, a wider one
    contributes its points.

    Between steps the pairs can only close by what :meth:`cover` bounds, so after a detection that
    finds every pair farther than the margin, by more than they may have closed since, the step need
    not look: :meth:`cover` says so, and a robot in flight pays for one detection per many steps
    (see :meth:`forget` for a state from elsewhere). :meth:`detect` itself always looks.
    """

    def __init__(self, scene: Scene, margin: float) -> None:
        self.base_margin = self.margin = margin
        self.pairs = [_Pair(scene, p) for p in scene.pairs]
        model = scene.robot.model
        # per pair and velocity coordinate, how fast (at most) the pair's two geometries approach per
        # unit of |v_k| [m/s per unit]: the margin covers what a step can travel (see cover)
        self.levers = np.array(
            [
                _speed_levers(model, p.joint, p.local.act(p.center), p.radius)
                + (
                    _speed_levers(
                        model, p.other_joint, p.other_local.act(p.obstacle_local_center), p.obstacle_radius
                    )
                    if p.other_local is not None
                    else 0.0
                )
                for p in self.pairs
            ]
        )
        self.longest = float(self.levers.max(initial=0.0))  # the longest lever: see cover's reach
        self.hulls = _GroundHulls(self.pairs)
        self.others = [k for k, pair in enumerate(self.pairs) if pair.vertices is None]
        self.request = self._request(margin, coal.GJKVariant.DefaultGJK)
        # coal 3.0's default GJK/EPA returns a NaN normal and a depth of -DBL_MAX for two boxes face
        # to face within ~1e-11 rad (measured: a box resting on a box); the Nesterov-accelerated
        # GJK answers those, and is the retry of any non-finite answer
        self.retry_request = self._request(margin, coal.GJKVariant.NesterovAcceleration)
        self.patch_request = coal.ContactPatchRequest()
        self.patch_request.setPatchTolerance(PATCH_TOLERANCE)
        self.result = coal.CollisionResult()
        self.patch_result = coal.ContactPatchResult(self.patch_request)
        self.friction = np.array([pair.friction for pair in self.pairs])
        self.restitution = np.array([pair.restitution for pair in self.pairs])
        self.joint = np.array([pair.joint for pair in self.pairs], dtype=int)
        self.other_joint = np.array([pair.other_joint for pair in self.pairs], dtype=int)
        self._layouts: dict[bytes, tuple] = {}  # what does not move, per set of touching pairs
        # a lower bound on every pair's gap [m]: the least gap of the last detection less what the
        # pairs may have closed since (-inf: unknown, so the next detection runs)
        self.clearance = -np.inf

    def forget(self) -> None:
        """Detect afresh at the next step: the configuration did not come from the last one's motion."""
        self.clearance = -np.inf

    def cover(
        self, v: np.ndarray, x: np.ndarray, dt: float, x_scale: float, reach: float | None = None
    ) -> bool:
        """Widen the margin to what the pairs can close in one step, at velocity v and free velocity
        x (``x_scale`` 1) or free acceleration x (``x_scale`` dt): a contact is then found the step
        before it closes, at any speed. The margin changes by factors of 1.5 or more, so coal's
        requests are rarely rewritten.

        The bound also covers the motion that led to this step's configuration (its velocity is v), so
        it is taken off the clearance. Returns whether a pair may now be within the margin (False
        while the clearance exceeds it: no detection is needed; NaN: True).

        ``reach``, sum_i |v_i| + |x_i| when known (velocity level), gives a coarser bound at no cost,
        dt reach times the longest lever: while the clearance exceeds twice it plus the base margin,
        that bound alone is taken off and the step need not look (a robot in flight: 0.4 us a step
        less)."""
        if reach is not None:
            coarse = dt * self.longest * reach
            if self.clearance - 2 * coarse > self.base_margin:
                self.clearance -= coarse
                return False
        travel = _travel(self.levers, v, x, dt, x_scale)
        self.clearance -= travel
        needed = self.base_margin + travel
        if needed > self.margin or (self.margin > self.base_margin and 3 * needed < self.margin):
            self.margin = max(self.base_margin, 1.5 * needed)
            self.request.security_margin = self.retry_request.security_margin = self.margin
        return not self.clearance > self.margin

    def detect(self, data: pin.Data) -> Contacts:
        """Contacts at the placements held in ``data`` (after forward kinematics), in the order of the
        declared pairs; the least gap of all, a lower bound for the pairs coal answers, becomes the
        clearance."""
        pieces: list[tuple[np.ndarray, ...]] = []  # (pair of each point (k,), points, normals, gaps)
        clearance = np.inf
        if len(self.hulls.pairs):
            one, wide, clearance = self.hulls.detect(data, self.margin)
            if len(one[0]):
                pieces.append(one)
            for h in wide.tolist():
                outline = self._on_ground(h, data.oMi[self.hulls.joints[h]].homogeneous)
                pieces.append(self._piece(int(self.hulls.index[h]), self.hulls.plane[h, :3], *outline))
        for k in self.others:
            hit, least = self._collide(self.pairs[k], data)
            clearance = min(clearance, least)
            if hit is not None:
                pieces.append(self._piece(k, *hit))
        self.clearance = clearance
        if not pieces:
            return NO_CONTACTS
        if len(pieces) == 1:
            owner, points, normals, gaps = pieces[0]
        else:
            owner, points, normals, gaps = (np.concatenate([p[i] for p in pieces]) for i in range(4))
            order = np.argsort(owner, kind="stable")  # the declared order of the pairs
            owner, points, normals, gaps = owner[order], points[order], normals[order], gaps[order]
        key = owner.tobytes()
        if key not in self._layouts:
            if len(self._layouts) > 1024:  # many pairs touching in ever new combinations
                self._layouts.clear()
            self._layouts[key] = self._layout(owner)
        names, geometry, obstacle, joint, other_joint, friction, restitution = self._layouts[key]
        return Contacts(
            names, geometry, obstacle, joint, other_joint, points, normals, gaps, friction, restitution
        )

    def _layout(self, owner: np.ndarray) -> tuple:
        """What the contacts of pairs ``owner`` (one entry per point, sorted) have that does not move."""
        pairs, counts = np.unique(owner, return_counts=True)
        chosen = [self.pairs[k] for k in owner.tolist()]
        arrays = [self.joint[owner], self.other_joint[owner], self.friction[owner], self.restitution[owner]]
        for array in arrays:
            array.flags.writeable = False  # shared by every step with these pairs touching
        names = [
            name for k, n in zip(pairs.tolist(), counts.tolist()) for name in self.pairs[k].contact_names(n)
        ]
        return (names, [pair.geometry for pair in chosen], [pair.obstacle_name for pair in chosen], *arrays)

    @staticmethod
    def _request(margin: float, variant: coal.GJKVariant) -> coal.CollisionRequest:
        request = coal.CollisionRequest()
        request.security_margin = margin
        request.num_max_contacts = 1
        request.gjk_variant = variant
        return request

    def _piece(
        self, k: int, normal: np.ndarray, points: np.ndarray, gaps: np.ndarray
    ) -> tuple[np.ndarray, ...]:
        count = len(points)
        return np.full(count, k), points, np.repeat(normal[None, :], count, axis=0), gaps

    def _collide(
        self, pair: _Pair, data: pin.Data
    ) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray] | None, float]:
        """coal's narrow phase and contact patch for one pair: (normal, points (k, 3), gaps (k,)), or
        None when the pair is farther apart than the margin; and a lower bound on its gap [m]."""
        placement = data.oMi[pair.joint] * pair.local
        if pair.other_local is not None:
            other = data.oMi[pair.other_joint] * pair.other_local
            pair.obstacle_tf = coal.Transform3s(other)
            pair.obstacle_center = other.act(pair.obstacle_local_center)
        if pair.obstacle_radius < np.inf:  # coal's half-space test is as cheap as a bounding-sphere test
            apart = self._sphere_gap(pair, placement)
            if apart > self.margin:
                return None, apart
        for request in (self.request, self.retry_request):
            self.result.clear()
            if not coal.collide(
                pair.shape, placement, pair.obstacle_shape, pair.obstacle_tf, request, self.result
            ):
                return None, request.security_margin
            # copies: coal's arrays are views into its result, which the next pair overwrites
            contact = self.result.getContact(0)
            normal = -contact.normal.copy()  # coal's normal points from the robot to the obstacle
            gap = contact.penetration_depth
            if finite(normal) and np.isfinite(gap):
                break
        else:
            raise ContactError(
                f"coal returned a non-finite contact for pair '{pair.name}' (normal {normal}, gap {gap}) "
                "with both GJK variants tried",
                pair.name,
            )
        patch = self._patch(pair, placement, normal, gap)
        if patch is None:
            return (normal, contact.getNearestPoint1().copy()[None, :], np.array([gap])), gap
        return (normal, patch, np.full(len(patch), gap)), gap

    def _patch(self, pair: _Pair, placement: pin.SE3, normal: np.ndarray, gap: float) -> np.ndarray | None:
        """The points (k, 3) of the pair's contact patch on the robot's surface when it spans more than
        PATCH_MIN_EXTENT, ordered by their place on the robot's body, else None (one point)."""
        patch_result = self.patch_result
        coal.computeContactPatch(
            pair.shape,
            placement,
            pair.obstacle_shape,
            pair.obstacle_tf,
            self.result,
            self.patch_request,
            patch_result,
        )
        if not patch_result.numContactPatches():
            return None
        patch = patch_result.getContactPatch(0)
        size = patch.size()
        if size < 2:
            return None
        # patch points lie midway between the surfaces: move them onto the robot's
        middle = np.array([patch.getPoint(i) for i in range(size)]) + normal * (gap / 2)
        if np.ptp(middle, axis=0).max() <= PATCH_MIN_EXTENT:
            return None
        # coal orders a patch's points arbitrarily: order them by their place on the robot's body so
        # that a contact keeps its name from step to step
        local = np.round((middle - placement.translation) @ placement.rotation, 4)
        return middle[np.lexsort(local.T[::-1])]

    def _on_ground(self, hull: int, placement: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Hull ``hull`` (its joint's placement (4, 4)) on the ground: its vertices within PATCH_TOLERANCE
        of the deepest one (or penetrating), reduced to the vertices of their support outline: (points
        (k, 3), gaps (k,)), each with its own gap; the deepest vertex alone when they span less than
        PATCH_MIN_EXTENT."""
        pair, columns = self.hulls.pairs[hull], self.hulls.columns[hull]
        heights = self.hulls.plane[hull] @ placement @ columns
        near = np.flatnonzero(heights <= max(0.0, min(self.margin, float(heights.min()) + PATCH_TOLERANCE)))
        world, heights = (placement[:3] @ columns[:, near]).T, heights[near]
        if np.ptp(world, axis=0).max() <= PATCH_MIN_EXTENT:
            deepest = int(np.argmin(heights))
            return world[deepest : deepest + 1], heights[deepest : deepest + 1]
        chosen = sorted(set(np.argmax(world @ pair.directions.T, axis=0).tolist()))
        return world[chosen], heights[chosen]

    def _sphere_gap(self, pair: _Pair, placement: pin.SE3) -> float:
        """The gap of the pair's bounding spheres, a lower bound on its own [m] (far pairs skip the
        narrow phase)."""
        distance = np.linalg.norm(placement.act(pair.center) - pair.obstacle_center)
        return float(distance - pair.radius - pair.obstacle_radius)


def _speed_levers(model: pin.Model, joint: int, center: np.ndarray, radius: float) -> np.ndarray:
    """For a body's sphere (``center`` in the frame of ``joint``, ``radius``), bounds on the speed of
    its points per unit |v_k|, shape (nv,): |linear| + |angular| reach for each velocity coordinate k
    of the joint and its ancestors, with reach the farthest the sphere can be from that joint's
    origin (the joint placements along the chain, a prismatic joint's limits, |center| + radius)."""
    levers, neutral = np.zeros(model.nv), pin.neutral(model)
    reach = float(np.linalg.norm(center)) + radius
    while joint > 0:
        jmodel = model.joints[joint]
        jdata = jmodel.createData()
        jmodel.calc(jdata, neutral)
        S = np.asarray(jdata.S).reshape(6, -1)
        for i in range(jmodel.nv):
            levers[jmodel.idx_v + i] = np.linalg.norm(S[:3, i]) + np.linalg.norm(S[3:, i]) * reach
        if not np.linalg.norm(S[3:]):  # prismatic: how far it carries the body
            limits = np.concatenate(
                [
                    model.lowerPositionLimit[jmodel.idx_q : jmodel.idx_q + jmodel.nq],
                    model.upperPositionLimit[jmodel.idx_q : jmodel.idx_q + jmodel.nq],
                ]
            )
            reach += float(np.abs(limits[np.isfinite(limits)]).max(initial=0.0))
        reach += float(np.linalg.norm(model.jointPlacements[joint].translation))
        joint = model.parents[joint]
    return levers


@njit(cache=True)
def _travel(levers, v, x, dt, x_scale):  # type: ignore[no-untyped-def]
    """The farthest a pair can close in a step: max_k dt sum_i levers[k, i] (|v_i| + x_scale |x_i|)."""
    farthest = 0.0
    for k in range(levers.shape[0]):
        total = 0.0
        for i in range(levers.shape[1]):
            total += levers[k, i] * (abs(v[i]) + x_scale * abs(x[i]))
        farthest = max(farthest, total)
    return dt * farthest


def _convex(shape: coal.CollisionGeometry) -> coal.CollisionGeometry:
    """The shape contacts are computed on: the convex hull of a mesh (built at robot load)."""
    shape = shape.convex if isinstance(shape, coal.BVHModelBase) else shape
    shape.computeLocalAABB()
    return shape


def _vertices(shape: coal.CollisionGeometry) -> tuple[np.ndarray, list[list[int]]] | None:
    """Vertices of a box or convex polyhedron in its own frame, shape (V, 3), and the vertices each
    shares an edge with; a sphere's centre (its radius is the hull's rounding); None for the other
    curved shapes."""
    if isinstance(shape, coal.Box):
        half = np.asarray(shape.halfSide)
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
        return corners * half, [[i ^ 1, i ^ 2, i ^ 4] for i in range(8)]  # corner i = 4 x + 2 y + z
    if isinstance(shape, coal.ConvexBase):
        points = np.asarray(shape.points())
        return points, [list(shape.neighbors(i)) for i in range(len(points))]
    if isinstance(shape, coal.Sphere):
        return np.zeros((1, 3)), [[]]
    return None
