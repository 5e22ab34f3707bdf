"""Stage 2, contact detection (coal): per declared pair, the contact points, normals and gaps."""

from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

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
        self.geometry = geometry.name
        self.other_joint, self.other_local = 0, None
        if pair.other is not None:  # another robot geometry: it moves, so its placement is per step
            other = geometries[pair.other]
            self.obstacle: Ground | Box | Sphere | None = None
            self.obstacle_name = other.name
            self.friction, self.restitution = scene.self_contact
            self.obstacle_shape = _convex(other.geometry)
            self.other_joint, self.other_local = int(other.parentJoint), other.placement
            self.obstacle_tf = coal.Transform3s()
        else:
            obstacle = scene.obstacles[pair.obstacle]  # type: ignore[index]
            self.obstacle = obstacle
            self.obstacle_name = obstacle.name
            self.friction, self.restitution = obstacle.friction, obstacle.restitution
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
        # Polyhedra against the ground: the vertices of a wide patch, each with its own gap
        self.vertices = _vertices(self.shape) if isinstance(self.obstacle, Ground) else None
        if self.vertices is not None and isinstance(self.obstacle, Ground):
            self.ground_normal = n = np.asarray(self.obstacle.normal)
            t1 = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
            t1 /= np.linalg.norm(t1)
            angles = 2 * np.pi * np.arange(SUPPORT_DIRECTIONS) / SUPPORT_DIRECTIONS
            self.directions = np.outer(np.cos(angles), t1) + np.outer(np.sin(angles), np.cross(n, t1))
            # two vertices' heights differ by at most 2 r |u - u0| more when the ground normal seen
            # from the body moves from u0 to u (r: largest distance of a vertex from their mean)
            reach = float(np.linalg.norm(self.vertices - self.vertices.mean(axis=0), axis=1).max())
            self.narrow_turn = NARROW_SLACK / (2.0 * reach) if reach > 0 else np.inf
            self.narrow_at: list[float] | None = None  # body-frame normal of the last one-point verdict


class ContactDetector:
    """Finds the contact points of the scene's declared pairs that are closer than ``margin``.

    Every pair goes through coal's narrow phase (the deepest point, the normal and the gap) and its
    contact patch (the points within PATCH_TOLERANCE of the support plane). A patch narrower than
    PATCH_MIN_EXTENT is one point; a wider one contributes its points, except for a polyhedron on the
    ground, which touches at the vertices of its support outline, each with its own gap (coal's patch
    gives one depth for the whole patch, which props a tilted sole).
    """

    def __init__(self, scene: Scene, margin: float) -> None:
        self.margin = margin
        self.pairs = [_Pair(scene, p) for p in scene.pairs]
        self.request = coal.CollisionRequest()
        self.request.security_margin = margin
        self.request.num_max_contacts = 1
        self.patch_request = coal.ContactPatchRequest()
        self.patch_request.setPatchTolerance(PATCH_TOLERANCE)
        self.result = coal.CollisionResult()
        self.patch_result = coal.ContactPatchResult(self.patch_request)

    def detect(self, data: pin.Data) -> Contacts:
        """Contacts at the placements held in ``data`` (after forward kinematics)."""
        found: list[tuple[_Pair, np.ndarray, list, list[float]]] = []  # pair, normal, points, gaps
        for pair in self.pairs:
            placement = data.oMi[pair.joint] * pair.local
            if pair.other_local is not None:
                other = data.oMi[pair.other_joint] * pair.other_local
                pair.obstacle_tf = coal.Transform3s(other)
                pair.obstacle_center = other.act(pair.obstacle_local_center)
            if pair.obstacle_radius < np.inf and not self._near(pair, placement):
                continue  # coal's half-space test is as cheap as this bounding-sphere test
            self.result.clear()
            if not coal.collide(
                pair.shape, placement, pair.obstacle_shape, pair.obstacle_tf, self.request, self.result
            ):
                continue
            # copies: coal's arrays are views into its result, which the next pair overwrites
            contact = self.result.getContact(0)
            normal = -contact.normal  # coal's normal points from the robot to the obstacle
            gap = contact.penetration_depth
            if pair.vertices is not None:
                normal = pair.ground_normal
                wide = None if self._narrow_on_ground(pair, placement) else self._on_ground(pair, placement)
            else:
                patch = self._patch(pair, placement, normal, gap)
                wide = None if patch is None else (list(patch), [gap] * len(patch))
            points, gaps = wide or ([contact.getNearestPoint1().copy()], [gap])
            found.append((pair, normal, points, gaps))
        if not found:
            return NO_CONTACTS
        owners = [pair for pair, _, points, _ in found for _ in points]
        return Contacts(
            [f"{pair.name}#{k}" for pair, _, points, _ in found for k in range(len(points))],
            [pair.geometry for pair in owners],
            [pair.obstacle_name for pair in owners],
            np.array([pair.joint for pair in owners]),
            np.array([pair.other_joint for pair in owners]),
            np.array([p for _, _, points, _ in found for p in points]),
            np.array([normal for _, normal, points, _ in found for _ in points]),
            np.array([g for _, _, _, gaps in found for g in gaps]),
            np.array([pair.friction for pair in owners]),
            np.array([pair.restitution for pair in owners]),
        )

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

    def _narrow_on_ground(self, pair: _Pair, placement: pin.SE3) -> bool:
        """True when a polyhedron's vertices near the ground span less than PATCH_MIN_EXTENT, so that it
        touches at its deepest vertex alone. The verdict is computed with NARROW_SLACK more tolerance
        and kept while the body has turned too little to change it (most steps of a rounded foot)."""
        u = (pair.ground_normal @ placement.rotation).tolist()  # the ground normal in the body frame
        if pair.narrow_at is not None:
            du = [a - b for a, b in zip(u, pair.narrow_at)]
            if (du[0] * du[0] + du[1] * du[1] + du[2] * du[2]) ** 0.5 <= pair.narrow_turn:
                return True
        heights = pair.vertices @ np.array(u)  # type: ignore[operator]
        near = pair.vertices[heights <= heights.min() + PATCH_TOLERANCE + NARROW_SLACK]  # type: ignore[index]
        pair.narrow_at = u if np.ptp(near, axis=0).max() <= PATCH_MIN_EXTENT else None
        return pair.narrow_at is not None

    def _on_ground(self, pair: _Pair, placement: pin.SE3) -> tuple[list, list[float]] | None:
        """A polyhedron on the ground: its vertices within PATCH_TOLERANCE of the deepest one (or
        penetrating), reduced to the vertices of their support outline: (points, gaps), each with its own
        gap; None when they span less than PATCH_MIN_EXTENT (one point). coal's normal is the ground's."""
        ground: Ground = pair.obstacle  # type: ignore[assignment]
        n = pair.ground_normal
        R, p = placement.rotation, placement.translation
        vertices: np.ndarray = pair.vertices  # type: ignore[assignment]  # set for ground pairs
        heights = vertices @ (R.T @ n) + (p @ n - ground.height)
        near = np.flatnonzero(heights <= max(0.0, min(self.margin, float(heights.min()) + PATCH_TOLERANCE)))
        world, heights = vertices[near] @ R.T + p, heights[near]
        if np.ptp(world, axis=0).max() <= PATCH_MIN_EXTENT:
            return None
        chosen = sorted(set(np.argmax(world @ pair.directions.T, axis=0).tolist()))
        return list(world[chosen]), heights[chosen].tolist()

    def _near(self, pair: _Pair, placement: pin.SE3) -> bool:
        """Bounding-sphere test that skips the narrow phase for far pairs."""
        gap = np.linalg.norm(placement.act(pair.center) - pair.obstacle_center) - pair.radius
        return gap - pair.obstacle_radius <= self.margin


def _convex(shape: coal.CollisionGeometry) -> coal.CollisionGeometry:
    """The shape contacts are computed on: the convex hull of a mesh (built at robot load)."""
    shape = shape.convex if isinstance(shape, coal.BVHModelBase) else shape
    shape.computeLocalAABB()
    return shape


def _vertices(shape: coal.CollisionGeometry) -> np.ndarray | None:
    """Vertices of a box or convex polyhedron in its own frame, shape (V, 3); None for curved shapes."""
    if isinstance(shape, coal.Box):
        half = np.asarray(shape.halfSide)
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
        return corners * half
    if isinstance(shape, coal.ConvexBase):
        return np.asarray(shape.points())
    return None
