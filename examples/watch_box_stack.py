"""Three stacked boxes (mass ratios 1 : 10 : 100) settle on the ground: write the replay page with
the contact-force arrows and the force plot, or watch it live with --live.

Run:  python examples/watch_box_stack.py [--duration 1] [--out out/watch_box_stack] [--live [--no-wait]]

With --live the run plays at real time in the browser, then its replay is served until Ctrl-C (not
at all with --no-wait, or when standard input is not a terminal).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from _shared import positive, run

import gaussim
from gaussim.plots import save_plot
from gaussim.viewer import Viewer, follow

SCENE = Path(__file__).resolve().parents[1] / "robots" / "scenes" / "box_stack.toml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=positive, default=1.0, help="simulated time [s]")
    parser.add_argument(
        "--out", type=Path, default=Path("out/watch_box_stack"), help="prefix of the files written"
    )
    parser.add_argument("--live", action="store_true", help="also show the run live in the browser")
    parser.add_argument("--no-wait", action="store_true", help="with --live: exit when the run ends")
    args = parser.parse_args()

    spec = gaussim.load_scene(SCENE)
    spec.duration = args.duration
    with Viewer(spec.scene, live=args.live) as viewer:  # a page alone needs no server
        if args.live:
            viewer.show(spec.initial.q, t=0.0)  # the scene is on the page before the first step
            print(f"watch at {viewer.url}", flush=True)
        observer = follow(viewer) if args.live else None
        log = gaussim.run(spec, args.out.with_suffix(".runlog"), observer=observer)
        viewer.replay(log)
        page = viewer.save_html(args.out.with_suffix(".html"))
        plot = save_plot(log, spec.scene, args.out.with_suffix(".png"))
        print(log.summary())
        print(f"replay page: {page}\nforce plot: {plot}")
        if args.live and not args.no_wait and sys.stdin.isatty():
            print(f"the replay is at {viewer.url} (Ctrl-C to stop)", flush=True)
            try:
                while True:
                    time.sleep(1.0)
            except KeyboardInterrupt:
                pass


if __name__ == "__main__":
    run(main)
