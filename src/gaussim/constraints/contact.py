"""Unilateral contacts with Coulomb friction (FORMULATION.md sections 2, 5).

Each contact point with normal n, point Jacobian J (3, nv) and friction mu contributes the rows

    (n + mu d_i)^T J x >= b - s,   i = 1..k

where d_i are k unit tangent directions: the multipliers lambda_i >= 0 give the force
sum_i lambda_i (n + mu d_i), which lies in the friction pyramid inscribed in the Coulomb cone.
(The rows say that the contact velocity lies in the dual of that pyramid: Anitescu's relaxation.)
b is the stabilised normal bound (with restitution), s the De Saxce shift mu |u_t+| that removes
the relaxation's lift-off while sliding. The shift needs the slip u_t+ of the solution: it starts
from the current slip and, while a contact slides, the QP is solved again with the slip of the last
solution until it moves less than SLIP_TOLERANCE[mode] (a lagged slip lets a decelerating contact
sink by mu (|u_t| - |u_t+|) dt per step; each pass divides that error by about 1 + 1/mu^2).
d_1 is turned against the tangential velocity the contact would have without friction, so a
sliding or pulled contact sees the full cone, not a facet of the pyramid ("pyramid" mode keeps a
fixed basis and no shift). With mu = 0 a contact is the single row n^T J x >= b.

At the acceleration level a sliding contact (|u_t| > SLIP_SPEED) cannot be posed as a QP row set
(its force is on the cone's edge opposite the slip, which couples to the normal force): it keeps
the normal row and receives the friction force -mu lambda_n u_t/|u_t| outside the QP, with lambda_n
iterated to a fixed point (``Options.friction_iterations``); a contact whose slip that force would
reverse within the step sticks instead.

All contacts of a step are handled at once, as arrays; ``Context.lagged`` holds the fixed-point
values ("slip", "normal", "stops") aligned with the contacts that produced rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..collision import Contacts
from ..dynamics import point_drifts, point_jacobians, point_placements, support_masks
from .base import Context, Rows, is_active, stabilised_bound

# Below this tangential speed a contact sticks at the acceleration level [m/s].
SLIP_SPEED = 1e-4
# Fixed-point iterations on the slip stop when it moves less than this [m/s].
SLIP_TOLERANCE = {"accurate": 1e-4, "exact": 1e-9}
# Acceleration-level sliding friction iterations stop when the normal force moves less than this [N].
NORMAL_FORCE_TOLERANCE = 1e-8


@dataclass
class ContactForce:
    """The reaction at one contact point, world frame.

    Attributes:
        name: contact name ``geometry/obstacle#k``.
        geometry: robot collision geometry.
        obstacle: obstacle name.
        point: application point on the robot, shape (3,) [m].
        normal: unit normal from the obstacle to the robot, shape (3,).
        gap: signed distance, negative when penetrating [m].
        force: force on the robot, shape (3,) [N] (an impulse [N s] in impact reports).
    """

    name: str
    geometry: str
    obstacle: str
    point: np.ndarray
    normal: np.ndarray
    gap: float
    force: np.ndarray

    @property
    def normal_force(self) -> float:
        """Component along the normal [N]."""
        return float(self.force @ self.normal)

    @property
    def tangential_force(self) -> np.ndarray:
        """Friction force, shape (3,) [N]."""
        return self.force - self.normal_force * self.normal


@dataclass
class _Batch:
    """The contacts that produced rows, and what turns multipliers back into forces.

    Rows are grouped by contact: contact i owns rows starts[i] to starts[i + 1].

    Attributes:
        contacts: m contacts.
        J: point Jacobians, shape (m, 3, nv).
        generators: force direction of each row, shape (R, 3): row r reads generators[r] @ J[i] x >= bound[r].
        starts: first row of each contact, shape (m,).
        friction: friction force applied outside the QP, shape (m, 3) (acceleration-level sliding).
        sliding: which contacts get that force, shape (m,).
        slipping: which contacts iterate the De Saxce shift, shape (m,).
        slip: the slip the De Saxce shift used, shape (m, 3) [m/s], and its norm slip_speed (m,).
    """

    contacts: Contacts
    J: np.ndarray
    generators: np.ndarray
    starts: np.ndarray
    friction: np.ndarray
    sliding: np.ndarray
    slipping: np.ndarray
    slip: np.ndarray
    slip_speed: np.ndarray

    def forces(self, lam: np.ndarray) -> np.ndarray:
        """Sum each contact's rows' multipliers times their generators, shape (m, 3)."""
        return np.add.reduceat(lam[:, None] * self.generators, self.starts, axis=0)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of (m, 3) arrays, shape (m,)."""
    return np.einsum("mi,mi->m", a, b)


def _tangential(u: np.ndarray, n: np.ndarray) -> np.ndarray:
    return u - _dot(u, n)[:, None] * n


# Per-contact 3-vector algebra runs on Python floats: for the handful of contacts of a robot this
# is several times faster than numpy calls on (m, 3) arrays (measured in benchmarks/step_cost.py).
def _dot3(a, b) -> float:  # type: ignore[no-untyped-def]
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross3(a, b) -> tuple[float, float, float]:  # type: ignore[no-untyped-def]
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _tangent_basis(n, direction) -> tuple[tuple[float, float, float], tuple[float, float, float]]:  # type: ignore[no-untyped-def]
    """Unit tangents (t1, t2) at normal n; t1 along ``direction`` projected on the tangent plane
    when it has a component there, else along n x (the axis of n's smallest component)."""
    norm = 0.0
    if direction is not None:
        d_n = _dot3(direction, n)
        t = (direction[0] - d_n * n[0], direction[1] - d_n * n[1], direction[2] - d_n * n[2])
        norm = _dot3(t, t) ** 0.5
    if norm <= 1e-12:
        k = min(range(3), key=lambda i: abs(n[i]))
        t = _cross3(n, [float(i == k) for i in range(3)])
        norm = _dot3(t, t) ** 0.5
    t1 = (t[0] / norm, t[1] / norm, t[2] / norm)
    return t1, _cross3(n, t1)


class ContactModule:
    """Rows of the ground and obstacle contacts detected this step."""

    name = "contact"

    def __init__(self, model: pin.Model, facets: int, mode: str) -> None:
        self.mode = mode
        self.facets = facets
        angles = 2.0 * np.pi * np.arange(facets) / facets
        self.cos, self.sin = np.cos(angles)[None, :, None], np.sin(angles)[None, :, None]
        self.masks = support_masks(model)
        self._layouts: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def rows(self, ctx: Context) -> Rows | None:
        contacts = ctx.contacts
        if not len(contacts):
            return None
        acceleration = ctx.level == "acceleration"
        lagged, options = ctx.lagged, ctx.options
        J = point_jacobians(ctx.data, self.masks, contacts.joint, contacts.other_joint, contacts.point)
        # contact velocities J v, and J x_free: where the contacts would go without friction
        motion = J @ np.stack((ctx.v, ctx.x_free), axis=1)
        if ctx.level != "velocity":
            keep = is_active(ctx, contacts.gap, _dot(motion[:, :, 0], contacts.normal), 0.0)
            if not keep.any():
                return None
            if not keep.all():
                contacts, J, motion = contacts.select(keep), J[keep], motion[keep]
        m = len(contacts)
        drift = _drifts(ctx, contacts) if acceleration else np.zeros((m, 3))
        U = motion[:, :, 0]
        slips: list = lagged["slip"].tolist() if "slip" in lagged else [None] * m
        stops = lagged["stops"].tolist() if "stops" in lagged else [False] * m
        normal_forces = lagged["normal"].tolist() if "normal" in lagged else [0.0] * m
        pyramid = self.mode == "pyramid"

        counts, cone, tangents, bounds = [], [], [], []  # type: ignore[var-annotated]
        frictions, sliding, slip_used, speeds = [], [], [], []  # type: ignore[var-annotated]
        for i, (n, gap, mu, e, u, tendency) in enumerate(
            zip(
                contacts.normal.tolist(),
                contacts.gap.tolist(),
                contacts.friction.tolist(),
                contacts.restitution.tolist(),
                U.tolist(),
                (motion[:, :, 1] + drift).tolist(),
            )
        ):
            u_n = _dot3(u, n)
            u_t = [u[0] - u_n * n[0], u[1] - u_n * n[1], u[2] - u_n * n[2]]
            slip: list[float] = u_t if acceleration or slips[i] is None else slips[i]
            speed = _dot3(slip, slip) ** 0.5
            slides = acceleration and mu > 0 and speed > SLIP_SPEED and not stops[i]
            friction = [0.0, 0.0, 0.0]
            if slides:  # explicit Coulomb force opposite the slip, lambda_n iterated (module docstring)
                f = -mu * normal_forces[i] / speed
                friction = [f * slip[0], f * slip[1], f * slip[2]]
            if mu == 0 or slides:  # the normal row alone
                counts.append(1)
                cone.append(0.0)
                tangents.append(((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))
            else:  # friction opposes the tangential velocity the contact would have without it
                counts.append(self.facets)
                cone.append(mu)
                tangents.append(_tangent_basis(n, None if pyramid else [-x for x in tendency]))
            if not acceleration:
                # restitution: an approaching contact leaves at -e u_n at least; De Saxce shift mu |slip|
                floor = -e * u_n if e > 0 and -u_n > options.restitution_threshold else -np.inf
                bounds.append((gap, floor, 0.0 if pyramid else mu * speed))
            frictions.append(friction)
            sliding.append(slides)
            slip_used.append(slip)
            speeds.append(speed)

        # generators n + mu (cos a_k t1 + sin a_k t2) of every contact's pyramid, (m, k, 3)
        t = np.array(tangents)
        generators = contacts.normal[:, None, :] + np.array(cone)[:, None, None] * (
            self.cos * t[:, None, 0, :] + self.sin * t[:, None, 1, :]
        )
        if sum(counts) == m * self.facets:  # every contact has a full pyramid
            G = generators.reshape(-1, 3)
            rows = np.matmul(generators, J).reshape(len(G), -1)
            owner, starts = self._layout(m)
        else:
            chosen = np.arange(self.facets) < np.array(counts)[:, None]
            G, owner = generators[chosen], np.nonzero(chosen)[0]
            rows = np.einsum("ri,rin->rn", G, J[owner])
            starts = np.searchsorted(owner, np.arange(m))
        if acceleration:
            bound = stabilised_bound(ctx, contacts.gap[owner], _dot(G, U[owner]), _dot(G, drift[owner]), True)
        else:
            gap_, floor_, shift_ = np.array(bounds).T
            bound = (np.maximum(stabilised_bound(ctx, gap_, gap_, 0.0, True), floor_) - shift_)[owner]
        friction_ = np.array(frictions)
        batch = _Batch(
            contacts,
            J,
            G,
            starts,
            friction_,
            np.array(sliding),
            (np.array(counts) > 1) & (not acceleration and not pyramid),
            np.array(slip_used),
            np.array(speeds),
        )

        def labels() -> list[str]:
            return [f"contact {contacts.names[i]} row {r - starts[i]}" for r, i in enumerate(owner.tolist())]

        force = np.einsum("min,mi->n", J, friction_) if any(sliding) else None
        return Rows(rows, bound, False, labels, batch, force)

    def _layout(self, m: int) -> tuple[np.ndarray, np.ndarray]:
        """Owner contact of each row and first row of each contact when m contacts have full pyramids."""
        if m not in self._layouts:
            k = self.facets
            self._layouts[m] = np.repeat(np.arange(m), k), np.arange(0, m * k, k)
        return self._layouts[m]

    def reactions(self, rows: Rows, multipliers: np.ndarray, scale: float) -> list[ContactForce]:
        b: _Batch = rows.data  # type: ignore[assignment]
        c = b.contacts
        forces = scale * b.forces(multipliers) + b.friction
        return [
            ContactForce(
                c.names[i], c.geometry[i], c.obstacle[i], c.point[i], c.normal[i], float(c.gap[i]), forces[i]
            )
            for i in range(len(c))
        ]

    def refine(self, ctx: Context, rows: Rows, x: np.ndarray, multipliers: np.ndarray) -> bool:
        b: _Batch = rows.data  # type: ignore[assignment]
        lagged, normals, m = ctx.lagged, b.contacts.normal, len(b.contacts)
        changed = False
        if b.sliding.any():
            u_next = _tangential(b.J @ (ctx.v + ctx.options.dt * x), normals)
            reverse = b.sliding & (_dot(u_next, b.friction) > 0)  # such a contact sticks instead
            if reverse.any():
                lagged["stops"] = lagged.get("stops", np.zeros(m, bool)) | reverse
                changed = True
            slides = b.sliding & ~reverse
            lam, previous = multipliers[b.starts], lagged.get("normal", np.zeros(m))
            changed |= bool((np.abs(lam - previous) > NORMAL_FORCE_TOLERANCE)[slides].any())
            lagged["normal"] = np.where(slides, lam, previous)
        if b.slipping.any():
            new = _tangential(b.J @ x, normals)
            speed = np.sqrt(_dot(new, new))
            # a sticking contact has no shift to refine
            moving = b.slipping & ((b.slip_speed > SLIP_SPEED) | (speed > SLIP_SPEED))
            if moving.any():
                changed |= bool((np.abs(new - b.slip).max(axis=1) > SLIP_TOLERANCE[self.mode])[moving].any())
                lagged["slip"] = np.where(moving[:, None], new, b.slip)
        return changed


def _drifts(ctx: Context, contacts: Contacts) -> np.ndarray:
    """Jdot v of the contact points, shape (m, 3), relative to the other body's point when the
    obstacle is another robot geometry."""
    model, data = ctx.model, ctx.data
    joints = contacts.joint.tolist()
    result = point_drifts(model, data, joints, point_placements(data, joints, contacts.point))
    others = np.flatnonzero(contacts.other_joint)
    if len(others):
        other_joints = contacts.other_joint[others].tolist()
        points = contacts.point[others]
        result[others] -= point_drifts(
            model, data, other_joints, point_placements(data, other_joints, points)
        )
    return result
