"""The library's conventions: the force export's columns and units, the run log's time, gravity and
masses, old logs still read, plots without contacts, the CLI's --help / --version / help texts, and the
compile notice."""

from __future__ import annotations

import csv
import io
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import gaussim
from gaussim.runlog import RunLog, write_forces
from gaussim.runner import COMPILING, _Progress, compile_notice

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "robots" / "scenes"
DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def solo_dir(tmp_path_factory) -> Path:
    """The log directory of 50 steps of the main job."""
    spec = gaussim.load_scene(SCENES / "solo12_standing.toml")
    spec.duration = 0.05
    path = tmp_path_factory.mktemp("solo") / "solo.runlog"
    gaussim.run(spec, path)
    return path


@pytest.fixture(scope="module")
def solo_log(solo_dir) -> RunLog:
    return RunLog.load(solo_dir)


def test_the_force_export_has_step_t_pair_point_normal_fn_ft_force_and_gap_with_units(solo_log, tmp_path):
    rows = write_forces(solo_log, tmp_path / "f.csv")
    table = list(csv.DictReader((tmp_path / "f.csv").open()))
    assert rows == len(table) > 0
    assert list(table[0]) == [
        "step", "t_s", "contact", "geometry", "obstacle", "body", "other",
        "point_x_m", "point_y_m", "point_z_m", "normal_x", "normal_y", "normal_z",
        "fn_N", "ft_N", "force_x_N", "force_y_N", "force_z_N", "gap_m",
    ]  # fmt: skip
    c = solo_log.contact_arrays()
    for row, k in zip(table, range(len(c["step"]))):  # fn, ft from the stored vectors, by hand
        force, normal = c["force"][k], c["normal"][k]
        fn = float(force @ normal)
        assert float(row["fn_N"]) == pytest.approx(fn, rel=1e-12, abs=1e-12)
        assert float(row["ft_N"]) == pytest.approx(np.linalg.norm(force - fn * normal), rel=1e-9, abs=1e-12)
        assert int(row["step"]) == c["step"][k] and float(row["t_s"]) == solo_log.t[c["step"][k] + 1]
        assert float(row["gap_m"]) == c["gap"][k] and row["body"] == "solo12" and row["other"] == "ground"


def test_the_cli_export_is_the_same_file(solo_dir, tmp_path):
    from gaussim.cli import main

    assert main(["forces", str(solo_dir), "--csv", str(tmp_path / "cli.csv")]) == 0
    write_forces(RunLog.load(solo_dir), tmp_path / "api.csv")
    assert (tmp_path / "cli.csv").read_text() == (tmp_path / "api.csv").read_text()


def test_the_log_stores_t_as_step_times_dt_gravity_and_masses(solo_log):
    dt = solo_log.options.dt
    assert np.array_equal(solo_log.t, np.arange(solo_log.steps + 1) * dt), "no summed round-off"
    assert solo_log.gravity == [0.0, 0.0, -9.81]
    assert solo_log.masses is not None and solo_log.masses["solo12"] == pytest.approx(
        gaussim.load_robot("solo12").mass, rel=1e-12
    )


def test_gravity_and_masses_survive_the_single_file_form(solo_log, tmp_path):
    again = RunLog.load(solo_log.save(tmp_path / "solo.npz"))
    assert again.gravity == solo_log.gravity and again.masses == solo_log.masses
    assert np.array_equal(again.t, solo_log.t)


@pytest.mark.parametrize("name", ["box_stack_format1.npz", "box_stack_directory2.runlog"])
def test_old_logs_still_read_without_gravity_or_masses(name, tmp_path):
    log = RunLog.load(DATA / name)
    assert log.steps > 0 and log.gravity is None and log.masses is None
    assert write_forces(log, tmp_path / "old.csv") == len(log.contact_arrays()["step"]) > 0


def test_a_header_with_a_bad_gravity_is_refused(solo_dir, tmp_path):
    import json
    import shutil

    copy = tmp_path / "copy.runlog"
    shutil.copytree(solo_dir, copy)
    header = json.loads((copy / "header.json").read_text())
    header["gravity"] = [0, "down"]
    (copy / "header.json").write_text(json.dumps(header))
    with pytest.raises(gaussim.GaussimError, match="'gravity' must be a list of 3 numbers"):
        RunLog.load(copy)


def test_a_run_without_contacts_plots_a_message(tmp_path):
    from gaussim.plots import force_figure

    spec = gaussim.load_scene(SCENES / "double_pendulum.toml")
    spec.duration = 0.01
    log = gaussim.run(spec)
    assert not log.contact_names
    figure = force_figure(log, spec.scene)
    texts = [t.get_text() for ax in figure.axes for t in ax.texts]
    assert texts.count("no contacts in this run") == 3


def test_help_and_version_answer_without_numba_or_pinocchio():
    code = (
        "import sys\nfrom gaussim.cli import main\n"
        "try:\n    main(['--version'])\nexcept SystemExit:\n    pass\n"
        "print(sorted(m for m in ('numba', 'pinocchio', 'numpy') if m in sys.modules))"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.splitlines() == ["gaussim 0.1.0", "[]"]
    assert gaussim.__version__ == "0.1.0"


def test_every_cli_argument_has_help(monkeypatch):
    import argparse

    from gaussim import cli

    built: list[argparse.ArgumentParser] = []

    def stop(self, *args, **kwargs):  # the parser is built: keep it, run nothing
        built.append(self)
        raise SystemExit(0)

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", stop)
    with pytest.raises(SystemExit):
        cli.main([])
    (top,) = built
    (commands,) = (a for a in top._actions if isinstance(a, argparse._SubParsersAction))
    parsers = [top, *commands.choices.values()]
    missing = [
        f"{p.prog} {a.dest}"
        for p in parsers
        for a in p._actions
        if not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)) and not a.help
    ]
    assert len(parsers) > 5 and missing == []


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_the_progress_line_says_when_kernels_compile():
    from numba import njit

    @njit
    def fresh(x):  # a kernel this process has not compiled (no cache)
        return x + 1

    stream = io.StringIO()  # a file: the notice once, then a line per PROGRESS_SECONDS and the last
    line = _Progress(stream, 2)
    with compile_notice(line.compiling):
        fresh(1)
        line.update(1, 0.001, 0)
        fresh(2.0)
        line.update(2, 0.002, 3)
    line.close()
    lines = stream.getvalue().splitlines()
    assert lines[0] == f"gaussim: {COMPILING}" and len(lines) == 2
    assert "2/2" in lines[1] and "steps/s" in lines[1] and "contacts: 3" in lines[1]


def test_the_terminal_bar_shows_the_notice_while_compiling_and_leaves_its_time_out_of_the_rate():
    stream = _Tty()
    line = _Progress(stream, 10)
    line.compiling(True)
    assert COMPILING in stream.getvalue()
    time.sleep(0.3)
    line.compiling(False)
    assert line.bar.desc == ""
    assert time.perf_counter() - line.start < 0.1, "the compile's 0.3 s is not stepping time"
    line.close()


def test_an_impact_reports_its_contact_impulses_by_that_name(ball):
    """A ball at 1 m/s onto ground with e = 0.8 (acceleration scheme): the impact's contact impulses
    [N s] are the ball's momentum change m (w - v) (w the velocity after the impact), and the impact
    report's ContactForce.force holds the same numbers."""
    from .conftest import G, at_height

    dt = 1e-3
    scene = gaussim.Scene(ball, ground=gaussim.Ground(friction=0.8, restitution=0.8))
    sim = gaussim.Simulator(scene, gaussim.Options(scheme="acceleration", dt=dt))
    state = sim.reset(at_height(ball, 0.1 + 5e-4), np.array([0, 0, -1.0, 0, 0, 0]))
    for _ in range(5):
        before = state.v[2]
        state = sim.step(state)
        if sim.last_step.impact is not None:
            break
    report = sim.last_step
    assert report.impact is not None and sim.last_step.impulses
    w = state.v[2] + G * dt  # the velocity the impact left, before the step's gravity
    total = sum(i.impulse for i in report.impulses)
    assert total[2] == pytest.approx(ball.mass * (w - before), rel=1e-6)
    assert all(i.normal_impulse > 0 for i in report.impulses)
    assert [i.impulse.tolist() for i in report.impulses] == [c.force.tolist() for c in report.impact.contacts]


def test_a_step_without_impact_has_no_impulses(ball):
    from .conftest import at_height

    sim = gaussim.Simulator(gaussim.Scene(ball, ground=gaussim.Ground()))
    sim.step(sim.reset(at_height(ball, 0.1)))
    assert sim.last_step.impulses == []


def test_the_package_imports_its_names_and_submodules_on_first_use():
    assert gaussim.options.SCHEMES and gaussim.Simulator.__name__ == "Simulator"
    assert set(gaussim.__all__) <= set(dir(gaussim))
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        gaussim.nope  # noqa: B018
