"""The signals that stop a run at the end of its step, its log kept: Ctrl-C, kill / timeout, a closed
terminal (a module of its own: the command line reads them while it handles a stop, with nothing heavy
to import then)."""

import signal
from types import FrameType

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)

_stopped: list[int] = []  # the stop signals :func:`interrupt` raised, not yet taken


def interrupt(signum: int, frame: FrameType | None) -> None:
    """The command's handler of a stop signal before a run handles its own: a KeyboardInterrupt, as
    Python's, and the signal remembered for :func:`taken_stop` (CPython loses the exception when it
    lands while a C extension module is imported, and the run would go on)."""
    _stopped.append(signum)
    raise KeyboardInterrupt


def taken_stop() -> int | None:
    """The first stop signal :func:`interrupt` raised since the last call, or None; forgets them."""
    first = _stopped[0] if _stopped else None
    _stopped.clear()
    return first
