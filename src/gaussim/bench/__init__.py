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

from .cases import CASES, QUICK_CASES
from .sweep import points, sweep, table

__all__ = ["CASES", "QUICK_CASES", "run_bench", "report"]


def run_bench(
    cases: Sequence[str] | None,
    out: Path,
    quick: bool = False,
    peers: Sequence[str] | None = None,
    workers: int | None = None,
    scheduler: Any = None,
    progress: Callable[[int, int, dict], None] | None = None,
) -> list[dict]:
    """Run the sweep of ``cases`` (default: all, or QUICK_CASES with ``quick``) into
    ``out/results.jsonl``, then write ``out/benchmarks.md`` and a Pareto plot per case; return the
    records. ``peers`` default to the installed ones."""
    from .peers import available

    chosen = list(cases or (QUICK_CASES if quick else CASES))
    unknown = sorted(set(chosen) - set(CASES))
    if unknown:
        raise ValueError(f"unknown benchmark cases {unknown}; known: {', '.join(CASES)}")
    todo = points(chosen, quick, available() if peers is None else peers)
    records = sweep(todo, out / "results.jsonl", workers, scheduler, progress)
    report(records, out, chosen)
    return records


def report(records: list[dict], out: Path, cases: Sequence[str]) -> Path:
    """``out/benchmarks.md``: per case, what its error measures, its table and its Pareto plot."""
    from ..plots import pareto_figure

    lines = [
        "# Benchmark results",
        "",
        "Made by `gaussim bench`; each table row is one run (see docs/benchmarks.md).",
        "",
    ]
    for case in cases:
        mine = [r for r in records if r["case"] == case]
        if not mine:
            continue
        figure = pareto_figure(mine, f"{case}: {CASES[case].error}")
        figure.savefig(out / f"pareto_{case}.png", dpi=90)
        lines += [
            f"## {case}",
            "",
            f"error: {CASES[case].error}",
            "",
            table(records, case),
            "",
            f"![{case}](pareto_{case}.png)",
            "",
        ]
    path = out / "benchmarks.md"
    path.write_text("\n".join(lines))
    return path
