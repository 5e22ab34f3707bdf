"""Twenty mixed objects (boxes, balls, capsules) dropped into a bin of five fixed boxes settle into a
pile: prints their motion as it dies out, the deepest penetration, whether any left the bin, and
writes the run log and its replay page.

The bin is tilted by SLOPE, as a hopper's floor is, so that the balls come to rest in its low corner:
on a level floor a ball rolls without end (rigid contact has no rolling resistance).

Run:  python examples/bin_pile.py [--duration 1.2] [--mode accurate] [--out out/bin_pile]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
from _shared import Recording, positive, run

import gaussim
from gaussim import FreeBody

INSIDE, HEIGHT, WALL = 0.28, 0.2, 0.02  # the bin: inner side, wall height, thickness [m]
SLOPE = np.radians(8.0)  # the bin's tilt about its diagonal (-1, 1, 0) [rad]
FRICTION = 0.6  # of the bin and between the objects
DENSITY = 500.0  # of the objects (wood) [kg/m^3]
LAYERS, SPACING = 4, 0.005  # the objects start in 4 layers of 5, this far apart [m]
# Below these speeds every object is at rest [m/s], [rad/s].
AT_REST = (1e-3, 1e-2)


def bin_walls() -> tuple[pin.SE3, list[gaussim.Box]]:
    """The bin's frame (its floor's top centre, tilted by SLOPE) and its floor and four walls."""
    frame = pin.SE3(pin.AngleAxis(SLOPE, np.array([-1.0, 1.0, 0.0]) / np.sqrt(2)).matrix(), np.zeros(3))
    half, side = INSIDE / 2, INSIDE + 2 * WALL
    parts = {
        "floor": ((0, 0, -WALL / 2), (side, side, WALL)),
        "wall_x+": ((half + WALL / 2, 0, HEIGHT / 2), (WALL, side, HEIGHT)),
        "wall_x-": ((-half - WALL / 2, 0, HEIGHT / 2), (WALL, side, HEIGHT)),
        "wall_y+": ((0, half + WALL / 2, HEIGHT / 2), (INSIDE, WALL, HEIGHT)),
        "wall_y-": ((0, -half - WALL / 2, HEIGHT / 2), (INSIDE, WALL, HEIGHT)),
    }
    boxes = [
        gaussim.Box(
            name,
            size,
            position=frame.act(np.array(centre, float)),
            rotation=frame.rotation,
            friction=FRICTION,
        )
        for name, (centre, size) in parts.items()
    ]
    return frame, boxes


def objects() -> dict[str, tuple[FreeBody, float]]:
    """Twenty objects, boxes, balls and capsules in turn, each with its bounding radius [m]."""
    shapes = {
        "box": (lambda name: FreeBody.box(name, (0.08, 0.06, 0.04), density=DENSITY), 0.054),
        "ball": (lambda name: FreeBody.sphere(name, 0.03, density=DENSITY), 0.03),
        "capsule": (lambda name: FreeBody.capsule(name, 0.02, 0.06, density=DENSITY), 0.05),
    }
    chosen = {}
    for k in range(20):
        kind = list(shapes)[k % 3]
        make, radius = shapes[kind]
        chosen[f"{kind}{k}"] = (make(f"{kind}{k}"), radius)
    return chosen


def drop_poses(frame: pin.SE3, bodies: dict[str, tuple[FreeBody, float]], seed: int) -> dict[str, pin.SE3]:
    """Each object's start in the bin: layers of five (the corners and the centre), each layer clear
    of the one below, at random orientations."""
    rng = np.random.default_rng(seed)
    corner = INSIDE / 2 - 0.055
    slots = [(-corner, -corner), (corner, -corner), (corner, corner), (-corner, corner), (0.0, 0.0)]
    names, poses, z = list(bodies), {}, 0.0
    per = len(names) // LAYERS
    for layer in range(LAYERS):
        group = names[layer * per : (layer + 1) * per]
        radius = max(bodies[name][1] for name in group)
        z += radius + SPACING
        for name, (x, y) in zip(group, slots):
            rotation = pin.rpy.rpyToMatrix(*rng.uniform(-0.5, 0.5, 3))
            poses[name] = frame * pin.SE3(rotation, np.array([x, y, z]))
        z += radius
    return poses


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=positive, default=1.2, help="simulated time [s]")
    parser.add_argument("--dt", type=positive, default=1e-3, help="time step [s]")
    parser.add_argument("--mode", default="accurate", choices=gaussim.options.FRICTION_MODES)
    parser.add_argument("--seed", type=int, default=0, help="of the random orientations")
    parser.add_argument("--out", type=Path, default=Path("out/bin_pile"), help="prefix of the files written")
    args = parser.parse_args(argv)

    frame, walls = bin_walls()
    bodies = objects()
    scene = gaussim.Scene(
        bodies={name: body for name, (body, _) in bodies.items()},
        obstacles=walls,
        self_contact=(FRICTION, 0.0),  # between the objects
    )
    sim = gaussim.Simulator(scene, gaussim.Options(dt=args.dt, friction_mode=args.mode))
    state = sim.reset(drop_poses(frame, bodies, args.seed))
    recording = Recording(sim, state)
    print(f"{len(bodies)} objects, {len(scene.pairs)} contact pairs, {args.mode} friction", file=sys.stderr)

    steps, every = sim.options.steps(args.duration), sim.options.steps(0.1)
    deepest, uncertified, wall = 0.0, 0, time.perf_counter()
    for k in range(steps):
        state = recording.step(state)
        report = sim.last_step
        assert report is not None
        deepest = min(deepest, min((c.gap for c in report.contacts), default=0.0))
        uncertified += not report.converged
        if (k + 1) % every == 0 or k == steps - 1:
            linear, angular = (
                max(float(np.linalg.norm(state.body(name).v[part])) for name in bodies)
                for part in (slice(0, 3), slice(3, 6))
            )
            rate = (k + 1) / (time.perf_counter() - wall)
            print(
                f"t = {state.t:.2f} s: {len(report.contacts):3d} contacts, fastest object {linear:.1e} m/s "
                f"and {angular:.1e} rad/s ({rate:.0f} steps/s)",
                file=sys.stderr,
            )
    log, page = recording.save(args.out)

    local = np.array([frame.actInv(state.body(name).q[:3]) for name in bodies])  # in the bin's frame
    inside = bool(np.all(np.abs(local[:, :2]) <= INSIDE / 2) and np.all(local[:, 2] >= 0))
    rest = linear <= AT_REST[0] and angular <= AT_REST[1]
    final = min((c.gap for c in report.contacts), default=0.0)
    print(f"after {state.t:.2f} s: {'at rest' if rest else 'still moving'} (fastest {linear:.1e} m/s)")
    print(f"deepest penetration {-1e3 * deepest:.3f} mm during the run, {-1e3 * final:.2e} mm at the end")
    print(f"every object inside the bin: {inside}; steps with an uncertified QP: {uncertified}")
    print(f"run log: {log}\nreplay page: {page}")
    return 0 if inside and not uncertified else 1


if __name__ == "__main__":
    run(main)
