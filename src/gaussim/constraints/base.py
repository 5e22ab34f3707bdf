"""What every constraint module shares: the rows it contributes and how bounds are stabilised.

A module turns one constraint family of the scene into rows of the admissible set

    J x >= bound   (unilateral)      or      J x = bound   (bilateral)

where x is the unknown of the Gauss problem being posed: the next velocity v+ (``velocity``
level), the post-impact velocity w (``impulse`` level) or the acceleration a (``acceleration``
level). The QP multipliers of those rows are the reactions (impulses at the first two levels).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np
import pinocchio as pin
from numba import vectorize

from ..collision import Contacts
from ..options import Options

Level = Literal["velocity", "impulse", "acceleration"]


@dataclass
class Rows:
    """Rows of one module.

    Attributes:
        J: row Jacobians, shape (m, nv).
        bound: right-hand sides, shape (m,).
        equality: True for bilateral rows.
        labels: returns one name per row; called only to report infeasibility.
        data: module-specific bookkeeping used to turn multipliers into reactions.
        force: generalized force the module applies outside the QP, shape (nv,), or None
            (sliding friction at the acceleration level).
    """

    J: np.ndarray
    bound: np.ndarray
    equality: bool
    labels: Callable[[], list[str]]
    data: object = None
    force: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.bound)


@dataclass
class Context:
    """What the modules read to build their rows at one level of one step.

    Attributes:
        model, data: Pinocchio model and data with kinematics (and drifts at acceleration level).
        q, v: current configuration (nq,) and velocity (nv,).
        x_free: the unconstrained solution at this level, shape (nv,): v + dt M^-1 F (velocity),
            v (impulse) or M^-1 F (acceleration).
        contacts: detected contact points.
        options: the step options.
        level: which Gauss problem is posed.
        lagged: per-contact arrays carried between fixed-point iterations of one step, aligned with
            the contacts that produced rows (slip velocity for the De Saxce shift, normal force and
            stick decisions for acceleration-level sliding), and the iteration's own bookkeeping
            (its passes; whether the shift was dropped).
    """

    model: pin.Model
    data: pin.Data
    q: np.ndarray
    v: np.ndarray
    x_free: np.ndarray
    contacts: Contacts
    options: Options
    level: Level
    lagged: dict[str, Any] = field(default_factory=dict)


class ConstraintModule(Protocol):
    """A constraint family: produces rows and turns their multipliers into reactions."""

    name: str

    def rows(self, ctx: Context) -> Rows | None:
        """Rows of the admissible set at ``ctx.level``, or None when nothing restricts x."""

    def reactions(self, rows: Rows, multipliers: np.ndarray, scale: float) -> list:
        """Reports from the multipliers of ``rows``, times ``scale`` (1/dt turns impulses into forces)."""

    def refine(self, ctx: Context, rows: Rows, x: np.ndarray, multipliers: np.ndarray) -> bool:
        """Update ``ctx.lagged`` from a solution; True when the step must be solved again."""


def stabilised_bound(
    ctx: Context, phi: np.ndarray, rate: np.ndarray, drift: np.ndarray | float, unilateral: bool
) -> np.ndarray:
    """Right-hand side of  J x >= bound  (or = bound) for a position constraint phi(q) >= 0 (or = 0).

    Args:
        phi: constraint value, positive inside [m or rad].
        rate: its velocity J v.
        drift: Jdot v, used at the acceleration level only.
        unilateral: True for phi >= 0 (an open gap may close exactly within the step).

    At the velocity level a gap closes in one step at most and a violation is removed at the rate
    ``stabilisation / dt``; at the acceleration level a critically damped Baumgarte term with time
    constant dt / stabilisation does the same; at the impulse level the rows only stop the approach.
    """
    o = ctx.options
    return bound_of(LEVELS[ctx.level], o.dt, o.stabilisation, phi, rate, drift, unilateral)


# Levels as compiled code sees them.
LEVELS = {"velocity": 0, "impulse": 1, "acceleration": 2}


@vectorize(["float64(int64, float64, float64, float64, float64, float64, boolean)"], cache=True)
def bound_of(level, dt, stabilisation, phi, rate, drift, unilateral):  # type: ignore[no-untyped-def]
    """:func:`stabilised_bound` for a level code (LEVELS), elementwise; callable from compiled code."""
    if level == 0:
        return -(1.0 / dt if phi >= 0 and unilateral else stabilisation / dt) * phi
    if level == 1:
        return 0.0
    gain = stabilisation / dt
    return -drift - 2.0 * gain * rate - gain * gain * phi


def is_active(ctx: Context, phi: np.ndarray, rate: np.ndarray, margin: float) -> np.ndarray:
    """Which unilateral constraints restrict x at ctx.level (see FORMULATION.md section 2).

    Velocity level: the constraint could be reached within the step (phi + dt * rate <= margin).
    Impulse and acceleration levels: the constraint is closed or closes within the step
    (phi + dt * rate <= active_tolerance) and is not separating, or it is violated (phi <
    -active_tolerance: its stabilised bound brings it back however fast it separates, where dropping
    it let Solo-12's feet take turns sinking at dt = 10 ms).
    """
    options = ctx.options
    closing = phi + options.dt * np.minimum(rate, 0.0)
    if ctx.level == "velocity":
        return closing <= margin
    tolerance = options.active_tolerance
    return (closing <= tolerance) & ((rate <= options.restitution_threshold) | (phi < -tolerance))
