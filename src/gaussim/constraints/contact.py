"""Unilateral contacts with Coulomb friction (FORMULATION.md sections 2, 5).

Each contact point with normal n, point Jacobian J (3, nv) and friction mu contributes the rows

    (n + mu d_i)^T J x >= b - s,   i = 1..k

where d_i are k unit tangent directions: the multipliers lambda_i >= 0 give the force
sum_i lambda_i (n + mu d_i), which lies in the friction pyramid inscribed in the Coulomb cone.
(The rows say that the contact velocity lies in the dual of that pyramid: Anitescu's relaxation.)
b is the stabilised normal bound, s the De Saxce shift mu |u_t+| that removes the relaxation's
lift-off while sliding. The shift needs the slip u_t+ of the solution: it starts from the current
slip and, while a contact slides, the QP is solved again with the slip of the last solution until
it moves less than SLIP_TOLERANCE[mode] (a lagged slip lets a decelerating contact sink by
mu (|u_t| - |u_t+|) dt per step; each pass divides that error by about 1 + 1/mu^2).
d_1 is turned against the tangential
velocity the contact would have without friction, so a sliding or pulled contact sees the full
cone, not a facet of the pyramid. With mu = 0 a contact is the single row n^T J x >= b.

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
from ..dynamics import point_drift, point_jacobian
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
class _Point:
    contact: Contact
    J: np.ndarray  # (3, nv)
    generators: np.ndarray  # (m, 3): row i reads generators[i] @ J x >= bound[i]
    friction: np.ndarray | None  # friction force applied outside the QP (sliding, acceleration level)


def _tangent_basis(n: np.ndarray, direction: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents (t1, t2); t1 along ``direction`` projected on the tangent plane when it has one."""
    if direction is not None:
        t1 = direction - (direction @ n) * n
        norm = np.linalg.norm(t1)
        if norm > 1e-12:
            t1 = t1 / norm
            return t1, np.cross(n, t1)
    axis = np.eye(3)[int(np.argmin(np.abs(n)))]
    t1 = np.cross(n, axis)
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(n, t1)


class ContactModule:
    """Rows of the ground and obstacle contacts detected this step."""

    name = "contact"

    def __init__(self, facets: int, mode: str) -> None:
        self.mode = mode
        angles = 2.0 * np.pi * np.arange(facets) / facets
        self.cos, self.sin = np.cos(angles), np.sin(angles)

    def rows(self, ctx: Context) -> Rows | None:
        points, bounds = [], []
        force = np.zeros(ctx.model.nv)
        acceleration = ctx.level == "acceleration"
        for contact in ctx.contacts:
            n, mu = contact.normal, contact.friction
            J = point_jacobian(ctx.model, ctx.data, contact.joint, contact.point)
            u = J @ ctx.v
            u_n = float(u @ n)
            u_t = _tangential(u, n)
            if ctx.level != "velocity" and not is_active(ctx, np.array([contact.gap]), np.array([u_n]), 0.0)[0]:
                continue
            drift = point_drift(ctx.model, ctx.data, contact.joint, contact.point) if acceleration else np.zeros(3)
            slip = u_t if acceleration else ctx.lagged.get((contact.name, "slip"), u_t)
            slip_speed = float(np.linalg.norm(slip))
            friction = None
            if mu == 0.0:
                generators = n[None, :]
            elif acceleration and slip_speed > SLIP_SPEED and (contact.name, "stops") not in ctx.lagged:
                generators = n[None, :]
                normal_force = float(ctx.lagged.get((contact.name, "normal"), 0.0))
                friction = -mu * normal_force * slip / slip_speed
                force += J.T @ friction
            else:
                # friction opposes the tangential velocity the contact would have without it
                tendency = J @ ctx.x_free + drift if self.mode != "pyramid" else None
                t1, t2 = _tangent_basis(n, None if tendency is None else -tendency)
                generators = n + mu * (np.outer(self.cos, t1) + np.outer(self.sin, t2))
            rate = generators @ u
            bound = stabilised_bound(ctx, np.full(len(generators), contact.gap), rate, generators @ drift, True)
            if ctx.level != "acceleration":
                if -u_n > ctx.options.restitution_threshold and contact.restitution > 0:
                    bound = np.maximum(bound, -contact.restitution * u_n)
                if self.mode != "pyramid" and mu > 0:
                    bound = bound - mu * slip_speed  # De Saxce: no lift-off while sliding
            points.append(_Point(contact, J, generators, friction))
            bounds.append(bound)
        if not points:
            return None
        labels = [f"contact {p.contact.name} row {i}" for p in points for i in range(len(p.generators))]
        J_rows = np.vstack([p.generators @ p.J for p in points])
        return Rows(J_rows, np.concatenate(bounds), False, labels, points, force if force.any() else None)

    def reactions(self, rows: Rows, multipliers: np.ndarray, scale: float) -> list[ContactForce]:
        reports, start = [], 0
        for p in rows.data:  # type: ignore[attr-defined]
            lam = multipliers[start : start + len(p.generators)]
            start += len(p.generators)
            force = scale * (lam @ p.generators)
            if p.friction is not None:
                force = force + p.friction
            c = p.contact
            reports.append(ContactForce(c.name, c.geometry, c.obstacle, c.point, c.normal, c.gap, force))
        return reports

    def refine(self, ctx: Context, rows: Rows, x: np.ndarray, multipliers: np.ndarray) -> bool:
        changed, start = False, 0
        for p in rows.data:  # type: ignore[attr-defined]
            lam = multipliers[start : start + len(p.generators)]
            start += len(p.generators)
            c = p.contact
            if p.friction is not None:
                u_next = _tangential(p.J @ (ctx.v + ctx.options.dt * x), c.normal)
                if u_next @ p.friction > 0:  # friction would reverse the slip: the contact sticks
                    ctx.lagged[(c.name, "stops")] = np.ones(1)
                    changed = True
                    continue
                key, value, previous = (c.name, "normal"), lam[0], ctx.lagged.get((c.name, "normal"), 0.0)
                tolerance = NORMAL_FORCE_TOLERANCE
            elif self.mode != "pyramid" and ctx.level != "acceleration" and c.friction > 0:
                key, value = (c.name, "slip"), _tangential(p.J @ x, c.normal)
                previous = ctx.lagged.get(key, _tangential(p.J @ ctx.v, c.normal))
                if max(np.linalg.norm(previous), np.linalg.norm(value)) <= SLIP_SPEED:
                    continue  # a sticking contact has no shift to refine
                tolerance = SLIP_TOLERANCE[self.mode]
            else:
                continue
            changed |= float(np.max(np.abs(value - previous))) > tolerance
            ctx.lagged[key] = value
        return changed


def _tangential(u: np.ndarray, n: np.ndarray) -> np.ndarray:
    return u - (u @ n) * n
