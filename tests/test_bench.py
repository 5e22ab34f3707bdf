"""The benchmark: its quick sweep's tables and metrics, incremental results, Dask, and the CLI."""

from __future__ import annotations

import json
import math

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
        rows = [line for line in section.splitlines() if line.startswith("| gaussim |")]
        assert len(rows) == expected // len(QUICK_CASES)
        assert all(line.count("|") == len(METRICS) + 4 for line in rows)
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
