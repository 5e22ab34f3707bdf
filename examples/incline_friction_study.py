"""A parameter study from Python: the box of robots/scenes/box_incline.toml (a 30 degree slope) for
several friction coefficients, its slide against the closed form 1/2 g (sin 30 - mu cos 30) t^2 (none
once mu > tan 30 = 0.577).

The same study from the command line:
    gaussim sweep robots/scenes/box_incline.toml --vary ground.friction=0.1,0.3,0.5,0.7 \\
        --plot box.displacement --against ground.friction

Run:  python examples/incline_friction_study.py [--frictions 0.1,0.3,0.5,0.7] [--duration 0.5]
      [--workers 2] [--out out/incline_friction]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from _shared import positive, run

from gaussim import study

SCENE = Path(__file__).resolve().parents[1] / "robots" / "scenes" / "box_incline.toml"
SLOPE, G = math.radians(30.0), 9.81


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frictions", default="0.1,0.3,0.5,0.7", help="the values of ground.friction")
    parser.add_argument("--duration", type=positive, default=0.5, help="simulated time of each run [s]")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("out/incline_friction"))
    args = parser.parse_args(argv)

    vary = dict([study.parse_vary(f"ground.friction={args.frictions}")])
    vary["simulation.duration"] = [args.duration]
    runs = study.plan(SCENE, vary, args.out)
    records = study.study(runs, args.out, workers=args.workers)  # runs already in out/ are skipped
    frame = study.table(records)
    print(f"{'mu':>5} {'slide [m]':>10} {'closed form [m]':>16} {'status':>7}")
    for _, row in frame.iterrows():
        mu = row["ground.friction"]
        expected = 0.5 * G * max(0.0, math.sin(SLOPE) - mu * math.cos(SLOPE)) * args.duration**2
        print(f"{mu:>5g} {row['box.displacement']:>10.5f} {expected:>16.5f} {row['status']:>7}")
    print(f"table: {study.write_table(records, args.out)}")
    return 0 if (frame["status"] == "ok").all() else 1


if __name__ == "__main__":
    run(main)
