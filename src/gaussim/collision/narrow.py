"""coal's narrow phase and contact patch, for the pairs no specialised routine answers."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin

from ..exceptions import ContactError
from ..kernels.bound import Bound
from ..linalg import finite
from .contacts import PATCH_MIN_EXTENT, PATCH_TOLERANCE, Piece, one_pair
from .pairs import JointPlacements, Pair, vertices

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
nearby = Bound("pairs.nearby")
sphere_gaps = Bound("pairs.sphere_gaps")
support_gaps = Bound("pairs.support_gaps")


class NarrowPhase:
    """coal's narrow phase (the deepest point, the normal and the gap) and its contact patch (the
    points within PATCH_TOLERANCE of the support plane), pair by pair: a patch narrower than
    PATCH_MIN_EXTENT is one point, a wider one contributes its points. Only the pairs whose bounding
    spheres are within the margin reach coal (:class:`BoundingSpheres`, all pairs at once).

    Args:
        pairs: the declared pairs of the scene.
        index: which of them this routine answers.
        supports: whether its broad phase bounds pairs with a box by their vertices (see
            :class:`BoundingSpheres`; not for a compiled family's pairs, which it only collides).
    """

    def __init__(self, pairs: list[Pair], index: list[int], supports: bool = True) -> None:
        self.index = index
        self.pairs = [pairs[k] for k in index]
        self.request = _request(coal.GJKVariant.DefaultGJK)
        # coal 3.0's default GJK/EPA returns a NaN normal and a depth of -DBL_MAX for two boxes face
        # to face within ~1e-11 rad (measured: a box resting on a box); the Nesterov-accelerated
        # GJK answers those, and is the retry of any non-finite answer
        self.retry_request = _request(coal.GJKVariant.NesterovAcceleration)
        self.patch_request = coal.ContactPatchRequest()
        self.patch_request.setPatchTolerance(PATCH_TOLERANCE)
        self.result = coal.CollisionResult()
        self.patch_result = coal.ContactPatchResult(self.patch_request)
        self.spheres = BoundingSpheres(self.pairs, supports)

    def detect(self, data: pin.Data, margin: float, turns: np.ndarray) -> tuple[list[Piece], float]:
        """The contacts of the pairs within ``margin`` [m] at the placements held in ``data``, and a
        lower bound on every pair's gap [m] (``turns`` unused: these patches keep PATCH_TOLERANCE)."""
        self.use_margin(margin)
        near, clearance = nearby.call(self.spheres.gaps(data, margin), margin)
        pieces: list[Piece] = []
        for i in near.tolist():
            hit, least = self.collide(self.pairs[i], data)
            clearance = min(clearance, least)
            if hit is not None:
                pieces.append(one_pair(self.index[i], *hit))
        return pieces, clearance

    def use_margin(self, margin: float) -> None:
        """Make :meth:`collide` find the contacts within ``margin`` [m]."""
        if self.request.security_margin != margin:
            self.request.security_margin = self.retry_request.security_margin = margin

    def collide(
        self, pair: Pair, data: pin.Data
    ) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray] | None, float]:
        """coal's narrow phase and contact patch for one pair: (normal, points (k, 3), gaps (k,)), or
        None when the pair is farther apart than the margin; and a lower bound on its gap [m]."""
        placement = data.oMi[pair.joint] * pair.local
        if pair.other_local is not None:
            pair.obstacle_tf = coal.Transform3s(data.oMi[pair.other_joint] * pair.other_local)
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

    def _patch(self, pair: Pair, placement: pin.SE3, normal: np.ndarray, gap: float) -> np.ndarray | None:
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


def _request(variant: coal.GJKVariant) -> coal.CollisionRequest:
    """A request for one contact with GJK ``variant`` (its security margin is set per detection)."""
    request = coal.CollisionRequest()
    request.num_max_contacts = 1
    request.gjk_variant = variant
    return request


class BoundingSpheres:
    """The broad phase: the gaps of the P pairs' bounding spheres, lower bounds on their own, all at
    once (a pile of objects has a pair for every two of them, most of them far apart); a pair whose
    spheres are within the margin gets the gap of the robot geometry's sphere to the obstacle's
    bounding box instead where that is larger (a table's or a wall's sphere holds much of the scene),
    and with ``supports``, that of the geometry's vertices to that box where larger still (a robot's
    link, whose sphere is loose, above a table).

    Args:
        pairs: the P pairs; a ground's sphere is infinite (its pairs always reach coal, whose
            half-space test is as cheap).
        supports: whether to bound by the geometries' vertices (for the pairs that go to coal).
    """

    def __init__(self, pairs: list[Pair], supports: bool = False) -> None:
        # the joints of each pair's two sides, whose placements are read
        self.side = np.array([[p.joint, p.other_joint] for p in pairs], dtype=np.int64).reshape(-1, 2)
        self.placements = JointPlacements(int(self.side.max(initial=0)) + 1)
        self.centers = np.array([[p.center, p.obstacle_center] for p in pairs]).reshape(-1, 2, 3)
        self.radius = np.array([p.radius for p in pairs])
        self.obstacle_radius = np.array([p.obstacle_radius for p in pairs])
        self.boxes = np.array([p.obstacle_box for p in pairs]).reshape(-1, 4, 3)
        self.vertices = _supports(pairs) if supports else None

    def gaps(self, data: pin.Data, margin: float) -> np.ndarray:
        """The pairs' gaps at the joint placements held in ``data``, shape (P,) [m] (-inf against a
        ground): the spheres', or within ``margin`` [m] the larger of that and the sphere's to the
        obstacle's box (and its vertices' to that box, with ``supports``)."""
        gaps = np.empty(len(self.radius))
        if len(gaps):
            placements, spheres = self.placements(data), (self.side, self.centers, self.radius)
            sphere_gaps.call(placements, *spheres, self.obstacle_radius, self.boxes, margin, gaps)
            if self.vertices is not None:
                box = (self.centers, self.boxes, self.obstacle_radius)
                support_gaps.call(placements, self.side, *self.vertices, *box, margin, gaps)
        return gaps


def _supports(pairs: list[Pair]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(the vertices of every pair's robot geometry in the frame of its joint, stacked (N, 3); where
    each pair's start, (P + 1,); how far each geometry reaches beyond their hull [m], (P,)): a box's
    corners, a convex hull's vertices, a capsule's segment or a sphere's centre (with its radius);
    none for another shape, or against a ground."""
    chunks, rounding = [], np.zeros(len(pairs))
    for k, pair in enumerate(pairs):
        shape = pair.shape
        if not np.isfinite(pair.obstacle_radius):  # a ground: coal's half-space test
            points = np.zeros((0, 3))
        elif isinstance(shape, coal.Box | coal.ConvexBase):
            points = vertices(shape)[0]
        elif isinstance(shape, coal.Capsule | coal.Sphere):
            points, rounding[k] = vertices(shape)[0], shape.radius
        else:
            points = np.zeros((0, 3))
        chunks.append(points @ pair.local.rotation.T + pair.local.translation)
    start = np.concatenate([[0], np.cumsum([len(c) for c in chunks])]).astype(np.int64)
    stacked = np.vstack(chunks) if chunks else np.zeros((0, 3))
    return np.ascontiguousarray(stacked, dtype=float), start, rounding
