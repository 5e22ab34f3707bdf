"""Box against box, compiled (:mod:`gaussim.kernels.boxes`: the separating-axis test and the clipped
face-on-face patch): coal's answer without its calls; what the kernel cannot answer exactly goes to coal."""

from __future__ import annotations

import numpy as np

from ..kernels.bound import Bound
from ..kernels.boxes import MAX_POINTS
from .compiled import CompiledPairs
from .contacts import PATCH_TOLERANCE
from .pairs import Pair

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
box_pairs = Bound("boxes.box_pairs")


class BoxPairs(CompiledPairs):
    """All the declared pairs of a box with a box (a fixed one or another robot geometry).

    Only the pairs whose bounding spheres are within the margin reach the compiled test
    (:func:`~gaussim.kernels.boxes.box_pairs`); those it cannot answer exactly, and boxes with a side
    of PATCH_TOLERANCE or less, go to :class:`~.narrow.NarrowPhase`.

    Args:
        pairs: the declared pairs of the scene.
        index: which of them this routine answers, each a box against a box.
    """

    max_points = MAX_POINTS

    def __init__(self, pairs: list[Pair], index: list[int]) -> None:
        super().__init__(pairs, index)
        self.half = np.array(
            [[np.asarray(p.shape.halfSide), np.asarray(p.obstacle_shape.halfSide)] for p in self.pairs]
        ).reshape(-1, 2, 3)
        self.thin = np.array([2 * h.min() <= PATCH_TOLERANCE for h in self.half], dtype=bool).reshape(-1)

    def _kernel(self, placements, near, margin, answer, gaps, normals, points, sizes):  # type: ignore[no-untyped-def]
        box_pairs.call(
            placements,
            self.spheres.side,
            self.local_rotation,
            self.local_translation,
            self.half,
            self.thin,
            near,
            margin,
            answer,
            gaps,
            normals,
            points,
            sizes,
        )
