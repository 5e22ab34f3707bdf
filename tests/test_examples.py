"""Every example runs headless as a test (short durations)."""

import csv
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _run(*args: str) -> str:
    result = subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_solo12_drop(tmp_path):
    out = tmp_path / "forces.csv"
    stdout = _run(str(EXAMPLES / "solo12_drop.py"), "--duration", "0.3", "--csv", str(out))
    assert "FL_FOOT_0/ground#0" in stdout and "total" in stdout
    rows = list(csv.DictReader(out.open()))
    assert rows and {r["contact"] for r in rows} >= {"FL_FOOT_0/ground#0", "HR_FOOT_0/ground#0"}


@pytest.mark.parametrize("mode", ["pyramid", "accurate"])
def test_sliding_block(mode):
    stdout = _run(str(EXAMPLES / "sliding_block.py"), "--mode", mode, "--heading", "15")
    assert "stopped after" in stdout


def test_watch_box_stack(tmp_path):
    stdout = _run(str(EXAMPLES / "watch_box_stack.py"), "--duration", "0.1", "--out", str(tmp_path / "stack"))
    assert "replay page:" in stdout
    assert (tmp_path / "stack.html").stat().st_size > 0 and (tmp_path / "stack.png").stat().st_size > 0


def test_free_bodies():
    stdout = _run(str(EXAMPLES / "free_bodies.py"), "--dt", "2e-3")
    assert "rolling:" in stdout and "flipping: turned over 1 times" in stdout  # it flips at 4.2 s
