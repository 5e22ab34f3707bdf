"""Small compiled vector helpers for the kernels: loops, not BLAS (at a robot's sizes a BLAS call costs
more than the arithmetic it does, and its code evicts the step's own from the instruction cache)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def dot(a, b):  # type: ignore[no-untyped-def]
    """a . b of two vectors."""
    total = 0.0
    for i in range(len(a)):
        total += a[i] * b[i]
    return total


@njit(cache=True)
def matvec(A, x):  # type: ignore[no-untyped-def]
    """A x."""
    result = np.empty(A.shape[0])
    for i in range(A.shape[0]):
        result[i] = dot(A[i], x)
    return result


@njit(cache=True)
def finite(x):  # type: ignore[no-untyped-def]
    """True when every entry of the vector x is finite."""
    for value in x:
        if not np.isfinite(value):
            return False
    return True
