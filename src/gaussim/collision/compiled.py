"""What the compiled routine families share: the bounding-sphere broad phase, each side's placement
in the frame of its joint, one kernel call over the pairs within the margin, and coal's narrow phase
for the pairs the kernel hands back."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..kernels.bound import Bound
from .contacts import Piece, one_pair
from .narrow import BoundingSpheres, NarrowPhase
from .pairs import Pair

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
gathered = Bound("pairs.gathered")
nearby = Bound("pairs.nearby")


class CompiledPairs:
    """A family of declared pairs answered by one compiled kernel (:meth:`_kernel`, in a subclass).

    Only the pairs whose bounding spheres are within the margin reach the kernel; it answers each with
    FAR (and a lower bound on its gap), FOUND (a normal, a gap and up to ``max_points`` points on the
    robot's geometry, all at that gap) or ASK_COAL, and those go to :class:`~.narrow.NarrowPhase`.

    Args:
        pairs: the declared pairs of the scene.
        index: which of them this family answers.
    """

    max_points = 1

    def __init__(self, pairs: list[Pair], index: list[int]) -> None:
        self.index = index
        self.owner = np.array(index, dtype=np.int64)
        self.pairs = [pairs[k] for k in index]
        self.spheres = BoundingSpheres(self.pairs)
        self.coal = NarrowPhase(pairs, index, supports=False)  # its collide alone
        # each side's shape in the frame of its joint (a fixed obstacle's joint is the world's, 0)
        self.local_rotation = np.array(
            [[p.local.rotation, _other_placement(p).rotation] for p in self.pairs]
        ).reshape(-1, 2, 3, 3)
        self.local_translation = np.array(
            [[p.local.translation, _other_placement(p).translation] for p in self.pairs]
        ).reshape(-1, 2, 3)
        count = len(index)  # what the kernel fills, for the pairs it is handed: at most all of them
        self._buffers = (
            np.empty(count, np.int64),
            np.empty(count),
            np.empty((count, 3)),
            np.empty((count, self.max_points, 3)),
            np.empty(count, np.int64),
        )

    def detect(self, data: pin.Data, margin: float, turns: np.ndarray) -> tuple[list[Piece], float]:
        """The contacts of the pairs within ``margin`` [m] at the placements held in ``data``, and a
        lower bound on every pair's gap [m] (``turns`` unused: these patches keep PATCH_TOLERANCE)."""
        near, clearance = nearby.call(self.spheres.gaps(data, margin), margin)
        if not len(near):
            return [], clearance
        answer, gaps, normals, points, sizes = self._buffers
        self._kernel(self.spheres.placements(data), near, margin, answer, gaps, normals, points, sizes)
        # one piece for all the points found: a piece per pair costs more than the kernel
        found, asked, clearance = gathered.call(
            self.owner, near, answer, gaps, normals, points, sizes, clearance
        )
        pieces: list[Piece] = [found] if len(found[0]) else []
        self.coal.use_margin(margin)
        for i in asked.tolist():
            hit, least = self.coal.collide(self.pairs[i], data)
            clearance = min(clearance, least)
            if hit is not None:
                pieces.append(one_pair(self.index[i], *hit))
        return pieces, clearance

    def _kernel(
        self,
        placements: np.ndarray,
        near: np.ndarray,
        margin: float,
        answer: np.ndarray,
        gaps: np.ndarray,
        normals: np.ndarray,
        points: np.ndarray,
        sizes: np.ndarray,
    ) -> None:
        """Fills, for each pair ``near[k]`` (an index into :attr:`pairs`), ``answer[k]``, ``gaps[k]``,
        ``normals[k]`` (from the other side towards the robot's) and the ``sizes[k]`` points
        ``points[k]``, at the joint placements ``placements`` (see :mod:`gaussim.kernels.pairs`)."""
        raise NotImplementedError


def _other_placement(pair: Pair) -> pin.SE3:
    """Where the pair's other side sits in the frame of its joint (a fixed obstacle: in the world)."""
    if pair.other_local is not None:
        return pair.other_local
    return pair.obstacle.placement()  # type: ignore[union-attr]
