"""Small compiled vector helpers for the kernels: loops, not BLAS (at a robot's sizes a BLAS call costs
more than the arithmetic it does, and its code evicts the step's own from the instruction cache), and
not numba's array expressions or np.cross / np.linalg (each drags seconds of first-run compilation in:
broadcasting and its shape-error messages, LAPACK wrappers)."""

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


@njit(cache=True, inline="always")
def cross(a0, a1, a2, b0, b1, b2):  # type: ignore[no-untyped-def]
    """a x b of two 3-vectors given by their components, as a tuple."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


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


@njit(cache=True, fastmath={"reassoc", "contract"}, inline="always")
def _factor(A, shift, tolerance, drop):  # type: ignore[no-untyped-def]
    """(L, kept, done): the Cholesky factor of A + shift I on the rows whose pivot exceeds
    ``tolerance`` times their diagonal; another row stops it (done False) or, with ``drop``, is left
    out (kept False, its row of L the identity's and no other row reading it)."""
    n = A.shape[0]
    L, kept = np.zeros((n, n)), np.ones(n, np.bool_)
    for j in range(n):
        pivot = A[j, j] + shift
        for p in range(j):
            pivot -= L[j, p] * L[j, p]
        if not pivot > tolerance * A[j, j]:  # NaN fails too
            if not drop:
                return L, kept, False
            L[j, :j] = 0.0
            L[j, j], kept[j] = 1.0, False
            continue
        L[j, j] = diagonal = np.sqrt(pivot)
        for i in range(j + 1, n):
            total = A[i, j]
            for p in range(j):
                total -= L[i, p] * L[j, p]
            L[i, j] = total / diagonal
    return L, kept, True


@njit(cache=True)
def cholesky(A, shift):  # type: ignore[no-untyped-def]
    """The lower Cholesky factor L of A + shift I (A symmetric, (n, n)), L L^T = A + shift I; None
    when that is not positive definite."""
    L, _, done = _factor(A, shift, 0.0, False)
    return L if done else None


@njit(cache=True)
def independent_cholesky(A, tolerance):  # type: ignore[no-untyped-def]
    """(L, kept): the Cholesky factor of A (symmetric positive semidefinite, (n, n)) on the rows kept
    in order, each row i left out (kept[i] False) whose pivot is at most ``tolerance`` times A[i, i]
    (a row dependent on the ones before); a left-out row of L is the identity's, and no other row
    reads it, so a solve with L leaves its entry as given."""
    L, kept, _ = _factor(A, 0.0, tolerance, True)
    return L, kept


@njit(cache=True, fastmath={"reassoc", "contract"})
def forward(L, B):  # type: ignore[no-untyped-def]
    """L^-1 applied to each row of B (k, n) (B L^-T), for a lower-triangular L (n, n); in place."""
    for r in range(B.shape[0]):
        row = B[r]
        for i in range(L.shape[0]):
            total = row[i]
            for j in range(i):
                total -= L[i, j] * row[j]
            row[i] = total / L[i, i]
    return B


@njit(cache=True, fastmath={"reassoc", "contract"})
def forward_columns(L, B):  # type: ignore[no-untyped-def]
    """L^-1 B for a lower-triangular L (n, n) and B (n, k), in place: all k columns at once, the inner
    loop along a row of B (independent sums: it vectorizes, where :func:`forward`'s chained sums wait on
    each other)."""
    for i in range(L.shape[0]):
        row = B[i]
        for j in range(i):
            factor, solved = L[i, j], B[j]
            for r in range(B.shape[1]):
                row[r] -= factor * solved[r]
        for r in range(B.shape[1]):
            row[r] /= L[i, i]
    return B


@njit(cache=True, fastmath={"reassoc", "contract"})
def backward(L, y):  # type: ignore[no-untyped-def]
    """L^-T y for a lower-triangular L (n, n) and a vector y (n,), in place of y."""
    for i in range(L.shape[0] - 1, -1, -1):
        total = y[i]
        for j in range(i + 1, L.shape[0]):
            total -= L[j, i] * y[j]
        y[i] = total / L[i, i]
    return y


@njit(cache=True)
def solve(A, b):  # type: ignore[no-untyped-def]
    """A^-1 b for a square A (n, n) by Gaussian elimination with partial pivoting, in place of A and b;
    None when a pivot is 0 (A singular) or not finite."""
    n = A.shape[0]
    for j in range(n):
        pivot = j
        for i in range(j + 1, n):
            if abs(A[i, j]) > abs(A[pivot, j]):
                pivot = i
        if not abs(A[pivot, j]) > 0.0:  # NaN fails too
            return None
        if pivot != j:
            for k in range(n):
                A[j, k], A[pivot, k] = A[pivot, k], A[j, k]
            b[j], b[pivot] = b[pivot], b[j]
        for i in range(j + 1, n):
            factor = A[i, j] / A[j, j]
            for k in range(j, n):
                A[i, k] -= factor * A[j, k]
            b[i] -= factor * b[j]
    for i in range(n - 1, -1, -1):
        total = b[i]
        for k in range(i + 1, n):
            total -= A[i, k] * b[k]
        b[i] = total / A[i, i]
    return b


@njit(cache=True)
def solve3(K, r0, r1, r2):  # type: ignore[no-untyped-def]
    """K^-1 r for a nonsingular K (3, 3) and r = (r0, r1, r2), by Cramer's rule, as a tuple."""
    c00 = K[1, 1] * K[2, 2] - K[1, 2] * K[2, 1]  # the cofactors of K's first row
    c01 = K[1, 2] * K[2, 0] - K[1, 0] * K[2, 2]
    c02 = K[1, 0] * K[2, 1] - K[1, 1] * K[2, 0]
    det = K[0, 0] * c00 + K[0, 1] * c01 + K[0, 2] * c02
    return (
        (
            c00 * r0
            + (K[0, 2] * K[2, 1] - K[0, 1] * K[2, 2]) * r1
            + (K[0, 1] * K[1, 2] - K[0, 2] * K[1, 1]) * r2
        )
        / det,
        (
            c01 * r0
            + (K[0, 0] * K[2, 2] - K[0, 2] * K[2, 0]) * r1
            + (K[0, 2] * K[1, 0] - K[0, 0] * K[1, 2]) * r2
        )
        / det,
        (
            c02 * r0
            + (K[0, 1] * K[2, 0] - K[0, 0] * K[2, 1]) * r1
            + (K[0, 0] * K[1, 1] - K[0, 1] * K[1, 0]) * r2
        )
        / det,
    )
