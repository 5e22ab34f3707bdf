"""The declared contact pairs as the detection routines read them."""

from __future__ import annotations

import coal
import numpy as np

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
        center, radius: the geometry's bounding sphere, in the shape's frame, (3,) [m], [m].
        obstacle_local_center, obstacle_radius: the obstacle's, in its shape's frame (3,) [m]; a
            ground's radius is infinite.
        obstacle_center: the obstacle's bounding-sphere centre in the world (a robot geometry's is
            set per step) (3,) [m].
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
        else:
            obstacle = scene.obstacles[pair.obstacle]  # type: ignore[index]
            self.obstacle = obstacle
            self.obstacle_name = obstacle.name
            self.obstacle_shape = obstacle.shape()
            self.obstacle_tf = coal.Transform3s(obstacle.placement())
        self.radius = self.shape.aabb_radius
        self.center = np.asarray(self.shape.aabb_center)
        if isinstance(self.obstacle, Ground):
            self.obstacle_radius = np.inf
            self.obstacle_center = np.zeros(3)
        else:
            self.obstacle_shape.computeLocalAABB()
            self.obstacle_radius = self.obstacle_shape.aabb_radius
            self.obstacle_local_center = np.asarray(self.obstacle_shape.aabb_center)
            if self.obstacle is not None:
                self.obstacle_center = self.obstacle.placement().act(self.obstacle_local_center)
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
