"""An arm let go with no torque, with and without the damping and dry friction its URDF gives its joints.

example-robot-data's Unitree Z1 declares `<dynamics damping friction>` on every joint (1 to 2 N m of dry
friction). Let go from a reaching pose with zero torque, it falls under gravity where its joints slide
and stays where their friction holds it: the run prints each joint's travel and its friction at the
end, sticking or sliding, against the same arm with `joint_friction=False`.

Run:  python examples/arm_joint_friction.py [--duration 1.0]
"""

from __future__ import annotations

import argparse

import numpy as np
from _shared import positive

import gaussim

POSE = np.array([0.3, 1.2, -1.0, 0.4, 0.2, 0.0, -0.5])  # reaching out, within the joints' limits


def let_go(robot: gaussim.Robot, friction: bool, duration: float) -> tuple[gaussim.State, gaussim.StepReport]:
    """The arm let go from POSE with zero torque for ``duration``: its last state and step report."""
    scene = gaussim.Scene(robot, joint_limits=True, joint_friction=friction)
    sim = gaussim.Simulator(scene, gaussim.Options(dt=1e-3))
    state = sim.reset(POSE)
    for _ in range(round(duration / 1e-3)):
        state = sim.step(state)
    assert sim.last_step is not None
    return state, sim.last_step


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=positive, default=1.0, help="simulated time [s]")
    args = parser.parse_args(argv)

    robot = gaussim.load_robot("z1")
    free, _ = let_go(robot, False, args.duration)
    held, report = let_go(robot, True, args.duration)
    friction = {r.joint: r for r in report.joint_friction}
    print(f"Z1 let go for {args.duration:g} s with zero torque, from q = {POSE.tolist()}")
    print(f"{'joint':14s} {'f [N m]':>8s} {'travel, free':>13s} {'travel, rubbed':>15s}  friction at the end")
    for j in range(1, robot.model.njoints):
        name, i = robot.model.names[j], robot.model.joints[j].idx_q
        r = friction[name]
        state = "slides" if r.sliding else "sticks"
        print(
            f"{name:14s} {robot.model.friction[i]:8.2f} {free.q[i] - POSE[i]:+13.3f} "
            f"{held.q[i] - POSE[i]:+15.3f}  {r.torque:+.3f} N m, {state}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
