"""The simulator: a short ``step`` that reads as the algorithm.

velocity scheme (default), the discrete Gauss principle (Moreau-Jean time stepping):
    a_free = M^-1 (tau - b(q, v)) (ABA);  contacts = detect(q)
    v+ = argmin 1/2 (w - v_free)^T M (w - v_free)  over the velocity-level rows,  v_free = v + dt a_free
         (M from CRBA only when a module can produce rows; else v+ = v_free)
    q+ = q (+) dt v+

floating bases (dynamics.FloatingBases, integrator): the base's linear velocity is its origin's in the
    frame of the step's start, so a_free leaves out the frame's turn -w x v_l, and q+ = q (+) dt v+ moves
    the base on R3 x SO(3) (MuJoCo's free joint); a free rigid body's gyroscopic term is taken at the
    step's midpoint (in free flight it keeps energy and angular momentum exactly)

implicit damping D (``step(..., damping=D)``, e.g. a PD drive's kd + dt kp): the joints get tau - D v+,
    which is M + dt D in place of M and tau - D v in place of tau (Pinocchio's armature carries dt D
    through CRBA and ABA alike); stable at any dt, where explicit damping diverges once D dt exceeds
    about twice a joint's inertia.

acceleration scheme, the paper's:
    if v is not admissible (an impact): v = argmin 1/2 (w - v)^T M (w - v) over the impulse-level rows
    a  = argmin 1/2 a^T M a - a^T F  over the acceleration-level rows (second-order tangent sets)
    v+ = v + dt a;  q+ = q (+) dt v+
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from .assembly import assemble
from .collision import NO_CONTACTS, ContactDetector, Contacts
from .constraints import BilateralModule, ContactModule, LimitModule, checked_modules
from .constraints.base import ConstraintModule, Context, Level, Rows
from .dynamics import Dynamics, DynamicsStage, damped_torque, padded_torque
from .exceptions import InvalidState, SolverError
from .integrator import integrate
from .options import Options
from .report import StepReport
from .scene import Scene
from .solver import GaussSolver
from .state import State, real_array

# A velocity violating an impulse-level row by more than this is an impact [m/s or rad/s].
IMPACT_TOLERANCE = 1e-9
# How far from 1 the norm of a configuration's quaternion may be.
UNIT_TOLERANCE = 1e-6
_FLOAT = np.dtype(float)  # a torque of this dtype is read as given


class Simulator:
    """Steps a scene with the Gauss principle; ``last_step`` holds the latest :class:`StepReport`.

    ``constraints``: the user's constraint families (:class:`gaussim.constraints.ConstraintModule`),
    posed with the scene's own each step; their reactions are ``StepReport.reactions(name)``.
    """

    def __init__(
        self, scene: Scene, options: Options | None = None, *, constraints: Sequence[ConstraintModule] = ()
    ) -> None:
        self.scene = scene
        self.options = options or Options()
        self.model = scene.robot.model.copy()
        self.model.gravity.linear = scene.gravity
        self.data = self.model.createData()
        self.dynamics = DynamicsStage(self.model, self.data)
        self.detector = ContactDetector(scene, self.options.contact_margin) if scene.pairs else None
        self.modules = checked_modules(self._modules(scene, self.options), constraints)
        # modules whose rows do not come from detected contacts: with one, every step poses the QP
        self._rows_without_contact = any(not m.needs_contacts for m in self.modules)
        self.solvers: dict[Level, GaussSolver] = {
            level: GaussSolver(self.options) for level in ("velocity", "impulse", "acceleration")
        }
        self.last_step: StepReport | None = None
        self._floating = scene.robot.floating
        self._last_state: State | None = None  # the state the last step returned: already valid
        self._rigid_bases = bool(self.dynamics.bases.rigid.any())
        self._nv = self.model.nv  # read each step: a plain int, not a property of the Pinocchio model
        # the torque shapes a step takes: (nv,), and a floating robot's actuated joints' (nv - 6,)
        self._torque_shapes = {(self._nv,), (self._nv - 6,)} if self._floating else {(self._nv,)}
        self._no_torque = np.zeros(self._nv)
        self._scratch = np.zeros(self._nv)  # the step's displacement dt v+, read by Pinocchio's integrate
        self._no_torque.flags.writeable = False
        self._armature = self.model.armature.copy()  # the robot's own (rotor inertias)
        self._damping: np.ndarray | None = None  # the implicit damping D, (nv,), whose dt D is added to it
        # (slice, what) of each joint whose configuration ends with a unit quaternion or (cos, sin)
        self._unit_parts = []
        for j in range(1, self.model.njoints):
            joint = self.model.joints[j]
            if joint.nq > joint.nv:
                planar = any(k in joint.shortname() for k in ("RUB", "Planar"))
                what, size = ("(cos, sin) pair", 2) if planar else ("quaternion (x, y, z, w)", 4)
                part = slice(joint.idx_q + joint.nq - size, joint.idx_q + joint.nq)
                self._unit_parts.append(
                    (
                        part,
                        f"q[{part.start}:{part.stop}] of joint '{self.model.names[j]}' must be a unit {what}",
                    )
                )

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
        return modules

    # -- state handling ---------------------------------------------------------------------------

    def reset(self, q: np.ndarray | None = None, v: np.ndarray | None = None, t: float = 0.0) -> State:
        """A validated initial state (default: neutral configuration at rest)."""
        q = pin.neutral(self.model) if q is None else q
        v = np.zeros(self.model.nv) if v is None else v
        state = State(t, q, v)
        self._check_state(state)
        self._check_overlap(state)
        self.last_step = None
        return state

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

    def full_torque(
        self, tau: np.ndarray | None, damping: np.ndarray | None = None, v: np.ndarray | None = None
    ) -> np.ndarray:
        """The joint torques a step applies, shape (nv,): ``tau`` validated (zeros for None; a floating
        robot's actuated-joint torques (nv - 6,) are padded with zeros on the base), minus D v for an
        implicit damping D at the step's new velocity ``v``."""
        return self._torques(tau, damping, v)[0]

    def _torques(
        self, tau: np.ndarray | None, damping: np.ndarray | None, v: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray | None, bool]:
        """(tau - D v, D, whether D is the damping of the last step), validated and padded to (nv,);
        D is None without damping."""
        tau = self._shaped_torque(tau)
        if damping is None:
            full = padded_torque(tau, self._nv)
            if full is None:
                raise InvalidState.non_finite("tau", tau)
            return full, None, self._damping is None
        previous = self._no_torque[:0] if self._damping is None else self._damping
        code, full, D, same = damped_torque(tau, self._shaped_torque(damping, "damping"), v, previous)
        if code == 1:
            raise InvalidState.non_finite("tau", tau)
        if code == 2:
            raise InvalidState(f"damping must be finite and >= 0 [N m s/rad], got {damping}")
        return full, D, same

    def _shaped_torque(self, tau: np.ndarray | None, name: str = "tau") -> np.ndarray:
        """``tau`` as a float array of shape (nv,) or, for a floating robot, (nv - 6,) (zeros for None);
        its entries are checked by the dynamics stage, which reads them."""
        if tau is None:
            return self._no_torque
        tau = np.asarray(tau)
        if tau.dtype is not _FLOAT:  # ints, float32, or what is no torque at all (complex, text)
            tau = real_array(name, tau)
        if tau.shape not in self._torque_shapes:
            nv = self._nv
            hint = f" or ({nv - 6},) for the actuated joints" if self._floating else ""
            raise InvalidState(f"{name} must have shape ({nv},){hint}, got {tau.shape}")
        return tau

    def _damped_torque(self, tau: np.ndarray | None, damping: np.ndarray | None, v: np.ndarray) -> np.ndarray:
        """tau - D v, with dt D added to the model's armature, for the implicit damping D (see the
        module's docstring); without damping, ``tau`` shaped, and the robot's own armature."""
        if damping is None:
            if self._damping is not None:
                self.model.armature = self._armature
                self._damping = None
            return self._shaped_torque(tau)
        full, D, same = self._torques(tau, damping, v)
        if not same:
            assert D is not None
            self.model.armature = self._armature + self.options.dt * D
            self._damping = D
        return full

    # -- the step ---------------------------------------------------------------------------------

    def step(self, state: State, tau: np.ndarray | None = None, damping: np.ndarray | None = None) -> State:
        """Advance ``state`` by one time step under joint torques ``tau`` [N m], shape (nv,) (or, for a
        floating robot, (nv - 6,): the actuated joints'); return the new state.

        ``damping`` D [N m s/rad], shaped as ``tau`` and >= 0, is velocity feedback applied implicitly:
        the joints get tau - D v+, with v+ the new velocity (stable at any time step).

        Raises:
            InvalidState: bad state or torque.
            InfeasibleConstraints: the constraints admit no motion (the rows involved are named).
            SolverError: ProxQP failed (see ``Options.on_failure``) or the result is not finite.
        """
        if state is not self._last_state:
            self._check_state(state)
            if self.detector:
                self.detector.forget()
        if damping is None and self._damping is None:  # the common case, one call
            tau = self._shaped_torque(tau)
        else:
            tau = self._damped_torque(tau, damping, state.v)
        o = self.options
        report = StepReport(state.t, o.timings)
        mark = report.mark
        acceleration = o.scheme == "acceleration"
        x_free = self.dynamics.free_motion(state.q, state.v, tau, o.dt, acceleration)
        mark("dynamics")
        contacts = NO_CONTACTS
        if self.detector:  # it looks when the step's motion may have brought a pair within its margin
            if self.detector.cover(state.v, x_free, o.dt, o.dt if acceleration else 1.0, self.dynamics.reach):
                contacts = self.detector.detect(self.data)
            mark("collision")
        if acceleration:
            dyn = self.dynamics.problem()
            v = self._impact(state, dyn.M, contacts, report)
            if v is not state.v:  # the damping acts on the velocity after the impact
                damped = tau if self._damping is None else tau - self._damping * (v - state.v)
                self.dynamics.free_motion(state.q, v, damped, o.dt, True)
                dyn = self.dynamics.problem()
            v_next = v + o.dt * self._gauss("acceleration", state.q, v, dyn, contacts, report, 1.0)
        elif len(contacts.gap) or self._rows_without_contact:
            v_next = self._gauss(
                "velocity", state.q, state.v, self._problem(report), contacts, report, 1 / o.dt
            )
        else:  # nothing can restrict the motion: no Gauss problem to pose
            v_next = x_free
        bases = self.dynamics.bases
        free = bases.untouched(report, report.impact) if self._rigid_bases else None
        moved = integrate(self.model, state.q, state.v, v_next, o.dt, self._scratch, bases, free)
        mark("integrate")
        if moved is None:
            raise SolverError(f"step at t={state.t:.6g} s produced a non-finite velocity", report)
        self.last_step = report
        self._last_state = State.adopt(state.t + o.dt, *moved)  # both arrays are this step's own
        return self._last_state

    def _problem(self, report: StepReport) -> Dynamics:
        """The step's free Gauss problem (its CRBA, when the free motion skipped it, timed as dynamics)."""
        report.mark("")
        dyn = self.dynamics.problem()
        report.mark("dynamics")
        return dyn

    def _impact(self, state: State, M: np.ndarray, contacts: Contacts, report: StepReport) -> np.ndarray:
        """The impulsive Gauss projection of v while v violates an impulse-level row, else v itself.

        A projection can set a contact it did not hold approaching (a ball struck towards the next one,
        within a step): it is projected again, so no approach faster than ``restitution_threshold`` is
        left to the acceleration level's Baumgarte rows, which stopped it plastically (slower ones are
        inelastic, and a projection's own rows are met only to the QP's tolerance). Each projection's
        impulses are in ``report.impact``, the next ones in its own ``impact``."""
        v, last, tolerance = state.v, report, IMPACT_TOLERANCE
        for _ in range(len(contacts.gap) + 1):  # each projection makes a contact separate, or ends
            ctx = self._context("impulse", state.q, v, v, contacts)
            parts = self._rows(ctx)
            if not any(np.any(rows.J @ v < rows.bound - tolerance) for _, rows in parts if not rows.equality):
                break
            tolerance = max(IMPACT_TOLERANCE, self.options.restitution_threshold)
            last.impact = StepReport(state.t, report.timed)
            last = last.impact
            v = self._solve(ctx, M, -(M @ v), parts, last, 1.0)
            report.certificates += last.certificates
        return v

    def _gauss(
        self,
        level: Level,
        q: np.ndarray,
        v: np.ndarray,
        dyn: Dynamics,
        contacts: Contacts,
        report: StepReport,
        scale: float,
    ) -> np.ndarray:
        """Minimise the Gauss functional of ``level`` (``dyn``'s free problem over the constraints' rows);
        record the reactions in ``report``."""
        ctx = self._context(level, q, v, dyn.x_free, contacts)
        return self._solve(ctx, dyn.M, dyn.g, None, report, scale)

    def _context(
        self, level: Level, q: np.ndarray, v: np.ndarray, x_free: np.ndarray, contacts: Contacts
    ) -> Context:
        return Context(self.model, self.data, q, v, x_free, contacts, self.options, level)

    def _rows(self, ctx: Context) -> list[tuple[ConstraintModule, Rows]]:
        parts = [(module, module.rows(ctx)) for module in self.modules]
        return [(module, rows) for module, rows in parts if rows is not None]

    def _solve(
        self,
        ctx: Context,
        M: np.ndarray,
        g: np.ndarray,
        parts: list[tuple[ConstraintModule, Rows]] | None,
        report: StepReport,
        scale: float,
    ) -> np.ndarray:
        """Solve, re-posing the rows while a module's fixed-point iteration asks for it."""
        mark = report.mark
        for _ in range(self.options.friction_iterations):
            mark("")
            parts = self._rows(ctx) if parts is None else parts
            if not parts:
                mark("assembly")
                return ctx.x_free
            problem = assemble(M, g, parts)
            mark("assembly")
            solution = self.solvers[ctx.level].solve(problem)
            mark("solve")
            report.certificates += (solution.certificate,)
            x, lam = solution.x, solution.multipliers
            blocks = [(module, rows, lam[part]) for module, rows, part in problem.blocks]
            refine = False
            for module, rows, multipliers in blocks:
                refine |= module.refine(ctx, rows, x, multipliers)
            if not refine:
                break
            parts = None
        report.blocks, report.scale = blocks, scale
        mark("")
        return x
