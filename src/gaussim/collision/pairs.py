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
    """Every joint's placement in the world as one read-only array (njoints, 4, 3), the kernels' input
    (:mod:`gaussim.kernels.pairs`): row j holds the columns of joint j's rotation, then its translation.

    Pinocchio keeps ``data.oMi`` as consecutive SE3s, each its column-major rotation then its translation
    (sized with the model, never moved): the array is a view of that memory, which follows every
    kinematics pass on that data without a copy (made once per data, after its layout is checked; the
    view holds the data alive). Where a build of Pinocchio lays them out otherwise, each call copies them.

    Args:
        joints: how many joints the kernels read (1 + the largest index they read): a data of a model
            with fewer is refused.
    """

    def __init__(self, joints: int) -> None:
        self.joints = joints
        self._data: pin.Data | None = None
        self._view: np.ndarray | None = None

    def __call__(self, data: pin.Data) -> np.ndarray:
        """The placements held in ``data``."""
        if self._data is not data:
            if len(data.oMi) < self.joints:  # the kernels index the array unchecked
                raise ValueError(
                    f"the data has {len(data.oMi)} joint placements, the contact pairs read {self.joints}: "
                    "a data of another model"
                )
            self._data, self._view = data, _view(data)
        return self._view if self._view is not None else copied(data.oMi)


def copied(oMi: pin.StdVec_SE3) -> np.ndarray:
    """The placements ``oMi`` as :class:`JointPlacements` gives them, copied (read-only)."""
    placements = np.array([np.vstack([M.rotation.T, M.translation]) for M in oMi]).reshape(-1, 4, 3)
    placements.flags.writeable = False
    return placements


class _Memory:
    """The memory of ``data.oMi`` as numpy reads it (``__array_interface__``): an array made from it
    keeps this, and so the data, alive."""

    def __init__(self, data: pin.Data, start: int) -> None:
        self.data = data
        count = len(data.oMi)
        self.__array_interface__ = {
            "shape": (count, 4, 3),
            "typestr": "<f8",
            "data": (start, True),
            "version": 3,
        }


def _view(data: pin.Data) -> np.ndarray | None:
    """A read-only view of ``data.oMi``'s memory as :class:`JointPlacements` gives it, or None where the
    placements do not lie there as such."""
    oMi = data.oMi
    start = oMi[0].rotation.__array_interface__["data"][0]
    step = 12 * 8  # bytes: a rotation's 9 doubles, then a translation's 3
    for j, M in enumerate(oMi):
        rotation, translation = M.rotation, M.translation
        if (
            rotation.__array_interface__["data"][0] != start + j * step
            or rotation.strides != (8, 24)
            or translation.__array_interface__["data"][0] != start + j * step + 72
            or translation.strides != (8,)
        ):
            return None
    view = np.asarray(_Memory(data, start))
    return view if not view.flags.writeable and np.array_equal(view, copied(oMi)) else None


def vertices(shape: coal.CollisionGeometry) -> tuple[np.ndarray, list[list[int]]]:
    """Vertices of a box or convex polyhedron in its own frame, shape (V, 3), and the vertices each
    shares an edge with; a capsule's segment (its radius is the hull's rounding); else (a sphere) its
    centre (its radius is the hull's rounding)."""
    if isinstance(shape, coal.Box):
        half = np.asarray(shape.halfSide)
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
        return corners * half, [[i ^ 1, i ^ 2, i ^ 4] for i in range(8)]  # corner i = 4 x + 2 y + z
    if isinstance(shape, coal.Capsule):
        return np.array([[0.0, 0.0, -shape.halfLength], [0.0, 0.0, shape.halfLength]]), [[1], [0]]
    if isinstance(shape, coal.ConvexBase):
        points = np.asarray(shape.points())
        return points, [list(shape.neighbors(i)) for i in range(len(points))]
    return np.zeros((1, 3)), [[]]
