"""Shared fixtures: robots are loaded once per test session (they are immutable)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import gaussim

G = 9.81


@pytest.fixture(scope="session")
def ball() -> gaussim.Robot:
    return gaussim.load_robot("ball", floating_base=True)


@pytest.fixture(scope="session")
def box() -> gaussim.Robot:
    return gaussim.load_robot("box", floating_base=True)


@pytest.fixture(scope="session")
def pendulum() -> gaussim.Robot:
    return gaussim.load_robot("pendulum")


@pytest.fixture(scope="session")
def solo12() -> gaussim.Robot:
    return gaussim.load_robot("solo12")


def at_height(robot: gaussim.Robot, z: float) -> np.ndarray:
    """Neutral configuration of a floating robot with its base at height z [m]."""
    q = robot.neutral()
    q[2] = z
    return q


def run(sim: gaussim.Simulator, state: gaussim.State, steps: int, tau=None, each=None) -> gaussim.State:
    """Step ``steps`` times, calling ``each(state)`` after every step."""
    for _ in range(steps):
        state = sim.step(state, tau(state) if callable(tau) else tau)
        if each is not None:
            each(state)
    return state


SOLO12_SCENE = "robots/scenes/solo12_standing.toml"


@pytest.fixture(scope="session")
def solo12_run(tmp_path_factory) -> tuple[gaussim.RunLog, gaussim.SceneSpec]:
    """A short logged run of the shipped Solo-12 scene: it drops 1 cm and lands on its four feet."""
    spec = gaussim.load_scene(Path(__file__).parent.parent / SOLO12_SCENE)
    spec.duration = 0.15
    out = tmp_path_factory.mktemp("solo12") / "run.npz"
    return gaussim.run(spec, out), spec


BOX_SIDE = 0.2  # [m], the cubes of two_boxes
_FREE_CUBE = """
  <joint name="{name}_joint" type="floating"><parent link="world"/><child link="{name}"/></joint>
  <link name="{name}">
    <inertial>
      <mass value="{mass}"/><inertia ixx="{i}" ixy="0" ixz="0" iyy="{i}" iyz="0" izz="{i}"/>
    </inertial>
    <collision><geometry><box size="{side} {side} {side}"/></geometry></collision>
  </link>"""


def two_boxes(path: Path, bottom: float, top: float) -> gaussim.Robot:
    """Two free cubes named bottom and top, of masses ``bottom`` and ``top`` [kg], written as a URDF
    at ``path`` (their collision geometries are bottom_0 and top_0)."""
    cubes = "".join(
        _FREE_CUBE.format(name=name, mass=mass, i=mass * BOX_SIDE**2 / 6, side=BOX_SIDE)
        for name, mass in (("bottom", bottom), ("top", top))
    )
    path.write_text(f'<?xml version="1.0"?>\n<robot name="pair"><link name="world"/>{cubes}\n</robot>\n')
    return gaussim.load_robot(path)
