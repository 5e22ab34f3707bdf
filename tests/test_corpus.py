"""A fixed sample of the robot corpora (benchmarks/corpus.py), both passes, 60 steps each: every robot
simulates or is refused naming its fault, with the warnings its file calls for; none crashes, fails or
explodes. The sample holds a robot of each cause issue 22 found (each cause has its own unit test in
test_loaders.py with a small URDF)."""

from __future__ import annotations

import importlib.util
import re
import sys
import time
from pathlib import Path

import numpy as np
import pybullet_data
import pytest

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("corpus", ROOT / "benchmarks" / "corpus.py")
corpus = importlib.util.module_from_spec(spec)
sys.modules["corpus"] = corpus  # its dataclass looks its module up
spec.loader.exec_module(corpus)

DURATION = 0.06  # [s]: allegro_left_hand's false dual infeasibility came at step 23
PYBULLET = Path(pybullet_data.getDataPath())
# robot: (the outcome of both passes, a text its message or warnings must hold)
SAMPLE = {
    "solo12": ("ok", ""),
    "go1": ("ok", ""),  # joint damping and dry friction in its file, applied
    "laikago": ("ok", ""),  # tilted continuous joints: (cos, sin) pairs
    "kinova": ("ok", "'j2s6s200_joint_3' at -1.571 (limits 0.3316, 5.952)"),  # clamped into its limits
    "talos_legs": ("ok", ""),  # its torso's and arms' collision geometry left out, as its loader's visual
    "bravo7_gripper": ("ok", "['bravo_finger1_link', 'bravo_finger2_link'] have no mass"),
    "allegro_left_hand": ("ok", ""),
    "allegro_right_hand": ("ok", ""),  # a false PROXQP_DUAL_INFEASIBLE at step 23
    "centauro": ("ok", "more neighbours than coal stores"),
    "cassie": ("refused", "a closed kinematic loop"),  # read by gaussim's SDF reader, not an ImportError
    "a1/a1.urdf": ("ok", ""),  # <transmission> joints
    "cube_no_rotation.urdf": ("ok", "Bullet's convention for no limit"),
    "teddy_large.urdf": ("ok", "centre of mass of the links 'baseLink'"),
    "torus_deform.urdf": ("refused", "no <link> element"),
    "mini_cheetah/mini_cheetah.urdf": ("ok", "link 'thigh_fl' (the body of joint"),  # I1 + I2 < I3: balanced
    "random_urdfs/000/000.urdf": ("ok", "['random_obj_000'] have no mass"),
    "sphere2red_nocol.urdf": ("refused", "has no collision geometry"),
    "mjcf/half_cheetah.xml": ("ok", ""),  # an MJCF of slide and hinge joints, fixed as it says
    "mjcf/humanoid_fixed.xml": ("refused", "has type 'fixed'; known: hinge, slide, ball, free"),
    "gripper/wsg50_one_motor_gripper_new.sdf": ("ok", "the link 'world' has no <inertial>"),
}
PYBULLET_FILES = (".urdf", ".xml", ".sdf")


@pytest.mark.parametrize("name", SAMPLE)
def test_a_corpus_robot_simulates_or_is_refused_by_name(name):
    outcome, text = SAMPLE[name]
    if name.endswith(PYBULLET_FILES):
        rows = corpus.one(name, "pybullet_data", str(PYBULLET / name), DURATION)
    else:
        rows = corpus.one(name, "example-robot-data", name, DURATION)
    for row in rows:
        assert row.outcome == outcome, (row.run, row.message)
        assert text in row.message + row.warnings, (row.run, row.message, row.warnings)
        if outcome == "ok":
            assert row.steps == round(DURATION / corpus.DT)
            assert row.max_kkt <= 100 * 1e-9  # every answer certified to KKT_RTOL eps_abs


def test_a_fast_turning_collapse_stays_on_the_ground():
    """hextilt collapsing under zero torque rolls its base over the ground at up to 37 rad/s: its
    widened patch (the turn within the step times the hull's size) keeps the resting patch's vertices
    too, so no vertex sinks (the widened outline alone let one reach 10 mm at 0.68 s)."""
    rows = corpus.one("hextilt", "example-robot-data", "hextilt", 0.7)
    zero = next(row for row in rows if row.run == "zero")
    assert zero.outcome == "ok", zero.message
    assert zero.max_penetration_mm < 2.0
    assert 1 <= zero.contacts_median <= zero.contacts_p90  # on the ground, the step's contact points


def test_the_corpus_table_says_when_and_on_what_it_was_made(tmp_path):
    """``python benchmarks/corpus.py``'s table names its command, the day (and the commit of a source
    checkout) and the machine's speed before and after its run, and counts its outcomes."""
    out = tmp_path / "corpus.md"
    argv = ["--only", "sphere2red_nocol.urdf", "--duration", "0.01", "--workers", "1", "--out", str(out)]
    assert corpus.main(argv) == 0
    text = out.read_text()
    command = "python benchmarks/corpus.py " + " ".join(argv)
    assert f"Written by `{command}` (0.01 s each pass, dt = 0.001 s; {time.strftime('%Y-%m-%d')}" in text
    assert re.search(r"a fixed Python loop \(3,000,000 additions\) took \d\.\d\d s before the run", text)
    assert "1 robots: 0 simulate both passes, 1 are refused with a reason, 0 neither." in text
    assert out.with_suffix(".csv").exists()
    assert "| contact points (median / p90) |" in text


def test_a_pass_times_each_step_by_the_least_of_its_runs(monkeypatch):
    """A pass's step times are the least of TIMING_RUNS runs, step by step, when the runs end in the
    same state (gaussim is deterministic); a run that ends elsewhere is said, and its times not read."""
    runs = iter([([1.0, 5.0, 2.0, 9.0], 0.5), ([3.0, 1.0, 2.0, 4.0], 0.5)])

    def run(robot, scene, q0, pass_name, duration, row):
        times, q = next(runs)
        return np.array(times), (np.array([q]), np.zeros(1))

    monkeypatch.setattr(corpus, "scene_and_start", lambda robot: (None, None))
    monkeypatch.setattr(corpus, "_run", run)
    monkeypatch.setattr(corpus, "TIMING_RUNS", 2)
    row = corpus.Row("r", "c", "hold")
    corpus.simulate(None, "hold", 0.004, row)
    assert (row.median_ms, row.p90_ms) == (np.median([1, 1, 2, 4]), np.percentile([1, 1, 2, 4], 90))
    assert row.message == ""
    runs = iter([([1.0, 5.0, 2.0, 9.0], 0.5), ([1.0] * 4, 0.7)])
    row = corpus.Row("r", "c", "hold")
    corpus.simulate(None, "hold", 0.004, row)
    assert row.p90_ms == np.percentile([1, 5, 2, 9], 90)
    assert "differed" in row.message
