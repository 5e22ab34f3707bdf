"""A constraint family written by a user: keep a frame's origin above the plane z >= height.

The family is a :class:`gaussim.constraints.ConstraintModule`; its one method, ``rows``, returns
the row of the admissible set at the level of the Gauss problem being posed (x is v+, w or a):

    phi(q) = z(q) - height >= 0,    J = dz/dq = e_z^T J_frame,    J x >= stabilised bound

(``stabilised_bound`` is the bound gaussim's own families use: at the velocity level a gap closes
within the step at most, a violation is removed at ``stabilisation / dt``). Its multiplier is the
plane's push on the frame [N]. A ball of radius r with no ground in its scene, its centre kept above
z = r by this module, drops and comes to rest on the plane; the example prints the landing time
against sqrt(2 (z0 - r) / g), the resting height against r and the push against m g, and how far
its heights are from the same drop on gaussim's own frictionless ground.

Run:  python examples/custom_constraint.py [--dt 1e-3] [--scheme acceleration]
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from _shared import positive, run

import gaussim
from gaussim.constraints import ConstraintModule, Context, Rows, is_active, stabilised_bound

G = 9.81
RADIUS = 0.1  # the shipped ball's [m]
LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


class AbovePlane(ConstraintModule[None]):
    """Keeps the origin of one frame above the horizontal plane z = ``height`` [m]."""

    name = "above_plane"

    def __init__(self, robot: gaussim.Robot, frame: str, height: float) -> None:
        self.frame = frame
        self.frame_id = robot.frame_id(frame)  # FrameNotFound lists the robot's frames
        self.height = float(height)

    def rows(self, ctx: Context) -> Rows[None] | None:
        z = pin.updateFramePlacement(ctx.model, ctx.data, self.frame_id).translation[2]
        J = pin.getFrameJacobian(ctx.model, ctx.data, self.frame_id, LWA)[2:3]  # (1, nv)
        phi, rate = np.array([z - self.height]), J @ ctx.v
        if not is_active(ctx, phi, rate, ctx.options.contact_margin)[0]:
            return None  # the plane cannot be reached within the step: nothing restricts x
        drift = 0.0  # Jdot v, read at the acceleration level only
        if ctx.level == "acceleration":
            drift = pin.getFrameClassicalAcceleration(ctx.model, ctx.data, self.frame_id, LWA).linear[2]
        bound = stabilised_bound(ctx, phi, rate, drift, unilateral=True)
        return Rows(J, bound, False, lambda: [f"{self.name} {self.frame}"])


@dataclass
class Drop:
    """One drop of the ball: its centre's height each step, and the plane's push at rest."""

    t: np.ndarray  # (N + 1,) [s]
    z: np.ndarray  # (N + 1,) [m]
    landed: float  # the end of the first step in which the plane pushes or strikes [s]
    push: float  # the push at the end [N]


def drop(
    ground: bool, z0: float = 0.5, duration: float = 0.5, dt: float = 1e-3, scheme: str = "velocity"
) -> Drop:
    """The ball released at rest with its centre at ``z0`` [m], held either by :class:`AbovePlane`
    (``ground`` False: no ground in the scene) or by gaussim's frictionless ground at z = 0."""
    ball = gaussim.load_robot("ball", floating_base=True)
    options = gaussim.Options(dt=dt, scheme=scheme)
    if ground:
        sim = gaussim.Simulator(gaussim.Scene(ball, ground=gaussim.Ground(friction=0.0)), options)
    else:
        plane = AbovePlane(ball, "ball", height=RADIUS)
        sim = gaussim.Simulator(gaussim.Scene(ball, ground=None), options, constraints=[plane])
    q = ball.neutral()
    q[2] = z0
    state = sim.reset(q)
    t, z, landed, push = [state.t], [z0], np.inf, 0.0
    while state.t < duration - dt / 2:
        state = sim.step(state)
        report = sim.last_step
        push = _push(report, ground)
        impact = report.impact  # the acceleration scheme's impulsive projection [N s], when there was one
        if landed == np.inf and (push > 0 or (impact is not None and _push(impact, ground) > 0)):
            landed = state.t
        t.append(state.t)
        z.append(state.q[2])
    return Drop(np.array(t), np.array(z), landed, float(push))


def _push(report: gaussim.StepReport, ground: bool) -> float:
    """The upward push of the plane or the ground in ``report`` [N] (an impulse [N s] in an impact's)."""
    if ground:
        return float(report.total_contact_force()[2])
    return sum(r.value for r in report.reactions(AbovePlane.name))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dt", type=positive, default=1e-3)
    parser.add_argument("--scheme", default="velocity", choices=gaussim.options.SCHEMES)
    args = parser.parse_args(argv)
    z0 = 0.5
    custom = drop(False, z0, dt=args.dt, scheme=args.scheme)
    builtin = drop(True, z0, dt=args.dt, scheme=args.scheme)
    mass = gaussim.load_robot("ball", floating_base=True).mass
    print(f"{args.scheme} scheme, dt {args.dt:g} s: a {mass:g} kg ball dropped from z = {z0:g} m")
    print(f"landed at {custom.landed:.4f} s (sqrt(2 (z0 - r) / g) = {np.sqrt(2 * (z0 - RADIUS) / G):.4f} s)")
    print(f"rests at z = {custom.z[-1]:.9f} m (r = {RADIUS:g} m)")
    print(f"pushed up by {custom.push:.6f} N (m g = {mass * G:.6f} N)")
    gap = np.abs(custom.z - builtin.z).max()
    print(f"largest height difference from gaussim's frictionless ground: {gap:.2e} m")
    return 0


if __name__ == "__main__":
    run(main)
