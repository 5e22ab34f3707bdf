"""Stress: a light box under a heavy one and the reverse, mass ratios 1 .. 1e6, 10 s each.

Pass criterion: the stack holds: penetration below 1e-4 m at every step and no sinking (the top
box's height moves less than SINK_TOLERANCE between t = 1 s and the end).

Found by these cases and fixed in the engine: coal 3.0's default GJK returns a NaN normal for two
boxes face to face (the detector retries with the Nesterov-accelerated GJK); ProxQP stops at its
iteration cap when redundant contact rows conflict in round-off (accepted when the KKT check
certifies the point); a -1e-7 multiplier beside a 1e4 load failed an absolute sign test (now
relative to the problem's scale).
"""

from __future__ import annotations

import numpy as np
import pytest

import gaussim
from gaussim.bench.cases import BOX_SIDE as SIDE
from gaussim.bench.cases import two_boxes

PENETRATION = 1e-4  # [m]
SINK_TOLERANCE = 1e-5  # [m]


def run_stack(robot: gaussim.Robot, seconds: float, dt: float = 1e-3) -> tuple[float, float]:
    """(largest penetration [m], sinking of the top box from t = 1 s to the end [m])."""
    scene = gaussim.Scene(
        robot, ground=gaussim.Ground(friction=0.8), contacts=[("bottom_0", "ground"), ("top_0", "bottom_0")]
    )
    sim = gaussim.Simulator(scene, gaussim.Options(dt=dt))
    q = robot.neutral()
    q[2], q[9] = SIDE / 2, 1.5 * SIDE  # bottom centre, top centre: resting, touching
    state = sim.reset(q)
    penetration, settled = 0.0, None
    for _ in range(round(seconds / dt)):
        state = sim.step(state)
        bottom, top = state.q[2], state.q[9]
        penetration = max(penetration, SIDE / 2 - bottom, SIDE - (top - bottom))
        if settled is None and state.t >= 1.0:
            settled = top
    assert np.isfinite(state.q).all()
    return penetration, abs(state.q[9] - settled)


@pytest.mark.parametrize("ratio", [1.0, 1e2, 1e4, 1e6])
@pytest.mark.parametrize("heavy", ["top", "bottom"])
def test_stack_holds(tmp_path, ratio, heavy):
    masses = (1.0, ratio) if heavy == "top" else (ratio, 1.0)
    penetration, sinking = run_stack(two_boxes(tmp_path / "pair.urdf", *masses), seconds=10.0)
    assert penetration < PENETRATION, f"penetration {penetration:.3g} m"
    assert sinking < SINK_TOLERANCE, f"sank {sinking:.3g} m"
