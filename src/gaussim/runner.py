"""Running a scene file: step it for its duration, log every step, never lose what was done."""

from __future__ import annotations

import signal
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import FrameType
from typing import TextIO

from numba.core import event
from tqdm import tqdm

from .control import command
from .exceptions import GaussimError, GaussimWarning, InvalidOptions, shown
from .options import is_real
from .report import StepReport
from .runlog import RunLog, RunLogWriter
from .scenefile import SceneSpec
from .simulator import Simulator
from .state import State
from .stops import STOP_SIGNALS, taken_stop

# While a run goes on, the steps recorded are written as a new chunk of its log this often [s of wall
# time], and whenever this many are held in memory.
CHECKPOINT_SECONDS = 5.0
CHECKPOINT_STEPS = 10_000
# The progress line is redrawn this often [s]: on a terminal, and when written to a file or pipe.
PROGRESS_SECONDS = {True: 0.2, False: 5.0}
# What the progress line says while numba compiles a kernel its cache does not hold yet.
COMPILING = "compiling kernels (first run only)"


class Interrupted(KeyboardInterrupt):
    """A run stopped by a signal (a KeyboardInterrupt, as a Ctrl-C is). ``signal`` names it; the log of
    the steps made was written (to ``run``'s ``out``) before this was raised."""

    def __init__(self, signal_name: str, step: int) -> None:
        super().__init__(f"stopped by {signal_name} at step {step}")
        self.signal, self.step = signal_name, step


class LogWriteError(GaussimError):
    """The run log could not be written midway (a full disk): the run stopped; the message says which
    steps are on disk and where."""


def run(
    spec: SceneSpec,
    out: str | Path | None = None,
    *,
    progress: TextIO | None = None,
    checkpoint_seconds: float = CHECKPOINT_SECONDS,
    checkpoint_steps: int = CHECKPOINT_STEPS,
    observer: Callable[[State, StepReport], None] | None = None,
) -> RunLog:
    """Simulate ``spec`` for its duration and return the log (also written to ``out`` when given).

    ``out`` is a log directory (:class:`gaussim.runlog.RunLogWriter`), made before the first step: a path
    that cannot be written raises :class:`gaussim.files.OutputError` before any work, and a log already
    there is moved to ``out.prev``. The steps are written in chunks as the run goes, so that whatever
    stops it, a valid log of the steps made is on disk.

    A signal (SIGINT = Ctrl-C, SIGTERM, SIGHUP) or a simulation error stops the run: the log of the steps
    made so far is written, marked incomplete with the reason, and the exception propagates
    (:class:`Interrupted`, a KeyboardInterrupt, for a signal, which stops the run at the end of its step;
    a second one stops a step that hangs at once; while the log is being written, signals wait).

    Args:
        progress: a stream for a progress line (steps/s, simulated time, active contacts), or None.
        checkpoint_seconds: write a chunk at least this often [s].
        checkpoint_steps: write a chunk when this many steps are held.
        observer: called with the state and the report after every step (e.g. a live viewer,
            :func:`gaussim.viewer.follow`).
    """
    if not (is_real(spec.duration) and spec.duration > 0):  # a spec's fields are the caller's to set
        raise InvalidOptions("duration", f"must be a finite number > 0 [s], got {shown(spec.duration)}")
    steps = spec.options.steps(spec.duration)
    note = spec.options.duration_note(spec.duration)
    if note is not None:  # the run does not simulate the time asked for: say so before it
        warnings.warn(note, GaussimWarning, stacklevel=2)
    line = _Progress(progress, steps) if progress is not None else None
    with compile_notice(line.compiling if line is not None else None):
        return _steps(spec, out, steps, line, checkpoint_seconds, checkpoint_steps, observer)


def _steps(
    spec: SceneSpec,
    out: str | Path | None,
    steps: int,
    progress: _Progress | None,
    checkpoint_seconds: float,
    checkpoint_steps: int,
    observer: Callable[[State, StepReport], None] | None,
) -> RunLog:
    """:func:`run`'s loop, ``progress`` its progress line."""
    sim = Simulator(spec.scene, spec.options)
    state = sim.reset(spec.initial.q, spec.initial.v)
    # absolute: a replay from another folder resolves the scene's relative paths against its folder
    log = RunLog(spec.robot.name, spec.text, spec.options, str(Path(spec.path).resolve()))
    log.start(state, spec.scene.gravity)
    writer = RunLogWriter(out, log) if out is not None else None
    start = last_saved = time.perf_counter()
    with _stop_signals() as stop:
        try:
            for step in range(steps):
                if stop.signal is not None:
                    raise Interrupted(stop.signal, step)
                tau, damping = command(spec.controller(state))
                state = sim.step(state, tau, damping)
                report = sim.last_step
                assert report is not None  # set by every step
                stop.protected = True  # a step is recorded whole or not at all
                log.record(state, sim.full_torque(tau, damping, state.v), report)
                stop.protected = False
                if observer is not None:
                    observer(state, report)
                now = time.perf_counter()
                if progress is not None:
                    progress.update(step + 1, state.t, len(report.contacts))
                if writer is not None and (
                    log.buffered >= checkpoint_steps or now - last_saved > checkpoint_seconds
                ):
                    last_saved = now
                    stop.protected = True
                    _append(writer, log.steps)
                    stop.protected = False
        except BaseException as err:
            stop.protected = True
            interruption = _interruption(err, stop.signal or _signal_name(signal.SIGINT))
            if interruption is not None:
                log.finish(False, f"interrupted ({interruption}) at step {log.steps}, t = {state.t:.6g} s")
                if progress is not None and writer is not None:
                    progress.say(f"{interruption}: stopping, writing the log {writer.path}")
            else:  # a GaussimError, or a bug: either way the steps made are kept
                log.finish(False, f"{type(err).__name__} at step {log.steps}, t = {state.t:.6g} s: {err}")
            _close(writer, log, progress)
            if interruption is not None and not isinstance(err, Interrupted):
                raise Interrupted(interruption, log.steps) from err
            raise
        stop.protected = True
        log.finish(True)
        log.wall_time = time.perf_counter() - start
        _close(writer, log, progress)
    return log if writer is None else RunLog.load(writer.path)


class _Stop:
    """What the signal handler shares with the run: the first stop signal's name, and whether the run is
    recording a step or writing its log (then no signal interrupts it)."""

    def __init__(self) -> None:
        self.signal: str | None = None
        self.protected = False


@contextmanager
def _stop_signals() -> Iterator[_Stop]:
    """Catch the STOP_SIGNALS while the run goes on, for the loop to stop at the end of the step: the
    interrupt never surfaces from inside numba, Pinocchio or ProxQP (numba turns one raised while it
    converts a result into a SystemError). A second one raises KeyboardInterrupt at once (a step that
    hangs), except while a step is recorded or the log written. A signal the process ignores (nohup,
    the background of a script) stays ignored; outside the main thread, where Python delivers no
    signal, Python's own handling applies."""
    stop = _Stop()
    early = taken_stop()  # one that landed before: the run stops before its first step
    stop.signal = None if early is None else _signal_name(early)
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        if stop.signal is not None and not stop.protected:
            stop.protected = True  # from here on the run only writes its log: no signal may stop that
            raise KeyboardInterrupt
        stop.signal = stop.signal or _signal_name(signum)

    previous = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    for s, handling in previous.items():
        if handling != signal.SIG_IGN:
            signal.signal(s, handler)
    try:
        yield stop
    finally:
        for s, handling in previous.items():
            signal.signal(s, handling)


def _signal_name(signum: int) -> str:
    return "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name


def _interruption(err: BaseException, name: str) -> str | None:
    """The signal's name when ``err`` is a stop by signal: an Interrupted, a KeyboardInterrupt, or an error
    a KeyboardInterrupt caused (numba turns one raised while it converts a result into "SystemError: ...
    returned a result with an exception set"); None otherwise."""
    cause: BaseException | None = err
    while cause is not None:
        if isinstance(cause, Interrupted):
            return cause.signal
        if isinstance(cause, KeyboardInterrupt):
            return name
        cause = cause.__cause__ or cause.__context__
    return None


def _append(writer: RunLogWriter, step: int) -> None:
    try:
        writer.append()
    except OSError as err:
        raise LogWriteError(
            f"writing the run log {writer.path} failed at step {step} ({err.strerror or err}); "
            f"the log of the first {writer.steps} steps is there"
        ) from err


def _close(writer: RunLogWriter | None, log: RunLog, progress: _Progress | None) -> None:
    if progress is not None:
        progress.close()
    if writer is None:
        return
    try:
        writer.close()
    except OSError as err:
        raise LogWriteError(
            f"writing the end of the run log {writer.path} failed ({err.strerror or err}): the log of the "
            f"first {writer.steps} steps is there, its header says it is incomplete; the run: {log.reason}"
        ) from err


class _Progress:
    """A run's progress line on ``stream``: steps done, ETA, steps/s, simulated time, active contacts; and
    while numba compiles, :data:`COMPILING` (the time it takes is left out of the rate and the ETA). On a
    terminal a tqdm bar redrawn in place; to a file or a pipe one line every ``PROGRESS_SECONDS[False]`` s
    (a log reads line by line)."""

    def __init__(self, stream: TextIO, total: int) -> None:
        self.stream, self.total, self.tty = stream, total, stream.isatty()
        self.bar = tqdm(
            total=total,
            unit=" steps",
            file=stream,
            mininterval=PROGRESS_SECONDS[True],
            dynamic_ncols=True,
            disable=not self.tty,
        )
        self.start = self.last_line = time.perf_counter()
        self.compiled_since: float | None = None  # when the compile going on started

    def update(self, done: int, t: float, contacts: int) -> None:
        """After a step: ``done`` steps made, at simulated time ``t`` [s], ``contacts`` active."""
        postfix = f"t = {t:.3f} s, contacts: {contacts}"
        if self.tty:
            self.bar.set_postfix_str(postfix, refresh=False)
            self.bar.update(done - self.bar.n)
            return
        now = time.perf_counter()
        if now - self.last_line > PROGRESS_SECONDS[False] or done == self.total:
            self.last_line = now
            meter = tqdm.format_meter(done, self.total, now - self.start, unit=" steps", postfix=postfix)
            self.stream.write(meter + "\n")
            self.stream.flush()

    def compiling(self, active: bool) -> None:
        """numba started (``active``) or ended compiling kernels: say so (a file gets it once)."""
        now = time.perf_counter()
        if active and self.compiled_since is None:
            self.compiled_since = now
        elif not active and self.compiled_since is not None:
            self.start += now - self.compiled_since  # the rate is the stepping's
            self.compiled_since = None
        if self.tty:
            self.bar.set_description_str(COMPILING if active else "", refresh=True)
            if not active:
                self.bar.unpause()  # the same for tqdm's rate
        else:
            announce(self.stream, active)

    def say(self, text: str) -> None:
        """A line of its own under the bar."""
        self.bar.write(text, file=self.stream) if self.tty else print(text, file=self.stream)

    def close(self) -> None:
        self.bar.close()


@contextmanager
def compile_notice(show: Callable[[bool], None] | None) -> Iterator[None]:
    """While inside, call ``show(True)`` when numba starts compiling a kernel that its on-disk cache does
    not hold (a first run: a cached kernel is loaded with no compile) and ``show(False)`` when the
    outermost compile ends; numba's compile events are nested, each start calls again (the line's
    elapsed time is redrawn). ``show`` None: nothing is watched."""
    if show is None:
        yield
        return
    listener = _Compiles(show)
    event.register("numba:compile", listener)
    try:
        yield
    finally:
        event.unregister("numba:compile", listener)


_ANNOUNCED: set[int] = set()  # the streams told of a compile: once is enough


def announce(stream: TextIO, active: bool) -> None:
    """A :func:`compile_notice` callback (with ``functools.partial``) that writes "gaussim: " and
    :data:`COMPILING` on a line of its own to ``stream`` at the first compile this process makes (where
    no progress bar is drawn: loading a scene, a run written to a file)."""
    if active and id(stream) not in _ANNOUNCED:
        _ANNOUNCED.add(id(stream))
        print(f"gaussim: {COMPILING}", file=stream, flush=True)


class _Compiles(event.Listener):
    """numba's compile events, told to a ``show(active)`` callback (:func:`compile_notice`)."""

    def __init__(self, show: Callable[[bool], None]) -> None:
        self.show, self.depth = show, 0

    def on_start(self, event: event.Event) -> None:
        self.depth += 1
        self.show(True)

    def on_end(self, event: event.Event) -> None:
        self.depth -= 1
        if self.depth == 0:
            self.show(False)
