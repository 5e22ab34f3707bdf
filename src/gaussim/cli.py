"""The ``gaussim`` command: run, inspect and export simulations described by scene files.

Exit codes: 0 ok, 2 bad input (the message names the file and key), 1 a simulation failure
(the message gives the step, the time and the cause; the log of the steps made is kept).
"""

from __future__ import annotations

import argparse
import csv
import math
import re
import signal
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from .exceptions import ContactError, GaussimError, InvalidOptions, InvalidRobot, InvalidState, SolverError
from .files import atomic_path, check_writable
from .options import FRICTION_MODES, SCHEMES

if TYPE_CHECKING:
    from .scene import Scene
    from .world import BodyLayout

EXIT_OK, EXIT_FAILURE, EXIT_BAD_INPUT = 0, 1, 2
# what stops a simulation midway (the other GaussimErrors are bad input)
SIMULATION_FAILURES = (SolverError, ContactError)
# the contact pairs of two bodies that `gaussim inspect` names (the others are counted)
PAIRS_SHOWN = 6
# control characters (but newline and tab): a name in a file must not drive the terminal
_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f]")


def _printable(text: object) -> str:
    """``text`` with its control characters (terminal escape codes) shown escaped, as repr does."""
    return _CONTROL.sub(lambda m: repr(m[0])[1:-1], str(text))


def _say(text: object, file: TextIO | None = None) -> None:
    print(_printable(text), file=file or sys.stdout)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="gaussim", description="Robot simulation by the Gauss principle.")
    commands = parser.add_subparsers(dest="command", required=True)

    run = commands.add_parser("run", help="simulate a scene file, write its log and print a summary")
    run.add_argument("scene", type=Path)
    run.add_argument(
        "--out",
        type=Path,
        help="run log directory (one already there is kept as OUT.prev); default out/<scene>.runlog",
    )
    run.add_argument("--dt", type=float, help="time step [s] (overrides the scene's)")
    run.add_argument("--scheme", choices=SCHEMES)
    run.add_argument("--friction-mode", choices=FRICTION_MODES)
    run.add_argument("--duration", type=float, help="simulated time [s]")
    run.add_argument("--quiet", action="store_true", help="no progress line")
    run.add_argument("--view", action="store_true", help="show the run live in the browser (meshcat)")
    run.add_argument("--speed", type=float, default=1.0, help="with --view: times real time (default 1)")
    run.add_argument(
        "--no-wait",
        action="store_true",
        help="with --view: exit when the run ends (by default the replay is served until Ctrl-C, "
        "or not at all when standard input is not a terminal)",
    )
    run.add_argument("--html", type=Path, help="also write the replay page (self-contained HTML)")
    run.add_argument("--plot", type=Path, help="also write the contact-force plot (PNG, PDF or SVG)")
    run.add_argument(
        "--checkpoint-steps",
        type=int,
        help="write the log's next chunk after this many steps (default 10000) or 5 s of wall time",
    )
    _arrow_option(run)

    replay = commands.add_parser("replay", help="replay a run log in the browser, live or as an HTML page")
    replay.add_argument("log", type=Path)
    replay.add_argument("--html", type=Path, help="write a self-contained page instead of serving it live")
    replay.add_argument("--speed", type=float, default=1.0, help="times real time (default 1)")
    replay.add_argument("--fps", type=float, default=30.0, help="animation frames per second (default 30)")
    _arrow_option(replay)

    plot = commands.add_parser(
        "plot", help="plot a run log: contact forces, friction, gaps, solver; or energy"
    )
    plot.add_argument("log", type=Path)
    plot.add_argument("-o", "--output", type=Path, required=True, help="image file (PNG, PDF or SVG)")
    plot.add_argument("--what", choices=("forces", "energy"), default="forces")
    plot.add_argument(
        "--bodies", nargs="+", metavar="NAME", help="forces of these bodies' (or obstacles') contacts only"
    )

    inspect = commands.add_parser("inspect", help="describe a scene's robot, constraints and QP size")
    inspect.add_argument("scene", type=Path)

    forces = commands.add_parser("forces", help="export the per-contact force time series of a run log")
    forces.add_argument("log", type=Path)
    target = forces.add_mutually_exclusive_group(required=True)
    target.add_argument("--csv", type=Path)
    target.add_argument("--parquet", type=Path, help="needs pandas and pyarrow")

    bench = commands.add_parser(
        "bench", help="sweep the speed-accuracy knobs over the reference cases, against peers if installed"
    )
    bench.add_argument("cases", nargs="*", help="cases to run (default: all; see --list)")
    bench.add_argument("--quick", action="store_true", help="a few cases and knobs, short runs (< 2 min)")
    bench.add_argument("--out", type=Path, default=Path("out/bench"), help="results, tables, plots")
    bench.add_argument("--workers", type=int, help="local processes (default: all cores)")
    bench.add_argument("--scheduler", help="run on a Dask cluster: its scheduler address")
    bench.add_argument("--no-peers", action="store_true", help="gaussim only")
    bench.add_argument("--list", action="store_true", help="list the cases and what their error measures")
    bench.add_argument("--report", type=Path, help="markdown report (default: OUT/benchmarks.md)")

    stability = commands.add_parser("stability", help="run the stability cases and write their table")
    stability.add_argument("--long", action="store_true", help="add the long cases (1e6 steps, tiny dt)")
    stability.add_argument("--report", type=Path, default=Path("out/stability.md"), help="markdown table")

    args = parser.parse_args(argv)
    for stop in (signal.SIGTERM, signal.SIGHUP):  # stop as a Ctrl-C does: the viewers' servers stopped
        if signal.getsignal(stop) == signal.SIG_DFL:
            signal.signal(stop, signal.default_int_handler)
    try:
        commands_ = {
            "run": _run,
            "inspect": _inspect,
            "forces": _forces,
            "replay": _replay,
            "plot": _plot,
            "bench": _bench,
            "stability": _stability,
        }
        return commands_[args.command](args)
    except KeyboardInterrupt:
        print("gaussim: interrupted", file=sys.stderr)
        return EXIT_FAILURE
    except OSError as err:  # a write that failed midway (a full disk): the message names the file
        where = f"{err.filename}: " if err.filename else ""
        print(f"gaussim: {where}{err.strerror or err}", file=sys.stderr)
        return EXIT_FAILURE
    except SIMULATION_FAILURES as err:
        _say(f"gaussim: simulation failed: {err}", sys.stderr)
        return EXIT_FAILURE
    except (InvalidOptions, InvalidRobot, InvalidState, GaussimError) as err:
        _say(f"gaussim: {err}", sys.stderr)
        return EXIT_BAD_INPUT


def _bench(args: argparse.Namespace) -> int:
    from .bench import CASES, run_bench

    if args.list:
        for name, case in CASES.items():
            print(f"{name:18s} {case.error}")
        return 0
    if args.workers is not None and args.workers < 1:
        raise InvalidOptions("--workers", f"must be >= 1, got {args.workers}")
    unknown = sorted(set(args.cases) - set(CASES))
    if unknown:
        raise InvalidOptions("cases", f"unknown {unknown}; known: {', '.join(CASES)}")

    def progress(done: int, total: int, record: dict) -> None:
        print(f"[{done}/{total}] {record['key']}: {record['status']}", file=sys.stderr, flush=True)

    records = run_bench(
        args.cases or None,
        args.out,
        quick=args.quick,
        peers=[] if args.no_peers else None,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=progress,
        report_path=args.report,
    )
    failed = [r for r in records if r["status"] != "ok"]
    report = args.report or args.out / "benchmarks.md"
    print(f"{len(records)} runs, {len(failed)} failed; tables and plots: {report}")
    return EXIT_FAILURE if failed else 0


def _stability(args: argparse.Namespace) -> int:
    from .bench.stability import cases, markdown

    rows = []
    for case in cases(args.long):
        row = case()
        rows.append(row)
        print(f"{'pass' if row.passed else 'FAIL'}  {row.case}, {row.setting}: {row.result}", file=sys.stderr)
    command = "gaussim stability" + (" --long" if args.long else "") + f" --report {args.report}"
    with atomic_path(args.report) as tmp:
        tmp.write_text(markdown(rows, command))
    failed = sum(not row.passed for row in rows)
    print(f"{len(rows)} cases, {failed} failed; table: {args.report}")
    return EXIT_FAILURE if failed else 0


def _run(args: argparse.Namespace) -> int:
    from .runlog import is_run_log
    from .runner import CHECKPOINT_STEPS, STOP_SIGNALS, Interrupted, LogWriteError, run
    from .scenefile import load_scene

    if args.plot:
        from .plots import plot_path

        plot_path(args.plot)  # before the run, not after it
    spec = load_scene(args.scene, dt=args.dt, scheme=args.scheme, friction_mode=args.friction_mode)
    if args.duration is not None:
        if not (math.isfinite(args.duration) and args.duration > 0):
            raise InvalidOptions("--duration", f"must be a finite number > 0, got {args.duration}")
        spec.duration = args.duration
    out = args.out or Path("out") / f"{args.scene.stem}.runlog"
    started = time.time()
    checkpoint_steps = CHECKPOINT_STEPS if args.checkpoint_steps is None else args.checkpoint_steps
    if checkpoint_steps < 1:
        raise InvalidOptions("--checkpoint-steps", f"must be >= 1, got {args.checkpoint_steps}")
    for flag, path in (("--html", args.html), ("--plot", args.plot)):
        if path is not None:
            check_writable(path, flag)  # before the run, not after it
    if is_run_log(out):
        print(f"gaussim: {out} holds a run log: it will be kept as {out}.prev", file=sys.stderr)
    viewer = None
    if args.view:
        from .viewer import Viewer, follow

        _positive("--speed", args.speed)
        viewer = Viewer(spec.scene, force_scale=args.force_scale)
        viewer.show(spec.initial.q, t=0.0)  # the page shows the scene while the kernels compile
        print(f"gaussim: watch the run at {viewer.url}", file=sys.stderr, flush=True)
    done = False
    try:
        log = run(
            spec,
            out,
            progress=None if args.quiet else sys.stderr,
            checkpoint_steps=checkpoint_steps,
            observer=follow(viewer, args.speed) if viewer else None,
        )
        done = True
    except Interrupted as stop:
        for repeated in STOP_SIGNALS:  # more Ctrl-Cs while we report change nothing: the log is written
            signal.signal(repeated, signal.SIG_IGN)
        print(f"gaussim: {stop}; the log of the steps made is in {out}", file=sys.stderr)
        return EXIT_FAILURE
    except LogWriteError as err:
        print(f"gaussim: {err}", file=sys.stderr)
        return EXIT_FAILURE
    except SIMULATION_FAILURES as err:
        _say(f"gaussim: simulation failed: {err}\ngaussim: the steps made are in {out}", sys.stderr)
        return EXIT_FAILURE
    except InvalidState as err:  # the scene's initial state or its controller's torques
        raise InvalidState(f"{args.scene}: {err}") from err
    except KeyboardInterrupt:
        written = is_run_log(out) and out.stat().st_mtime >= started - 1.0  # (a coarse clock's second)
        print(
            "gaussim: interrupted; " + (f"the steps made are in {out}" if written else "no log written"),
            file=sys.stderr,
        )
        return EXIT_FAILURE
    finally:
        if viewer is not None and not done:
            viewer.close()
    _say(log.summary())
    print(f"\nrun log: {out}")
    if args.html:
        print(f"replay page: {_write_replay(log, spec.scene, args.html, args.force_scale)}")
    if args.plot:
        from .plots import save_plot

        print(f"force plot: {save_plot(log, spec.scene, args.plot)}")
    if viewer is not None:
        with viewer:
            viewer.replay(log)  # at real time: the live page's clock shows animation time as simulated time
            if args.no_wait or not sys.stdin.isatty():
                why = "--no-wait" if args.no_wait else "standard input is not a terminal"
                print(f"gaussim: viewer closed ({why})", file=sys.stderr)
            else:
                _serve(f"the run's replay is at {viewer.url}")
    return EXIT_OK


def _arrow_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--force-scale", type=float, help="force arrow length per newton [m/N]; default: the weight is 0.25 m"
    )


def _positive(flag: str, value: float) -> None:
    if not value > 0:
        raise InvalidOptions(flag, f"must be > 0, got {value}")


def _log_and_scene(path: Path):  # type: ignore[no-untyped-def]
    """A run log and the scene it was made from (its scene text is stored in it)."""
    from .runlog import RunLog
    from .scenefile import load_scene_text

    log = RunLog.load(path)
    if log.steps == 0:
        raise GaussimError(f"{path}: the run log holds no step")
    try:
        return log, load_scene_text(log.scene_text, log.scene_path or path).scene
    except GaussimError as err:
        raise GaussimError(f"{path}: the scene this log holds does not load: {err}") from err


def _write_replay(
    log, scene, html: Path, force_scale: float | None, fps: float = 30.0, speed: float = 1.0
) -> Path:  # type: ignore[no-untyped-def]
    from .viewer import Viewer

    viewer = Viewer(scene, force_scale=force_scale, live=False)  # a page needs no server
    viewer.replay(log, fps=fps, speed=speed)
    return viewer.save_html(html)


def _replay(args: argparse.Namespace) -> int:
    from .viewer import Viewer

    _positive("--fps", args.fps)
    _positive("--speed", args.speed)
    if args.html:
        check_writable(args.html, "--html")
    log, scene = _log_and_scene(args.log)
    if args.html:
        print(f"replay page: {_write_replay(log, scene, args.html, args.force_scale, args.fps, args.speed)}")
        return EXIT_OK
    with Viewer(scene, force_scale=args.force_scale) as viewer:
        viewer.replay(log, fps=args.fps, speed=args.speed)
        _serve(f"replaying {args.log} at {viewer.url}")
    return EXIT_OK


def _serve(message: str) -> None:
    """Say ``message`` and wait for Ctrl-C (or SIGTERM, SIGHUP) while a live viewer serves its page."""
    print(f"{message} (Ctrl-C to stop)", flush=True)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        print("gaussim: viewer stopped", file=sys.stderr)


def _plot(args: argparse.Namespace) -> int:
    from .plots import plot_path, save_plot

    plot_path(args.output)
    check_writable(args.output, "--output")
    log, scene = _log_and_scene(args.log)
    print(f"{args.what} plot: {save_plot(log, scene, args.output, args.what, args.bodies)}")
    return EXIT_OK


def _inspect(args: argparse.Namespace) -> int:
    import numpy as np

    from .scenefile import load_scene
    from .simulator import Simulator

    spec = load_scene(args.scene)
    robot, scene, o = spec.robot, spec.scene, spec.options
    model = robot.model
    _say(f"robot {robot.name} ({robot.urdf or f'{len(scene.bodies)} bodies merged'})")
    _say(f"  nq = {model.nq}, nv = {model.nv}, mass = {robot.mass:.3f} kg, floating base: {robot.floating}")
    _say(f"  frames: {', '.join(f.name for f in model.frames)}")
    _say(f"  collision geometries: {', '.join(g.name for g in robot.collision_model.geometryObjects)}")
    limited = [
        f"{model.names[j]} [{model.lowerPositionLimit[model.joints[j].idx_q]:.3g}, "
        f"{model.upperPositionLimit[model.joints[j].idx_q]:.3g}]"
        for j in range(1, model.njoints)
        if model.joints[j].nq == 1 and np.isfinite(model.upperPositionLimit[model.joints[j].idx_q])
    ]
    _say(f"  joint limits: {', '.join(limited) or 'none'}")
    _say(f"bodies: {len(scene.bodies)}")
    for layout in scene.bodies.values():
        _say(f"  {_body_line(layout)}")
    _say("constraints (only these are built):")
    _say(f"  obstacles: {', '.join(ob.name for ob in scene.obstacles) or 'none'}")
    _say(f"  contact pairs: {len(scene.pairs)}")
    for (body, other), names in _pairs_by_body(scene).items():
        listed = ", ".join(names[:PAIRS_SHOWN])
        more = f", ... ({len(names) - PAIRS_SHOWN} more)" if len(names) > PAIRS_SHOWN else ""
        _say(f"    {body} - {other if other != body else 'itself'}: {len(names)}: {listed}{more}")
    _say(f"  joint limits: {'on' if scene.joint_limits else 'off'}")
    for b in scene.bilaterals:
        _say(f"  {b.name}")
    sim = Simulator(scene, o)
    _say(f"modules: {', '.join(m.name for m in sim.modules) or 'none'}")
    facets = o.friction_facets
    bilateral_rows = sum(
        6 if getattr(b, "rotation", None) is not None or getattr(b, "orientation", False) else 3
        for b in scene.bilaterals
    )
    limit_rows = 2 * len(limited) if scene.joint_limits else 0
    _say(
        f"QP per step ({o.scheme} scheme): {model.nv} unknowns; up to {facets} rows per contact point, "
        f"up to {limit_rows} limit rows, {bilateral_rows} bilateral rows"
    )
    _say(f"options: dt = {o.dt} s, friction {o.friction_mode} ({facets} facets), duration {spec.duration} s")
    return EXIT_OK


def _body_line(layout: BodyLayout) -> str:
    """One body of ``gaussim inspect``: what it is, its slices of q and v, its base and its mass."""
    from .world import FreeBody

    source, placement = layout.body.source, layout.body.placement
    if isinstance(source, FreeBody):
        size = (
            source.mesh_path if source.shape == "mesh" else " x ".join(f"{s:g}" for s in source.size) + " m"
        )
        what, base = f"{source.shape} {size}", "free body"
    else:
        what, base = f"robot {layout.robot.name}", "floating base" if layout.floating else "fixed base"
        if placement is not None:
            base += f" at ({', '.join(f'{x:.4g}' for x in placement.translation)}) m"
    actuated = layout.actuated.stop - layout.actuated.start
    return (
        f"{layout.name}: {what}; q[{layout.q.start}:{layout.q.stop}], v[{layout.v.start}:{layout.v.stop}]; "
        f"{base}, {actuated} actuated; mass {layout.robot.mass:.4g} kg"
    )


def _pairs_by_body(scene: Scene) -> dict[tuple[str, str], list[str]]:
    """A scene's contact pairs' names by the bodies (or body and obstacle) they are between."""
    groups: dict[tuple[str, str], list[str]] = {}
    for pair in scene.pairs:
        a = scene.world.owner(pair.geometry).name
        if pair.obstacle is not None:
            b = scene.obstacles[pair.obstacle].name
        else:
            assert pair.other is not None  # a pair of two geometries
            b = scene.world.owner(pair.other).name
        groups.setdefault((b, a) if (b, a) in groups else (a, b), []).append(pair.name)
    return groups


def _forces(args: argparse.Namespace) -> int:
    from .runlog import RunLog

    check_writable(args.csv or args.parquet, "--csv" if args.csv else "--parquet")
    log = RunLog.load(args.log)
    if args.csv:
        columns = log.contact_records()
        with atomic_path(args.csv) as tmp, tmp.open("w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(columns)
            writer.writerows(zip(*columns.values()))
        print(f"{len(columns['t'])} rows written to {args.csv}")
    else:
        frame = log.contact_forces()
        try:
            with atomic_path(args.parquet) as tmp:
                frame.to_parquet(tmp)
        except ImportError as err:
            raise GaussimError(f"--parquet needs pyarrow: pip install pyarrow ({err})") from err
        print(f"{len(frame)} rows written to {args.parquet}")
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
