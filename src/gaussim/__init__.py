"""gaussim: robot simulation by the Gauss principle of least constraint.

The motion of a robot with generalized coordinates q, velocities v, inertia M(q) and forces
F = tau - b(q, v) under constraints minimises the Gauss functional

    Z(a) = 1/2 a^T M a - a^T F    over the admissible set Omega(t, q, v)

(at the velocity level, Z(v+) = 1/2 (v+ - v_free)^T M (v+ - v_free) with v_free = v + dt M^-1 F).
Each constraint module (contacts with Coulomb friction, joint limits, bilateral constraints, or a
user's :class:`gaussim.constraints.ConstraintModule`) contributes linear rows to Omega; ProxQP solves
the QP and its multipliers are the reactions. The documentation states the formulation (its page
"The formulation", docs/FORMULATION.md in the source repository) and the API; the README says how to
build and open it.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from . import portable as _portable  # noqa: F401  # proxsuite's build is chosen at its first import

if TYPE_CHECKING:
    from .constraints import BilateralReaction, ContactForce, JointFrictionReaction, LimitReaction
    from .exceptions import (
        ContactError,
        FrameNotFound,
        GaussimError,
        GaussimWarning,
        GeometryNotFound,
        InfeasibleConstraints,
        InvalidOptions,
        InvalidRobot,
        InvalidState,
        RobotNotFound,
        SolverError,
    )
    from .options import Options
    from .report import StepReport
    from .robot import Robot, as_robot, load_robot
    from .runlog import RunLog
    from .runner import run
    from .scene import Anchor, Box, Ground, LoopClosure, Scene, Sphere
    from .scenefile import SceneSpec, load_scene
    from .simulator import Simulator
    from .solver import Certificate
    from .state import BodyState, State
    from .world import Body, FreeBody, Material, pose

# where each public name lives: imported on first use, so that `gaussim --help` loads no numba or Pinocchio
_HOME = {
    "BilateralReaction": "constraints",
    "ContactForce": "constraints",
    "LimitReaction": "constraints",
    "JointFrictionReaction": "constraints",
    "ContactError": "exceptions",
    "FrameNotFound": "exceptions",
    "GaussimError": "exceptions",
    "GaussimWarning": "exceptions",
    "GeometryNotFound": "exceptions",
    "InfeasibleConstraints": "exceptions",
    "InvalidOptions": "exceptions",
    "InvalidRobot": "exceptions",
    "InvalidState": "exceptions",
    "RobotNotFound": "exceptions",
    "SolverError": "exceptions",
    "Options": "options",
    "StepReport": "report",
    "Robot": "robot",
    "as_robot": "robot",
    "load_robot": "robot",
    "RunLog": "runlog",
    "run": "runner",
    "Anchor": "scene",
    "Box": "scene",
    "Ground": "scene",
    "LoopClosure": "scene",
    "Scene": "scene",
    "Sphere": "scene",
    "SceneSpec": "scenefile",
    "load_scene": "scenefile",
    "Simulator": "simulator",
    "Certificate": "solver",
    "BodyState": "state",
    "State": "state",
    "Body": "world",
    "FreeBody": "world",
    "Material": "world",
    "pose": "world",
}

__all__ = [
    "Anchor",
    "BilateralReaction",
    "Body",
    "BodyState",
    "Box",
    "Certificate",
    "ContactError",
    "ContactForce",
    "FrameNotFound",
    "FreeBody",
    "GaussimError",
    "GaussimWarning",
    "GeometryNotFound",
    "Ground",
    "InfeasibleConstraints",
    "InvalidOptions",
    "InvalidRobot",
    "InvalidState",
    "JointFrictionReaction",
    "LimitReaction",
    "LoopClosure",
    "Material",
    "Options",
    "Robot",
    "RobotNotFound",
    "RunLog",
    "Scene",
    "SceneSpec",
    "Simulator",
    "SolverError",
    "Sphere",
    "State",
    "StepReport",
    "as_robot",
    "load_robot",
    "load_scene",
    "pose",
    "run",
]


def __getattr__(name: str) -> Any:
    if name == "__version__":
        from importlib.metadata import version

        return version("gaussim")
    if name not in _HOME:  # a submodule (gaussim.options): it was an attribute once the names were imported
        try:
            return importlib.import_module(f".{name}", __name__)
        except ModuleNotFoundError as err:
            if err.name != f"{__name__}.{name}":
                raise  # the submodule exists and failed to import
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(importlib.import_module(f".{_HOME[name]}", __name__), name)
    globals()[name] = value  # looked up once
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_HOME))
