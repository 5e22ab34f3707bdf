"""Every robot people already have: the example-robot-data and pybullet_data corpora (pybullet_data's
URDF, MJCF and SDF files), each robot loaded and dropped onto the ground, or refused with a reason.

Each robot runs in its own process (forked from this one, which has imported gaussim and compiled its
kernels) with a time limit, twice: a PD hold of its initial pose (``hold``; zero torque for an object
without joints) and zero torque (``zero``: a robot collapses onto the ground). Settings: dt = 1e-3,
every collision geometry against the ground, joint limits on; a floating robot starts 1 cm above the
ground, a fixed-base one has the ground 1 cm below its lowest geometry. A pass runs TIMING_RUNS times
(the same trajectory: a second that differs is said in its message), and its step times are the least
of those runs', step by step. The table (robot, nq/nv, geometries, outcome, message, steps, median
and p90 step, median and p90 contact points, max penetration, max KKT residual, final base height)
goes to a Markdown file and a CSV; the counts per outcome are printed.

Outcomes: ``ok`` (ran to the end), ``refused`` (gaussim refused the robot at load, naming the cause),
``failed`` (a gaussim error while simulating), ``exploded`` (a non-finite state, |v| > 1e3 or the base
farther than 100 m), ``crash`` (an exception that is not gaussim's: a bug), ``timeout``.

    python benchmarks/corpus.py                       # both corpora, 1 s each pass; docs/corpus.md + .csv
    python benchmarks/corpus.py --quick               # 0.1 s each pass, a few random_urdfs
    python benchmarks/corpus.py --only solo12 a1.urdf # some robots (example-robot-data names, file names)
"""

from __future__ import annotations

import argparse
import csv
import math
import multiprocessing as mp
import os
import sys
import time
import traceback
import warnings
from collections import Counter
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

import gaussim
from gaussim.bench.provenance import made, python_loop
from gaussim.exceptions import GaussimError, GaussimWarning
from gaussim.robot import example_robot_names
from gaussim.scenefile import (
    HOLD_KD_PER_KG,
    HOLD_KP_PER_KG,
    ROBOT_CLEARANCE,
    ground_below,
    place_on_ground,
    start_configuration,
)

PASSES = ("hold", "zero")
OUTCOMES = ("ok", "refused", "failed", "exploded", "crash", "timeout")
DT = 1e-3
# A state this far gone is an explosion: no robot of the corpora moves at 1 km/s or leaves 100 m.
MAX_SPEED, MAX_DISTANCE = 1e3, 100.0
# The target on the spread of a run's step times: its p90 within this many times its median.
P90_SPREAD = 3.0
# A pass's step times are the least of this many runs of its trajectory, step by step (a run is
# deterministic): the engine's cost, not the spells of a machine that runs other work too.
TIMING_RUNS = 2


@dataclass
class Row:
    """One robot's run of one pass."""

    robot: str
    corpus: str
    run: str
    nq: int = 0
    nv: int = 0
    geometries: int = 0
    outcome: str = ""
    message: str = ""
    steps: int = 0
    median_ms: float = math.nan
    p90_ms: float = math.nan
    max_penetration_mm: float = math.nan
    max_kkt: float = math.nan
    base_height: float = math.nan
    contacts_median: float = math.nan
    contacts_p90: float = math.nan
    warnings: str = ""


def corpus(random_urdfs: int) -> list[tuple[str, str, str]]:
    """(name, corpus, what load_robot takes) of every robot: example-robot-data's names, pybullet_data's
    URDFs (floating, as pybullet loads them by default), MJCF (``mjcf/*.xml``) and SDF files (floating as
    they say), and every ``random_urdfs``-th random object (0: none)."""
    import pybullet_data

    root = Path(pybullet_data.getDataPath())
    entries = [(name, "example-robot-data", name) for name in example_robot_names()]
    files = sorted(p for p in root.rglob("*.urdf") if "random_urdfs" not in p.parts)
    files += sorted(root.glob("mjcf/*.xml")) + sorted(root.rglob("*.sdf"))
    entries += [(str(p.relative_to(root)), "pybullet_data", str(p)) for p in files]
    if random_urdfs:
        objects = sorted((root / "random_urdfs").rglob("*.urdf"))
        entries += [(str(p.relative_to(root)), "random_urdfs", str(p)) for p in objects[::random_urdfs]]
    return entries


def scene_and_start(robot: gaussim.Robot) -> tuple[gaussim.Scene, np.ndarray]:
    """The robot above a ground (every geometry against it, limits on, and the joint damping and dry
    friction its file gives) and its start: as ``gaussim run ROBOT`` makes them
    (:func:`gaussim.scenefile.robot_scene_text`), from the start clamped into the limits as reset
    leaves it."""
    rubbed = bool(robot.model.damping.any() or robot.model.friction.any())
    scene = gaussim.Scene(robot, ground=gaussim.Ground(), joint_limits=True, joint_friction=rubbed)
    probe = gaussim.Simulator(scene, gaussim.Options(start_penetration=1e9))
    q = probe.reset(robot.configuration(start_configuration(robot))).q
    if robot.floating:
        return scene, place_on_ground(scene, q, ROBOT_CLEARANCE)
    ground = gaussim.Ground(height=ground_below(robot, q, ROBOT_CLEARANCE))
    return gaussim.Scene(robot, ground=ground, joint_limits=True, joint_friction=rubbed), q


def simulate(robot: gaussim.Robot, run: str, duration: float, row: Row) -> None:
    """Run one pass, filling ``row`` with its outcome and measures; its step times are the least of
    TIMING_RUNS runs of the same trajectory, step by step."""
    start = scene_and_start(robot)
    times, end = _run(robot, *start, run, duration, row)
    for _ in range(TIMING_RUNS - 1):
        again, again_end = _run(robot, *start, run, duration, Row(row.robot, row.corpus, row.run))
        if len(again) != len(times) or not all(np.array_equal(a, b) for a, b in zip(end, again_end)):
            row.message = "step times of one run: a second run's trajectory differed"
            break
        times = np.minimum(times, again)
    row.median_ms, row.p90_ms = float(np.median(times)), float(np.percentile(times, 90))


def _run(
    robot: gaussim.Robot, scene: gaussim.Scene, q0: np.ndarray, run: str, duration: float, row: Row
) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """One run of a pass from ``q0`` in ``scene``, filling ``row`` (but its step times): the step
    times [ms] and the last state's (q, v)."""
    sim = gaussim.Simulator(scene, gaussim.Options(dt=DT))
    state = sim.reset(q0)
    model = sim.model
    actuated = robot.actuated
    hold = run == "hold" and len(actuated) > 0
    gain = max(robot.mass, 1.0)
    pd = gaussim.control.PDHold(model, q0, HOLD_KP_PER_KG * gain, HOLD_KD_PER_KG * gain, actuated, DT)
    times, contacts, penetration, kkt = [], [], 0.0, 0.0
    for _ in range(round(duration / DT)):
        command = pd(state) if hold else gaussim.control.Command(None)
        start = time.perf_counter()
        state = sim.step(state, command.tau, command.damping)
        times.append(time.perf_counter() - start)
        report = sim.last_step
        contacts.append(len(report.contacts))
        kkt = max([kkt, *(c.relative_kkt_residual for c in report.certificates)])
        if report.blocks:
            penetration = max([penetration, *(-c.gap for c in report.contacts)])
        row.steps += 1
        if (
            not np.all(np.isfinite(state.v))
            or np.abs(state.v).max() > MAX_SPEED
            or (robot.floating and np.abs(state.q[:3]).max() > MAX_DISTANCE)
        ):
            row.outcome = "exploded"
            row.message = f"|v| = {np.abs(state.v).max():.3g}, base at {np.round(state.q[:3], 2).tolist()}"
            break
    else:
        row.outcome = "ok"
    row.max_penetration_mm, row.max_kkt = 1e3 * max(penetration, 0.0), kkt
    row.contacts_median, row.contacts_p90 = np.median(contacts), np.percentile(contacts, 90)
    row.base_height = float(state.q[2]) if robot.floating else math.nan
    return 1e3 * np.asarray(times), (state.q, state.v)


def one(name: str, corpus_name: str, source: str, duration: float) -> list[Row]:
    """Both passes of one robot (in a worker process), with the GaussimWarnings they gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", GaussimWarning)
        rows = _passes(name, corpus_name, source, duration)
    said = [str(w.message) for w in caught if issubclass(w.category, GaussimWarning)]
    return _noted(rows, said)


def _passes(name: str, corpus_name: str, source: str, duration: float) -> list[Row]:
    rows = [Row(name, corpus_name, run) for run in PASSES]
    try:
        # a URDF of pybullet_data floats, as PyBullet loads it by default; the others as their files say
        floats = corpus_name != "example-robot-data" and source.endswith(".urdf")
        robot = gaussim.load_robot(source, floating_base=True if floats else None)
    except GaussimError as err:
        for row in rows:
            row.outcome, row.message = "refused", f"{type(err).__name__}: {err}"
        return rows
    except Exception as err:  # a bug: recorded as a crash with its place
        for row in rows:
            row.outcome, row.message = "crash", _crash(err)
        return rows
    for row in rows:
        row.nq, row.nv, row.geometries = robot.model.nq, robot.model.nv, robot.collision_model.ngeoms
        try:
            simulate(robot, row.run, duration, row)
        except GaussimError as err:
            row.outcome = "failed" if row.steps or not isinstance(err, gaussim.InvalidOptions) else "refused"
            row.message = f"{type(err).__name__} at step {row.steps}: {err}"
        except Exception as err:
            row.outcome, row.message = "crash", f"at step {row.steps}: {_crash(err)}"
    return rows


def _noted(rows: list[Row], caught: list[str]) -> list[Row]:
    text = _short(" | ".join(dict.fromkeys(caught)))
    for row in rows:
        row.message = _short(row.message)
        row.warnings = text
    return rows


def _short(text: str) -> str:
    """A message with the corpora's install folders left out."""
    import example_robot_data
    import pybullet_data

    folders = {
        pybullet_data.getDataPath() + "/": "pybullet_data/",
        str(Path(example_robot_data.getModelPath("")).resolve()) + "/": "example-robot-data/",
        example_robot_data.getModelPath("") + "/": "example-robot-data/",
    }
    for folder, short in folders.items():
        text = text.replace(folder, short)
    return " ".join(text.split())


def _crash(err: Exception) -> str:
    where = traceback.extract_tb(err.__traceback__)[-1]
    return f"{type(err).__name__}: {err} ({Path(where.filename).name}:{where.lineno})"


def _worker(conn, name: str, corpus_name: str, source: str, duration: float) -> None:  # type: ignore[no-untyped-def]
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    conn.send([asdict(r) for r in one(name, corpus_name, source, duration)])
    conn.close()


def run_all(entries: list[tuple[str, str, str]], duration: float, workers: int, limit: float) -> list[Row]:
    """Every entry in its own forked process, ``workers`` at a time, each killed after ``limit`` s."""
    context = mp.get_context("fork")
    pending, running, rows = list(entries), [], []
    done = 0
    while pending or running:
        while pending and len(running) < workers:
            entry = pending.pop(0)
            receive, send = context.Pipe(duplex=False)
            process = context.Process(target=_worker, args=(send, *entry, duration), daemon=True)
            process.start()
            send.close()
            running.append((entry, process, receive, time.monotonic()))
        time.sleep(0.05)
        for item in list(running):
            entry, process, receive, started = item
            result = None
            if receive.poll():
                try:
                    result = [Row(**r) for r in receive.recv()]
                except EOFError:
                    result = _lost(entry, f"the process died (exit code {process.exitcode})")
            elif not process.is_alive():
                result = _lost(entry, f"the process died (exit code {process.exitcode})")
            elif time.monotonic() - started > limit:
                process.kill()
                result = _lost(entry, f"no answer within {limit:g} s", "timeout")
            if result is None:
                continue
            process.join()
            running.remove(item)
            rows += result
            done += 1
            outcomes = "/".join(r.outcome for r in result)
            took = time.monotonic() - started
            print(f"[{done}/{len(entries)}] {entry[0]}: {outcomes} ({took:.1f} s)", flush=True)
    order = {name: i for i, (name, _, _) in enumerate(entries)}
    return sorted(rows, key=lambda r: (order[r.robot], PASSES.index(r.run)))


def _lost(entry: tuple[str, str, str], why: str, outcome: str = "crash") -> list[Row]:
    return [Row(entry[0], entry[1], run, outcome=outcome, message=why) for run in PASSES]


def summary(rows: list[Row]) -> list[str]:
    """The runs' step-time spread (p90 over median, the issue's measure) and their worst residuals."""
    ran = [r for r in rows if r.outcome == "ok"]
    if not ran:
        return []
    spread = sorted(ran, key=lambda r: r.p90_ms / r.median_ms, reverse=True)
    within = sum(r.p90_ms <= P90_SPREAD * r.median_ms for r in ran)
    worst = ", ".join(
        f"{r.robot} {r.run} {r.p90_ms / r.median_ms:.1f} (contact points: median {r.contacts_median:g}, "
        f"p90 {r.contacts_p90:g})"
        for r in spread[:5]
    )
    return [
        f"p90 step within {P90_SPREAD:g} x the median on {within} of {len(ran)} runs; the widest: {worst}.",
        f"Largest relative KKT residual accepted: {max(r.max_kkt for r in ran):.2g}; deepest penetration: "
        f"{max(r.max_penetration_mm for r in ran):.3g} mm.",
    ]


def write(rows: list[Row], markdown: Path, command: str, duration: float, notes: list[str]) -> None:
    """The table as Markdown (with the counts and the run's ``notes``: see
    :func:`gaussim.bench.provenance.made`) and as a CSV beside it."""
    markdown.parent.mkdir(parents=True, exist_ok=True)
    with open(markdown.with_suffix(".csv"), "w", newline="") as f:
        writer = csv.DictWriter(f, [f.name for f in fields(Row)])
        writer.writeheader()
        writer.writerows(asdict(r) for r in rows)
    robots = {r.robot for r in rows}
    both = {r.robot for r in rows if r.outcome == "ok"} - {r.robot for r in rows if r.outcome != "ok"}
    refused = {r.robot for r in rows if r.outcome == "refused"}
    lines = [
        "# The robot corpora",
        "",
        f"Written by `{command}` ({duration:g} s each pass, dt = {DT:g} s; {'; '.join(notes)}; see "
        "benchmarks/corpus.py for the settings and the outcomes). A pass's step times are the least of "
        f"{TIMING_RUNS} runs of its trajectory, step by step. The CSV beside this file holds the same "
        "rows with the warnings.",
        "",
        f"{len(robots)} robots: {len(both)} simulate both passes, {len(refused)} are refused with a reason, "
        f"{len(robots - both - refused)} neither.",
        "",
        "| outcome | " + " | ".join(PASSES) + " |",
        "|---|" + "---:|" * len(PASSES),
    ]
    for outcome in OUTCOMES:
        counts = [sum(r.outcome == outcome and r.run == run for r in rows) for run in PASSES]
        lines.append(f"| {outcome} | " + " | ".join(map(str, counts)) + " |")
    lines += ["", *summary(rows)]
    lines += [
        "",
        "| robot | corpus | pass | nq/nv | geoms | outcome | steps | median [ms] | p90 [ms] | "
        "contact points (median / p90) | max pen. [mm] | max KKT | base z [m] | message |",
        "|---|---|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        message = r.message.replace("|", "/").replace("\n", " ")
        lines.append(
            f"| {r.robot} | {r.corpus} | {r.run} | {r.nq}/{r.nv} | {r.geometries} | {r.outcome} | "
            f"{r.steps} | "
            f"{r.median_ms:.3g} | {r.p90_ms:.3g} | {r.contacts_median:g} / {r.contacts_p90:g} | "
            f"{r.max_penetration_mm:.3g} | {r.max_kkt:.2g} | "
            f"{r.base_height:.3g} | {message[:300]} |"
        )
    markdown.write_text("\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=1.0, help="simulated time of each pass [s]")
    parser.add_argument("--quick", action="store_true", help="0.1 s each pass, every 200th random_urdf")
    parser.add_argument("--random", type=int, default=10, help="every N-th random_urdfs object (0: none)")
    parser.add_argument("--workers", type=int, default=max(1, (os.cpu_count() or 2)))
    parser.add_argument("--limit", type=float, default=600.0, help="time limit per robot [s]")
    parser.add_argument("--only", nargs="*", help="robot names, pybullet_data file names or corpus names")
    parser.add_argument("--out", type=Path, default=Path("docs/corpus.md"))
    args = parser.parse_args(argv)
    duration = 0.1 if args.quick else args.duration
    entries = corpus(200 if args.quick else args.random)
    if args.only:
        entries = [e for e in entries if {e[0], e[1], Path(e[0]).name} & set(args.only)]
    warm = [e for e in corpus(0) if e[0] == "solo12"]  # compiles the kernels before the fork
    one(*warm[0], DT)
    before = python_loop()  # the machine's speed around the run: its step times compare within it
    rows = run_all(entries, duration, args.workers, args.limit)
    notes = made((before, python_loop()))
    write(rows, args.out, "python benchmarks/corpus.py " + " ".join(argv or sys.argv[1:]), duration, notes)
    counts = Counter((r.run, r.outcome) for r in rows)
    for run in PASSES:
        print(run + ": " + ", ".join(f"{o} {counts[run, o]}" for o in OUTCOMES if counts[run, o]))
    print("\n".join(summary(rows)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
