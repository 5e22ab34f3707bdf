"""Stage 2, contact detection (coal): per declared pair, the contact points, normals and gaps."""

from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from .scene import Ground, Scene

# Surface points within this distance of the support plane belong to a contact patch [m].
PATCH_TOLERANCE = 1e-6
# A contact patch narrower than this is one point (the rounded foot of a mesh hull touches on a
# small facet; several points there would only add redundant rows) [m].
PATCH_MIN_EXTENT = 5e-3


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


class _Pair:
    """Everything about one declared pair that does not change during a run."""

    def __init__(self, scene: Scene, geometry_id: int, obstacle_id: int, name: str) -> None:
        geometry = scene.robot.collision_model.geometryObjects[geometry_id]
        obstacle = scene.obstacles[obstacle_id]
        shape = geometry.geometry
        self.shape = shape.convex if isinstance(shape, coal.BVHModelBase) else shape
        self.shape.computeLocalAABB()
        self.local = geometry.placement
        self.joint = int(geometry.parentJoint)
        self.name = name
        self.geometry = geometry.name
        self.obstacle = obstacle
        self.obstacle_shape = obstacle.shape()
        self.obstacle_tf = coal.Transform3s(obstacle.placement())
        if isinstance(obstacle, Ground):
            self.obstacle_radius = np.inf
            self.obstacle_center = np.zeros(3)
        else:
            self.obstacle_shape.computeLocalAABB()
            self.obstacle_radius = self.obstacle_shape.aabb_radius
            self.obstacle_center = obstacle.placement().act(np.asarray(self.obstacle_shape.aabb_center))
        self.radius = self.shape.aabb_radius
        self.center = np.asarray(self.shape.aabb_center)


class ContactDetector:
    """Finds the contact points of the scene's declared pairs that are closer than ``margin``."""

    def __init__(self, scene: Scene, margin: float) -> None:
        self.margin = margin
        self.pairs = [_Pair(scene, p.geometry, p.obstacle, p.name) for p in scene.pairs]
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
                    points = list(middle)
            for k, point in enumerate(points):
                contacts.append(
                    Contact(
                        f"{pair.name}#{k}",
                        pair.geometry,
                        pair.obstacle.name,
                        pair.joint,
                        point,
                        normal,
                        gap,
                        pair.obstacle.friction,
                        pair.obstacle.restitution,
                    )
                )
        return contacts

    def _near(self, pair: _Pair, placement: pin.SE3) -> bool:
        """Bounding-sphere test that skips the narrow phase for far pairs."""
        gap = np.linalg.norm(placement.act(pair.center) - pair.obstacle_center) - pair.radius
        return gap - pair.obstacle_radius <= self.margin
