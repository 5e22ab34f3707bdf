"""Constraint modules: each turns one constraint family of the scene into rows of the admissible set.

A family is a :class:`ConstraintModule`: its :meth:`~ConstraintModule.rows` returns, at one level
of one step, the rows J x >= bound (or = bound) of the unknown x of the Gauss problem, or None; the
QP multipliers of those rows are its reactions. gaussim builds the families a scene declares
(contacts with Coulomb friction, joint limits, bilateral constraints, dry friction in the joints); a
user adds one with ``Simulator(scene, options, constraints=[...])`` (see examples/custom_constraint.py).
"""

from collections.abc import Sequence

from ..exceptions import InvalidOptions
from .base import ConstraintModule, Context, Level, RowReaction, Rows, is_active, stabilised_bound
from .bilateral import BilateralModule, BilateralReaction
from .contact import ContactForce, ContactModule, FrictionIterate
from .joint_friction import JointFrictionModule, JointFrictionReaction
from .limits import LimitModule, LimitReaction

# The names of the families gaussim builds from a scene: a user's module takes another.
BUILT_IN = (ContactModule.name, LimitModule.name, BilateralModule.name, JointFrictionModule.name)


def checked_modules(built_in: list[ConstraintModule], extra: Sequence[object]) -> list[ConstraintModule]:
    """The modules a simulation runs: ``built_in`` then ``extra`` (the user's, ``Simulator``'s
    ``constraints``), each of ``extra`` checked once: a :class:`ConstraintModule` whose name is its own."""
    taken = list(BUILT_IN)
    for i, module in enumerate(extra):
        field = f"constraints[{i}]"
        if not isinstance(module, ConstraintModule):
            raise InvalidOptions(
                field, f"must be a gaussim.constraints.ConstraintModule, got {type(module).__name__}"
            )
        if type(module) in (ContactModule, LimitModule, BilateralModule, JointFrictionModule):  # the scene's
            raise InvalidOptions(
                field, f"gaussim's {type(module).__name__} comes from the scene: declare it there, not here"
            )
        if not isinstance(module.name, str) or not module.name:
            raise InvalidOptions(field, f"{type(module).__name__}.name must be a non-empty string")
        if module.name in taken:
            raise InvalidOptions(field, f"the name '{module.name}' is taken; taken: {', '.join(taken)}")
        taken.append(module.name)
    return [*built_in, *extra]  # type: ignore[list-item]


__all__ = [
    "BilateralModule",
    "BilateralReaction",
    "ConstraintModule",
    "ContactForce",
    "ContactModule",
    "Context",
    "FrictionIterate",
    "JointFrictionModule",
    "JointFrictionReaction",
    "Level",
    "LimitModule",
    "LimitReaction",
    "RowReaction",
    "Rows",
    "is_active",
    "stabilised_bound",
]
