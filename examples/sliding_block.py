"""A block sliding on the ground at 1 m/s with mu = 0.5: stopping distance against v^2 / (2 mu g).

Run:  python examples/sliding_block.py [--mode accurate] [--heading 30]
"""

from __future__ import annotations

import argparse

import numpy as np
from _shared import positive, run

import gaussim


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mode", default="accurate", choices=gaussim.options.FRICTION_MODES)
    parser.add_argument("--heading", type=float, default=30.0, help="sliding direction [deg]")
    parser.add_argument("--mu", type=float, default=0.5)
    parser.add_argument("--dt", type=positive, default=1e-3)
    args = parser.parse_args(argv)

    robot = gaussim.load_robot("box", floating_base=True)
    scene = gaussim.Scene(robot, ground=gaussim.Ground(friction=args.mu))
    sim = gaussim.Simulator(scene, gaussim.Options(dt=args.dt, friction_mode=args.mode))
    q = robot.neutral()
    q[2] = 0.05  # the box is 0.1 m high
    heading = np.radians(args.heading)
    state = sim.reset(q, np.array([np.cos(heading), np.sin(heading), 0, 0, 0, 0]))
    lift = 0.0
    while np.linalg.norm(state.v) > 1e-9 or state.t < 0.01:
        state = sim.step(state)
        lift = max(lift, abs(state.q[2] - 0.05))
    distance = np.linalg.norm(state.q[:2])
    reference = 1.0 / (2 * args.mu * 9.81)
    print(f"friction mode {args.mode}, heading {args.heading:g} deg, dt {args.dt:g} s")
    print(
        f"stopped after {state.t:.3f} s, distance {distance:.5f} m (v^2/(2 mu g) = {reference:.5f} m, "
        f"error {100 * (distance / reference - 1):+.2f} %)"
    )
    print(f"largest height change while sliding: {lift:.2e} m")
    return 0


if __name__ == "__main__":
    run(main)
