"""Running a scene file: step it for its duration, log every step, never lose what was done."""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import FrameType
from typing import TextIO

from .control import command
from .report import StepReport
from .runlog import RunLog
from .scenefile import SceneSpec
from .simulator import Simulator
from .state import State

# While a run goes on, its log is rewritten (atomically) this often [s of wall time].
CHECKPOINT_SECONDS = 30.0
# The progress line is redrawn this often [s]: on a terminal, and when written to a file or pipe.
PROGRESS_SECONDS = {True: 0.2, False: 5.0}


def run(
    spec: SceneSpec,
    out: str | Path | None = None,
    *,
    progress: TextIO | None = None,
    checkpoint_seconds: float = CHECKPOINT_SECONDS,
    observer: Callable[[State, StepReport], None] | None = None,
) -> RunLog:
    """Simulate ``spec`` for its duration and return the log (also written to ``out`` when given).

    A Ctrl-C or a simulation error stops the run: the log of the steps made so far is written,
    marked incomplete with the reason, and the exception propagates (KeyboardInterrupt for a Ctrl-C,
    which stops the run at the end of its step; a second one stops it at once).

    Args:
        progress: a stream for a progress line (steps/s, simulated time, active contacts), or None.
        checkpoint_seconds: rewrite ``out`` this often during long runs.
        observer: called with the state and the report after every step (e.g. a live viewer,
            :func:`gaussim.viewer.follow`).
    """
    sim = Simulator(spec.scene, spec.options)
    state = sim.reset(spec.initial.q, spec.initial.v)
    log = RunLog(spec.robot.name, spec.text, spec.options, str(spec.path))
    log.start(state)
    steps = max(1, round(spec.duration / spec.options.dt))
    start = last_shown = last_saved = time.perf_counter()
    step = 0
    try:
        with _ctrl_c() as pressed:
            for step in range(steps):
                if pressed[0]:
                    raise KeyboardInterrupt
                tau, damping = command(spec.controller(state))
                state = sim.step(state, tau, damping)
                report = sim.last_step
                assert report is not None  # set by every step
                log.record(state, sim.full_torque(tau, damping, state.v), report)
                if observer is not None:
                    observer(state, report)
                now = time.perf_counter()
                if progress is not None and (
                    now - last_shown > PROGRESS_SECONDS[progress.isatty()] or step == steps - 1
                ):
                    last_shown = now
                    _show(progress, step + 1, steps, state.t, len(report.contacts), now - start)
                if out is not None and now - last_saved > checkpoint_seconds:
                    last_saved = now
                    log.finish(False, f"checkpoint at step {step + 1} (the run was still going)")
                    log.save(out)
    except KeyboardInterrupt:
        log.finish(False, f"interrupted (Ctrl-C) at step {step}, t = {state.t:.6g} s")
        _save_and_close(log, out, progress)
        raise
    except Exception as err:  # a GaussimError, or a bug: either way the steps made are kept
        if _interrupted(err):  # a Ctrl-C that arrived inside a compiled call comes out as its SystemError
            log.finish(False, f"interrupted (Ctrl-C) at step {step}, t = {state.t:.6g} s")
            _save_and_close(log, out, progress)
            raise KeyboardInterrupt from err
        log.finish(False, f"{type(err).__name__} at step {step}, t = {state.t:.6g} s: {err}")
        _save_and_close(log, out, progress)
        raise
    log.finish(True)
    log.wall_time = time.perf_counter() - start
    _save_and_close(log, out, progress)
    return log


@contextmanager
def _ctrl_c() -> Iterator[list[bool]]:
    """A flag that a Ctrl-C (SIGINT) sets while the run goes on, for the loop to stop at the end of the
    step: the interrupt never surfaces from inside numba, Pinocchio or ProxQP (numba turns one raised
    while it converts a result into a SystemError). A second Ctrl-C raises KeyboardInterrupt at once
    (a step that hangs). A process that ignores SIGINT (started with nohup or in the background of a
    script) keeps ignoring it; outside the main thread, where Python delivers no signal, Python's own
    handling applies."""
    pressed = [False]
    if threading.current_thread() is not threading.main_thread():
        yield pressed
        return
    previous = signal.getsignal(signal.SIGINT)
    if previous == signal.SIG_IGN:
        yield pressed
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        if pressed[0]:
            signal.default_int_handler(signum, frame)
        pressed[0] = True

    signal.signal(signal.SIGINT, handler)
    try:
        yield pressed
    finally:
        signal.signal(signal.SIGINT, previous)


def _interrupted(err: BaseException) -> bool:
    """True when a KeyboardInterrupt caused ``err`` (numba turns one raised while it converts a
    result into "SystemError: ... returned a result with an exception set")."""
    cause: BaseException | None = err
    while cause is not None:
        if isinstance(cause, KeyboardInterrupt):
            return True
        cause = cause.__cause__ or cause.__context__
    return False


def _save_and_close(log: RunLog, out: str | Path | None, progress: TextIO | None) -> None:
    if progress is not None:
        print(file=progress)
    if out is not None:
        log.save(out)


def _show(stream: TextIO, done: int, total: int, t: float, contacts: int, elapsed: float) -> None:
    width = 30
    filled = int(width * done / total)
    bar = "#" * filled + "-" * (width - filled)
    end = "\r" if stream.isatty() else "\n"
    rate = done / elapsed
    stream.write(
        f"[{bar}] {done}/{total} steps  t = {t:.3f} s  {rate:,.0f} steps/s  contacts: {contacts}{end}"
    )
    stream.flush()
