"""The contact record the detection fills, and what a contact patch is."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kernels.pairs import PATCH_MIN_EXTENT, PATCH_TOLERANCE

__all__ = [
    "MAX_POINTS",
    "PATCH_MIN_EXTENT",
    "PATCH_TOLERANCE",
    "Contacts",
    "NO_CONTACTS",
    "Piece",
    "one_pair",
]


@dataclass
class Contacts:
    """The m contact points of one step, as arrays (one entry per point).

    Attributes:
        names: ``"geometry/obstacle#k"``, stable while a patch keeps its size.
        geometry, obstacle: robot collision geometry and obstacle of each point.
        joint: Pinocchio joint carrying the robot geometry, shape (m,).
        other_joint: joint carrying the obstacle when it is a robot geometry, else 0 (the world), (m,).
        point: points on the robot surface, world frame, shape (m, 3) [m].
        normal: unit normals from the obstacle towards the robot, shape (m, 3).
        gap: signed distances along the normal, negative when penetrating, shape (m,) [m].
        friction, restitution: coefficients of the obstacle, shape (m,).
        key: each point's identity, its declared pair and its rank among that pair's points
            (pair * MAX_POINTS + rank, stable while a patch keeps its size, as the names are), (m,);
            None: not known.
    """

    names: list[str]
    geometry: list[str]
    obstacle: list[str]
    joint: np.ndarray
    other_joint: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    gap: np.ndarray
    friction: np.ndarray
    restitution: np.ndarray
    key: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.names)

    def select(self, keep: np.ndarray) -> Contacts:
        """The contacts where the boolean mask ``keep`` (m,) is true."""
        chosen = np.flatnonzero(keep).tolist()
        return Contacts(
            [self.names[i] for i in chosen],
            [self.geometry[i] for i in chosen],
            [self.obstacle[i] for i in chosen],
            self.joint[keep],
            self.other_joint[keep],
            self.point[keep],
            self.normal[keep],
            self.gap[keep],
            self.friction[keep],
            self.restitution[keep],
            None if self.key is None else self.key[keep],
        )


NO_CONTACTS = Contacts(
    [],
    [],
    [],
    np.zeros(0, int),
    np.zeros(0, int),
    *(np.zeros((0, 3)),) * 2,
    *(np.zeros(0),) * 3,
    np.zeros(0, np.int64),
)

# The most points one pair's patch is named apart (Contacts.key).
MAX_POINTS = 4096


# Contact points a routine found, k of them, before the driver gathers them into Contacts: the
# declared pair of each (its index in Scene.pairs) (k,), the points on the robot surface, world frame
# (k, 3) [m], the unit normals from the obstacle towards the robot (k, 3), the gaps (k,) [m]. A plain
# tuple: a step builds one per touching pair.
Piece = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
NOTHING_FOUND: Piece = (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))


def one_pair(pair: int, normal: np.ndarray, point: np.ndarray, gap: np.ndarray) -> Piece:
    """The :data:`Piece` of one pair's points (k, 3) and gaps (k,), all with the same normal (3,)."""
    count = len(point)
    return np.full(count, pair), point, np.repeat(normal[None, :], count, axis=0), gap
