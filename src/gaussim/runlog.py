"""Run logs: everything a run produced, no pickle.

A log holds t, q, v (N + 1 states), tau (N steps), the per-contact forces, points, normals and gaps
of each step with the bodies each contact is between, the limit reactions, the solver certificate of
each step, the scene text and the options: a run can be reproduced and analysed from its log alone.

Two forms, both read by :meth:`RunLog.load`: one compressed ``.npz`` (:meth:`RunLog.save`, written
atomically), and the directory a run writes as it goes (:class:`RunLogWriter`): ``header.json`` and
numbered chunks ``chunk-000000.npz``, ``chunk-000001.npz``, ... of the steps since the last one, each
written atomically and never rewritten. Logging a run thus costs O(new steps) and bounded memory, and
at any instant (a SIGKILL, a full disk) the directory is a valid log of a prefix of the run: the
header says complete only once the last chunk is in. The process writing a directory holds the lock
of its file ``.writing`` (a POSIX record lock, released by the system however the process ends): a
reader tells a run still going from one that was killed, and a second run refuses to replace a log
being written. A directory is the simplest such format that
keeps the dependencies to numpy (HDF5 or Zarr would add one, and an appended zip is invalid while
its end is being written).
"""

from __future__ import annotations

import csv
import glob
import json
import os
import re
import shutil
import tempfile
import tomllib
from collections.abc import Sequence
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any

import numpy as np

from .exceptions import GaussimError, InvalidOptions, shown
from .files import Busy, OutputError, atomic_path, leftovers, lock_holder, take_lock, umask, write_atomic
from .options import Options
from .report import StepReport
from .solver import CONVERGED
from .state import State

FORMAT_VERSION = 2  # the single .npz
DIRECTORY_VERSION = 3  # the directory of chunks
# the oldest version of each form read, and the first that names each contact's bodies (an older log
# is of one robot, and read as such)
OLDEST_VERSION = {"file": 1, "directory": 2}
BODIES_SINCE = {"file": 2, "directory": 3}
HEADER = "header.json"
CHUNK = re.compile(r"chunk-(\d{6})\.npz")
# the header of a run still going, or ended without a word (SIGKILL, power cut)
RUNNING = "still running, or stopped by a kill: the log holds the steps of its chunks"
# the file whose lock (files.take_lock) the process writing a log directory holds while it writes
WRITING = ".writing"
# the reason RunLog.load gives a log whose header says RUNNING when no process writes it any more
STOPPED = (
    "stopped early: the process writing it ended before finishing it (killed, e.g. by SIGKILL or the "
    "out-of-memory killer, or crashed); the log holds the steps of its chunks"
)
# ... and while a process still writes it
LIVE = "still running (process {}): the log holds the steps of the chunks written so far"
# the log directories this process writes (their resolved paths): their lock is never probed here
_WRITTEN_HERE: set[Path] = set()
# A run whose contacts sink deeper than this is flagged by its summary [m] (the velocity scheme closes an
# approach exactly and rests within g dt^2 of the surface: a deeper penetration is lost accuracy)
PENETRATION_TOLERANCE = 1e-3
# what each array of a log holds: its numpy kinds (b bool, i int, f float, U text) and its shape, in
# the sizes N (steps), nq, nv, C (contact rows), K (contact names), L (limit rows), J (limit names),
# B (bodies)
LAYOUT: dict[str, tuple[str, tuple[str, ...]]] = {
    "format_version": ("i", ()),
    "robot": ("U", ()),
    "bodies": ("U", ("B",)),
    "scene_text": ("U", ()),
    "scene_path": ("U", ()),
    "options": ("U", ()),
    "complete": ("b", ()),
    "reason": ("U", ()),
    "wall_time": ("f", ()),
    "t": ("f", ("N+1",)),
    "q": ("f", ("N+1", "nq")),
    "v": ("f", ("N+1", "nv")),
    "tau": ("f", ("N", "nv")),
    "contact_names": ("U", ("K",)),
    "contact_geometry": ("U", ("K",)),
    "contact_obstacle": ("U", ("K",)),
    "contact_body": ("U", ("K",)),
    "contact_other": ("U", ("K",)),
    "limit_names": ("U", ("J",)),
    "limit_step": ("i", ("L",)),
    "limit_id": ("i", ("L",)),
    "limit_torque": ("f", ("L",)),
    "contact_step": ("i", ("C",)),
    "contact_id": ("i", ("C",)),
    "contact_point": ("f", ("C", "3")),
    "contact_normal": ("f", ("C", "3")),
    "contact_force": ("f", ("C", "3")),
    "contact_gap": ("f", ("C",)),
    "solver_qps": ("i", ("N",)),
    "solver_iterations": ("i", ("N",)),
    "solver_kkt_residual": ("f", ("N",)),
    "solver_status": ("U", ("N",)),
}
# the entries of a single-file log that are its header (its scalars and its bodies), not its columns
NPZ_HEADER = tuple(key for key, (_, shape) in LAYOUT.items() if shape in ((), ("B",)))
# header entries a log may lack (written before gaussim stored them): gravity (3,), masses (JSON text)
OPTIONAL_HEADER = ("gravity", "masses")
# what a log from before BODIES_SINCE lacks
BODY_ENTRIES = ("bodies", "contact_body", "contact_other")
# A step's status when its QPs converged but its friction fixed point did not (friction_unsettled).
FRICTION_UNSETTLED = "FRICTION_UNSETTLED"
# A step's status when it solved no QP (nothing restricted its motion).
NO_QP = "NO_QP"
# The stored statuses of a step that converged (a solver status is stored as its value: Status.value).
ACCEPTED = (*(status.value for status in CONVERGED), NO_QP)


class RunLogError(GaussimError):
    """A file is not a gaussim run log (or a damaged one)."""


class RunLog:
    """A run being recorded, or loaded from a file.

    Attributes:
        t: times [s], shape (N + 1,): the first state's time plus step * dt (no sum of dt's round-off).
        q, v: states, shapes (N + 1, nq), (N + 1, nv).
        tau: torques applied during each step, shape (N, nv).
        complete: False when the run stopped before its duration; ``reason`` says why.
        scene_text, options: what the run was made from.
        bodies: the names of the world's bodies (one, the robot's, in a one-robot scene).
        contact_names: each contact's name, ``"geometry/obstacle#k"``, indexed by the contact ids of
            :meth:`contact_arrays`; ``contact_geometry``, ``contact_obstacle``: its two sides;
            ``contact_body``: the body its force acts on (the geometry's), ``contact_other``: the body
            or obstacle pushing it.
        gravity: the scene's gravity [m/s^2], shape (3,), or None (not given to :meth:`start`, or a
            log written before gaussim stored it).
        masses: each body's mass [kg], by name, or None (a log from before gaussim stored them).
    """

    def __init__(self, robot: str, scene_text: str, options: Options, scene_path: str = "") -> None:
        self.robot, self.scene_text, self.options, self.scene_path = robot, scene_text, options, scene_path
        self.complete, self.reason = False, "not finished"
        self.wall_time: float | None = None
        self._t: list[float] = []
        self._t0 = 0.0
        self.gravity: list[float] | None = None
        self.masses: dict[str, float] | None = None
        self._q: list[np.ndarray] = []
        self._v: list[np.ndarray] = []
        self._tau: list[np.ndarray] = []
        self._solver: list[tuple[int, int, float, str]] = []  # qps, iterations, kkt residual, status
        self._contacts: list[tuple[int, int, np.ndarray, np.ndarray, np.ndarray, float]] = []
        self._limits: list[tuple[int, int, float]] = []
        self.contact_names: list[str] = []
        self.contact_geometry: list[str] = []
        self.contact_obstacle: list[str] = []
        self.bodies: list[str] = [robot]
        self.contact_body: list[str] = []
        self.contact_other: list[str] = []
        self.limit_names: list[str] = []
        self._ids: dict[str, int] = {}
        self._limit_ids: dict[str, int] = {}
        self._drained = 0  # steps already handed to a RunLogWriter (dropped from memory)
        self._names_drained = self._limit_names_drained = 0
        self._stored: dict[str, np.ndarray] | None = None  # a loaded log's columns (read-only)

    # -- recording ---------------------------------------------------------------------------------

    def start(self, state: State, gravity: Sequence[float] | np.ndarray | None = None) -> None:
        """Record the initial state (of a Simulator: its world names the bodies and their masses) and
        the scene's ``gravity`` [m/s^2] (``Scene.gravity``; stored in the log's header)."""
        if state.world is not None:
            self.bodies = list(state.world.bodies)
            self.masses = {name: float(b.robot.mass) for name, b in state.world.bodies.items()}
        self.gravity = None if gravity is None else [float(g) for g in gravity]
        self._t0 = state.t
        self._append_state(state, state.t)

    def record(self, state: State, tau: np.ndarray, report: StepReport) -> None:
        """Add one step to the log: call it after each ``Simulator.step``, in order, with the state the
        step reached, the torque the joints felt during it and the step's report.

        Args:
            state: the state after the step (its t is stored as the first state's t + step * dt).
            tau: the generalized torque applied during the step, shape (nv,) [N m or N]; with implicit
                damping, ``Simulator.full_torque(tau, damping, state.v)``.
            report: ``Simulator.last_step``: its contacts (force, point, normal, gap and the bodies
                each is between), limit reactions and solver certificates are stored.
        """
        step = self.steps
        self._append_state(state, self._t0 + (step + 1) * self.options.dt)
        self._tau.append(np.asarray(tau, dtype=float))
        certificates = report.certificates
        worst = next((c for c in certificates if not c.converged), certificates[0] if certificates else None)
        if worst is None:
            status = NO_QP
        elif worst.converged and report.friction_unsettled:
            status = FRICTION_UNSETTLED
        else:
            status = worst.status.value
        self._solver.append((len(certificates), report.iterations, report.max_residual, status))
        for c in report.contacts:
            if c.name not in self._ids:
                self._ids[c.name] = len(self.contact_names)
                self.contact_names.append(c.name)
                self.contact_geometry.append(c.geometry)
                self.contact_obstacle.append(c.obstacle)
                body, other = report.body_of(c)
                self.contact_body.append(body)
                self.contact_other.append(other)
            self._contacts.append((step, self._ids[c.name], c.point, c.normal, c.force, c.gap))
        for r in report.limits:
            key = f"{r.joint} {r.side}"
            if key not in self._limit_ids:
                self._limit_ids[key] = len(self.limit_names)
                self.limit_names.append(key)
            self._limits.append((step, self._limit_ids[key], r.torque))

    def _append_state(self, state: State, t: float) -> None:
        self._t.append(t)
        self._q.append(state.q)
        self._v.append(state.v)

    def finish(self, complete: bool, reason: str = "") -> None:
        self.complete, self.reason = complete, reason

    # -- arrays --------------------------------------------------------------------------------------

    @property
    def steps(self) -> int:
        return self._drained + len(self._tau)

    @property
    def buffered(self) -> int:
        """Steps held in memory, not yet handed to a writer."""
        return len(self._tau)

    @property
    def t(self) -> np.ndarray:
        return self._stored["t"] if self._stored is not None else np.array(self._t)

    @property
    def q(self) -> np.ndarray:
        return self._stored["q"] if self._stored is not None else np.array(self._q)

    @property
    def v(self) -> np.ndarray:
        return self._stored["v"] if self._stored is not None else np.array(self._v)

    @property
    def tau(self) -> np.ndarray:
        if self._stored is not None:
            return self._stored["tau"]
        return np.array(self._tau).reshape(len(self._tau), len(self._v[0]) if self._v else 0)

    def contact_arrays(self) -> dict[str, np.ndarray]:
        """Per (step, contact) rows: step, contact id, point (3), normal (3), force (3), gap."""
        if self._stored is not None:
            keys = ("step", "id", "point", "normal", "force", "gap")
            return {k: self._stored[f"contact_{k}"] for k in keys}
        rows = self._contacts
        return {
            "step": np.array([r[0] for r in rows], dtype=int),
            "id": np.array([r[1] for r in rows], dtype=int),
            "point": np.array([r[2] for r in rows]).reshape(-1, 3),
            "normal": np.array([r[3] for r in rows]).reshape(-1, 3),
            "force": np.array([r[4] for r in rows]).reshape(-1, 3),
            "gap": np.array([r[5] for r in rows], dtype=float),
        }

    def solver_arrays(self) -> dict[str, np.ndarray]:
        if self._stored is not None:
            return {k: self._stored[f"solver_{k}"] for k in ("qps", "iterations", "kkt_residual", "status")}
        return {
            "qps": np.array([s[0] for s in self._solver], dtype=int),
            "iterations": np.array([s[1] for s in self._solver], dtype=int),
            "kkt_residual": np.array([s[2] for s in self._solver], dtype=float),
            "status": np.array([s[3] for s in self._solver], dtype=str),
        }

    # -- files -----------------------------------------------------------------------------------------

    def _rows(self) -> dict[str, np.ndarray]:
        """The per-state, per-step and per-row arrays held in memory, with the names first seen in them."""
        if self._stored is not None:
            return self._stored
        contacts, solver = self.contact_arrays(), self.solver_arrays()
        return {
            "t": self.t,
            "q": self.q,
            "v": self.v,
            "tau": self.tau,
            "contact_names": np.array(self.contact_names[self._names_drained :], dtype=str),
            "contact_geometry": np.array(self.contact_geometry[self._names_drained :], dtype=str),
            "contact_obstacle": np.array(self.contact_obstacle[self._names_drained :], dtype=str),
            "contact_body": np.array(self.contact_body[self._names_drained :], dtype=str),
            "contact_other": np.array(self.contact_other[self._names_drained :], dtype=str),
            "limit_names": np.array(self.limit_names[self._limit_names_drained :], dtype=str),
            "limit_step": np.array([r[0] for r in self._limits], dtype=int),
            "limit_id": np.array([r[1] for r in self._limits], dtype=int),
            "limit_torque": np.array([r[2] for r in self._limits], dtype=float),
            **{f"contact_{k}": v for k, v in contacts.items()},
            **{f"solver_{k}": v for k, v in solver.items()},
        }

    def _forget(self) -> None:
        """Drop the rows held in memory (a writer has them on disk): a long run's memory stays bounded."""
        self._drained += len(self._tau)
        self._names_drained, self._limit_names_drained = len(self.contact_names), len(self.limit_names)
        for buffer in (self._t, self._q, self._v, self._tau, self._solver, self._contacts, self._limits):
            buffer.clear()

    def _header(self) -> dict[str, Any]:
        return {
            "robot": self.robot,
            "bodies": self.bodies,
            "scene_text": self.scene_text,
            "scene_path": self.scene_path,
            "options": asdict(self.options),
            "complete": self.complete,
            "reason": self.reason,
            "wall_time": self.wall_time,
            "gravity": self.gravity,
            "masses": self.masses,
        }

    def save(self, path: str | Path) -> Path:
        """Write the whole log as one ``.npz``, atomically: a half-written file never replaces a good one."""
        if self._drained and self._stored is None:
            raise RunLogError("this log was written by a RunLogWriter: load it from its directory")
        header = self._header()
        arrays: dict[str, Any] = {
            "format_version": np.array(FORMAT_VERSION),
            **{
                k: np.array(v)
                for k, v in header.items()
                if k not in ("options", "wall_time", "bodies", "gravity", "masses")
            },
            "bodies": np.array(self.bodies, dtype=str),
            "options": np.array(json.dumps(header["options"])),
            "wall_time": np.array(np.nan if self.wall_time is None else self.wall_time),
            **({} if self.gravity is None else {"gravity": np.array(self.gravity)}),
            **({} if self.masses is None else {"masses": np.array(json.dumps(self.masses))}),
            **self._rows(),
        }
        with atomic_path(path) as tmp, tmp.open("wb") as f:
            np.savez_compressed(f, **arrays)
        return Path(path)

    @classmethod
    def load(cls, path: str | Path) -> RunLog:
        """Read a log: a ``.npz`` written by :meth:`save`, or a directory written by :class:`RunLogWriter`
        (all its chunks, up to the first one missing). The log read is read-only: its columns are the
        arrays read, with no per-step Python object (a 236k-step Solo-12 log: 1.2 GB of them)."""
        path = Path(path)
        if path.is_dir():
            header, data = _read_directory(path)
            bodied = header["format_version"] >= BODIES_SINCE["directory"]
            if not header["complete"] and header["reason"].startswith(RUNNING):
                header["reason"] = _running_reason(path) + header["reason"][len(RUNNING) :]
        else:
            data = _read_npz(path)
            _check_version(path, data.get("format_version"), OLDEST_VERSION["file"], FORMAT_VERSION)
            bodied = int(data["format_version"]) >= BODIES_SINCE["file"]
            _check_layout(path, data, _held(NPZ_HEADER, bodied))
            header = {k: data[k].item() for k in ("robot", "scene_text", "scene_path", "complete", "reason")}
            header["options"] = _json(path, data, "options")
            header["wall_time"] = None if np.isnan(data["wall_time"]) else float(data["wall_time"])
            if bodied:
                header["bodies"] = list(map(str, data["bodies"]))
            header["gravity"] = data["gravity"].tolist() if "gravity" in data else None
            header["masses"] = _json(path, data, "masses") if "masses" in data else None
        _check_layout(path, data, _held(tuple(k for k in LAYOUT if k not in NPZ_HEADER), bodied))
        if not bodied:
            header["bodies"] = [str(header["robot"])]
            data = {**data, **_one_robot_sides(str(header["robot"]), str(header["scene_text"]), data)}
        log = cls(str(header["robot"]), str(header["scene_text"]), _options(path, header["options"]))
        log.bodies = header["bodies"]
        log.scene_path = str(header["scene_path"])
        log.complete, log.reason = bool(header["complete"]), str(header["reason"])
        log.wall_time = header["wall_time"]
        log.gravity, log.masses = header.get("gravity"), header.get("masses")
        log._stored = {k: v for k, v in data.items() if k not in NPZ_HEADER + OPTIONAL_HEADER}
        log._drained = len(data["tau"])
        log.contact_names = list(map(str, data["contact_names"]))
        log.contact_geometry = list(map(str, data["contact_geometry"]))
        log.contact_obstacle = list(map(str, data["contact_obstacle"]))
        log.contact_body = list(map(str, data["contact_body"]))
        log.contact_other = list(map(str, data["contact_other"]))
        log.limit_names = list(map(str, data["limit_names"]))
        log._names_drained, log._limit_names_drained = len(log.contact_names), len(log.limit_names)
        return log

    # -- analysis --------------------------------------------------------------------------------------

    def contact_records(self) -> dict[str, list]:
        """The per-contact force time series as columns, one row per contact per step, units in the
        names (what :meth:`contact_forces`, :func:`write_forces` and ``gaussim forces`` hold):

        ``step`` (the step, from 0; its force acts from t[step] to t[step + 1]), ``t_s`` (t[step + 1],
        when the step ends [s]), ``contact`` (its name), ``geometry``, ``obstacle`` (its two sides),
        ``body`` (the body the force acts on), ``other`` (the body or obstacle pushing it),
        ``point_{x,y,z}_m`` (on the body, world frame [m]), ``normal_{x,y,z}`` (unit, from the other
        side to the body), ``fn_N`` (the normal component [N]), ``ft_N`` (the tangential one's
        magnitude [N]), ``force_{x,y,z}_N`` (the force vector [N], world frame) and ``gap_m`` (the
        signed distance, negative when penetrating [m])."""
        c = self.contact_arrays()
        ids, force = c["id"], c["force"]
        fn, ft = split_forces(force, c["normal"])
        columns: dict[str, list] = {
            "step": c["step"].tolist(),
            "t_s": self.t[c["step"] + 1].tolist(),
            "contact": [self.contact_names[i] for i in ids],
            "geometry": [self.contact_geometry[i] for i in ids],
            "obstacle": [self.contact_obstacle[i] for i in ids],
            "body": [self.contact_body[i] for i in ids],
            "other": [self.contact_other[i] for i in ids],
        }
        for name, unit in (("point", "_m"), ("normal", "")):
            for axis, column in zip("xyz", c[name].T):
                columns[f"{name}_{axis}{unit}"] = column.tolist()
        columns["fn_N"] = fn.tolist()
        columns["ft_N"] = ft.tolist()
        for axis, column in zip("xyz", force.T):
            columns[f"force_{axis}_N"] = column.tolist()
        columns["gap_m"] = c["gap"].tolist()
        return columns

    def contact_forces(self):  # type: ignore[no-untyped-def]
        """The per-contact time series as a pandas DataFrame (``pip install pandas``)."""
        try:
            import pandas as pd
        except ImportError as err:
            raise GaussimError("contact_forces() needs pandas: pip install 'gaussim[analysis]'") from err
        return pd.DataFrame(self.contact_records())

    def forces_between(self, a: str, b: str) -> np.ndarray:
        """The total contact force on body ``a`` from body or obstacle ``b`` at each step, world frame,
        shape (N, 3) [N]: row k is ``StepReport.forces_between(a, b)`` of the step from ``t[k]`` to
        ``t[k + 1]`` (zero when they do not touch); ``forces_between(b, a)`` is its opposite.

        Raises:
            InvalidOptions: ``a`` is no body of the log, or ``b`` no body or obstacle of it (the
                message lists them).
        """
        if a not in self.bodies:
            raise InvalidOptions("body", f"no body '{a}' in this log; its bodies: {', '.join(self.bodies)}")
        # the obstacles: the scene file's, else those that touched (a misspelt one would sum to zeros)
        obstacles = _declared_obstacles(self.scene_text, one_robot=False)
        obstacles = set(self.contact_other) - set(self.bodies) if obstacles is None else obstacles
        if b not in self.bodies and b not in obstacles:
            raise InvalidOptions(
                "body",
                f"no body or obstacle '{b}' in this log; its bodies: {', '.join(self.bodies)}; "
                f"its obstacles: {', '.join(sorted(obstacles)) or 'none'}",
            )
        body, other = np.array(self.contact_body, dtype=str), np.array(self.contact_other, dtype=str)
        # per contact: +1 when its force is on a from b, -1 when on b from a (the reaction)
        sign = np.where((body == a) & (other == b), 1.0, np.where((body == b) & (other == a), -1.0, 0.0))
        c = self.contact_arrays()
        rows = np.flatnonzero(sign[c["id"]])
        total = np.zeros((self.steps, 3))
        np.add.at(total, c["step"][rows], sign[c["id"][rows], None] * c["force"][rows])
        return total

    def body_pairs(self) -> list[tuple[str, str]]:
        """The pairs (body, other body or obstacle) of the log's contacts, each once (in the order of
        the contact first seen, whichever its sides' order)."""
        pairs: dict[tuple[str, str], None] = {}
        for a, b in zip(self.contact_body, self.contact_other):
            if (b, a) not in pairs:
                pairs[a, b] = None
        return list(pairs)

    def warnings(self) -> list[str]:
        """What makes the run's motion less accurate than its options promise: contacts sinking
        deeper than PENETRATION_TOLERANCE, steps whose QP did not converge (kept by
        ``on_failure='report'``); empty for a run to trust."""
        c, s, o = self.contact_arrays(), self.solver_arrays(), self.options
        found = []
        depth = max(0.0, -c["gap"].min()) if len(c["gap"]) else 0.0
        if depth > PENETRATION_TOLERANCE:
            found.append(
                f"contacts sank {1e3 * depth:.4g} mm, more than {1e3 * PENETRATION_TOLERANCE:g} mm: "
                f"dt = {o.dt:g} s is too coarse for the {o.scheme} scheme on this scene; reduce dt "
                "(or the friction)"
            )
        failed = int(np.sum(~np.isin(s["status"], ACCEPTED)))
        if failed:
            found.append(
                f"{failed} steps did not converge (max KKT residual {s['kkt_residual'].max():.2e}, "
                f"eps_abs = {o.eps_abs:g}): on_failure = '{o.on_failure}' kept their iterates, which need "
                "not be the Gauss principle's motion"
            )
        return found

    def summary(self) -> str:
        """A plain-text summary: run and solver statistics, a WARNING line for each of
        :meth:`warnings`, the force between each pair of bodies (or body and obstacle), and each
        contact's force statistics, grouped by pair."""
        c, s = self.contact_arrays(), self.solver_arrays()
        wall_time = self.wall_time
        failed = int(np.sum(~np.isin(s["status"], ACCEPTED)))
        t = self.t
        warnings = self.warnings()
        status = "complete" if self.complete else "INCOMPLETE: " + self.reason
        lines = [
            f"robot {self.robot}: {self.steps} steps, {t[-1] - t[0]:.4g} s simulated"
            + (f" in {wall_time:.3g} s wall ({self.steps / wall_time:.0f} steps/s)" if wall_time else ""),
            f"status: {status}" + (f", with {len(warnings)} warning(s)" if warnings else ""),
            *(f"WARNING: {w}" for w in warnings),
            f"max penetration: {max(0.0, -c['gap'].min()) * 1e3 if len(c['gap']) else 0.0:.4f} mm;"
            f" max KKT residual: {s['kkt_residual'].max() if self.steps else 0.0:.2e};"
            f" QPs: {int(s['qps'].sum())}, steps not converged: {failed}",
        ]
        if self.contact_names:
            lines += self._force_lines(c)
        return "\n".join(lines)

    def _force_lines(self, c: dict[str, np.ndarray]) -> list[str]:
        """The summary's force tables: the total force between each pair of bodies (or body and
        obstacle) over the steps they touch, then each contact's statistics, grouped by pair."""
        pairs = self.body_pairs()
        sides = list(zip(self.contact_body, self.contact_other))
        width = max(30, *(len(n) + 2 for n in self.contact_names), *(len(f"{a} from {b}") for a, b in pairs))
        lines = [
            "",
            f"{'force on a body from':<{width}} {'steps':>6} {'mean |F| [N]':>13} {'max |F| [N]':>12}",
        ]
        for a, b in pairs:
            if a == b:  # a body's own links: forces on each of them, not one force
                continue
            ids = [i for i, pair in enumerate(sides) if pair in ((a, b), (b, a))]
            touching = np.unique(c["step"][np.isin(c["id"], ids)])
            norms = np.linalg.norm(self.forces_between(a, b)[touching], axis=1)
            label = f"{a} from {b}"
            lines.append(f"{label:<{width}} {len(touching):>6} {norms.mean():>13.3f} {norms.max():>12.3f}")
        lines += [
            "",
            f"{'contact':<{width}} {'steps':>6} {'mean fn [N]':>12} {'max fn [N]':>11}"
            f" {'max |ft|/fn':>12} {'min gap [mm]':>13}",
        ]
        for a, b in pairs:
            if len(pairs) > 1:
                lines.append(f"{a} from {b}:" if a != b else f"{a} from its own links:")
            for i in (i for i, pair in enumerate(sides) if pair in ((a, b), (b, a))):
                mine = c["id"] == i
                fn = np.einsum("ij,ij->i", c["force"][mine], c["normal"][mine])
                ft = np.linalg.norm(c["force"][mine] - fn[:, None] * c["normal"][mine], axis=1)
                ratio = np.max(np.where(fn > 1e-9, ft / np.maximum(fn, 1e-300), 0.0))
                lines.append(
                    f"{self.contact_names[i]:<{width}} {int(mine.sum()):>6} {fn.mean():>12.3f}"
                    f" {fn.max():>11.3f} {ratio:>12.3f} {1e3 * c['gap'][mine].min():>13.4f}"
                )
        return lines


class RunLogWriter:
    """Writes the log of a run as it goes, into a directory (see the module docstring).

    Made after the log's first state and before the first step, so that a path that cannot be written
    is reported before the run. A log already at ``path`` (a directory or an ``.npz``) is moved to
    ``path.prev`` (an older ``.prev`` log is removed); anything else there is refused, never deleted.

    Attributes:
        path: the directory.
        previous: where the log that was at ``path`` went, or None.
        steps: the steps on disk.
    """

    def __init__(self, path: str | Path, log: RunLog) -> None:
        self.path, self.log, self.steps, self._chunks = Path(path), log, 0, 0
        self._lock: int | None = None
        check_replaceable(self.path)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            _remove_stale(self.path)
            # made under a temporary name, so that a failure here leaves what was at path as it was
            new = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.", suffix=".new", dir=self.path.parent))
            new.chmod(0o777 & ~umask())
        except OSError as err:
            raise OutputError(f"run log {self.path}: cannot be written ({err.strerror or err})") from err
        try:
            self.path, final = new, self.path
            self._hold(new)
            self._write_header()
            self.append()  # the initial state: from here on the directory is a valid log
            self.previous = _set_aside(final)
            os.replace(new, final)
            self._hold(final)
            self.path = final
        except OSError as err:
            self._release()
            shutil.rmtree(new, ignore_errors=True)
            raise OutputError(f"run log {final}: cannot be written ({err.strerror or err})") from err

    def _hold(self, path: Path) -> None:
        """Take (the first time) the log's WRITING lock, held until :meth:`close`; the directory it is
        in is ``path`` (renamed: the lock follows the file)."""
        _WRITTEN_HERE.discard(self.path.resolve())
        _WRITTEN_HERE.add(path.resolve())
        if self._lock is None:
            try:
                self._lock = take_lock(path / WRITING)
            except Busy as err:  # a directory this process just made: no other process knows its name
                raise OSError(f"{path / WRITING}: {err}") from err

    def _release(self) -> None:
        _WRITTEN_HERE.discard(self.path.resolve())
        if self._lock is not None:
            os.close(self._lock)
            self._lock = None

    def append(self) -> None:
        """Write the steps recorded since the last chunk as the next chunk (nothing when there is none)."""
        if self.log.buffered == 0 and self._chunks > 0:
            return
        with atomic_path(self.path / f"chunk-{self._chunks:06d}.npz") as tmp, tmp.open("wb") as f:
            np.savez_compressed(f, **self.log._rows())  # type: ignore[arg-type]
        self.log._forget()
        self._chunks += 1
        self.steps = self.log.steps

    def close(self) -> None:
        """Write the last chunk, then the header with the log's outcome (complete or why not; the header
        also when the chunk cannot be written), and release the log's lock."""
        try:
            self.append()
        finally:
            try:
                self._write_header()
            finally:
                self._release()

    def _write_header(self) -> None:
        header = {"format_version": DIRECTORY_VERSION, **self.log._header()}
        if self._chunks == 0 or not header["complete"] and header["reason"] == "not finished":
            header["reason"] = RUNNING
        write_atomic(self.path / HEADER, json.dumps(header, indent=1).encode())


def split_forces(force: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The normal components (m,) and the tangential magnitudes (m,) of forces (m, 3) along unit
    normals (m, 3)."""
    fn = np.einsum("ij,ij->i", force, normal)
    return fn, np.linalg.norm(force - fn[:, None] * normal, axis=1)


def require_parquet(what: str) -> None:
    """Raise GaussimError naming ``what`` and the install command unless pandas and pyarrow, which a
    Parquet file needs, are installed (pandas' own error is several lines about engines)."""
    import importlib.util

    missing = [m for m in ("pandas", "pyarrow") if importlib.util.find_spec(m) is None]
    if missing:
        raise GaussimError(
            f"{what} needs {' and '.join(missing)}: pip install 'gaussim[analysis]' (pandas and pyarrow)"
        )


def write_forces(log: RunLog, path: str | Path, kind: str = "csv") -> int:
    """Write ``log``'s per-contact force time series (:meth:`RunLog.contact_records`: its columns, units
    in their names) to ``path``, atomically, as ``kind`` "csv" or "parquet" (needs pandas and pyarrow);
    returns the number of rows. The one export of ``gaussim forces`` and the examples."""
    columns = log.contact_records()
    if kind == "csv":
        with atomic_path(path) as tmp, tmp.open("w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(columns)
            writer.writerows(zip(*columns.values()))
    elif kind == "parquet":
        require_parquet(str(path))
        frame = log.contact_forces()
        with atomic_path(path) as tmp:
            frame.to_parquet(tmp)
    else:
        raise InvalidOptions("kind", f"must be 'csv' or 'parquet', got {shown(kind)}")
    return len(columns["step"])


def is_run_log(path: Path) -> bool:
    """True for a run log file or directory (checked from its header, not its name)."""
    if path.is_dir():
        return (path / HEADER).is_file()
    try:
        with np.load(path, allow_pickle=False) as f:
            return "format_version" in f.files
    except (OSError, ValueError):
        return False


def check_replaceable(path: Path) -> None:
    """Raise OutputError when a run log cannot be written at ``path``: ``path`` or ``path.prev`` holds
    something that is not a run log, or a log another run is still writing (moved aside, it would take
    that run's next chunks into the new log)."""
    for p in (path, _previous(path)):
        if p.exists() and not is_run_log(p):
            raise OutputError(f"run log {path}: {p} exists and is not a run log; it is left alone")
        try:
            holder = _writer(p) if p.is_dir() else None
        except OSError:  # a log from before the lock: nothing tells whether it is written
            holder = None
        if holder is not None:
            by = f" (process {holder})" if holder else ""
            raise OutputError(
                f"run log {path}: another run{by} is still writing {p}; wait for it to end, or give "
                "another path"
            )


def _writer(path: Path) -> str | None:
    """The process id (text, "" when unknown) of the run still writing the log directory ``path``, or
    None when none is; an OSError when that cannot be told (a log from before the WRITING lock, a file
    system without locks)."""
    if path.resolve() in _WRITTEN_HERE:
        return str(os.getpid())
    return lock_holder(path / WRITING)


def _running_reason(path: Path) -> str:
    """The reason of a log directory whose header says RUNNING: STOPPED when no process writes it any
    more, LIVE while one does, RUNNING when that cannot be told."""
    try:
        holder = _writer(path)
    except OSError:
        return RUNNING
    return STOPPED if holder is None else LIVE.format(holder)


def _remove_stale(path: Path) -> None:
    """Remove the temporary directory (``.NAME.*.new``) that a run killed before its log at ``path``
    held its first state left beside it, once no process writes it."""
    for new in path.parent.glob(f".{glob.escape(path.name)}.*.new"):
        try:
            stale = new.is_dir() and _writer(new) is None
        except OSError:  # no lock file (not gaussim's), or no locks: left alone
            continue
        if stale:
            shutil.rmtree(new, ignore_errors=True)


def _previous(path: Path) -> Path:
    return path.with_name(path.name + ".prev")


def _set_aside(path: Path) -> Path | None:
    """Move the run log at ``path`` to ``path.prev`` (replacing an older one); None when there is none."""
    if not path.exists():
        return None
    if path.is_dir():  # the chunk or header a kill interrupted: hidden, never read, only taking room
        for leftover in leftovers(path):
            leftover.unlink(missing_ok=True)
    previous = _previous(path)
    if previous.is_dir():
        shutil.rmtree(previous)
    elif previous.exists():
        previous.unlink()
    os.replace(path, previous)
    return previous


def _json(path: Path, data: dict, field: str) -> object:
    """The JSON a log's header ``field`` holds; a :class:`RunLogError` naming the file and field."""
    try:
        return json.loads(str(data[field]))
    except json.JSONDecodeError as err:
        raise RunLogError(f"{path}: {field}: not JSON ({err})") from err


def _read_npz(path: Path) -> dict[str, np.ndarray]:
    """The arrays of the .npz at ``path`` (a single-file log or a chunk)."""
    try:
        archive = np.load(path, allow_pickle=False)
        if not isinstance(archive, np.lib.npyio.NpzFile):
            raise RunLogError(f"{path}: not a gaussim run log (a single .npy array, not a .npz archive)")
        with archive as f:
            return {k: f[k] for k in f.files}
    except RunLogError:
        raise
    except OSError as err:
        raise RunLogError(f"{path}: cannot read it: {err.strerror or err}") from err
    except (
        ValueError
    ) as err:  # not numpy's words: they advise allow_pickle=True, which runs what a file holds
        raise RunLogError(
            f"{path}: not a gaussim run log (one is the directory `gaussim run` writes, or the .npz archive "
            "of plain arrays RunLog.save writes)"
        ) from err
    except Exception as err:  # zipfile reads a damaged archive's bytes as anything: encryption, a method
        what = f"{type(err).__name__}: {err}"
        raise RunLogError(f"{path}: a truncated or damaged .npz archive ({what})") from err


def _options(path: Path, options: object) -> Options:
    """The Options a log's header holds, or a RunLogError naming the file."""
    try:
        return Options(**options)  # type: ignore[arg-type]
    except TypeError as err:  # not a dict (an option this gaussim does not have: InvalidOptions)
        known = ", ".join(f.name for f in fields(Options))
        raise RunLogError(
            f"{path}: options: must be a JSON object of Options fields ({known}), got {shown(str(options))}"
        ) from err
    except InvalidOptions as err:
        raise RunLogError(f"{path}: options.{err}") from err


def _check_version(path: Path, version: object, oldest: int, newest: int) -> None:
    """Raise RunLogError unless ``version`` (an array or a number) is a format this gaussim reads, one of
    ``oldest`` to ``newest``."""
    if version is None:
        raise RunLogError(f"{path}: not a gaussim run log (no format_version)")
    value = np.asarray(version)
    number = value.shape == () and value.dtype.kind == "i"
    if not (number and oldest <= int(value) <= newest):
        newer = number and int(value) > newest
        raise RunLogError(
            f"{path}: format_version {shown(value.tolist())} is "
            + ("newer than this gaussim reads" if newer else "unknown")
            + f" (it reads formats {oldest} to {newest})"
            + ("; upgrade gaussim" if newer else "")
        )


def _check_layout(path: Path, data: dict[str, np.ndarray], keys: tuple[str, ...]) -> None:
    """Raise RunLogError naming the array when one of ``keys`` is missing from ``data`` or not as LAYOUT
    says (kind, dimensions, sizes agreeing across arrays), or an index points outside its table."""
    sizes: dict[str, int] = {"3": 3}
    origin = {"3": "a point"}  # the array each size was read from
    for key in keys:
        kind, shape = LAYOUT[key]
        if key not in data:
            raise RunLogError(f"{path}: damaged run log: no array '{key}'")
        arr = data[key]
        if arr.dtype.kind != kind or arr.ndim != len(shape):
            raise RunLogError(
                f"{path}: damaged run log: '{key}' is a {arr.ndim}-d {arr.dtype} array, not the "
                f"{len(shape)}-d {dict(b='bool', i='int', f='float', U='text')[kind]} array it should be"
            )
        for size, name in zip(arr.shape, shape):
            n, base = (name[:-2], 1) if name.endswith("+1") else (name, 0)
            origin.setdefault(n, f"'{key}'")
            if sizes.setdefault(n, size - base) != size - base:
                raise RunLogError(
                    f"{path}: damaged run log: '{key}' has shape {arr.shape}, where {origin[n]} has "
                    f"{n} = {sizes[n]}"
                )
    if "N" not in sizes:
        return
    for ids, names in (("contact_id", "contact_names"), ("limit_id", "limit_names")):
        if len(data[ids]) and not (0 <= data[ids].min() and data[ids].max() < len(data[names])):
            raise RunLogError(f"{path}: damaged run log: '{ids}' refers to entries not in '{names}'")
    for steps in ("contact_step", "limit_step"):
        if len(data[steps]) and not (0 <= data[steps].min() and data[steps].max() < sizes["N"]):
            raise RunLogError(f"{path}: damaged run log: '{steps}' refers to steps the log does not hold")


def _held(keys: tuple[str, ...], bodied: bool) -> tuple[str, ...]:
    """The ``keys`` a log holds: all of them, or (a log from before BODIES_SINCE) all but BODY_ENTRIES."""
    return keys if bodied else tuple(k for k in keys if k not in BODY_ENTRIES)


def _one_robot_sides(robot: str, scene_text: str, data: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The contact_body and contact_other of a log from before BODIES_SINCE, which is of one robot:
    each contact's force acts on it, from an obstacle of its scene or from another of its geometries."""
    obstacles = _declared_obstacles(scene_text)
    if obstacles is None:  # no scene file's log: an obstacle is what no contact has as its geometry
        obstacles = set(map(str, data["contact_obstacle"])) - set(map(str, data["contact_geometry"]))
    other = [str(o) if o in obstacles else robot for o in data["contact_obstacle"]]
    return {
        "contact_body": np.array([robot] * len(other), dtype=str),
        "contact_other": np.array(other, dtype=str),
    }


def _declared_obstacles(scene_text: str, one_robot: bool = True) -> set[str] | None:
    """The obstacles a scene file (with ``one_robot``, a one-robot scene file) declares (its [ground]
    and [[obstacles]]), or None for a text that is no such file."""
    try:
        data = tomllib.loads(scene_text)
    except tomllib.TOMLDecodeError:
        return None
    listed = data.get("obstacles", [])
    scene = "robot" in data or (not one_robot and "bodies" in data)
    if not scene or not isinstance(listed, list):
        return None
    names = {o["name"] for o in listed if isinstance(o, dict) and isinstance(o.get("name"), str)}
    return names | ({"ground"} if "ground" in data else set())


def _read_directory(path: Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The header and the chunks of a log directory, concatenated (up to the first chunk missing)."""
    try:
        header = json.loads((path / HEADER).read_text())
    except (OSError, ValueError) as err:
        raise RunLogError(f"{path}: not a gaussim run log directory (no readable {HEADER}: {err})") from err
    if not isinstance(header, dict):
        raise RunLogError(f"{path}: {HEADER}: not a JSON object")
    _check_version(
        path / HEADER, header.get("format_version"), OLDEST_VERSION["directory"], DIRECTORY_VERSION
    )
    for key, kind in (
        ("robot", str),
        ("scene_text", str),
        ("scene_path", str),
        ("complete", bool),
        ("reason", str),
    ):
        if not isinstance(header.get(key), kind):
            raise RunLogError(
                f"{path / HEADER}: '{key}' must be a {kind.__name__}, got {shown(header.get(key))}"
            )
    if not (header.get("wall_time") is None or isinstance(header["wall_time"], (int, float))):
        raise RunLogError(f"{path / HEADER}: 'wall_time' must be a number or null")
    gravity, masses = header.get("gravity"), header.get("masses")
    if not (
        gravity is None
        or isinstance(gravity, list)
        and len(gravity) == 3
        and all(_number(g) for g in gravity)
    ):
        raise RunLogError(
            f"{path / HEADER}: 'gravity' must be a list of 3 numbers or null, got {shown(gravity)}"
        )
    if not (masses is None or isinstance(masses, dict) and all(_number(m) for m in masses.values())):
        raise RunLogError(
            f"{path / HEADER}: 'masses' must map body names to numbers or be null, got {shown(masses)}"
        )
    bodies = header.get("bodies")
    if header["format_version"] >= BODIES_SINCE["directory"] and not (
        isinstance(bodies, list) and bodies and all(isinstance(b, str) for b in bodies)
    ):
        raise RunLogError(f"{path / HEADER}: 'bodies' must be a list of body names, got {shown(bodies)}")
    numbers = sorted(int(m.group(1)) for p in path.iterdir() if (m := CHUNK.fullmatch(p.name)))
    contiguous = next((k for k, n in enumerate(numbers) if n != k), len(numbers))
    chunks = [_read_npz(path / f"chunk-{k:06d}.npz") for k in range(contiguous)]
    if not chunks:
        raise RunLogError(f"{path}: the run log holds no chunk (the run stopped before its first state)")
    data = {key: np.concatenate([c[key] for c in chunks]) for key in chunks[0]}
    if not header["complete"] and contiguous < len(numbers):
        header["reason"] += f" (chunk {contiguous} is missing: the later ones are left out)"
    return header, data


def _number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)
