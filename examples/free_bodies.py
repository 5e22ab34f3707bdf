"""Free bodies against their closed forms: a ball rolling down an incline, a body flipping about its
intermediate axis (the Dzhanibekov effect), both in gaussim's default velocity scheme.

Run:  python examples/free_bodies.py [--dt 1e-3]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import pinocchio as pin
from _shared import positive, run

import gaussim

G = 9.81
TOP = """<?xml version="1.0"?>
<robot name="top"><link name="body"><inertial><origin xyz="0 0 0"/><mass value="1"/>
<inertia ixx="1" ixy="0" ixz="0" iyy="2" iyz="0" izz="2.5"/></inertial>
<collision><geometry><box size="0.4 0.3 0.2"/></geometry></collision></link></robot>
"""


def rolling(dt: float, theta: float = np.radians(30.0), mu: float = 0.5) -> None:
    """A solid ball from rest on a 30 deg slope rolls 5/14 g sin(theta) t^2 (tan(theta) < 7/2 mu)."""
    ball = gaussim.load_robot("ball", floating_base=True)
    normal = np.array([-np.sin(theta), 0.0, np.cos(theta)])
    sim = gaussim.Simulator(
        gaussim.Scene(ball, ground=gaussim.Ground(friction=mu, normal=tuple(normal))), gaussim.Options(dt=dt)
    )
    q = ball.neutral()
    q[:3] = 0.1 * normal  # the ball's radius
    state = sim.reset(q)
    depth = 0.0
    while state.t < 1.0 - dt / 2:
        state = sim.step(state)
        depth = max(depth, 0.1 - state.q[:3] @ normal)
    distance = float(np.linalg.norm(state.q[:3] - q[:3]))
    reference = 5 / 14 * G * np.sin(theta) * state.t**2
    print(
        f"rolling: {distance:.5f} m in {state.t:.3f} s (5/14 g sin(theta) t^2 = {reference:.5f} m, "
        f"error {100 * (distance / reference - 1):+.3f} %), deepest {depth:.1e} m"
    )


def flipping(dt: float, w0: tuple[float, float, float] = (0.01, 5.0, 0.01)) -> None:
    """A torque-free body of inertia (1, 2, 2.5) kg m^2 spun near its middle axis turns over and back;
    its energy and world angular momentum stay constant."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "top.urdf"
        path.write_text(TOP)
        top = gaussim.load_robot(path, floating_base=True)
    I = np.array([1.0, 2.0, 2.5])
    sim = gaussim.Simulator(gaussim.Scene(top, gravity=(0, 0, 0)), gaussim.Options(dt=dt))
    state = sim.reset(top.neutral(), np.array([0, 0, 0, *w0]))
    energy, momentum = state.v[3:] @ (I * state.v[3:]) / 2, I * state.v[3:]
    flips, up, drift = 0, True, 0.0
    while state.t < 10.0 - dt / 2:
        state = sim.step(state)
        axis = pin.Quaternion(state.q[3:7]).matrix()[:, 1]  # the body's middle axis, in the world
        if (axis[1] > 0) != up:
            up, flips = not up, flips + 1
        world = pin.Quaternion(state.q[3:7]).matrix() @ (I * state.v[3:])
        drift = max(drift, abs(state.v[3:] @ (I * state.v[3:]) / 2 / energy - 1))
        drift = max(drift, float(np.linalg.norm(world - momentum) / np.linalg.norm(momentum)))
    print(f"flipping: turned over {flips} times in {state.t:.1f} s, energy and momentum kept to {drift:.1e}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dt", type=positive, default=1e-3, help="time step [s]")
    args = parser.parse_args(argv)
    rolling(args.dt)
    flipping(args.dt)
    return 0


if __name__ == "__main__":
    run(main)
