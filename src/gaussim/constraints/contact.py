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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..collision import Contact
from ..dynamics import point_drifts, point_jacobians, point_placements
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
        normals: contact normals, shape (m, 3).
        slip: the slip the De Saxce shift used, shape (m, 3) [m/s], and its norm slip_speed (m,).
    """

    contacts: list[Contact]
    J: np.ndarray
    generators: np.ndarray
    starts: np.ndarray
    friction: np.ndarray
    sliding: np.ndarray
    slipping: np.ndarray
    normals: np.ndarray
    slip: np.ndarray
    slip_speed: np.ndarray

    def forces(self, lam: np.ndarray) -> np.ndarray:
        """Sum each contact's rows' multipliers times their generators, shape (m, 3)."""
        return np.add.reduceat(lam[:, None] * self.generators, self.starts, axis=0)


def _tangential(u: np.ndarray, n: np.ndarray) -> np.ndarray:
    return u - np.einsum("mi,mi->m", u, n)[:, None] * n


def _relative(kinematics, model, data, contacts: list[Contact]) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Point Jacobians (m, 3, nv) or drifts (m, 3) of the robot side of each contact, minus those of
    the other side's body at the same point when the obstacle is another robot geometry."""
    joints = [c.joint for c in contacts]
    points = [c.point for c in contacts]
    result = kinematics(model, data, joints, point_placements(data, joints, points))
    others = [i for i, c in enumerate(contacts) if c.other_joint]
    if others:
        other_joints = [contacts[i].other_joint for i in others]
        other_points = [points[i] for i in others]
        result[others] -= kinematics(
            model, data, other_joints, point_placements(data, other_joints, other_points)
        )
    return result


# Per-contact 3-vector algebra runs on Python floats: for the handful of contacts of a robot
# this is several times faster than numpy calls on (m, 3) arrays (measured in benchmarks/step_cost.py).
def _dot(a, b) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _tangent_basis(n, direction) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """Unit tangents (t1, t2) at normal n; t1 along ``direction`` projected on the tangent plane
    when it has a component there, else along a fixed axis."""
    if direction is not None:
        d_n = _dot(direction, n)
        t = (direction[0] - d_n * n[0], direction[1] - d_n * n[1], direction[2] - d_n * n[2])
        norm = _dot(t, t) ** 0.5
    if direction is None or norm <= 1e-12:
        # n x (axis of n's smallest component)
        k = min(range(3), key=lambda i: abs(n[i]))
        axis = [0.0, 0.0, 0.0]
        axis[k] = 1.0
        t = _cross(n, axis)
        norm = _dot(t, t) ** 0.5
    t1 = (t[0] / norm, t[1] / norm, t[2] / norm)
    return t1, _cross(n, t1)


def _cross(a, b) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


class ContactModule:
    """Rows of the ground and obstacle contacts detected this step."""

    name = "contact"

    def __init__(self, facets: int, mode: str) -> None:
        self.mode = mode
        angles = 2.0 * np.pi * np.arange(facets) / facets
        self.directions = list(zip(np.cos(angles).tolist(), np.sin(angles).tolist()))

    def rows(self, ctx: Context) -> Rows | None:
        contacts = ctx.contacts
        if not contacts:
            return None
        model, data, options = ctx.model, ctx.data, ctx.options
        acceleration = ctx.level == "acceleration"
        J = _relative(point_jacobians, model, data, contacts)
        U = (J @ ctx.v).tolist()
        if ctx.level != "velocity":
            normal_speed = np.array([_dot(u, c.normal) for u, c in zip(U, contacts)])
            keep = is_active(ctx, np.array([c.gap for c in contacts]), normal_speed, 0.0).tolist()
            if not any(keep):
                return None
            contacts = [c for c, k in zip(contacts, keep) if k]
            J, U = J[keep], [u for u, k in zip(U, keep) if k]
        drifts = (
            _relative(point_drifts, model, data, contacts).tolist()
            if acceleration
            else [(0.0, 0.0, 0.0)] * len(contacts)
        )
        tendencies = (J @ ctx.x_free).tolist() if self.mode != "pyramid" else [None] * len(contacts)

        generators: list[list[float]] = []
        phi, rates, drift_rates, shifts, floors, slip_speeds = [], [], [], [], [], []  # type: ignore[var-annotated]
        starts, frictions, sliding, slipping, normals, slips = [], [], [], [], [], []  # type: ignore[var-annotated]
        owner: list[int] = []
        for c, u, drift, tendency in zip(contacts, U, drifts, tendencies):
            n, mu = c.normal.tolist(), c.friction
            u_n = _dot(u, n)
            u_t = [u[i] - u_n * n[i] for i in range(3)]
            slip = u_t if acceleration else ctx.lagged.get((c.name, "slip"), u_t)
            speed = _dot(slip, slip) ** 0.5
            slides = acceleration and mu > 0 and speed > SLIP_SPEED and (c.name, "stops") not in ctx.lagged
            friction = [0.0, 0.0, 0.0]
            if mu == 0 or slides:
                gens = [n]
                if slides:  # explicit Coulomb force opposite the slip, lambda_n iterated (module docstring)
                    f = -mu * float(ctx.lagged.get((c.name, "normal"), 0.0)) / speed
                    friction = [f * slip[i] for i in range(3)]
            else:
                # friction opposes the tangential velocity the contact would have without it
                direction = None if tendency is None else [-(tendency[i] + drift[i]) for i in range(3)]
                t1, t2 = _tangent_basis(n, direction)
                gens = [
                    [n[i] + mu * (cs * t1[i] + sn * t2[i]) for i in range(3)] for cs, sn in self.directions
                ]
            starts.append(len(generators))
            generators += gens
            phi += [c.gap] * len(gens)
            if acceleration:  # the velocity and impulse levels' bounds use neither
                rates += [_dot(g, u) for g in gens]
                drift_rates += [_dot(g, drift) for g in gens]
            owner += [len(starts) - 1] * len(gens)
            # restitution: an approaching contact leaves at -e u_n at least (velocity and impulse levels)
            bounce = not acceleration and c.restitution > 0 and -u_n > options.restitution_threshold
            floors += [-c.restitution * u_n if bounce else -np.inf] * len(gens)
            shift = mu * speed if not acceleration and self.mode != "pyramid" else 0.0
            shifts += [shift] * len(gens)  # De Saxce: no lift-off while sliding
            frictions.append(friction)
            sliding.append(slides)
            slipping.append(len(gens) > 1 and not acceleration and self.mode != "pyramid")
            normals.append(n)
            slips.append(slip)
            slip_speeds.append(speed)

        G = np.array(generators)
        starts_ = np.array(starts)
        phi_ = np.array(phi)
        if acceleration:
            bound = stabilised_bound(ctx, phi_, np.array(rates), np.array(drift_rates), True)
        else:
            bound = stabilised_bound(ctx, phi_, phi_, 0.0, True)
        bound = np.maximum(bound, np.array(floors)) - np.array(shifts)
        friction_ = np.array(frictions)
        batch = _Batch(
            contacts,
            J,
            G,
            starts_,
            friction_,
            np.array(sliding),
            np.array(slipping),
            np.array(normals),
            np.array(slips),
            np.array(slip_speeds),
        )
        if len(G) == len(contacts) * len(self.directions):  # every contact has a full pyramid
            rows = np.matmul(G.reshape(len(contacts), -1, 3), J).reshape(len(G), -1)
        else:
            rows = np.einsum("ri,rin->rn", G, J[owner])

        def labels() -> list[str]:
            return [f"contact {contacts[i].name} row {r - starts[i]}" for r, i in enumerate(owner)]

        force = np.einsum("min,mi->n", J, friction_) if any(sliding) else None
        return Rows(rows, bound, False, labels, batch, force)

    def reactions(self, rows: Rows, multipliers: np.ndarray, scale: float) -> list[ContactForce]:
        b: _Batch = rows.data  # type: ignore[assignment]
        forces = scale * b.forces(multipliers) + b.friction
        return [
            ContactForce(c.name, c.geometry, c.obstacle, c.point, c.normal, c.gap, f)
            for c, f in zip(b.contacts, forces)
        ]

    def refine(self, ctx: Context, rows: Rows, x: np.ndarray, multipliers: np.ndarray) -> bool:
        b: _Batch = rows.data  # type: ignore[assignment]
        changed = False
        if b.sliding.any():
            lam = multipliers[b.starts]
            u_next = _tangential(b.J @ (ctx.v + ctx.options.dt * x), b.normals)
            for i in np.flatnonzero(b.sliding).tolist():
                name = b.contacts[i].name
                if u_next[i] @ b.friction[i] > 0:  # friction would reverse the slip: the contact sticks
                    ctx.lagged[(name, "stops")] = True
                    changed = True
                    continue
                changed |= abs(lam[i] - ctx.lagged.get((name, "normal"), 0.0)) > NORMAL_FORCE_TOLERANCE
                ctx.lagged[(name, "normal")] = lam[i]
        if b.slipping.any():
            new = _tangential(b.J @ x, b.normals)
            for i in np.flatnonzero(b.slipping).tolist():
                if max(b.slip_speed[i], float(np.linalg.norm(new[i]))) <= SLIP_SPEED:
                    continue  # a sticking contact has no shift to refine
                changed |= float(np.abs(new[i] - b.slip[i]).max()) > SLIP_TOLERANCE[self.mode]
                ctx.lagged[(b.contacts[i].name, "slip")] = new[i]
        return changed
