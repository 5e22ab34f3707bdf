"""The shipped robots and scenes are package data: a non-editable install runs every shipped scene."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import gaussim

from .test_kernels import WORKLOAD

ROOT = Path(__file__).resolve().parents[1]
LEFT_BY_BUILDS = ("build", "dist", "*.egg-info", ".venv", "out", "__pycache__", ".hypothesis", ".*_cache")
SHIPPED = sorted(
    p.relative_to(ROOT / "robots").as_posix() for p in (ROOT / "robots").rglob("*") if p.is_file()
)

# Run from outside the repository, by the installed package only: each shipped scene loads and steps.
RUN_EVERY_SCENE = """
import sys
from pathlib import Path
import gaussim
from gaussim.robot import ROBOTS_DIR
assert Path(gaussim.__file__).parent / "robots" == ROBOTS_DIR, (gaussim.__file__, ROBOTS_DIR)
for scene in sorted((ROBOTS_DIR / "scenes").glob("*.toml")):
    spec = gaussim.load_scene(scene)
    spec.duration = 3 * spec.options.dt
    assert gaussim.run(spec, Path(scene.stem)).steps == 3
    print("ran", scene.name)
"""


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    source = out / "source"  # a clean copy: a build/ or egg-info left by an earlier build adds its files
    shutil.copytree(ROOT, source, ignore=shutil.ignore_patterns(*LEFT_BY_BUILDS))
    command = [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(out), str(source)]
    built = subprocess.run(command, capture_output=True, text=True, timeout=900)  # it compiles the kernels
    assert built.returncode == 0, built.stderr
    return next(out.glob("gaussim-*.whl"))


def test_the_wheel_holds_every_shipped_robot_and_scene(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    missing = [f for f in SHIPPED if f"gaussim/robots/{f}" not in names]
    assert SHIPPED and not missing, missing


def _run_installed(wheel: Path, tmp_path: Path, script: str, env: dict) -> subprocess.CompletedProcess:
    """``script`` run by Python from outside the source tree, with ``wheel`` unpacked as ``pip install .``
    lays it out first on the path."""
    target = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(target)
    return subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
        env={**env, "PYTHONPATH": str(target)},
    )


def test_an_installed_package_runs_every_shipped_scene(wheel, tmp_path):
    """``pip install .`` (here: the wheel unpacked as an install would lay it) found no robot of its own
    through the source tree's path: 6 of the 8 shipped scenes exited 2."""
    # the kernels as plain Python: this checks where the package finds its files, not the kernels,
    # whose compiling at the installed copy's paths would take a minute
    result = _run_installed(wheel, tmp_path, RUN_EVERY_SCENE, {**_environment(), "NUMBA_DISABLE_JIT": "1"})
    assert result.returncode == 0, result.stderr
    scenes = sorted(p.name for p in (ROOT / "robots" / "scenes").glob("*.toml"))
    assert result.stdout.split() == [word for name in scenes for word in ("ran", name)]


# The kernels' workload (every shipped scene, each primitive pair family), from the installed package,
# with the kernels numba compiles written down.
RUN_THE_WORKLOAD = (
    """
from numba.core import event
compiled = []
class Compiles(event.Listener):
    def on_start(self, ev):
        compiled.append(ev.data["dispatcher"].py_func.__qualname__)
    def on_end(self, ev):
        pass
event.register("numba:compile", Compiles())
"""
    + WORKLOAD
    + """
print(*compiled)
"""
)


def test_an_installed_package_runs_every_scene_without_compiling(wheel, tmp_path):
    """The build compiled the kernels into numba's cache in the wheel (setup.py): the first run after
    ``pip install .`` took 37 s when it compiled them (the main job), and 20 s for the shipped box stack
    while the pair families' kernels compiled at their first call."""
    env = {k: v for k, v in _environment().items() if not k.startswith("NUMBA_")}  # the cache beside them
    result = _run_installed(wheel, tmp_path, RUN_THE_WORKLOAD, env)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == [], result.stdout


def test_a_name_in_both_collections_is_the_shipped_robot_with_a_warning():
    with pytest.warns(
        gaussim.GaussimWarning, match="example-robot-data's robot of that name by its URDF path"
    ):
        robot = gaussim.load_robot("double_pendulum")
    assert Path(robot.urdf) == gaussim.robot.ROBOTS_DIR / "double_pendulum.urdf"


def _environment() -> dict[str, str]:
    import os

    return {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
