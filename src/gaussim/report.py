"""What one step reports: reactions per contact, limit and bilateral constraint, and the solver's word."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property, partial
from time import perf_counter as _clock
from typing import TYPE_CHECKING

import numpy as np

from .constraints import (
    BUILT_IN,
    BilateralModule,
    BilateralReaction,
    ConstraintModule,
    ContactForce,
    ContactModule,
    JointFrictionModule,
    JointFrictionReaction,
    LimitModule,
    LimitReaction,
    Rows,
)
from .constraints.contact import contact_batch
from .exceptions import InvalidOptions, _choices, _meant
from .solver import Certificate
from .solver.reactions import least_norm_multipliers

if TYPE_CHECKING:
    from .assembly import GaussProblem
    from .world import World

# Relative singular-value threshold under which stacked contact Jacobians count as rank deficient.
RANK_TOLERANCE = 1e-9


def _untimed(stage: str) -> None:
    """The stage mark of an untimed step: nothing (cheaper than recording marks no one reads)."""


def _timed(marks: list[tuple[str, float]], stage: str) -> None:
    """The stage mark of a timed step: (stage, now) into its ``marks``."""
    marks.append((stage, _clock()))


@dataclass(frozen=True)
class ContactImpulse:
    """An impact's reaction at one contact point, world frame: an impulse, what ``ContactForce.force``
    holds in an impact report (:attr:`StepReport.impact`), under its own name.

    Attributes:
        name, geometry, obstacle, point, normal, gap: as :class:`ContactForce`'s.
        impulse: the impulse on the robot, shape (3,) [N s].
    """

    name: str
    geometry: str
    obstacle: str
    point: np.ndarray
    normal: np.ndarray
    gap: float
    impulse: np.ndarray

    @property
    def normal_impulse(self) -> float:
        """Component along the normal [N s]."""
        return float(self.impulse @ self.normal)


@dataclass(init=False)
class StepReport:
    """The reactions and certificates of one step.

    The reactions are built from the QP multipliers when first read (most steps of a long run are
    never inspected, so the step itself only records the multipliers).

    Attributes:
        t: time at the start of the step [s].
        contacts: force at each contact point [N], world frame.
        limits: joint-limit torques [N m] (forces [N] for prismatic joints).
        bilaterals: bilateral reaction wrenches.
        impact: the reactions of an impact resolved at the start of the step, as impulses
            ([N s], [N m s]) (acceleration scheme only), or None; its own ``impact`` holds the next
            projection, when that one left a contact approaching. Its contacts' ``force`` is an impulse:
            :attr:`impulses` gives them under that name.
        certificates: one per QP solved this step (fixed-point iterations and impacts add QPs).
        timings: wall time per stage [s]: dynamics, collision, assembly, solve, integrate, when the
            step was timed (``Options.timings``), else empty (from ``marks``: (stage,
            time.perf_counter() at its end), the stage "" untimed).
        mark: ``mark(stage)`` records the end of a stage (of its untimed gap for ""): into ``marks``
            when timed, else nothing.
        contact_jacobian: stacked 3-row point Jacobians of the contacts, shape (3 m, nv).
    """

    t: float
    mark: Callable[[str], None] = field(repr=False, compare=False)
    impact: StepReport | None = None
    certificates: tuple[Certificate, ...] = ()
    marks: list[tuple[str, float]] = field(default_factory=list, repr=False)
    # (module, rows, multipliers) of each block of the last QP, the reactions' source, and the factor
    # from multipliers to reactions (1 / dt at the velocity level: impulses to forces)
    blocks: Sequence[tuple[ConstraintModule, Rows, np.ndarray]] = field(default=(), repr=False)
    scale: float = field(default=1.0, repr=False)
    # that QP, its answer x, its multipliers and eps_abs: where its contacts rest, the reactions reported
    # are its least-norm multipliers (gaussim.solver.reactions), computed when first read
    solved: tuple[GaussProblem, np.ndarray, np.ndarray, float] | None = field(
        default=None, repr=False, compare=False
    )
    # the bodies of the stepped world (set by the Simulator), for the forces between bodies
    world: World | None = field(default=None, repr=False, compare=False)
    # the names of the constraint families the Simulator poses (set by it), which :meth:`reactions` knows
    families: tuple[str, ...] | None = field(default=None, repr=False, compare=False)

    def __init__(self, t: float, timed: bool = False) -> None:
        """The report of the step from time ``t``, whose stages start now; ``timed``: record their
        wall times. (Written out, and the class's defaults stand for no impact, no certificates and no
        blocks until a QP sets them: every step makes a report, so it must be cheap.)"""
        self.t = t
        if timed:  # a partial of the list, not a bound method: no reference cycle to collect
            self.marks = [("", _clock())]
            self.mark = partial(_timed, self.marks)
        else:
            self.marks, self.mark = [], _untimed

    @property
    def timed(self) -> bool:
        """True when the step recorded its stages' wall times (``Options.timings``)."""
        return self.mark is not _untimed

    def reactions(self, family: str) -> list:
        """The reactions of the constraint family named ``family`` (a module's ``name``), as its module
        reports them from the multipliers of the step's last QP (forces [N], torques [N m]); empty when
        it held no rows. A name that is no family of the simulator's (nor gaussim's own: ``contact``,
        ``limit``, ``bilateral``, ``joint_friction``) raises :class:`gaussim.InvalidOptions` listing
        them: a misspelt one would read as a step without reactions."""
        # gaussim's own families answer whether or not the simulator poses them (no limit: no reaction)
        if self.families is not None and family not in self.families and family not in BUILT_IN:
            known = {*self.families, *BUILT_IN}
            raise InvalidOptions(
                "family",
                f"no constraint family '{family}' in this simulator{_meant(str(family), known)}; its "
                f"families: {_choices(known)}",
            )
        return [
            r for m, rows, lam in self._spread if m.name == family for r in m.reactions(rows, lam, self.scale)
        ]

    @cached_property
    def _spread(self) -> Sequence[tuple[ConstraintModule, Rows, np.ndarray]]:
        """``blocks`` with the least-norm multipliers of the last QP's answer, which the reactions read
        (where the rows holding it are redundant, a vertex of its multipliers' set is one of many). A QP
        with a force applied outside it (the acceleration level's sliding friction, mu times the normal
        multipliers it was solved with) keeps the solver's: the force goes with them."""
        if self.solved is None or any(rows.force is not None for _, rows, _ in self.blocks):
            return self.blocks
        problem, x, multipliers, eps_abs = self.solved
        lam = least_norm_multipliers(problem, x, multipliers, eps_abs)
        return [(module, rows, lam[part]) for module, rows, part in problem.blocks]

    @cached_property
    def timings(self) -> dict[str, float]:
        timings: dict[str, float] = {}
        for (_, start), (stage, end) in zip(self.marks, self.marks[1:]):
            if stage:
                timings[stage] = timings.get(stage, 0.0) + end - start
        return timings

    @cached_property
    def contacts(self) -> list[ContactForce]:
        return self.reactions(ContactModule.name)

    @cached_property
    def limits(self) -> list[LimitReaction]:
        return self.reactions(LimitModule.name)

    @cached_property
    def bilaterals(self) -> list[BilateralReaction]:
        return self.reactions(BilateralModule.name)

    @cached_property
    def joint_friction(self) -> list[JointFrictionReaction]:
        return self.reactions(JointFrictionModule.name)

    @property
    def impulses(self) -> list[ContactImpulse]:
        """The contact impulses [N s] of the impacts resolved at the start of the step (``impact`` and
        the projections after it, in order), named as impulses; empty without an impact."""
        found, impact = [], self.impact
        while impact is not None:
            found += [
                ContactImpulse(c.name, c.geometry, c.obstacle, c.point, c.normal, c.gap, c.force)
                for c in impact.contacts
            ]
            impact = impact.impact
        return found

    @property
    def contact_jacobian(self) -> np.ndarray | None:
        batch = contact_batch(self.blocks)
        return None if batch is None else batch.J.reshape(-1, batch.J.shape[-1])

    @property
    def friction_relaxed(self) -> bool:
        """True when the De Saxce shift's fixed point was not reached within
        ``Options.friction_iterations`` and the step kept the plain pyramid relaxation (see
        gaussim.constraints.contact)."""
        batch = contact_batch(self.blocks)
        return batch is not None and batch.relaxed

    @property
    def friction_unsettled(self) -> bool:
        """True when a module's fixed-point iteration had not settled (``Rows.settled``) when
        ``Options.friction_iterations`` QPs were spent: among gaussim's modules, the acceleration-level
        sliding friction's (its normal forces still moving, f_t = mu f_n not met; see
        gaussim.constraints.contact); the step is then not ``converged``."""
        return not all(rows.settled for _, rows, _ in self.blocks)

    @property
    def converged(self) -> bool:
        """True when every QP of the step converged (vacuously true when none was needed) and so did
        its friction fixed point (``friction_unsettled``)."""
        return all(c.converged for c in self.certificates) and not self.friction_unsettled

    @property
    def iterations(self) -> int:
        return sum(c.iterations for c in self.certificates)

    @property
    def max_residual(self) -> float:
        """Largest KKT residual (gaussim's own check) of the step's QPs (0 when none was solved)."""
        return max((c.kkt_residual for c in self.certificates), default=0.0)

    @cached_property
    def redundant(self) -> bool:
        """True when the contact forces are not unique: the contact point Jacobians are rank deficient
        (four coplanar feet, a box face on the ground). The motion is unique all the same."""
        J = self.contact_jacobian
        if J is None or not len(J):
            return False
        s = np.linalg.svd(J, compute_uv=False)
        return int(np.sum(s > RANK_TOLERANCE * s[0])) < J.shape[0]

    def body_of(self, contact: ContactForce) -> tuple[str, str]:
        """(the body whose geometry a contact's force acts on, the body or obstacle pushing it)."""
        world = self.world
        if world is None:
            raise ValueError("this report knows no bodies: take it from Simulator.last_step")
        first = world.body_of(contact.geometry)
        second = world.body_of(contact.obstacle)
        return str(first), contact.obstacle if second is None else second

    def forces_between(self, a: str, b: str) -> np.ndarray:
        """The total contact force on body ``a`` from body or obstacle ``b``, world frame, shape (3,)
        [N] (an impulse [N s] in an impact report); ``forces_between(b, a)`` is its opposite."""
        if self.world is not None:
            self.world.body(a)  # an unknown body raises, listing the bodies
            self.world.other(b)  # so does an unknown body or obstacle: a misspelt one would sum to zeros
        total = np.zeros(3)
        for c in self.contacts:
            pair = self.body_of(c)
            if pair == (a, b):
                total += c.force
            elif pair == (b, a):
                total -= c.force
        return total

    def total_contact_force(self) -> np.ndarray:
        """Sum of the contact forces, shape (3,) [N]."""
        return np.sum([c.force for c in self.contacts], axis=0) if self.contacts else np.zeros(3)

    def table(self) -> str:
        """A plain-text table of the contact forces, grouped by pair of bodies (or body and obstacle),
        each group followed by the force between them (:meth:`forces_between`) when there are several."""
        groups: dict[tuple[str, str], list[ContactForce]] = {}
        for c in self.contacts:
            a, b = self.body_of(c) if self.world is not None else ("", c.obstacle)
            groups.setdefault((b, a) if (b, a) in groups else (a, b), []).append(c)
        w = max([28, *(len(c.name) for c in self.contacts), *(len(f"  {a} from {b}") for a, b in groups)])
        lines = [
            f"{'contact':<{w}} {'fx [N]':>9} {'fy [N]':>9} {'fz [N]':>9} {'normal [N]':>11} {'gap [mm]':>9}"
        ]
        for (a, b), contacts in groups.items():
            for c in contacts:
                fx, fy, fz = c.force
                lines.append(
                    f"{c.name:<{w}} {fx:9.3f} {fy:9.3f} {fz:9.3f} {c.normal_force:11.3f} {1e3 * c.gap:9.4f}"
                )
            if len(groups) > 1 and a != b:  # (a body's own links touching: forces on each, not one)
                fx, fy, fz = self.forces_between(a, b) if a else np.sum([c.force for c in contacts], axis=0)
                label = f"  {a} from {b}" if a else f"  from {b}"
                lines.append(f"{label:<{w}} {fx:9.3f} {fy:9.3f} {fz:9.3f}")
        total = self.total_contact_force()
        lines.append(f"{'total':<{w}} {total[0]:9.3f} {total[1]:9.3f} {total[2]:9.3f}")
        return "\n".join(lines)
