"""The reactions a step reports when its multipliers are not unique: the least-norm ones.

At the answer x of a Gauss problem (see :mod:`.certificate`), the multipliers that certify it are

    { (y, z) :  A^T y + C^T z = H x + g,   z >= 0,   z_i = 0 where C_i x > l_i },

a single point when the rows holding x are independent, else a polytope: redundant contacts (a box
face on the ground, a stack of boxes, four feet on a plane) and the facets of each sticking contact's
pyramid. A dual active-set method answers with one of its vertices: a few rows carry the load, each
contact's force on a facet, its friction at the cone's edge where none is needed (a box at rest, its
corners pushing each other sideways). The reported reactions are the set's point of least norm
instead: the load spread evenly over the rows that can carry it, no friction a rest does not need,
and the same whichever solver or start found x (the motion, x, is unique either way).
"""

from __future__ import annotations

import numpy as np

from ..assembly import GaussProblem
from ..kernels.solver import least_norm
from ..portable import portable_proxsuite
from .certificate import KKT_RTOL, Status, checked

# Up to this many coordinates the reactions are the least-norm ones; a larger problem (a pile of 20
# boxes) reports its solver's: the dense factorization of its size would cost more than its step.
LEAST_NORM_UP_TO = 64


def least_norm_multipliers(
    problem: GaussProblem, x: np.ndarray, multipliers: np.ndarray, eps_abs: float
) -> np.ndarray:
    """The multipliers [y; z] of least norm that certify the answer ``x`` of ``problem`` (see the
    module's docstring), or ``multipliers`` (the solver's) when none is found that gaussim's KKT check
    accepts at the solver's tolerance KKT_RTOL ``eps_abs``. The rows that may carry a multiplier are
    those x holds to within ``eps_abs`` (relative to max(1, |l_i|)). Beyond LEAST_NORM_UP_TO
    coordinates, ``multipliers``."""
    p, n_eq = problem, len(problem.b)
    if len(p.g) > LEAST_NORM_UP_TO:
        return multipliers
    x = np.array(x)  # writable, as the kernels' compiled signatures take it (a certified last answer is not)
    spread = np.empty_like(multipliers)
    if least_norm(p.H, p.g, p.A, p.C, p.l, x, eps_abs, spread) < 0.0:  # a sign the set forbids: a QP
        holding = np.flatnonzero(p.C @ x - p.l <= eps_abs * np.maximum(1.0, np.abs(p.l)))
        K = np.hstack([p.A.T, p.C[holding].T])
        lam = _least_norm_qp(K, p.H @ x + p.g, n_eq, eps_abs / KKT_RTOL)
        spread[:] = 0.0
        spread[:n_eq] = lam[:n_eq]
        spread[n_eq + holding] = np.maximum(lam[n_eq:], 0.0)
    if checked(p, x, spread, Status.SOLVED, KKT_RTOL * eps_abs, screened=False) is None:
        return multipliers
    return spread


def _least_norm_qp(K: np.ndarray, r: np.ndarray, n_eq: int, eps_abs: float) -> np.ndarray:
    """min 1/2 |lam|^2  s.t.  K lam = r,  lam[n_eq:] >= 0, by ProxQP."""
    n = K.shape[1]
    k = n - n_eq
    qp = portable_proxsuite().proxqp.dense.QP(n, K.shape[0], k)
    qp.settings.eps_abs = eps_abs
    sign = np.zeros((k, n))
    sign[:, n_eq:] = np.eye(k)
    qp.init(np.eye(n), np.zeros(n), K, r, sign, np.zeros(k), np.full(k, np.inf))
    qp.solve()
    return np.array(qp.results.x)
