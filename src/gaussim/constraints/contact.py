"""Unilateral contacts with Coulomb friction (docs/FORMULATION.md sections 2, 4, 5).

Each contact point with normal n, point Jacobian J (3, nv) and friction mu contributes the rows

    (n + mu d_i)^T J x >= b - s,   i = 1..k

where d_i are k unit tangent directions: the multipliers lambda_i >= 0 give the force
sum_i lambda_i (n + mu d_i), which lies in the friction pyramid inscribed in the Coulomb cone.
(The rows say that the contact velocity lies in the dual of that pyramid: Anitescu's relaxation.)
b is the stabilised normal bound (with restitution), s the De Saxce shift mu |u_t+| that removes
the relaxation's lift-off while sliding. The shift needs the slip u_t+ of the solution: it starts
from the current slip and, while a contact slides, the QP is solved again with the slip of the last
solution until max(1, mu) times its change is below SLIP_TOLERANCE[mode] (a lagged slip lets a
decelerating contact sink at mu (|u_t| - |u_t+|), an accelerating one lift off at as much; each pass
divides that error by about 1 + 1/mu^2). When the passes of ``Options.friction_iterations`` do not
come within RELAX_TOLERANCE of that fixed point (measured: mu = 1000, where a block sank through the
ground under a tiny normal force whose friction relaxed the shifted bound), the last QP drops the shift: the
plain relaxation, which may lift a sliding contact at mu |u_t+| but never lets it sink; the step's
report says so (``StepReport.friction_relaxed``).
d_1 is turned against the tangential velocity the contact would have without friction, so a
sliding or pulled contact sees the full cone, not a facet of the pyramid ("pyramid" mode keeps a
fixed basis and no shift). With mu = 0 a contact is the single row n^T J x >= b.

At the acceleration level a sliding contact (|u_t| > SLIP_SPEED) cannot be posed as a QP row set
(its force is on the cone's edge opposite the slip, which couples to the normal force): it keeps
the normal row and receives the friction force -mu lambda_n u_t/|u_t| outside the QP, with lambda_n
iterated to a fixed point with Anderson mixing (:func:`_anderson`) in at most
``Options.friction_iterations`` QPs (a step that spends them unsettled says so:
``StepReport.friction_unsettled``); a contact whose slip that force would reverse within the step
sticks instead. A sticking contact's rows stop its slip within the step (a Baumgarte rate on it
would let a stopping block creep, its slip shrinking by 1 - 2 stabilisation a step).

All contacts of a step are handled at once, as arrays; the module's :class:`FrictionIterate` in
``Context.lagged`` carries the fixed-point values between the QPs of one solve.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import coal
import numpy as np
import pinocchio as pin
from numba import njit

from ..collision import Contacts
from ..dynamics import (
    joint_jacobians,
    point_drifts,
    point_jacobians,
    point_jacobians_into,
    point_placements,
    support_masks,
)
from ..linalg import cross, dot
from .base import LEVELS, ConstraintModule, Context, Rows, bound_of, is_active

# Below this tangential speed a contact sticks: no sliding force at the acceleration level, no De
# Saxce shift (a lagged slip that small is the step's own error, which mu would amplify) [m/s].
SLIP_SPEED = 1e-4
# Fixed-point iterations on the slip stop when max(1, mu) times its change is below this [m/s].
SLIP_TOLERANCE = {"accurate": 1e-4, "exact": 1e-9}
# Still above this after the step's passes, the iteration is far from its fixed point: the last QP
# drops the De Saxce shift [m/s] (below it, the last shifted solution is kept).
RELAX_TOLERANCE = 1e-3
# Acceleration-level sliding friction iterations stop when the normal force moves less than this [N].
NORMAL_FORCE_TOLERANCE = 1e-8
# Passes the Anderson mixing of those iterations combines.
ANDERSON_MEMORY = 5


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
class FrictionIterate:
    """What the friction's fixed-point iteration carries between the QPs of one solve, aligned with
    the contacts that produced rows (the module docstring poses the iteration).

    Attributes:
        slip: the slip the De Saxce shift uses, shape (m, 3) [m/s], or None: each contact's current one.
        normal: acceleration-level sliding: the lagged normal force of each contact, shape (m,) [N],
            or None: no friction force yet.
        stops: acceleration-level sliding: the contacts that stick instead, shape (m,), or None: none.
        history: the Anderson mixing's (inputs, outputs) of the last passes (:func:`_anderson`), or None.
        passes: the De Saxce passes made.
        relaxed: True once the passes have not come within RELAX_TOLERANCE of the fixed point: the
            next QP drops the shift.
    """

    slip: np.ndarray | None = None
    normal: np.ndarray | None = None
    stops: np.ndarray | None = None
    history: tuple[list, list] | None = None
    passes: int = 0
    relaxed: bool = False


# The iterate of a solve's first QP (read, never written: refine makes each solve its own).
_FIRST_PASS = FrictionIterate()


class ContactBatch:
    """The contact module's record of its rows: the contacts that produced them, and what turns
    multipliers back into forces.

    Rows are grouped by contact: contact i owns rows starts[i] to starts[i + 1]. The per-step arrays
    come from :func:`_pyramids` packed in one buffer (returning each would cost more than computing
    it); :func:`_unpacked` gives views of them, read here only when asked for.

    Attributes:
        contacts: m contacts.
        packed: the point Jacobians J (m, 3, nv), the force direction of each row (R, 3) (row r reads
            generators[r] @ J[i] x >= bound[r]), the slip the De Saxce shift used (m, 3) [m/s] and the
            friction force applied outside the QP (m, 3) (acceleration-level sliding), in one buffer.
        starts: first row of each contact, then the number of rows, shape (m + 1,).
        sliding: which contacts get that friction force, shape (m,), or None when none does.
        shifts: True when the contacts with a full pyramid refine their De Saxce shift.
        relaxed: True when these rows dropped the shift: its fixed point was not reached.
    """

    def __init__(
        self,
        contacts: Contacts,
        packed: np.ndarray,
        starts: np.ndarray,
        sliding: np.ndarray | None,
        shifts: bool,
        relaxed: bool,
    ) -> None:
        self.contacts, self.packed, self.starts = contacts, packed, starts
        self.sliding, self.shifts, self.relaxed = sliding, shifts, relaxed

    @cached_property
    def _views(self) -> tuple[np.ndarray, ...]:
        m = len(self.contacts)
        nv = (len(self.packed) - 3 * int(self.starts[-1]) - 6 * m) // (3 * m)
        return _unpacked(self.packed, m, nv)

    @property
    def J(self) -> np.ndarray:
        """Point Jacobians, shape (m, 3, nv)."""
        return self._views[0]

    @property
    def generators(self) -> np.ndarray:
        """Force direction of each row, shape (R, 3)."""
        return self._views[1]

    @property
    def friction(self) -> np.ndarray:
        """Friction force applied outside the QP, shape (m, 3) [N]."""
        return self._views[3]

    def forces(self, lam: np.ndarray) -> np.ndarray:
        """Sum each contact's rows' multipliers times their generators, shape (m, 3)."""
        return np.add.reduceat(lam[:, None] * self.generators, self.starts[:-1], axis=0)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of (m, 3) arrays, shape (m,)."""
    return np.einsum("mi,mi->m", a, b)


def _tangential(u: np.ndarray, n: np.ndarray) -> np.ndarray:
    return u - _dot(u, n)[:, None] * n


@njit(cache=True)
def _unpacked(packed, m, nv):  # type: ignore[no-untyped-def]
    """Views of the buffer :func:`_pyramids` fills: J (m, 3, nv), generators (R, 3), slip (m, 3),
    friction (m, 3)."""
    rows = (len(packed) - 3 * m * nv - 6 * m) // 3
    a = 3 * m * nv  # where each part ends
    b = a + 3 * rows
    c = b + 3 * m
    return (
        packed[:a].reshape((m, 3, nv)),
        packed[a:b].reshape((rows, 3)),
        packed[b:c].reshape((m, 3)),
        packed[c : c + 3 * m].reshape((m, 3)),
    )


def pyramid_rows(
    joint_jacobians: np.ndarray,
    masks: np.ndarray,
    contacts: Contacts,
    ctx: Context,
    drift: np.ndarray,
    iterate: tuple[np.ndarray, np.ndarray, np.ndarray],
    cone: tuple[np.ndarray, np.ndarray, bool],
) -> tuple[np.ndarray, ...]:
    """Every contact's rows at ``ctx``'s level (:func:`_pyramids`, compiled): (rows (R, nv), bound (R,),
    the packed buffer :class:`ContactBatch` reads, starts (m + 1,), sliding contacts or None, their
    friction's generalized force or None).

    Args:
        joint_jacobians, masks: what :func:`point_jacobians` reads.
        drift: Jdot v of the contacts at the acceleration level, else zeros, (m, 3).
        iterate: the lagged (slip (m, 3), stops (m,), normal forces (m,)) of the friction iteration.
        cone: (cos, sin) of the pyramid's facet directions, and whether the basis is fixed (the plain
            pyramid, no De Saxce shift).
    """
    m, nv, options = len(contacts), len(ctx.v), ctx.options
    most = m * len(cone[0])  # at most m facets rows
    rows, bound = np.empty((most, nv)), np.empty(most)
    packed, starts = np.empty(3 * m * nv + 3 * most + 6 * m), np.empty(m + 1, np.int64)
    # read-only views whoever made them: one compiled signature (numba types writability)
    drift, iterate = _read_only(drift), tuple(_read_only(a) for a in iterate)  # type: ignore[assignment]
    total, sliding, force = _pyramids(
        joint_jacobians,
        masks,
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
        *iterate,
        LEVELS[ctx.level],
        *cone,
        (options.dt, options.stabilisation, options.restitution_threshold),
        rows,
        bound,
        packed,
        starts,
    )
    if total < most:  # frictionless or sliding contacts: fewer rows
        rows, bound, packed = rows[:total], bound[:total], packed[: 3 * m * nv + 3 * total + 6 * m]
    return rows, bound, packed, starts, sliding, force


def _read_only(array: np.ndarray) -> np.ndarray:
    """``array`` itself when read-only, else a read-only view of it."""
    if not array.flags.writeable:
        return array
    view = array.view()
    view.flags.writeable = False
    return view


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
    bounds,
    rows,
    bound,
    packed,
    starts,
):
    """Every contact's rows, as the module docstring poses them; the per-contact work in one pass.

    Args:
        joint_jacobians, masks, joints, other_joints, points: what :func:`point_jacobians` reads.
        v: the velocity (nv,); x_free: the unconstrained solution (nv,);
        drift: Jdot v of the contacts at the acceleration level, else zeros, (m, 3).
        slips: the lagged slip of each contact (m, 3), NaN where there is none (use the current one).
        stops, normal_forces: acceleration-level sliding: contacts that stick instead, lagged lambda_n.
        level: 0 velocity, 1 impulse, 2 acceleration; pyramid: fixed basis and no De Saxce shift.
        bounds: (dt, stabilisation, restitution_threshold).

    Fills the first R rows of ``rows`` (m facets, nv) and ``bound`` (m facets,), the first entries of
    ``packed`` (the buffer :func:`_unpacked` reads: point Jacobians, generators, slip used, friction
    force; room for m facets rows) and ``starts`` (m + 1,) (the first row of each contact, then R);
    the caller allocates them, which costs less than a kernel's new arrays.

    Returns:
        R, and, when a contact gets an explicit friction force (acceleration-level sliding), which ones
        (m,) and that force's generalized force (nv,), else None and None.
    """
    dt, stabilisation, threshold = bounds
    m, nv, facets = len(joints), len(v), len(cos)
    acceleration = level == 2
    J = packed[: 3 * m * nv].reshape((m, 3, nv))  # the buffer's first part, whatever R is
    point_jacobians_into(J, joint_jacobians, masks, joints, other_joints, points)
    starts[0], sliding, any_sliding = 0, np.zeros(m, np.bool_), False
    contact_bound, slip_used, u, free = np.empty(m), np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3))
    for i in range(m):
        n0, n1, n2 = normal[i, 0], normal[i, 1], normal[i, 2]
        u0, u1, u2 = dot(J[i, 0], v), dot(J[i, 1], v), dot(J[i, 2], v)
        u[i, 0], u[i, 1], u[i, 2] = u0, u1, u2
        free[i, 0], free[i, 1], free[i, 2] = dot(J[i, 0], x_free), dot(J[i, 1], x_free), dot(J[i, 2], x_free)
        u_n = u0 * n0 + u1 * n1 + u2 * n2
        if acceleration or np.isnan(slips[i, 0]):  # the current slip
            slip_used[i, 0], slip_used[i, 1], slip_used[i, 2] = u0 - u_n * n0, u1 - u_n * n1, u2 - u_n * n2
        else:
            slip_used[i, 0], slip_used[i, 1], slip_used[i, 2] = slips[i, 0], slips[i, 1], slips[i, 2]
        speed = np.sqrt(slip_used[i, 0] ** 2 + slip_used[i, 1] ** 2 + slip_used[i, 2] ** 2)
        sliding[i] = acceleration and mu[i] > 0 and speed > SLIP_SPEED and not stops[i]
        any_sliding |= sliding[i]
        starts[i + 1] = starts[i] + (1 if mu[i] == 0 or sliding[i] else facets)
        contact_bound[i] = bound_of(level, dt, stabilisation, gap[i], 0.0, 0.0, True)
        if not acceleration:
            # restitution: an approaching contact that closes within the step leaves at -e u_n at least
            # (velocity level: under the free motion, as the margin finds contacts earlier; impulse level:
            # every contact here, is_active's closing test chose them); De Saxce shift mu |slip|
            closes = level == 1 or gap[i] + dt * (n0 * free[i, 0] + n1 * free[i, 1] + n2 * free[i, 2]) <= 0.0
            if e[i] > 0 and -u_n > threshold and closes:
                contact_bound[i] = max(contact_bound[i], -e[i] * u_n)
            if not pyramid and speed > SLIP_SPEED:  # slower, it sticks: no shift to make
                contact_bound[i] -= mu[i] * speed
    total = starts[m]
    J, generators, slip, friction = _unpacked(packed[: 3 * m * nv + 3 * total + 6 * m], m, nv)
    for i in range(m):
        for j in range(3):
            slip[i, j], friction[i, j] = slip_used[i, j], 0.0
    force = np.zeros(nv)
    for i in range(m):
        n0, n1, n2 = normal[i, 0], normal[i, 1], normal[i, 2]
        r, count = starts[i], starts[i + 1] - starts[i]
        if sliding[i]:  # explicit Coulomb force opposite the slip, lambda_n iterated (module docstring)
            speed = np.sqrt(slip[i, 0] ** 2 + slip[i, 1] ** 2 + slip[i, 2] ** 2)
            for j in range(3):
                friction[i, j] = -mu[i] * normal_forces[i] / speed * slip[i, j]
                for k in range(nv):
                    force[k] += friction[i, j] * J[i, j, k]
        if count == 1:  # the normal row alone
            generators[r, 0], generators[r, 1], generators[r, 2] = n0, n1, n2
        else:  # friction opposes the tangential velocity the contact would have without it
            # (acceleration level: the acceleration that keeps it, plus the one that stops it in the step)
            d0, d1, d2 = free[i, 0] + drift[i, 0], free[i, 1] + drift[i, 1], free[i, 2] + drift[i, 2]
            if acceleration:
                d0, d1, d2 = d0 + u[i, 0] / dt, d1 + u[i, 1] / dt, d2 + u[i, 2] / dt
            along = d0 * n0 + d1 * n1 + d2 * n2
            t0, t1, t2 = -d0 + along * n0, -d1 + along * n1, -d2 + along * n2
            norm = np.sqrt(t0**2 + t1**2 + t2**2)
            if pyramid or norm <= 1e-12:  # a fixed basis: n x (the axis of n's smallest component)
                a0, a1, a2 = abs(n0), abs(n1), abs(n2)
                if a0 <= a1 and a0 <= a2:
                    t0, t1, t2 = cross(n0, n1, n2, 1.0, 0.0, 0.0)
                elif a1 <= a2:
                    t0, t1, t2 = cross(n0, n1, n2, 0.0, 1.0, 0.0)
                else:
                    t0, t1, t2 = cross(n0, n1, n2, 0.0, 0.0, 1.0)
                norm = np.sqrt(t0**2 + t1**2 + t2**2)
            t0, t1, t2 = t0 / norm, t1 / norm, t2 / norm
            s0, s1, s2 = cross(n0, n1, n2, t0, t1, t2)
            for k in range(count):
                generators[r + k, 0] = n0 + mu[i] * (cos[k] * t0 + sin[k] * s0)
                generators[r + k, 1] = n1 + mu[i] * (cos[k] * t1 + sin[k] * s1)
                generators[r + k, 2] = n2 + mu[i] * (cos[k] * t2 + sin[k] * s2)
        for k in range(count):
            g = generators[r + k]
            for c in range(nv):
                rows[r + k, c] = g[0] * J[i, 0, c] + g[1] * J[i, 1, c] + g[2] * J[i, 2, c]
            if acceleration:  # the row's drift; Baumgarte on the normal rate, the slip stopped in the step
                u_n = n0 * u[i, 0] + n1 * u[i, 1] + n2 * u[i, 2]
                slip_rate = g[0] * u[i, 0] + g[1] * u[i, 1] + g[2] * u[i, 2] - u_n
                row_drift = g[0] * drift[i, 0] + g[1] * drift[i, 1] + g[2] * drift[i, 2]
                normal_bound = bound_of(level, dt, stabilisation, gap[i], u_n, row_drift, True)
                bound[r + k] = normal_bound - slip_rate / dt
            else:
                bound[r + k] = contact_bound[i]
    if any_sliding:
        return total, sliding, force
    return total, None, None


class ContactModule(ConstraintModule[ContactBatch]):
    """Rows of the ground and obstacle contacts detected this step."""

    name = "contact"
    needs_contacts = True

    def __init__(
        self, model: pin.Model, facets: int, mode: str, geometry: pin.GeometryModel | None = None
    ) -> None:
        self.mode = mode
        # the radius of each sphere-swept collision geometry (sphere, capsule): its acceleration-level
        # drift is its centre's (see _drifts)
        self.radii = {
            g.name: float(g.geometry.radius)
            for g in (geometry.geometryObjects if geometry is not None else [])
            if isinstance(g.geometry, (coal.Sphere, coal.Capsule))
        }
        self.facets = facets
        angles = 2.0 * np.pi * np.arange(facets) / facets
        self.cos, self.sin = np.cos(angles), np.sin(angles)
        self.masks = support_masks(model)
        self._blanks: dict[int, tuple[np.ndarray, ...]] = {}
        self._data: pin.Data | None = None
        self._joint_jacobians = np.zeros((6, 0))

    def rows(self, ctx: Context) -> Rows[ContactBatch] | None:
        contacts = ctx.contacts
        if not len(contacts):
            return None
        level = ctx.level
        lagged: FrictionIterate = ctx.lagged.get(id(self), _FIRST_PASS)
        if level != "velocity":
            J = point_jacobians(ctx.data, self.masks, contacts.joint, contacts.other_joint, contacts.point)
            keep = is_active(ctx, contacts.gap, _dot(J @ ctx.v, contacts.normal), 0.0)
            if not keep.any():
                return None
            if not keep.all():
                contacts = contacts.select(keep)
        m = len(contacts)
        no_slip, no_stops, no_force, no_drift = self._blank(m)
        drift = _drifts(ctx, contacts, self.radii) if level == "acceleration" else no_drift
        cone = (self.cos, self.sin, self.mode == "pyramid")
        iterate = (
            no_slip if lagged.slip is None else lagged.slip,
            no_stops if lagged.stops is None else lagged.stops,
            no_force if lagged.normal is None else lagged.normal,
        )
        rows, bound, packed, starts, sliding, force = pyramid_rows(
            self._jacobians(ctx.data), self.masks, contacts, ctx, drift, iterate, cone
        )
        # contacts with a full pyramid refine their De Saxce shift at the velocity and impulse levels
        shifts = level != "acceleration" and self.mode != "pyramid"

        def labels() -> list[str]:
            return [
                f"contact {name} row {r}"
                for name, count in zip(contacts.names, np.diff(starts).tolist())
                for r in range(count)
            ]

        batch = ContactBatch(contacts, packed, starts, sliding, shifts, lagged.relaxed)
        return Rows(rows, bound, False, labels, batch, force)

    def _jacobians(self, data: pin.Data) -> np.ndarray:
        """The joint Jacobians data.J (6, nv): a view of Pinocchio's array that follows every pass on
        that data (made once per data object)."""
        if data is not self._data:
            self._data, self._joint_jacobians = data, joint_jacobians(data)  # keeps the memory alive
        return self._joint_jacobians

    def _blank(self, m: int) -> tuple[np.ndarray, ...]:
        """Read-only defaults for m contacts: no lagged slip (NaN: each uses its current one), no
        stops, no lagged normal force, no drift."""
        if m not in self._blanks:
            self._blanks[m] = (np.full((m, 3), np.nan), np.zeros(m, bool), np.zeros(m), np.zeros((m, 3)))
            for array in self._blanks[m]:
                array.flags.writeable = False
        return self._blanks[m]

    def reactions(
        self, rows: Rows[ContactBatch], multipliers: np.ndarray, scale: float
    ) -> list[ContactForce]:
        b = rows.data
        c = b.contacts
        forces = scale * b.forces(multipliers) + b.friction
        return [
            ContactForce(
                c.names[i], c.geometry[i], c.obstacle[i], c.point[i], c.normal[i], float(c.gap[i]), forces[i]
            )
            for i in range(len(c))
        ]

    def refine(self, ctx: Context, rows: Rows[ContactBatch], x: np.ndarray, multipliers: np.ndarray) -> bool:
        b = rows.data
        normals, m = b.contacts.normal, len(b.contacts)
        changed = False
        if b.sliding is not None:
            lagged = self._iterate(ctx)
            u_next = _tangential(b.J @ (ctx.v + ctx.options.dt * x), normals)
            reverse = b.sliding & (_dot(u_next, b.friction) > 0)  # such a contact sticks instead
            if reverse.any():
                lagged.stops = (np.zeros(m, bool) if lagged.stops is None else lagged.stops) | reverse
                lagged.history = None  # fewer sliding contacts: another map
            slides = b.sliding & ~reverse
            previous = np.zeros(m) if lagged.normal is None else lagged.normal
            lam = multipliers[b.starts[:-1]]
            moved = bool((np.abs(lam - previous) > NORMAL_FORCE_TOLERANCE)[slides].any())
            if moved and lagged.normal is not None:  # mixed from the second pass: the first lagged no force
                if lagged.history is None:
                    lagged.history = ([], [])
                lam[slides] = _anderson(lagged.history, previous[slides], lam[slides])
            lagged.normal = np.where(slides, lam, previous)
            rows.settled = not (moved or bool(reverse.any()))
            changed = not rows.settled
        if b.shifts and not b.relaxed:
            mu = b.contacts.friction
            slip = _slips(b.packed, b.starts, x, normals, mu, SLIP_TOLERANCE[self.mode])
            if slip is not None:
                lagged = self._iterate(ctx)
                lagged.passes += 1
                last = lagged.passes >= ctx.options.friction_iterations - 1  # one QP left in the step
                if last and _slips(b.packed, b.starts, x, normals, mu, RELAX_TOLERANCE) is not None:
                    lagged.relaxed = True  # far from the fixed point: that QP drops the shift
                    slip = np.zeros_like(slip)
                lagged.slip = slip
                changed = True
        return changed

    def _iterate(self, ctx: Context) -> FrictionIterate:
        """This solve's iterate, made at its first update."""
        lagged = ctx.lagged.get(id(self))
        if lagged is None:
            lagged = ctx.lagged[id(self)] = FrictionIterate()
        return lagged


def contact_batch(blocks: Iterable[tuple[ConstraintModule, Rows, Any]]) -> ContactBatch | None:
    """The contact module's record among the blocks of a QP (a step report's), or None: no contact rows."""
    for module, rows, _ in blocks:
        if isinstance(module, ContactModule):
            return rows.data
    return None


def _anderson(history: tuple[list, list], x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The next normal forces of the iteration x -> y = G(x) (the sliding friction lagged on x, the
    normal forces y of its QP): Anderson's mixing of the last ANDERSON_MEMORY passes, which ``history``
    (inputs, outputs) keeps. G is affine while the QP's active set stays (its slope, the friction's
    pull on the normal row, is 0.6 for a rod at 45 degrees and mu = 1, which plain passes divide the
    error by), and the mixing then reaches its fixed point in one pass per sliding contact, plus one
    (for fewer than ANDERSON_MEMORY of them)."""
    inputs, outputs = history
    inputs.append(x)
    outputs.append(y)
    del inputs[:-ANDERSON_MEMORY], outputs[:-ANDERSON_MEMORY]
    if len(inputs) == 1:
        return y
    Y = np.array(outputs)
    R = Y - np.array(inputs)
    gamma = np.linalg.lstsq(np.diff(R, axis=0).T, R[-1], rcond=None)[0]
    return np.maximum(y - np.diff(Y, axis=0).T @ gamma, 0.0)


@njit(cache=True)
def _slips(packed, starts, x, normal, mu, tolerance):  # type: ignore[no-untyped-def]
    """When the slip of a contact that refines its shift (one with a full pyramid) and is moving (a
    sticking contact has no shift to refine) moved by more than ``tolerance`` / max(1, mu) (the
    normal velocity error it causes is mu times that): the slips (m, 3) of solution x for those
    contacts, the others' unchanged; else None. ``packed`` and ``starts`` are :func:`_pyramids`'.
    (In scalars, no array per contact: this runs after every QP with friction.)"""
    J, _, slip, _ = _unpacked(packed, len(normal), len(x))
    moved = False
    for i in range(len(slip)):
        moving, u0, u1, u2 = _moving_slip(J, slip, starts, x, normal, i)
        if moving:
            change = max(abs(u0 - slip[i, 0]), abs(u1 - slip[i, 1]), abs(u2 - slip[i, 2]))
            moved |= max(1.0, mu[i]) * change > tolerance
    if not moved:
        return None
    result = slip.copy()
    for i in range(len(slip)):
        moving, u0, u1, u2 = _moving_slip(J, slip, starts, x, normal, i)
        if moving:
            result[i, 0], result[i, 1], result[i, 2] = u0, u1, u2
    return result


@njit(cache=True, inline="always")
def _moving_slip(J, slip, starts, x, normal, i):  # type: ignore[no-untyped-def]
    """(whether contact i refines its shift and its tangential velocity in solution x or its last
    slip is moving, that velocity's 3 components)."""
    if starts[i + 1] - starts[i] == 1:
        return False, 0.0, 0.0, 0.0
    u0, u1, u2 = dot(J[i, 0], x), dot(J[i, 1], x), dot(J[i, 2], x)
    along = u0 * normal[i, 0] + u1 * normal[i, 1] + u2 * normal[i, 2]
    u0, u1, u2 = u0 - along * normal[i, 0], u1 - along * normal[i, 1], u2 - along * normal[i, 2]
    speed = np.sqrt(slip[i, 0] ** 2 + slip[i, 1] ** 2 + slip[i, 2] ** 2)
    return speed > SLIP_SPEED or np.sqrt(u0**2 + u1**2 + u2**2) > SLIP_SPEED, u0, u1, u2


def _drifts(ctx: Context, contacts: Contacts, radii: dict[str, float]) -> np.ndarray:
    """Jdot v of the contact points, shape (m, 3), relative to the other body's point when the
    obstacle is another robot geometry.

    On a sphere-swept geometry (``radii``) the contact point is not a material point: it stays at
    the radius from the centre while the body rolls, so its acceleration is the centre's, without the
    centripetal r |w|^2 of the material point that a rolling ball would take for a lift-off."""
    model, data = ctx.model, ctx.data
    joints = contacts.joint.tolist()
    n = contacts.normal
    centres = contacts.point + np.array([radii.get(g, 0.0) for g in contacts.geometry])[:, None] * n
    result = point_drifts(model, data, joints, point_placements(data, joints, centres))
    others = np.flatnonzero(contacts.other_joint)
    if len(others):
        other_joints = contacts.other_joint[others].tolist()
        depth = contacts.gap[others] + np.array([radii.get(contacts.obstacle[i], 0.0) for i in others])
        points = contacts.point[others] - depth[:, None] * n[others]
        result[others] -= point_drifts(
            model, data, other_joints, point_placements(data, other_joints, points)
        )
    return result
