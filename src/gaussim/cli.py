"""The ``gaussim`` command: run, inspect and export simulations described by scene files.

Exit codes: 0 ok, 2 bad input (the message names the file and key), 1 a simulation failure
(the message gives the step, the time and the cause; the log of the steps made is kept).
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

from .exceptions import GaussimError, InvalidOptions, InvalidRobot, InvalidState, SolverError
from .options import FRICTION_MODES, SCHEMES

EXIT_OK, EXIT_FAILURE, EXIT_BAD_INPUT = 0, 1, 2


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="gaussim", description="Robot simulation by the Gauss principle.")
    commands = parser.add_subparsers(dest="command", required=True)

    run = commands.add_parser("run", help="simulate a scene file, write its log and print a summary")
    run.add_argument("scene", type=Path)
    run.add_argument("--out", type=Path, help="run log (.npz); default out/<scene>.npz")
    run.add_argument("--dt", type=float, help="time step [s] (overrides the scene's)")
    run.add_argument("--scheme", choices=SCHEMES)
    run.add_argument("--friction-mode", choices=FRICTION_MODES)
    run.add_argument("--duration", type=float, help="simulated time [s]")
    run.add_argument("--quiet", action="store_true", help="no progress line")

    inspect = commands.add_parser("inspect", help="describe a scene's robot, constraints and QP size")
    inspect.add_argument("scene", type=Path)

    forces = commands.add_parser("forces", help="export the per-contact force time series of a run log")
    forces.add_argument("log", type=Path)
    target = forces.add_mutually_exclusive_group(required=True)
    target.add_argument("--csv", type=Path)
    target.add_argument("--parquet", type=Path, help="needs pandas and pyarrow")

    args = parser.parse_args(argv)
    try:
        return {"run": _run, "inspect": _inspect, "forces": _forces}[args.command](args)
    except KeyboardInterrupt:
        print("gaussim: interrupted; the log of the steps made was written", file=sys.stderr)
        return EXIT_FAILURE
    except SolverError as err:
        print(f"gaussim: simulation failed: {err}", file=sys.stderr)
        return EXIT_FAILURE
    except (InvalidOptions, InvalidRobot, InvalidState, GaussimError) as err:
        print(f"gaussim: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT


def _run(args: argparse.Namespace) -> int:
    from .runner import run
    from .scenefile import load_scene

    spec = load_scene(args.scene, dt=args.dt, scheme=args.scheme, friction_mode=args.friction_mode)
    if args.duration is not None:
        if not args.duration > 0:
            raise InvalidOptions("--duration", f"must be > 0, got {args.duration}")
        spec.duration = args.duration
    out = args.out or Path("out") / f"{args.scene.stem}.npz"
    try:
        log = run(spec, out, progress=None if args.quiet else sys.stderr)
    except SolverError as err:
        print(f"gaussim: simulation failed: {err}\ngaussim: the steps made are in {out}", file=sys.stderr)
        return EXIT_FAILURE
    print(log.summary())
    print(f"\nrun log: {out}")
    return EXIT_OK


def _inspect(args: argparse.Namespace) -> int:
    import numpy as np

    from .scenefile import load_scene
    from .simulator import Simulator

    spec = load_scene(args.scene)
    robot, scene, o = spec.robot, spec.scene, spec.options
    model = robot.model
    print(f"robot {robot.name} ({robot.urdf})")
    print(f"  nq = {model.nq}, nv = {model.nv}, mass = {robot.mass:.3f} kg, floating base: {robot.floating}")
    print(f"  frames: {', '.join(f.name for f in model.frames)}")
    print(f"  collision geometries: {', '.join(g.name for g in robot.collision_model.geometryObjects)}")
    limited = [
        f"{model.names[j]} [{model.lowerPositionLimit[model.joints[j].idx_q]:.3g}, "
        f"{model.upperPositionLimit[model.joints[j].idx_q]:.3g}]"
        for j in range(1, model.njoints)
        if model.joints[j].nq == 1 and np.isfinite(model.upperPositionLimit[model.joints[j].idx_q])
    ]
    print(f"  joint limits: {', '.join(limited) or 'none'}")
    print("constraints (only these are built):")
    print(f"  obstacles: {', '.join(ob.name for ob in scene.obstacles) or 'none'}")
    print(f"  contact pairs: {len(scene.pairs)}: {', '.join(p.name for p in scene.pairs)}")
    print(f"  joint limits: {'on' if scene.joint_limits else 'off'}")
    for b in scene.bilaterals:
        print(f"  {b.name}")
    sim = Simulator(scene, o)
    print(f"modules: {', '.join(m.name for m in sim.modules) or 'none'}")
    facets = o.friction_facets
    bilateral_rows = sum(
        6 if getattr(b, "rotation", None) is not None or getattr(b, "orientation", False) else 3
        for b in scene.bilaterals
    )
    limit_rows = 2 * len(limited) if scene.joint_limits else 0
    print(
        f"QP per step ({o.scheme} scheme): {model.nv} unknowns; up to {facets} rows per contact point, "
        f"up to {limit_rows} limit rows, {bilateral_rows} bilateral rows"
    )
    print(f"options: dt = {o.dt} s, friction {o.friction_mode} ({facets} facets), duration {spec.duration} s")
    return EXIT_OK


def _forces(args: argparse.Namespace) -> int:
    from .runlog import RunLog

    log = RunLog.load(args.log)
    if args.csv:
        columns = log.contact_records()
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        with args.csv.open("w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(columns)
            writer.writerows(zip(*columns.values()))
        print(f"{len(columns['t'])} rows written to {args.csv}")
    else:
        frame = log.contact_forces()
        try:
            frame.to_parquet(args.parquet)
        except ImportError as err:
            raise GaussimError(f"--parquet needs pyarrow: pip install pyarrow ({err})") from err
        print(f"{len(frame)} rows written to {args.parquet}")
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
