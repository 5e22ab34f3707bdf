"""Solo-12 dropped 1 cm onto the ground stands under a PD posture hold; prints its contact forces.

Run:  python examples/solo12_drop.py [--duration 2.0] [--scheme velocity] [--csv out/solo12_drop_forces.csv]

The CSV is the run log's force export (``gaussim.runlog.write_forces``, the columns of
``gaussim forces``), under this example's own name: the main job's out/solo12_forces.csv is left alone.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from _shared import positive, run

import gaussim
from gaussim.runlog import write_forces

KP, KD = 5.0, 0.2  # posture PD gains [N m / rad], [N m s / rad]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=positive, default=2.0, help="simulated time [s]")
    parser.add_argument("--dt", type=positive, default=1e-3, help="time step [s]")
    parser.add_argument("--scheme", default="velocity", choices=gaussim.options.SCHEMES)
    parser.add_argument(
        "--csv", type=Path, default=Path("out/solo12_drop_forces.csv"), help="contact-force time series"
    )
    args = parser.parse_args(argv)

    robot = gaussim.load_robot("solo12")
    feet = [(f"{leg}_FOOT_0", "ground") for leg in ("FL", "FR", "HL", "HR")]
    scene = gaussim.Scene(robot, ground=gaussim.Ground(friction=0.8), contacts=feet)
    sim = gaussim.Simulator(scene, gaussim.Options(dt=args.dt, scheme=args.scheme))
    q_ref = robot.configuration("standing")
    q0 = q_ref.copy()
    q0[2] += 0.01
    state = sim.reset(q0)
    log = gaussim.RunLog(robot.name, "", sim.options)
    log.start(state, scene.gravity)

    args.csv.parent.mkdir(parents=True, exist_ok=True)
    steps = sim.options.steps(args.duration)
    start = time.perf_counter()
    for k in range(steps):
        tau = KP * (q_ref[7:] - state.q[7:]) - KD * state.v[6:]
        state = sim.step(state, tau)
        log.record(state, sim.full_torque(tau, None, state.v), sim.last_step)
        if (k + 1) % max(1, steps // 10) == 0:
            rate = (k + 1) / (time.perf_counter() - start)
            print(f"\r  t = {state.t:5.2f} s  ({rate:6.0f} steps/s)", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    log.finish(True)
    write_forces(log, args.csv)
    report = sim.last_step
    print(f"Solo-12 after {state.t:.2f} s ({args.scheme} scheme, dt = {args.dt:g} s):")
    print(report.table())
    print(f"weight m g = {robot.mass * 9.81:.3f} N; contact forces redundant: {report.redundant}")
    print(f"contact-force time series written to {args.csv}")
    return 0


if __name__ == "__main__":
    run(main)
