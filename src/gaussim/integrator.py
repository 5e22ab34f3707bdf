"""Stage 6, integration on the configuration manifold (semi-implicit: q+ = q (+) dt v+)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from numba import njit

from .linalg import finite


def integrate(model: pin.Model, q: np.ndarray, v_next: np.ndarray, dt: float) -> np.ndarray | None:
    """Configuration after moving with the new velocity ``v_next`` (nv,) for ``dt`` [s], or None when
    ``v_next`` is not finite (from a finite q and a finite displacement Pinocchio's integrate is finite).

    Uses Pinocchio's Lie-group ``integrate`` (a free-flyer's quaternion stays unit), never q + dt v.
    """
    displacement = _displacement(v_next, dt)
    return None if displacement is None else pin.integrate(model, q, displacement)


@njit(cache=True)
def _displacement(v, dt):  # type: ignore[no-untyped-def]
    """dt v, or None when v is not finite."""
    return dt * v if finite(v) else None
