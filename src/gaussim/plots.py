"""Plots of a run log (matplotlib, headless Agg unless a backend was chosen): contact forces,
friction use, gaps, the solver's work, and energy."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .exceptions import InvalidOptions
from .files import atomic_path
from .runlog import RunLog, split_forces
from .scene import Scene

WHATS = ("forces", "energy")
FORMATS = (".png", ".pdf", ".svg")


def _pyplot() -> Any:
    """pyplot, on the headless Agg backend unless in an interactive session (Python prompt, Jupyter)."""
    import sys

    import matplotlib

    if not (hasattr(sys, "ps1") or "ipykernel" in sys.modules):
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def force_figure(log: RunLog, scene: Scene, bodies: Sequence[str] | None = None) -> Any:
    """Four panels over time: the normal force of each contact, its friction ratio |f_t| / f_n against
    the friction coefficient mu of its pair, its gap, and the solver's KKT residual and iterations.
    Without contacts (of ``bodies``) the first three say "no contacts in this run".

    Args:
        bodies: show only the contacts of these bodies or obstacles (on either side), e.g.
            ``["crate"]``; default: every contact.

    Raises:
        InvalidOptions: a name of ``bodies`` is no body or obstacle of the log (the message lists them).
    """
    plt = _pyplot()
    figure, axes = plt.subplots(4, 1, figsize=(9, 11), sharex=True, constrained_layout=True)
    normal_ax, ratio_ax, gap_ax, solver_ax = axes
    c = log.contact_arrays()
    t = log.t
    friction = {p.name: p.friction for p in scene.pairs}
    shown = _contacts_of(log, scene, bodies)
    coefficients = set()
    for i in shown:
        name = log.contact_names[i]
        rows = c["id"] == i
        times = t[c["step"][rows] + 1]
        f_n, f_t = split_forces(c["force"][rows], c["normal"][rows])
        normal_ax.plot(times, f_n, ".", ms=2, label=name)
        loaded = f_n > 1e-9
        ratio_ax.plot(times[loaded], f_t[loaded] / f_n[loaded], ".", ms=2)
        gap_ax.plot(times, 1e3 * c["gap"][rows], ".", ms=2)
        coefficients.add(friction.get(name.rsplit("#", 1)[0], scene.self_contact[0]))
    of = f" of {', '.join(bodies)}" if bodies else ""
    if not shown:  # three empty panels would look like a plotting failure
        for ax in (normal_ax, ratio_ax, gap_ax):
            ax.text(
                0.5, 0.5, f"no contacts{of} in this run", ha="center", va="center", transform=ax.transAxes
            )
    for mu in sorted(coefficients):
        ratio_ax.axhline(mu, color="k", ls="--", lw=1)
        ratio_ax.annotate(  # under its line, at the right: the line may be the panel's top
            f"mu = {mu:g}", (t[-1], mu), xytext=(-2, -2), textcoords="offset points", ha="right", va="top"
        )
    normal_ax.set_ylabel("normal force [N]")
    if shown and len(shown) <= 12:
        normal_ax.legend(fontsize="small", markerscale=4, ncol=2)
    ratio_ax.set_ylabel("|f_t| / f_n")
    gap_ax.set_ylabel("gap [mm]")
    gap_ax.axhline(0.0, color="k", lw=0.5)
    s = log.solver_arrays()
    steps_t = t[1:]
    solved = s["qps"] > 0
    solver_ax.semilogy(steps_t[solved], np.maximum(s["kkt_residual"][solved], 1e-300), ".", ms=2, color="C0")
    solver_ax.set_ylabel("KKT residual", color="C0")
    iterations_ax = solver_ax.twinx()
    iterations_ax.plot(steps_t, s["iterations"], lw=0.8, color="C3")
    iterations_ax.set_ylabel("solver iterations", color="C3")  # 0: the last solution or active set held
    iterations_ax.set_ylim(0, 1.1 * max(1, int(s["iterations"].max(initial=0))))
    solver_ax.set_xlabel("t [s]")
    figure.suptitle(f"{log.robot}: contact forces{of} and solver")
    return figure


def _contacts_of(log: RunLog, scene: Scene, bodies: Sequence[str] | None) -> list[int]:
    """The ids of the log's contacts that ``bodies`` (names of bodies or obstacles) take part in."""
    if bodies is None:
        return list(range(len(log.contact_names)))
    known = [*log.bodies, *(o.name for o in scene.obstacles)]
    if isinstance(bodies, str) or not all(isinstance(b, str) for b in bodies):
        raise InvalidOptions("bodies", f"must be a list of body names, got {bodies!r}")
    for name in bodies:
        if name not in known:
            raise InvalidOptions("bodies", f"no body or obstacle '{name}'; known: {', '.join(known)}")
    return [
        i for i, (a, b) in enumerate(zip(log.contact_body, log.contact_other)) if a in bodies or b in bodies
    ]


def energy_figure(log: RunLog, scene: Scene) -> Any:
    """Kinetic, potential (gravity) and total energy over time [J]."""
    plt = _pyplot()
    model = scene.robot.model.copy()
    model.gravity.linear = scene.gravity
    data = model.createData()
    kinetic = np.array([pin.computeKineticEnergy(model, data, q, v) for q, v in zip(log.q, log.v)])
    potential = np.array([pin.computePotentialEnergy(model, data, q) for q in log.q])
    figure, axis = plt.subplots(figsize=(9, 4), constrained_layout=True)
    axis.plot(log.t, kinetic, label="kinetic")
    axis.plot(log.t, potential - potential[0], label="potential (from t0)")
    axis.plot(log.t, kinetic + potential - potential[0], label="total", color="k")
    axis.set_xlabel("t [s]")
    axis.set_ylabel("energy [J]")
    axis.legend()
    figure.suptitle(f"{log.robot}: energy")
    return figure


def plot_path(path: str | Path, what: str = "") -> Path:
    """``path`` as a Path, when its suffix names a format save_plot writes (matplotlib would add .png to
    a name without one, and write elsewhere than told); ``what`` (an option's flag) names it in the
    error, as files.check_writable does."""
    path = Path(path)
    if path.suffix.lower() not in FORMATS:
        named = f"{what} {path}" if what else str(path)
        raise InvalidOptions(named, f"the image's suffix must be one of {', '.join(FORMATS)}")
    return path


def save_plot(
    log: RunLog, scene: Scene, path: str | Path, what: str = "forces", bodies: Sequence[str] | None = None
) -> Path:
    """Write the ``what`` figure ("forces" or "energy") of a run to an image file (.png, .pdf, .svg);
    ``bodies`` selects the contacts of the forces figure (see :func:`force_figure`)."""
    if what not in WHATS:
        raise InvalidOptions("what", f"must be one of {', '.join(WHATS)}, got {what!r}")
    if bodies is not None and what != "forces":
        raise InvalidOptions("bodies", "selects the contacts of the forces figure; the energy is the world's")
    path = plot_path(path)
    return _save(force_figure(log, scene, bodies) if what == "forces" else energy_figure(log, scene), path)


def _save(figure: Any, path: Path) -> Path:
    """Write ``figure`` to ``path`` and close it."""
    try:
        with atomic_path(path) as tmp:  # a failed write leaves any previous image
            figure.savefig(tmp, dpi=110)
    finally:
        _pyplot().close(figure)
    return path


def close_figure(figure: Any) -> None:
    """Release a figure made here (pyplot keeps each until it is closed)."""
    _pyplot().close(figure)


def pareto_figure(records: list[dict], title: str) -> Any:
    """Error against wall time per simulated second, one curve per engine and knob (each knob's
    values joined through the default point), for the records of one benchmark case."""
    plt = _pyplot()
    figure, axis = plt.subplots(figsize=(7, 5), constrained_layout=True)
    ok = [r for r in records if r["status"] == "ok" and "error" in r["metrics"]]
    default = [r for r in ok if r["engine"] == "gaussim" and r["knob"] == "default"]
    series: dict[str, list[dict]] = {}
    for r in ok:
        name = r["engine"] if r["engine"] != "gaussim" else f"gaussim {r['knob']}"
        series.setdefault(name, []).append(r)
    colors = plt.get_cmap("tab20").colors  # one colour each for up to 20 curves
    for i, (name, rows) in enumerate(sorted(series.items())):
        ours = name.startswith("gaussim ")
        if ours and name != "gaussim default":
            rows = rows + default
        rows.sort(key=lambda r: r["metrics"]["wall_per_sim_s"])
        x = [r["metrics"]["wall_per_sim_s"] for r in rows]
        y = [max(r["metrics"]["error"], 1e-16) for r in rows]
        style = ("o-" if ours else "^--") if len(rows) > 1 else "s"  # the peers dashed
        axis.plot(x, y, style, color=colors[i % len(colors)], label=name)
    axis.set(
        xscale="log", yscale="log", xlabel="wall time per simulated second [s]", ylabel="error", title=title
    )
    axis.grid(True, which="both", alpha=0.3)
    axis.legend(fontsize=7)
    return figure


def sweep_figure(rows: Sequence[dict], summary: str, against: str, keys: Sequence[str]) -> Any:
    """A sweep's ``summary`` column against its varied key ``against``: one curve per combination of
    the other varied ``keys``' values, through the mean over seeds, each run a point; failed runs are
    left out (counted in the title). ``against``'s values are the x axis when they are numbers, else
    equally spaced labels."""
    plt = _pyplot()
    figure, axis = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
    ok = [r for r in rows if r["status"] == "ok" and r.get(summary) is not None]
    xs = list(dict.fromkeys(str(r[against]) for r in rows))
    numeric = all(isinstance(r[against], (int, float)) and not isinstance(r[against], bool) for r in rows)
    others = [k for k in keys if k != against]
    series: dict[str, list[dict]] = {}
    for r in ok:
        series.setdefault(", ".join(f"{k} = {str(r[k])}" for k in others), []).append(r)
    for i, (name, mine) in enumerate(series.items()):
        x = [r[against] if numeric else xs.index(str(r[against])) for r in mine]
        y = [r[summary] for r in mine]
        means = {xi: float(np.mean([yj for xj, yj in zip(x, y) if xj == xi])) for xi in sorted(set(x))}
        axis.plot(list(means), list(means.values()), "-", color=f"C{i % 10}", label=name or None)
        axis.plot(x, y, "o", ms=4, color=f"C{i % 10}", alpha=0.6)
    if not numeric:
        axis.set_xticks(range(len(xs)), xs, rotation=20)
    axis.set(xlabel=against, ylabel=summary)
    failed = len(rows) - len(ok)
    axis.set_title(f"{summary} against {against}: {len(ok)} runs" + (f", {failed} failed" if failed else ""))
    axis.grid(True, alpha=0.3)
    if any(series):
        axis.legend(fontsize=7)
    return figure


def save_sweep_plot(
    rows: Sequence[dict], summary: str, against: str, keys: Sequence[str], path: str | Path
) -> Path:
    """Write :func:`sweep_figure` to an image file (.png, .pdf, .svg); the path."""
    return _save(sweep_figure(rows, summary, against, keys), plot_path(path))
