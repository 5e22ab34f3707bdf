"""The ``gaussim`` command: run, inspect and export simulations described by scene files.

Exit codes: 0 ok, 2 bad input (the message names the file and key), 1 a simulation failure
(the message gives the step, the time and the cause; the log of the steps made is kept).
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import re
import signal
import sys
import time
import tomllib
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn, TextIO

from .exceptions import (
    ContactError,
    GaussimError,
    GaussimWarning,
    InvalidOptions,
    InvalidState,
    SolverError,
)
from .files import atomic_path, check_folder, check_writable
from .options import FRICTION_MODES, SCHEMES
from .stops import STOP_SIGNALS, interrupt, taken_stop

if TYPE_CHECKING:
    from .scene import Scene
    from .scenefile import SceneSpec
    from .study import Run
    from .world import BodyLayout

EXIT_OK, EXIT_FAILURE, EXIT_BAD_INPUT = 0, 1, 2
# what stops a simulation midway (the other GaussimErrors are bad input)
SIMULATION_FAILURES = (SolverError, ContactError)
# the contact pairs of two bodies that `gaussim inspect` names (the others are counted)
PAIRS_SHOWN = 6
# a replay page's name ends in one of these (another may be the scene, mistyped)
PAGE_SUFFIXES = (".html", ".htm")
# control characters (but newline and tab): a name in a file must not drive the terminal
_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f]")


def _printable(text: object) -> str:
    """``text`` with its control characters (terminal escape codes) shown escaped, as repr does."""
    return _CONTROL.sub(lambda m: repr(m[0])[1:-1], str(text))


def _say(text: object, file: TextIO | None = None) -> None:
    print(_printable(text), file=file or sys.stdout)


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("gaussim")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "(not installed)"


class _Parser(argparse.ArgumentParser):
    """argparse's parser, whose "expected one argument" says how to give a value that starts with
    '-' (argparse takes "-1e-3" for an option)."""

    def error(self, message: str) -> NoReturn:
        given = re.fullmatch(r"argument (\S+?)(?:/(\S+))?: expected one argument", message)
        if given:
            message += f" (if its value starts with '-', write {given[2] or given[1]}=VALUE)"
        super().error(message)


def main(argv: list[str] | None = None) -> int:
    parser = _Parser(prog="gaussim", description="Robot simulation by the Gauss principle.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    commands = parser.add_subparsers(dest="command", required=True)

    run = commands.add_parser("run", help="simulate a scene file, write its log and print a summary")
    run.add_argument(
        "scene",
        type=Path,
        help="scene file (TOML), or the name of a shipped one (robots/scenes: solo12_standing, ...); or a "
        "robot (a URDF, MJCF or SDF file, or a name such as solo12), run in a scene of its own",
    )
    run.add_argument(
        "--out",
        type=Path,
        help="run log directory (one already there is kept as OUT.prev); default out/<scene>.runlog",
    )
    run.add_argument("--dt", type=float, help="time step [s] (overrides the scene's)")
    run.add_argument("--scheme", choices=SCHEMES, help="Gauss problem's level (overrides the scene's)")
    run.add_argument("--friction-mode", choices=FRICTION_MODES, help="friction model (overrides the scene's)")
    run.add_argument("--duration", type=float, help="simulated time [s]")
    run.add_argument("--quiet", action="store_true", help="no progress line")
    run.add_argument("--view", action="store_true", help="show the run live in the browser (meshcat)")
    run.add_argument("--speed", type=float, help="with --view: times real time (default 1)")
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
    replay.add_argument("log", type=Path, help="run log directory (written by gaussim run)")
    replay.add_argument("--html", type=Path, help="write a self-contained page instead of serving it live")
    replay.add_argument("--speed", type=float, default=1.0, help="times real time (default 1)")
    replay.add_argument("--fps", type=float, default=30.0, help="animation frames per second (default 30)")
    _arrow_option(replay)

    plot = commands.add_parser(
        "plot", help="plot a run log: contact forces, friction, gaps, solver; or energy"
    )
    plot.add_argument("log", type=Path, help="run log directory (written by gaussim run)")
    plot.add_argument("-o", "--output", type=Path, required=True, help="image file (PNG, PDF or SVG)")
    plot.add_argument(
        "--what", choices=("forces", "energy"), default="forces", help="which plot (default forces)"
    )
    plot.add_argument(
        "--bodies", nargs="+", metavar="NAME", help="forces of these bodies' (or obstacles') contacts only"
    )

    inspect = commands.add_parser(
        "inspect", help="describe a scene's robot, constraints and QP size; or a run log and its scene"
    )
    inspect.add_argument(
        "scene", type=Path, help="scene file (TOML), a robot (see gaussim run), or a run log"
    )

    forces = commands.add_parser("forces", help="export the per-contact force time series of a run log")
    forces.add_argument("log", type=Path, help="run log directory (written by gaussim run)")
    target = forces.add_mutually_exclusive_group(required=True)
    target.add_argument(
        "--csv", type=Path, help="CSV file: one row per contact per step, units in the header"
    )
    target.add_argument(
        "--parquet", type=Path, help="Parquet file, the same columns (needs pandas and pyarrow)"
    )

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
    bench.add_argument(
        "--report",
        type=Path,
        help="markdown report (default: OUT/benchmarks.md); with --scenes or --motion: its section there",
    )
    mode = bench.add_mutually_exclusive_group()
    mode.add_argument(
        "--scenes", action="store_true", help="the speed suite instead: CASES are its scenes (see --list)"
    )
    mode.add_argument(
        "--motion", action="store_true", help="matched accuracy on motion instead: CASES are its tasks"
    )

    stability = commands.add_parser("stability", help="run the stability cases and write their table")
    stability.add_argument("--long", action="store_true", help="add the long cases (1e6 steps, tiny dt)")
    stability.add_argument("--report", type=Path, default=Path("out/stability.md"), help="markdown table")

    sweep = commands.add_parser(
        "sweep",
        help="run a scene over every combination of values of its fields (a parameter study)",
        description="Run SCENE once per combination of the --vary values (and per seed), each run's log "
        "and summary kept in OUT, the summaries gathered in OUT/results.parquet. Started again, it skips "
        "the runs OUT holds. See docs/sweeps.md.",
    )
    sweep.add_argument("scene", type=Path, help="a scene file (TOML), or a robot (see gaussim run)")
    sweep.add_argument(
        "--vary",
        action="append",
        default=[],
        metavar="KEY=VALUES",
        help="a scene-file field and its values, TOML separated by commas: ground.friction=0.2,0.5, "
        "options.dt=1e-3,2e-3, bodies.crate.mass=1,2,4, control.kp=5,10, initial.q[2]=0.5,1, "
        "bodies.crate.position=[0,0,0.3],[0,0,0.5] (repeat --vary for more keys; at least one, or --seeds)",
    )
    sweep.add_argument(
        "--seeds",
        type=int,
        default=0,
        metavar="N",
        help="run each combination with seeds 0..N-1, its initial state perturbed",
    )
    sweep.add_argument(
        "--position-noise",
        type=float,
        metavar="SIGMA",
        help="with --seeds: std of each floating base's start position along the ground [m] (default 1e-3)",
    )
    sweep.add_argument(
        "--velocity-noise",
        type=float,
        metavar="SIGMA",
        help="with --seeds: std added to each initial velocity coordinate [m/s, rad/s] (default 1e-2)",
    )
    sweep.add_argument("--out", type=Path, metavar="DIR", help="output folder (default out/<scene>.sweep)")
    sweep.add_argument("--workers", type=int, metavar="N", help="local processes (default: all cores)")
    sweep.add_argument("--scheduler", metavar="ADDRESS", help="run on a Dask cluster: its scheduler address")
    sweep.add_argument("--plot", metavar="SUMMARY", help="plot this summary column against --against")
    sweep.add_argument("--against", metavar="KEY", help="with --plot: a varied key (or seed)")
    sweep.add_argument(
        "--plot-file", type=Path, metavar="IMAGE", help="the plot's image (default OUT/SUMMARY-vs-KEY.png)"
    )
    sweep.add_argument("--quiet", action="store_true", help="no progress lines")

    args = parser.parse_args(argv)
    if argv is None:  # the command: gaussim's warnings told as its errors are (a caller's stay as they are)
        warnings.showwarning = _show_warning
    saved = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    for stop, default in saved.items():  # each stops as a Ctrl-C does: the viewers' servers stopped
        if default in (signal.SIG_DFL, signal.default_int_handler):
            signal.signal(stop, interrupt)
    try:
        commands_ = {
            "run": _run,
            "inspect": _inspect,
            "forces": _forces,
            "replay": _replay,
            "plot": _plot,
            "bench": _bench,
            "stability": _stability,
            "sweep": _sweep,
        }
        return commands_[args.command](args)
    except KeyboardInterrupt:
        _ignore_stops()
        print("gaussim: interrupted", file=sys.stderr)
        return EXIT_FAILURE
    except BrokenPipeError:  # stdout's reader left (`| head`): what it read stands, as with Unix tools
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no error at the exit's flush
        return EXIT_FAILURE
    except (OSError, GaussimError) as err:
        message, code = told(err)
        _say(f"gaussim: {message}", sys.stderr)
        return code
    finally:
        taken_stop()  # a stop this command had: none for a later run in the same process
        if argv is not None:  # called in-process (not as the command): its caller's handling as it was
            for s, handling in saved.items():
                signal.signal(s, handling)


def told(err: OSError | GaussimError) -> tuple[str, int]:
    """The one line and the exit status a command gives for ``err``: a write that failed midway (a full
    disk: the line names the file) or a failed simulation, 1; a user's mistake, 2."""
    if isinstance(err, OSError):
        where = f"{err.filename}: " if err.filename else ""
        return f"{where}{err.strerror or err}", EXIT_FAILURE
    if isinstance(err, SIMULATION_FAILURES):
        return f"simulation failed: {err}", EXIT_FAILURE
    return str(err), EXIT_BAD_INPUT


def _show_warning(message, category, filename, lineno, file=None, line=None):  # type: ignore[no-untyped-def]
    """``warnings.showwarning`` of the command: a GaussimWarning as ``gaussim: warning: ...`` (its
    message names the file, body or joint; where in gaussim it was raised is no help to a user)."""
    if issubclass(category, GaussimWarning):
        _say(f"gaussim: warning: {message}", sys.stderr if file is None else file)
    else:
        _SHOW_WARNING(message, category, filename, lineno, file, line)


_SHOW_WARNING = warnings.showwarning


def _ignore_stops() -> None:
    """From a stop on, more Ctrl-Cs (SIGTERM, SIGHUP) change nothing: the command only reports and exits
    (one landing later would end the process by the signal, its exit status lost)."""
    for repeated in STOP_SIGNALS:
        signal.signal(repeated, signal.SIG_IGN)


def _bench(args: argparse.Namespace) -> int:
    if args.scenes or args.motion:
        return _bench_suite(args)
    from .bench import CASES, run_bench
    from .pool import check_workers

    if args.list:
        for name, case in CASES.items():
            print(f"{name:18s} {case.error}")
        return 0
    check_workers(args.workers, "--workers")
    unknown = sorted(set(args.cases) - set(CASES))
    if unknown:
        raise InvalidOptions("cases", f"unknown {unknown}; known: {', '.join(CASES)}")
    check_folder(args.out, "--out")  # before the runs, not after them
    if args.report is not None:
        check_writable(args.report, "--report")

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


def _bench_suite(args: argparse.Namespace) -> int:
    """``gaussim bench --scenes`` (the speed suite) or ``--motion`` (matched accuracy on motion): the
    table on stdout, progress on stderr, and with ``--report`` a markdown file."""
    from .bench.provenance import made, python_loop

    if args.scenes:
        from .bench import scenes as suite
    else:
        from .bench import motion as suite  # type: ignore[no-redef]
    if args.list:
        for name, case in suite.SCENES.items():
            print(f"{name:14s} {case.about}")
        return 0
    unknown = sorted(set(args.cases) - set(suite.SCENES))
    if unknown:
        raise InvalidOptions("cases", f"unknown {unknown}; known: {', '.join(suite.SCENES)}")
    if args.report is not None:
        check_writable(args.report, "--report")  # before the suite, not after it
    flags = " --quick" if args.quick else ""
    command = f"gaussim bench --{'scenes' if args.scenes else 'motion'}{flags} {' '.join(args.cases)}".strip()
    before = python_loop()  # the machine's speed around the run: timings compare within one spell
    records = suite.run_suite(
        args.cases or None,
        quick=args.quick,
        peers=[] if args.no_peers else None,
        progress=lambda line: print(line, file=sys.stderr, flush=True),
    )
    after = python_loop()
    text = suite.markdown(records)
    print(text)
    if args.report:
        from .bench.scenes import write_section

        steps = {r["steps"] for r in records if "steps" in r}
        notes = [f"{steps.pop()} steps per scene"] if len(steps) == 1 else []
        notes += made((before, after))
        if args.quick:
            notes.append("short runs of a subset: the structure of the full run, timings indicative only")
        line = f"Made by `{command} --report {args.report}` ({'; '.join(notes)})."
        write_section(args.report, suite.TITLE, f"{suite.INTRO}\n\n{line}\n\n{text}")
        print(f"table: section '{suite.TITLE}' of {args.report}")
    return 0


def _sweep(args: argparse.Namespace) -> int:
    from .pool import check_scheduler, check_workers, exclusive
    from .study import Noise, plan, require_table, summary_columns

    require_table()  # before the runs, not after them
    check_workers(args.workers, "--workers")
    if args.scheduler is not None:
        check_scheduler(args.scheduler)
    vary = _vary(args.vary)
    noise = None
    if args.position_noise is not None or args.velocity_noise is not None:
        default = Noise()
        noise = Noise(
            default.position if args.position_noise is None else args.position_noise,
            default.velocity if args.velocity_noise is None else args.velocity_noise,
        )
    out = args.out or Path("out") / f"{args.scene.stem}.sweep"
    runs = plan(args.scene, vary, out, args.seeds, noise)
    check_folder(out, "--out")  # before the plot's default path in it is checked
    plot: tuple[str, str, Path] | None = None  # the summary, the key and the image
    if args.plot is not None or args.against is not None or args.plot_file is not None:
        from .plots import plot_path
        from .scenefile import load_scene

        if args.plot is None or args.against is None:
            raise InvalidOptions("--plot", "give both --plot SUMMARY and --against KEY")
        columns = summary_columns(load_scene(args.scene))
        if args.plot not in columns:
            raise InvalidOptions(
                "--plot", f"no summary column {args.plot!r}; the scene's: {', '.join(columns)}"
            )
        keys = [*vary, *(["seed"] if args.seeds else [])]
        if args.against not in keys:
            raise InvalidOptions(
                "--against", f"{args.against!r} is not varied; the varied: {', '.join(keys) or 'none'}"
            )
        plot = (
            args.plot,
            args.against,
            plot_path(args.plot_file or out / f"{args.plot}-vs-{args.against}.png", "--plot-file"),
        )
        check_writable(plot[2], "--plot-file")
    with exclusive(out):  # from the count of the finished runs to the table: a second sweep stops at once
        return _sweep_runs(args, runs, out, [*vary], plot)


def _sweep_runs(
    args: argparse.Namespace, runs: list[Run], out: Path, keys: list[str], plot: tuple[str, str, Path] | None
) -> int:
    """The runs of a sweep whose input is checked: those not in ``out`` made, the table written, the
    plot drawn."""
    from .study import study, write_table

    done_before = len(runs) - len({r.key for r in runs} - _finished(out))
    processes = args.workers or os.cpu_count() or 1
    workers = (
        "the Dask cluster" if args.scheduler else f"{processes} processes" if processes > 1 else "1 process"
    )
    print(
        f"gaussim: {len(runs)} runs, {done_before} already in {out}, "
        f"{len(runs) - done_before} to run on {workers}",
        file=sys.stderr,
    )
    labels = {r.key: r.label for r in runs}
    started = time.perf_counter()

    def progress(done: int, total: int, record: dict) -> None:
        if args.quiet:
            return
        elapsed = time.perf_counter() - started
        left = elapsed / done * (total - done)
        _say(
            f"[{done}/{total}] {labels[record['key']]}: {record['status']}"
            f"  ({elapsed:.0f} s, ~{left:.0f} s left)",
            sys.stderr,
        )

    try:
        records = study(runs, out, args.workers, args.scheduler, progress)
    except KeyboardInterrupt:
        _ignore_stops()
        print(
            f"gaussim: interrupted; {len(_finished(out) & set(labels))} of {len(runs)} runs are kept in "
            f"{out}: the same command again runs the others",
            file=sys.stderr,
        )
        return EXIT_FAILURE
    path = write_table(records, out)
    failed = [r for r in records if r["status"] != "ok"]
    for r in failed:
        _say(f"failed: {labels[r['key']]}: {r['status']}", sys.stderr)
    print(f"{len(records)} runs, {len(failed)} failed; table: {path}; run logs: {out / 'runs'}")
    if plot is not None:
        from .plots import save_sweep_plot
        from .study import rows

        print(f"plot: {save_sweep_plot(rows(records), plot[0], plot[1], keys, plot[2])}")
    return EXIT_FAILURE if failed else EXIT_OK


def _vary(texts: list[str]) -> dict[str, list]:
    """The --vary options as {key: values}; a key given twice is an error."""
    from .study import parse_vary

    vary: dict[str, list] = {}
    for text in texts:
        key, values = parse_vary(text)
        if key in vary:
            raise InvalidOptions(f"--vary {key}", "given twice: list all its values in one --vary")
        vary[key] = values
    return vary


def _finished(out: Path) -> set[str]:
    """The keys of the runs a sweep's folder holds."""
    from .pool import load
    from .study import RESULTS

    return {r["key"] for r in load(out / RESULTS) if "key" in r}


def _stability(args: argparse.Namespace) -> int:
    from .bench.stability import cases, markdown

    check_writable(args.report, "--report")  # before the cases, not after them
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
    from .runlog import check_replaceable, is_run_log
    from .runner import (
        CHECKPOINT_STEPS,
        Interrupted,
        LogWriteError,
        announce,
        compile_notice,
        run,
    )
    from .scenefile import load_scene, names_robot

    if args.plot:
        from .plots import plot_path

        plot_path(args.plot, "--plot")  # before the run, not after it
    if args.dt is not None:
        _positive("--dt", args.dt)
    if args.out is not None and args.out.suffix == ".npz":  # else a folder named like a file
        folder = args.out.with_suffix(".runlog")
        raise InvalidOptions(
            "--out",
            f"{args.out}: a run log is a folder of chunks written as the run goes (kept whatever stops "
            f"it), not one .npz file; name it without .npz (e.g. {folder}), then write one file from it "
            f"with gaussim.RunLog.load('{folder}').save('{args.out}')",
        )
    for flag, given in (("--speed", args.speed is not None), ("--no-wait", args.no_wait)):
        if given and not args.view:  # else ignored without a word
            raise InvalidOptions(
                flag,
                "applies to a live view only: add --view (a replay page's speed: gaussim replay --speed)",
            )
    # placing the robot on the ground compiles kernels too
    with compile_notice(None if args.quiet else functools.partial(announce, sys.stderr)):
        spec = load_scene(args.scene, dt=args.dt, scheme=args.scheme, friction_mode=args.friction_mode)
    if args.duration is not None:
        _positive("--duration", args.duration)
        spec.duration = args.duration
    out = args.out or Path("out") / f"{args.scene.stem}.runlog"
    if names_robot(args.scene):
        told = _robot_scene_file(spec.text, out.with_suffix(".toml"))
        _say(f"gaussim: {args.scene} is a robot, not a scene file: {told}", sys.stderr)
    started = time.time()
    checkpoint_steps = CHECKPOINT_STEPS if args.checkpoint_steps is None else args.checkpoint_steps
    if checkpoint_steps < 1:
        raise InvalidOptions("--checkpoint-steps", f"must be >= 1, got {args.checkpoint_steps}")
    # before the run, not after it
    if args.html is not None:
        check_writable(args.html, "--html", PAGE_SUFFIXES)
    if args.plot is not None:
        check_writable(args.plot, "--plot")
    if args.force_scale is not None:
        _positive("--force-scale", args.force_scale)
    check_replaceable(out)  # before saying the log there is kept: it may be refused
    if is_run_log(out):
        print(f"gaussim: {out} holds a run log: it will be kept as {out}.prev", file=sys.stderr)
    viewer = None
    if args.view:
        from .viewer import Viewer, follow

        speed = 1.0 if args.speed is None else args.speed
        _positive("--speed", speed)
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
            observer=follow(viewer, speed) if viewer else None,
        )
        done = True
    except Interrupted as stop:
        _ignore_stops()
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
    except KeyboardInterrupt:  # a Ctrl-C before the run began, or one that landed as its stop surfaced
        _ignore_stops()
        written = is_run_log(out) and out.stat().st_mtime >= started - 1.0  # (a coarse clock's second)
        where = f"the log of the steps made is in {out}" if written else "no log written"
        print(f"gaussim: interrupted; {where}", file=sys.stderr)
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


def _robot_scene_file(text: str, path: Path) -> str:
    """Write the scene of a robot run by itself (``text``) to ``path``, unless a different file is
    there (a user's edit of the last one); returns what the run tells of it."""
    said = "it runs in the scene gaussim writes for it (its first lines say what it holds)"
    if path.is_file() and (there := path.read_text()) != text:
        other = _scene_robot(there)
        if other != _scene_robot(text):  # not this robot's scene edited: running it runs something else
            return (
                f"{said}; {path} is {'the scene of ' + other if other else 'another scene'}, not of this "
                "robot: it is left as it is, and this robot's scene is not written (it goes beside the run "
                "log: give --out another name)"
            )
        return f"{said}; {path}, which differs from it, is left as it is (run that file to use it)"
    check_writable(path, "scene")
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return f"{said}, written to {path}: edit it and run that file"


def _scene_robot(text: str) -> str | None:
    """The robot a scene file's ``[robot]`` table loads (``urdf = "PATH"``, ``name = "NAME"``, ...), or None
    (no such table, or no TOML)."""
    try:
        robot = tomllib.loads(text).get("robot")
    except tomllib.TOMLDecodeError:
        return None
    if not isinstance(robot, dict):
        return None
    return next(
        (f"{key} = {json.dumps(robot[key])}" for key in ("urdf", "mjcf", "sdf", "name") if key in robot), None
    )


def _arrow_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--force-scale", type=float, help="force arrow length per newton [m/N]; default: the weight is 0.25 m"
    )


def _positive(flag: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0):
        raise InvalidOptions(flag, f"must be a finite number > 0, got {value}")


def _read_log(path: Path):  # type: ignore[no-untyped-def]
    """The run log at ``path``; said on stderr when its run did not finish (a user reads it as a whole)."""
    from .runlog import RunLog

    log = RunLog.load(path)
    if not log.complete:
        _say(
            f"gaussim: note: {path} holds the {log.steps} steps of a run that did not finish: {log.reason}",
            sys.stderr,
        )
    return log


def _log_and_scene(path: Path):  # type: ignore[no-untyped-def]
    """A run log and the scene it was made from (its scene text is stored in it)."""
    log = _read_log(path)
    if log.steps == 0:
        raise GaussimError(f"{path}: the run log holds no step")
    return log, _log_spec(path, log).scene


def _log_spec(path: Path, log) -> SceneSpec:  # type: ignore[no-untyped-def]
    """The scene file a run log was made from (the text it stores), with the options the run used."""
    from .scenefile import load_scene_text

    try:
        spec = load_scene_text(log.scene_text, log.scene_path or path)
    except GaussimError as err:
        raise GaussimError(f"{path}: the scene this log holds does not load: {err}") from err
    spec.options = log.options  # a run's --dt, --scheme, --friction-mode
    return spec


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
    if args.force_scale is not None:
        _positive("--force-scale", args.force_scale)
    if args.html:
        check_writable(args.html, "--html", PAGE_SUFFIXES)
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
        _ignore_stops()
        print("gaussim: viewer stopped", file=sys.stderr)


def _plot(args: argparse.Namespace) -> int:
    from .plots import plot_path, save_plot

    plot_path(args.output, "--output")
    check_writable(args.output, "--output")
    log, scene = _log_and_scene(args.log)
    print(f"{args.what} plot: {save_plot(log, scene, args.output, args.what, args.bodies)}")
    return EXIT_OK


def _inspect(args: argparse.Namespace) -> int:
    import numpy as np

    from .runlog import is_run_log
    from .scenefile import load_scene
    from .simulator import Simulator

    if is_run_log(args.scene):  # a log: what it holds, then the scene it was made from
        from .runlog import RunLog

        log = RunLog.load(args.scene)
        t = log.t
        status = "complete" if log.complete else f"INCOMPLETE: {log.reason}"
        _say(f"run log {args.scene}: {log.steps} steps, t = {t[0]:.6g} to {t[-1]:.6g} s; {status}")
        if not log.scene_text.strip():
            _say("  no scene file stored (a log written from Python without its scene's text)")
            return EXIT_OK
        _say(f"  made from {log.scene_path or 'a scene file'}, with its options; that scene:")
        spec = _log_spec(args.scene, log)
    else:
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
    damped, rubbing = int(np.count_nonzero(model.damping)), int(np.count_nonzero(model.friction))
    given = f"the files give damping to {damped} coordinates, dry friction to {rubbing}"
    _say(f"  joint friction: {'on' if scene.joint_friction else 'off'} ({given})")
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
    actuated = len(layout.actuated)
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
    from .runlog import write_forces

    path, kind = (args.csv, "csv") if args.csv else (args.parquet, "parquet")
    check_writable(path, f"--{kind}", (f".{kind}",))
    rows = write_forces(_read_log(args.log), path, kind)
    print(f"{rows} rows written to {path}")
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
