"""When and where a benchmark's numbers were made: the day, the commit, and the machine's speed.

A shared machine's speed drifts (a fixed Python loop has taken from 0.10 to 0.38 s on the same kind of
machine): a report gives the loop's time before and after its run, so that its timings are compared
within one spell.
"""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

LOOP = 3_000_000  # additions of python_loop


def python_loop() -> float:
    """The seconds a fixed loop of LOOP integer additions takes: the machine's speed for Python."""
    tic = time.perf_counter()
    total = 0
    for k in range(LOOP):
        total += k
    return time.perf_counter() - tic


def commit() -> str:
    """ ", at commit <short hash>" of the source checkout gaussim runs from, or "" (an installed
    package, no git)."""
    try:
        found = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=Path(__file__).parent,
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.SubprocessError):
        return ""
    return f", at commit {found.stdout.strip()}" if found.returncode == 0 and found.stdout.strip() else ""


def made(loops: tuple[float, float]) -> list[str]:
    """The notes of a report's "Made by" line: the day and commit, and the loop's seconds (``loops``,
    from :func:`python_loop` before and after the run)."""
    return [
        time.strftime("%Y-%m-%d") + commit(),
        f"a fixed Python loop ({LOOP:,} additions) took {loops[0]:.2f} s before the run, "
        f"{loops[1]:.2f} s after",
    ]
