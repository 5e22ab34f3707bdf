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
from ..dynamics import cross, point_drifts, point_jacobians, point_placements
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

    Attributes:
        contacts: m contacts.
        J: point Jacobians, shape (m, 3, nv).
        generators: force directions, shape (m, k, 3); row (i, j) reads generators[i, j] @ J[i] x >= bound.
        valid: which (contact, facet) pairs are rows, shape (m, k).
        friction: friction force applied outside the QP, shape (m, 3) (acceleration-level sliding).
        sliding: which contacts get that force, shape (m,).
        slipping: which contacts iterate the De Saxce shift, shape (m,).
        normals: contact normals, shape (m, 3).
        slip: the slip the De Saxce shift used, shape (m, 3) [m/s], and its norm slip_speed (m,).
    """

    contacts: list[Contact]
    J: np.ndarray
    generators: np.ndarray
    valid: np.ndarray
    friction: np.ndarray
    sliding: np.ndarray
    slipping: np.ndarray
    normals: np.ndarray
    slip: np.ndarray
    slip_speed: np.ndarray

    def multipliers(self, lam: np.ndarray) -> np.ndarray:
        """Scatter the rows' multipliers into shape (m, k)."""
        full = np.zeros(self.valid.shape)
        full[self.valid] = lam
        return full


def _normalized(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    norm = np.sqrt(np.einsum("...i,...i->...", x, x))
    return x / np.where(norm > 1e-12, norm, 1.0)[..., None], norm


def _tangent_basis(n: np.ndarray, direction: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents (t1, t2), shape (m, 3) each; t1 along ``direction`` projected on the tangent
    plane where it has a component there, else a fixed axis."""
    if direction is not None:
        t1, norm = _normalized(direction - np.einsum("mi,mi->m", direction, n)[:, None] * n)
        fixed = norm <= 1e-12
    else:
        t1, fixed = np.empty_like(n), np.ones(len(n), dtype=bool)
    if fixed.any():
        axis = np.eye(3)[np.argmin(np.abs(n[fixed]), axis=1)]
        t1[fixed] = _normalized(cross(n[fixed], axis))[0]
    return t1, cross(n, t1)


def _tangential(u: np.ndarray, n: np.ndarray) -> np.ndarray:
    return u - np.einsum("mi,mi->m", u, n)[:, None] * n


class ContactModule:
    """Rows of the ground and obstacle contacts detected this step."""

    name = "contact"

    def __init__(self, facets: int, mode: str) -> None:
        self.mode = mode
        angles = 2.0 * np.pi * np.arange(facets) / facets
        self.cos, self.sin = np.cos(angles)[None, :, None], np.sin(angles)[None, :, None]

    def rows(self, ctx: Context) -> Rows | None:
        contacts = ctx.contacts
        if not contacts:
            return None
        model, data, options = ctx.model, ctx.data, ctx.options
        acceleration = ctx.level == "acceleration"
        n = np.array([c.normal for c in contacts])
        joints = [c.joint for c in contacts]
        placements = point_placements(data, joints, [c.point for c in contacts])
        J = point_jacobians(model, data, joints, placements)
        u = J @ ctx.v
        u_n = np.einsum("mi,mi->m", u, n)
        gap = np.array([c.gap for c in contacts])
        if ctx.level != "velocity":
            keep = is_active(ctx, gap, u_n, 0.0)
            if not keep.any():
                return None
            contacts = [c for c, k in zip(contacts, keep) if k]
            joints = [c.joint for c in contacts]
            placements = [M for M, k in zip(placements, keep) if k]
            n, J, u, u_n, gap = n[keep], J[keep], u[keep], u_n[keep], gap[keep]
        mu = np.array([c.friction for c in contacts])
        u_t = _tangential(u, n)
        drift = point_drifts(model, data, joints, placements) if acceleration else np.zeros_like(u)
        slip = u_t if acceleration else np.array([ctx.lagged.get((c.name, "slip"), s) for c, s in zip(contacts, u_t)])
        slip_direction, slip_speed = _normalized(slip)
        sliding = acceleration & (slip_speed > SLIP_SPEED) & (mu > 0)
        sliding &= np.array([(c.name, "stops") not in ctx.lagged for c in contacts])
        pyramid = (mu > 0) & ~sliding

        tendency = None if self.mode == "pyramid" else -(J @ ctx.x_free + drift)
        t1, t2 = _tangent_basis(n, tendency)
        generators = n[:, None, :] + mu[:, None, None] * (self.cos * t1[:, None, :] + self.sin * t2[:, None, :])
        generators[~pyramid] = n[~pyramid, None, :]
        valid = pyramid[:, None] | (np.arange(generators.shape[1]) == 0)[None, :]

        rate = np.einsum("mki,mi->mk", generators, u)
        phi = np.broadcast_to(gap[:, None], rate.shape)
        bound = stabilised_bound(ctx, phi, rate, np.einsum("mki,mi->mk", generators, drift), True)
        if not acceleration:
            e = np.array([c.restitution for c in contacts])
            bounce = (-u_n > options.restitution_threshold) & (e > 0)
            bound = np.where(bounce[:, None], np.maximum(bound, (-e * u_n)[:, None]), bound)
            if self.mode != "pyramid":
                bound = bound - (mu * slip_speed)[:, None]  # De Saxce: no lift-off while sliding
        normal_force = np.array([ctx.lagged.get((c.name, "normal"), 0.0) for c in contacts])
        friction = np.where(sliding[:, None], -(mu * normal_force)[:, None] * slip_direction, 0.0)
        batch = _Batch(
            contacts, J, generators, valid, friction, sliding,
            pyramid & ~acceleration & (self.mode != "pyramid"), n, slip, slip_speed,
        )
        rows = np.einsum("mki,min->mkn", generators, J)[valid]

        def labels() -> list[str]:
            return [f"contact {contacts[i].name} row {j}" for i, j in zip(*np.nonzero(valid))]

        force = np.einsum("min,mi->n", J, friction) if sliding.any() else None
        return Rows(rows, bound[valid], False, labels, batch, force)

    def reactions(self, rows: Rows, multipliers: np.ndarray, scale: float) -> list[ContactForce]:
        b: _Batch = rows.data  # type: ignore[assignment]
        forces = scale * np.einsum("mk,mki->mi", b.multipliers(multipliers), b.generators) + b.friction
        return [
            ContactForce(c.name, c.geometry, c.obstacle, c.point, c.normal, c.gap, f)
            for c, f in zip(b.contacts, forces)
        ]

    def refine(self, ctx: Context, rows: Rows, x: np.ndarray, multipliers: np.ndarray) -> bool:
        b: _Batch = rows.data  # type: ignore[assignment]
        changed = False
        if b.sliding.any():
            lam = b.multipliers(multipliers)[:, 0]
            u_next = _tangential(b.J @ (ctx.v + ctx.options.dt * x), b.normals)
            for i in np.flatnonzero(b.sliding):
                name = b.contacts[i].name
                if u_next[i] @ b.friction[i] > 0:  # friction would reverse the slip: the contact sticks
                    ctx.lagged[(name, "stops")] = np.ones(1)
                    changed = True
                    continue
                changed |= abs(lam[i] - ctx.lagged.get((name, "normal"), 0.0)) > NORMAL_FORCE_TOLERANCE
                ctx.lagged[(name, "normal")] = lam[i]
        if b.slipping.any():
            new = _tangential(b.J @ x, b.normals)
            # a sticking contact has no shift to refine
            moving = b.slipping & ((b.slip_speed > SLIP_SPEED) | (_normalized(new)[1] > SLIP_SPEED))
            for i in np.flatnonzero(moving):
                previous = ctx.lagged.get((b.contacts[i].name, "slip"), b.slip[i])
                changed |= float(np.max(np.abs(new[i] - previous))) > SLIP_TOLERANCE[self.mode]
                ctx.lagged[(b.contacts[i].name, "slip")] = new[i]
        return changed
