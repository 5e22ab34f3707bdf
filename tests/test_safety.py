"""Faults on real processes: signals, kills, unwritable and full disks, the viewer's address and its server's
life, sizes out of bounds. Each case runs ``python -m gaussim`` (or a small script) in a subprocess."""

import contextlib
import os
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import psutil
import pytest

import gaussim
import gaussim.files
import gaussim.viewer
from gaussim.cli import main
from gaussim.files import OutputError
from gaussim.runlog import LIVE, STOPPED, WRITING, RunLogWriter
from gaussim.runner import STOP_SIGNALS
from gaussim.viewer import Viewer

SCENES = Path(__file__).resolve().parents[1] / "robots" / "scenes"
ENV = {**os.environ, "PYTHONPATH": str(Path(gaussim.__file__).resolve().parents[1])}
# how long a subprocess may take to start and reach a given point [s] (its first import is slow)
STARTUP = 90.0
# a server must be gone this soon after its parent [s] (it checks every 0.25 s)
SERVER_GONE = 5.0
ROOT = os.geteuid() == 0


def _default_signals() -> None:
    """Default dispositions in the child, even where this test runs with SIGINT ignored (a background job)."""
    for s in STOP_SIGNALS:
        signal.signal(s, signal.SIG_DFL)


_started: list[subprocess.Popen] = []


@pytest.fixture(autouse=True)
def _no_process_left():
    """A test that fails midway leaves no run (of 1000 s) or viewer going."""
    yield
    while _started:
        process = _started.pop()
        if process.poll() is None:
            process.kill()
        process.communicate()


def _start(*args: str) -> subprocess.Popen:
    process = subprocess.Popen(
        [sys.executable, "-m", "gaussim", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=ENV,
        preexec_fn=_default_signals,
    )
    _started.append(process)
    return process


def _long_run(out: Path, checkpoint_steps: int) -> subprocess.Popen:
    return _start("run", str(SCENES / "fourbar.toml"), "--out", str(out), "--duration", "1000",
                  "--checkpoint-steps", str(checkpoint_steps))  # fmt: skip


def _wait_for_chunks(out: Path, count: int, process: subprocess.Popen) -> None:
    """Wait until the run's log holds ``count`` chunks: the run is under way at full speed."""
    deadline = time.time() + STARTUP
    while not (out / f"chunk-{count - 1:06d}.npz").exists():
        assert process.poll() is None, process.communicate()
        assert time.time() < deadline, "the run never wrote its chunks"
        time.sleep(0.02)


def _chunks(out: Path) -> list[str]:
    return sorted(p.name for p in out.iterdir() if p.name.startswith("chunk-"))


# -- signals ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_a_stop_signal_ends_the_run_at_the_end_of_its_step(tmp_path, stop):
    """In-process: the signal lands during step 6, which ends; no 7th begins; the handlers are restored."""
    calls: list[float] = []

    def controller(state):
        calls.append(state.t)
        if len(calls) == 6:
            os.kill(os.getpid(), stop)

    spec = gaussim.load_scene(SCENES / "fourbar.toml")
    spec.controller, spec.duration = controller, 20 * spec.options.dt
    previous = {
        s: signal.signal(s, signal.default_int_handler)
        for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    }
    try:
        with pytest.raises(KeyboardInterrupt) as raised:
            gaussim.run(spec, tmp_path / "r")
        assert all(signal.getsignal(s) is signal.default_int_handler for s in previous)
    finally:
        for s, handling in previous.items():
            signal.signal(s, handling)
    name = "Ctrl-C" if stop == signal.SIGINT else stop.name
    assert raised.value.signal == name and len(calls) == 6
    log = gaussim.RunLog.load(tmp_path / "r")
    assert log.steps == 6 and not log.complete and log.reason.startswith(f"interrupted ({name}) at step 6")


def test_a_second_ctrl_c_stops_a_step_that_hangs_and_the_log_holds_whole_steps(tmp_path):
    """Step 4's controller hangs: the first Ctrl-C waits for the step's end, the second stops it at once;
    the log holds the 3 whole steps before it."""
    calls: list[float] = []

    def controller(state):
        calls.append(state.t)
        if len(calls) == 4:
            os.kill(os.getpid(), signal.SIGINT)
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(30)  # a hung step (the KeyboardInterrupt ends the sleep)

    spec = gaussim.load_scene(SCENES / "fourbar.toml")
    spec.controller, spec.duration = controller, 20 * spec.options.dt
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    started = time.perf_counter()
    try:
        with pytest.raises(KeyboardInterrupt):
            gaussim.run(spec, tmp_path / "r")
    finally:
        signal.signal(signal.SIGINT, previous)
    assert time.perf_counter() - started < 20, "the second Ctrl-C did not stop the hung step"
    log = gaussim.RunLog.load(tmp_path / "r")
    assert log.steps == 3 and len(log.t) == 4 and len(log.solver_arrays()["qps"]) == 3
    assert log.reason.startswith("interrupted (Ctrl-C) at step 3")


def test_sigterm_ends_the_command_at_a_step_keeps_the_log_and_stops_the_viewer(tmp_path):
    out = tmp_path / "r"
    process = _start("run", str(SCENES / "fourbar.toml"), "--out", str(out), "--duration", "1000",
                     "--checkpoint-steps", "50", "--view", "--speed", "1000")  # fmt: skip
    _wait_for_chunks(out, 3, process)
    (server,) = psutil.Process(process.pid).children()
    process.terminate()
    _, stderr = process.communicate(timeout=30)
    assert _gone(server), "the live view's server outlived the run"
    assert process.returncode == 1, stderr
    assert "stopped by SIGTERM at step" in stderr and str(out) in stderr and "Traceback" not in stderr
    log = gaussim.RunLog.load(out)
    assert not log.complete and f"interrupted (SIGTERM) at step {log.steps}" in log.reason
    assert log.steps >= 100 and len(log.t) == log.steps + 1 and len(log.solver_arrays()["qps"]) == log.steps


def test_ctrl_c_again_and_again_while_the_log_is_written_keeps_it(tmp_path):
    """The first Ctrl-C stops the run; a burst of more, landing while the last (large) chunk is written,
    neither deletes nor truncates the log, and the message tells the truth."""
    out = tmp_path / "r"
    process = _long_run(out, 4000)
    _wait_for_chunks(out, 2, process)
    time.sleep(0.5)  # a chunk of a few thousand steps to write at the stop
    for _ in range(100):
        if process.poll() is not None:
            break
        process.send_signal(signal.SIGINT)
        time.sleep(0.003)
    _, stderr = process.communicate(timeout=30)
    assert process.returncode == 1 and "the log of the steps made is in" in stderr, stderr
    log = gaussim.RunLog.load(out)
    assert not log.complete and "interrupted (Ctrl-C)" in log.reason and log.steps > 4000
    assert len(log.t) == log.steps + 1 and len(log.tau) == log.steps


def test_a_ctrl_c_landing_as_the_stop_surfaces_leaves_the_command_deaf_to_more(tmp_path, capsys, monkeypatch):
    """A burst of Ctrl-Cs, one landing after the run restored the handlers and before the command
    reported its stop (a plain KeyboardInterrupt where Interrupted was on its way): the command
    names the log it wrote and from then on ignores the stop signals, where one more ended the
    process by SIGINT, its exit status lost (seen once in CI)."""
    import gaussim.runner

    real = gaussim.runner.run

    def stopped(spec, out, **kwargs):  # the steps made, logged; then the Ctrl-C surfaces
        spec.duration = 5 * spec.options.dt
        real(spec, out, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(gaussim.runner, "run", stopped)
    argv = ["run", str(SCENES / "fourbar.toml"), "--out", str(tmp_path / "r"), "--quiet"]
    saved = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    assert main(argv) == 1  # in-process, with its arguments: the caller's handlers are left as they were
    assert {s: signal.getsignal(s) for s in STOP_SIGNALS} == saved
    capsys.readouterr()
    monkeypatch.setattr(sys, "argv", ["gaussim", *argv])
    try:
        code = main()  # as the command: ignoring the stop signals until the process exits
        after = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    finally:
        for s, handling in saved.items():
            signal.signal(s, handling)
    err = capsys.readouterr().err
    assert code == 1 and f"interrupted; the log of the steps made is in {tmp_path / 'r'}" in err, err
    assert set(after.values()) == {signal.SIG_IGN}
    assert gaussim.RunLog.load(tmp_path / "r").steps == 5


def test_the_log_is_a_valid_prefix_at_any_instant_and_after_a_sigkill(tmp_path):
    """Read while chunks of 10 steps are written as fast as the run goes, then after a SIGKILL (most
    likely during a chunk's write): each read is a whole log of the first steps of the run."""
    out = tmp_path / "r"
    process = _long_run(out, 10)
    _wait_for_chunks(out, 2, process)
    seen = []
    for _ in range(5):
        log = gaussim.RunLog.load(out)
        assert log.reason == LIVE.format(process.pid) and log.steps % 10 == 0 and len(log.t) == log.steps + 1
        seen.append(log.steps)
    process.kill()
    process.communicate(timeout=30)
    log = gaussim.RunLog.load(out)  # its writer gone: it says so, not "still running"
    assert not log.complete and log.reason == STOPPED
    assert log.steps >= seen[-1] > 0 and log.steps % 10 == 0 and len(log.t) == log.steps + 1
    # a prefix of the run: the same steps as an uninterrupted run's
    spec = gaussim.load_scene(SCENES / "fourbar.toml")
    spec.duration = log.steps * spec.options.dt
    np.testing.assert_array_equal(gaussim.run(spec).q, log.q)


def test_a_run_into_a_log_another_run_is_writing_is_refused_and_leaves_it_whole(tmp_path, capsys):
    """Moved aside, the log would have taken the first run's next chunks into the second's (a mix of two
    runs); once the first is killed, the same command replaces it."""
    out = tmp_path / "r"
    process = _long_run(out, 10)
    _wait_for_chunks(out, 2, process)
    argv = ["run", str(SCENES / "box_incline.toml"), "--out", str(out), "--duration", "0.01", "--quiet"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"another run (process {process.pid}) is still writing {out}" in err and "Traceback" not in err
    assert not (tmp_path / "r.prev").exists()
    process.kill()
    process.communicate(timeout=30)
    assert gaussim.RunLog.load(out).robot == "fourbar"
    assert main(argv) == 0
    assert gaussim.RunLog.load(out).robot == "box" and gaussim.RunLog.load(f"{out}.prev").robot == "fourbar"


def _long_sweep(out: Path) -> subprocess.Popen:
    """A sweep of two endless runs on two workers, in a process group of its own (a terminal's job)."""
    process = subprocess.Popen(
        [sys.executable, "-m", "gaussim", "sweep", str(SCENES / "fourbar.toml"),
         "--vary", "options.eps_abs=1e-9,1e-10", "--vary", "simulation.duration=1000",
         "--out", str(out), "--workers", "2"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV, preexec_fn=_default_signals,
        start_new_session=True,
    )  # fmt: skip
    _started.append(process)
    deadline = time.time() + STARTUP
    while len(list((out / "runs").glob("*/chunk-000001.npz"))) < 2:  # both runs under way
        assert process.poll() is None, process.communicate()
        assert time.time() < deadline, "the runs never started"
        time.sleep(0.05)
    return process


@pytest.mark.parametrize("group", [True, False], ids=["two-ctrl-c-to-the-group", "one-sigint-to-the-command"])
def test_a_stopped_sweep_stops_its_runs_and_exits_without_a_traceback(tmp_path, group):
    """Two Ctrl-Cs 10 ms apart (to the whole group, as a terminal sends them) hung the sweep at its exit,
    on workers waiting for work, after workers printed KeyboardInterrupt tracebacks; a SIGINT to the
    command alone left its runs going to their end (1000 s). Now each run stops at a step, its log
    kept."""
    out = tmp_path / "sweep"
    process = _long_sweep(out)
    try:
        for _ in range(2 if group else 1):
            (os.killpg if group else os.kill)(process.pid, signal.SIGINT)
            time.sleep(0.01)
        _, stderr = process.communicate(timeout=60)
    finally:  # no worker left behind by a sweep that hangs
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
    assert process.returncode == 1 and "gaussim: interrupted; 0 of 2 runs are kept" in stderr, stderr
    assert "Traceback" not in stderr, stderr
    for log in (out / "runs").iterdir():
        assert "interrupted" in gaussim.RunLog.load(log).reason


# -- the log's format ------------------------------------------------------------------------------------


def test_chunks_are_written_once_each_and_hold_the_new_steps_only(tmp_path, monkeypatch):
    """Logging costs O(new steps): each chunk holds at most checkpoint_steps steps and is never rewritten;
    the directory loads into the same log as the run's in memory, bit for bit."""
    spec = gaussim.load_scene(SCENES / "box_incline.toml")
    spec.duration = 95 * spec.options.dt
    out = tmp_path / "r"
    written: dict[str, int] = {}
    original = RunLogWriter.append

    def append(self):
        before = set(_chunks(self.path))
        stamps = {name: (self.path / name).stat().st_mtime_ns for name in before}
        original(self)
        for name in before:  # an old chunk untouched
            assert (self.path / name).stat().st_mtime_ns == stamps[name]
        for name in set(_chunks(self.path)) - before:
            with np.load(self.path / name) as chunk:
                written[name] = len(chunk["tau"])

    monkeypatch.setattr(RunLogWriter, "append", append)
    log = gaussim.run(spec, out, checkpoint_steps=10)
    assert list(written.values()) == [0] + [10] * 9 + [5]
    memory = gaussim.run(spec)
    np.testing.assert_array_equal(log.q, memory.q)
    np.testing.assert_array_equal(log.tau, memory.tau)
    assert log.contact_records() == memory.contact_records() and log.complete


def test_old_npz_logs_and_new_directories_load_the_same_in_every_command(tmp_path):
    spec = gaussim.load_scene(SCENES / "box_incline.toml")
    spec.duration = 40 * spec.options.dt
    new = tmp_path / "new"
    old = gaussim.run(spec, new).save(tmp_path / "old.npz")
    a, b = gaussim.RunLog.load(old), gaussim.RunLog.load(new)
    for name in ("t", "q", "v", "tau"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert a.contact_records() == b.contact_records() and a.summary() == b.summary()
    for log in (old, new):
        assert main(["forces", str(log), "--csv", str(tmp_path / f"{log.stem}.csv")]) == 0
    assert (tmp_path / "old.csv").read_text() == (tmp_path / "new.csv").read_text()
    assert main(["plot", str(old), "-o", str(tmp_path / "old.png")]) == 0
    assert main(["replay", str(new), "--html", str(tmp_path / "new.html")]) == 0


# -- output paths ----------------------------------------------------------------------------------------


@contextmanager
def _tmpfs(path: Path, options: str):
    # a real size or write limit needs a mounted filesystem; where none can be made, the case says why
    if not ROOT:
        pytest.skip("mounting a tmpfs needs root (chmod does not stop root, so there is no other way)")
    path.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode().strip()}")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], check=True)


def test_a_ctrl_c_whose_exception_was_lost_before_the_run_stops_it_at_its_first_step(
    tmp_path, capsys, monkeypatch, request
):
    """CPython can drop the KeyboardInterrupt of a Ctrl-C that lands while a C extension is imported
    (seen: 3 launches in 60, within the import of xml.etree's _elementtree): the command's handler
    remembers the signal, and the run stops before its first step with its (empty) log written."""
    import gaussim.runner
    import gaussim.stops

    real = gaussim.runner.run

    def swallowed(spec, out, **kwargs):  # the Ctrl-C landed in an import, its exception lost there
        try:
            signal.getsignal(signal.SIGINT)(signal.SIGINT, None)
        except KeyboardInterrupt:
            pass
        return real(spec, out, **kwargs)

    monkeypatch.setattr(gaussim.runner, "run", swallowed)
    # Ctrl-C as at a terminal: a suite run in the background (`&`) ignores it, and so does gaussim
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    request.addfinalizer(lambda: signal.signal(signal.SIGINT, previous))
    assert main(["run", str(SCENES / "fourbar.toml"), "--out", str(tmp_path / "r"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert f"stopped by Ctrl-C at step 0; the log of the steps made is in {tmp_path / 'r'}" in err, err
    log = gaussim.RunLog.load(tmp_path / "r")
    assert log.steps == 0 and not log.complete
    assert gaussim.stops.taken_stop() is None, "the command forgets its stop: a later run goes on"


def test_outputs_of_the_wrong_kind_and_a_bad_arrow_scale_are_refused_before_the_first_step(tmp_path, capsys):
    """``--html scene.toml`` overwrote the scene with the page (tried as a new user would)."""
    scene = tmp_path / "s.toml"
    scene.write_text((SCENES / "fourbar.toml").read_text())
    for args, said in (
        (["--html", str(scene)], f"--html {scene}: the file's name must end in .html or .htm"),
        (["--force-scale=-1"], "--force-scale: must be a finite number > 0, got -1.0"),
    ):
        assert main(["run", str(scene), "--out", str(tmp_path / "r"), *args]) == 2
        err = capsys.readouterr().err
        assert said in err and "steps/s" not in err, err
    assert scene.read_text() == (SCENES / "fourbar.toml").read_text()
    assert main(["run", str(scene), "--out", str(tmp_path / "r"), "--quiet", "--duration", "0.01"]) == 0
    capsys.readouterr()
    assert main(["forces", str(tmp_path / "r"), "--csv", str(scene)]) == 2
    assert f"--csv {scene}: the file's name must end in .csv" in capsys.readouterr().err
    assert scene.read_text() == (SCENES / "fourbar.toml").read_text()


def test_an_unwritable_output_is_refused_before_the_first_step(tmp_path, capsys):
    with _tmpfs(tmp_path / "ro", "size=1m,ro") as ro:
        for args in (["--out", str(ro / "r")], ["--out", str(tmp_path / "r"), "--html", str(ro / "p.html")]):
            assert main(["run", str(SCENES / "fourbar.toml"), "--duration", "0.05", *args]) == 2
            stderr = capsys.readouterr().err
            assert "cannot be written (Read-only file system)" in stderr
            assert "steps/s" not in stderr, "no step made"
        # the reports of the benchmarks and the stability cases (minutes to hours of work) as well
        for command in (
            ["stability", "--report", str(ro / "s.md")],
            ["bench", "--quick", "--no-peers", "--out", str(ro / "b")],
            ["bench", "--quick", "--no-peers", "--out", str(tmp_path / "b"), "--report", str(ro / "b.md")],
            ["bench", "--scenes", "--quick", "--no-peers", "--report", str(ro / "s.md")],
        ):
            assert main(command) == 2, command
            stderr = capsys.readouterr().err
            assert f"{command[-2]} {command[-1]}: cannot be written (Read-only file system)" in stderr
            assert "pass " not in stderr and "[1/" not in stderr, "no case run"
        with pytest.raises(OSError) as raised:  # named after the file asked for, not its temporary one
            gaussim.files.write_atomic(ro / "page.html", b"")
        assert raised.value.filename == str(ro / "page.html")
    (tmp_path / "dir.png").mkdir()
    assert main(["run", str(SCENES / "fourbar.toml"), "--plot", str(tmp_path / "dir.png")]) == 2
    assert "dir.png: is a directory" in capsys.readouterr().err


def test_a_full_disk_midway_stops_the_run_and_keeps_what_fits(tmp_path, capsys):
    with _tmpfs(tmp_path / "small", "size=256k") as small:
        args = ["--out", str(small / "r"), "--duration", "1000", "--checkpoint-steps", "20", "--quiet"]
        assert main(["run", str(SCENES / "solo12_standing.toml"), *args]) == 1
        stderr = capsys.readouterr().err
        assert "No space left on device" in stderr and str(small) in stderr
        assert "the log of the first" in stderr
        log = gaussim.RunLog.load(small / "r")
        assert not log.complete and log.steps >= 20 and len(log.t) == log.steps + 1
        left = [p.name for p in (small / "r").iterdir() if p.name.startswith(".") and p.name != WRITING]
        assert not left, "no temporary file left"


def test_a_page_rewritten_on_a_full_disk_keeps_the_previous_one(tmp_path, capsys):
    spec = gaussim.load_scene(SCENES / "box_incline.toml")
    spec.duration = 20 * spec.options.dt
    log = gaussim.run(spec, tmp_path / "r")
    with _tmpfs(tmp_path / "small", "size=1200k") as small:  # room for one page (~0.9 MB), not two
        page = small / "page.html"
        assert main(["replay", str(tmp_path / "r"), "--html", str(page)]) == 0
        good = page.read_bytes()
        assert main(["replay", str(tmp_path / "r"), "--html", str(page)]) == 1
        assert f"gaussim: {page}: No space left on device" in capsys.readouterr().err  # named
        assert page.read_bytes() == good and os.listdir(small) == ["page.html"]
    assert log.steps == 20


def test_a_failed_run_keeps_the_previous_log_and_says_so(tmp_path, capsys):
    out = tmp_path / "r"
    assert main(["run", str(SCENES / "box_incline.toml"), "--out", str(out), "--duration", "0.2"]) == 0
    failing = tmp_path / "failing.toml"
    failing.write_text(
        (SCENES / "box_incline.toml").read_text() + "\n[options]\nmax_iter = 1\nsolver = 'proxqp'\n"
    )
    capsys.readouterr()
    assert main(["run", str(failing), "--out", str(out), "--quiet"]) == 1
    assert f"it will be kept as {out}.prev" in capsys.readouterr().err
    previous = gaussim.RunLog.load(tmp_path / "r.prev")
    assert previous.complete and previous.steps == 200
    assert not gaussim.RunLog.load(out).complete
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "mine.txt").write_text("keep me")
    with pytest.raises(OutputError, match="is not a run log; it is left alone"):
        gaussim.run(gaussim.load_scene(SCENES / "box_incline.toml"), tmp_path / "notes")
    assert (tmp_path / "notes" / "mine.txt").read_text() == "keep me"


# -- sizes -----------------------------------------------------------------------------------------------


def test_sizes_out_of_bounds_exit_2_naming_the_field(tmp_path, capsys):
    """8000 facets made ProxQP abort the process; --fps 1e9 built 2e8 frames."""
    scene = tmp_path / "facets.toml"
    scene.write_text((SCENES / "box_incline.toml").read_text() + "\n[options]\nfriction_facets = 8000\n")
    assert main(["run", str(scene), "--out", str(tmp_path / "r")]) == 2
    assert "friction_facets: must be an integer in [3, 64], got 8000" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()
    spec = gaussim.load_scene(SCENES / "box_incline.toml")
    spec.duration = 10 * spec.options.dt
    gaussim.run(spec, tmp_path / "log")
    assert main(["replay", str(tmp_path / "log"), "--fps", "1e9", "--html", str(tmp_path / "p.html")]) == 2
    assert "fps: 1e+09 frames/s at speed 1 make 1e+07 frames, more than 100000" in capsys.readouterr().err
    assert not (tmp_path / "p.html").exists()


# -- the viewer ------------------------------------------------------------------------------------------

# a parent that starts a live viewer's server as Viewer does (by path, its own pid as the argument), then
# waits: no import of gaussim, so that the test is quick
PARENT = f"{sys.executable} -u {Path(gaussim.viewer.__file__).with_name('viewer_server.py')} $$ & wait"


def _gone(server: psutil.Process) -> bool:
    """True when the server exits within SERVER_GONE; otherwise it is killed (no test leaves one)."""
    _, alive = psutil.wait_procs([server], timeout=SERVER_GONE)
    for process in alive:
        process.kill()
    return not alive


def _listening(pid: int) -> set[str]:
    return {c.laddr.ip for c in psutil.Process(pid).net_connections("inet") if c.status == psutil.CONN_LISTEN}


def test_the_viewer_listens_on_loopback_only_and_dies_with_its_parent():
    parent = subprocess.Popen(["bash", "-c", PARENT], stdout=subprocess.PIPE, text=True, env=ENV)
    try:
        assert parent.stdout.readline().startswith("zmq_url=tcp://127.0.0.1:")
        assert parent.stdout.readline().startswith("web_url=http://127.0.0.1:")
        (server,) = psutil.Process(parent.pid).children()
        assert _listening(server.pid) == {"127.0.0.1"}, "its web server and its ZMQ socket, on 127.0.0.1 only"
        assert len(psutil.Process(server.pid).net_connections("inet")) >= 2
    finally:
        parent.kill()  # SIGKILL: no handler, no atexit runs
        parent.wait()
        parent.stdout.close()
    assert _gone(server), "the server outlived its parent"


def test_replay_ended_by_sigterm_stops_its_server(tmp_path):
    spec = gaussim.load_scene(SCENES / "box_incline.toml")
    spec.duration = 10 * spec.options.dt
    gaussim.run(spec, tmp_path / "log")
    process = _start("replay", str(tmp_path / "log"))
    try:
        assert "replaying" in process.stdout.readline()
        (server,) = psutil.Process(process.pid).children()
        assert _listening(server.pid) == {"127.0.0.1"}
    finally:
        process.terminate()
        process.communicate(timeout=30)
    assert process.returncode == 0
    assert _gone(server)


def test_a_page_needs_no_server_and_is_the_page_a_server_makes():
    scene = gaussim.load_scene(SCENES / "box_incline.toml").scene
    before = set(psutil.Process().children(recursive=True))
    page = Viewer(scene, live=False).static_html()
    assert set(psutil.Process().children(recursive=True)) == before, "no process started"
    with Viewer(scene) as live:
        served = live.static_html()
    # the same drawing commands (the objects' uuids differ)
    assert page.count("handle_command") == served.count("handle_command") > 5
    assert len(page) == len(served)
