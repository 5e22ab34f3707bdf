"""gaussim's dual active-set method (``Options(solver="dual")``, the default) against DAQP's
(``solver="daqp"``) on the drops of examples/bin_pile.py: 20 objects into a bin, each seed's drop run
for STEPS steps by both, the two in turn seed by seed (so that both see the same spells of a busy
machine). Prints each run's wall time of its steps, its median step and the QPs each method answered.
The two pose the same first problems but their answers, where the forces are not unique, differ in
round-off, and a pile's settling is chaotic: compare sums over several seeds, not one drop.

Run:  python benchmarks/dual_methods.py [--seeds 8] [--steps 2000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import gaussim
from gaussim.bench.scenes import example
from gaussim.solver import Status

METHODS = {"dual": Status.DUAL_SOLVED, "daqp": Status.DUAL_ACTIVE_SET_SOLVED}


def drop(seed: int, solver: str, steps: int) -> tuple[float, float, int]:
    """(wall time of the steps [s], median step [us], QPs the method answered) of one drop."""
    pile = example("bin_pile")
    frame, walls = pile.bin_walls()
    bodies = pile.objects()
    scene = gaussim.Scene(
        bodies={name: body for name, (body, _) in bodies.items()},
        obstacles=walls,
        self_contact=(pile.FRICTION, 0.0),
    )
    sim = gaussim.Simulator(scene, gaussim.Options(solver=solver))
    state = sim.reset(pile.drop_poses(frame, bodies, seed))
    times, answered = np.empty(steps), 0
    for k in range(steps):
        start = time.perf_counter()
        state = sim.step(state)
        times[k] = time.perf_counter() - start
        answered += sum(c.status is METHODS[solver] for c in sim.last_step.certificates)
    return float(times.sum()), float(np.median(times) * 1e6), answered


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8, help="drops of seeds 0 .. N-1")
    parser.add_argument("--steps", type=int, default=2000, help="steps of each drop (dt 1 ms)")
    args = parser.parse_args()
    totals = dict.fromkeys(METHODS, 0.0)
    print(
        f"{'seed':>4}  " + "  ".join(f"{m + ' s':>8} {m + ' median us':>15} {m + ' QPs':>9}" for m in METHODS)
    )
    for seed in range(args.seeds):
        row = []
        for method in METHODS:
            wall, median, answered = drop(seed, method, args.steps)
            totals[method] += wall
            row.append(f"{wall:8.2f} {median:15.0f} {answered:9d}")
        print(f"{seed:4d}  " + "  ".join(row))
    dual, daqp = totals["dual"], totals["daqp"]
    print(f"sum   dual {dual:.2f} s, daqp {daqp:.2f} s: dual / daqp = {dual / daqp:.2f}")


if __name__ == "__main__":
    main()
