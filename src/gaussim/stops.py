"""The signals that stop a run at the end of its step, its log kept: Ctrl-C, kill / timeout, a closed
terminal (a module of its own: the command line reads them while it handles a stop, with nothing heavy
to import then)."""

import signal

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
