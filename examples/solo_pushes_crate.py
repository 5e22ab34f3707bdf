"""Solo-12 trots into a loose crate and pushes it along the ground: prints how far the crate went and
the force between them, and writes the run log and its replay page.

Run:  python examples/solo_pushes_crate.py [--duration 4] [--distance 0.2] [--out out/solo_pushes_crate]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from _shared import Recording, Trot, positive, run

import gaussim

CRATE = (0.3, 0.4, 0.2)  # side lengths [m]: as tall as Solo's base, wider than its stance
CRATE_MASS = 1.0  # [kg]
FRONT = 0.215  # how far Solo's front feet reach ahead of its base when standing [m]
# The crate slides on mu = 0.4 (its weight's friction, 3.9 N, is well within what Solo's feet hold on
# mu = 0.9 under 25 N)
GROUND, FEET = gaussim.Ground(friction=0.4), gaussim.Material(friction=0.9)
# A crate that moved less than this was not pushed [m].
PUSHED = 0.01


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=positive, default=4.0, help="simulated time [s]")
    parser.add_argument("--dt", type=positive, default=1e-3, help="time step [s]")
    parser.add_argument(
        "--distance", type=float, default=0.2, help="from Solo's front feet to the crate at the start [m]"
    )
    parser.add_argument(
        "--out", type=Path, default=Path("out/solo_pushes_crate"), help="prefix of the files written"
    )
    args = parser.parse_args(argv)

    solo = gaussim.load_robot("solo12")
    crate = gaussim.FreeBody.box("crate", CRATE, mass=CRATE_MASS)
    scene = gaussim.Scene(
        bodies={"solo": solo, "crate": crate},
        ground=GROUND,
        contacts=[("solo/*_FOOT_0", "ground"), ("crate", "ground"), ("solo", "crate")],
        materials={"solo/*_FOOT_0": FEET},
    )
    sim = gaussim.Simulator(scene, gaussim.Options(dt=args.dt))
    standing = solo.configuration("standing")
    standing[2] += 0.005  # dropped 5 mm onto its feet
    start = gaussim.pose(x=FRONT + args.distance + CRATE[0] / 2, z=CRATE[2] / 2 + 1e-4)
    state = sim.reset({"solo": standing, "crate": start})
    gait = Trot(solo, args.dt)
    recording = Recording(sim, state)

    crate_start, solo_start = state.body("crate").q[:3].copy(), state.body("solo").q[:3].copy()
    steps, peak, pushing = sim.options.steps(args.duration), 0.0, 0
    wall = time.perf_counter()
    for _ in range(steps):
        tau, damping = gait(state.t, state.body("solo"))
        state = recording.step(state, {"solo": tau}, {"solo": damping})
        force = sim.last_step.forces_between("crate", "solo")  # type: ignore[union-attr]
        peak = max(peak, float(np.linalg.norm(force)))
        pushing += bool(force.any())
    wall = time.perf_counter() - wall
    log, page = recording.save(args.out)

    moved = state.body("crate").q[:3] - crate_start
    walked = state.body("solo").q[:3] - solo_start
    print(f"Solo-12 trotted {walked[0]:.3f} m forward in {state.t:.2f} s ({steps / wall:.0f} steps/s)")
    print(
        f"crate displacement: {moved[0]:+.3f} m forward, {moved[1]:+.3f} m sideways "
        f"(touched during {pushing * args.dt:.2f} s, peak force {peak:.1f} N)"
    )
    print(f"run log: {log}\nreplay page: {page}")
    if moved[0] < PUSHED:
        print(f"the crate was not pushed (moved {moved[0]:.4f} m < {PUSHED} m)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    run(main)
