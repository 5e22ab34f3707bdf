"""Knob sweeps over the reference cases: points, where they run, and the file they go to.

A point is one case run with the default options but one knob changed (one knob at a time: the
effect of each is read against the same default). Points run in a local process pool, or on a Dask
cluster when given its scheduler address; each finished point is appended to a JSON-lines file at
once, so an interrupted sweep keeps what it finished and a new one skips it (:mod:`gaussim.pool`).
"""

from __future__ import annotations

import math
import traceback
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from operator import attrgetter
from pathlib import Path
from typing import Any

from ..pool import Progress, run_all
from .cases import CASES, options_with

# Each knob and the values swept (the default options' value is the reference row).
KNOBS: dict[str, list[object]] = {
    "dt": [1e-4, 5e-4, 2e-3, 5e-3, 1e-2, 2e-2, 5e-2],
    "scheme": ["acceleration"],
    "friction_facets": [8, 16],
    "friction_mode": ["pyramid", "exact"],
    "eps_abs": [1e-3, 1e-5, 1e-7],
    "max_iter": [10, 100],
    "solver": ["proxqp"],
    "stabilisation": [0.05, 0.5],
}
QUICK_KNOBS: dict[str, list[object]] = {"dt": [5e-3], "scheme": ["acceleration"]}
DEFAULT = ("default", None)


@dataclass(frozen=True)
class Point:
    """One run: ``engine`` ("gaussim" or a peer's name) on ``case`` with ``knob`` set to ``value``
    (``"default"``: the default options; a peer's knob is ``"setting"``, its value a setting's label)."""

    case: str
    knob: str
    value: object
    engine: str = "gaussim"
    quick: bool = False

    @property
    def key(self) -> str:
        return f"{self.engine}|{self.case}|{self.knob}={self.value}"


def points(cases: Iterable[str], quick: bool, peers: Iterable[str] = ()) -> list[Point]:
    """The sweep: every case at the default options and with each knob changed, then the peers."""
    knobs = QUICK_KNOBS if quick else KNOBS
    result = []
    for case in cases:
        result.append(Point(case, *DEFAULT, quick=quick))
        result += [
            Point(case, knob, value, quick=quick) for knob, values in knobs.items() for value in values
        ]
    from .peers import PEERS

    for engine in peers:  # a peer's settings are its knobs (the quick sweep runs its default only)
        settings = [] if quick else list(PEERS[engine].settings)
        for case in (c for c in cases if c in PEERS[engine].cases):
            result.append(Point(case, *DEFAULT, engine=engine, quick=quick))
            result += [Point(case, "setting", label, engine=engine, quick=quick) for label in settings]
    return result


def run_point(point: Point) -> dict:
    """A point's record: the point, its metrics, and "ok" or the error that stopped it."""
    record: dict = {**asdict(point), "key": point.key}
    try:
        if point.engine == "gaussim":
            options = options_with() if point.knob == "default" else options_with(**{point.knob: point.value})
            metrics = CASES[point.case].run(options, point.quick)
        else:
            from .peers import PEERS

            peer = PEERS[point.engine]
            setting = {} if point.knob == "default" else peer.settings[str(point.value)]
            metrics = peer.run(point.case, point.quick, setting)
        record["metrics"] = {k: float(v) for k, v in metrics.items()}
        diverged = [k for k, v in record["metrics"].items() if not math.isfinite(v)]
        record["status"] = f"diverged: non-finite {', '.join(diverged)}" if diverged else "ok"
    except Exception as err:  # a failing point is a result: it is recorded and the sweep goes on
        record["metrics"] = {}
        record["status"] = f"{type(err).__name__}: {err}"
        record["traceback"] = traceback.format_exc(limit=3)
    return record


def sweep(
    todo: list[Point],
    path: Path,
    workers: int | None = None,
    scheduler: Any = None,
    progress: Progress | None = None,
) -> list[dict]:
    """Run the points not already in ``path``, appending each record as it finishes; return all the
    records of ``todo`` (see :func:`gaussim.pool.run_all` for ``workers``, ``scheduler`` and
    ``progress``)."""
    return run_all(todo, attrgetter("key"), run_point, path, workers, scheduler, progress)


METRICS = (
    "error",
    "penetration",
    "signorini",
    "cone",
    "dissipation",
    "iterations",
    "kkt_residual",
    "unconverged_steps",
    "us_per_step",
    "us_per_step_p90",
    "wall_per_sim_s",
)


# The accuracy at which engines are compared on a standing robot (the deepest penetration while
# standing [m], a foot's slip [m/s]): their cheapest setting that meets it is the matched-accuracy cost.
MATCHED = {"standing_penetration": 1e-5, "slip_per_s": 1e-4}


def table(records: list[dict], case: str) -> str:
    """A markdown table of one case's records: a row per engine and knob setting, a column per
    metric (METRICS, then the case's own)."""
    rows = [r for r in records if r["case"] == case]
    own = dict.fromkeys(k for r in rows for k in r["metrics"] if k not in METRICS)  # the case's own
    columns = [*METRICS, *own]
    header = "| engine | setting | " + " | ".join(columns) + " | status |"
    lines = [header, "|" + "---|" * 2 + "---:|" * len(columns) + "---|"]
    for r in rows:
        values = [_number(r["metrics"].get(m)) for m in columns]
        lines.append(f"| {r['engine']} | {_setting(r)} | " + " | ".join(values) + f" | {r['status']} |")
    return "\n".join(lines)


def matched_table(records: list[dict], case: str) -> str | None:
    """A markdown table of each engine's cheapest run of ``case`` (least wall time per simulated
    second) that meets MATCHED, with that time's ratio to gaussim's; an engine none of whose runs meets
    it shows its closest (the least max_k metric_k / MATCHED_k). None when the case does not measure
    MATCHED's metrics."""
    rows = [r for r in records if r["case"] == case and r["status"] == "ok"]
    if not any(set(MATCHED) <= set(r["metrics"]) for r in rows):
        return None

    def excess(r: dict) -> float:
        return max(r["metrics"].get(k, math.inf) / bound for k, bound in MATCHED.items())

    best = {}
    for engine in dict.fromkeys(r["engine"] for r in rows):
        mine = [r for r in rows if r["engine"] == engine]
        meeting = [r for r in mine if excess(r) <= 1.0]
        chosen = (
            min(meeting, key=lambda r: r["metrics"]["wall_per_sim_s"]) if meeting else min(mine, key=excess)
        )
        best[engine] = (chosen, len(meeting), len(mine))
    reference = best.get("gaussim")
    columns = (*MATCHED, "us_per_step", "wall_per_sim_s")
    lines = [
        "| engine | cheapest setting that meets it | "
        + " | ".join(columns)
        + " | time ratio to gaussim | runs meeting it |",
        "|---|---|" + "---:|" * (len(columns) + 2),
    ]
    for engine, (r, count, runs) in best.items():
        setting = _setting(r) if count else f"none (closest: {_setting(r)})"
        values = [_number(r["metrics"].get(m)) for m in columns]
        ratio = ""
        if count and reference is not None and reference[1]:
            ratio = f"{r['metrics']['wall_per_sim_s'] / reference[0]['metrics']['wall_per_sim_s']:.2f}"
        lines.append(f"| {engine} | {setting} | " + " | ".join(values) + f" | {ratio} | {count} of {runs} |")
    return "\n".join(lines)


def _setting(record: dict) -> str:
    """ "default", a gaussim knob's "knob = value", or a peer setting's own label."""
    knob = record["knob"]
    if knob == "default":
        return "default"
    if knob == "setting":
        return str(record["value"])
    return f"{knob} = {record['value']}"


def _number(value: float | None) -> str:
    if value is None:
        return ""
    if value == 0 or not math.isfinite(value):
        return f"{value:g}"
    return f"{value:.3g}"
