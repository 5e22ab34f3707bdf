"""Cylinders on the ground, compiled (:mod:`gaussim.kernels.cylinders`: coal's support point and
sampled support set): coal's answer without its calls; a test within DECISION of its threshold goes to
coal."""

from __future__ import annotations

import numpy as np

from ..kernels.bound import Bound
from ..kernels.cylinders import CAP_SAMPLES
from .compiled import CompiledPairs
from .pairs import Pair

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
ground_cylinders = Bound("cylinders.ground_cylinders")


class GroundCylinders(CompiledPairs):
    """All the declared pairs of a cylinder with a ground plane: one compiled pass
    (:func:`~gaussim.kernels.cylinders.ground_cylinders`) over those within the margin.

    Args:
        pairs: the declared pairs of the scene.
        index: which of them this routine answers.
    """

    max_points = CAP_SAMPLES

    def __init__(self, pairs: list[Pair], index: list[int]) -> None:
        super().__init__(pairs, index)
        self.dims = np.array([[p.shape.radius, p.shape.halfLength] for p in self.pairs]).reshape(-1, 2)  # type: ignore[attr-defined]
        self.plane = np.array(
            [[*p.obstacle.normal, p.obstacle.height] for p in self.pairs]  # type: ignore[union-attr]
        ).reshape(-1, 4)

    def _kernel(self, placements, near, margin, answer, gaps, normals, points, sizes):  # type: ignore[no-untyped-def]
        ground_cylinders.call(
            placements,
            self.spheres.side,
            self.local_rotation,
            self.local_translation,
            self.dims,
            self.plane,
            near,
            margin,
            answer,
            gaps,
            normals,
            points,
            sizes,
        )
