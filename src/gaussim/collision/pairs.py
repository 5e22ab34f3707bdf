"""The declared contact pairs as the detection routines read them."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin

from ..scene import Box, ContactPair, Ground, Scene, Sphere


class Pair:
    """Everything about one declared pair that does not change during a run.

    Attributes:
        name: ``"geometry/obstacle"``; its contact points are ``name#k``.
        geometry, obstacle_name: the robot geometry's and the obstacle's (or other geometry's) names.
        shape, obstacle_shape: the coal shapes contacts are computed on (a mesh's convex hull).
        joint, local: the joint carrying the geometry and the geometry's placement in its frame.
        obstacle: the fixed obstacle, or None when the other side is a robot geometry.
        other_joint, other_local: the joint carrying that geometry (else 0, the world) and its
            placement in that joint's frame (else None).
        obstacle_tf: the obstacle's placement in the world (a robot geometry's is set per step).
        center, radius: the geometry's bounding sphere, in the frame of ``joint``, (3,) [m], [m].
        obstacle_center, obstacle_radius: the obstacle's, in the frame of ``other_joint`` (the world
            for a fixed obstacle) (3,) [m]; a ground's radius is infinite.
        obstacle_box: the obstacle shape's own bounding box around ``obstacle_center`` (coal's AABB
            in the shape's frame: a box's is the box), shape (4, 3): its half sides [m], then its three
            axes in the frame of ``other_joint``, one a row (zeros for a ground).
        friction, restitution: the pair's coefficients.
    """

    def __init__(self, scene: Scene, pair: ContactPair) -> None:
        geometries = scene.robot.collision_model.geometryObjects
        geometry = geometries[pair.geometry]
        self.shape = convex(geometry.geometry)
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
            self.obstacle_shape = convex(other.geometry)
            self.other_joint, self.other_local = int(other.parentJoint), other.placement
            self.obstacle_tf = coal.Transform3s()
            frame = other.placement  # where the obstacle sits in the frame of other_joint
        else:
            obstacle = scene.obstacles[pair.obstacle]  # type: ignore[index]
            self.obstacle = obstacle
            self.obstacle_name = obstacle.name
            self.obstacle_shape = obstacle.shape()
            self.obstacle_tf = coal.Transform3s(obstacle.placement())
            frame = obstacle.placement()
        self.center = self.local.act(np.asarray(self.shape.aabb_center))
        self.radius = self.shape.aabb_radius
        self.obstacle_box = np.zeros((4, 3))
        if isinstance(self.obstacle, Ground):
            self.obstacle_radius = np.inf
            self.obstacle_center = np.zeros(3)
        else:
            self.obstacle_shape.computeLocalAABB()
            self.obstacle_radius = self.obstacle_shape.aabb_radius
            self.obstacle_center = frame.act(np.asarray(self.obstacle_shape.aabb_center))
            box = self.obstacle_shape.aabb_local
            self.obstacle_box[0] = (np.asarray(box.max_) - np.asarray(box.min_)) / 2
            self.obstacle_box[1:] = frame.rotation.T
        self.names = [f"{self.name}#0"]  # contact names "name#k", grown on demand

    def contact_names(self, count: int) -> list[str]:
        """The names of this pair's first ``count`` contact points."""
        while len(self.names) < count:
            self.names.append(f"{self.name}#{len(self.names)}")
        return self.names[:count]


def convex(shape: coal.CollisionGeometry) -> coal.CollisionGeometry:
    """The shape contacts are computed on: the convex hull of a mesh (built at robot load)."""
    shape = shape.convex if isinstance(shape, coal.BVHModelBase) else shape
    shape.computeLocalAABB()
    return shape


class JointPlacements:
    """The placements of some joints in the world as (rotations (3, 3), translations (3,)): views of
    Pinocchio's arrays inside ``data.oMi`` itself, which follow every kinematics pass on that data
    (made once per data).

    Args:
        joints: the joints, in the order their placements are given.
    """

    def __init__(self, joints: list[int]) -> None:
        self.joints = joints
        self._data: pin.Data | None = None
        self._views: tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]] = ((), ())

    def __call__(self, data: pin.Data) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
        """The joints' (rotations, translations) in ``data``."""
        if self._data is not data:
            oMi = data.oMi
            self._views = (
                tuple(oMi[j].rotation for j in self.joints),
                tuple(oMi[j].translation for j in self.joints),
            )
            self._data = data  # keeps the memory the views read alive
        return self._views
