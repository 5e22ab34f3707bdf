"""Matched accuracy on motion (issue 21): a box tossed, a ball rolling down an incline, Solo-12
dropped from 0.3 m, a pile settling; for gaussim and MuJoCo the cheapest setting whose trajectory
(every body's position, RMS over the run) meets 1 mm and 1 cm against a converged reference, and its
wall time per simulated second as a ratio to gaussim's (see gaussim.bench.motion).

Run:  python benchmarks/motion.py [TASKS...] [--quick] [--report out/motion.md]
(the same as ``gaussim bench --motion``; ``--list`` names the tasks).
"""

from __future__ import annotations

import sys

from gaussim.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", "--motion", *sys.argv[1:]]))
