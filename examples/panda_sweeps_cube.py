"""A fixed-base Franka Panda mounted on a table sweeps a loose cube across it: the hand, held low over
the table, turns about the arm's vertical first joint along a smooth joint trajectory (PD with
gravity compensation and implicit damping); prints how far the cube travelled, and writes the run log
and its replay page.

Run:  python examples/panda_sweeps_cube.py [--duration 2] [--out out/panda_sweeps_cube]
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
from _shared import Recording, positive, run

import gaussim

TABLE_TOP = 0.4  # height of the table's top, where the arm's base stands [m]
TABLE = gaussim.Box("table", (1.2, 1.2, 0.04), position=(0.3, 0.0, TABLE_TOP - 0.02), friction=0.5)
CUBE, CUBE_MASS = 0.06, 0.2  # side [m], mass [kg]
REACH, HAND_HEIGHT = 0.5, 0.14  # the hand's distance from the base axis and height above the table [m]
SWEEP = (-0.9, 0.9)  # the first joint's angle at the start and at the end of the sweep [rad]
CUBE_ANGLE = -0.35  # where the cube sits along the hand's arc [rad]
KP, KD = 400.0, 40.0  # joint PD gains [N m/rad], [N m s/rad]
# A cube that travelled less than this was not swept [m].
SWEPT = 0.05


def reach_pose(panda: gaussim.Robot) -> np.ndarray:
    """The arm's configuration with its hand pointing down at REACH from the base axis, HAND_HEIGHT
    above the table (first joint at 0), fingers closed: Gauss-Newton on the hand's placement."""
    model, data = panda.model, panda.model.createData()
    hand = model.getFrameId("panda_hand")
    target = pin.SE3(np.diag([1.0, -1.0, -1.0]), np.array([REACH, 0.0, HAND_HEIGHT]))
    q = panda.configuration("default").copy()
    q[7:] = 0.0
    for _ in range(200):
        pin.framesForwardKinematics(model, data, q)
        error = pin.log6(data.oMf[hand].actInv(target)).vector
        J = pin.computeFrameJacobian(model, data, q, hand, pin.LOCAL)[:, :7]
        q[:7] += 0.5 * np.linalg.lstsq(J, error, rcond=None)[0]  # half steps: no jump between branches
    assert np.linalg.norm(error) < 1e-9, f"the reach pose is not reached: error {error}"
    return q


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=positive, default=2.0, help="simulated time of the sweep [s]")
    parser.add_argument("--dt", type=positive, default=1e-3, help="time step [s]")
    parser.add_argument(
        "--out", type=Path, default=Path("out/panda_sweeps_cube"), help="prefix of the files written"
    )
    args = parser.parse_args(argv)

    with warnings.catch_warnings():  # its finger joints mimic each other; here they are held apart
        warnings.simplefilter("ignore", gaussim.GaussimWarning)
        panda = gaussim.load_robot("panda")
    cube = gaussim.FreeBody.box("cube", (CUBE,) * 3, mass=CUBE_MASS)
    scene = gaussim.Scene(
        bodies={"arm": gaussim.Body(panda, placement=gaussim.pose(z=TABLE_TOP)), "cube": cube},
        ground=gaussim.Ground(),
        obstacles=[TABLE],
        contacts="auto",  # the arm's links with the table, the cube and the ground; the cube with all
    )
    sim = gaussim.Simulator(scene, gaussim.Options(dt=args.dt))
    reach = reach_pose(panda)
    start = reach.copy()
    start[0] = SWEEP[0]
    cube_at = gaussim.pose(
        x=REACH * np.cos(CUBE_ANGLE),
        y=REACH * np.sin(CUBE_ANGLE),
        z=TABLE_TOP + CUBE / 2 + 1e-4,
        rpy=(0.0, 0.0, CUBE_ANGLE),
    )
    state = sim.reset({"arm": start, "cube": cube_at})
    recording = Recording(sim, state)
    arm = scene.bodies["arm"]
    model, data = sim.model, sim.model.createData()
    damping = np.full(panda.model.nv, KD + args.dt * KP)  # the PD's velocity feedback, implicit

    cube_start = state.body("cube").q[:3].copy()
    steps, lag, peak = sim.options.steps(args.duration), 0.0, 0.0
    wall = time.perf_counter()
    for _ in range(steps):
        s = min(1.0, state.t / args.duration)  # a smooth step from SWEEP[0] to SWEEP[1]
        target, speed = reach.copy(), np.zeros(panda.model.nv)
        target[0] = SWEEP[0] + (SWEEP[1] - SWEEP[0]) * (3 * s**2 - 2 * s**3)
        speed[0] = (SWEEP[1] - SWEEP[0]) * 6 * s * (1 - s) / args.duration
        gravity = pin.computeGeneralizedGravity(model, data, state.q)[arm.v]
        q = state.body("arm").q
        tau = gravity + KP * (target - q) + KD * speed  # tau - D v+: the PD about the target's speed
        state = recording.step(state, {"arm": tau}, {"arm": damping})
        lag = max(lag, float(np.abs(target - q).max()))
        peak = max(peak, float(np.linalg.norm(sim.last_step.forces_between("cube", "arm"))))  # type: ignore[union-attr]
    wall = time.perf_counter() - wall
    log, page = recording.save(args.out)

    travel = state.body("cube").q[:3] - cube_start
    print(
        f"Panda swept its first joint from {SWEEP[0]:+.2f} to {state.body('arm').q[0]:+.2f} rad in "
        f"{state.t:.2f} s (largest tracking error {lag:.3f} rad; {steps / wall:.0f} steps/s)"
    )
    print(
        f"cube travel: {np.linalg.norm(travel[:2]):.3f} m across the table (dx {travel[0]:+.3f} m, "
        f"dy {travel[1]:+.3f} m, dz {travel[2]:+.4f} m; peak force from the arm {peak:.1f} N)"
    )
    print(f"run log: {log}\nreplay page: {page}")
    across = float(np.linalg.norm(travel[:2]))
    if across < SWEPT:
        print(f"the cube was not swept (travel {across:.4f} m < {SWEPT} m)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    run(main)
