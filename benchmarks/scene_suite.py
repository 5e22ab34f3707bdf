"""The scene suite for speed (issue 21): gaussim, MuJoCo and PyBullet (where it loads) on the same
scenes, interleaved step by step in one process; per-step cost (median, p90) and the ratios, gaussim's
deepest penetration and largest KKT residual (see gaussim.bench.scenes).

Run:  python benchmarks/scene_suite.py [SCENES...] [--quick] [--report out/scene_suite.md]
(the same as ``gaussim bench --scenes``; ``--list`` names the scenes).
"""

from __future__ import annotations

import sys

from gaussim.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", "--scenes", *sys.argv[1:]]))
