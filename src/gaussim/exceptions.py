"""The exceptions gaussim raises: one hierarchy, messages that name the cause and the valid choices."""

from __future__ import annotations

import os
import reprlib
import sys
from collections.abc import Iterable
from difflib import get_close_matches
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # numpy is imported where used: the CLI's --help imports this module and no numpy
    import numpy as np


class _Shown(reprlib.Repr):
    """reprlib's repr cut to a line, a numpy scalar or array shown as the Python number or list it
    holds: the message of a scene's size [0.2, -0.1] says -0.1, as the file does, not np.float64(-0.1),
    and a colour [1, 2, 3] is [1.0, 2.0, 3.0], not array([1., 2., 3.])."""

    def repr1(self, x: object, level: int) -> str:
        numpy = sys.modules.get("numpy")  # a numpy value exists only once numpy is imported
        if numpy is not None and isinstance(x, numpy.generic | numpy.ndarray):
            x = x.tolist() if x.size <= 64 else x  # a large array stays reprlib's short "array(...)"
        return super().repr1(x, level)


_SHOWN = _Shown()
_SHOWN.maxlist = _SHOWN.maxtuple = _SHOWN.maxdict = 8
_SHOWN.maxstring = _SHOWN.maxother = 60


class GaussimError(Exception):
    """Base class of every error gaussim raises on purpose."""


class GaussimWarning(UserWarning):
    """An input gaussim accepts but does not model as given (the message says what it did instead)."""


def shown(value: object) -> str:
    """``repr(value)`` cut to a line: an error echoes what it was given, never megabytes of it."""
    return _SHOWN.repr(value)


def finite_numbers(size: int | None) -> str:
    """What a field of ``size`` numbers must hold, for its message: "3 finite numbers", "1 finite
    number" (a one-joint robot's q), "a list of finite numbers" (None: any length)."""
    if size is None:
        return "a list of finite numbers"
    return f"{size} finite number{'' if size == 1 else 's'}"


def _choices(known: Iterable[str], limit: int = 80) -> str:
    names = sorted(set(known))
    shown = ", ".join(names[:limit])
    return shown + (f", ... ({len(names) - limit} more)" if len(names) > limit else "")


def _meant(name: str, known: Iterable[str]) -> str:
    """ " (did you mean a or b?)" for the known names closest to a misspelt ``name``, else ""."""
    close = get_close_matches(name, sorted(set(known)), n=3)
    return f" (did you mean {' or '.join(close)}?)" if close else ""


def missing_file(path: str | os.PathLike[str]) -> str:
    """Why ``path`` names no file: "no such file: PATH", with the files of its folder closest to its
    name (a typo: "did you mean ball.urdf?"), or the folder that does not exist."""
    path = Path(path)
    if not path.parent.is_dir():
        return f"no such file: {path} (no folder {path.parent})"
    try:  # the files of its kind, by their stems (a shared ".urdf" makes every name look close)
        kind = {p.stem: p.name for p in path.parent.iterdir() if p.suffix == path.suffix and p.is_file()}
    except OSError:  # a folder that cannot be listed: no suggestion
        kind = {}
    close = get_close_matches(path.stem, sorted(kind), n=3)
    meant = f" (did you mean {' or '.join(kind[c] for c in close)}?)" if close else ""
    return f"no such file: {path}{meant}"


class RobotNotFound(GaussimError):
    """A robot name is neither an example-robot-data robot nor an existing URDF file."""

    def __init__(self, name: str, known: Iterable[str], file: bool = False) -> None:
        if file:  # a path: the names are no help, its folder's files are
            super().__init__(f"no robot file: {missing_file(name)}")
            return
        super().__init__(
            f"no robot '{name}': not an existing URDF path and not an example-robot-data "
            f"robot{_meant(name, known)}; known names: {_choices(known)}"
        )


class InvalidRobot(GaussimError):
    """A robot description (URDF, MJCF, SDF or an in-memory model) is not a usable model."""


class FrameNotFound(GaussimError):
    """A frame name does not exist in the robot model."""

    def __init__(
        self, name: str, known: Iterable[str], what: str = "frame", where: str = "the robot"
    ) -> None:
        known = list(known)
        super().__init__(f"no {what} '{name}' in {where}{_meant(name, known)}; known: {_choices(known)}")


class GeometryNotFound(FrameNotFound):
    """A collision geometry or environment object name does not exist."""

    def __init__(
        self, name: str, known: Iterable[str], what: str = "collision geometry", where: str = "the robot"
    ) -> None:
        super().__init__(name, known, what, where)


class InvalidOptions(GaussimError, ValueError):
    """An option or scene field holds an invalid value; ``field`` names it, ``message`` says what."""

    def __init__(self, field: str, message: str) -> None:
        self.field, self.message = field, message
        super().__init__(f"{field}: {message}")


class InvalidState(GaussimError, ValueError):
    """A configuration, velocity or torque has the wrong shape, is not finite, or is off the manifold."""

    @classmethod
    def non_finite(cls, name: str, values: np.ndarray) -> InvalidState:
        """The error for an array ``name`` with non-finite entries: it lists where they are."""
        import numpy as np

        return cls(f"{name} has non-finite entries at {np.flatnonzero(~np.isfinite(values)).tolist()}")


class SolverError(GaussimError):
    """ProxQP did not return a usable solution; ``report`` holds the step's certificate."""

    def __init__(self, message: str, report: object | None = None) -> None:
        self.report = report
        super().__init__(message)


class InfeasibleConstraints(SolverError):
    """The admissible set of the step is empty; ``rows`` names the constraints that conflict."""

    def __init__(self, message: str, rows: list[str], report: object | None = None) -> None:
        self.rows = rows
        super().__init__(message, report)


class ContactError(GaussimError):
    """Contact detection gave no usable answer for a pair; ``pair`` names it."""

    def __init__(self, message: str, pair: str) -> None:
        self.pair = pair
        super().__init__(message)
