"""Stage 6, integration on the configuration manifold (semi-implicit: q+ = q (+) dt v+).

Joints move by Pinocchio's Lie-group ``integrate``, except the floating bases (see
:class:`~gaussim.dynamics.FloatingBases`), which move on R3 x SO(3) as MuJoCo's free joints do: the
origin by dt R v_l+ (R the frame at the step's start, in which v_l+ is expressed), the frame by
exp(dt w+); v_l+ is then re-expressed in the new frame, R+^T R v_l+. A body that keeps its world
velocity keeps it exactly, and a ball rolling on a plane keeps its height (Pinocchio's SE(3)
exponential moves a rolling twist along a screw about the contact point, which lowers the centre
by |v|^2 dt^2 / (2 r) a step). A rigid base that no constraint row touched this step (free flight)
turns instead by the Cayley map of dt w_m, w_m = (w + w+) / 2, the rotation that goes with its
midpoint gyroscopic term: the energy-momentum rule, which keeps a torque-free body's energy and world
angular momentum exactly (exp(dt w+) would keep the energy but let the momentum's direction wander by
about dt |w|). Where rows hold the body, q+ = q (+) dt v+ moves it as the rows' velocities say.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .dynamics import FloatingBases
from .kernels.bound import Bound

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
displacement = Bound("integrator.displacement")
move_bases = Bound("integrator.move_bases")

_NO_BASES = np.zeros(0, dtype=bool)  # ``free`` when no base turns by the midpoint rule


def integrate(
    model: pin.Model,
    q: np.ndarray,
    v: np.ndarray,
    v_next: np.ndarray,
    dt: float,
    scratch: np.ndarray,
    bases: FloatingBases,
    free: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray] | None:
    """The configuration and velocity (nq,), (nv,) after moving from (q, v) with the new velocity
    ``v_next`` (nv,) for ``dt`` [s], or None when ``v_next`` is not finite (from a finite q and a finite
    displacement Pinocchio's integrate is finite). ``scratch`` (nv,) receives the displacement.
    ``free`` (k,): which bases turn by the midpoint rule (rigid bases no row touched; None: none).
    The velocity returned is ``v_next`` itself unless a floating base re-expresses it.
    """
    if not displacement.call(v, v_next, dt, bases.velocity, _NO_BASES if free is None else free, scratch):
        return None
    q_next = pin.integrate(model, q, scratch)
    if not len(bases):
        return q_next, v_next
    v_out = v_next.copy()
    move_bases.call(q, q_next, v_out, dt, bases.configuration, bases.velocity)
    return q_next, v_out
