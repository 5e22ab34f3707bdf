"""Stage 6, integration on the configuration manifold (semi-implicit: q+ = q (+) dt v+)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from numba import njit

from .linalg import finite


def integrate(
    model: pin.Model,
    q: np.ndarray,
    v_next: np.ndarray,
    dt: float,
    scratch: np.ndarray,
    moved: np.ndarray | None = None,
) -> np.ndarray | None:
    """Configuration after moving with the new velocity ``v_next`` (nv,) for ``dt`` [s], or None when
    ``v_next`` is not finite (from a finite q and a finite displacement Pinocchio's integrate is finite).
    ``scratch`` (nv,) receives the displacement dt v_next (Pinocchio copies what it reads; a kernel
    that writes into an array given costs 0.3 us less than one that returns a new one), unless
    ``moved`` already holds it, finite (the free motion's kernel writes it with v_next).

    Uses Pinocchio's Lie-group ``integrate`` (a free-flyer's quaternion stays unit), never q + dt v.
    """
    if moved is not None:
        return pin.integrate(model, q, moved)
    return pin.integrate(model, q, scratch) if _displacement(v_next, dt, scratch) else None


@njit(cache=True)
def _displacement(v, dt, out):  # type: ignore[no-untyped-def]
    """out = dt v; False when v is not finite."""
    for i in range(len(v)):
        out[i] = dt * v[i]
    return finite(v)
