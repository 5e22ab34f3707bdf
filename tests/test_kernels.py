"""The kernels the build compiles ahead (gaussim.kernels.prebuild): the signatures it compiles are the
ones the main job calls, and its signature codes read back as written."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from gaussim.kernels.prebuild import SIGNATURES, code_of, kernel, parse

# The main job in both schemes, with every call of a kernel from Python (the stage modules' names)
# written down as prebuild's code of its argument types.
CALLED = """
import importlib
import numba
from numba.core.registry import CPUDispatcher
import gaussim
from gaussim.kernels.prebuild import code_of

def recording(name, dispatcher):
    def call(*args):
        print(name, "=", code_of(tuple(numba.typeof(a) for a in args)))
        return dispatcher(*args)
    return call

for stage in ("actuation", "collision.ground", "collision.margin", "constraints.base", "constraints.contact",
              "dynamics", "integrator", "solver.active_set", "solver.certificate", "solver.proxqp"):
    module = importlib.import_module("gaussim." + stage)
    for attribute, value in list(vars(module).items()):
        if isinstance(value, CPUDispatcher) and value.py_func.__module__.startswith("gaussim.kernels."):
            kernel = value.py_func.__module__.rsplit(".", 1)[1] + "." + value.py_func.__name__
            setattr(module, attribute, recording(kernel, value))
for scheme in ("velocity", "acceleration"):
    spec = gaussim.load_scene("robots/scenes/solo12_standing.toml", scheme=scheme)
    spec.duration = 0.05
    gaussim.run(spec)
"""


@pytest.mark.parametrize("name", sorted(SIGNATURES))
def test_a_signature_code_reads_back_as_written(name):
    for code in SIGNATURES[name]:
        assert code_of(parse(code)) == code
    assert kernel(name).py_func.__module__ == f"gaussim.kernels.{name.split('.')[0]}"


def test_the_build_compiles_every_signature_the_main_job_calls():
    """A signature left out compiles at the first run (a kernel called with a read-only array where it
    took a writable one is another signature); the wheel's test runs the main job without compiling."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    result = subprocess.run(
        [sys.executable, "-c", CALLED], capture_output=True, text=True, timeout=900, cwd=root
    )
    assert result.returncode == 0, result.stderr
    called = {tuple(line.split(" = ")) for line in result.stdout.splitlines() if " = " in line}
    assert {name for name, _ in called} >= {"contact.pyramids", "solver.kkt_residuals"}, called
    missing = sorted((name, code) for name, code in called if code not in SIGNATURES.get(name, ()))
    assert not missing, missing
