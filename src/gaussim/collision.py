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


@dataclass
class Contact:
    """One contact point between a robot geometry and an obstacle.

    Attributes:
        name: ``"geometry/obstacle#k"``, stable while the patch keeps its size.
        joint: Pinocchio joint carrying the robot geometry.
        point: point on the robot surface, world frame, shape (3,) [m].
        normal: unit normal from the obstacle towards the robot, shape (3,).
        gap: signed distance along the normal, negative when penetrating [m].
        friction: Coulomb coefficient of the obstacle.
        restitution: restitution coefficient of the obstacle.
        other_joint: joint carrying the obstacle when it is a robot geometry, else 0 (the world).
    """

    name: str
    geometry: str
    obstacle: str
    joint: int
    point: np.ndarray
    normal: np.ndarray
    gap: float
    friction: float
    restitution: float
    other_joint: int = 0


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
        # Polyhedra against the ground: every vertex within the margin is a candidate contact with
        # its own gap (coal's patch gives one depth for the whole patch, which props a tilted sole).
        self.vertices = _vertices(self.shape) if isinstance(self.obstacle, Ground) else None
        if self.vertices is not None and isinstance(self.obstacle, Ground):
            self.ground_normal = n = np.asarray(self.obstacle.normal)
            t1 = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
            t1 /= np.linalg.norm(t1)
            angles = 2 * np.pi * np.arange(SUPPORT_DIRECTIONS) / SUPPORT_DIRECTIONS
            self.directions = np.outer(np.cos(angles), t1) + np.outer(np.sin(angles), np.cross(n, t1))


class ContactDetector:
    """Finds the contact points of the scene's declared pairs that are closer than ``margin``."""

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

    def detect(self, data: pin.Data) -> list[Contact]:
        """Contacts at the placements held in ``data`` (after forward kinematics)."""
        contacts: list[Contact] = []
        for pair in self.pairs:
            placement = data.oMi[pair.joint] * pair.local
            if pair.other_local is not None:
                other = data.oMi[pair.other_joint] * pair.other_local
                pair.obstacle_tf = coal.Transform3s(other)
                pair.obstacle_center = other.act(pair.obstacle_local_center)
            if pair.vertices is not None:
                contacts += self._on_ground(pair, placement)
                continue
            if pair.obstacle_radius < np.inf and not self._near(pair, placement):
                continue  # coal's half-space test is as cheap as this bounding-sphere test
            tf = coal.Transform3s(placement)
            self.result.clear()
            if not coal.collide(
                pair.shape, tf, pair.obstacle_shape, pair.obstacle_tf, self.request, self.result
            ):
                continue
            contact = self.result.getContact(0)
            normal = -np.asarray(contact.normal)  # coal's normal points from the robot to the obstacle
            gap = float(contact.penetration_depth)
            points = [np.asarray(contact.getNearestPoint1())]
            coal.computeContactPatch(
                pair.shape,
                tf,
                pair.obstacle_shape,
                pair.obstacle_tf,
                self.result,
                self.patch_request,
                self.patch_result,
            )
            if (
                self.patch_result.numContactPatches()
                and (patch := self.patch_result.getContactPatch(0)).size() > 1
            ):
                # patch points lie midway between the surfaces: move them onto the robot's
                middle = np.array([patch.getPoint(i) for i in range(patch.size())]) + normal * (gap / 2)
                if np.ptp(middle, axis=0).max() > PATCH_MIN_EXTENT:
                    # coal orders a patch's points arbitrarily: order them by their place on the robot's
                    # body so that a contact keeps its name from step to step
                    local = np.round((middle - placement.translation) @ placement.rotation, 4)
                    points = list(middle[np.lexsort(local.T[::-1])])
            for k, point in enumerate(points):
                contacts.append(
                    Contact(
                        f"{pair.name}#{k}",
                        pair.geometry,
                        pair.obstacle_name,
                        pair.joint,
                        point,
                        normal,
                        gap,
                        pair.friction,
                        pair.restitution,
                        pair.other_joint,
                    )
                )
        return contacts

    def _on_ground(self, pair: _Pair, placement: pin.SE3) -> list[Contact]:
        """Contacts of a polyhedron with the ground: its vertices within the margin and within
        PATCH_TOLERANCE of the deepest one (or penetrating), reduced to the deepest one when they span
        less than PATCH_MIN_EXTENT, else to the vertices of their support outline."""
        ground: Ground = pair.obstacle  # type: ignore[assignment]
        n = pair.ground_normal
        R, p = placement.rotation, placement.translation
        vertices: np.ndarray = pair.vertices  # type: ignore[assignment]  # set for ground pairs
        # heights of all vertices with one matrix-vector product; world points only for the near ones
        heights = vertices @ (R.T @ n) + (p @ n - ground.height)
        lowest = float(heights.min())
        if lowest > self.margin:
            return []
        # penetrating vertices, and those within PATCH_TOLERANCE of the deepest one
        near = np.flatnonzero(heights <= max(0.0, min(self.margin, lowest + PATCH_TOLERANCE)))
        world, heights = vertices[near] @ R.T + p, heights[near]
        if len(near) == 1 or float((world.max(axis=0) - world.min(axis=0)).max()) <= PATCH_MIN_EXTENT:
            chosen = [int(np.argmin(heights))]
        else:
            chosen = sorted(set(np.argmax(world @ pair.directions.T, axis=0).tolist()))
        return [
            Contact(
                f"{pair.name}#{k}",
                pair.geometry,
                ground.name,
                pair.joint,
                world[i],
                n,
                float(heights[i]),
                ground.friction,
                ground.restitution,
            )
            for k, i in enumerate(chosen)
        ]

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
