"""Stage 0, actuation: the joint torques of a step, (nv,), from what a user passes.

A torque is given for the whole world, (nv,), or for its actuated coordinates only (every body's
but the six of each free root, :attr:`Robot.actuated`, stacked: a floating robot's (nv - 6,)), or per
body as ``{"solo": tau_solo}`` (each (nv_b,) or its actuated ones); what is not given is zero.

Implicit damping D (a PD drive's kd + dt kp), shaped as a torque and >= 0, makes the joints feel
tau - D v+ with v+ the step's new velocity: that is M + dt D in place of M and tau - D v in place of
tau, and Pinocchio's armature carries dt D through CRBA and ABA alike (MuJoCo's implicit damping in
its Euler integrator). It is stable at any dt, where explicit damping diverges once D dt exceeds
about twice a joint's inertia.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pinocchio as pin

from .exceptions import InvalidState, shown
from .kernels.bound import Bound
from .state import real_array
from .world import World

# the kernels called here, past numba's dispatcher (gaussim.kernels.bound)
damped_torque = Bound("actuation.damped_torque")

_FLOAT = np.dtype(float)  # a torque of this dtype is read as given


class Actuation:
    """The torques and implicit damping of each step, for one model and its world.

    Args:
        model: the simulated model, whose armature the damping sets (its own armature is kept).
        world: the bodies' layout.
        dt: the time step [s].
        damping: a damping (nv,) every step has, a step's own added to it (the robot files' joint
            damping, ``Scene(joint_friction=True)``), or None.
    """

    def __init__(self, model: pin.Model, world: World, dt: float, damping: np.ndarray | None = None) -> None:
        self.model, self.world, self.dt = model, world, dt
        self._always = damping if damping is not None and damping.any() else None
        self.nv = model.nv
        actuated = np.concatenate([b.actuated for b in world.bodies.values()]).astype(int)
        contiguous = len(actuated) and np.array_equal(actuated, np.arange(actuated[0], actuated[-1] + 1))
        # a slice where the actuated coordinates are one block (a floating robot's): a cheaper copy
        self._actuated: slice | np.ndarray = (
            slice(int(actuated[0]), int(actuated[-1]) + 1) if contiguous else actuated
        )
        self._shapes = {(self.nv,), (len(actuated),)}
        # the padded torque and damping: zero outside the actuated coordinates, always
        self._padded, self._padded_damping = np.zeros(self.nv), np.zeros(self.nv)
        self._damped = np.empty(self.nv)  # tau - D v of a damped step
        self._zero = np.zeros(self.nv)
        self._zero.flags.writeable = False
        self._undamped = np.zeros(0)  # the previous damping of a step that had none
        self._armature = model.armature.copy()  # the robot's own (rotor inertias)
        self.damping: np.ndarray | None = None  # the implicit damping D (nv,) of the last step

    def torque(self, tau: object, damping: object = None, v: np.ndarray | None = None) -> np.ndarray:
        """The torque of a step, (nv,): ``tau`` [N m] less D v for an implicit ``damping`` D at the
        velocity ``v`` (the step's start), with dt D added to the model's armature (D: ``damping``
        plus the damping every step has, when ``v`` is given). The result may be a buffer the next
        call overwrites. Raises :class:`InvalidState` for a bad shape or value."""
        full = self._full(tau, "tau", self._padded)
        if damping is None and (self._always is None or v is None):
            if self.damping is not None:
                self.model.armature = self._armature
                self.damping = None
            return full
        D = self._full(damping, "damping", self._padded_damping)
        if self._always is not None:
            D = D + self._always
        assert v is not None
        damped = self._damped
        code, same = damped_torque.call(
            full, D, v, self._undamped if self.damping is None else self.damping, damped
        )
        if code == 1:
            raise InvalidState.non_finite("tau", full)
        if code == 2:
            raise InvalidState(f"damping must be finite and >= 0 [N m s/rad], got {shown(damping)}")
        if not same:
            self.model.armature = self._armature + self.dt * D
            self.damping = D.copy()
        return damped

    def after_impact(self, tau: np.ndarray, v_before: np.ndarray, v_after: np.ndarray) -> np.ndarray:
        """The step's torque once an impact changed its velocity: the damping acts on the new one."""
        return tau if self.damping is None else tau - self.damping * (v_after - v_before)

    def non_finite(self, tau: object) -> InvalidState:
        """The error for a torque with non-finite entries, named as the user gave them."""
        if isinstance(tau, Mapping):
            for body, part in tau.items():
                arr = np.asarray(part, dtype=float)
                if not np.all(np.isfinite(arr)):
                    return InvalidState.non_finite(f"tau['{body}']", arr)
        return InvalidState.non_finite("tau", np.asarray(tau, dtype=float))

    def _full(self, tau: object, name: str, padded: np.ndarray) -> np.ndarray:
        """``tau`` as a float array (nv,): zeros for None, padded from the actuated coordinates' or
        from a per-body mapping (entries are checked for finiteness by the kernels that read them)."""
        if tau is None:
            return self._zero
        if type(tau) is not np.ndarray and isinstance(tau, Mapping):  # an array first: ABCs are slow
            return self._per_body(tau, name)
        arr = np.asarray(tau)
        # ints, float32, what is no torque at all (complex, text), or a strided view (the kernels
        # read C-ordered floats: gaussim.kernels.bound)
        if arr.dtype is not _FLOAT or not arr.flags.c_contiguous:
            arr = real_array(name, arr)
        if arr.shape == (self.nv,):
            return arr
        if arr.shape not in self._shapes:
            raise InvalidState(f"{name} must have shape {self._expected()}, got {arr.shape}")
        padded[self._actuated] = arr
        return padded

    def _expected(self) -> str:
        shapes = sorted(self._shapes, reverse=True)
        text = " or ".join(str(s) for s in shapes) + (" for the actuated joints" if len(shapes) > 1 else "")
        bodies = ", ".join(self.world.bodies)
        return f"{text}, or a mapping of body name ({bodies}) to its own"

    def _per_body(self, given: Mapping, name: str) -> np.ndarray:
        full = np.zeros(self.nv)
        for body, tau in given.items():
            layout = self.world.body(str(body))
            arr = real_array(f"{name}['{body}']", tau)
            nv = layout.v.stop - layout.v.start
            shapes = {(nv,), (len(layout.actuated),)}
            if arr.shape not in shapes:
                listed = " or ".join(str(s) for s in sorted(shapes, reverse=True))
                raise InvalidState(f"{name}['{body}'] must have shape {listed}, got {arr.shape}")
            full[layout.v if arr.shape == (nv,) else layout.actuated] = arr
        return full
