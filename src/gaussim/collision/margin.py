"""Margin scheduling: how far the pairs can close in a step, and when a step need not look."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..dynamics import sparse_rows
from ..kernels.bound import Bound
from .pairs import Pair

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
travel = Bound("collision.travel")

# The margin is this many times what the step needs: it changes by factors of this or more.
WIDENING = 1.5


class MarginSchedule:
    """The detection margin and a lower bound on every pair's gap (the clearance).

    Between steps the pairs can only close by what :meth:`cover` bounds, so after a detection that
    finds every pair farther than the margin, by more than they may have closed since, the step need
    not look: :meth:`cover` says so, and a robot in flight pays for one detection per many steps
    (see :meth:`forget` for a state from elsewhere).

    Args:
        model: the world's Pinocchio model.
        pairs: the declared pairs.
        margin: the base margin [m] (``Options.contact_margin``).
        turning: the pairs whose routine reads their turn (:class:`~.ground.GroundHulls`').

    Attributes:
        base_margin, margin: the base margin and the margin the next detection uses [m].
        levers: per pair and velocity coordinate, how fast (at most) the pair's two geometries
            approach per unit of |v_k| [m/s per unit], as a CSR matrix (pairs, nv): (row starts,
            coordinates, levers); a pair moves with the coordinates of its two joints' chains only, so
            a pile's pairs cost in proportion to their number, not to it times nv.
        longest: the longest lever (see :meth:`cover`'s reach).
        turn_levers: per pair and velocity coordinate, how fast (at most) the pair's robot geometry
            turns per unit of |v_k| [rad/s per unit], in the same CSR form (its joint chain's angular
            parts; for two robot geometries, their sum: how fast they turn relative to each other).
        turns: per pair, the most it may turn within the step [rad], as of the last :meth:`cover`
            that looked (0 before, and for the pairs no routine reads it of).
        clearance: the least gap of the last detection less what the pairs may have closed since
            [m] (-inf: unknown, so the next detection runs).
        distance: the farthest the pairs may close within the step, as of the last :meth:`cover`
            that looked [m].
    """

    def __init__(self, model: pin.Model, pairs: list[Pair], margin: float, turning: list[int]) -> None:
        self.base_margin = self.margin = margin
        self.levers = sparse_rows([_pair_levers(model, p) for p in pairs])
        self.longest = float(self.levers[2].max(initial=0.0))
        read = set(turning)
        self.turn_levers = sparse_rows(
            [_turn_levers(model, p) if k in read else np.zeros(model.nv) for k, p in enumerate(pairs)]
        )
        # travel's per-pair closing, which only its maximum is read from
        self.turns, self._closing = np.zeros(len(pairs)), np.zeros(len(pairs))
        self.distance = 0.0
        self.clearance = -np.inf

    def forget(self) -> None:
        """Detect afresh at the next step: the configuration did not come from the last one's motion."""
        self.clearance = -np.inf

    def cover(
        self, v: np.ndarray, x: np.ndarray, dt: float, x_scale: float, reach: float | None = None
    ) -> bool:
        """Widen the margin to what the pairs can close in one step, at velocity v and free velocity
        x (``x_scale`` 1) or free acceleration x (``x_scale`` dt): a contact is then found the step
        before it closes, at any speed. The margin changes by factors of 1.5 or more, so coal's
        requests are rarely rewritten.

        The bound also covers the motion that led to this step's configuration (its velocity is v), so
        it is taken off the clearance. Returns whether a pair may now be within the margin (False
        while the clearance exceeds it: no detection is needed; NaN: True).

        ``reach``, sum_i |v_i| + |x_i| when known (velocity level), gives a coarser bound at no cost,
        dt reach times the longest lever: while the clearance exceeds twice it plus the base margin,
        that bound alone is taken off and the step need not look (a robot in flight: 0.4 us a step
        less)."""
        if reach is not None:
            coarse = dt * self.longest * reach
            if self.clearance - 2 * coarse > self.base_margin:
                self.clearance -= coarse
                return False
        distance = travel.call(*self.levers, *self.turn_levers, v, x, dt, x_scale, self._closing, self.turns)
        self.clearance -= distance
        self.distance = distance
        needed = self.base_margin + distance
        if needed > self.margin or (self.margin > self.base_margin and 3 * needed < self.margin):
            self.margin = max(self.base_margin, WIDENING * needed)
        return not self.clearance > self.margin


def _turn_levers(model: pin.Model, pair: Pair) -> np.ndarray:
    """How fast (at most) the pair's robot geometry turns, relative to the other side, per unit |v_k|,
    shape (nv,): the angular part of each coordinate of its joint's chain (and of the other's)."""
    levers = _angular_levers(model, pair.joint)
    if pair.other_local is None:
        return levers
    return levers + _angular_levers(model, pair.other_joint)


def _angular_levers(model: pin.Model, joint: int) -> np.ndarray:
    """|angular part| of each velocity coordinate of ``joint`` and its ancestors, shape (nv,)."""
    levers = np.zeros(model.nv)
    for j, S in _chain(model, joint):
        jmodel = model.joints[j]
        levers[jmodel.idx_v : jmodel.idx_v + jmodel.nv] = np.linalg.norm(S[3:], axis=0)
    return levers


def _chain(model: pin.Model, joint: int) -> list[tuple[int, np.ndarray]]:
    """``joint`` and its ancestors, each with its motion subspace S (6, nv_j) at the neutral
    configuration."""
    chain, neutral = [], pin.neutral(model)
    while joint > 0:
        jmodel = model.joints[joint]
        jdata = jmodel.createData()
        jmodel.calc(jdata, neutral)
        chain.append((joint, np.asarray(jdata.S).reshape(6, -1)))
        joint = model.parents[joint]
    return chain


def _pair_levers(model: pin.Model, pair: Pair) -> np.ndarray:
    """How fast (at most) the pair's two bounding spheres approach per unit |v_k|, shape (nv,)."""
    levers = _speed_levers(model, pair.joint, pair.center, pair.radius)
    if pair.other_local is None:
        return levers
    return levers + _speed_levers(model, pair.other_joint, pair.obstacle_center, pair.obstacle_radius)


def _speed_levers(model: pin.Model, joint: int, center: np.ndarray, radius: float) -> np.ndarray:
    """For a body's sphere (``center`` in the frame of ``joint``, ``radius``), bounds on the speed of
    its points per unit |v_k|, shape (nv,): |linear| + |angular| reach for each velocity coordinate k
    of the joint and its ancestors, with reach the farthest the sphere can be from that joint's
    origin (the joint placements along the chain, a prismatic joint's limits, |center| + radius)."""
    levers = np.zeros(model.nv)
    reach = float(np.linalg.norm(center)) + radius
    for link, S in _chain(model, joint):
        jmodel = model.joints[link]
        for i in range(jmodel.nv):
            levers[jmodel.idx_v + i] = np.linalg.norm(S[:3, i]) + np.linalg.norm(S[3:, i]) * reach
        if not np.linalg.norm(S[3:]):  # prismatic: how far it carries the body
            limits = np.concatenate(
                [
                    model.lowerPositionLimit[jmodel.idx_q : jmodel.idx_q + jmodel.nq],
                    model.upperPositionLimit[jmodel.idx_q : jmodel.idx_q + jmodel.nq],
                ]
            )
            reach += float(np.abs(limits[np.isfinite(limits)]).max(initial=0.0))
        reach += float(np.linalg.norm(model.jointPlacements[link].translation))
    return levers
