"""Two Solo-12 robots trot towards each other and bump: prints when they met, the force between them
(equal and opposite on each) and where each ended up, and writes the run log and its replay page.

Run:  python examples/solo_bump.py [--duration 3] [--apart 0.7] [--out out/solo_bump]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from _shared import Recording, Trot, positive, run

import gaussim

FEET = gaussim.Material(friction=0.9)
FACING = {
    "left": (0.0, 0.0, 0.0, 1.0),
    "right": (0.0, 0.0, 1.0, 0.0),
}  # base quaternions (x, y, z, w): +x, -x


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=positive, default=3.0, help="simulated time [s]")
    parser.add_argument("--dt", type=positive, default=1e-3, help="time step [s]")
    parser.add_argument(
        "--apart", type=float, default=0.7, help="distance between the bases at the start [m]"
    )
    parser.add_argument("--out", type=Path, default=Path("out/solo_bump"), help="prefix of the files written")
    args = parser.parse_args(argv)

    solo = gaussim.load_robot("solo12")
    scene = gaussim.Scene(
        bodies={"left": solo, "right": solo},
        ground=gaussim.Ground(friction=0.6),
        contacts="auto",  # every link on the ground and on every link of the other robot
        materials={"*/*_FOOT_0": FEET},
    )
    sim = gaussim.Simulator(scene, gaussim.Options(dt=args.dt))
    starts = {}
    for k, (name, quaternion) in enumerate(FACING.items()):
        q = solo.configuration("standing")
        q[0], q[2], q[3:7] = (k - 0.5) * args.apart, q[2] + 0.005, quaternion
        starts[name] = q
    state = sim.reset(starts)
    gaits = {name: Trot(solo, args.dt) for name in FACING}
    recording = Recording(sim, state)

    steps, met, peak = sim.options.steps(args.duration), None, 0.0
    wall = time.perf_counter()
    for _ in range(steps):
        commands = {name: gait(state.t, state.body(name)) for name, gait in gaits.items()}
        state = recording.step(
            state, {n: c.tau for n, c in commands.items()}, {n: c.damping for n, c in commands.items()}
        )
        report = sim.last_step
        assert report is not None
        on_left, on_right = report.forces_between("left", "right"), report.forces_between("right", "left")
        assert np.allclose(on_left, -on_right), "action and reaction"
        if on_left.any():
            met = state.t if met is None else met
            peak = max(peak, float(np.linalg.norm(on_left)))
    wall = time.perf_counter() - wall
    log, page = recording.save(args.out)

    print(f"two Solo-12 trotted {state.t:.2f} s towards each other ({steps / wall:.0f} steps/s)")
    if met is None:
        print("they did not meet: give them more time (--duration) or start them closer (--apart)")
        return 1
    print(f"first touch at t = {met:.3f} s; peak force between them {peak:.1f} N")
    for name, start in starts.items():
        base = state.body(name).q
        print(f"{name:>5}: base moved {base[0] - start[0]:+.3f} m along x, {base[1]:+.3f} m sideways")
    print(f"run log: {log}\nreplay page: {page}")
    return 0


if __name__ == "__main__":
    run(main)
