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

actuation (actuation.py): the torques per body, padded to nv, and implicit damping D as M + dt D.

acceleration scheme, the paper's:
    if v is not admissible (an impact): v = argmin 1/2 (w - v)^T M (w - v) over the impulse-level rows
    a  = argmin 1/2 a^T M a - a^T F  over the acceleration-level rows (second-order tangent sets)
    v+ = v + dt a;  q+ = q (+) dt v+
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pinocchio as pin

from .actuation import Actuation
from .assembly import assemble
from .collision import NO_CONTACTS, ContactDetector, Contacts
from .constraints import BilateralModule, ContactModule, LimitModule
from .constraints.base import ConstraintModule, Context, Level, Rows
from .dynamics import Dynamics, DynamicsStage
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


class Simulator:
    """Steps a scene with the Gauss principle; ``last_step`` holds the latest :class:`StepReport`."""

    def __init__(self, scene: Scene, options: Options | None = None) -> None:
        self.scene = scene
        self.options = options or Options()
        self.world = scene.world
        self.model = scene.robot.model.copy()
        self.model.gravity.linear = scene.gravity
        self.data = self.model.createData()
        self.actuation = Actuation(self.model, self.world, self.options.dt)
        self.dynamics = DynamicsStage(self.model, self.data)
        self.detector = ContactDetector(scene, self.options.contact_margin) if scene.pairs else None
        self.modules = self._modules(scene, self.options)
        # modules whose rows do not come from detected contacts: with one, every step poses the QP
        self._rows_without_contact = any(not isinstance(m, ContactModule) for m in self.modules)
        self.solvers: dict[Level, GaussSolver] = {
            level: GaussSolver(self.options) for level in ("velocity", "impulse", "acceleration")
        }
        self.last_step: StepReport | None = None
        self._last_state: State | None = None  # the state the last step returned: already valid
        self._rigid_bases = bool(self.dynamics.bases.rigid.any())
        self._scratch = np.zeros(
            self.model.nv
        )  # the step's displacement dt v+, read by Pinocchio's integrate
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
        full = self.actuation.torque(tau, damping, v).copy()
        if not np.all(np.isfinite(full)):
            raise InvalidState.non_finite("tau", full)
        return full

    # -- the step ---------------------------------------------------------------------------------

    def step(self, state: State, tau: object = None, damping: object = None) -> State:
        """Advance ``state`` by one time step under joint torques ``tau`` [N m] and return the new state.

        ``tau``: the world's (nv,), its actuated coordinates' (a floating robot's (nv - 6,)), or
        ``{body: tau_b}`` (see :mod:`.actuation`); ``damping`` D [N m s/rad], shaped alike and >= 0,
        is velocity feedback applied implicitly: the joints get tau - D v+ (stable at any time step).

        Raises:
            InvalidState: bad state or torque.
            InfeasibleConstraints: the constraints admit no motion (the rows involved are named).
            SolverError: ProxQP failed (see ``Options.on_failure``) or the result is not finite.
        """
        if state is not self._last_state:
            self._check_state(state)
            if self.detector:
                self.detector.forget()
        o = self.options
        given, tau = tau, self.actuation.torque(tau, damping, state.v)
        report = StepReport(state.t, o.timings)
        mark = report.mark
        acceleration = o.scheme == "acceleration"
        try:  # the dynamics check tau's entries, where they are read
            x_free = self.dynamics.free_motion(state.q, state.v, tau, o.dt, acceleration)
        except InvalidState:
            raise self.actuation.non_finite(given) from None
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
                self.dynamics.free_motion(
                    state.q, v, self.actuation.after_impact(tau, state.v, v), o.dt, True
                )
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
        report.world = self.world
        self.last_step = report
        self._last_state = State.adopt(state.t + o.dt, *moved, self.world)  # both arrays are this step's own
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
