"""The kernels the build compiles ahead (gaussim.kernels.prebuild): the signatures it compiles are the
ones every shipped scene and each primitive pair family call, and its signature codes read back as written."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from gaussim.kernels.prebuild import SIGNATURES, code_of, kernel, parse

# What the build's kernels must cover: every shipped scene for 50 ms (the main job in both schemes), and a
# free body of each primitive shape touching another, a fixed box or the ground (several bodies: islands).
WORKLOAD = """
import numpy as np
import pinocchio as pin
import gaussim
from gaussim import FreeBody
from gaussim.robot import ROBOTS_DIR

for path in sorted((ROBOTS_DIR / "scenes").glob("*.toml")):
    for scheme in ("velocity", "acceleration") if path.stem == "solo12_standing" else (None,):
        spec = gaussim.load_scene(path, **({"scheme": scheme} if scheme else {}))
        spec.duration = 0.05
        gaussim.run(spec)
# every primitive shape as a free body, each touching another or the ground, on a fixed box
bodies = {
    "box": FreeBody.box("box", (0.1, 0.1, 0.1), mass=1.0),
    "ball": FreeBody.sphere("ball", 0.05, mass=1.0),
    "capsule": FreeBody.capsule("capsule", 0.03, 0.2, mass=1.0),
    "cylinder": FreeBody.cylinder("cylinder", 0.05, 0.1, mass=1.0),
}
poses = {
    "box": pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.1505])),  # on the table's top
    "ball": pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.2515])),  # on the box
    "capsule": pin.SE3(pin.rpy.rpyToMatrix(np.pi / 2, 0, 0), np.array([0.4, 0.0, 0.0305])),  # lying
    "cylinder": pin.SE3(np.eye(3), np.array([0.4, 0.3, 0.0505])),  # standing
}
table = gaussim.Box("table", (0.3, 0.3, 0.1), position=(0.0, 0.0, 0.05))
scene = gaussim.Scene(bodies=bodies, ground=gaussim.Ground(), obstacles=[table])
sim = gaussim.Simulator(scene)
state = sim.reset(poses)
for _ in range(100):
    state = sim.step(state)
assert len(sim.last_step.contacts) >= 8, sim.last_step.contacts
"""

# The workload, with every call of a kernel from Python (the stage modules' names) written down as
# prebuild's code of its argument types.
CALLED = (
    """
import importlib
import numba
from numba.core.registry import CPUDispatcher
from gaussim.kernels.prebuild import code_of

def recording(name, dispatcher):
    def call(*args):
        print(name, "=", code_of(tuple(numba.typeof(a) for a in args)))
        return dispatcher(*args)
    return call

STAGES = ("actuation", "assembly", "collision.boxes", "collision.cylinders", "collision.ground",
          "collision.driver", "collision.margin", "collision.narrow", "collision.primitives",
          "constraints.base", "constraints.limits",
          "constraints.contact", "dynamics", "integrator", "solver.active_set", "solver.certificate",
          "solver.dual", "solver.islands", "solver.proxqp", "solver.reactions")
for stage in STAGES:
    module = importlib.import_module("gaussim." + stage)
    for attribute, value in list(vars(module).items()):
        if isinstance(value, CPUDispatcher) and value.py_func.__module__.startswith("gaussim.kernels."):
            kernel = value.py_func.__module__.rsplit(".", 1)[1] + "." + value.py_func.__name__
            setattr(module, attribute, recording(kernel, value))
"""
    + WORKLOAD
)


@pytest.mark.parametrize("name", sorted(SIGNATURES))
def test_a_signature_code_reads_back_as_written(name):
    for code in SIGNATURES[name]:
        assert code_of(parse(code)) == code
    assert kernel(name).py_func.__module__ == f"gaussim.kernels.{name.split('.')[0]}"


def test_the_build_compiles_every_signature_the_workload_calls():
    """A signature left out compiles at the first run (a kernel called with a read-only array where it
    took a writable one is another signature); the wheel's test runs the workload without compiling."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    result = subprocess.run(
        [sys.executable, "-c", CALLED], capture_output=True, text=True, timeout=900, cwd=root
    )
    assert result.returncode == 0, result.stderr
    called = {tuple(line.split(" = ")) for line in result.stdout.splitlines() if " = " in line}
    families = {"boxes.box_pairs", "primitives.primitive_pairs", "cylinders.ground_cylinders"}
    assert {name for name, _ in called} >= {
        "contact.pyramids",
        "solver.islands",
        "dual.dual_iterations",
        "solver.least_norm",
        *families,
    }, called
    missing = sorted((name, code) for name, code in called if code not in SIGNATURES.get(name, ()))
    assert not missing, missing
