"""The constraint protocol: a family of constraints is a :class:`ConstraintModule` that returns its rows.

A module turns one constraint family of the scene into rows of the admissible set

    J x >= bound   (unilateral)      or      J x = bound   (bilateral)

where x is the unknown of the Gauss problem being posed: the next velocity v+ (``velocity``
level), the post-impact velocity w (``impulse`` level) or the acceleration a (``acceleration``
level). The QP multipliers of those rows are the reactions (impulses at the first two levels), >= 0
on unilateral rows: J^T lambda is the generalized force the family applies. See docs/FORMULATION.md.
"""

from __future__ import annotations

import abc
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Generic, Literal, TypeVar

import numpy as np
import pinocchio as pin

from ..collision import Contacts
from ..exceptions import InvalidOptions
from ..kernels.bound import Bound, c_int, is_c_float
from ..kernels.contact import bound_of
from ..options import Options

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
restricting = Bound("contact.restricting")

if TYPE_CHECKING:
    from ..assembly import GaussProblem

Level = Literal["velocity", "impulse", "acceleration"]
T = TypeVar("T")
# The bits of a row's id (Rows.ids): a solver names a row by its module and this id in one int64.
ROW_ID_BITS = 48


@dataclass
class Rows(Generic[T]):
    """Rows of one module, and the module's own record of them (``data``, of the module's type T).

    A user's module's arrays may be of any real dtype and memory order: the Gauss stage replaces them
    with C-ordered float64 (int64 joints) copies where they are not, in this object, and checks their
    shapes (:func:`checked_rows`); gaussim's own modules make them so.
    Neither the module nor anyone else modifies the arrays once returned: a later pass of the step
    that returns the same J array (new bounds alone) keeps the rows the solver has stacked and factored.

    Attributes:
        J: row Jacobians, shape (m, nv).
        bound: right-hand sides, shape (m,).
        equality: True for bilateral rows.
        labels: returns one name per row; called only to report an infeasibility or a reaction.
        data: the module's bookkeeping that turns multipliers into reactions (None when it needs none).
        force: generalized force the module applies outside the QP, shape (nv,), or None
            (sliding friction at the acceleration level).
        settled: False when the module's fixed-point iteration (:meth:`ConstraintModule.refine`) had
            not reached its fixed point at the QP of these rows: the step is then not converged.
        joints: the two joints whose motion each row reads, shape (m, 2) (0: the world): the row is
            zero off their supports, so the solver need not scan J for the bodies it couples; None
            (the default): J is scanned.
        ids: returns one integer per row (m,), in [0, 2**ROW_ID_BITS), that names the same constraint
            from step to step (a contact point's facet, a joint's limit side), so that a solver
            starts from the rows the last step held active; called only when a solver sets up a new
            problem, so it must read the rows it came with, not the module's later state. None (the
            default), or ids of another shape: a row is named by its position among the module's rows.
    """

    J: np.ndarray
    bound: np.ndarray
    equality: bool
    labels: Callable[[], list[str]]
    data: T = None  # type: ignore[assignment]  # a module without bookkeeping: Rows[None]
    force: np.ndarray | None = None
    settled: bool = True
    joints: np.ndarray | None = None
    ids: Callable[[], np.ndarray] | None = None

    def __len__(self) -> int:
        return len(self.bound)


def real_floats(field: str, value: object) -> np.ndarray:
    """``value`` itself when it is what the bound kernels read (:func:`~gaussim.kernels.bound.is_c_float`),
    else a C-ordered float64 copy of the same shape; an :class:`InvalidOptions` naming ``field`` when it
    is ragged or holds no real numbers (numpy would drop an imaginary part with a warning)."""
    if is_c_float(value):
        return value  # type: ignore[return-value]
    try:
        a = np.asarray(value)
    except ValueError:  # nested sequences of unequal lengths
        raise InvalidOptions(field, "must be a rectangular array of real numbers") from None
    if a.dtype.kind not in "biuf":
        raise InvalidOptions(field, f"must hold real numbers, got {a.dtype}")
    return np.array(a, dtype=np.float64, order="C")


def checked_rows(name: str, rows: Rows, masks: np.ndarray) -> Rows:
    """``rows`` of a user's module ``name``, its arrays made what the solver's kernels read and do not
    check, in place: C-ordered float64 of real values, of the shapes the :class:`Rows` fields give,
    joints int64 among the model's whose supports (``masks``, :attr:`~gaussim.dynamics.Supports.masks`,
    (njoints, nv)) hold every nonzero of their row (the islands split the rows by them); raises
    :class:`InvalidOptions` naming the module and the field of a wrong one."""
    where = f"module '{name}': Rows."

    def misfit(field: str, what: str) -> InvalidOptions:
        return InvalidOptions(where + field, f"must {what}")

    njoints, nv = masks.shape
    rows.J, rows.bound = J, bound = real_floats(where + "J", rows.J), real_floats(where + "bound", rows.bound)
    if J.ndim != 2 or J.shape[1] != nv:
        raise misfit("J", f"have shape (rows, {nv}), got {J.shape}")
    if bound.shape != (len(J),):
        raise misfit("bound", f"have shape ({len(J)},), got {bound.shape}")
    if rows.force is not None:
        rows.force = real_floats(where + "force", rows.force)
        if rows.force.shape != (nv,):
            raise misfit("force", f"have shape ({nv},), got {rows.force.shape}")
    if rows.joints is not None:
        try:
            joints = np.asarray(rows.joints)
        except ValueError:  # nested sequences of unequal lengths
            raise misfit("joints", f"be joint indices of shape ({len(J)}, 2)") from None
        if joints.dtype.kind not in "iuf" or joints.shape != (len(J), 2):
            raise misfit(
                "joints", f"be joint indices of shape ({len(J)}, 2), got {joints.dtype} {joints.shape}"
            )
        if joints.dtype.kind == "f" and not np.array_equal(joints, np.round(joints)):  # NaN too
            raise misfit("joints", f"be whole numbers, got {joints[joints != np.round(joints)][0]}")
        if len(joints) and not (0 <= joints.min() and joints.max() < njoints):
            raise misfit(
                "joints", f"be joint indices in [0, {njoints}), got {joints.min():g} to {joints.max():g}"
            )
        joints = c_int(joints)
        outside = (J != 0) & (masks[joints[:, 0]] + masks[joints[:, 1]] == 0)
        if outside.any():
            r, k = np.argwhere(outside)[0]
            a, b = joints[r]
            raise misfit(
                "joints",
                f"name the joints whose motion each row reads: row {r} reads v[{k}], "
                f"which moves neither joint {a} nor joint {b}",
            )
        rows.joints = joints
    return rows


@dataclass
class Context:
    """What the modules read to build their rows at one level of one step.

    Attributes:
        model, data: Pinocchio model and data with kinematics (and drifts at acceleration level).
        q: current configuration, shape (nq,).
        v: current velocity, shape (nv,).
        x_free: the unconstrained solution at this level, shape (nv,): v + dt M^-1 F (velocity),
            v (impulse) or M^-1 F (acceleration).
        contacts: detected contact points.
        options: the step options.
        level: which Gauss problem is posed.
        lagged: each module's record of its fixed-point iteration (:meth:`ConstraintModule.refine`),
            carried between the QPs of one solve, keyed by ``id(module)`` (the contact module's is a
            :class:`~gaussim.constraints.contact.FrictionIterate`); empty at a solve's first QP.
        solved: the QP of the solve's last pass and its multipliers [lambda_eq; lambda_in], set
            before the modules refine (a fixed-point iteration may read how the solution responds to
            its rows' bounds), or None.
    """

    model: pin.Model
    data: pin.Data
    q: np.ndarray
    v: np.ndarray
    x_free: np.ndarray
    contacts: Contacts
    options: Options
    level: Level
    lagged: dict[int, Any] = field(default_factory=dict)
    solved: tuple[GaussProblem, np.ndarray] | None = None


@dataclass
class RowReaction:
    """The reaction of one row: its multiplier in the row's force units ([N] for a row n^T J_p x of
    a point Jacobian J_p and a unit direction n, [N m] for a joint's row; impulses in impact reports).

    Attributes:
        name: the row's label.
        value: the multiplier times the report's scale (>= 0 on unilateral rows).
    """

    name: str
    value: float


class ConstraintModule(abc.ABC, Generic[T]):
    """A constraint family: one method, :meth:`rows`, returns its rows of the admissible set or None.

    Subclass it to add a family to a simulation (``Simulator(scene, options, constraints=[...])``);
    :meth:`reactions` and :meth:`refine` have defaults (one :class:`RowReaction` per row; no
    fixed-point iteration). A step's report gives the reactions of a family by its ``name``
    (``StepReport.reactions(name)``).

    Attributes:
        name: the family's name, unique in a simulation (the built-in ones: ``contact``, ``limit``,
            ``bilateral``).
        needs_contacts: True when the rows come only from the step's detected contacts (the built-in
            contact module): a step without contacts, whose every module says so, poses no QP.
    """

    name: str = ""
    needs_contacts: bool = False

    @abc.abstractmethod
    def rows(self, ctx: Context) -> Rows[T] | None:
        """Rows of the admissible set at ``ctx.level``, or None when nothing restricts x."""

    def reactions(self, rows: Rows[T], multipliers: np.ndarray, scale: float) -> list:
        """Reports from the multipliers of ``rows``, times ``scale`` (1/dt turns impulses into forces)."""
        return [RowReaction(name, float(scale * lam)) for name, lam in zip(rows.labels(), multipliers)]

    def refine(self, ctx: Context, rows: Rows[T], x: np.ndarray, multipliers: np.ndarray) -> bool:
        """Update the module's record in ``ctx.lagged`` from the solution (x, its multipliers of
        ``rows``); True when the step must be posed and solved again (at most
        ``Options.friction_iterations`` QPs a step); set ``rows.settled`` False when the iteration is
        not at its fixed point."""
        return False


def stabilised_bound(
    ctx: Context, phi: np.ndarray, rate: np.ndarray, drift: np.ndarray | float, unilateral: bool
) -> np.ndarray:
    """Right-hand side of  J x >= bound  (or = bound) for a position constraint phi(q) >= 0 (or = 0).

    Args:
        phi: constraint value, positive inside [m or rad].
        rate: its velocity J v.
        drift: Jdot v, used at the acceleration level only.
        unilateral: True for phi >= 0 (an open gap may close exactly within the step).

    At the velocity level a gap closes in one step at most and a violation is removed at the rate
    ``stabilisation / dt`` (a unilateral gap within :data:`~gaussim.kernels.contact.GAP_TOLERANCE` is
    kept as it is: round-off); at the acceleration level a critically damped Baumgarte term with time
    constant dt / stabilisation does the same; at the impulse level the rows only stop the approach.
    """
    o = ctx.options
    return bound_of(LEVELS[ctx.level], o.dt, o.stabilisation, phi, rate, drift, unilateral)


# Levels as compiled code sees them.
LEVELS = {"velocity": 0, "impulse": 1, "acceleration": 2}


def is_active(ctx: Context, phi: np.ndarray, rate: np.ndarray, margin: float) -> np.ndarray:
    """Which unilateral constraints restrict x at ctx.level (see docs/FORMULATION.md section 2).

    Velocity level: the constraint could be reached within the step (phi + dt * rate <= margin).
    Impulse and acceleration levels: the constraint is closed or closes within the step
    (phi + dt * rate <= active_tolerance) and is not separating, or it is violated (phi <
    -active_tolerance: its stabilised bound brings it back however fast it separates, where dropping
    it let Solo-12's feet take turns sinking at dt = 10 ms).
    """
    o = ctx.options
    # a module's, of any make: the kernel reads (m,) floats
    phi, rate = real_floats("is_active: phi", phi), real_floats("is_active: rate", rate)
    if phi.ndim != 1 or rate.shape != phi.shape:
        shapes = f"{phi.shape}, {rate.shape}"
        raise InvalidOptions("is_active", f"phi and rate must have one shape (m,), got {shapes}")
    return restricting.call(  # type: ignore[no-any-return]
        LEVELS[ctx.level], phi, rate, o.dt, float(margin), o.active_tolerance, o.restitution_threshold
    )
