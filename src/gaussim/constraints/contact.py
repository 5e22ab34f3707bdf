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
from numba import njit

from ..collision import Contacts
from ..dynamics import point_drifts, point_jacobians, point_jacobians_from, point_placements, support_masks
from ..linalg import dot
from .base import LEVELS, Context, Rows, bound_of, is_active

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
        sliding: which contacts get that force, shape (m,), or None when none does.
        slipping: which contacts iterate the De Saxce shift, shape (m,), or None when none does.
        slip: the slip the De Saxce shift used, shape (m, 3) [m/s], and its norm slip_speed (m,).
    """

    contacts: Contacts
    J: np.ndarray
    generators: np.ndarray
    starts: np.ndarray
    friction: np.ndarray
    sliding: np.ndarray | None
    slipping: np.ndarray | None
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


@njit(cache=True)
def _pyramids(  # type: ignore[no-untyped-def]
    joint_jacobians,
    masks,
    joints,
    other_joints,
    points,
    v,
    x_free,
    drift,
    normal,
    gap,
    mu,
    e,
    slips,
    stops,
    normal_forces,
    level,
    cos,
    sin,
    pyramid,
    shifts,
    bounds,
):
    """Every contact's rows, as the module docstring poses them; the per-contact work in one pass.

    Args:
        joint_jacobians, masks, joints, other_joints, points: what :func:`point_jacobians` reads.
        v: the velocity (nv,); x_free: the unconstrained solution (nv,);
        drift: Jdot v of the contacts at the acceleration level, else zeros, (m, 3).
        slips: the lagged slip of each contact (m, 3), NaN where there is none (use the current one).
        stops, normal_forces: acceleration-level sliding: contacts that stick instead, lagged lambda_n.
        level: 0 velocity, 1 impulse, 2 acceleration; pyramid: fixed basis and no De Saxce shift.
        shifts: contacts with a full pyramid refine their De Saxce shift.
        bounds: (dt, stabilisation, restitution_threshold).

    Returns:
        the point Jacobians (m, 3, nv), rows (R, nv), bound (R,), generators (R, 3), owner contact of
        each row (R,), first row of each contact (m,), the contacts that get an explicit friction
        force (sliding) and that refine their shift (slipping), each (m,) or None when there is none,
        that friction force (m, 3) and its generalized force (nv,), the slip used (m, 3) and its norm
        (m,).
    """
    dt, stabilisation, threshold = bounds
    J = point_jacobians_from(joint_jacobians, masks, joints, other_joints, points)
    m, nv = J.shape[0], J.shape[2]
    acceleration = level == 2
    counts = np.empty(m, np.int64)
    friction, slip_used = np.zeros((m, 3)), np.empty((m, 3))
    speeds, sliding = np.empty(m), np.zeros(m, np.bool_)
    contact_bound = np.zeros(m)
    # contact velocities, and where the contacts would go without friction
    U, tendency = np.empty((m, 3)), np.empty((m, 3))
    for i in range(m):
        for j in range(3):
            U[i, j] = dot(J[i, j], v)
            tendency[i, j] = dot(J[i, j], x_free) + drift[i, j]
    for i in range(m):
        n = normal[i]
        u_n = U[i, 0] * n[0] + U[i, 1] * n[1] + U[i, 2] * n[2]
        slip = U[i] - u_n * n if acceleration or np.isnan(slips[i, 0]) else slips[i]
        speed = np.sqrt(slip[0] ** 2 + slip[1] ** 2 + slip[2] ** 2)
        slides = acceleration and mu[i] > 0 and speed > SLIP_SPEED and not stops[i]
        if slides:  # explicit Coulomb force opposite the slip, lambda_n iterated (module docstring)
            friction[i] = -mu[i] * normal_forces[i] / speed * slip
        counts[i] = 1 if mu[i] == 0 or slides else len(cos)
        sliding[i], slip_used[i], speeds[i] = slides, slip, speed
        contact_bound[i] = bound_of(level, dt, stabilisation, gap[i], 0.0, 0.0, True)
        if not acceleration:
            # restitution: an approaching contact leaves at -e u_n at least; De Saxce shift mu |slip|
            if e[i] > 0 and -u_n > threshold:
                contact_bound[i] = max(contact_bound[i], -e[i] * u_n)
            if not pyramid:
                contact_bound[i] -= mu[i] * speed
    starts = np.zeros(m, np.int64)
    starts[1:] = np.cumsum(counts)[:-1]
    total = counts.sum()
    generators, owner = np.empty((total, 3)), np.empty(total, np.int64)
    for i in range(m):
        n, r = normal[i], starts[i]
        if counts[i] == 1:  # the normal row alone
            generators[r] = n
        else:  # friction opposes the tangential velocity the contact would have without it
            t = -tendency[i] + (tendency[i, 0] * n[0] + tendency[i, 1] * n[1] + tendency[i, 2] * n[2]) * n
            norm = np.sqrt(t[0] ** 2 + t[1] ** 2 + t[2] ** 2)
            if pyramid or norm <= 1e-12:  # a fixed basis: n x (the axis of n's smallest component)
                axis = np.zeros(3)
                axis[np.argmin(np.abs(n))] = 1.0
                t = np.cross(n, axis)
                norm = np.sqrt(t[0] ** 2 + t[1] ** 2 + t[2] ** 2)
            t1 = t / norm
            t2 = np.cross(n, t1)
            for k in range(counts[i]):
                generators[r + k] = n + mu[i] * (cos[k] * t1 + sin[k] * t2)
        owner[r : r + counts[i]] = i
    rows, bound = np.zeros((total, nv)), contact_bound[owner]
    for r in range(total):
        i = owner[r]
        g, Ji = generators[r], J[i]
        for k in range(nv):
            rows[r, k] = g[0] * Ji[0, k] + g[1] * Ji[1, k] + g[2] * Ji[2, k]
        if acceleration:  # the row's own rate and drift
            rate, row_drift = g @ U[i], g @ drift[i]
            bound[r] = bound_of(level, dt, stabilisation, gap[i], rate, row_drift, True)
    force = np.zeros(nv)
    for i in range(m):
        if sliding[i]:
            force += friction[i, 0] * J[i, 0] + friction[i, 1] * J[i, 1] + friction[i, 2] * J[i, 2]
    slipping = (counts > 1) & shifts
    return (
        J,
        rows,
        bound,
        generators,
        owner,
        starts,
        sliding if sliding.any() else None,
        slipping if slipping.any() else None,
        friction,
        force,
        slip_used,
        speeds,
    )


class ContactModule:
    """Rows of the ground and obstacle contacts detected this step."""

    name = "contact"

    def __init__(self, model: pin.Model, facets: int, mode: str) -> None:
        self.mode = mode
        self.facets = facets
        angles = 2.0 * np.pi * np.arange(facets) / facets
        self.cos, self.sin = np.cos(angles), np.sin(angles)
        self.masks = support_masks(model)
        self._blanks: dict[int, tuple[np.ndarray, ...]] = {}

    def rows(self, ctx: Context) -> Rows | None:
        contacts = ctx.contacts
        if not len(contacts):
            return None
        level, lagged, options = ctx.level, ctx.lagged, ctx.options
        if level != "velocity":
            J = point_jacobians(ctx.data, self.masks, contacts.joint, contacts.other_joint, contacts.point)
            keep = is_active(ctx, contacts.gap, _dot(J @ ctx.v, contacts.normal), 0.0)
            if not keep.any():
                return None
            if not keep.all():
                contacts = contacts.select(keep)
        m = len(contacts)
        no_slip, no_stops, no_force, no_drift = self._blank(m)
        drift = _drifts(ctx, contacts) if level == "acceleration" else no_drift
        # contacts with a full pyramid refine their De Saxce shift at the velocity and impulse levels
        shifts = level != "acceleration" and self.mode != "pyramid"
        J, rows, bound, G, owner, starts, sliding, slipping, friction, force, slip, speed = _pyramids(
            ctx.data.J,
            self.masks,
            contacts.joint,
            contacts.other_joint,
            contacts.point,
            ctx.v,
            ctx.x_free,
            drift,
            contacts.normal,
            contacts.gap,
            contacts.friction,
            contacts.restitution,
            lagged.get("slip", no_slip),
            lagged.get("stops", no_stops),
            lagged.get("normal", no_force),
            LEVELS[level],
            self.cos,
            self.sin,
            self.mode == "pyramid",
            shifts,
            (options.dt, options.stabilisation, options.restitution_threshold),
        )
        batch = _Batch(contacts, J, G, starts, friction, sliding, slipping, slip, speed)

        def labels() -> list[str]:
            return [f"contact {contacts.names[i]} row {r - starts[i]}" for r, i in enumerate(owner.tolist())]

        return Rows(rows, bound, False, labels, batch, force if batch.sliding is not None else None)

    def _blank(self, m: int) -> tuple[np.ndarray, ...]:
        """Read-only defaults for m contacts: no lagged slip (NaN: each uses its current one), no
        stops, no lagged normal force, no drift."""
        if m not in self._blanks:
            self._blanks[m] = (np.full((m, 3), np.nan), np.zeros(m, bool), np.zeros(m), np.zeros((m, 3)))
            for array in self._blanks[m]:
                array.flags.writeable = False
        return self._blanks[m]

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
        if b.sliding is not None:
            u_next = _tangential(b.J @ (ctx.v + ctx.options.dt * x), normals)
            reverse = b.sliding & (_dot(u_next, b.friction) > 0)  # such a contact sticks instead
            if reverse.any():
                lagged["stops"] = lagged.get("stops", np.zeros(m, bool)) | reverse
                changed = True
            slides = b.sliding & ~reverse
            lam, previous = multipliers[b.starts], lagged.get("normal", np.zeros(m))
            changed |= bool((np.abs(lam - previous) > NORMAL_FORCE_TOLERANCE)[slides].any())
            lagged["normal"] = np.where(slides, lam, previous)
        if b.slipping is not None:
            moved, slip = _slips(b.J, x, normals, b.slip, b.slip_speed, b.slipping, SLIP_TOLERANCE[self.mode])
            changed |= moved
            lagged["slip"] = slip
        return changed


@njit(cache=True)
def _slips(J, x, normal, slip, speed, slipping, tolerance):  # type: ignore[no-untyped-def]
    """The slips of solution x for the contacts that refine their shift and are moving (a sticking
    contact has no shift to refine), the others' unchanged: (True when one moved more than
    ``tolerance``, slips (m, 3))."""
    result, moved = slip.copy(), False
    for i in range(len(slip)):
        if not slipping[i]:
            continue
        u = np.array([J[i, 0] @ x, J[i, 1] @ x, J[i, 2] @ x])
        u -= (u[0] * normal[i, 0] + u[1] * normal[i, 1] + u[2] * normal[i, 2]) * normal[i]
        if speed[i] > SLIP_SPEED or np.sqrt(u[0] ** 2 + u[1] ** 2 + u[2] ** 2) > SLIP_SPEED:
            moved |= np.abs(u - slip[i]).max() > tolerance
            result[i] = u
    return moved, result


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
