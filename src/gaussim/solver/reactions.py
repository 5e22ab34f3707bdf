"""The reactions a step reports when its multipliers are not unique: the least-norm ones.

At the answer x of a Gauss problem (see :mod:`.certificate`), the multipliers that certify it are

    { (y, z) :  A^T y + C^T z = H x + g,   z >= 0,   z_i = 0 where C_i x > l_i },

a single point when the rows holding x are independent, else a polytope: redundant contacts (a box
face on the ground, a stack of boxes, four feet on a plane) and the facets of each sticking contact's
pyramid. A dual active-set method answers with one of its vertices: a few rows carry the load, each
contact's force on a facet, its friction at the cone's edge where none is needed (a box at rest, its
corners pushing each other sideways). The reported reactions are the set's point of least norm
instead where no sign constraint binds at it (contacts at rest): the load spread evenly over the rows
that can carry it, no friction a rest does not need, the same whichever solver or start found x (the
motion, x, is unique either way). Elsewhere they are the solver's (see :func:`least_norm_multipliers`).
"""

from __future__ import annotations

import numpy as np

from ..assembly import GaussProblem
from ..kernels.bound import Bound
from .certificate import KKT_RTOL, Status, checked

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
least_norm = Bound("solver.least_norm")

# Up to this many coordinates the reactions are the least-norm ones; a larger problem (a pile of 20
# boxes) reports its solver's: the dense factorization of its size would cost more than its step.
LEAST_NORM_UP_TO = 64


def least_norm_multipliers(
    problem: GaussProblem, x: np.ndarray, multipliers: np.ndarray, eps_abs: float
) -> np.ndarray:
    """The multipliers [y; z] of least norm that certify the answer ``x`` of ``problem`` (see the
    module's docstring), when the least-norm solution of A^T y + C^T z = H x + g on the rows x holds (to
    within ``eps_abs``, relative to max(1, |l_i|)) has no negative z and gaussim's KKT check accepts it
    at the solver's tolerance KKT_RTOL ``eps_abs``; else ``multipliers`` (the solver's). Contacts at rest
    meet the first: their loads spread with z > 0. Where a sign constraint would bind (a sliding, tipping
    or collapsing body), the least-norm point would take a QP at every step a log reads (ProxQP's took
    milliseconds on a collapsing humanoid): those steps report the solver's. Beyond LEAST_NORM_UP_TO
    coordinates, ``multipliers``."""
    if len(problem.g) > LEAST_NORM_UP_TO:
        return multipliers
    x = np.array(x)  # writable, as the kernels' compiled signatures take it (a certified last answer is not)
    spread = np.empty_like(multipliers)
    least = least_norm.call(problem.H, problem.g, problem.A, problem.C, problem.l, x, eps_abs, spread)
    z = spread[len(problem.b) :]
    if not least >= -eps_abs * max(1.0, float(np.abs(z).max(initial=0.0))):  # round-off below 0 passes
        return multipliers
    np.maximum(z, 0.0, out=z)
    if checked(problem, x, spread, Status.SOLVED, KKT_RTOL * eps_abs, screened=False) is None:
        return multipliers
    return spread
