"""Compiled kernel of the actuation (:mod:`gaussim.actuation`): implicitly damped torques."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def damped_torque(tau, damping, v, previous, full):  # type: ignore[no-untyped-def]
    """(code, D == previous) for an implicit damping D at velocity v, with tau - D v into ``full``, all
    (nv,); code 1 when tau is not finite, 2 when D is not finite or negative (one kernel: this runs
    every damped step; a buffer, not a new array: numba boxes a returned one at 0.35 us)."""
    nv = len(v)
    code = 0
    same = len(previous) == nv
    for i in range(nv):
        if not np.isfinite(tau[i]):
            code = 1
        if not (damping[i] >= 0 and np.isfinite(damping[i])):
            code = 2
        full[i] = tau[i] - damping[i] * v[i]
        same = same and damping[i] == previous[i]
    return code, same
