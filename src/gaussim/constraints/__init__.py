"""Constraint modules: each turns one constraint family of the scene into rows of the admissible set."""

from .base import ConstraintModule, Context, Rows
from .bilateral import BilateralModule, BilateralReaction
from .contact import ContactForce, ContactModule
from .limits import LimitModule, LimitReaction

__all__ = [
    "BilateralModule",
    "BilateralReaction",
    "ConstraintModule",
    "ContactForce",
    "ContactModule",
    "Context",
    "LimitModule",
    "LimitReaction",
    "Rows",
]
