"""Stages 3 and 4, the constraint rows and the Gauss solve: every module's rows at one level, the QP
over them (one per island of bodies that touch, ProxQP, certified), and the multipliers that are the
reactions."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from .assembly import assemble
from .collision import Contacts
from .constraints.base import ConstraintModule, Context, Level, Rows, checked_rows
from .dynamics import Dynamics, Supports
from .exceptions import InvalidOptions
from .options import Options
from .report import StepReport
from .solver.islands import IslandSolver

Parts = list[tuple[ConstraintModule, Rows]]


class GaussStage:
    """The constrained minimum of a step's Gauss functional, for one model and its modules: gaussim's
    own, built from the scene, and the user's (``users``), whose rows are checked (:meth:`posed`)."""

    def __init__(
        self,
        model: pin.Model,
        data: pin.Data,
        modules: list[ConstraintModule],
        options: Options,
        users: Sequence[ConstraintModule] = (),
    ) -> None:
        self.model, self.data, self.modules, self.options = model, data, modules, options
        self._users = {id(module) for module in users}  # by identity: a user's module may define __eq__
        self._masks = Supports.of(model).masks if users else np.zeros((0, 0))  # what checks their rows
        # The acceleration scheme's sliding friction is a fixed point on each contact's normal force,
        # which redundant contacts (a box's four corners) leave non-unique: DAQP answers with a vertex
        # of that set (a corner or three carry the load, a lopsided friction turns the box), ProxQP's
        # proximal iterations with an even spread; its levels keep ProxQP.
        accelerations = options.replace(solver="proxqp")
        self.solvers: dict[Level, IslandSolver] = {
            level: IslandSolver(model, options if level == "velocity" else accelerations)
            for level in ("velocity", "impulse", "acceleration")
        }

    def context(
        self, level: Level, q: np.ndarray, v: np.ndarray, x_free: np.ndarray, contacts: Contacts
    ) -> Context:
        """What the modules read to pose their rows at ``level``."""
        return Context(self.model, self.data, q, v, x_free, contacts, self.options, level)

    def rows(self, ctx: Context) -> Parts:
        """The rows of every module that restricts x at ``ctx.level``."""
        parts = [(module, self.posed(module, ctx)) for module in self.modules]
        return [(module, rows) for module, rows in parts if rows is not None]

    def posed(self, module: ConstraintModule, ctx: Context) -> Rows | None:
        """``module``'s rows at ``ctx``; a user's module's checked (:func:`checked_rows`), and the
        :class:`InvalidOptions` of its call of a gaussim helper (``is_active``) told with its name."""
        try:
            rows = module.rows(ctx)
        except InvalidOptions as err:
            if id(module) not in self._users or err.field.startswith("module "):
                raise
            raise InvalidOptions(f"module '{module.name}': {err.field}", err.message) from err
        if rows is None or id(module) not in self._users:  # gaussim's own make them as the kernels read
            return rows
        return checked_rows(module.name, rows, self._masks)

    def minimise(
        self,
        level: Level,
        q: np.ndarray,
        v: np.ndarray,
        dyn: Dynamics,
        contacts: Contacts,
        report: StepReport,
        scale: float,
    ) -> np.ndarray:
        """Minimise the Gauss functional of ``level`` (``dyn``'s free problem over the modules' rows);
        record the reactions (multipliers times ``scale``) in ``report``."""
        ctx = self.context(level, q, v, dyn.x_free, contacts)
        return self.solve(ctx, dyn.M, dyn.g, None, report, scale)

    def solve(
        self,
        ctx: Context,
        M: np.ndarray,
        g: np.ndarray,
        parts: Parts | None,
        report: StepReport,
        scale: float,
    ) -> np.ndarray:
        """min 1/2 x^T M x + g^T x over the rows ``parts`` (posed from ``ctx`` when None), the rows of
        a module posed again while its fixed-point iteration asks for it."""
        mark, passes = report.mark, self.options.friction_iterations
        problem = None  # the last pass's, whose stacked rows a pass that moved bounds alone keeps
        for k in range(passes):
            mark("")
            parts = self.rows(ctx) if parts is None else parts
            if not parts:
                mark("assembly")
                return ctx.x_free
            problem = assemble(M, g, parts, problem)
            mark("assembly")
            x, lam, certificates = self.solvers[ctx.level].solve(problem, ctx.x_free)
            mark("solve")
            report.certificates += certificates
            ctx.solved = (problem, lam)
            blocks = [(module, rows, lam[part]) for module, rows, part in problem.blocks]
            again = [
                module for module, rows, multipliers in blocks if module.refine(ctx, rows, x, multipliers)
            ]
            mark("solve")  # the modules' fixed-point updates are the solve's too
            if not again or k == passes - 1:  # the last pass's answer stands: no rows to pose for it
                break
            asked = {id(module) for module in again}  # by identity: a user's module may define __eq__
            posed = [
                (module, self.posed(module, ctx) if id(module) in asked else rows) for module, rows in parts
            ]
            parts = [(module, rows) for module, rows in posed if rows is not None]
        assert problem is not None  # the loop posed one: it returns early when no module has rows
        report.blocks, report.scale = blocks, scale
        report.solved = (problem, x, lam, self.options.eps_abs)
        mark("")
        return x
