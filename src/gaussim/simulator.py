"""The simulator: a short ``step`` that reads as the algorithm.

    tau    = actuation(tau, damping)                 the torques per body, padded to nv (actuation.py)
    x_free = free motion(q, v, tau)                  ABA, or CRBA + RNEA when a QP follows (dynamics.py)
    contacts = detect(q)                             when the step can bring a pair within its margin
    v+     = scheme(x_free, contacts)                the rows of every module and the Gauss QP over them
                                                     (schemes.py: the velocity or acceleration scheme)
    q+     = q (+) dt v+                             on each joint's manifold (integrator.py)

floating bases (dynamics.FloatingBases, integrator): the base's linear velocity is its origin's in the
    frame of the step's start, so a_free leaves out the frame's turn -w x v_l, and q+ = q (+) dt v+ moves
    the base on R3 x SO(3) (MuJoCo's free joint); a free rigid body's gyroscopic term is taken at the
    step's midpoint (in free flight it keeps energy and angular momentum exactly)
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence

import numpy as np
import pinocchio as pin

from .actuation import Actuation
from .collision import NO_CONTACTS, ContactDetector, Contacts
from .collision.contacts import NOTHING_FOUND
from .constraints import BilateralModule, ContactModule, JointFrictionModule, LimitModule, checked_modules
from .constraints.base import ConstraintModule
from .dynamics import DynamicsStage
from .exceptions import GaussimWarning, InvalidOptions, InvalidRobot, InvalidState, SolverError, shown
from .gauss import GaussStage
from .integrator import integrate
from .kernels.bound import is_c_float
from .options import Options
from .report import StepReport
from .robot import Robot
from .scene import Scene
from .schemes import SCHEMES, Scheme
from .state import State, real_array

# How far from 1 the norm of a configuration's quaternion may be.
UNIT_TOLERANCE = 1e-6


class Simulator:
    """Steps a scene with the Gauss principle; ``last_step`` holds the latest :class:`StepReport`.

    ``constraints``: the user's constraint families (:class:`gaussim.constraints.ConstraintModule`),
    posed with the scene's own each step; their reactions are ``StepReport.reactions(name)``.
    """

    def __init__(
        self, scene: Scene, options: Options | None = None, *, constraints: Sequence[ConstraintModule] = ()
    ) -> None:
        if not isinstance(scene, Scene):
            hint = ": gaussim.Scene(robot, ...) makes one of a robot" if isinstance(scene, Robot) else ""
            raise InvalidOptions("scene", f"must be a gaussim.Scene, got {shown(scene)}{hint}")
        if options is not None and not isinstance(options, Options):
            hint = (
                ": gaussim.Options(**fields) makes one of a mapping" if isinstance(options, Mapping) else ""
            )
            raise InvalidOptions("options", f"must be a gaussim.Options or None, got {shown(options)}{hint}")
        self.scene = scene
        self.options = options or Options()
        self.world = scene.world
        self.model = scene.robot.model.copy()
        self.model.gravity.linear = scene.gravity
        self.data = self.model.createData()
        damping = self.model.damping.copy() if scene.joint_friction else None  # the files' viscous friction
        self.actuation = Actuation(self.model, self.world, self.options.dt, damping)
        self.dynamics = DynamicsStage(self.model, self.data)
        self.detector = ContactDetector(scene, self.options.contact_margin) if scene.pairs else None
        built_in = self._modules(scene, self.options)
        self.modules = checked_modules(built_in, constraints)
        self._families = tuple(m.name for m in self.modules)
        self.gauss = GaussStage(
            self.model, self.data, self.modules, self.options, self.modules[len(built_in) :]
        )
        # a module whose rows do not come from detected contacts makes every step pose the QP
        always = any(not m.needs_contacts for m in self.modules)
        self.scheme: Scheme = SCHEMES[self.options.scheme](self.dynamics, self.gauss, self.actuation, always)
        self.last_step: StepReport | None = None
        self._last_state: State | None = None  # the state the last step returned: already valid
        self._rigid_bases = bool(self.dynamics.bases.rigid.any())
        self._narrow = not self.scheme.acceleration  # see _detect
        # the step's points, and those it left out (see _detect)
        self._found = self._left_out = NOTHING_FOUND
        self._scratch = np.zeros(self.model.nv)  # the step's dt v+, read by Pinocchio's integrate
        self._unit_parts = _unit_parts(self.model)

    @staticmethod
    def _modules(scene: Scene, options: Options) -> list[ConstraintModule]:
        """One module per constraint family the scene declares, and no other."""
        modules: list[ConstraintModule] = []
        if scene.pairs:
            robot = scene.robot
            modules.append(
                ContactModule(
                    robot.model, options.friction_facets, options.friction_mode, robot.collision_model
                )
            )
        if scene.joint_limits:
            modules.append(LimitModule(scene.robot.model))
        if scene.bilaterals:
            modules.append(BilateralModule(scene.robot.frame_id, scene.bilaterals))
        if scene.joint_friction and scene.robot.model.friction.any():
            modules.append(JointFrictionModule(scene.robot.model))
        return modules

    # -- state handling ---------------------------------------------------------------------------

    def reset(
        self,
        q: np.ndarray | Mapping[str, object] | None = None,
        v: np.ndarray | Mapping[str, object] | None = None,
        t: float = 0.0,
    ) -> State:
        """A validated initial state (default: neutral configuration at rest).

        ``q`` is the world's configuration (nq,) or a mapping of body name to its configuration
        (nq_b,) or, for a floating body, its base placement (a pinocchio.SE3, e.g. ``gaussim.pose``,
        its joints neutral); ``v`` the world's velocity (nv,) or a mapping of body name to its (nv_b,).
        What a mapping leaves out is neutral and at rest.
        """
        q = pin.neutral(self.model) if q is None else q
        v = np.zeros(self.model.nv) if v is None else v
        if isinstance(q, Mapping):
            q = self._per_body(q, "q", pin.neutral(self.model))
        if isinstance(v, Mapping):
            v = self._per_body(v, "v", np.zeros(self.model.nv))
        state = State(t, q, v, self.world)  # type: ignore[arg-type]
        self._check_state(state)
        state = self._within_limits(state)
        self._check_overlap(state)
        self.last_step = None
        return state

    def _per_body(self, given: Mapping[str, object], name: str, full: np.ndarray) -> np.ndarray:
        """The world's ``full`` q or v with the bodies' given parts in place."""
        for body, part in given.items():
            layout = self.world.body(str(body))
            where = layout.q if name == "q" else layout.v
            if isinstance(part, pin.SE3):
                if name != "q" or not layout.floating:
                    raise InvalidState(
                        f"{name}['{body}']: a placement (SE3) places a floating body's base only"
                    )
                part = np.concatenate([pin.SE3ToXYZQUAT(part), full[where][7:]])
            arr = real_array(f"{name}['{body}']", part)
            size = where.stop - where.start
            if arr.shape != (size,):
                raise InvalidState(f"{name}['{body}'] must have shape ({size},), got {arr.shape}")
            full[where] = arr
        return full

    def _within_limits(self, state: State) -> State:
        """With joint limits on, a start outside them clamped into them, with a warning naming each
        joint (the limit rows would snap it back in one step, at any speed)."""
        if not self.scene.joint_limits:
            return state
        clamped, listed = within_limits(self.model, state.q)
        if not listed:
            return state
        warnings.warn(
            f"the initial configuration has joints outside their limits, clamped into them: {listed}",
            GaussimWarning,
            stacklevel=3,
        )
        return State(state.t, clamped, state.v, self.world)

    def _check_overlap(self, state: State) -> None:
        """Refuse a start whose pairs overlap deeper than ``Options.start_penetration``."""
        if self.detector is None:
            return
        pin.forwardKinematics(self.model, self.data, state.q)
        self.detector.forget()
        contacts = self.detector.detect(self.data)
        if len(contacts) and contacts.gap.min() < -self.options.start_penetration:
            k = int(np.argmin(contacts.gap))
            raise InvalidState(
                f"the initial configuration has '{contacts.geometry[k]}' {-1e3 * contacts.gap[k]:.4g} mm "
                f"inside '{contacts.obstacle[k]}' (deeper than Options.start_penetration, "
                f"{1e3 * self.options.start_penetration:g} mm): lift it, or raise start_penetration"
            )

    def _check_state(self, state: State) -> None:
        model = self.model
        for name, arr, size in (("q", state.q, model.nq), ("v", state.v, model.nv)):
            if arr.shape != (size,):
                raise InvalidState(f"{name} must have shape ({size},), got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise InvalidState.non_finite(name, arr)
        if not np.isfinite(state.t):
            raise InvalidState(f"t must be finite, got {state.t}")
        for part, message in self._unit_parts:
            norm = float(np.linalg.norm(state.q[part]))
            if abs(norm - 1.0) > UNIT_TOLERANCE:
                raise InvalidState(f"{message}, got norm {norm:.9g}; normalize it (pinocchio.normalize)")

    def full_torque(self, tau: object, damping: object = None, v: np.ndarray | None = None) -> np.ndarray:
        """The joint torques a step applies, shape (nv,): ``tau`` validated and padded (see
        :mod:`.actuation`), minus D v for an implicit damping D at the step's new velocity ``v``."""
        if damping is not None:  # the kernel reads nv floats of v
            if v is None:
                raise InvalidState("damping needs the velocity v it acts on")
            if not is_c_float(v):  # checked and copied, read-only as a state's (one compiled signature)
                v = real_array("v", v)
                v.setflags(write=False)
            if v.shape != (self.model.nv,):
                raise InvalidState(f"v must have shape ({self.model.nv},), got {v.shape}")
        full = self.actuation.torque(tau, damping, v).copy()
        if not np.all(np.isfinite(full)):
            raise InvalidState.non_finite("tau", full)
        return full

    # -- the step ---------------------------------------------------------------------------------

    def step(self, state: State, tau: object = None, damping: object = None) -> State:
        """Advance ``state`` by one time step under joint torques ``tau`` [N m] and return the new state.

        ``tau``: the world's (nv,), its actuated coordinates' (:attr:`Robot.actuated`), or
        ``{body: tau_b}`` (see :mod:`.actuation`); ``damping`` D [N m s/rad], shaped alike and >= 0,
        is velocity feedback applied implicitly: the joints get tau - D v+ (stable at any time step).

        Raises:
            InvalidState: bad state or torque.
            InfeasibleConstraints: the constraints admit no motion (the rows involved are named).
            SolverError: ProxQP failed (see ``Options.on_failure``) or the result is not finite.
        """
        state = self._admit(state)
        report = StepReport(state.t, self.options.timings)
        torque = self.actuation.torque(tau, damping, state.v)
        x_free = self._free_motion(state, torque, tau, report)
        contacts = self._detect(state.v, x_free, report)
        v_next = self.scheme.next_velocity(state, torque, x_free, contacts, report)
        if self._reaches_left_out(v_next):
            v_next = self._again(state, torque, x_free, report)
        return self._advance(state, v_next, report)

    def _admit(self, state: State) -> State:
        """Check a state that is not the one the last step returned (and detect afresh from it); the
        state to step: a copy with C-ordered float arrays when :meth:`State.adopt` took others."""
        if state is not self._last_state:
            if not (is_c_float(state.q) and is_c_float(state.v)):  # the kernels read these
                state = State(state.t, state.q, state.v, state.world)
            self._check_state(state)
            if self.detector:
                self.detector.forget()
        return state

    def _free_motion(self, state: State, torque: np.ndarray, given: object, report: StepReport) -> np.ndarray:
        try:  # the dynamics check the torque's entries, where they are read
            x_free = self.dynamics.free_motion(
                state.q, state.v, torque, self.options.dt, self.scheme.acceleration
            )
        except InvalidState:
            raise self.actuation.non_finite(given) from None
        report.mark("dynamics")
        return x_free

    def _detect(self, v: np.ndarray, x_free: np.ndarray, report: StepReport) -> Contacts:
        """The contacts, when the step's motion may have brought a pair within its margin; in a fast
        step of the velocity scheme, only the points the step can close (the others are kept in
        ``_left_out``, the points found in ``_found``). The acceleration scheme's impacts change v
        within the step: it keeps every point."""
        self._left_out = NOTHING_FOUND
        if not self.detector:
            return NO_CONTACTS
        dt = self.options.dt
        x_scale = dt if self.scheme.acceleration else 1.0
        if not self.detector.cover(v, x_free, dt, x_scale, self.dynamics.reach):
            report.mark("collision")
            return NO_CONTACTS
        found = self._found = self.detector.find(self.data)
        if self._narrow and self.detector.fast and self.detector.beyond_rest(found):
            report.mark("collision")
            self.dynamics.problem()  # the Jacobians the step's rows need anyway
            report.mark("dynamics")
            found, self._left_out = self.detector.reachable(found, self.data, v, x_free, dt, x_scale)
        contacts = self.detector.contacts(found)
        report.mark("collision")
        return contacts

    def _reaches_left_out(self, v_next: np.ndarray) -> bool:
        """Whether the step's answer v+ reaches a point :meth:`_detect` left out."""
        if not len(self._left_out[0]) or self.detector is None:
            return False
        return not self.detector.kept_apart(self._left_out, self.data, v_next, self.options.dt)

    def _again(self, state: State, torque: np.ndarray, x_free: np.ndarray, report: StepReport) -> np.ndarray:
        """The step solved again with every point its detection found, into the same ``report`` (its
        certificates then count both solves): its answer reached a point it had left out as out of
        reach (a push elsewhere on that point's body)."""
        assert self.detector is not None  # only a step that detected leaves points out
        contacts = self.detector.contacts(self._found)
        return self.scheme.next_velocity(state, torque, x_free, contacts, report)

    def _advance(self, state: State, v_next: np.ndarray, report: StepReport) -> State:
        """The next state: q moved by dt v+ on each joint's manifold."""
        dt, bases = self.options.dt, self.dynamics.bases
        free = bases.untouched(report, report.impact) if self._rigid_bases else None
        moved = integrate(self.model, state.q, state.v, v_next, dt, self._scratch, bases, free)
        report.mark("integrate")
        if moved is None:
            raise SolverError(f"step at t={state.t:.6g} s produced a non-finite velocity", report)
        report.world, report.families = self.world, self._families
        self.last_step = report
        self._last_state = State.adopt(state.t + dt, *moved, self.world)  # both arrays are this step's own
        return self._last_state


# Where each joint type's configuration holds a unit vector: (offset in its q, size); a joint type
# whose nq exceeds its nv and is not listed here is refused (its q cannot be checked).
UNIT_PARTS = {
    "JointModelFreeFlyer": (3, 4),
    "JointModelSpherical": (0, 4),
    "JointModelPlanar": (2, 2),
    "JointModelRevoluteUnboundedUnaligned": (0, 2),
    **{f"JointModelRUB{axis}": (0, 2) for axis in "XYZ"},
}


def _unit_parts(model: pin.Model) -> list[tuple[slice, str]]:
    """(slice, what) of each joint whose configuration holds a unit quaternion or (cos, sin), told by
    the joint's type (a composite joint's parts each by theirs)."""
    parts = []
    for j in range(1, model.njoints):
        joint = model.joints[j]
        kinds = [joint]
        if joint.shortname() == "JointModelComposite":
            kinds = list(joint.extract().joints)
        start = joint.idx_q
        for kind in kinds:
            name = kind.shortname()
            if name in UNIT_PARTS:
                offset, size = UNIT_PARTS[name]
                what = "(cos, sin) pair" if size == 2 else "quaternion (x, y, z, w)"
                part = slice(start + offset, start + offset + size)
                message = f"q[{part.start}:{part.stop}] of joint '{model.names[j]}' must be a unit {what}"
                parts.append((part, message))
            elif kind.nq > kind.nv:
                raise InvalidRobot(
                    f"joint '{model.names[j]}' is a {name} (nq {kind.nq} > nv {kind.nv}), a type gaussim "
                    f"cannot check the configuration of; known: {', '.join(sorted(UNIT_PARTS))}"
                )
            start += kind.nq
    return parts


def within_limits(model: pin.Model, q: np.ndarray) -> tuple[np.ndarray, str]:
    """``q`` with its one-coordinate joints clamped into their position limits, and the joints it
    moved, listed with their values and limits ("" when none)."""
    one = [j for j in range(1, model.njoints) if model.joints[j].nq == 1]
    at = [model.joints[j].idx_q for j in one]
    lower, upper = model.lowerPositionLimit[at], model.upperPositionLimit[at]
    outside = [k for k in range(len(at)) if not lower[k] <= q[at[k]] <= upper[k]]
    clamped = q.copy()
    clamped[at] = np.clip(q[at], lower, upper)
    listed = ", ".join(
        f"'{model.names[one[k]]}' at {q[at[k]]:.4g} (limits {lower[k]:.4g}, {upper[k]:.4g})" for k in outside
    )
    return clamped, listed
