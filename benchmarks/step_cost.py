"""Cost of one step of Solo-12 standing (dt 1e-3, velocity scheme, hard contacts), split by stage,
and MuJoCo's step on the same robot in the same run when MuJoCo is installed (`pip install -e '.[bench]'`);
then Solo-12 in free fall (without contacts, and with its feet and the ground declared but far apart)
against a loop of pin.aba and semi-implicit integration.

Run:  python benchmarks/step_cost.py [--steps 3000] [--repeats 5]

Each engine's figure is the least of its repeats: these machines share their cores, and a busy
spell of a neighbour only ever adds time (the engines take turns within each repeat, so that every
one of them gets the same chances of a quiet spell).
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

import gaussim
from gaussim.bench.peers import mujoco_model

KP, KD = 5.0, 0.2
STAGES = ("dynamics", "collision", "assembly", "solve", "integrate")
FEET = ("FL", "FR", "HL", "HR")


def _standing_scene(robot: gaussim.Robot) -> gaussim.Scene:
    """Solo-12's four feet on the ground (friction 0.8)."""
    feet = [(f"{leg}_FOOT_0", "ground") for leg in FEET]
    return gaussim.Scene(robot, ground=gaussim.Ground(friction=0.8), contacts=feet)


def gaussim_cost(steps: int, **options) -> tuple[float, dict[str, float], float]:
    """(us per step, us per stage, max penetration [m]) after 1 s of settling."""
    robot = gaussim.load_robot("solo12")
    scene = _standing_scene(robot)
    sim = gaussim.Simulator(scene, gaussim.Options(**options))
    q_ref = robot.configuration("standing")
    state = sim.reset(q_ref)

    def tau(s):
        return KP * (q_ref[7:] - s.q[7:]) - KD * s.v[6:]

    for _ in range(1000):
        state = sim.step(state, tau(state))
    start = time.perf_counter()
    for _ in range(steps):
        state = sim.step(state, tau(state))
    total = (time.perf_counter() - start) / steps * 1e6
    split, penetration = dict.fromkeys((*STAGES, "other"), 0.0), 0.0
    timed = gaussim.Simulator(scene, gaussim.Options(**options, timings=True))  # steps that time their stages
    for _ in range(steps):  # reading the reports (stage timings, forces) is outside each step's time
        torque = tau(state)
        start = time.perf_counter()
        state = timed.step(state, torque)
        split["other"] += time.perf_counter() - start  # the whole step, less its stages below
        report = timed.last_step
        for stage, seconds in report.timings.items():
            split[stage] += seconds
            split["other"] -= seconds
        penetration = max(penetration, max((-c.gap for c in report.contacts), default=0.0))
    return total, {k: v / steps * 1e6 for k, v in split.items()}, penetration


def free_flight_cost(steps: int) -> tuple[float, float, float]:
    """(gaussim's us per step with no contact declared, the same with the four feet and the ground
    declared but the robot far above it, a loop of pin.aba + semi-implicit integration's) for Solo-12
    in free fall under zero torques: the issue's free-flight target is 1.2x the loop."""
    import pinocchio as pin

    robot = gaussim.load_robot("solo12")
    q0 = robot.configuration("standing")
    q0[2] += 100.0  # 3 s of fall take 44 m
    tau, dt = np.zeros(12), 1e-3
    costs = []
    for scene in (gaussim.Scene(robot), _standing_scene(robot)):
        sim = gaussim.Simulator(scene, gaussim.Options())
        for _ in range(200):  # warm-up (the first steps load the compiled kernels)
            sim.step(sim.reset(q0), tau)
        state = sim.reset(q0)
        start = time.perf_counter()
        for _ in range(steps):
            state = sim.step(state, tau)
        costs.append((time.perf_counter() - start) / steps * 1e6)
    model, data = robot.model, robot.model.createData()
    q, v, full = q0.copy(), np.zeros(model.nv), np.zeros(model.nv)
    start = time.perf_counter()
    for _ in range(steps):
        v = v + dt * pin.aba(model, data, q, v, full)
        q = pin.integrate(model, q, v * dt)
    return costs[0], costs[1], (time.perf_counter() - start) / steps * 1e6


def mujoco_cost(robot: gaussim.Robot, steps: int, solver: str) -> tuple[float, float]:
    """(us per step, max penetration [m]) of MuJoCo on Solo-12 standing under the same PD hold."""
    import mujoco

    model = mujoco_model(robot)
    model.opt.solver = {"Newton": mujoco.mjtSolver.mjSOL_NEWTON, "PGS": mujoco.mjtSolver.mjSOL_PGS}[solver]
    data = mujoco.MjData(model)
    q_ref = robot.configuration("standing")
    data.qpos[:3] = q_ref[:3]
    data.qpos[3:7] = [q_ref[6], *q_ref[3:6]]  # Pinocchio xyzw -> MuJoCo wxyz
    data.qpos[7:] = q_ref[7:]
    for _ in range(1000):
        data.qfrc_applied[6:] = KP * (q_ref[7:] - data.qpos[7:]) - KD * data.qvel[6:]
        mujoco.mj_step(model, data)
    start = time.perf_counter()
    for _ in range(steps):
        data.qfrc_applied[6:] = KP * (q_ref[7:] - data.qpos[7:]) - KD * data.qvel[6:]
        mujoco.mj_step(model, data)
    total = (time.perf_counter() - start) / steps * 1e6
    penetration = 0.0
    for _ in range(steps):  # untimed, as for gaussim: reading the contacts costs MuJoCo up to 8 us a step
        data.qfrc_applied[6:] = KP * (q_ref[7:] - data.qpos[7:]) - KD * data.qvel[6:]
        mujoco.mj_step(model, data)
        if data.ncon:
            penetration = max(penetration, -float(data.contact.dist.min()))
    return total, penetration


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=5, help="the least of this many runs is reported")
    args = parser.parse_args(argv)

    try:
        import mujoco  # noqa: F401

        peers = ("Newton", "PGS")
    except ImportError:
        peers = ()
        print("MuJoCo is not installed (pip install -e '.[bench]'): no peer in this run.\n")
    robot = gaussim.load_robot("solo12")
    # the engines take turns within each repeat (see the module docstring)
    runs, acc, peer_runs = [], [], {solver: [] for solver in peers}  # type: ignore[var-annotated]
    for _ in range(args.repeats):
        runs.append(gaussim_cost(args.steps))
        acc.append(gaussim_cost(args.steps, scheme="acceleration"))
        for solver in peers:
            peer_runs[solver].append(mujoco_cost(robot, args.steps, solver))
    free = [free_flight_cost(args.steps) for _ in range(args.repeats)]
    total, split, _ = min(runs, key=lambda r: r[0])  # the split of the same repeat
    rows = [
        ("gaussim (velocity, accurate friction)", total, max(r[2] for r in runs)),
        ("gaussim (acceleration scheme)", min(r[0] for r in acc), max(r[2] for r in acc)),
    ]
    for solver, peer in peer_runs.items():
        rows.append((f"MuJoCo {solver} (pyramidal)", min(p[0] for p in peer), max(p[1] for p in peer)))

    print("Solo-12 standing, dt = 1 ms, 4 foot contacts, PD posture hold\n")
    print("| engine | us/step | ratio to MuJoCo Newton | max penetration [mm] |")
    print("|---|---:|---:|---:|")
    reference = next((r[1] for r in rows if r[0].startswith("MuJoCo Newton")), None)
    for name, cost, pen in rows:
        ratio = f"{cost / reference:.2f}" if reference else "n/a"
        print(f"| {name} | {cost:.1f} | {ratio} | {1e3 * pen:.4f} |")
    print("\ngaussim split (velocity scheme; Options(timings=True), whose marks add to it), us/step:\n")
    print("| " + " | ".join(split) + " | total |")
    print("|" + "---:|" * (len(split) + 1))
    print("| " + " | ".join(f"{us:.1f}" for us in split.values()) + f" | {sum(split.values()):.1f} |")
    bare, flying, loop = (min(f[i] for f in free) for i in range(3))
    print("\nSolo-12 in free fall, us/step:\n")
    print("| engine | us/step | ratio to the loop |\n|---|---:|---:|")
    print(f"| gaussim, no contact declared | {bare:.1f} | {bare / loop:.2f} |")
    print(f"| gaussim, feet and ground declared, none touching | {flying:.1f} | {flying / loop:.2f} |")
    print(f"| pin.aba + integrate loop | {loop:.1f} | 1.00 |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
