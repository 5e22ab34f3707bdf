"""Scene files: every shipped scene loads and runs; every malformed file is named precisely."""

from pathlib import Path

import numpy as np
import pytest

import gaussim
from gaussim.scenefile import SceneFileError

SCENES = sorted((Path(__file__).resolve().parents[1] / "robots" / "scenes").glob("*.toml"))
STEPS = 200


def test_every_robot_of_the_library_has_a_scene():
    assert {p.stem for p in SCENES} >= {
        "solo12_standing",
        "talos_standing",
        "box_incline",
        "ball_bounce",
        "fourbar",
        "pendulum_limits",
        "double_pendulum",
        "box_stack",
    }


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_shipped_scene_loads_and_runs(path):
    spec = gaussim.load_scene(path)
    spec.duration = STEPS * spec.options.dt
    log = gaussim.run(spec)
    assert log.complete and log.steps == STEPS
    assert np.all(np.isfinite(log.q)) and np.all(np.isfinite(log.v))
    assert log.solver_arrays()["kkt_residual"].max() < 1e-6


def _write(tmp_path, text):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    return path


BALL = '[robot]\nname = "ball"\nfloating_base = true\n'


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        (BALL + "[grond]\n", "grond", "unknown section; known:.*ground"),
        (BALL + "[ground]\nfriction = -1\n", "ground.friction", "must be a finite number >= 0"),
        (BALL + "[ground]\nfrction = 0.5\n", "ground.frction", "unknown key; known:.*friction"),
        (BALL + "[options]\nscheme = 'implicit'\n", "options.scheme", "not one of velocity, acceleration"),
        (BALL + "[options]\ndt = -1\n", "options.dt", "must be a finite number > 0"),
        (BALL + "[initial]\nq = [0, 0]\n", "initial.q", "must be 7 finite numbers"),
        (
            BALL + "[initial]\nconfiguration = 'standing'\n",
            "initial.configuration",
            "no configuration 'standing'",
        ),
        (
            BALL + "[ground]\n[contacts]\npairs = [['ball_9', 'ground']]\n",
            r"contacts.pairs",
            "no collision geometry 'ball_9'.*ball_0",
        ),
        (
            BALL + "[ground]\n[contacts]\npairs = [['ball_0', 'table']]\n",
            r"contacts.pairs",
            "no obstacle 'table'.*ground",
        ),
        (
            BALL + "[[obstacles]]\ntype = 'cone'\nname = 'c'\n",
            r"obstacles\[0\].type",
            "'cone' is not one of box, sphere",
        ),
        (
            BALL + "[[bilaterals]]\ntype = 'anchor'\nframe = 'nose'\nposition = [0, 0, 1]\n",
            r"bilaterals\[0\].frame",
            "no frame 'nose'",
        ),
        (BALL + "[control]\ntype = 'pd'\nkp = -1.0\n", "control", "gains must be >= 0"),
        (BALL + "[simulation]\nduration = 0\n", "simulation.duration", "must be > 0"),
        ('[robot]\nname = "solo13"\n', "robot.name", "no robot 'solo13'.*solo12"),
        ('[robot]\nurdf = "missing.urdf"\n', "robot.urdf", "no such file"),
        ("[robot\n", "toml", ""),
    ],
)
def test_malformed_scene_names_file_and_key(tmp_path, text, key, message):
    path = _write(tmp_path, text)
    with pytest.raises(SceneFileError, match=rf"^{path}: {key}: .*{message}"):
        gaussim.load_scene(path)


def test_overrides_replace_the_scene_options(tmp_path):
    spec = gaussim.load_scene(
        _write(tmp_path, BALL + "[options]\ndt = 0.002\n"), dt=5e-4, scheme="acceleration"
    )
    assert spec.options.dt == 5e-4 and spec.options.scheme == "acceleration"


def test_relative_urdf_path_is_taken_from_the_scene_folder(tmp_path):
    (tmp_path / "models").mkdir()
    urdf = Path(gaussim.robot.ROBOTS_DIR / "ball.urdf").read_text()
    (tmp_path / "models" / "b.urdf").write_text(urdf)
    spec = gaussim.load_scene(_write(tmp_path, '[robot]\nurdf = "models/b.urdf"\nfloating_base = true\n'))
    assert spec.robot.floating and spec.robot.model.nq == 7


def test_ground_clearance_places_the_feet(tmp_path):
    text = (
        '[robot]\nname = "solo12"\n[initial]\nconfiguration = "standing"\nground_clearance = 0.02\n'
        '[ground]\n[contacts]\npairs = [["FL_FOOT_0", "ground"], ["HR_FOOT_0", "ground"]]\n'
    )
    spec = gaussim.load_scene(_write(tmp_path, text))
    sim = gaussim.Simulator(spec.scene, spec.options.replace(contact_margin=1.0))
    sim.step(sim.reset(spec.initial.q))
    assert min(c.gap for c in sim.last_step.contacts) == pytest.approx(0.02, abs=1e-9)
