"""Run logs: complete round trips, and nothing lost when a run stops early."""

import csv
import dataclasses
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import gaussim
from gaussim.files import OutputError
from gaussim.runlog import WRITING, RunLogError

SCENES = Path(__file__).resolve().parents[1] / "robots" / "scenes"


def _short(name, steps=100):
    spec = gaussim.load_scene(SCENES / f"{name}.toml")
    spec.duration = steps * spec.options.dt
    return spec


def test_log_round_trip(tmp_path):
    out = tmp_path / "run.npz"
    log = gaussim.run(_short("box_incline"), out)
    loaded = gaussim.RunLog.load(out)
    assert loaded.complete and loaded.steps == log.steps == 100
    np.testing.assert_array_equal(loaded.q, log.q)
    np.testing.assert_array_equal(loaded.tau, log.tau)
    assert loaded.contact_records() == log.contact_records()
    assert loaded.options == log.options and "[ground]" in loaded.scene_text
    # a step's status is stored as its Status value, a plain string that old logs hold too
    stored = loaded.solver_arrays()["status"]
    assert stored.dtype.kind == "U" and set(stored) <= {s.value for s in gaussim.solver.Status} | {"NO_QP"}
    np.testing.assert_array_equal(stored, log.solver_arrays()["status"])
    # reproducible from the log alone: the same scene text and options give the same trajectory
    scene_file = tmp_path / "again.toml"
    scene_file.write_text(loaded.scene_text)
    again = gaussim.run(_short_from(scene_file, loaded))
    np.testing.assert_array_equal(again.q, loaded.q)  # to the bit (see test_runs_repeat_bit_for_bit)


def _short_from(path, log):
    spec = gaussim.load_scene(path, **{k: getattr(log.options, k) for k in ("dt", "scheme", "friction_mode")})
    spec.duration = log.steps * log.options.dt
    return spec


def test_interrupted_run_keeps_the_steps_made(tmp_path, capsys):
    out = tmp_path / "run.npz"
    spec = _short("ball_bounce", 500)
    control = spec.controller

    def interrupt_at_step_120(state):
        if round(state.t / spec.options.dt) == 120:
            raise KeyboardInterrupt
        return control(state)

    spec.controller = interrupt_at_step_120
    with pytest.raises(KeyboardInterrupt):
        gaussim.run(spec, out)
    log = gaussim.RunLog.load(out)
    assert not log.complete and "interrupted" in log.reason
    assert log.steps == 120 and len(log.t) == 121
    # the commands read it, and say that its run did not finish (a user reads a log as the whole run)
    from gaussim.cli import main

    assert main(["forces", str(out), "--csv", str(tmp_path / "f.csv")]) == 0
    err = capsys.readouterr().err
    assert f"note: {out} holds the 120 steps of a run that did not finish: interrupted (Ctrl-C)" in err, err


def test_a_ctrl_c_inside_compiled_code_is_an_interruption(tmp_path):
    """A Ctrl-C that lands while numba converts a kernel's result surfaces as "SystemError: ...
    returned a result with an exception set", the KeyboardInterrupt as its context (seen in the CLI
    test): the run treats it as the interruption it is."""
    out = tmp_path / "run.npz"
    spec = _short("ball_bounce", 500)
    control = spec.controller

    def interrupt_inside_a_kernel_at_step_80(state):
        if round(state.t / spec.options.dt) == 80:
            try:
                raise KeyboardInterrupt
            except KeyboardInterrupt:
                raise SystemError("CPUDispatcher returned a result with an exception set")  # noqa: B904
        return control(state)

    spec.controller = interrupt_inside_a_kernel_at_step_80
    with pytest.raises(KeyboardInterrupt):
        gaussim.run(spec, out)
    log = gaussim.RunLog.load(out)
    assert not log.complete and "interrupted" in log.reason and log.steps == 80


def test_failed_run_keeps_the_steps_made_and_says_why(tmp_path):
    out = tmp_path / "run.npz"
    spec = _short("box_incline", 300)
    spec.options = spec.options.replace(
        max_iter=1, solver="proxqp"
    )  # ProxQP cannot converge in one iteration
    with pytest.raises(gaussim.SolverError):
        gaussim.run(spec, out)
    log = gaussim.RunLog.load(out)
    assert not log.complete and "SolverError at step" in log.reason


def test_a_failed_save_never_replaces_a_good_log(tmp_path, monkeypatch):
    out = tmp_path / "run.npz"
    gaussim.run(_short("ball_bounce", 10), out)

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez_compressed", broken)
    with pytest.raises(OutputError, match="run.npz: cannot be written"):
        gaussim.run(_short("ball_bounce", 20), out)
    assert gaussim.RunLog.load(out).steps == 10
    assert [p.name for p in tmp_path.iterdir()] == ["run.npz"], "no temporary file left behind"


# a process that holds the lock of the file argv[1], as a run writing its log does, until it is killed
HOLDER = (
    "import fcntl, os, sys, time; fd = os.open(sys.argv[1], os.O_RDWR); fcntl.lockf(fd, fcntl.LOCK_EX); "
    "print('held', flush=True); time.sleep(600)"
)


def test_what_a_kill_midway_through_a_write_leaves_is_ignored_then_cleared(tmp_path):
    """A SIGKILL while a chunk is written leaves its hidden temporary file in the log, and one before the
    log's first state its temporary folder beside it: a read ignores them; the next run into the path
    removes them (the folder of a run still starting, whose lock is held, is left alone)."""
    out = tmp_path / "r"
    gaussim.run(_short("ball_bounce", 10), out)
    torn = out / ".chunk-000002.npz.ab12cd_x.tmp.npz"
    torn.write_bytes(b"PK\x03\x04 torn")
    stale, starting = tmp_path / ".r.k3j4h5g6.new", tmp_path / ".r.a1b2c3d4.new"
    for folder in (stale, starting):
        folder.mkdir()
        (folder / WRITING).write_text("")
    holder = subprocess.Popen([sys.executable, "-c", HOLDER, str(starting / WRITING)], stdout=subprocess.PIPE)
    try:
        assert holder.stdout.readline() == b"held\n"
        log = gaussim.RunLog.load(out)
        assert log.complete and log.steps == 10
        gaussim.run(_short("ball_bounce", 5), out)
    finally:
        holder.kill()
        holder.communicate()
    assert sorted(p.name for p in tmp_path.iterdir()) == [starting.name, "r", "r.prev"]
    assert not [p.name for p in (tmp_path / "r.prev").iterdir() if p.name.endswith(".tmp.npz")]
    assert gaussim.RunLog.load(tmp_path / "r.prev").steps == 10


def test_not_a_log_is_named(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_text("hello")
    with pytest.raises(RunLogError, match="bad.npz"):
        gaussim.RunLog.load(bad)


def _cli(*args, **kwargs):
    return subprocess.run(
        [sys.executable, "-m", "gaussim.cli", *args], capture_output=True, text=True, **kwargs
    )


def test_cli_run_inspect_and_forces(tmp_path):
    out = tmp_path / "run.runlog"
    result = _cli("run", str(SCENES / "solo12_standing.toml"), "--out", str(out), "--duration", "0.2")
    assert result.returncode == 0, result.stderr
    assert "max penetration" in result.stdout and "FL_FOOT_0/ground#0" in result.stdout
    assert "steps/s" in result.stderr, "a progress line"

    result = _cli("inspect", str(SCENES / "solo12_standing.toml"))
    assert (
        result.returncode == 0 and "nq = 19, nv = 18" in result.stdout and "contact pairs: 4" in result.stdout
    )

    csv_path = tmp_path / "forces.csv"
    result = _cli("forces", str(out), "--csv", str(csv_path))
    assert result.returncode == 0, result.stderr
    rows = list(csv.DictReader(csv_path.open()))
    log = gaussim.RunLog.load(out)
    records = log.contact_records()
    assert len(rows) == len(records["step"]) and list(rows[0]) == list(records)
    assert float(rows[-1]["force_z_N"]) == pytest.approx(records["force_z_N"][-1], rel=1e-12)


def test_parquet_round_trip(tmp_path):
    import pandas as pd  # the optional 'analysis' extra, part of the 'test' extra

    out = tmp_path / "run.npz"
    gaussim.run(_short("box_incline"), out)
    result = _cli("forces", str(out), "--parquet", str(tmp_path / "f.parquet"))
    assert result.returncode == 0, result.stderr
    frame = pd.read_parquet(tmp_path / "f.parquet")
    expected = gaussim.RunLog.load(out).contact_forces()
    pd.testing.assert_frame_equal(frame, expected)
    assert set(frame["contact"]) == {f"box_0/ground#{k}" for k in range(4)}


def test_parquet_without_pyarrow_says_what_to_install(tmp_path, monkeypatch):
    """One line naming the file and the install command (pandas' own error is several lines about
    engines), and no file written."""
    import importlib.util

    log = gaussim.run(_short("box_incline", steps=5))
    found = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "pyarrow" else found(name, *a)
    )
    path = tmp_path / "f.parquet"
    with pytest.raises(gaussim.GaussimError) as err:
        gaussim.runlog.write_forces(log, path, "parquet")
    assert str(err.value) == f"{path} needs pyarrow: pip install 'gaussim[analysis]' (pandas and pyarrow)"
    assert not path.exists()


@pytest.mark.parametrize(
    ("args", "code", "message"),
    [
        (["run", "missing.toml"], 2, "missing.toml: file: cannot read it"),
        (
            ["run", str(SCENES / "ball_bounce.toml"), "--dt", "-1"],
            2,
            "--dt: must be a finite number > 0, got -1.0",
        ),
        (["forces", "missing.npz", "--csv", "x.csv"], 2, "missing.npz: cannot read it: No such file"),
        # flags of a live view, without one: they were ignored without a word
        (
            ["run", str(SCENES / "ball_bounce.toml"), "--speed", "0.5"],
            2,
            "--speed: applies to a live view only",
        ),
        (["run", str(SCENES / "ball_bounce.toml"), "--no-wait"], 2, "--no-wait: applies to a live view only"),
    ],
)
def test_cli_bad_input_exits_2_without_traceback(tmp_path, args, code, message):
    result = _cli(*args, cwd=tmp_path)
    assert result.returncode == code
    assert message in result.stderr and "Traceback" not in result.stderr


def test_a_reader_that_leaves_early_stops_the_command_quietly(tmp_path):
    """`gaussim inspect ... | head -1`: the reader closes the pipe; the command stops (exit 1, as
    Python's own recipe for a broken pipe) with no error message and no traceback."""
    command = [sys.executable, "-m", "gaussim.cli", "inspect", str(SCENES / "solo12_standing.toml")]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path)
    process.stdout.close()  # before the command writes a line
    stderr = process.stderr.read().decode()
    assert process.wait(timeout=300) == 1
    assert "Broken pipe" not in stderr and "Traceback" not in stderr and "Exception" not in stderr, stderr


def test_cli_simulation_failure_exits_1_and_keeps_the_log(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text(
        (SCENES / "box_incline.toml").read_text() + "\n[options]\nmax_iter = 1\nsolver = 'proxqp'\n"
    )
    result = _cli("run", str(scene), "--out", str(tmp_path / "r.runlog"), "--quiet")
    assert (
        result.returncode == 1 and "simulation failed" in result.stderr and "Traceback" not in result.stderr
    )
    assert not gaussim.RunLog.load(tmp_path / "r.runlog").complete


def test_cli_contact_failure_exits_1_and_keeps_the_log(tmp_path, monkeypatch, capsys):
    """Detection that gives no usable contact midway is a simulation failure, not bad input."""
    from gaussim.cli import main
    from gaussim.collision.boxes import BoxPairs

    detect = BoxPairs.detect
    calls = []

    def failing(self, data, margin, turns):  # the 14th detection fails, as coal's NaN normal did
        calls.append(margin)
        if len(calls) == 14:
            raise gaussim.ContactError("a non-finite contact for pair 'top_0/middle_0'", "top_0/middle_0")
        return detect(self, data, margin, turns)

    monkeypatch.setattr(BoxPairs, "detect", failing)
    out = tmp_path / "r.runlog"
    assert main(["run", str(SCENES / "box_stack.toml"), "--out", str(out), "--quiet"]) == 1
    stderr = capsys.readouterr().err
    assert "simulation failed" in stderr and "non-finite contact" in stderr and str(out) in stderr
    log = gaussim.RunLog.load(out)
    assert not log.complete and 1 <= log.steps < 14  # the steps before the failing detection are kept


def test_cli_ctrl_c_keeps_the_log(tmp_path):
    out = tmp_path / "r.runlog"
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "gaussim.cli",
            "run",
            str(SCENES / "fourbar.toml"),
            "--out",
            str(out),
            "--duration",
            "1000",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # Ctrl-C's default disposition, even when this test runs where SIGINT is ignored (a script's
        # background job: the child would inherit that and never stop)
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.time() + 60
    while time.time() < deadline:  # wait for the first progress line: the run is under way
        line = process.stderr.readline()
        if "steps/s" in line:
            break
    os.kill(process.pid, signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 1 and "stopped by Ctrl-C" in stderr
    log = gaussim.RunLog.load(out)
    assert not log.complete and "interrupted" in log.reason and log.steps > 0


def _ctrl_c_at_step(count: int) -> tuple[gaussim.SceneSpec, list[float]]:
    """The four-bar scene, 2 s, with a controller that sends this process a SIGINT during step ``count``."""
    calls: list[float] = []

    def controller(state):
        calls.append(state.t)
        if len(calls) == count:
            os.kill(os.getpid(), signal.SIGINT)
        return None

    spec = gaussim.load_scene(SCENES / "fourbar.toml")
    return dataclasses.replace(spec, controller=controller, duration=2e-2), calls


@pytest.mark.parametrize("disposition", [signal.default_int_handler, signal.SIG_IGN])
def test_ctrl_c_stops_the_run_at_the_end_of_its_step_unless_ignored(tmp_path, disposition):
    """A SIGINT sets a flag that the loop reads between steps, so the interrupt never surfaces from
    inside a compiled call; the log keeps the steps made. A process that ignores SIGINT (nohup, a
    script's background job) runs on."""
    previous = signal.signal(signal.SIGINT, disposition)
    try:
        spec, calls = _ctrl_c_at_step(6)
        out = tmp_path / "r.npz"
        if disposition is signal.SIG_IGN:
            assert gaussim.run(spec, out).complete and len(calls) == 20
        else:
            with pytest.raises(KeyboardInterrupt):
                gaussim.run(spec, out)
            log = gaussim.RunLog.load(out)
            assert log.steps == 6 and len(calls) == 6, "the 6th step ends, no 7th begins"
            assert not log.complete and "interrupted (Ctrl-C) at step 6" in log.reason
        assert signal.getsignal(signal.SIGINT) is disposition, "the disposition is restored"
    finally:
        signal.signal(signal.SIGINT, previous)


DATA = Path(__file__).parent / "data"


def test_forces_between_bodies_are_logged_as_the_simulator_reports_them(crate_run, tmp_path):
    """The log's force on the crate from Solo-12 at each step is the step report's forces_between, bit
    for bit, in the log directory and in its single-file copy; the reaction is its opposite."""
    log, _, reported = crate_run
    assert log.bodies == ["solo", "crate"] and log.steps == len(reported)
    assert np.count_nonzero(reported[:, 2] > 0) > 50, "Solo-12 carries the crate"
    for loaded in (log, gaussim.RunLog.load(log.save(tmp_path / "run.npz"))):
        assert np.array_equal(loaded.forces_between("crate", "solo"), reported)
        assert np.array_equal(loaded.forces_between("solo", "crate"), -reported)
    assert log.body_pairs() == [("solo", "ground"), ("solo", "crate")]
    assert not log.forces_between("crate", "ground").any(), "the crate never touches the ground"
    with pytest.raises(gaussim.InvalidOptions, match="no body 'box' in this log; its bodies: solo, crate"):
        log.forces_between("box", "solo")
    # a misspelt other side is named, not summed to zeros (the ground, declared, never touched the crate)
    with pytest.raises(gaussim.InvalidOptions, match="no body or obstacle 'grund' .*its obstacles: ground"):
        log.forces_between("crate", "grund")


def test_the_export_and_the_summary_name_the_bodies(crate_run, tmp_path):
    log, _, reported = crate_run
    records = log.contact_records()
    assert {(b, o) for b, o in zip(records["body"], records["other"])} == {
        ("solo", "ground"),
        ("solo", "crate"),
    }
    for contact, body, other in zip(records["contact"], records["body"], records["other"]):
        assert contact.startswith(f"{body}/") and f"/{other}" in contact
    from gaussim.cli import main

    csv_path = tmp_path / "forces.csv"
    log.save(tmp_path / "run.npz")
    assert main(["forces", str(tmp_path / "run.npz"), "--csv", str(csv_path)]) == 0
    rows = list(csv.DictReader(csv_path.open()))
    assert [(r["body"], r["other"]) for r in rows] == list(zip(records["body"], records["other"]))
    summary = log.summary().splitlines()
    # the force between each pair over the steps they touch, then the contacts grouped by pair
    pair = next(line for line in summary if line.startswith("solo from crate "))
    touching = np.linalg.norm(reported[np.linalg.norm(reported, axis=1) > 0], axis=1)
    steps, mean, peak = pair.split()[3:]
    assert int(steps) >= len(touching) and float(peak) == pytest.approx(touching.max(), abs=1e-3)
    grouped = summary[summary.index("solo from crate:") + 1 :]
    assert grouped and all(line.startswith("solo/base_link_0/crate/box#") for line in grouped)


@pytest.mark.parametrize("form", ["box_stack_format1.npz", "box_stack_directory2.runlog", "no scene text"])
def test_logs_from_before_bodies_still_read(form, tmp_path):
    """Logs written before contacts named their bodies (format 1, directory 2: box_stack, 5 steps, by
    gaussim 2e4bfed) read as logs of their one robot: each contact against the ground or the robot's
    own links (told apart by the scene text, or without one by the geometries' names)."""
    path = DATA / form
    if form == "no scene text":
        with np.load(DATA / "box_stack_format1.npz") as f:
            arrays = {k: f[k] for k in f.files}
        path = tmp_path / "log.npz"
        np.savez(path, **{**arrays, "scene_text": np.array("")})
    log = gaussim.RunLog.load(path)
    assert log.bodies == ["box_stack"] and log.steps == 5
    sides = dict(zip(log.contact_names, zip(log.contact_body, log.contact_other)))
    assert sides["bottom_0/ground#0"] == ("box_stack", "ground")
    assert sides["middle_0/bottom_0#2"] == sides["top_0/middle_0#0"] == ("box_stack", "box_stack")
    # the ground carries the stack: 1 + 10 + 100 kg at rest
    np.testing.assert_allclose(
        log.forces_between("box_stack", "ground"), [[0, 0, 111 * 9.81]] * 5, rtol=1e-6, atol=1e-6
    )
    assert set(log.contact_records()["other"]) == {"ground", "box_stack"}
    assert "box_stack from ground " in log.summary() and "box_stack from its own links:" in log.summary()


def test_a_step_report_groups_its_contacts_by_body():
    """A box resting on another on the ground: the table's rows come in one group per pair of bodies,
    each followed by the force between them."""
    scene = gaussim.Scene(
        bodies={
            "bottom": gaussim.FreeBody.box("bottom", (0.4, 0.4, 0.2), mass=3.0),
            "top": gaussim.FreeBody.box("top", (0.2, 0.2, 0.2), mass=1.0),
        },
        ground=gaussim.Ground(),
    )
    sim = gaussim.Simulator(scene)
    state = sim.reset({"bottom": gaussim.pose(z=0.1), "top": gaussim.pose(z=0.3 + 1e-4)})
    for _ in range(100):
        state = sim.step(state)
    report = sim.last_step
    lines = report.table().splitlines()[1:-1]
    sums = [k for k, line in enumerate(lines) if line.startswith("  ")]
    assert [lines[k].split()[:3] for k in sums] == [["bottom", "from", "ground"], ["bottom", "from", "top"]]
    for start, end in zip([-1, *sums], sums):
        a, _, b = lines[end].split()[:3]
        names = [line.split()[0] for line in lines[start + 1 : end]]
        assert names and all(name.startswith(f"{a}/box/{b}") for name in names)
        fz = float(lines[end].split()[-1])
        assert fz == pytest.approx(report.forces_between(a, b)[2], abs=1e-3)
    assert float(lines[sums[1]].split()[-1]) == pytest.approx(-1.0 * 9.81, abs=1e-3)  # the top's weight


def test_inspect_lists_the_bodies_and_their_pairs(tmp_path, capsys):
    from gaussim.cli import main

    assert main(["inspect", str(SCENES / "solo12_crate.toml")]) == 0
    out = capsys.readouterr().out
    assert "bodies: 2\n" in out
    assert "  solo: robot solo12; q[0:19], v[0:18]; floating base, 12 actuated; mass 2.5 kg\n" in out
    assert "  crate: box 0.2 x 0.15 x 0.1 m; q[19:26], v[18:24]; free body, 0 actuated; mass 0.5 kg\n" in out
    assert "  contact pairs: 6\n    solo - ground: 4: solo/FL_FOOT_0/ground, " in out
    assert "    crate - ground: 1: crate/box/ground\n    solo - crate: 1: solo/base_link_0/crate/box\n" in out
    # the automatic pairs: every geometry of Solo-12 against the crate, counted
    scene = tmp_path / "auto.toml"
    scene.write_text(
        (SCENES / "solo12_crate.toml").read_text().split("[contacts]")[0]
        + '[[bodies]]\nname = "arm"\nrobot = "pendulum"\nposition = [2, 0, 0]\n'
    )
    assert main(["inspect", str(scene)]) == 0
    out = capsys.readouterr().out
    assert "  arm: robot pendulum; q[26:27], v[24:25]; fixed base at (2, 0, 0) m, 1 actuated" in out
    assert "    solo - crate: 17: solo/base_link_0/crate/box, " in out and ", ... (11 more)\n" in out


def test_inspect_reads_a_stopped_log_and_a_log_in_place_of_a_scene_is_named(tmp_path, capsys):
    """`inspect` on a log told its scene file "cannot read it: Is a directory"; run and sweep, which take a
    scene, say it is a log and what reads it."""
    from gaussim.cli import main

    spec = _short("box_incline", 30)
    spec.options = spec.options.replace(max_iter=1, solver="proxqp", dt=2e-3)  # it fails at its first QP
    with pytest.raises(gaussim.SolverError):
        gaussim.run(spec, tmp_path / "r")
    capsys.readouterr()
    assert main(["inspect", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"run log {tmp_path / 'r'}: ") and "; INCOMPLETE: SolverError at step" in out
    assert f"made from {SCENES / 'box_incline.toml'}" in out and "robot box" in out
    assert "options: dt = 0.002 s" in out, "the run's options, not its scene file's"
    for command in ("run", "sweep"):
        assert main([command, str(tmp_path / "r"), "--seeds" if command == "sweep" else "--quiet", *(
            ["2"] if command == "sweep" else [])]) == 2  # fmt: skip
        err = capsys.readouterr().err
        assert f"r: file: a run log, not a scene file: `gaussim inspect {tmp_path / 'r'}` shows it" in err


def test_cli_tells_gaussims_warnings_as_its_own_lines(tmp_path):
    """The command prints a GaussimWarning as ``gaussim: warning: ...``, not as Python shows it (the
    gaussim source file and line that raised it)."""
    scene = tmp_path / "outside.toml"
    scene.write_text('[robot]\nname = "pendulum"\n[initial]\nq = [1.0]\n[limits]\nenabled = true\n')
    result = _cli("run", str(scene), "--duration", "0.01", "--quiet", "--out", str(tmp_path / "run.runlog"))
    assert result.returncode == 0, result.stderr
    assert "gaussim: warning: the initial configuration has joints outside their limits" in result.stderr
    assert "GaussimWarning" not in result.stderr and ".py:" not in result.stderr


def test_a_log_replays_and_plots_from_any_folder(tmp_path):
    """A scene with a robot path relative to its folder, run from that folder: its log replays and
    plots from another folder (the log keeps the scene file's absolute path)."""
    project = tmp_path / "project"
    project.mkdir()
    (project / "pendulum.urdf").write_text((SCENES.parent / "pendulum.urdf").read_text())
    scene = '[robot]\nurdf = "pendulum.urdf"\n[initial]\nq = [0.3]\n[simulation]\nduration = 0.05\n'
    (project / "scene.toml").write_text(scene)
    result = _cli("run", "scene.toml", "--quiet", cwd=project)
    assert result.returncode == 0, result.stderr
    elsewhere = project / "out"
    for args in (["replay", "scene.runlog", "--html", "a.html"], ["plot", "scene.runlog", "-o", "a.png"]):
        result = _cli(*args, cwd=elsewhere)
        assert result.returncode == 0, result.stderr
