"""Simulation options, validated once at construction."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields

from .exceptions import InvalidOptions, shown

SCHEMES = ("velocity", "acceleration")
FRICTION_MODES = ("pyramid", "accurate", "exact")
ON_FAILURE = ("raise", "report")
SOLVERS = ("dual", "daqp", "proxqp")
# Upper bounds of the integer options: ProxQP's max_iter is a C int; more facets or fixed-point QPs than
# these only cost time (a 64-facet pyramid is within 0.12 % of the cone)
MAXIMA = {"max_iter": 2**31 - 1, "friction_facets": 64, "friction_iterations": 1000}
# A duration within this fraction of a whole number of steps is that number of steps (round-off of
# decimal durations and steps: 0.3 / 1e-3 is 299.99999999999994)
DURATION_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Options:
    """How a scene is stepped: the speed/accuracy knobs.

    Attributes:
        dt: time step [s].
        scheme: ``"velocity"`` (discrete Gauss principle on v+, Moreau-Jean time stepping; default)
            or ``"acceleration"`` (the paper's scheme: Gauss principle on a over the active set,
            impulsive projection at impacts, Baumgarte stabilisation).
        friction_facets: number k of facets of the pyramid approximating the Coulomb cone (3 to 64).
        friction_mode: ``"pyramid"`` (Anitescu's convex relaxation, MuJoCo's: one QP whose contact
            velocity lies in the dual of the pyramid, so a sliding contact leaves the ground at the
            normal speed mu |slip| (on a facet direction; down to cos(pi/k) of that between facets) and
            flies ballistically: a box sliding at v0 hops (mu v0 / (1 + mu^2))^2 / (2 g), 32.6 mm at
            2 m/s and mu = 0.5, whatever dt), ``"accurate"`` (default: the pyramid is turned against the free
            tangential velocity and its normal bound shifted by mu |slip| of the current velocity, the
            one-step De Saxce correction: no lift-off, no pyramid anisotropy while sliding) or
            ``"exact"`` (the De Saxce shift iterated to a fixed point within the step).
        friction_iterations: maximal number of QPs per step for ``"exact"`` friction and for sliding
            contacts of the acceleration scheme.
        restitution_threshold: impacts slower than this normal speed are treated as inelastic [m/s]
            (prevents micro-bouncing of resting contacts when restitution > 0).
        stabilisation: fraction in (0, 1] of a constraint violation (penetration, limit overshoot,
            bilateral drift) removed per step; the acceleration scheme uses it as a critically
            damped Baumgarte term with time constant dt / stabilisation.
        contact_margin: pairs closer than this distance produce contact rows [m]; the velocity
            scheme lets an approaching contact close exactly, so a margin of a few |v| dt suffices.
        limit_margin: joint limits closer than this produce rows [rad or m], plus the distance the
            joint can travel in one step.
        active_tolerance: acceleration scheme: a gap below this is an active contact [m].
        solver: ``"dual"`` (default): each QP that the previous solution's active set does not answer
            is solved by gaussim's dual active-set method on sparse rows (:mod:`gaussim.solver.dual`),
            which drops the dependent rows of contact pyramids (a pile's island: a tenth of ProxQP's
            time), and by ProxQP when its answer fails the KKT check; ``"daqp"``: the same with DAQP's
            dual active-set method on dense rows; ``"proxqp"``: by ProxQP alone. The acceleration
            scheme solves with ProxQP either way (its sliding friction is a fixed point on the normal
            forces, which a dual active-set method's answers split unevenly over redundant contacts).
        eps_abs: the solvers' absolute tolerance on primal/dual residuals and duality gap (the KKT
            check accepts a relative residual of 100 eps_abs).
        max_iter: ProxQP's cap on its outer iterations for a solve from a cold start; a warm-started
            solve gets at most WARM_START_ITERATIONS of them (gaussim.solver.proxqp) before gaussim
            solves again from a cold start. Normal solves need far fewer (a few hundred at most); a
            point reached at the cap is accepted when the KKT check certifies it.
        on_failure: ``"raise"`` (default) a :class:`SolverError` when ProxQP does not converge, or
            ``"report"`` (accept the finite iterate and record the status). A non-finite solution
            or an infeasible constraint set always raises.
        start_penetration: how deep a pair may overlap at :meth:`Simulator.reset` [m]: a deeper start
            is an error naming the pair (the step would push it out at once: kN forces, a body thrown
            up); raise it to start so all the same.
        timings: record each step's wall time per stage in ``StepReport.timings`` (profiling; off by
            default: a mark per stage is a noticeable part of a free-flight step's cost).
    """

    dt: float = 1e-3
    scheme: str = "velocity"
    friction_facets: int = 4
    friction_mode: str = "accurate"
    friction_iterations: int = 10
    restitution_threshold: float = 1e-2
    stabilisation: float = 0.2
    contact_margin: float = 5e-3
    limit_margin: float = 1e-2
    active_tolerance: float = 1e-6
    solver: str = "dual"
    eps_abs: float = 1e-9
    max_iter: int = 1000
    on_failure: str = "raise"
    start_penetration: float = 1e-3
    timings: bool = False

    def __new__(cls, *args: object, **given: object) -> Options:
        # an unknown keyword, named with the valid ones (the dataclass's own __init__ raises a bare TypeError)
        known = {f.name for f in fields(cls)}
        for key in given:
            if key not in known:
                raise InvalidOptions(key, f"unknown option; known: {', '.join(sorted(known))}")
        return super().__new__(cls)

    def __post_init__(self) -> None:
        for f in fields(self):  # numpy scalars in, Python's out (they go to JSON in run logs)
            value = getattr(self, f.name)
            if isinstance(value, numbers.Integral) and not isinstance(value, bool) and f.type == "int":
                object.__setattr__(self, f.name, int(value))
            elif is_real(value) and f.type == "float":
                object.__setattr__(self, f.name, float(value))  # type: ignore[arg-type]
        _positive("dt", self.dt)
        _choice("scheme", self.scheme, SCHEMES)
        _choice("friction_mode", self.friction_mode, FRICTION_MODES)
        _choice("on_failure", self.on_failure, ON_FAILURE)
        _choice("solver", self.solver, SOLVERS)
        _integer("friction_facets", self.friction_facets, minimum=3)
        _integer("friction_iterations", self.friction_iterations, minimum=1)
        _integer("max_iter", self.max_iter, minimum=1)
        _positive("eps_abs", self.eps_abs)
        _positive("contact_margin", self.contact_margin)
        _positive("active_tolerance", self.active_tolerance)
        _non_negative("restitution_threshold", self.restitution_threshold)
        _non_negative("limit_margin", self.limit_margin)
        _non_negative("start_penetration", self.start_penetration)
        if not isinstance(self.timings, bool):
            raise InvalidOptions("timings", f"must be True or False, got {shown(self.timings)}")
        if not (is_real(self.stabilisation) and 0.0 < self.stabilisation <= 1.0):
            raise InvalidOptions("stabilisation", f"must be in (0, 1], got {shown(self.stabilisation)}")

    def steps(self, duration: float) -> int:
        """The number of steps a run of ``duration`` [s] takes: the nearest whole number, at least one."""
        return max(1, round(duration / self.dt))

    def duration_note(self, duration: float) -> str | None:
        """What a run of ``duration`` [s] simulates instead, when that is not ``duration`` (a duration
        shorter than one step, or not a whole number of steps); None when it is."""
        steps = self.steps(duration)
        simulated = steps * self.dt
        if abs(simulated - duration) <= DURATION_TOLERANCE * duration:
            return None
        why = "shorter than one step" if duration < self.dt else "not a whole number of steps"
        return (
            f"the duration {duration:g} s is {why} of dt = {self.dt:g} s: the run takes {steps} "
            f"step{'s' if steps > 1 else ''}, {simulated:g} s (make the duration a multiple of dt)"
        )

    def replace(self, **changes: object) -> Options:
        """Return a copy with some fields changed (validated again)."""
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        values.update(changes)
        return Options(**values)  # type: ignore[arg-type]


def is_real(value: object) -> bool:
    """True for a finite int or float, numpy's too (not a bool, nor an int beyond any float)."""
    if not isinstance(value, numbers.Real) or isinstance(value, bool):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:  # a TOML integer of 400 digits
        return False


def _positive(field: str, value: object) -> None:
    if not (is_real(value) and value > 0):  # type: ignore[operator]
        raise InvalidOptions(field, f"must be a finite number > 0, got {shown(value)}")


def _non_negative(field: str, value: object) -> None:
    if not (is_real(value) and value >= 0):  # type: ignore[operator]
        raise InvalidOptions(field, f"must be a finite number >= 0, got {shown(value)}")


def _integer(field: str, value: object, minimum: int) -> None:
    maximum = MAXIMA[field]
    if not (isinstance(value, int) and not isinstance(value, bool) and minimum <= value <= maximum):
        raise InvalidOptions(field, f"must be an integer in [{minimum}, {maximum}], got {shown(value)}")


def _choice(field: str, value: object, choices: tuple[str, ...]) -> None:
    if not (isinstance(value, str) and value in choices):
        raise InvalidOptions(field, f"{shown(value)} is not one of {', '.join(choices)}")
