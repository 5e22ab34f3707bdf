"""Stage 5, the solve of the Gauss problem, and its certificate.

    min_x 1/2 x^T H x + g^T x   s.t.   A x = b,   C x >= l

Modules: :mod:`.certificate` (the status of a solve and gaussim's own KKT check of its answer),
:mod:`.active_set` (the answer built from the last solution's active rows, one linear solve),
:mod:`.dual` (DAQP's dual active-set solve, each island keeping its workspace),
:mod:`.proxqp` (the dense ProxQP wrapper that tries those first, then ProxQP, then recovers),
:mod:`.islands` (the problem split into the independent problems of the bodies that touch, each
solved by its own ProxQP wrapper),
:mod:`.diagnosis` (the errors of a failed solve: the rows behind an infeasibility),
:mod:`.reactions` (the least-norm multipliers a step reports where its answer's are not unique); proxsuite is
loaded with its portable build by :mod:`gaussim.portable`, so that runs repeat bit for bit.
"""

from .certificate import CONVERGED, KKT_RTOL, Certificate, Solution, Status, kkt_residual
from .proxqp import GaussSolver

__all__ = ["CONVERGED", "KKT_RTOL", "Certificate", "GaussSolver", "Solution", "Status", "kkt_residual"]
