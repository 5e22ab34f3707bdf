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
from gaussim.runlog import RunLogError

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
    # reproducible from the log alone: the same scene text and options give the same trajectory
    scene_file = tmp_path / "again.toml"
    scene_file.write_text(loaded.scene_text)
    again = gaussim.run(_short_from(scene_file, loaded))
    np.testing.assert_array_equal(again.q, loaded.q)  # to the bit (see test_runs_repeat_bit_for_bit)


def _short_from(path, log):
    spec = gaussim.load_scene(path, **{k: getattr(log.options, k) for k in ("dt", "scheme", "friction_mode")})
    spec.duration = log.steps * log.options.dt
    return spec


def test_interrupted_run_keeps_the_steps_made(tmp_path):
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
    spec.options = spec.options.replace(max_iter=1)  # ProxQP cannot converge in one iteration
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
    out = tmp_path / "run.npz"
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
    assert len(rows) == len(log.contact_records()["t"])
    assert float(rows[-1]["force_z"]) == pytest.approx(log.contact_records()["force_z"][-1], rel=1e-12)


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


@pytest.mark.parametrize(
    ("args", "code", "message"),
    [
        (["run", "missing.toml"], 2, "missing.toml: file: cannot read it"),
        (
            ["run", str(SCENES / "ball_bounce.toml"), "--dt", "-1"],
            2,
            "options.dt: must be a finite number > 0",
        ),
        (["forces", "missing.npz", "--csv", "x.csv"], 2, "missing.npz: cannot read it: No such file"),
    ],
)
def test_cli_bad_input_exits_2_without_traceback(tmp_path, args, code, message):
    result = _cli(*args, cwd=tmp_path)
    assert result.returncode == code
    assert message in result.stderr and "Traceback" not in result.stderr


def test_cli_simulation_failure_exits_1_and_keeps_the_log(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text((SCENES / "box_incline.toml").read_text() + "\n[options]\nmax_iter = 1\n")
    result = _cli("run", str(scene), "--out", str(tmp_path / "r.npz"), "--quiet")
    assert (
        result.returncode == 1 and "simulation failed" in result.stderr and "Traceback" not in result.stderr
    )
    assert not gaussim.RunLog.load(tmp_path / "r.npz").complete


def test_cli_contact_failure_exits_1_and_keeps_the_log(tmp_path, monkeypatch, capsys):
    """Detection that gives no usable contact midway is a simulation failure, not bad input."""
    from gaussim.cli import main
    from gaussim.collision.narrow import NarrowPhase

    collide = NarrowPhase.collide
    calls = []

    def failing(self, pair, data):  # the 30th narrow phase fails, as coal's NaN normal did
        calls.append(pair.name)
        if len(calls) == 30:
            raise gaussim.ContactError(
                f"coal returned a non-finite contact for pair '{pair.name}'", pair.name
            )
        return collide(self, pair, data)

    monkeypatch.setattr(NarrowPhase, "collide", failing)
    out = tmp_path / "r.npz"
    assert main(["run", str(SCENES / "box_stack.toml"), "--out", str(out), "--quiet"]) == 1
    stderr = capsys.readouterr().err
    assert "simulation failed" in stderr and "non-finite contact" in stderr and str(out) in stderr
    log = gaussim.RunLog.load(out)
    assert not log.complete and log.steps == 13  # two narrow phases at reset and a step: the 14th failed


def test_cli_ctrl_c_keeps_the_log(tmp_path):
    out = tmp_path / "r.npz"
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
