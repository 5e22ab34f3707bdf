"""Matched accuracy on motion: dynamic tasks with a converged reference, and for each engine the
cheapest setting whose trajectory meets 1 mm and 1 cm.

A task's trajectory is the world position of every body (each Pinocchio joint's origin: a free
body's centre, a robot's every link) sampled every SAMPLE seconds; its error is the RMS over the
samples and bodies of the distance to the reference's. The reference is the closed form where one
exists (a ball rolling down an incline without slipping: a = 5/7 g sin(theta)), else each engine's
own run at its smallest step and tightest solver settings (:data:`REFERENCE`). Each engine sweeps
its time step and its solver's tolerance (gaussim: ProxQP's ``eps_abs``; MuJoCo: Newton's
``tolerance`` and ``iterations``); its cost is the wall time of its steps alone per simulated second.
MuJoCo runs the model :func:`gaussim.bench.scenes.mjcf` generates from the gaussim scene.

Run it with ``gaussim bench --motion [--quick]`` or ``python benchmarks/motion.py``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..kernels import prebuild as kernels
from ..options import Options
from ..scene import Ground, Scene
from ..simulator import Simulator
from ..world import FreeBody, pose
from .peers import MuJoCo, available
from .scenes import BOX, BOX_MASS, FRICTION, Setup, boxes, standing

G = 9.81
SAMPLE = 0.02  # [s] the trajectories' sampling period (a multiple of every swept dt)
TOLERANCES = (1e-3, 1e-2)  # [m] the RMS position errors each engine must meet
INCLINE, BALL = np.radians(20.0), 0.05  # the incline [rad] and the ball's radius [m]
DROP = 0.3  # [m] Solo-12's drop

Setting = Mapping[str, float | str]  # Options fields (dt, eps_abs, friction_mode), or MuJoCo's knobs


@dataclass(frozen=True)
class Task:
    """A dynamic task: ``build(dt) -> Setup``, its duration [s] (``quick`` its shorter one) and, where
    one exists, the closed-form trajectory ``exact(times) -> (samples, bodies, 3)``."""

    name: str
    about: str
    build: Callable[[float], Setup]
    duration: float
    quick: float
    exact: Callable[[np.ndarray], np.ndarray] | None = None


def tossed_box(dt: float) -> Setup:
    """A box (BOX, BOX_MASS) thrown from 0.3 m at (1, 0, 1) m/s spinning at (4, 6, 0) rad/s onto the
    ground (friction FRICTION): it bounces on its corners, tumbles and comes to rest."""
    scene = Scene(
        bodies={"box": FreeBody.box("box", (BOX,) * 3, mass=BOX_MASS)}, ground=Ground(friction=FRICTION)
    )
    q = pin.SE3ToXYZQUAT(pose(z=0.3, rpy=(0.3, 0.2, 0.0)))
    return Setup(scene, q, np.array([1.0, 0.0, 1.0, 4.0, 6.0, 0.0]), dt=dt)


def _downhill() -> np.ndarray:
    return np.array([-np.cos(INCLINE), 0.0, -np.sin(INCLINE)])


def rolling_ball(dt: float) -> Setup:
    """A ball (BALL, 1 kg) released at rest on an incline of INCLINE (friction 0.8, more than the
    2/7 tan(theta) rolling needs), touching it."""
    normal = np.array([-np.sin(INCLINE), 0.0, np.cos(INCLINE)])
    ball = FreeBody.sphere("ball", BALL, mass=1.0)
    scene = Scene(bodies={"ball": ball}, ground=Ground(friction=FRICTION, normal=tuple(normal)))
    q = np.concatenate([BALL * normal, [0.0, 0.0, 0.0, 1.0]])
    return Setup(scene, q, np.zeros(6), dt=dt)


def rolling_exact(times: np.ndarray) -> np.ndarray:
    """The ball's centre (samples, 1, 3) rolling without slipping: s = 5/14 g sin(theta) t^2."""
    start = BALL * np.array([-np.sin(INCLINE), 0.0, np.cos(INCLINE)])
    s = 5 / 14 * G * np.sin(INCLINE) * times**2
    return (start + s[:, None] * _downhill())[:, None, :]


def solo_drop(dt: float) -> Setup:
    """Solo-12 dropped from DROP above its standing height onto its four feet, landing into its PD
    stance (robots/scenes/solo12_standing.toml's hold)."""
    setup = standing("solo12_standing")(dt)
    setup.q[2] += DROP
    return setup


def settling_pile(dt: float) -> Setup:
    """Four boxes in 2-high columns released 1 cm apart (from the ground and each other), tilted a
    little, settling into a pile."""
    setup = boxes(4)
    q = setup.q.copy()
    for k, layout in enumerate(setup.scene.bodies.values()):
        level = k % 2
        tilt = pin.Quaternion(pin.rpy.rpyToMatrix(0.05 * (-1) ** k, 0.04, 0.03 * k)).coeffs()
        part = q[layout.q]  # a view
        part[2] += 0.01 * (level + 1)
        part[3:7] = tilt
    return dataclasses.replace(setup, q=q, dt=dt)


TASKS: dict[str, Task] = {
    task.name: task
    for task in [
        Task("tossed_box", "a box tossed onto the ground, tumbling to rest", tossed_box, 1.5, 0.6),
        Task(
            "rolling_ball",
            "a ball rolling down a 20 deg incline (closed form)",
            rolling_ball,
            1.0,
            0.5,
            rolling_exact,
        ),
        Task("solo12_drop", "Solo-12 dropped from 0.3 m, landing into its PD stance", solo_drop, 1.0, 0.5),
        Task("pile_settling", "four boxes released 1 cm apart settling", settling_pile, 1.0, 0.4),
    ]
}
SCENES = TASKS  # the name ``gaussim bench`` lists

# each engine's sweep and its reference (its smallest step, tightest settings)
GAUSSIM_SETTINGS: dict[str, Setting] = {
    **{f"dt={dt:g}": {"dt": dt} for dt in (2e-2, 1e-2, 5e-3, 2e-3, 1e-3, 5e-4)},
    **{f"dt={dt:g} eps_abs=1e-4": {"dt": dt, "eps_abs": 1e-4} for dt in (1e-2, 5e-3, 2e-3, 1e-3)},
    # MuJoCo's own friction model (its default pyramidal cone): one QP a step, no De Saxce passes;
    # its error is still taken against gaussim's reference in the accurate mode
    **{
        f"dt={dt:g} eps_abs=1e-4 pyramid": {"dt": dt, "eps_abs": 1e-4, "friction_mode": "pyramid"}
        for dt in (1e-2, 5e-3, 2e-3, 1e-3)
    },
}
MUJOCO_SETTINGS: dict[str, Setting] = {
    **{f"dt={dt:g}": {"dt": dt} for dt in (2e-2, 1e-2, 5e-3, 2e-3, 1e-3, 5e-4)},
    **{
        f"dt={dt:g} tolerance=1e-4 iterations=10": {"dt": dt, "tolerance": 1e-4, "iterations": 10}
        for dt in (1e-2, 5e-3, 2e-3, 1e-3)
    },
}
QUICK_SETTINGS = ("dt=0.005", "dt=0.002", "dt=0.001")
REFERENCE = {
    "gaussim": {"dt": 1e-4, "eps_abs": 1e-10},
    "mujoco": {"dt": 1e-4, "tolerance": 1e-12, "iterations": 1000},
}
QUICK_REFERENCE_DT = 2.5e-4
# A setting's wall time is the least of this many runs (one with --quick): a run sums its steps, and
# one step slowed by the machine moved a whole run's figure by a third.
REPEATS = 3


def positions(model: pin.Model, data: pin.Data, q: np.ndarray) -> np.ndarray:
    """Every joint's origin in the world (njoints - 1, 3) [m]."""
    pin.forwardKinematics(model, data, q)
    return np.array([data.oMi[j].translation for j in range(1, model.njoints)])


def trajectory(engine: str, task: Task, setting: Setting, duration: float) -> tuple[np.ndarray, float]:
    """(every body's position at each SAMPLE (samples, bodies, 3) [m], the wall time of the steps per
    simulated second [s]) of ``engine`` on ``task`` at ``setting``."""
    dt = float(setting["dt"])
    setup = task.build(dt)
    model = setup.scene.robot.model
    data = model.createData()
    every, steps = round(SAMPLE / dt), round(duration / dt)
    samples, wall = [], 0.0
    if engine == "gaussim":
        knobs = {k: v for k, v in setting.items() if k != "dt"}
        sim = Simulator(setup.scene, Options(dt=dt, **knobs))  # type: ignore[arg-type]
        state = sim.reset(setup.q, setup.v)
        for k in range(1, steps + 1):
            tau = setup.drive(state.t, state.q, state.v) if setup.drive else None
            tic = time.perf_counter()
            state = sim.step(state, tau, setup.damping)
            wall += time.perf_counter() - tic
            if k % every == 0:
                samples.append(positions(model, data, state.q))
    else:
        peer = MuJoCo(setup)
        if "tolerance" in setting:
            peer.model.opt.tolerance = float(setting["tolerance"])
        if "iterations" in setting:
            peer.model.opt.iterations = int(setting["iterations"])
        for k in range(1, steps + 1):
            if setup.drive:
                peer.apply(setup.drive(peer.data.time, *peer.state()))
            tic = time.perf_counter()
            peer.step()
            wall += time.perf_counter() - tic
            if k % every == 0:
                samples.append(positions(model, data, peer.state()[0]))
    return np.array(samples), wall / duration


def rms(a: np.ndarray, b: np.ndarray) -> float:
    """The RMS over samples and bodies of the distance between two trajectories [m]."""
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=-1))))


def run_task(task: Task, quick: bool, engines: Iterable[str], progress: Callable[[str], None] | None) -> dict:
    """Every engine's sweep of ``task`` against its reference: per engine and setting the error [m]
    and the wall time per simulated second [s]."""
    duration = task.quick if quick else task.duration
    times = SAMPLE * np.arange(1, round(duration / SAMPLE) + 1)
    result: dict = {"task": task.name, "about": task.about, "duration": duration, "engines": {}}
    for engine in engines:
        sweep = GAUSSIM_SETTINGS if engine == "gaussim" else MUJOCO_SETTINGS
        labels = QUICK_SETTINGS if quick else tuple(sweep)
        trajectory(engine, task, sweep[labels[0]], 10 * SAMPLE)  # untimed: numba compiles on first use
        if task.exact is not None:
            reference, against = task.exact(times), "closed form"
        else:
            tight = dict(REFERENCE[engine], **({"dt": QUICK_REFERENCE_DT} if quick else {}))
            if progress:
                progress(f"  {task.name}: {engine} reference (dt={tight['dt']:g}) ...")
            reference, against = trajectory(engine, task, tight, duration)[0], f"own, dt={tight['dt']:g}"
        runs = {}
        for label in labels:
            path, wall = trajectory(engine, task, sweep[label], duration)
            for _ in range(0 if quick else REPEATS - 1):
                wall = min(wall, trajectory(engine, task, sweep[label], duration)[1])
            runs[label] = {"error": rms(path, reference), "wall_per_sim_s": wall}
            if progress:
                progress(
                    f"  {task.name}: {engine} {label}: error {runs[label]['error']:.2e} m, {wall:.3f} s/s"
                )
        result["engines"][engine] = {"reference": against, "runs": runs}
    return result


def cheapest(runs: dict[str, dict], tolerance: float) -> tuple[str, dict] | None:
    """The least wall time per simulated second among ``runs`` whose error meets ``tolerance``."""
    meeting = [(label, r) for label, r in runs.items() if r["error"] <= tolerance]
    return min(meeting, key=lambda item: item[1]["wall_per_sim_s"]) if meeting else None


def run_suite(
    names: Iterable[str] | None = None,
    quick: bool = False,
    peers: Iterable[str] | None = None,
    progress: Callable[[str], None] | None = None,
) -> list[dict]:
    """Run the tasks (default: all) with gaussim and MuJoCo (when installed; ``peers=[]``: gaussim
    only); ``quick``: shorter runs, three time steps, a coarser reference."""
    chosen = list(names or TASKS)
    unknown = sorted(set(chosen) - set(TASKS))
    if unknown:
        raise ValueError(f"unknown tasks {unknown}; known: {', '.join(TASKS)}")
    if peers is None:
        peers = ["mujoco"] if any(p.startswith("mujoco") for p in available()) else []
    # every kernel loaded now: a run sums its steps' wall time, and the first step to call a kernel
    # would pay its load from numba's cache (Solo-12's landing at dt 20 ms: 0.1 s, twenty times its run)
    kernels.load()
    records = []
    for k, name in enumerate(chosen, start=1):
        if progress:
            progress(f"[{k}/{len(chosen)}] {name}: {TASKS[name].about}")
        records.append(run_task(TASKS[name], quick, ["gaussim", *peers], progress))
    return records


TITLE = "Matched accuracy on motion"
INTRO = f"""Dynamic tasks with a converged reference: a box tossed onto the ground tumbling to rest, a ball
rolling down a 20 deg incline (against the closed form of rolling without slipping, a = 5/7 g
sin(theta)), Solo-12 dropped from 0.3 m landing into its PD stance, four boxes settling into a pile.
The error is the RMS over the run (sampled every {SAMPLE * 1e3:g} ms) of the distance of every body
(each joint's origin: a free body's centre, each of a robot's links) to the reference: the closed
form, else the engine's own run at dt 0.1 ms (0.25 ms with `--quick`) and its tightest solver settings
(gaussim eps_abs 1e-10; MuJoCo tolerance 1e-12, 1000 iterations). Each engine sweeps its time step
(20 ms to 0.5 ms; 5 to 1 ms with `--quick`) and its solver tolerance, gaussim also its friction model
(`friction_mode="pyramid"`, MuJoCo's own pyramidal cone, its error still taken against gaussim's
reference in the accurate mode; `gaussim.bench.motion`); the
row is its cheapest setting (wall time of its steps per simulated second, the least of {REPEATS} runs)
that meets the tolerance, and that time's ratio to gaussim's cheapest."""


def markdown(records: list[dict]) -> str:
    """The matched-accuracy table: per task, tolerance and engine, the cheapest setting that meets it,
    its error, its wall time per simulated second and that time's ratio to gaussim's."""
    lines = [
        "| task | RMS tolerance | engine | reference | cheapest setting that meets it | error [m] "
        "| wall per sim s [s] | time ratio to gaussim |",
        "|---|---:|---|---|---|---:|---:|---:|",
    ]
    for r in records:
        for tolerance in TOLERANCES:
            best = {e: cheapest(v["runs"], tolerance) for e, v in r["engines"].items()}
            mine = best.get("gaussim")
            for engine, found in best.items():
                reference = r["engines"][engine]["reference"]
                if found is None:
                    closest = min(r["engines"][engine]["runs"].items(), key=lambda item: item[1]["error"])
                    cells = [f"none (closest: {closest[0]}, {closest[1]['error']:.2e})", "", "", ""]
                else:
                    label, run = found
                    ratio = run["wall_per_sim_s"] / mine[1]["wall_per_sim_s"] if mine else math.nan
                    cells = [label, f"{run['error']:.2e}", f"{run['wall_per_sim_s']:.3g}", f"{ratio:.3g}"]
                lines.append(
                    f"| {r['task']} | {tolerance:g} | {engine} | {reference} | " + " | ".join(cells) + " |"
                )
    return "\n".join(lines)
