"""Stage 6, integration on the configuration manifold (semi-implicit: q+ = q (+) dt v+)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin


def integrate(model: pin.Model, q: np.ndarray, v_next: np.ndarray, dt: float) -> np.ndarray:
    """Configuration after moving with the new velocity ``v_next`` (nv,) for ``dt`` [s].

    Uses Pinocchio's Lie-group ``integrate`` (a free-flyer's quaternion stays unit), never q + dt v.
    """
    return pin.integrate(model, q, v_next * dt)
