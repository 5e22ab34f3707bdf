"""Spheres, capsules and boxes against each other (but box on box, :mod:`.boxes`), compiled
(:mod:`gaussim.kernels.primitives`: coal's closed forms and contact patches): coal's answer without its
calls; what round-off could decide either way goes to coal."""

from __future__ import annotations

import coal
import numpy as np

from ..kernels.bound import Bound
from ..kernels.primitives import BOX, CAPSULE, MAX_POINTS, SPHERE
from .compiled import CompiledPairs
from .pairs import Pair

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
primitive_pairs = Bound("primitives.primitive_pairs")


class PrimitivePairs(CompiledPairs):
    """All the declared pairs of a sphere, capsule or box with a sphere, capsule or box (a fixed
    obstacle or another robot geometry), but box with box: one compiled pass
    (:func:`~gaussim.kernels.primitives.primitive_pairs`) over those whose bounding spheres are within the
    margin.

    Args:
        pairs: the declared pairs of the scene.
        index: which of them this routine answers.
    """

    max_points = MAX_POINTS

    def __init__(self, pairs: list[Pair], index: list[int]) -> None:
        super().__init__(pairs, index)
        described = [[_describe(p.shape), _describe(p.obstacle_shape)] for p in self.pairs]
        self.kind = np.array([[k for k, _ in sides] for sides in described], dtype=np.int64).reshape(-1, 2)
        self.dims = np.array([[d for _, d in sides] for sides in described]).reshape(-1, 2, 3)

    def _kernel(self, placements, near, margin, answer, gaps, normals, points, sizes):  # type: ignore[no-untyped-def]
        primitive_pairs.call(
            placements,
            self.spheres.side,
            self.local_rotation,
            self.local_translation,
            self.kind,
            self.dims,
            near,
            margin,
            answer,
            gaps,
            normals,
            points,
            sizes,
        )


def _describe(shape: coal.CollisionGeometry) -> tuple[int, list[float]]:
    """A shape's kind and sizes: a sphere's (radius), a capsule's (radius, half length), a box's half
    sides [m]."""
    if isinstance(shape, coal.Sphere):
        return SPHERE, [shape.radius, 0.0, 0.0]
    if isinstance(shape, coal.Capsule):
        return CAPSULE, [shape.radius, shape.halfLength, 0.0]
    return BOX, [float(h) for h in shape.halfSide]
