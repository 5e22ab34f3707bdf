"""The speed-accuracy benchmark: reference cases with analytic references, ContactBench contact
metrics, knob sweeps (one knob at a time around the defaults), peers in the same run, markdown
tables and Pareto plots (error against wall time per simulated second).

Run it with ``gaussim bench [CASES...] [--quick] [--out DIR] [--workers N] [--scheduler ADDRESS]``
(see ``docs/benchmarks.md``); :func:`run_bench` is the same from Python.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ..files import atomic_path
from .cases import CASES, QUICK_CASES
from .sweep import MATCHED, matched_table, points, sweep, table

__all__ = ["CASES", "QUICK_CASES", "run_bench", "report"]


def run_bench(
    cases: Sequence[str] | None,
    out: Path,
    quick: bool = False,
    peers: Sequence[str] | None = None,
    workers: int | None = None,
    scheduler: Any = None,
    progress: Callable[[int, int, dict], None] | None = None,
    report_path: Path | None = None,
) -> list[dict]:
    """Run the sweep of ``cases`` (default: all, or QUICK_CASES with ``quick``) into
    ``out/results.jsonl``, then write the report (default ``out/benchmarks.md``) and a Pareto plot per
    case in ``out``; return the records. ``peers`` default to the installed ones."""
    from .peers import available

    chosen = list(cases or (QUICK_CASES if quick else CASES))
    unknown = sorted(set(chosen) - set(CASES))
    if unknown:
        raise ValueError(f"unknown benchmark cases {unknown}; known: {', '.join(CASES)}")
    todo = points(chosen, quick, available() if peers is None else peers)
    records = sweep(todo, out / "results.jsonl", workers, scheduler, progress)
    report(records, out, chosen, report_path or out / "benchmarks.md")
    return records


HEADER = """# Benchmark results

Made by `{command}`. Each case runs gaussim at the default options and with one knob changed at a
time (dt, scheme, friction facets and mode, ProxQP tolerance and iteration cap, stabilisation), and
the peers installed on the same scene (Solo-12 standing: MuJoCo Newton and PGS with pyramidal and
elliptic cones, Pinocchio 4's ADMM and PGS constraint solvers driven from Python, and PyBullet), each
at its defaults and at the settings a user turns to for accuracy (smaller steps, MuJoCo's stiff
contacts and no-slip pass, tighter tolerances; see `gaussim.bench.peers`).

Columns: `error` is the case's own error against its reference (named above each table);
`penetration` [m], `signorini` [W], `cone` [N] and `dissipation` [W] are the largest ContactBench
residuals of the run (see `gaussim.bench.metrics`); `iterations` are ProxQP's per step,
`kkt_residual` the largest KKT residual of a QP, `unconverged_steps` the steps whose solver did not
converge; `us_per_step` (median) and its p90 time the step alone, `wall_per_sim_s` is the wall time
per simulated second. Then each case's own measurements: where it has no analytic trajectory (the
pendulum, the four-bar), `trajectory_error` is |q - q_ref| at 1 s against gaussim at dt / 16 with
eps_abs 1e-12 (self-consistency) and `energy_gain` the largest rise of the mechanical energy relative
to the largest kinetic energy; a sliding block's `heading_drift` [rad] and `lift` [m]; a standing
robot's `standing_penetration` [m] and `slip_per_s` [m/s], with a matched-accuracy table: each
engine's cheapest setting that meets a given penetration and slip.

Runs share the machine's cores (`--workers`): compare times within a table, and use
`benchmarks/step_cost.py` for the step cost itself. The plots put error against wall time per
simulated second, one curve per knob (through the default point) and one per peer (its settings).
"""

MATCHED_HEADER = (
    "Matched accuracy: each engine's cheapest setting (wall time per simulated second) at which the "
    "robot stands with penetration <= {standing_penetration:g} m and foot slip <= {slip_per_s:g} m/s."
).format(**MATCHED)


def report(
    records: list[dict], out: Path, cases: Sequence[str], path: Path, command: str = "gaussim bench"
) -> Path:
    """The markdown report at ``path``: per case, what its error measures, its table and its Pareto
    plot (written to ``out`` and linked relative to the report)."""
    import os

    from ..plots import close_figure, pareto_figure

    out.mkdir(parents=True, exist_ok=True)
    lines = [HEADER.format(command=command)]
    for case in cases:
        mine = [r for r in records if r["case"] == case]
        if not mine:
            continue
        image = out / f"pareto_{case}.png"
        figure = pareto_figure(mine, f"{case}: {CASES[case].error}")
        try:
            with atomic_path(image) as tmp:
                figure.savefig(tmp, dpi=90)
        finally:
            close_figure(figure)  # 24 cases: pyplot keeps every figure it made until closed
        link = os.path.relpath(image, path.parent)
        lines += [
            f"## {case}",
            "",
            f"error: {CASES[case].error}",
            "",
            table(records, case),
            "",
        ]
        matched = matched_table(records, case)
        if matched is not None:
            lines += [MATCHED_HEADER, "", matched, ""]
        lines += [f"![{case}]({link})", ""]
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines))
    return path
