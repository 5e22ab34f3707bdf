"""Constraint modules: each turns one constraint family of the scene into rows of the admissible set.

A family is a :class:`ConstraintModule`: its :meth:`~ConstraintModule.rows` returns, at one level
of one step, the rows J x >= bound (or = bound) of the unknown x of the Gauss problem, or None; the
QP multipliers of those rows are its reactions. gaussim builds the families a scene declares
(contacts with Coulomb friction, joint limits, bilateral constraints).
"""

from .base import ConstraintModule, Context, Level, RowReaction, Rows, is_active, stabilised_bound
from .bilateral import BilateralModule, BilateralReaction
from .contact import ContactForce, ContactModule, FrictionIterate
from .limits import LimitModule, LimitReaction

__all__ = [
    "BilateralModule",
    "BilateralReaction",
    "ConstraintModule",
    "ContactForce",
    "ContactModule",
    "Context",
    "FrictionIterate",
    "Level",
    "LimitModule",
    "LimitReaction",
    "RowReaction",
    "Rows",
    "is_active",
    "stabilised_bound",
]
