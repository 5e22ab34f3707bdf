"""The friction passes' Newton step (gaussim.constraints.contact.NEWTON_UP_TO) against the secant alone,
on the zero-torque runs of the corpus robots (benchmarks/corpus.py's scenes and settings, 1 s each):
QPs made, steps whose passes ended relaxed (the De Saxce shift dropped), and with ``--time`` each
step timed from the same states both ways (the best of 3 each, the two alternating step by step, so
that both see the same spells of a busy machine).

Run:  python benchmarks/friction_passes.py [ROBOT ...] [--time]

Without robot names, every example-robot-data robot of the corpus.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
from corpus import DT, corpus, scene_and_start

import gaussim
from gaussim.constraints import contact

STEPS = 1000
SETTINGS = {"secant": 0, "newton": contact.NEWTON_UP_TO}


def counts(robot: gaussim.Robot) -> dict[str, tuple[int, int]]:
    """(QPs, relaxed steps) of the zero-torque run of ``robot``, per setting."""
    scene, q0 = scene_and_start(robot)
    result = {}
    for setting, limit in SETTINGS.items():
        contact.NEWTON_UP_TO = limit
        sim = gaussim.Simulator(scene, gaussim.Options(dt=DT))
        state, qps, relaxed = sim.reset(q0), 0, 0
        for _ in range(STEPS):
            state = sim.step(state)
            qps += len(sim.last_step.certificates)
            relaxed += sim.last_step.friction_relaxed
        result[setting] = (qps, relaxed)
    return result


def timings(robot: gaussim.Robot) -> dict[str, float]:
    """Mean step [ms] of the zero-torque run, each step from the states of one run, per setting."""
    scene, q0 = scene_and_start(robot)
    contact.NEWTON_UP_TO = SETTINGS["newton"]
    sim = gaussim.Simulator(scene, gaussim.Options(dt=DT))
    state, states = sim.reset(q0), []
    for _ in range(STEPS):
        states.append(state)
        state = sim.step(state)
    spent = {setting: 0.0 for setting in SETTINGS}
    for state in states:
        for setting, limit in SETTINGS.items():
            contact.NEWTON_UP_TO = limit
            best = np.inf
            for _ in range(3):
                start = time.perf_counter()
                sim.step(state)
                best = min(best, time.perf_counter() - start)
            spent[setting] += best
    return {setting: 1e3 * seconds / STEPS for setting, seconds in spent.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("robots", nargs="*", help="robot names (default: every example-robot-data one)")
    parser.add_argument("--time", action="store_true", help="time each step from the same states both ways")
    args = parser.parse_args()
    names = args.robots or [name for name, corpus_name, _ in corpus(0) if corpus_name == "example-robot-data"]
    totals = {setting: np.zeros(2, int) for setting in SETTINGS}
    for name in names:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                robot = gaussim.load_robot(name)
                found = counts(robot)
            except gaussim.GaussimError as err:  # refused (benchmarks/corpus.py says why)
                print(f"{name}: refused ({type(err).__name__})")
                continue
            line = ", ".join(f"{s}: {q} QPs, {r} relaxed" for s, (q, r) in found.items())
            if args.time:
                line += ", " + ", ".join(f"{s} {ms:.3f} ms" for s, ms in timings(robot).items())
        print(f"{name}: {line}", flush=True)
        for setting, pair in found.items():
            totals[setting] += pair
    for setting, (qps, relaxed) in totals.items():
        print(f"total, {setting}: {qps} QPs, {relaxed} relaxed steps")


if __name__ == "__main__":
    main()
