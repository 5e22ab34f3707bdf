"""Numerical stability at the extremes: each case runs a setting and says whether it passed, and why.

The fast settings run with the test suite (tests/stress); ``long=True`` adds the long ones (small
time steps, long horizons). ``gaussim stability [--long] --report docs/stability.md`` writes the
table.
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from ..control import command
from ..exceptions import GaussimError, InfeasibleConstraints
from ..options import Options
from ..robot import Robot, load_robot
from ..scene import Anchor, Ground, Scene
from ..scenefile import load_scene
from ..simulator import Simulator
from .cases import BOX_HALF_HEIGHT, BOX_SIDE, SCENES_DIR, arm, rebound_apex, two_boxes

G = 9.81


@dataclass(frozen=True)
class Row:
    """One case at one setting: what was measured, and whether it meets the case's criterion."""

    case: str
    setting: str
    result: str
    passed: bool


def name(case: Callable[[], Row]) -> str:
    """A case's name: its function and settings, ``solo12_time_step(0.02, 'velocity')``."""
    return f"{case.func.__name__}({', '.join(map(repr, case.args[:2]))})"  # type: ignore[attr-defined]


def _guard(case: str, setting: str, body: Callable[[], Row]) -> Row:
    """A case that raises fails with the error as its result (the suite goes on)."""
    try:
        return body()
    except GaussimError as err:
        return Row(case, setting, f"{type(err).__name__}: {str(err)[:120]}", False)


def ball_time_step(dt: float, scheme: str) -> Row:
    """A ball dropped from 1 m onto the ground (e = 0.5), 2 s: finite, penetration below max(1 mm, two
    steps' travel at impact speed) (the acceleration scheme finds a contact once it is closed, up to
    a step late; the velocity scheme closes a gap within the step when the margin sees it coming)."""
    setting = f"dt = {dt:g}, {scheme}"

    def body() -> Row:
        ball = load_robot("ball", floating_base=True)
        radius = float(ball.collision_model.geometryObjects[0].geometry.radius)
        sim = Simulator(Scene(ball, ground=Ground(restitution=0.5)), Options(dt=dt, scheme=scheme))
        q = ball.neutral()
        q[2] = radius + 1.0
        state, lowest = sim.reset(q), np.inf
        for _ in range(round(2.0 / dt)):
            state = sim.step(state)
            lowest = min(lowest, state.q[2] - radius)
        bound = max(1e-3, 2 * np.sqrt(2 * G) * dt)
        passed = bool(np.isfinite(state.q).all()) and -lowest <= bound
        result = f"penetration {max(0.0, -lowest):.2e} m (bound {bound:.1e})"
        return Row("ball drop, time step", setting, result, passed)

    return _guard("ball drop, time step", setting, body)


def solo12_time_step(dt: float, scheme: str, seconds: float = 1.0) -> Row:
    """Solo-12 dropped 1 cm, standing under its (implicit) PD hold for ``seconds``: finite, feet
    penetration below max(1 mm, two steps' travel at the 0.44 m/s landing speed) (as for the ball),
    base height within 2 cm of where it settles at dt = 1e-3 (0.219 m)."""
    setting = f"dt = {dt:g}, {scheme}"

    def body() -> Row:
        spec = load_scene(SCENES_DIR / "solo12_standing.toml", dt=dt, scheme=scheme)
        sim = Simulator(spec.scene, spec.options)
        state, penetration = sim.reset(spec.initial.q, spec.initial.v), 0.0
        for _ in range(round(seconds / dt)):
            state = sim.step(state, *command(spec.controller(state)))
            report = sim.last_step
            assert report is not None
            penetration = max([penetration, *(-c.gap for c in report.contacts)])
        height, bound = state.q[2], max(1e-3, 2 * np.sqrt(2 * G * 0.01) * dt)
        passed = bool(np.isfinite(state.q).all()) and penetration < bound and abs(height - 0.219) < 0.02
        result = f"penetration {penetration:.2e} m (bound {bound:.1e}), base {height:.3f} m"
        return Row("Solo-12 standing, time step", setting, result, passed)

    return _guard("Solo-12 standing, time step", setting, body)


def fast_impact(speed: float, scheme: str, dt: float = 1e-3) -> Row:
    """A ball thrown down at ``speed`` onto the ground (e = 0): it must not tunnel (a half-space is
    found at any depth), its penetration stays below the travel of one step, and it rests on the
    ground within 1e-6 m after 1 s."""
    setting = f"{speed:g} m/s, dt = {dt:g}, {scheme}"

    def body() -> Row:
        ball = load_robot("ball", floating_base=True)
        radius = float(ball.collision_model.geometryObjects[0].geometry.radius)
        sim = Simulator(Scene(ball, ground=Ground()), Options(dt=dt, scheme=scheme))
        q = ball.neutral()
        q[2] = radius + 0.5
        state, lowest = sim.reset(q, np.array([0, 0, -speed, 0, 0, 0])), np.inf
        for _ in range(round(1.0 / dt)):
            state = sim.step(state)
            lowest = min(lowest, state.q[2] - radius)
        rest = state.q[2] - radius
        passed = -lowest <= speed * dt and abs(rest) < 1e-6
        result = f"penetration {max(0.0, -lowest):.2e} m, rest gap {rest:.1e} m"
        return Row("fast impact", setting, result, passed)

    return _guard("fast impact", setting, body)


def friction_extremes(mu: float) -> Row:
    """A 0.2 x 0.2 x 0.1 m block sliding at 1 m/s on ground of friction ``mu`` for 0.5 s, finite, and:
    below mu = 2 (where friction cannot tip it: half-width / half-height) no lift-off (1e-6 m) and the
    distance v^2 / (2 mu g) within 1 % (0.5 m travelled when frictionless); from mu = 2 on (it may
    tip) no energy gain: its centre never rises above v^2 / (2 g). ProxQP may stop at its cap on a step
    at mu = 1000 (seen on one step of 500, in 1 process of 8: runs differ across processes in
    round-off), so a step's non-convergence is reported (``on_failure="report"``) and counted, not
    fatal."""
    setting = f"mu = {mu:g}"

    def body() -> Row:
        box = load_robot("box", floating_base=True)
        sim = Simulator(Scene(box, ground=Ground(friction=mu)), Options(on_failure="report"))
        q = box.neutral()
        q[2] = BOX_HALF_HEIGHT
        state, lift, unconverged = sim.reset(q, np.array([1.0, 0, 0, 0, 0, 0])), 0.0, 0
        for _ in range(500):
            state = sim.step(state)
            lift = max(lift, abs(state.q[2] - BOX_HALF_HEIGHT))
            unconverged += not sim.last_step.converged  # type: ignore[union-attr]
        distance = state.q[0]
        expected = min(0.5, 1.0 / (2 * mu * G)) if mu > 0 else 0.5
        if mu < 2:
            passed = lift < 1e-6 and abs(distance / expected - 1) < 0.01
        else:
            passed = lift <= 1.0 / (2 * G)
        passed = passed and bool(np.isfinite(state.q).all())
        result = (
            f"distance {distance:.4g} m (v^2/(2 mu g) {expected:.4g}), largest rise {lift:.1e} m, "
            f"unconverged steps {unconverged}"
        )
        return Row("friction extremes", setting, result, passed)

    return _guard("friction extremes", setting, body)


def stack(ratio: float, heavy: str, seconds: float) -> Row:
    """Two 0.2 m cubes resting one on the other, masses 1 and ``ratio`` kg (``heavy`` on top or at the
    bottom): penetration below 1e-4 m at every step, the top box moves less than 1e-5 m after 1 s."""
    setting = f"ratio {ratio:g}, heavy {heavy}, {seconds:g} s"

    def body() -> Row:
        masses = (1.0, ratio) if heavy == "top" else (ratio, 1.0)
        with tempfile.TemporaryDirectory() as folder:
            robot = two_boxes(Path(folder) / "pair.urdf", *masses)
        contacts = [("bottom_0", "ground"), ("top_0", "bottom_0")]
        sim = Simulator(Scene(robot, ground=Ground(friction=0.8), contacts=contacts), Options())
        q = robot.neutral()
        q[2], q[9] = BOX_SIDE / 2, 1.5 * BOX_SIDE
        state, penetration, settled = sim.reset(q), 0.0, None
        for _ in range(round(seconds / 1e-3)):
            state = sim.step(state)
            penetration = max(penetration, BOX_SIDE / 2 - state.q[2], BOX_SIDE - (state.q[9] - state.q[2]))
            if settled is None and state.t >= 1.0:
                settled = state.q[9]
        sinking = abs(state.q[9] - settled) if settled is not None else 0.0
        passed = penetration < 1e-4 and sinking < 1e-5
        result = f"penetration {penetration:.1e} m, sinking {sinking:.1e} m"
        return Row("mass ratio stack", setting, result, passed)

    return _guard("mass ratio stack", setting, body)


def _resting_box() -> tuple[Robot, Simulator, np.ndarray]:
    """robots/box.urdf on the ground at the default options: (robot, simulator, its resting q)."""
    box = load_robot("box", floating_base=True)
    q = box.neutral()
    q[2] = BOX_HALF_HEIGHT
    return box, Simulator(Scene(box, ground=Ground()), Options()), q


def redundant_box(seconds: float = 2.0) -> Row:
    """A box resting flat on the ground (four coplanar corners, 12 force unknowns for 6 dofs): the
    report flags the forces as not unique, and they do not chatter: after 0.5 s no corner's normal
    force changes by more than 1 % of the weight from a step to the next, and their sum is the weight
    within 1e-6."""
    setting = f"{seconds:g} s"

    def body() -> Row:
        box, sim, q = _resting_box()
        state, weight = sim.reset(q), box.mass * G
        previous, jump, balance, flagged = None, 0.0, 0.0, True
        for _ in range(round(seconds / 1e-3)):
            state = sim.step(state)
            report = sim.last_step
            assert report is not None
            forces = np.array([c.normal_force for c in report.contacts])
            if state.t > 0.5:
                flagged = flagged and report.redundant
                balance = max(balance, abs(forces.sum() - weight) / weight)
                if previous is not None and len(previous) == len(forces):
                    jump = max(jump, float(np.abs(forces - previous).max()) / weight)
            previous = forces
        passed = flagged and jump < 0.01 and balance < 1e-6
        result = f"largest force jump {jump:.1e} mg, balance {balance:.1e}, flagged redundant: {flagged}"
        return Row("redundant contacts", setting, result, passed)

    return _guard("redundant contacts", setting, body)


def duplicate_loop(seconds: float = 1.0) -> Row:
    """The four-bar loop closure declared twice (rank-deficient equality rows): it runs, and the loop
    stays closed within 1e-6 m."""
    setting = f"{seconds:g} s, the loop declared twice"

    def body() -> Row:
        import pinocchio as pin

        spec = load_scene(SCENES_DIR / "fourbar.toml")
        loops = [*spec.scene.bilaterals, *spec.scene.bilaterals]
        sim = Simulator(Scene(spec.robot, bilaterals=loops, gravity=tuple(spec.scene.gravity)), spec.options)
        model, data = spec.robot.model, spec.robot.model.createData()
        tip, anchor = model.getFrameId("tip"), model.getFrameId("anchor")
        state, drift = sim.reset(spec.initial.q, spec.initial.v), 0.0
        for _ in range(round(seconds / sim.options.dt)):
            state = sim.step(state)
            pin.framesForwardKinematics(model, data, state.q)
            drift = max(
                drift, float(np.linalg.norm(data.oMf[tip].translation - data.oMf[anchor].translation))
            )
        return Row("duplicate constraints", setting, f"closure drift {drift:.1e} m", drift < 1e-6)

    return _guard("duplicate constraints", setting, body)


def elastic_bounce(dt: float = 1e-3) -> Row:
    """A ball dropped from 1 m onto ground of restitution 1: its first rebound reaches 1 m within
    2 |v_impact| dt (the impact is resolved up to a step early or late)."""
    setting = f"e = 1, dt = {dt:g}"

    def body() -> Row:
        ball = load_robot("ball", floating_base=True)
        radius = float(ball.collision_model.geometryObjects[0].geometry.radius)
        sim = Simulator(Scene(ball, ground=Ground(restitution=1.0)), Options(dt=dt))
        q = ball.neutral()
        q[2] = radius + 1.0
        apex = rebound_apex(sim.step, sim.reset(q), radius, 3.0)
        bound = 2 * np.sqrt(2 * G) * dt
        return Row(
            "restitution", setting, f"rebound {apex:.4f} m of 1 m (bound {bound:.1e})", abs(apex - 1) <= bound
        )

    return _guard("restitution", setting, body)


def long_pendulum(steps: int) -> Row:
    """A passive pendulum (1 m, 1 kg) released at 1 rad, ``steps`` steps of 1 ms: finite, its energy
    error bounded by omega dt (relative to m g l; semi-implicit Euler is symplectic: its energy
    oscillates by O(omega dt) and does not drift), and no drift: the largest gain over the last tenth
    of the run at most 10 % above that over the first tenth."""
    setting = f"{steps:g} steps"

    def body() -> Row:
        import pinocchio as pin

        robot = load_robot("pendulum")
        sim = Simulator(Scene(robot), Options())
        model, data = robot.model, robot.model.createData()

        def energy(s) -> float:  # type: ignore[no-untyped-def]
            kinetic = pin.computeKineticEnergy(model, data, s.q, s.v)
            return kinetic + pin.computePotentialEnergy(model, data, s.q)

        state = sim.reset(np.array([1.0]))
        start, scale = energy(state), pin.computeTotalMass(model) * G * 1.0
        tenth, first, last = steps // 10, -np.inf, -np.inf
        for k in range(steps):
            state = sim.step(state)
            if k % 100 == 0:
                gain = (energy(state) - start) / scale
                first = max(first, gain) if k < tenth else first
                last = max(last, gain) if k >= steps - tenth else last
        bound = np.sqrt(G / 1.0) * sim.options.dt
        worst = max(first, last)
        passed = bool(np.isfinite(state.q).all()) and worst <= bound and last <= 1.1 * max(first, 0.0) + 1e-12
        result = (
            f"energy gain {first:.2e} (first tenth), {last:.2e} (last tenth), bound {bound:.1e} (relative)"
        )
        return Row("long horizon: pendulum", setting, result, passed)

    return _guard("long horizon: pendulum", setting, body)


def long_resting_box(steps: int) -> Row:
    """A box resting on the ground, ``steps`` steps of 1 ms: it moves less than 1e-6 m."""
    setting = f"{steps:g} steps"

    def body() -> Row:
        _, sim, q = _resting_box()
        state = sim.reset(q)
        for _ in range(steps):
            state = sim.step(state)
        drift = float(np.linalg.norm(state.q[:3] - q[:3]))
        passed = bool(np.isfinite(state.q).all()) and drift < 1e-6
        return Row("long horizon: resting box", setting, f"drift {drift:.1e} m", passed)

    return _guard("long horizon: resting box", setting, body)


def _energy(robot: Robot) -> Callable[[np.ndarray, np.ndarray], float]:
    """The mechanical energy of ``robot`` at (q, v) [J] (kinetic plus potential)."""
    import pinocchio as pin

    model, data = robot.model, robot.model.createData()

    def energy(q: np.ndarray, v: np.ndarray) -> float:
        return pin.computeKineticEnergy(model, data, q, v) + pin.computePotentialEnergy(model, data, q)

    return energy


def arm_at_limit(ratio: float, seconds: float = 2.0) -> Row:
    """A two-link arm (0.5 m rods, the upper ``ratio`` kg, the lower 1 kg: a light link at the end of
    a heavy chain) released horizontal at full extension, its elbow pressed against its lower limit
    (0 rad) by gravity, then flung against it as it swings: finite, the elbow below its limit by
    less than 1e-6 rad at every step, no energy gain above omega dt (relative to the largest m g l;
    the limit is inelastic)."""
    setting = f"masses {ratio:g} : 1, {seconds:g} s"

    def body() -> Row:
        with tempfile.TemporaryDirectory() as folder:
            robot = arm(Path(folder) / "arm.urdf", (ratio, 1.0), (0.0, 2.5))
        sim = Simulator(Scene(robot, joint_limits=True), Options())
        energy = _energy(robot)
        state = sim.reset(np.array([np.pi / 2, 0.0]))
        start, scale = energy(state.q, state.v), (ratio + 1.0) * G
        violation, gain = 0.0, -np.inf
        for _ in range(round(seconds / sim.options.dt)):
            state = sim.step(state)
            violation = max(violation, -state.q[1])
            gain = max(gain, (energy(state.q, state.v) - start) / scale)
        bound = np.sqrt(G) * sim.options.dt
        passed = bool(np.isfinite(state.q).all() and violation < 1e-6 and gain <= bound)
        result = f"limit violation {violation:.1e} rad, energy gain {gain:.1e} (bound {bound:.1e}, relative)"
        return Row("arm against a limit", setting, result, passed)

    return _guard("arm against a limit", setting, body)


def spinning_pendulum(speed: float, seconds: float = 1.0) -> Row:
    """The pendulum of robots/scenes/pendulum_limits.toml launched at ``speed`` rad/s against its
    joint limit (0.5 rad, a radian travelled a step at 1000 rad/s): finite, the limit violated by less
    than 1e-6 rad, the energy never above the launch energy by more than the scheme's first-order
    error over the steps before the limit, |v| dt m g l (the limit is inelastic)."""
    setting = f"{speed:g} rad/s, dt = 0.001"

    def body() -> Row:
        spec = load_scene(SCENES_DIR / "pendulum_limits.toml")
        sim = Simulator(spec.scene, spec.options)
        upper = float(spec.robot.model.upperPositionLimit[0])
        energy = _energy(spec.robot)
        state = sim.reset(spec.initial.q, np.array([speed]))
        start, violation, gain = energy(state.q, state.v), 0.0, -np.inf
        for _ in range(round(seconds / sim.options.dt)):
            state = sim.step(state)
            violation = max(violation, state.q[0] - upper)
            gain = max(gain, energy(state.q, state.v) - start)
        bound = speed * sim.options.dt * spec.robot.mass * G * 1.0  # the rod is 1 m
        passed = bool(np.isfinite(state.q).all() and violation < 1e-6 and gain <= bound)
        result = f"limit violation {violation:.1e} rad, energy gain {gain:.2g} J (bound {bound:.2g} J)"
        return Row("large joint velocity", setting, result, passed)

    return _guard("large joint velocity", setting, body)


def talos_flat_feet(seconds: float = 1.0) -> Row:
    """Talos legs standing on flat feet (robots/scenes/talos_standing.toml: each sole touches at
    several points, more force unknowns than the motion fixes): after 0.5 s the report flags the
    forces as not unique, no normal force changes by more than 1 % of the weight from a step to the
    next (no chatter), and their sum is the weight within 1 %."""
    setting = f"{seconds:g} s"

    def body() -> Row:
        spec = load_scene(SCENES_DIR / "talos_standing.toml")
        sim = Simulator(spec.scene, spec.options)
        weight = spec.robot.mass * G
        state, previous, points = sim.reset(spec.initial.q, spec.initial.v), None, 0
        jump = balance = 0.0
        flagged = True
        for _ in range(round(seconds / sim.options.dt)):
            state = sim.step(state, *command(spec.controller(state)))
            report = sim.last_step
            assert report is not None
            forces = {c.name: c.normal_force for c in report.contacts}
            if state.t > 0.5:
                flagged = flagged and report.redundant
                points = max(points, len(forces))
                balance = max(balance, abs(sum(forces.values()) - weight) / weight)
                if previous is not None:
                    jump = max([jump, *(abs(f - previous.get(n, 0.0)) / weight for n, f in forces.items())])
            previous = forces
        passed = bool(np.isfinite(state.q).all()) and flagged and jump < 0.01 and balance < 0.01
        result = (
            f"{points} contact points, largest force jump {jump:.1e} mg, balance {balance:.1e}, "
            f"flagged redundant: {flagged}"
        )
        return Row("redundant contacts", f"Talos, both feet flat, {setting}", result, passed)

    return _guard("redundant contacts", f"Talos, both feet flat, {setting}", body)


def conflict(kind: str) -> Row:
    """Constraints that cannot hold together: a ball anchored 0.5 m below the ground it rests on
    (``anchor-ground``), or an arm whose tip is anchored where its elbow would be at 0.2 rad while the
    elbow's limits are [0.5, 1] rad (``limit-anchor``): the step raises InfeasibleConstraints naming
    both constraints."""
    setting = {
        "anchor-ground": "a ball anchored below the ground",
        "limit-anchor": "limits exclude the anchored pose",
    }[kind]

    def body() -> Row:
        if kind == "anchor-ground":
            robot = load_robot("ball", floating_base=True)
            scene = Scene(robot, ground=Ground(), bilaterals=[Anchor("ball", (0, 0, -0.5))])
            q = robot.neutral()
            q[2] = 0.1
            expected = ("contact", "anchor")
        else:
            import pinocchio as pin

            with tempfile.TemporaryDirectory() as folder:
                robot = arm(Path(folder) / "arm.urdf", (1.0, 1.0), (0.5, 1.0))
            data = robot.model.createData()
            pin.framesForwardKinematics(robot.model, data, np.array([0.0, 0.2]))
            target = data.oMf[robot.frame_id("tip")].translation.copy()
            scene = Scene(robot, joint_limits=True, bilaterals=[Anchor("tip", target)])
            q, expected = np.array([0.0, 0.5]), ("limit", "anchor")
        sim = Simulator(scene, Options())
        try:
            sim.step(sim.reset(q))
        except InfeasibleConstraints as err:
            named = [any(row.startswith(e) for row in err.rows) for e in expected]
            result = f"InfeasibleConstraints naming {sorted(set(row.split(' row ')[0] for row in err.rows))}"
            return Row("conflicting constraints", setting, result, all(named))
        return Row("conflicting constraints", setting, "the step returned a state", False)

    return _guard("conflicting constraints", setting, body)


def cases(long: bool = False) -> Iterator[Callable[[], Row]]:
    """The suite, fast settings first; ``long`` adds the long ones."""
    schemes = ("velocity", "acceleration")
    for scheme in schemes:
        for dt in (1e-4, 1e-3, 5e-3, 1e-2, 2e-2, 5e-2) + ((1e-5,) if long else ()):
            yield partial(ball_time_step, dt, scheme)
        for dt in (1e-3, 5e-3, 1e-2, 2e-2) + ((1e-4, 5e-2) if long else ()):
            yield partial(solo12_time_step, dt, scheme)
        for speed in (10.0, 50.0):
            yield partial(fast_impact, speed, scheme)
    for mu in (0.0, 1e-6, 10.0, 1e3):
        yield partial(friction_extremes, mu)
    yield partial(elastic_bounce)
    yield partial(redundant_box)
    yield partial(talos_flat_feet)
    yield partial(duplicate_loop)
    for kind in ("anchor-ground", "limit-anchor"):
        yield partial(conflict, kind)
    for ratio in (1.0, 1e4, 1e6):
        yield partial(arm_at_limit, ratio)
    for speed in (100.0, 1000.0):
        yield partial(spinning_pendulum, speed)
    for ratio in (1.0, 1e2, 1e4, 1e6):
        for heavy in ("top", "bottom"):
            yield partial(stack, ratio, heavy, 10.0)
    if long:
        yield partial(long_pendulum, 1_000_000)
        yield partial(long_resting_box, 1_000_000)


def largest_stable(rows: list[Row], case: str) -> dict[str, float]:
    """Per scheme, the largest time step at which ``case`` passed with every smaller one passing."""
    result: dict[str, float] = {}
    for scheme in ("velocity", "acceleration"):
        mine = sorted(
            (float(r.setting.split(",")[0].split("=")[1]), r.passed)
            for r in rows
            if r.case == case and r.setting.endswith(scheme)
        )
        stable = 0.0
        for dt, passed in mine:
            if not passed:
                break
            stable = dt
        result[scheme] = stable
    return result


def markdown(rows: list[Row], command: str) -> str:
    """The report: the largest stable time steps, then every row."""
    lines = [
        "# Stability at the extremes",
        "",
        f"Made by `{command}`. Each row is one run; its pass criterion is the docstring of its case in",
        "`gaussim.bench.stability`. A failing row stays in the table with what it measured.",
        "",
    ]
    for case in ("ball drop, time step", "Solo-12 standing, time step"):
        stable = largest_stable(rows, case)
        lines.append(f"- {case}: largest stable dt " + ", ".join(f"{s} {dt:g} s" for s, dt in stable.items()))
    lines += ["", "| case | setting | result | pass |", "|---|---|---|---|"]
    lines += [f"| {r.case} | {r.setting} | {r.result} | {'pass' if r.passed else 'FAIL'} |" for r in rows]
    return "\n".join(lines) + "\n"
