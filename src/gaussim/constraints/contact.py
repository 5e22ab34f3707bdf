"""Unilateral contacts with Coulomb friction (docs/FORMULATION.md sections 2, 4, 5).

Each contact point with normal n, point Jacobian J (3, nv) and friction mu contributes the rows

    (n + mu d_i)^T J x >= b - s,   i = 1..k

where d_i are k unit tangent directions: the multipliers lambda_i >= 0 give the force
sum_i lambda_i (n + mu d_i), which lies in the friction pyramid inscribed in the Coulomb cone.
(The rows say that the contact velocity lies in the dual of that pyramid: Anitescu's relaxation.)
b is the stabilised normal bound (with restitution), s the De Saxce shift mu |u_t+| that removes
the relaxation's lift-off while sliding. The shift needs the slip u_t+ of the solution: it starts
from the current slip, or from none for a contact that stuck at the end of the last step (a foot
pivoting on an edge slips at its start velocity by the turn of its point, and its QP would be solved
twice a step to find it stuck again), and, while a contact slides, the QP is solved again with the
slip of the last solution (a lagged slip lets a decelerating contact sink at mu (|u_t| - |u_t+|), an
accelerating one lift off at as much; each pass divides that error by about 1 + 1/mu^2) until the
bounds' error is below SLIP_TOLERANCE[mode]: mu times the change of |u_t+| (all the shift reads),
less the slack the contact's rows leave (a bound that moves within its row's slack leaves the
solution where it is).
Each contact's step is scaled by the secant of its last two passes (:func:`_secant`: a contact switching
between sticking and sliding no longer cycles), or, for the sliding contacts that hold a row active in a
QP of at most NEWTON_UP_TO coordinates, is a Newton step on all their shifts at once (the solution's
response to their bounds couples them), and passes that stall (:func:`_stalled`) within RELAX_TOLERANCE
stop. When the passes of ``Options.friction_iterations`` do not come within RELAX_TOLERANCE of that
fixed point, the last QP takes the slips of the pass nearest it if the passes closed in on it (its
residual RELAX_MARGIN times below the first pass's: a box sliding and spinning, whose corners slide
four ways); else (measured: mu = 1000, where a block sank through the ground under a tiny normal force
whose friction relaxed the shifted bound, and no pass gains on the first) it drops the shift: the plain
relaxation, which may lift a sliding contact at mu |u_t+| but never lets it sink; the step's report
says so (``StepReport.friction_relaxed``).
d_1 is turned against the tangential velocity the contact would have without friction, so a
sliding or pulled contact sees the full cone, not a facet of the pyramid ("pyramid" mode keeps a
fixed basis and no shift); below ALIGN_SPEED that velocity is round-off, and the basis is the fixed one
(a resting contact's rows stay the same from step to step). With mu = 0 a contact is the single row
n^T J x >= b.

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

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from functools import cached_property, partial
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from ..collision import Contacts
from ..dynamics import (
    Supports,
    joint_jacobians,
    point_drifts,
    point_jacobians,
    point_placements,
)
from ..kernels.bound import Bound
from ..kernels.pairs import PATCH_TOLERANCE
from ..kernels.solver import ACTIVE_SET_FLOOR
from .base import LEVELS, ConstraintModule, Context, Rows, is_active

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
contact_row_ids = Bound("contact.contact_row_ids")
newton_moves = Bound("contact.newton_moves")
pyramids = Bound("contact.pyramids")
secant_moves = Bound("contact.secant_moves")
shifted_bounds = Bound("contact.shifted_bounds")
slips = Bound("contact.slips")
unpacked = Bound("contact.unpacked")
matched_values = Bound("solver.matched_values")

# More than a contact's rows (its pyramid's facets, at most options.MAXIMA["friction_facets"]): a row's
# id is its contact's key times this plus its place among them.
ROWS_PER_CONTACT = 128
# Fixed-point iterations on the slip stop when the shifted bounds' error is below this [m/s].
SLIP_TOLERANCE = {"accurate": 1e-4, "exact": 1e-9}
# Still above this after the step's passes, the iteration is far from its fixed point: the last QP
# drops the De Saxce shift [m/s] (below it, the last shifted solution is kept).
RELAX_TOLERANCE = 1e-3
# The last QP keeps the slips of the pass nearest the fixed point, rather than dropping the shift, when
# that pass's residual is this many times below the first pass's: the passes were closing in on it.
RELAX_MARGIN = 10.0
# Acceleration-level sliding friction iterations stop when the normal force moves less than this [N].
NORMAL_FORCE_TOLERANCE = 1e-8
# The De Saxce passes have stalled when two of them do not divide the residual by more than 1 / this.
STALL_RATIO = 0.5
# The range of the secant's scaling of each contact's slip residual (:func:`_secant`).
SECANT_SCALES = (0.2, 2.0)
# Up to this many coordinates, the contacts that slide with a row active take a Newton step on their
# shifts (:func:`_secant`); above, the dense factorization of the active rows costs more than a pass
# (at 35 to 49 it costs about what the passes it saves do: docs/step-cost.md).
NEWTON_UP_TO = 64
# A contact takes the Newton step where it scales the contact's residual within this range, else the
# secant's (where the passes' active set changes, the Newton step can point away from the residual).
NEWTON_SCALES = (0.2, 5.0)
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
        secant: the last pass's move of the lagged slips and its residual, each (m, 3) [m/s]
            (:func:`_secant`), or None.
        residuals: the largest error of the shifted bounds of each De Saxce pass
            (:func:`~gaussim.kernels.contact.slips`) [m/s].
        passes: the De Saxce passes made.
        relaxed: True once the passes have not come within RELAX_TOLERANCE of the fixed point: the
            next QP drops the shift.
        best: the smallest residual of the De Saxce passes and the lagged slips of its pass, or None.
    """

    slip: np.ndarray | None = None
    normal: np.ndarray | None = None
    stops: np.ndarray | None = None
    history: tuple[list, list] | None = None
    secant: tuple[np.ndarray, np.ndarray] | None = None
    residuals: list[float] = field(default_factory=list)
    passes: int = 0
    relaxed: bool = False
    best: tuple[float, np.ndarray] | None = None


# The iterate of a solve's first QP (read, never written: refine makes each solve its own).
_FIRST_PASS = FrictionIterate()


class ContactBatch:
    """The contact module's record of its rows: the contacts that produced them, and what turns
    multipliers back into forces.

    Rows are grouped by contact: contact i owns rows starts[i] to starts[i + 1]. The per-step arrays
    come from :func:`~gaussim.kernels.contact.pyramids` packed in one buffer (returning each would cost
    more than computing it); :func:`~gaussim.kernels.contact.unpacked` gives views of them, read here
    only when asked for.

    Attributes:
        contacts: m contacts.
        packed: the point Jacobians J (m, 3, nv), the force direction of each row (R, 3) (row r reads
            generators[r] @ J[i] x >= bound[r]), the slip the De Saxce shift used (m, 3) [m/s] and the
            friction force applied outside the QP (m, 3) (acceleration-level sliding), in one buffer.
        starts: first row of each contact, then the number of rows, shape (m + 1,).
        sliding: which contacts get that friction force, shape (m,), or None when none does.
        shifts: True when the contacts with a full pyramid refine their De Saxce shift.
        relaxed: True when these rows dropped the shift: its fixed point was not reached.
        slip: the slip the shift used when not the packed one, (m, 3) (a later pass's, see
            :func:`_reshifted`: the buffer, mostly J, is shared with the first pass's record).
    """

    def __init__(
        self,
        contacts: Contacts,
        packed: np.ndarray,
        starts: np.ndarray,
        sliding: np.ndarray | None,
        shifts: bool,
        relaxed: bool,
        slip: np.ndarray | None = None,
    ) -> None:
        self.contacts, self.packed, self.starts = contacts, packed, starts
        self.sliding, self.shifts, self.relaxed = sliding, shifts, relaxed
        self._slip = slip

    @cached_property
    def _views(self) -> tuple[np.ndarray, ...]:
        m = len(self.contacts)
        nv = (len(self.packed) - 3 * int(self.starts[-1]) - 6 * m) // (3 * m)
        return unpacked.call(self.packed, m, nv)

    @property
    def J(self) -> np.ndarray:
        """Point Jacobians, shape (m, 3, nv)."""
        return self._views[0]

    @property
    def generators(self) -> np.ndarray:
        """Force direction of each row, shape (R, 3)."""
        return self._views[1]

    @property
    def slip(self) -> np.ndarray:
        """The slip the De Saxce shift used, shape (m, 3) [m/s]."""
        if self._slip is None:  # the buffer's, before its last 3 m entries (a slice: each pass reads it)
            m = len(self.starts) - 1
            self._slip = self.packed[len(self.packed) - 6 * m : len(self.packed) - 3 * m].reshape(m, 3)
        return self._slip

    @property
    def friction(self) -> np.ndarray:
        """Friction force applied outside the QP, shape (m, 3) [N]."""
        return self._views[3]

    def forces(self, lam: np.ndarray) -> np.ndarray:
        """Sum each contact's rows' multipliers times their generators, shape (m, 3)."""
        return np.add.reduceat(lam[:, None] * self.generators, self.starts[:-1], axis=0)

    def row_ids(self) -> np.ndarray:
        """Each row's id (:attr:`Rows.ids`): its contact's key and its place among that contact's
        rows, shape (R,)."""
        key = self.contacts.key
        if key is None:  # contacts of no detector's making: named by their order
            key = np.arange(len(self.starts) - 1, dtype=np.int64)
        return contact_row_ids.call(self.starts, key, ROWS_PER_CONTACT)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of (m, 3) arrays, shape (m,)."""
    return np.einsum("mi,mi->m", a, b)


def _tangential(u: np.ndarray, n: np.ndarray) -> np.ndarray:
    return u - _dot(u, n)[:, None] * n


def pyramid_rows(
    joint_jacobians: np.ndarray,
    supports: Supports,
    contacts: Contacts,
    ctx: Context,
    drift: np.ndarray,
    iterate: tuple[np.ndarray, np.ndarray, np.ndarray],
    cone: tuple[np.ndarray, np.ndarray, bool],
) -> tuple[np.ndarray, ...]:
    """Every contact's rows at ``ctx``'s level (:func:`~gaussim.kernels.contact.pyramids`, whose
    compiled signature takes ``drift`` and ``iterate`` read-only, whoever made them): (rows
    (R, nv), bound (R,), the packed buffer :class:`ContactBatch` reads, starts (m + 1,), the two
    joints each row reads (R, 2), sliding contacts or None, their friction's generalized force or
    None).

    Args:
        joint_jacobians, supports: what :func:`point_jacobians` reads.
        drift: Jdot v of the contacts at the acceleration level, else zeros, (m, 3).
        iterate: the lagged (slip (m, 3), stops (m,), normal forces (m,)) of the friction iteration.
        cone: (cos, sin) of the pyramid's facet directions, and whether the basis is fixed (the plain
            pyramid, no De Saxce shift).
    """
    m, nv, options = len(contacts), len(ctx.v), ctx.options
    most = m * len(cone[0])  # at most m facets rows
    rows, bound = np.empty((most, nv)), np.empty(most)
    packed, starts = np.empty(3 * m * nv + 3 * most + 6 * m), np.empty(m + 1, np.int64)
    read = np.empty((most, 2), np.int64)
    total, sliding, force = pyramids.call(
        joint_jacobians,
        *supports,
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
        read,
    )
    if total < most:  # frictionless or sliding contacts: fewer rows
        rows, bound, read = rows[:total], bound[:total], read[:total]
        packed = packed[: 3 * m * nv + 3 * total + 6 * m]
    return rows, bound, packed, starts, read, sliding, force


def _read_only(array: np.ndarray) -> np.ndarray:
    """``array`` itself when read-only, else a read-only view of it."""
    if not array.flags.writeable:
        return array
    view = array.view()
    view.flags.writeable = False
    return view


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
        # each cylinder's radius, joint and placement on it: a contact on its rim rolls along the rim
        # (see _drifts)
        self.cylinders = {
            g.name: (float(g.geometry.radius), g.parentJoint, g.placement)
            for g in (geometry.geometryObjects if geometry is not None else [])
            if isinstance(g.geometry, coal.Cylinder)
        }
        self.facets = facets
        angles = 2.0 * np.pi * np.arange(facets) / facets
        self.cos, self.sin = np.cos(angles), np.sin(angles)
        self.supports = Supports.of(model)
        self._blanks: dict[int, tuple[np.ndarray, ...]] = {}
        self._data: pin.Data | None = None
        self._joint_jacobians = np.zeros((6, 0))
        # the rows a solve posed first, and its context: its later passes re-shift their bounds
        self._posed: tuple[Context, Rows[ContactBatch]] | None = None
        # the last velocity-level solution's contact keys and the slips the next one starts from
        # (:meth:`_stuck_start`), when a contact stuck
        self._stuck: tuple[np.ndarray, np.ndarray] | None = None

    def rows(self, ctx: Context) -> Rows[ContactBatch] | None:
        contacts = ctx.contacts
        if not len(contacts):
            self._stuck = None
            return None
        level = ctx.level
        lagged: FrictionIterate = ctx.lagged.get(id(self), _FIRST_PASS)
        last = self._posed
        if last is not None and last[0] is ctx and lagged.slip is not None and level != "acceleration":
            return _reshifted(last[1], lagged.slip, lagged.relaxed)
        if level != "velocity":
            J = point_jacobians(ctx.data, self.supports, contacts.joint, contacts.other_joint, contacts.point)
            keep = is_active(ctx, contacts.gap, _dot(J @ ctx.v, contacts.normal), 0.0)
            if not keep.any():
                return None
            if not keep.all():
                contacts = contacts.select(keep)
        m = len(contacts)
        no_slip, no_stops, no_force, no_drift = self._blank(m)
        # read-only, as the blanks are: one compiled signature (numba types writability)
        drift = no_drift
        if level == "acceleration":
            drift = _read_only(_drifts(ctx, contacts, self.radii, self.cylinders))
        cone = (self.cos, self.sin, self.mode == "pyramid")
        first = no_slip if level != "velocity" else self._stuck_start(contacts, no_slip)
        iterate = (
            first if lagged.slip is None else _read_only(lagged.slip),
            no_stops if lagged.stops is None else _read_only(lagged.stops),
            no_force if lagged.normal is None else _read_only(lagged.normal),
        )
        rows, bound, packed, starts, read, sliding, force = pyramid_rows(
            self._jacobians(ctx.data), self.supports, contacts, ctx, drift, iterate, cone
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
        posed = Rows(rows, bound, False, labels, batch, force, joints=read, ids=batch.row_ids)
        self._posed = (ctx, posed)
        return posed

    def _stuck_start(self, contacts: Contacts, no_slip: np.ndarray) -> np.ndarray:
        """The slips a velocity-level solve starts from (read-only): none (zero) for the contacts that
        stuck in the last one, matched by key, the current one (NaN, ``no_slip``) for the others."""
        if self._stuck is None or contacts.key is None:
            return no_slip
        key, start = self._stuck
        if contacts.key is key:  # the detector's layout of the last step: the same contacts, in order
            return start
        stuck = np.empty(len(contacts))
        if not matched_values.call(key, np.isfinite(start[:, 0]).astype(float), contacts.key, stuck):
            return no_slip
        return _read_only(np.where(stuck[:, None] == 1.0, 0.0, no_slip))

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
            joints = (b.contacts.joint, b.contacts.other_joint)
            start = np.empty((m, 3))  # the next step's start, from the last pass's slips
            slip, residual, stuck = slips.call(
                b.packed,
                b.slip,
                b.starts,
                x,
                normals,
                mu,
                rows.J,
                rows.bound,
                *joints,
                *self.supports[1:],
                start,
            )
            if ctx.level == "velocity":
                start.setflags(False)  # type: ignore[call-arg]  # write=False: read-only, as the blanks are
                self._stuck = (b.contacts.key, start) if stuck and b.contacts.key is not None else None
            if residual > SLIP_TOLERANCE[self.mode]:
                lagged = self._iterate(ctx)
                lagged.passes += 1
                lagged.residuals.append(residual)
                if lagged.best is None or residual < lagged.best[0]:
                    lagged.best = (residual, b.slip)
                last = lagged.passes >= ctx.options.friction_iterations - 1  # one QP left in the step
                if last and residual > RELAX_TOLERANCE:
                    nearest, used = lagged.best
                    # passes that closed in on the fixed point without settling keep the nearest
                    # (a box sliding and spinning at mu 0.5 came within 1e-3 m/s, and the relaxation
                    # threw it up); passes that made no headway drop the shift (mu 1000: it sank)
                    if nearest * RELAX_MARGIN <= lagged.residuals[0]:
                        lagged.slip = used
                        return True
                    lagged.relaxed = True  # far from the fixed point: the last QP drops the shift
                    lagged.slip = np.zeros_like(slip)
                    return True
                if residual <= RELAX_TOLERANCE and _stalled(lagged.residuals):
                    return changed  # near it, and no nearer with more passes: this solution stands
                lagged.slip, lagged.secant = _secant(b.slip, slip, lagged.secant, _newton(ctx, rows))
                changed = True
        return changed

    def _iterate(self, ctx: Context) -> FrictionIterate:
        """This solve's iterate, made at its first update."""
        lagged = ctx.lagged.get(id(self))
        if lagged is None:
            lagged = ctx.lagged[id(self)] = FrictionIterate()
        return lagged


def _reshifted(rows: Rows[ContactBatch], slip: np.ndarray, relaxed: bool) -> Rows[ContactBatch]:
    """``rows``, posed by the first pass of a solve at the velocity or impulse level, with the De Saxce
    shift of the lagged ``slip`` (m, 3): only the bounds move (the rows' directions read the free
    motion, not the slip), where posing them again cost a friction pass most of its time."""
    b = rows.data
    bound = np.empty_like(rows.bound)
    shifted_bounds.call(rows.bound, b.starts, b.contacts.friction, b.slip, slip, bound)
    batch = ContactBatch(b.contacts, b.packed, b.starts, b.sliding, b.shifts, relaxed, slip)
    return Rows(rows.J, bound, False, rows.labels, batch, rows.force, joints=rows.joints, ids=rows.ids)


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


def _stalled(residuals: list[float]) -> bool:
    """True when the De Saxce passes have stopped closing in on the fixed point: the residual did not
    fall below STALL_RATIO of its value two passes back (in the bin of examples/bin_pile.py, most
    steps that spend all the passes do so with a residual that stalls from the third or fourth)."""
    return len(residuals) >= 3 and residuals[-1] > STALL_RATIO * residuals[-3]


def _newton(ctx: Context, rows: Rows[ContactBatch]) -> Callable[..., bool] | None:
    """:func:`~gaussim.kernels.contact.newton_moves` on the QP ``rows`` were solved in (``ctx.solved``),
    to call with (used, mapped, scales, moved) (its arrays read-only whoever made them: one compiled
    signature); None: no QP at hand, or one of more than NEWTON_UP_TO coordinates."""
    if ctx.solved is None or ctx.solved[0].H.shape[0] > NEWTON_UP_TO:
        return None
    problem, multipliers = ctx.solved
    n_eq = len(problem.b)
    first = next(part.start for _, block, part in problem.blocks if block is rows) - n_eq
    b = rows.data
    H, A, C, mu = (_read_only(a) for a in (problem.H, problem.A, problem.C, b.contacts.friction))
    return partial(newton_moves, H, A, C, multipliers[n_eq:], ACTIVE_SET_FLOOR, first, b.starts, b.packed, mu)


def _secant(
    used: np.ndarray,
    mapped: np.ndarray,
    last: tuple[np.ndarray, np.ndarray] | None,
    newton: Callable[..., bool] | None = None,
) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """(the next lagged slips, what the next pass's secant reads) of the De Saxce iteration
    s -> F(s), from the slips ``used`` by this pass's QP, the slips ``mapped`` of its solution, and
    the last pass's (move of s, residual F(s) - s) or None.

    Each contact's residual is scaled by 1 / (1 - a), a the slope of its F along its last move (the
    secant through its last two passes), within SECANT_SCALES. Where a contact's F is about linear
    this reaches its fixed point in one pass: a slope of -1 (a contact switching between sticking and
    sliding, each pass undoing the last) halves the step, 0.5 (a slide's pull on its normal row)
    doubles it, where plain passes repeat or halve the error. The cap keeps the coupling between
    contacts, which each one's secant does not see, from overshooting (in the bin of
    examples/bin_pile.py, a cap of 3 or 4 took more passes than 2).

    ``newton`` (:func:`_newton`, on the QP of this pass) adds that coupling: the contacts that slide
    with a row active take its Newton step, which reaches the fixed point of all of them in one pass
    while the QP's active set stays."""
    moved, residual = np.empty_like(used), np.empty_like(used)
    move, previous = (_NO_MOVE, _NO_MOVE) if last is None else last
    secant_moves.call(used, mapped, move, previous, SECANT_SCALES, moved, residual)
    if newton is not None:
        newton(used, mapped, NEWTON_SCALES, moved)
    return used + moved, (moved, residual)


_NO_MOVE = np.zeros((0, 3))  # the first pass's: no secant yet


def _drifts(
    ctx: Context,
    contacts: Contacts,
    radii: dict[str, float],
    cylinders: dict[str, tuple[float, int, pin.SE3]],
) -> np.ndarray:
    """Jdot v of the contact points, shape (m, 3), relative to the other body's point when the
    obstacle is another robot geometry: the derivative of the velocity of the body's point at the
    contact, J(q) v, along the motion, the contact point moving over the surface as the body turns.

    On a sphere-swept geometry (``radii``) the contact point stays at the radius from the centre
    while the body rolls, so its acceleration is the centre's, without the centripetal r |w|^2 of the
    material point that a rolling ball would take for a lift-off. On a cylinder's rim (``cylinders``,
    unless it stands on a cap, whose points are a flat face's) the point is the rim's lowest, C - r u
    with C the rim's centre and u the normal's part across the axis a, normalised: its drift is C's
    less r w x du/dt (for a cylinder on its side, r (n . (w x a))^2 along n, nothing from rolling)."""
    model, data = ctx.model, ctx.data
    joints = contacts.joint.tolist()
    n = contacts.normal
    centres = contacts.point + np.array([radii.get(g, 0.0) for g in contacts.geometry])[:, None] * n
    rims = []  # (contact, radius, world angular velocity, axis, u) of the contacts rolling on a rim
    for i, g in enumerate(contacts.geometry):
        if g not in cylinders:
            continue
        radius, joint, placement = cylinders[g]
        frame = data.oMi[joint] * placement
        axis = frame.rotation[:, 2]
        s = float(n[i] @ axis)
        across = np.sqrt(max(0.0, 1.0 - s * s))
        if radius * across * (1.0 + across) <= PATCH_TOLERANCE:  # on a cap: the detection's own test
            continue
        centres[i] = frame.translation + ((contacts.point[i] - frame.translation) @ axis) * axis
        w = data.oMi[joint].rotation @ data.v[joint].angular
        rims.append((i, radius, w, axis, s, across))
    result = point_drifts(model, data, joints, point_placements(data, joints, centres))
    for i, radius, w, axis, s, across in rims:
        axis_rate = np.cross(w, axis)
        s_rate = float(n[i] @ axis_rate)
        u = (n[i] - s * axis) / across
        u_rate = -(s_rate * axis + s * axis_rate) / across + u * (s * s_rate / across**2)
        result[i] -= radius * np.cross(w, u_rate)
    others = np.flatnonzero(contacts.other_joint)
    if len(others):
        other_joints = contacts.other_joint[others].tolist()
        depth = contacts.gap[others] + np.array([radii.get(contacts.obstacle[i], 0.0) for i in others])
        points = contacts.point[others] - depth[:, None] * n[others]
        result[others] -= point_drifts(
            model, data, other_joints, point_placements(data, other_joints, points)
        )
    return result
