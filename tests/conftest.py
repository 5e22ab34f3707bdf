"""Shared fixtures: robots are loaded once per test session (they are immutable)."""

from __future__ import annotations

import hashlib
import importlib.util
import os
import tempfile
from pathlib import Path


def _key_the_kernel_cache() -> None:
    """Point numba's on-disk cache at a directory named by a hash of every source of the package.

    numba keys a cached kernel on its own file only: a kernel that inlines a function from another
    file (``linalg.dot``, ``inline="always"``) kept its stale code when only that file changed (a broken
    ``linalg.dot`` passed a slip test). Set before numba is imported, so every pytest run uses it."""
    spec = importlib.util.find_spec("gaussim")
    assert spec is not None and spec.origin is not None, "gaussim is not importable"
    digest = hashlib.sha256()
    for source in sorted(Path(spec.origin).parent.rglob("*.py")):
        digest.update(source.read_bytes())
    base = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(tempfile.gettempdir(), "gaussim-numba")
    os.environ["NUMBA_CACHE_DIR"] = os.path.join(base, digest.hexdigest()[:16])


_key_the_kernel_cache()
# every kernel a stage calls past numba's dispatcher checks its arguments' types (gaussim.kernels.bound)
os.environ["GAUSSIM_CHECK_KERNELS"] = "1"

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402
import pytest  # noqa: E402

import gaussim  # noqa: E402

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


def step_velocity(before: gaussim.State, after: gaussim.State) -> np.ndarray:
    """A floating robot's new velocity v+ as its step posed it, (nv,): the base's linear velocity in
    the frame of the step's start (the step re-expresses it in the new frame, R+^T R v_l+)."""
    v = after.v.copy()
    turn = pin.Quaternion(before.q[3:7]).matrix().T @ pin.Quaternion(after.q[3:7]).matrix()
    v[:3] = turn @ v[:3]
    return v


def frame_acceleration(v: np.ndarray) -> np.ndarray:
    """-w x v_l on a floating base's linear velocity, zeros elsewhere, (nv,): Pinocchio's acceleration
    less that of the Gauss problem's coordinates, in which the base origin's world velocity is held."""
    c = np.zeros(len(v))
    c[:3] = -np.cross(v[3:6], v[:3])
    return c


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


CRATE_SCENE = "robots/scenes/solo12_crate.toml"


@pytest.fixture(scope="session")
def crate_run(tmp_path_factory) -> tuple[gaussim.RunLog, gaussim.SceneSpec, np.ndarray]:
    """A short logged run of the shipped two-body scene (a crate dropped onto Solo-12's back), with
    the force on the crate from Solo-12 at each step as the simulator reported it, (N, 3) [N]."""
    spec = gaussim.load_scene(Path(__file__).parent.parent / CRATE_SCENE)
    spec.duration = 0.3
    reported: list[np.ndarray] = []
    out = tmp_path_factory.mktemp("crate") / "run"
    log = gaussim.run(
        spec, out, observer=lambda s, report: reported.append(report.forces_between("crate", "solo"))
    )
    return log, spec, np.array(reported)
