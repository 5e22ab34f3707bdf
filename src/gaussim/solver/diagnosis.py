"""What a failed solve is reported as: the rows behind an infeasibility, or why ProxQP failed."""

from __future__ import annotations

import math

import numpy as np

from ..assembly import GaussProblem
from ..exceptions import InfeasibleConstraints, SolverError
from .certificate import Certificate

# A row violated by more than this at ProxQP's closest-feasible point, or an inequality within it of its
# bound, is named as involved in an infeasibility.
INFEASIBLE_ROW_TOLERANCE = 1e-6
# A free motion faster than this [m/s or rad/s] comes from absurd inputs, not from the solver's settings.
EXTREME_REACH = 1e8


def infeasibility(problem: GaussProblem, certificate: Certificate, x: np.ndarray) -> InfeasibleConstraints:
    """The error of an empty admissible set, from ProxQP's closest-feasible point ``x`` (nv,): the x
    that needs the smallest change of the bounds, in the least-squares sense."""
    p, c = problem, certificate
    shift = float(np.linalg.norm(np.concatenate([p.A @ x - p.b, np.minimum(p.C @ x - p.l, 0.0)])))
    rows = involved_rows(problem, x)
    return InfeasibleConstraints(
        f"the admissible set is empty ({c.status}); conflicting rows: {', '.join(rows) or 'unknown'}"
        f"; the smallest change of their bounds that admits a motion is {shift:.3g} (2-norm)",
        rows,
        c,
    )


def involved_rows(problem: GaussProblem, x: np.ndarray) -> list[str]:
    """The rows behind an infeasibility, at the closest-feasible point x: the violated ones, and the
    inequalities at their bound (a joint limit that holds while the anchor it blocks is violated)."""
    names = []
    eq = np.abs(problem.A @ x - problem.b)
    names += [n for n, r in zip(problem.labels(True), eq) if r > INFEASIBLE_ROW_TOLERANCE]
    ineq = problem.l - problem.C @ x
    names += [n for n, r in zip(problem.labels(False), ineq) if r > -INFEASIBLE_ROW_TOLERANCE]
    return names


def failure(problem: GaussProblem, certificate: Certificate, raise_unconverged: bool) -> SolverError | None:
    """The error of a solution that is not finite, or not converged when ``raise_unconverged``
    (``Options.on_failure == 'raise'``), naming the inputs when the free motion is absurdly fast;
    else None."""
    c = certificate
    reach = _reach(problem)
    extreme = (
        f"; the free motion reaches |x| ~ {reach:.1e} (m/s or rad/s): a torque, gain or scene value far "
        "beyond any robot's, no solver setting, is the cause; check the inputs"
        if reach > EXTREME_REACH
        else ""
    )
    if not math.isfinite(c.kkt_residual):  # NaN or inf anywhere in x or the multipliers shows there
        return SolverError(f"ProxQP returned a non-finite solution ({c.status}){extreme}", c)
    if not c.converged and raise_unconverged:
        return SolverError(
            f"ProxQP did not converge: {c.status} after {c.outer_iterations} outer iterations, "
            f"{c.iterations} in all (primal residual {c.primal_residual:.2e}, dual residual "
            f"{c.dual_residual:.2e}, duality gap {c.duality_gap:.2e})"
            + (extreme or "; raise Options.max_iter or eps_abs, or set on_failure='report'"),
            c,
        )
    return None


def _reach(problem: GaussProblem) -> float:
    """The size of the problem's free solution, |g| / max diag(H) (inf for non-finite data)."""
    scale = float(np.abs(np.diagonal(problem.H)).max(initial=0.0))
    size = float(np.abs(problem.g).max(initial=0.0))
    return size / scale if scale > 0 and math.isfinite(size) else math.inf
