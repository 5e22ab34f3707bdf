"""The build also compiles gaussim's kernels into numba's cache beside them (gaussim.kernels.prebuild), so
that the first run after an install does not; when it cannot, they compile at their first call."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py


class BuildPy(build_py):
    def run(self) -> None:
        super().run()
        # an editable install runs the sources in place: their cache goes beside them
        package_root = Path("src" if self.editable_mode else self.build_lib).resolve()
        env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}  # in the tree, not elsewhere
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(package_root), env.get("PYTHONPATH")]))
        command = [sys.executable, "-m", "gaussim.kernels.prebuild"]
        if subprocess.run(command, env=env, check=False).returncode:
            print(
                "gaussim: the kernels were not compiled ahead: they compile at the first run", file=sys.stderr
            )


setup(cmdclass={"build_py": BuildPy})
