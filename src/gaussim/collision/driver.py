"""The detection driver: each declared pair goes to the routine of its geometry-pair type, and the
points the routines find are gathered into one :class:`~.contacts.Contacts` in the declared order."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import coal
import numpy as np
import pinocchio as pin

from ..dynamics import Supports, joint_jacobians
from ..kernels.bound import Bound
from ..scene import Scene
from .boxes import BoxPairs
from .contacts import MAX_POINTS, NO_CONTACTS, NOTHING_FOUND, Contacts, Piece
from .cylinders import GroundCylinders
from .ground import GroundHulls
from .margin import WIDENING, MarginSchedule
from .narrow import NarrowPhase
from .pairs import Pair
from .primitives import PrimitivePairs

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
closing = Bound("collision.closing")
in_pair_order = Bound("collision.in_pair_order")
joined = Bound("collision.joined")
point_keys = Bound("pairs.point_keys")

# A fast step leaves out the points it cannot close only when they are at least this fraction of
# those found: fewer rows do not repay what a new set of rows costs the solver's warm start (bin_pile,
# 4 of 74 points left out: 90 us a step more, not less).
LEAVE_OUT = 0.5


class Routine(Protocol):
    """A routine family: built once from the pairs it answers (``index`` into the declared pairs)."""

    def detect(self, data: pin.Data, margin: float, turns: np.ndarray) -> tuple[list[Piece], float]:
        """The contacts of its pairs within ``margin`` [m] at the placements held in ``data``, and a
        lower bound on every one of its pairs' gaps [m]. ``turns``: per declared pair, the most its
        geometry may turn within the step [rad] (:class:`~.margin.MarginSchedule`): a polyhedron on
        the ground whose turn times its size exceeds PATCH_TOLERANCE takes its patch that deep, the
        points the turn can bring down (coal's patches, and the compiled pairs that reproduce them,
        keep PATCH_TOLERANCE)."""
        ...


# The routine of each (robot geometry, obstacle) shape type, looked up along the geometry shape's
# class hierarchy; every other pair goes through coal's narrow phase.
ROUTINES: dict[tuple[type, type], Callable[[list[Pair], list[int]], Routine]] = {
    (coal.Box, coal.Halfspace): GroundHulls,
    (coal.ConvexBase, coal.Halfspace): GroundHulls,
    (coal.Sphere, coal.Halfspace): GroundHulls,
    (coal.Capsule, coal.Halfspace): GroundHulls,
    (coal.Cylinder, coal.Halfspace): GroundCylinders,
    (coal.Box, coal.Box): BoxPairs,
    (coal.Sphere, coal.Sphere): PrimitivePairs,
    (coal.Sphere, coal.Capsule): PrimitivePairs,
    (coal.Capsule, coal.Sphere): PrimitivePairs,
    (coal.Sphere, coal.Box): PrimitivePairs,
    (coal.Box, coal.Sphere): PrimitivePairs,
    (coal.Capsule, coal.Capsule): PrimitivePairs,
    (coal.Capsule, coal.Box): PrimitivePairs,
    (coal.Box, coal.Capsule): PrimitivePairs,
}


def routine_of(pair: Pair) -> Callable[[list[Pair], list[int]], Routine]:
    """The routine that answers ``pair``: the first of ROUTINES for its shape types, else coal's."""
    for kind in type(pair.shape).__mro__:
        routine = ROUTINES.get((kind, type(pair.obstacle_shape)))
        if routine is not None:
            return routine
    return NarrowPhase


class ContactDetector:
    """Finds the contact points of the scene's declared pairs that are closer than the margin.

    A polyhedron, a sphere or a capsule on a ground plane goes to :class:`~.ground.GroundHulls`, a
    cylinder on a ground plane to :class:`~.cylinders.GroundCylinders`, a box on a box to
    :class:`~.boxes.BoxPairs`, a sphere, capsule or box on a sphere, capsule or box to
    :class:`~.primitives.PrimitivePairs` (each one compiled pass for all its pairs), every other pair
    to :class:`~.narrow.NarrowPhase` (coal). The
    :class:`~.margin.MarginSchedule` widens the margin to what a step can travel and says when a step
    need not look (:meth:`cover`); :meth:`detect` itself always looks.

    Args:
        scene: the scene whose ``pairs`` are detected.
        margin: the base margin [m] (``Options.contact_margin``).
    """

    def __init__(self, scene: Scene, margin: float) -> None:
        self.pairs = [Pair(scene, p) for p in scene.pairs]
        groups: dict[Callable[[list[Pair], list[int]], Routine], list[int]] = {}
        for k, pair in enumerate(self.pairs):
            groups.setdefault(routine_of(pair), []).append(k)
        self.schedule = MarginSchedule(scene.robot.model, self.pairs, margin, groups.get(GroundHulls, []))
        self.supports = Supports.of(scene.robot.model)
        order = [*dict.fromkeys(ROUTINES.values()), NarrowPhase]
        self.routines = [routine(self.pairs, groups[routine]) for routine in order if routine in groups]
        self.friction = np.array([pair.friction for pair in self.pairs], dtype=float)  # a user's may be ints
        self.restitution = np.array([pair.restitution for pair in self.pairs], dtype=float)
        self.joint = np.array([pair.joint for pair in self.pairs], dtype=int)
        self.other_joint = np.array([pair.other_joint for pair in self.pairs], dtype=int)
        # each pair's names as object arrays: a layout takes them for all its points in one indexing
        self._geometry = np.array([pair.geometry for pair in self.pairs], dtype=object)
        self._obstacle = np.array([pair.obstacle_name for pair in self.pairs], dtype=object)
        self._layouts: dict[bytes, tuple] = {}  # what does not move, per set of touching pairs

    def forget(self) -> None:
        """Detect afresh at the next step (see :meth:`.MarginSchedule.forget`)."""
        self.schedule.forget()

    def cover(
        self, v: np.ndarray, x: np.ndarray, dt: float, x_scale: float, reach: float | None = None
    ) -> bool:
        """Whether a pair may be within the margin after this step (see :meth:`.MarginSchedule.cover`)."""
        return self.schedule.cover(v, x, dt, x_scale, reach)

    @property
    def fast(self) -> bool:
        """Whether the step may close a pair by more than the base margin (as of the last :meth:`cover`):
        the margin then covers the fastest pair, and :meth:`reachable` narrows it down to each point's
        own motion."""
        return self.schedule.distance > self.schedule.base_margin

    def beyond_rest(self, found: Piece) -> bool:
        """Whether some of the points ``found`` (:meth:`find`) is farther than a point at rest keeps
        (WIDENING times the base margin): only then can :meth:`reachable` leave points out."""
        gaps = found[3]
        return len(gaps) > 0 and gaps.max() > WIDENING * self.schedule.base_margin

    def reachable(
        self, found: Piece, data: pin.Data, v: np.ndarray, x: np.ndarray, dt: float, x_scale: float
    ) -> tuple[Piece, Piece]:
        """The points ``found`` (:meth:`find`) that the step can close, and the others (none unless they
        are at least the fraction LEAVE_OUT of the points): a gap within
        WIDENING times the base margin plus how far the point itself can close at velocity v and at
        the free motion x (:func:`~gaussim.kernels.collision.closing`, which counts the friction
        pyramid's rows too). The margin covers the fastest pair, so the points of slower ones, and of
        bodies moving apart, would only add rows; the step's answer v+ can still reach one (a push
        elsewhere on its body), which :meth:`kept_apart` checks. Reads the joint Jacobians in data.J
        (the step's Gauss problem posed)."""
        far = self._closing(found, data, v, x, dt, x_scale)
        keep = found[3] <= WIDENING * (self.schedule.base_margin + far)
        if np.count_nonzero(keep) > (1.0 - LEAVE_OUT) * len(keep):
            return found, NOTHING_FOUND
        apart = ~keep
        return tuple(a[keep] for a in found), tuple(a[apart] for a in found)  # type: ignore[return-value]

    def kept_apart(self, left_out: Piece, data: pin.Data, v_next: np.ndarray, dt: float) -> bool:
        """Whether the points ``left_out`` by :meth:`reachable` stay apart at the step's answer v+: each
        of their rows holds at v+, so the Gauss problem with them has the same answer."""
        far = self._closing(left_out, data, v_next, v_next, dt, 0.0)  # x_scale 0: v+ alone
        return bool(np.all(far < left_out[3]))

    def _closing(
        self, found: Piece, data: pin.Data, v: np.ndarray, x: np.ndarray, dt: float, x_scale: float
    ) -> np.ndarray:
        """:func:`~gaussim.kernels.collision.closing` of the points ``found``."""
        owner, points, normals, _ = found
        far = np.empty(len(owner))
        joints, others, mu = self.joint[owner], self.other_joint[owner], self.friction[owner]
        closing.call(
            joint_jacobians(data), *self.supports, joints, others, points, normals, mu, v, x, dt, x_scale, far
        )
        return far

    def detect(self, data: pin.Data) -> Contacts:
        """Contacts at the placements held in ``data`` (after forward kinematics), in the order of the
        declared pairs: :meth:`contacts` of :meth:`find`."""
        return self.contacts(self.find(data))

    def find(self, data: pin.Data) -> Piece:
        """The points of every pair within the margin at the placements held in ``data``, in the order
        of the declared pairs; the least gap of all, a lower bound for the pairs coal answers, becomes
        the schedule's clearance."""
        pieces: list[Piece] = []
        least = []
        for routine in self.routines:
            found, bound = routine.detect(data, self.schedule.margin, self.schedule.turns)
            pieces += found
            least.append(bound)
        self.schedule.clearance = min(least, default=np.inf)
        if not pieces:
            return NOTHING_FOUND
        if len(pieces) == 1:
            return pieces[0]
        if len(pieces) == 2:  # two routines' pieces, as a pile's ground and box pairs
            return joined.call(*pieces[0], *pieces[1])  # type: ignore[no-any-return]
        owner, points, normals, gaps = (np.concatenate([p[i] for p in pieces]) for i in range(4))
        in_pair_order.call(owner, points, normals, gaps)
        return owner, points, normals, gaps

    def contacts(self, found: Piece) -> Contacts:
        """The :class:`Contacts` of the points ``found`` (:meth:`find`)."""
        owner, points, normals, gaps = found
        if not len(owner):
            return NO_CONTACTS
        key = owner.tobytes()
        if key not in self._layouts:
            if len(self._layouts) > 1024:  # many pairs touching in ever new combinations
                self._layouts.clear()
            self._layouts[key] = self._layout(owner)
        names, geometry, obstacle, joint, other_joint, friction, restitution, ids = self._layouts[key]
        return Contacts(
            names, geometry, obstacle, joint, other_joint, points, normals, gaps, friction, restitution, ids
        )

    def _layout(self, owner: np.ndarray) -> tuple:
        """What the contacts of pairs ``owner`` (one entry per point, sorted) have that does not move."""
        keys = np.empty(len(owner), np.int64)
        starts, counts = point_keys.call(owner, MAX_POINTS, keys)
        arrays = [
            self.joint[owner],
            self.other_joint[owner],
            self.friction[owner],
            self.restitution[owner],
            keys,
        ]
        for array in arrays:
            array.flags.writeable = False  # shared by every step with these pairs touching
        names = [
            name
            for k, n in zip(owner[starts].tolist(), counts.tolist())
            for name in self.pairs[k].contact_names(n)
        ]
        return (names, self._geometry[owner].tolist(), self._obstacle[owner].tolist(), *arrays)
