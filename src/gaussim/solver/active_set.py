"""The active-set solve: a QP answered from the last solution, one linear solve, before ProxQP is asked.

On the rows K that a solution holds active (its equalities and the inequalities with a positive
multiplier) taken as equalities K x = r, the Gauss problem min 1/2 x^T H x + g^T x is solved by

    x = H^-1 (K^T lam - g),   G lam = r + K H^-1 g,   G = K H^-1 K^T

(G the rows' Delassus matrix). The answer is exact when the active set did not change since that
solution (a contact that keeps sticking, a limit that keeps holding); gaussim's KKT check decides.
When it refuses, a few primal-dual active-set steps follow (rows with a negative multiplier leave,
rows the answer violates join): a contact that starts or stops sliding, or lands, or leaves, changes
a few rows, which those steps find at the cost of a linear solve each instead of a ProxQP solve.
"""

from __future__ import annotations

from ..kernels.bound import Bound
from ..kernels.solver import ACTIVE_SET_FLOOR

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
active_set_candidate = Bound("solver.active_set_candidate")

__all__ = ["ACTIVE_SET_FLOOR", "ACTIVE_SET_UP_TO", "active_set_candidate"]

# Above this many coordinates, with DAQP at hand, the last solution itself is checked but its active set
# is not solved on: the dense factorizations of H and of the rows' Delassus matrix cost more than DAQP
# started from its last working set (a settled bin's island of 120 coordinates: 1.6 ms and certified in
# a third of the steps, against DAQP's 0.8 ms; Solo-12's 18: 11 us against DAQP's 41).
ACTIVE_SET_UP_TO = 64
