"""Parameter studies (gaussim sweep): keys, values, the product, seeds, failures, resume, Dask, table."""

import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import gaussim
from gaussim import study
from gaussim.cli import main
from gaussim.exceptions import GaussimError, InvalidOptions
from gaussim.pool import FolderInUse, exclusive, load
from gaussim.runlog import RunLog
from gaussim.scenefile import load_scene, load_scene_text

SCENES = Path(__file__).resolve().parents[1] / "robots" / "scenes"
INCLINE = SCENES / "box_incline.toml"
BALL = SCENES / "ball_bounce.toml"
TWO_BODIES = """
[[bodies]]
name = "crate"
shape = "box"
size = [0.2, 0.2, 0.2]
mass = 1.0
position = [0.0, 0.0, 0.1]

[[bodies]]
name = "ball"
shape = "sphere"
radius = 0.05
mass = 0.2
position = [0.5, 0.0, 0.05]

[ground]
friction = 0.8

[simulation]
duration = 0.1
"""
# the box of box_incline.toml slides down 30 degrees: a = g (sin - mu cos) while mu < tan 30 deg
G, SLOPE = 9.81, math.radians(30.0)
# its slide over 0.2 s against the closed form: the first steps settle it on the plane (0.5% seen)
SLIDE_RTOL = 0.02


def _sweep(*args: object) -> int:
    return main(["sweep", *map(str, args), "--workers", "1"])


def test_every_shipped_scene_survives_its_toml_writing():
    for path in SCENES.glob("*.toml"):
        data = tomllib.loads(path.read_text())
        assert tomllib.loads(study.to_toml(data)) == data, path.name
    odd = {"a": {"b c": 'quote " and \\ \x7f\n', "x": [1.5, -math.inf, True, [1, 2]], "t": {"u": 1}}}
    assert tomllib.loads(study.to_toml(odd)) == odd


def test_values_are_toml_separated_by_commas_outside_brackets():
    assert study.parse_vary("bodies.crate.position=[0, 0, 0.3],[0,0,0.5]") == (
        "bodies.crate.position",
        [[0, 0, 0.3], [0, 0, 0.5]],
    )
    assert study.parse_vary('options.friction_mode=pyramid, "exact"') == (
        "options.friction_mode",
        ["pyramid", "exact"],
    )
    assert study.parse_vary("options.dt=1e-3,2e-3") == ("options.dt", [1e-3, 2e-3])
    assert study.parse_vary("bodies.ball.mass=1,1.0")[1] == [1, 1.0]  # as TOML reads them (plan: one value)


@pytest.mark.parametrize(
    "vary, message",
    [
        ("friction", "must be KEY=VALUES"),
        ("ground.friction=", "--vary ground.friction: no values given"),
        ("ground.friction=0.1,,0.2", "--vary ground.friction: an empty value"),
        ("ground.friction=0.1+", "--vary ground.friction: '0.1+' is not a value"),
    ],
)
def test_malformed_values_are_refused_naming_the_key(vary, message):
    with pytest.raises(InvalidOptions, match=re.escape(message)):
        study.parse_vary(vary)


def test_keys_address_fields_bodies_by_name_and_list_elements(tmp_path):
    scene = tmp_path / "two.toml"
    scene.write_text(TWO_BODIES)
    vary = {
        "bodies.crate.mass": [2.0],
        "bodies[1].position[0]": [0.7],
        "options.dt": [2e-3],
        "contacts.friction": [0.3],
    }
    (run,) = study.plan(scene, vary, tmp_path / "out")
    spec = load_scene_text(run.text, scene)
    assert spec.scene.bodies["crate"].robot.mass == pytest.approx(2.0)
    assert spec.initial.body("ball").q[0] == 0.7 and spec.initial.body("ball").q[2] == 0.05
    assert spec.options.dt == 2e-3 and spec.scene.self_contact[0] == 0.3
    one_robot = study.plan(SCENES / "solo12_standing.toml", {"control.kp": [7.0]}, tmp_path / "out")
    assert load_scene_text(one_robot[0].text, SCENES / "solo12_standing.toml").controller.kp == 7.0


@pytest.mark.parametrize(
    "key, value, message",
    [
        ("dt", 1e-3, "unknown section 'dt'.*did you mean options.dt"),
        ("ground.frictoin", 0.1, "unknown field 'frictoin' of \\[ground\\]; known: friction"),
        ("bodies.box.mass", 1.0, "no \\[\\[bodies\\]\\] table named 'box'; the scene's: crate, ball"),
        ("bodies.crate.size[3]", 1.0, "the scene's size is \\[0.2, 0.2, 0.2\\]: it has no element \\[3\\]"),
        ("options.dt[0]", 1.0, "the scene gives no dt: it has no element \\[0\\]"),
        ("control.kp", 1.0, "this scene is of \\[\\[bodies\\]\\]"),
        ("bodies.crate.mass", -1.0, "the value -1.0: .*bodies\\[0\\].mass"),
        (
            "bodies.crate.size[1]",
            -0.1,
            "the value -0.1: .*bodies\\[0\\].size: .*> 0, got -0.1$",
        ),  # not np's repr
        ("bodies.crate.mass", [2.0, 2.0], "the value 2.0 is given twice"),
        ("bodies.crate.mass", [1, 2, 1.0], "the value 1.0 is given twice"),  # one number, two types
        ("bodies.crate.position", [[0, 0, 1], [0, 0, 1.0]], r"the value \[0, 0, 1.0\] is given twice"),
        ("options.scheme", "fast", 'the value "fast": .*options.scheme.*velocity'),
    ],
)
def test_unknown_keys_and_refused_values_name_the_key(tmp_path, key, value, message):
    scene = tmp_path / "two.toml"
    scene.write_text(TWO_BODIES)
    values = value if isinstance(value, list) else [value]
    with pytest.raises(InvalidOptions, match=f"--vary {re.escape(key)}: {message}"):
        study.plan(scene, {key: values}, tmp_path / "out")


@pytest.mark.parametrize("values", [0.1, "0.1,0.2", {0.1, 0.2}, np.float64(0.1)])
def test_the_values_of_a_key_are_a_list(tmp_path, values):
    with pytest.raises(InvalidOptions, match=re.escape("--vary ground.friction: needs a list of values")):
        study.plan(INCLINE, {"ground.friction": values}, tmp_path)


def test_a_numpy_array_gives_a_key_its_values_as_python_numbers(tmp_path):
    runs = study.plan(INCLINE, {"ground.friction": np.array([0.25, 0.5])}, tmp_path)
    assert [r.values for r in runs] == [(("ground.friction", 0.25),), (("ground.friction", 0.5),)]
    assert {type(r.values[0][1]) for r in runs} == {float}


def test_a_study_varies_a_key_or_the_seeds(tmp_path):
    """A study of no key and no seed would be one run of the scene as it is (gaussim run's), and its
    table would replace the folder's."""
    with pytest.raises(InvalidOptions, match=re.escape("--vary: nothing varies")):
        study.plan(INCLINE, {}, tmp_path)
    assert [r.label for r in study.plan(INCLINE, {}, tmp_path, seeds=2)] == ["seed=0", "seed=1"]


@pytest.mark.parametrize(
    "first, second, message",
    [
        (
            "bodies[1].mass=1.0",
            "bodies.ball.mass=2.0",
            "bodies.ball.mass: sets the field --vary bodies[1].mass sets",
        ),
        (
            "bodies.crate.position[2]=0.2",
            "bodies[0].position[2]=0.3",
            "sets the field --vary bodies.crate.position[2]",
        ),
        (
            "bodies.ball.position=[0.5, 0, 0.1]",
            "bodies[1].position[2]=0.2",
            "overlaps --vary bodies.ball.position (a",
        ),
        (
            "bodies.ball.position[2]=0.2",
            "bodies[1].position=[0.5, 0, 0.1]",
            "overlaps --vary bodies.ball.position[2]",
        ),
    ],
)
def test_two_keys_that_set_one_field_are_refused_naming_both(tmp_path, first, second, message):
    """The later key's value would be the one the runs use, the earlier's the one the table shows."""
    scene = tmp_path / "two.toml"
    scene.write_text(TWO_BODIES)
    with pytest.raises(InvalidOptions, match=re.escape(message)):
        study.plan(scene, dict(map(study.parse_vary, (first, second))), tmp_path / "out")
    apart = {"bodies.ball.position[0]": [0.6], "bodies[1].position[2]": [0.1], "bodies.crate.mass": [2.0]}
    (run,) = study.plan(scene, apart, tmp_path / "out")  # two elements of one list are two fields
    assert load_scene_text(run.text, scene).initial.body("ball").q[[0, 2]].tolist() == [0.6, 0.1]


@pytest.mark.parametrize(
    "args, message",
    [
        ([], "--vary: nothing varies: give --vary KEY=VALUES or --seeds N"),
        (["--vary", "options.dtt=1e-3"], "--vary options.dtt: unknown field 'dtt' of [options]"),
        (["--vary", "ground.friction="], "--vary ground.friction: no values given"),
        (["--vary", "ground.friction=-0.5"], "--vary ground.friction: the value -0.5"),
        (["--vary", "ground.friction=1", "--vary", "ground.friction=2"], "given twice"),
        (["--vary", "ground.friction=1,1.0"], "--vary ground.friction: the value 1.0 is given twice"),
        (
            ["--vary", "ground.normal=[0,0,1]", "--vary", "ground.normal[2]=2"],
            "overlaps --vary ground.normal",
        ),
        (["--seeds", "2", "--velocity-noise", "-1"], "--velocity-noise: must be a finite number >= 0"),
        (["--vary", "ground.friction=1", "--plot", "box.speed", "--against", "options.dt"], "not varied"),
        (["--vary", "ground.friction=1", "--plot", "speed", "--against", "ground.friction"], "box.speed"),
        (
            [
                "--vary",
                "ground.friction=1",
                "--plot",
                "box.x",
                "--against",
                "ground.friction",
                "--plot-file",
                "x.jpg",
            ],
            "--plot-file x.jpg: the image's suffix must be one of .png, .pdf, .svg",
        ),
        (
            ["--vary", "ground.friction=1", "--scheduler", "127.0.0.1"],
            "--scheduler: '127.0.0.1': missing port",
        ),
        (["--vary", "ground.friction=1", "--scheduler", "localhost:x"], "its port 'x' is not a number"),
        (["--vary", "ground.friction=1", "--scheduler", "http://host"], "unknown address scheme 'http'"),
    ],
)
def test_the_command_refuses_bad_input_with_exit_2_and_no_traceback(tmp_path, capsys, args, message):
    assert _sweep(INCLINE, "--out", tmp_path, *args) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert " to run on " not in err, "the input is checked before the sweep says what it runs"
    assert not (tmp_path / study.RESULTS).exists(), "nothing runs before the input is checked"


def test_an_out_that_cannot_be_a_folder_is_refused_before_any_run(tmp_path, capsys):
    afile = tmp_path / "afile"
    afile.write_text("mine")
    for out, message in ((afile, "is a file, not a folder"), (afile / "sub", "cannot be written")):
        assert _sweep(INCLINE, "--vary", "ground.friction=0.1", "--out", out) == 2
        err = capsys.readouterr().err
        assert f"gaussim: --out {out}: {message}" in err and " to run on " not in err
    assert afile.read_text() == "mine"


def test_a_friction_sweep_slides_the_box_as_the_closed_form(tmp_path, capsys):
    """Each value reaches its run: the box's slide over 0.2 s is 1/2 g (sin - mu cos) t^2, or none
    once mu > tan 30 deg; the seeds move the start along the slope by about 1 mm (the box stays on it)."""
    frictions = [0.1, 0.3, 0.7]
    code = _sweep(
        INCLINE,
        "--vary",
        "ground.friction=" + ",".join(map(str, frictions)),
        "--vary",
        "simulation.duration=0.2",
        "--seeds",
        2,
        "--velocity-noise",
        0,
        "--out",
        tmp_path,
        "--plot",
        "box.displacement",
        "--against",
        "ground.friction",
    )
    assert code == 0
    frame = pd.read_parquet(tmp_path / study.TABLE)
    assert list(frame["ground.friction"]) == [mu for mu in frictions for _ in range(2)]
    assert list(frame["seed"]) == [0, 1] * 3 and set(frame["status"]) == {"ok"}
    for mu, slide in zip(frame["ground.friction"], frame["box.displacement"]):
        expected = 0.5 * G * max(0.0, math.sin(SLOPE) - mu * math.cos(SLOPE)) * 0.2**2
        assert slide == pytest.approx(expected, rel=SLIDE_RTOL, abs=1e-4), mu
    starts = frame.groupby("seed")["box.y"].first()
    assert 1e-5 < abs(starts[0] - starts[1]) < 1e-2, "the seeds perturb the start along the slope"
    assert (tmp_path / "box.displacement-vs-ground.friction.png").stat().st_size > 0
    for log in frame["log"]:
        assert (tmp_path / log / "header.json").is_file()
    assert "[6/6]" in capsys.readouterr().err


def test_the_perturbation_is_the_seeds_and_moves_floating_bases_along_the_ground_and_velocities(tmp_path):
    spec = load_scene_text(TWO_BODIES, tmp_path / "two.toml")
    noise = study.Noise(position=1e-3, velocity=1e-2)
    first, again, other = (study.perturbed(spec, s, noise) for s in (3, 3, 4))
    np.testing.assert_array_equal(first.q, again.q)
    assert not np.array_equal(first.q, other.q)
    moved = first.q - spec.initial.q
    for name in ("crate", "ball"):
        q = spec.scene.bodies[name].q
        assert np.all(moved[q][:2] != 0) and np.all(moved[q][2:] == 0), name  # along the flat ground
    assert np.all(first.v != 0) and np.abs(first.v).max() < 10 * noise.velocity
    still = study.perturbed(spec, 3, study.Noise(0.0, 0.0))
    np.testing.assert_array_equal(still.q, spec.initial.q)


def test_the_perturbation_moves_every_free_root_of_a_body():
    """robots/box_stack.urdf: three boxes on free-flyer joints in one body; only the first was moved."""
    spec = load_scene(SCENES / "box_stack.toml")
    moved = study.perturbed(spec, 3, study.Noise(position=1e-3, velocity=0.0)).q - spec.initial.q
    for first in (0, 7, 14):  # each box's x, y moved along the ground, z and orientation kept
        assert np.all(moved[first : first + 2] != 0) and np.all(moved[first + 2 : first + 7] == 0), first


def test_the_summary_follows_every_free_root_of_a_body_named_by_its_joint():
    """box_stack.x, .z, .speed were the bottom box's alone: the top box could fall off unseen."""
    spec = load_scene(SCENES / "box_stack.toml")
    spec.duration = 0.05
    q = spec.initial.q.copy()
    q[14] += 0.3  # the top box starts beside the stack, 0.5 m up: it falls
    spec.initial = gaussim.State(0.0, q, spec.initial.v, spec.initial.world)
    summary = study.summarise(gaussim.run(spec), spec)
    boxes = [f"box_stack.{box}_joint" for box in ("bottom", "middle", "top")]
    assert study.summary_columns(spec) == [
        *study.SUMMARY, *(f"{box}.{c}" for box in boxes for c in study.BODY_SUMMARY)
    ]  # fmt: skip
    assert list(summary) == study.summary_columns(spec)
    assert summary["box_stack.top_joint.x"] == pytest.approx(0.3)
    assert summary["box_stack.top_joint.z"] == pytest.approx(0.5 - 9.81 * 0.05**2 / 2, abs=2e-3)
    assert summary["box_stack.top_joint.speed"] == pytest.approx(9.81 * 0.05, rel=1e-6)
    assert summary["box_stack.middle_joint.z"] == pytest.approx(0.3, abs=1e-3)
    assert summary["box_stack.bottom_joint.speed"] < 1e-3
    assert study.summary_columns(load_scene(BALL))[-5:] == [f"ball.{c}" for c in study.BODY_SUMMARY]
    # a change of these columns must raise SUMMARY_FORMAT: resumed sweeps then summarise again
    assert (study.SUMMARY_FORMAT, study.SUMMARY, study.BODY_SUMMARY) == (
        2,
        (*"steps t_end wall_time max_penetration max_kkt_residual".split(), "unconverged_steps",
         "max_contact_force", "kinetic_energy"),
        ("x", "y", "z", "displacement", "speed"),
    )  # fmt: skip


def test_a_failing_run_is_a_row_and_the_others_go_on(tmp_path):
    """A ball started 5 cm deep into the ground is refused when its run starts (not when its scene
    loads): that run's status says why, the other run is made."""
    runs = study.plan(BALL, {"initial.q[2]": [0.05, 0.2], "simulation.duration": [0.05]}, tmp_path)
    records = study.study(runs, tmp_path, workers=1)
    assert "InvalidState" in records[0]["status"] and "penetrat" in records[0]["status"]
    assert records[1]["status"] == "ok" and records[1]["summary"]["ball.z"] < 0.2
    frame = study.table(records)
    assert frame["status"].iloc[1] == "ok" and math.isnan(frame["ball.z"].iloc[0])


def test_an_interrupted_sweep_resumes_without_redoing_its_finished_runs(tmp_path, capsys):
    args = ["--vary", "simulation.duration=0.05", "--out", tmp_path]
    assert _sweep(BALL, "--vary", "ground.restitution=0.5", *args) == 0
    results = tmp_path / study.RESULTS
    (finished,) = load(results)
    results.write_text(results.read_text() + '{"key": "a line cut by the interrupt')
    (tmp_path / study.RUNS / "half-written").mkdir()  # a run killed midway left a partial log
    capsys.readouterr()
    assert _sweep(BALL, "--vary", "ground.restitution=0.5,0.9", *args) == 0
    err = capsys.readouterr().err
    assert "2 runs, 1 already in" in err and "[1/1] ground.restitution=0.9" in err
    frame = pd.read_parquet(tmp_path / study.TABLE)
    assert list(frame["ground.restitution"]) == [0.5, 0.9]
    assert frame["run"].iloc[0] == finished["run"]
    assert _sweep(BALL, "--vary", "ground.restitution=0.9", *args) == 0
    assert "1 runs, 1 already in" in capsys.readouterr().err
    assert len(pd.read_parquet(tmp_path / study.TABLE)) == 1, "the table holds the runs asked for"


def test_a_resumed_sweep_summarises_the_runs_an_older_gaussim_summarised_again(tmp_path, capsys):
    """A sweep resumed by a gaussim whose summary changed (a body's columns renamed, SUMMARY_FORMAT
    raised) reads the runs it holds again from their logs: one table of one summary's columns, the
    new record appended; a run whose log is gone keeps its record."""
    args = ["--vary", "simulation.duration=0.05", "--out", tmp_path]
    assert _sweep(BALL, "--vary", "ground.restitution=0.5,0.7", *args) == 0
    results = tmp_path / study.RESULTS
    made = load(results)
    assert {r["summary_format"] for r in made} == {study.SUMMARY_FORMAT}
    for record in made:  # as an older gaussim wrote them
        del record["summary_format"]
        record["summary"] = {k.replace("ball.", "ball_old."): v for k, v in record["summary"].items()}
    results.write_text("".join(json.dumps(r) + "\n" for r in made))
    shutil.rmtree(tmp_path / made[1]["log"])
    capsys.readouterr()
    assert _sweep(BALL, "--vary", "ground.restitution=0.5,0.7,0.9", *args) == 0
    frame = pd.read_parquet(tmp_path / study.TABLE)
    assert list(frame["ground.restitution"]) == [0.5, 0.7, 0.9]
    assert frame["ball.z"].notna().tolist() == [True, False, True]  # the second's log is gone
    assert frame["ball_old.z"].notna().tolist() == [False, True, False]
    again = load(results)
    assert len(again) == 4 and again[2]["key"] == made[0]["key"]
    assert again[2]["summary_format"] == study.SUMMARY_FORMAT
    assert again[2]["summary"]["ball.z"] == RunLog.load(tmp_path / made[0]["log"]).q[-1][2]


# holds a folder's lock as a sweep does, until killed
HOLD = """
import sys, time
from pathlib import Path
from gaussim.pool import exclusive
with exclusive(Path(sys.argv[1])):
    print("held", flush=True)
    time.sleep(600)
"""


def test_a_second_sweep_into_a_folder_being_written_stops_at_once(tmp_path, capsys):
    """Two sweeps into one folder would both make every run (runs.jsonl twice as long, each log kept as
    .prev): the second stops, naming the folder. The lock dies with its process: a sweep killed midway
    stops no later one."""
    args = (INCLINE, "--vary", "ground.friction=0.1", "--vary", "simulation.duration=0.01", "--out", tmp_path)
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline() == "held\n"
        assert _sweep(*args) == 2
        err = capsys.readouterr().err
        assert f"gaussim: {tmp_path}: another sweep (process {holder.pid}) is writing this folder" in err
        assert " to run on " not in err
        with pytest.raises(FolderInUse, match="another sweep"):
            study.study(study.plan(INCLINE, {"ground.friction": [0.1]}, tmp_path), tmp_path, workers=1)
        assert not (tmp_path / study.RESULTS).exists()
    finally:
        holder.kill()
        holder.wait()
    assert _sweep(*args) == 0, "the lock of a killed process is free"


HOLD_AND_FORK = """
import os, sys, time
from pathlib import Path
from gaussim.pool import exclusive
with exclusive(Path(sys.argv[1])):
    child = os.fork()  # as the process pool forks its workers
    if child == 0:
        time.sleep(600)
        os._exit(0)
    print(child, flush=True)
    time.sleep(600)
"""


def test_a_killed_sweeps_forked_workers_do_not_hold_its_folder(tmp_path):
    """The pool's workers are forked while the sweep holds the lock; killed by -9, the sweep leaves them
    running (orphans waiting on its pipe), and a lock they inherited (an flock) kept the folder locked
    until someone killed them. Only the process that took it holds it, and one thread's lock is not
    another's."""
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD_AND_FORK, str(tmp_path)], stdout=subprocess.PIPE, text=True
    )
    child = int(holder.stdout.readline())
    holder.kill()
    holder.wait()
    try:
        with exclusive(tmp_path):  # the orphaned child still runs
            other = []
            thread = threading.Thread(target=lambda: other.append(_enter(tmp_path)))
            thread.start()
            thread.join()
            assert other == ["another sweep of this process is writing this folder"]
    finally:
        os.kill(child, signal.SIGKILL)


def _enter(folder: Path) -> str:
    """What taking ``folder``'s lock raised, else ""."""
    try:
        with exclusive(folder):
            return ""
    except FolderInUse as err:
        return str(err).split(": ", 1)[1]


def test_the_sweep_command_runs_on_a_dask_cluster(tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=1, processes=False, threads_per_worker=1) as cluster:
        code = main(
            [
                "sweep",
                str(INCLINE),
                "--vary",
                "options.dt=1e-3,2e-3",
                "--vary",
                "simulation.duration=0.1",
                "--out",
                str(tmp_path),
                "--scheduler",
                cluster.scheduler_address,
            ]
        )
    assert code == 0
    frame = pd.read_parquet(tmp_path / study.TABLE)
    assert list(frame["options.dt"]) == [1e-3, 2e-3] and set(frame["status"]) == {"ok"}
    assert list(frame["steps"]) == [100, 50]


def test_a_worker_in_another_folder_writes_each_log_into_the_sweeps_folder(tmp_path, monkeypatch):
    """A Dask worker runs in a working directory of its own: a run planned with a relative scene path
    and output folder (the default out/SCENE.sweep) writes its log there all the same, and the log
    names the scene file."""
    (tmp_path / "box.toml").write_text(INCLINE.read_text())
    monkeypatch.chdir(tmp_path)
    (run,) = study.plan("box.toml", {"simulation.duration": [0.01]}, "out/box.sweep")
    (tmp_path / "worker").mkdir()
    monkeypatch.chdir(tmp_path / "worker")
    record = study.run_one(run)
    assert record["status"] == "ok"
    log = RunLog.load(tmp_path / "out" / "box.sweep" / record["log"])
    assert log.scene_path == str(tmp_path / "box.toml")
    assert not (tmp_path / "worker" / "out").exists()


def test_runs_planned_for_another_folder_are_refused(tmp_path):
    """plan(out=A) then study(runs, B) put the logs in A and the records and lock in B."""
    runs = study.plan(INCLINE, {"ground.friction": [0.1]}, tmp_path / "a")
    with pytest.raises(InvalidOptions, match=r"out: .*b: the runs were planned for .*a: give plan"):
        study.study(runs, tmp_path / "b", workers=1)
    assert not (tmp_path / "b").exists() and not (tmp_path / "a").exists()


def test_a_malformed_scheduler_address_is_refused_before_any_run(tmp_path, monkeypatch):
    runs = study.plan(INCLINE, {"ground.friction": [0.1]}, tmp_path)
    with pytest.raises(InvalidOptions, match="--scheduler: 'tcp://127.0.0.1': missing port"):
        study.study(runs, tmp_path, scheduler="tcp://127.0.0.1")
    # a port out of range: dask would try it for its 30 s connect timeout
    with pytest.raises(InvalidOptions, match=r"'tcp://127.0.0.1:99999': its port 99999 is not one of 1 to"):
        study.study(runs, tmp_path, scheduler="tcp://127.0.0.1:99999")
    for workers in (0, -1, 1.5):  # from Python, where no --workers check ran before
        with pytest.raises(InvalidOptions, match=rf"workers: must be a whole number >= 1, got {workers}"):
            study.study(runs, tmp_path, workers=workers)  # type: ignore[arg-type]
    assert not (tmp_path / study.RESULTS).exists()
    monkeypatch.setitem(sys.modules, "distributed.comm", None)  # as if dask were not installed
    with pytest.raises(GaussimError, match=re.escape("pip install 'dask[distributed]'")):
        study.study(runs, tmp_path, scheduler="tcp://127.0.0.1:8786")


def test_the_example_study_prints_each_slide_beside_its_closed_form(tmp_path):
    example = Path(__file__).resolve().parents[1] / "examples" / "incline_friction_study.py"
    result = subprocess.run(
        [sys.executable, str(example), "--frictions", "0.2,0.7", "--duration", "0.1", "--workers", "1"]
        + ["--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    for line, mu in zip(lines[1:3], (0.2, 0.7)):
        values = line.split()
        assert float(values[0]) == mu and values[3] == "ok"
        assert float(values[1]) == pytest.approx(float(values[2]), rel=SLIDE_RTOL, abs=1e-4)
    assert (tmp_path / study.TABLE).is_file()
