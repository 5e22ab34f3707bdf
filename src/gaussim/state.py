"""The small copyable state of a simulation: time, configuration and velocity."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .exceptions import InvalidState, shown

if TYPE_CHECKING:
    from .world import World


@dataclass(frozen=True, slots=True)
class BodyState:
    """One body's part of a world state: read-only views of its coordinates.

    Attributes:
        name: the body.
        q: its configuration, shape (nq_b,).
        v: its velocity, shape (nv_b,).
    """

    name: str
    q: np.ndarray
    v: np.ndarray


@dataclass(frozen=True, slots=True)
class State:
    """A point of the trajectory.

    Attributes:
        t: time [s].
        q: configuration, shape (nq,) (Pinocchio convention: free-flyer quaternion xyzw).
        v: generalized velocity, shape (nv,).

    q and v are read-only views of arrays the state owns: ``setflags(write=True)`` is refused (a
    Simulator steps the state it returned without checking it again). A state from a Simulator knows
    its world's bodies: ``state.body("crate").q`` is that body's configuration.
    """

    t: float
    q: np.ndarray
    v: np.ndarray
    world: World | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("q", "v"):
            object.__setattr__(self, name, _frozen(real_array(name, getattr(self, name))))
        if isinstance(self.t, (complex, str, bytes)):
            raise InvalidState(f"t must be a real number, got {shown(self.t)}")
        object.__setattr__(self, "t", float(self.t))

    @classmethod
    def adopt(cls, t: float, q: np.ndarray, v: np.ndarray, world: World | None = None) -> State:
        """A state that takes ownership of fresh C-ordered float64 arrays q and v (made read-only, not
        copied; a Simulator steps a copy of a state whose arrays are not such)."""
        state = _new(cls)
        # write=False, positional: cheaper than the keyword (numpy's stubs want the keyword)
        q.setflags(False)  # type: ignore[call-arg]
        v.setflags(False)  # type: ignore[call-arg]
        _set_t(state, float(t))  # past the frozen __setattr__: the slots' own setters, cheaper
        _set_q(state, q.view())  # views of read-only arrays: numpy will not make them writable (_frozen)
        _set_v(state, v.view())
        _set_world(state, world)
        return state

    def body(self, name: str) -> BodyState:
        """The part of this state that is body ``name``'s (views, not copies)."""
        if self.world is None:
            raise InvalidState("this state knows no bodies: take it from Simulator.reset or Simulator.step")
        layout = self.world.body(name)
        return BodyState(name, self.q[layout.q], self.v[layout.v])

    def copy(self) -> State:
        """Return an independent copy (arrays are already read-only, so this is cheap)."""
        return State(self.t, self.q.copy(), self.v.copy(), self.world)

    def save(self, path: str | Path) -> None:
        """Save to a ``.npz`` file (no pickle)."""
        np.savez(path, t=self.t, q=self.q, v=self.v)

    @classmethod
    def load(cls, path: str | Path) -> State:
        """Load a state written by :meth:`save`."""
        with np.load(path, allow_pickle=False) as f:
            return cls(float(f["t"]), f["q"], f["v"])


def real_array(name: str, value: object) -> np.ndarray:
    """``value`` as a new float array; a complex or non-numeric one is an :class:`InvalidState` (numpy
    would drop the imaginary part with a warning, or fail with its own words)."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf":
        raise InvalidState(f"{name} must hold real numbers, got {arr.dtype} values {shown(value)}")
    return np.array(arr, dtype=float)


def _frozen(arr: np.ndarray) -> np.ndarray:
    """A read-only view of ``arr``, itself made read-only: numpy refuses to make the view writable again."""
    arr.setflags(write=False)
    return arr.view()


_new = object.__new__
_set_t, _set_q, _set_v, _set_world = (State.__dict__[name].__set__ for name in ("t", "q", "v", "world"))
