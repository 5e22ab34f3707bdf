"""The benchmark: its quick sweep's tables and metrics, incremental results, Dask, and the CLI."""

from __future__ import annotations

import json
import math
import re
import time

import pytest

from gaussim.bench import CASES, QUICK_CASES, run_bench
from gaussim.bench.sweep import METRICS, QUICK_KNOBS, Point, points, sweep
from gaussim.cli import main


def test_quick_bench_writes_tables_plots_and_finite_metrics(tmp_path):
    """``--quick``: every quick case at the default options and each quick knob, gaussim only; every
    run succeeds with finite metrics; each case gets a table with a row per run and a Pareto plot."""
    records = run_bench(None, tmp_path, quick=True, peers=[], workers=2)
    expected = len(QUICK_CASES) * (1 + sum(len(v) for v in QUICK_KNOBS.values()))
    assert len(records) == expected
    for r in records:
        assert r["status"] == "ok", r
        assert set(METRICS) <= set(r["metrics"]), r["key"]
        assert all(math.isfinite(v) for v in r["metrics"].values()), r
    text = (tmp_path / "benchmarks.md").read_text()
    for case in QUICK_CASES:
        section = text.split(f"## {case}\n")[1].split("\n## ")[0]
        runs, matched = section.split("Matched accuracy") if "Matched" in section else (section, "")
        rows = [line for line in runs.splitlines() if line.startswith("| gaussim |")]
        assert (case == "solo12") == ("| gaussim | dt = 0.005 |" in matched)
        assert len(rows) == expected // len(QUICK_CASES)
        header = next(line for line in runs.splitlines() if line.startswith("| engine |"))
        assert all(name in header for name in METRICS)
        assert all(line.count("|") == header.count("|") for line in rows)
        assert (tmp_path / f"pareto_{case}.png").stat().st_size > 1000
    lines = (tmp_path / "results.jsonl").read_text().splitlines()
    assert len(lines) == expected and all(json.loads(line)["key"] for line in lines)


def test_the_analytic_references_hold_at_the_defaults():
    """The defaults reach the accuracy the tests of the engine demand (so a table's error column
    measures the knobs, not a broken case)."""
    from gaussim.bench.cases import options_with

    assert CASES["sliding_30"].run(options_with(), True)["error"] < 0.01
    assert CASES["incline_stick"].run(options_with(), True)["error"] < 1e-6
    assert CASES["ball_bounce"].run(options_with(), True)["error"] < 4.5e-3  # |v_impact| dt


def test_an_interrupted_sweep_keeps_its_points_and_resumes(tmp_path):
    path = tmp_path / "results.jsonl"
    todo = [Point("ball_bounce", "default", None, quick=True), Point("ball_bounce", "dt", 5e-3, quick=True)]
    sweep(todo[:1], path, workers=1)
    path.write_text(path.read_text() + '{"key": "torn')  # a write cut short by the interruption
    ran = []
    records = sweep(todo, path, workers=1, progress=lambda done, total, record: ran.append(record["key"]))
    assert ran == [todo[1].key], "only the missing point runs again"
    assert [r["key"] for r in records] == [p.key for p in todo]


def test_a_failing_point_is_recorded_and_the_sweep_goes_on(tmp_path):
    todo = [Point("ball_bounce", "dt", -1.0, quick=True), Point("ball_bounce", "default", None, quick=True)]
    first, second = sweep(todo, tmp_path / "results.jsonl", workers=1)
    assert first["status"].startswith("InvalidOptions: dt") and first["metrics"] == {}
    assert second["status"] == "ok"


def test_points_run_on_a_dask_cluster(tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    todo = [
        Point("ball_bounce", "default", None, quick=True),
        Point("pendulum_limits", "default", None, quick=True),
    ]
    with distributed.LocalCluster(n_workers=1, processes=False, threads_per_worker=1) as cluster:
        with distributed.Client(cluster) as client:
            records = sweep(todo, tmp_path / "results.jsonl", scheduler=client)
    assert [r["status"] for r in records] == ["ok", "ok"]


def test_points_cover_every_knob_once_around_the_default():
    todo = points(["ball_rest"], quick=False)
    assert todo[0].knob == "default"
    assert len({p.key for p in todo}) == len(todo)


def test_cli_lists_cases_and_rejects_unknown_ones(capsys):
    assert main(["bench", "--list"]) == 0
    assert "sliding_30" in capsys.readouterr().out
    assert main(["bench", "no_such_case"]) == 2
    assert "no_such_case" in capsys.readouterr().err


def _record(engine: str, knob: str, value: object, penetration: float, slip: float, wall: float) -> dict:
    metrics = {"standing_penetration": penetration, "slip_per_s": slip, "us_per_step": 1.0}
    metrics["wall_per_sim_s"] = wall
    return {
        "case": "solo12",
        "engine": engine,
        "knob": knob,
        "value": value,
        "status": "ok",
        "metrics": metrics,
    }


def test_matched_table_takes_each_engines_cheapest_run_that_meets_the_accuracy():
    from gaussim.bench.sweep import MATCHED, matched_table

    pen, slip = MATCHED["standing_penetration"], MATCHED["slip_per_s"]
    records = [
        _record("gaussim", "default", None, pen / 10, slip / 10, 0.2),
        _record("gaussim", "dt", 0.02, pen / 2, slip / 2, 0.01),
        _record("gaussim", "dt", 0.05, pen * 3, slip / 2, 0.004),  # cheaper, but too deep
        _record("peer", "default", None, pen * 80, slip * 100, 0.02),
        _record("peer", "setting", "stiff", pen / 2, slip / 3, 0.05),
        _record("other", "default", None, pen * 1.1, slip / 2, 0.1),
        _record("other", "setting", "small dt", pen * 1.02, slip / 2, 0.5),
    ]
    lines = matched_table(records, "solo12").splitlines()
    rows = {line.split(" | ")[0].strip("| "): line.split(" | ") for line in lines[2:]}
    assert rows["gaussim"][1] == "dt = 0.02" and rows["gaussim"][-2] == "1.00"
    assert rows["peer"][1] == "stiff" and rows["peer"][-2] == "5.00"  # 0.05 / 0.01
    assert rows["peer"][-1] == "1 of 2 |"
    assert rows["other"][1] == "none (closest: small dt)" and rows["other"][-2] == ""
    assert matched_table([{**records[0], "metrics": {"error": 0.0}}], "solo12") is None


def test_the_self_consistency_reference_converges_at_first_order():
    """The pendulum against its limit, compared with gaussim at dt / 16 and eps_abs 1e-12: the
    semi-implicit scheme is first order, so a 10x smaller step cuts the trajectory error about 10x
    (measured: 8x; the step in which the limit is hit adds its own first-order error)."""
    from gaussim.bench.cases import options_with

    case = CASES["pendulum_limits"]
    error = {dt: case.run(options_with(dt=dt), True)["trajectory_error"] for dt in (1e-2, 1e-3)}
    assert 4 < error[1e-2] / error[1e-3] < 25, error
    assert error[1e-3] < 2e-3


@pytest.mark.parametrize(
    "name", ["mujoco-newton-pyramidal", "mujoco-pgs-elliptic", "pybullet", "pinocchio-admm", "pinocchio-pgs"]
)
def test_a_peer_stands_solo12_and_reports_the_cases_metrics(name):
    from gaussim.bench.peers import PEERS

    metrics = PEERS[name].run("solo12", True, {})
    assert {"error", "penetration", "standing_penetration", "slip_per_s"} <= set(metrics)
    gaussims_own = {"signorini", "cone", "dissipation", "iterations", "kkt_residual", "unconverged_steps"}
    assert set(METRICS) - gaussims_own <= set(metrics)
    assert all(math.isfinite(v) for v in metrics.values()), metrics
    assert metrics["error"] < 1e-2, "the feet carry the robot's weight"
    assert 0 <= metrics["standing_penetration"] <= metrics["penetration"] < 0.01  # the drop's height
    assert metrics["slip_per_s"] < 0.05


def test_mujoco_stiff_contacts_cut_its_resting_penetration():
    """MuJoCo's soft contacts rest 0.8 mm deep at its defaults; the 'stiff' setting (solref 2 dt,
    solimp 0.99-0.999) is what the matched-accuracy table needs of it."""
    from gaussim.bench.peers import PEERS

    peer = PEERS["mujoco-newton-pyramidal"]
    soft, stiff = (peer.run("solo12", True, s)["standing_penetration"] for s in ({}, {"stiff": 1}))
    assert soft > 5e-4 and stiff < soft / 100


def test_a_run_with_non_finite_metrics_is_recorded_as_diverged(monkeypatch):
    """A peer that blows up (the explicit PD hold at too large a step) must not enter the tables as ok."""
    from gaussim.bench import peers
    from gaussim.bench.sweep import run_point

    def blown(case: str, quick: bool, setting: dict) -> dict[str, float]:
        return {"error": 1.0, "slip_per_s": math.nan, "penetration": 6e8}

    monkeypatch.setitem(peers.PEERS, "blown", peers.Peer(("solo12",), blown, {"dt=1": {"dt": 1.0}}))
    record = run_point(Point("solo12", "setting", "dt=1", engine="blown"))
    assert record["status"] == "diverged: non-finite slip_per_s"
    assert record["metrics"]["penetration"] == 6e8


NEW_CASES = (
    "rolling_flat",
    "rolling_incline",
    "spinning_free",
    "intermediate_axis",
    "intermediate_axis_fast",
    "newtons_cradle",
    "tipping",
    "double_pendulum",
)


@pytest.mark.parametrize("name", NEW_CASES)
def test_a_reference_case_runs_at_quick_settings_with_finite_metrics(name):
    from gaussim.bench.cases import options_with

    metrics = CASES[name].run(options_with(), True)
    assert set(METRICS) <= set(metrics)
    assert all(math.isfinite(v) for v in metrics.values()), metrics


REFERENCE_TOLERANCE = 1e-10


def test_the_free_rotation_reference_keeps_energy_and_world_momentum_and_turns_about_a_principal_axis():
    """DOP853 of Euler's equations and the quaternion kinematics: through the intermediate-axis flip
    the energy and the world angular momentum stay; spun about a principal axis, the body turns at
    constant rate about it (closed form)."""
    import numpy as np
    import pinocchio as pin

    from gaussim.bench.cases import PRINCIPAL_INERTIA, free_rotation

    I = np.array(PRINCIPAL_INERTIA)
    times = np.linspace(0.0, 5.0, 51)
    quaternions, omegas = free_rotation(I, np.array([0.01, 5.0, 0.01]), times)
    assert omegas[-1, 1] < 0, "it flips within 5 s"
    energy = np.einsum("ij,j,ij->i", omegas, I, omegas) / 2
    momentum = np.array([pin.Quaternion(x).matrix() @ (I * w) for x, w in zip(quaternions, omegas)])
    assert np.abs(energy / energy[0] - 1).max() < REFERENCE_TOLERANCE
    assert np.linalg.norm(momentum - momentum[0], axis=1).max() / np.linalg.norm(momentum[0]) < 1e-9
    quaternions, _ = free_rotation(I, np.array([0.0, 2.0, 0.0]), times)
    expected = [pin.Quaternion(pin.rpy.rpyToMatrix(0, 2 * t, 0)).coeffs() for t in times]
    signs = np.sign(np.sum(quaternions * expected, axis=1))[:, None]  # q and -q are the same attitude
    assert np.abs(quaternions - signs * expected).max() < 1e-9


def _lagrangian_double_pendulum(y):
    """d/dt (angles, velocities) of two uniform 1 kg, 0.5 m rods hinged about y (q = 0 hangs down), by
    hand: absolute angles p = (q1, q1 + q2), M(p) p'' + c(p, p') + dV/dp = 0."""
    import numpy as np

    m, l, g = 1.0, 0.5, 9.81
    Ic = 0.0208333  # the URDF's: m l^2 / 12 to its digits
    q, v = y[:2], y[2:]
    p, w = np.array([q[0], q[0] + q[1]]), np.array([v[0], v[0] + v[1]])
    c = m * l**2 / 2 * np.cos(p[0] - p[1])
    s = m * l**2 / 2 * np.sin(p[0] - p[1])
    M = np.array([[m * l**2 * 5 / 4 + Ic, c], [c, m * l**2 / 4 + Ic]])
    rest = np.array(
        [s * w[1] ** 2 + 1.5 * m * g * l * np.sin(p[0]), -s * w[0] ** 2 + m * g * l / 2 * np.sin(p[1])]
    )
    pdd = np.linalg.solve(M, -rest)
    return np.concatenate([v, [pdd[0], pdd[1] - pdd[0]]])


def test_the_double_pendulum_reference_is_its_lagrangian_and_keeps_its_energy():
    """The RHS integrated for double_pendulum (Pinocchio's aba) equals the hand-written Lagrangian of
    two rods at random states, and DOP853 keeps the energy over 2 s."""
    import numpy as np
    import pinocchio as pin

    from gaussim.bench.cases import PENDULUM_START, angles_to_q, pendulum_reference, pendulum_rhs
    from gaussim.robot import load_robot

    model = load_robot("double_pendulum").model
    rhs = pendulum_rhs(model)
    for y in np.random.default_rng(0).uniform(-3, 3, (20, 4)):
        assert np.allclose(rhs(0.0, y), _lagrangian_double_pendulum(y), rtol=1e-6, atol=1e-6), y
    states = pendulum_reference(model, np.array(PENDULUM_START), np.linspace(0.0, 2.0, 41))
    data = model.createData()
    energy = [pin.computeMechanicalEnergy(model, data, angles_to_q(y[:2]), y[2:]) for y in states]
    kinetic = max(pin.computeKineticEnergy(model, data, angles_to_q(y[:2]), y[2:]) for y in states)
    assert np.ptp(energy) / kinetic < REFERENCE_TOLERANCE


def test_the_tipping_angle_puts_the_centre_of_mass_over_the_lower_edge():
    """Placed on the incline as the case places it, the tall box's centre of mass is uphill of its
    lower collision corners just below tipping_angle and downhill of them just above."""
    import tempfile
    from pathlib import Path

    import numpy as np
    import pinocchio as pin

    from gaussim.bench.cases import TALL_BOX, free_bodies, on_incline, tipping_angle

    width, height = TALL_BOX
    with tempfile.TemporaryDirectory() as folder:
        box = free_bodies(
            Path(folder) / "b.urdf", "b", [("b", 1.0, (1, 1, 1), f'<box size="{width} {width} {height}"/>')]
        )
    corners = np.array(
        [[x, y, -height / 2] for x in (-width / 2, width / 2) for y in (-width / 2, width / 2)]
    )
    for factor, tips in ((0.99, False), (1.01, True)):
        _, q = on_incline(factor * tipping_angle(width, height), height / 2)
        placement = pin.XYZQUATToSE3(q)
        lowest = min(placement.act(c)[0] for c in corners)  # the incline falls toward -x
        com = pin.centerOfMass(box.model, box.model.createData(), q)
        assert (com[0] < lowest) == tips, factor


def test_the_rolling_references_hold_for_a_ball_constrained_at_its_contact_point():
    """Pinocchio's constraintDynamics of the ball with its contact point held (rolling without slip):
    on the 30 degree incline its centre accelerates at twice rolling_travel's coefficient, with the
    friction ratio 2/7 tan(theta) below the case's mu 0.5; rolling_velocity leaves that point at rest."""
    import numpy as np
    import pinocchio as pin

    from gaussim.bench.cases import INCLINE_DEG, on_incline, rolling_travel, rolling_velocity
    from gaussim.robot import load_robot

    model = load_robot("ball", floating_base=True).model
    data, radius, theta = model.createData(), 0.1, np.radians(INCLINE_DEG)
    normal, q = on_incline(theta, radius)
    R = pin.XYZQUATToSE3(q).rotation
    point = pin.SE3(np.eye(3), R.T @ (-radius * normal))
    constraint = pin.RigidConstraintModel(
        pin.ContactType.CONTACT_3D, model, 1, point, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    )
    models, datas = pin.StdVec_RigidConstraintModel(), pin.StdVec_RigidConstraintData()
    models.append(constraint)
    datas.append(constraint.createData())
    pin.initConstraintDynamics(model, data, models, datas)
    a = pin.constraintDynamics(model, data, q, np.zeros(6), np.zeros(6), models, datas)
    assert np.isclose(np.linalg.norm(R @ a[:3]), 2 * rolling_travel(theta, 1.0), rtol=1e-9)
    f = datas[0].contact_force.linear
    assert np.linalg.norm(f - (f @ normal) * normal) / (f @ normal) < 0.5
    downhill = np.array([-np.cos(theta), 0.0, -np.sin(theta)])
    v = rolling_velocity(3.0, radius, R.T @ downhill, R.T @ normal)  # in the body frame, as q's
    pin.forwardKinematics(model, data, q, v)
    body = data.v[1]
    contact = R @ (body.linear + np.cross(body.angular, point.translation))
    assert np.linalg.norm(contact) < 1e-12 and np.isclose(np.linalg.norm(v[:3]), 3.0)


def test_the_cradle_reference_is_the_impulsive_gauss_projection():
    """CRADLE_REFERENCE solves min 1/2 |w - v-|^2_M over J w >= -e J v- for the two closed contacts
    (solved here by scipy's SLSQP), keeping momentum and energy."""
    import numpy as np
    from scipy.optimize import minimize

    from gaussim.bench.cases import CRADLE_REFERENCE

    v = np.array([1.0, 0.0, 0.0])
    J = np.array([[-1.0, 1.0, 0.0], [0.0, -1.0, 1.0]])  # the gaps' rates
    rows = {"type": "ineq", "fun": lambda w: J @ w + J @ v}  # e = 1
    w = minimize(lambda w: (w - v) @ (w - v) / 2, v, constraints=[rows], method="SLSQP", tol=1e-14).x
    assert np.allclose(w, CRADLE_REFERENCE, atol=1e-7)
    assert np.isclose(sum(CRADLE_REFERENCE), 1.0) and np.isclose(np.square(CRADLE_REFERENCE).sum(), 1.0)


def test_a_recorder_absorbs_another_runs_steps():
    """A case of several runs (tipping's bisection) reports all their steps: the counts add up, the
    residuals are the larger of the two."""
    from gaussim.bench.metrics import Recorder
    from gaussim.options import Options
    from gaussim.robot import load_robot
    from gaussim.scene import Ground, Scene
    from gaussim.simulator import Simulator

    ball = load_robot("ball", floating_base=True)
    recorders = []
    for height in (0.1, 0.095):  # resting, and started 5 mm deep
        sim = Simulator(Scene(ball, ground=Ground()), Options(start_penetration=1e-2))
        q = ball.neutral()
        q[2] = height
        rec = Recorder(sim)
        rec.run(sim.reset(q), 0.01 * len(recorders) + 0.01)
        recorders.append(rec)
    first, second = recorders
    steps, iterations, deepest = (
        len(first.seconds) + len(second.seconds),
        first.iterations + second.iterations,
        second.penetration,
    )
    assert deepest > first.penetration
    first.absorb(second)
    summary = first.summary()
    assert len(first.seconds) == steps == 30
    assert summary["iterations"] == iterations / steps and summary["penetration"] == deepest


def test_the_scene_suite_runs_the_same_scene_in_every_engine(capsys, tmp_path):
    """``gaussim bench --scenes --quick``: a row per scene whose cells match the header; MuJoCo's model,
    generated from the gaussim scene, holds the same bodies and contact pairs and touches at as many
    points (a box face on the ground: 4 each); each engine is timed in turns and alone; gaussim's
    penetration and KKT residual are reported."""
    from gaussim.bench.scenes import QUICK_STEPS, run_suite

    records = run_suite(["box", "pile_4", "panda_cube"], quick=True, peers=["mujoco"])
    for r in records:
        gaussim, mujoco = r["engines"]["gaussim"], r["engines"]["mujoco"]
        assert r["steps"] == QUICK_STEPS and mujoco["status"] == "ok", r
        assert gaussim["bodies"] == mujoco["bodies"] == r["bodies"], r
        assert r["mujoco_pairs"] == r["pairs"], r
        assert round(gaussim["contacts"]) == round(mujoco["contacts"]) > 0, r
        assert 0 <= gaussim["penetration"] < 1e-4 and gaussim["kkt_residual"] < 1e-6, r
        # each engine is timed in turns and alone
        assert all(e[f"us{how}_median"] > 0 for e in (gaussim, mujoco) for how in ("", "_alone")), r
    report = tmp_path / "benchmarks.md"
    assert main(["bench", "--scenes", "--quick", "--no-peers", "stack_3", "--report", str(report)]) == 0
    table = [line for line in capsys.readouterr().out.splitlines() if line.startswith("|")]
    assert len(table) == 3 and table[2].startswith("| stack_3 | 3 | 18 | 6 |")
    assert len({line.count("|") for line in table}) == 1
    # the report says how it was made: the command, the run's length and the day
    made = (
        f"Made by `gaussim bench --scenes --quick stack_3 --report {report}` ({QUICK_STEPS} steps per scene; "
    )
    assert made + time.strftime("%Y-%m-%d") in report.read_text()
    assert re.search(
        r"a fixed Python loop \(3,000,000 additions\) took \d\.\d\d s before the run, \d\.\d\d s after",
        report.read_text(),
    )


def test_a_regenerated_section_keeps_its_notes_and_its_neighbours(tmp_path):
    """``write_section`` replaces a section's generated text and keeps the hand-written ``### ``
    subsections under it and the sections around it; a new title is appended."""
    from gaussim.bench.scenes import write_section

    path = tmp_path / "benchmarks.md"
    path.write_text("# Doc\n\n## A\n\nold table\n\n### Notes\n\nwhy A is slow\n\n## B\n\nb text\n")
    write_section(path, "A", "new table")
    assert path.read_text() == (
        "# Doc\n\n## A\n\nnew table\n\n### Notes\n\nwhy A is slow\n\n## B\n\nb text\n"
    )
    write_section(path, "B", "b again")
    write_section(path, "C", "c text")
    assert path.read_text().endswith("why A is slow\n\n## B\n\nb again\n\n## C\n\nc text\n")


def test_matched_accuracy_on_motion_picks_the_cheapest_setting_that_meets_each_tolerance():
    """The rolling ball against its closed form: gaussim's error falls with dt (first order) and the
    table names, per tolerance, the cheapest run that meets it."""
    from gaussim.bench.motion import TASKS, TOLERANCES, cheapest, markdown, run_task

    record = run_task(TASKS["rolling_ball"], True, ["gaussim"], None)
    runs = record["engines"]["gaussim"]["runs"]
    errors = [runs[label]["error"] for label in ("dt=0.005", "dt=0.002", "dt=0.001")]
    assert errors[0] > errors[1] > errors[2] and errors[2] < 1e-3
    assert errors[0] / errors[2] == pytest.approx(5, rel=0.2)
    for tolerance in TOLERANCES:
        label, run = cheapest(runs, tolerance)  # type: ignore[misc]
        assert run["error"] <= tolerance
        assert f"| rolling_ball | {tolerance:g} | gaussim | closed form | {label} |" in markdown([record])
