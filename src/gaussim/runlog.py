"""Run logs: everything a run produced, saved atomically as a compressed ``.npz`` (no pickle).

A log holds t, q, v (N + 1 states), tau (N steps), the per-contact forces, points, normals and gaps
of each step, the limit reactions, the solver certificate of each step, the scene text and the
options: a run can be reproduced and analysed from its log alone. A run that stops early (Ctrl-C,
a solver failure) still writes a valid log of the steps it made, marked incomplete with the reason.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any

import numpy as np

from .exceptions import GaussimError, InvalidOptions, shown
from .options import Options
from .report import StepReport
from .solver import CONVERGED
from .state import State

FORMAT_VERSION = 1
# A run whose contacts sink deeper than this is flagged by its summary [m] (the velocity scheme closes an
# approach exactly and rests within g dt^2 of the surface: a deeper penetration is lost accuracy)
PENETRATION_TOLERANCE = 1e-3
# what each array of a log holds: its numpy kinds (b bool, i int, f float, U text) and its shape, in
# the sizes N (steps), nq, nv, C (contact rows), K (contact names), L (limit rows), J (limit names)
LAYOUT: dict[str, tuple[str, tuple[str, ...]]] = {
    "format_version": ("i", ()),
    "robot": ("U", ()),
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
# A step's status when its QPs converged but its friction fixed point did not (friction_unsettled).
FRICTION_UNSETTLED = "FRICTION_UNSETTLED"


class RunLogError(GaussimError):
    """A file is not a gaussim run log (or a damaged one)."""


class RunLog:
    """A run being recorded, or loaded from a file.

    Attributes:
        t: times [s], shape (N + 1,).
        q, v: states, shapes (N + 1, nq), (N + 1, nv).
        tau: torques applied during each step, shape (N, nv).
        complete: False when the run stopped before its duration; ``reason`` says why.
        scene_text, options: what the run was made from.
    """

    def __init__(self, robot: str, scene_text: str, options: Options, scene_path: str = "") -> None:
        self.robot, self.scene_text, self.options, self.scene_path = robot, scene_text, options, scene_path
        self.complete, self.reason = False, "not finished"
        self.wall_time: float | None = None
        self._t: list[float] = []
        self._q: list[np.ndarray] = []
        self._v: list[np.ndarray] = []
        self._tau: list[np.ndarray] = []
        self._solver: list[tuple[int, int, float, str]] = []  # qps, iterations, kkt residual, status
        self._contacts: list[tuple[int, int, np.ndarray, np.ndarray, np.ndarray, float]] = []
        self._limits: list[tuple[int, int, float]] = []
        self.contact_names: list[str] = []
        self.contact_geometry: list[str] = []
        self.contact_obstacle: list[str] = []
        self.limit_names: list[str] = []
        self._ids: dict[str, int] = {}
        self._limit_ids: dict[str, int] = {}

    # -- recording ---------------------------------------------------------------------------------

    def start(self, state: State) -> None:
        self._append_state(state)

    def record(self, state: State, tau: np.ndarray, report: StepReport) -> None:
        """Add the step that led to ``state`` under torque ``tau`` (nv,) and its report."""
        step = len(self._tau)
        self._append_state(state)
        self._tau.append(np.asarray(tau, dtype=float))
        statuses = [c.status for c in report.certificates]
        worst = next((s for s in statuses if s not in CONVERGED), statuses[0] if statuses else "NO_QP")
        if worst in CONVERGED and report.friction_unsettled:
            worst = FRICTION_UNSETTLED
        self._solver.append((len(statuses), report.iterations, report.max_residual, worst))
        for c in report.contacts:
            if c.name not in self._ids:
                self._ids[c.name] = len(self.contact_names)
                self.contact_names.append(c.name)
                self.contact_geometry.append(c.geometry)
                self.contact_obstacle.append(c.obstacle)
            self._contacts.append((step, self._ids[c.name], c.point, c.normal, c.force, c.gap))
        for r in report.limits:
            key = f"{r.joint} {r.side}"
            if key not in self._limit_ids:
                self._limit_ids[key] = len(self.limit_names)
                self.limit_names.append(key)
            self._limits.append((step, self._limit_ids[key], r.torque))

    def _append_state(self, state: State) -> None:
        self._t.append(state.t)
        self._q.append(state.q)
        self._v.append(state.v)

    def finish(self, complete: bool, reason: str = "") -> None:
        self.complete, self.reason = complete, reason

    # -- arrays --------------------------------------------------------------------------------------

    @property
    def steps(self) -> int:
        return len(self._tau)

    @property
    def t(self) -> np.ndarray:
        return np.array(self._t)

    @property
    def q(self) -> np.ndarray:
        return np.array(self._q)

    @property
    def v(self) -> np.ndarray:
        return np.array(self._v)

    @property
    def tau(self) -> np.ndarray:
        return np.array(self._tau).reshape(len(self._tau), len(self._v[0]) if self._v else 0)

    def contact_arrays(self) -> dict[str, np.ndarray]:
        """Per (step, contact) rows: step, contact id, point (3), normal (3), force (3), gap."""
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
        return {
            "qps": np.array([s[0] for s in self._solver], dtype=int),
            "iterations": np.array([s[1] for s in self._solver], dtype=int),
            "kkt_residual": np.array([s[2] for s in self._solver], dtype=float),
            "status": np.array([s[3] for s in self._solver], dtype=str),
        }

    # -- files -----------------------------------------------------------------------------------------

    def save(self, path: str | Path) -> Path:
        """Write the log atomically: a half-written file never replaces a good one."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        contacts, solver = self.contact_arrays(), self.solver_arrays()
        arrays: dict[str, Any] = {
            "format_version": np.array(FORMAT_VERSION),
            "robot": np.array(self.robot),
            "scene_text": np.array(self.scene_text),
            "scene_path": np.array(self.scene_path),
            "options": np.array(json.dumps(asdict(self.options))),
            "complete": np.array(self.complete),
            "reason": np.array(self.reason),
            "wall_time": np.array(np.nan if self.wall_time is None else self.wall_time),
            "t": self.t,
            "q": self.q,
            "v": self.v,
            "tau": self.tau,
            "contact_names": np.array(self.contact_names, dtype=str),
            "contact_geometry": np.array(self.contact_geometry, dtype=str),
            "contact_obstacle": np.array(self.contact_obstacle, dtype=str),
            "limit_names": np.array(self.limit_names, dtype=str),
            "limit_step": np.array([r[0] for r in self._limits], dtype=int),
            "limit_id": np.array([r[1] for r in self._limits], dtype=int),
            "limit_torque": np.array([r[2] for r in self._limits], dtype=float),
            **{f"contact_{k}": v for k, v in contacts.items()},
            **{f"solver_{k}": v for k, v in solver.items()},
        }
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        try:
            os.chmod(fd, 0o666 & ~_umask())  # mkstemp's 0600, where every other output follows the umask
            with os.fdopen(fd, "wb") as f:
                np.savez_compressed(f, **arrays)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return path

    @classmethod
    def load(cls, path: str | Path) -> RunLog:
        """Read a log written by :meth:`save`.

        Raises:
            RunLogError: the file is not a run log, a damaged or tampered one (the message names the
                file and the array), or one of a newer format.
        """
        data = _read(Path(path))
        try:
            options = Options(**json.loads(str(data["options"])))
        except json.JSONDecodeError as err:
            raise RunLogError(f"{path}: options: not JSON ({err})") from err
        except TypeError as err:  # not a dict, or an option this gaussim does not have
            known = ", ".join(f.name for f in fields(Options))
            raise RunLogError(
                f"{path}: options: must be a JSON object of Options fields ({known}), "
                f"got {shown(str(data['options']))}"
            ) from err
        except InvalidOptions as err:
            raise RunLogError(f"{path}: options.{err}") from err
        log = cls(str(data["robot"]), str(data["scene_text"]), options)
        log.scene_path = str(data["scene_path"])
        log.complete, log.reason = bool(data["complete"]), str(data["reason"])
        log.wall_time = None if np.isnan(data["wall_time"]) else float(data["wall_time"])
        log._t, log._q, log._v = list(data["t"]), list(data["q"]), list(data["v"])
        log._tau = list(data["tau"])
        log.contact_names = list(map(str, data["contact_names"]))
        log.contact_geometry = list(map(str, data["contact_geometry"]))
        log.contact_obstacle = list(map(str, data["contact_obstacle"]))
        log.limit_names = list(map(str, data["limit_names"]))
        log._contacts = list(
            zip(
                data["contact_step"].tolist(),
                data["contact_id"].tolist(),
                data["contact_point"],
                data["contact_normal"],
                data["contact_force"],
                data["contact_gap"].tolist(),
            )
        )
        log._limits = list(
            zip(data["limit_step"].tolist(), data["limit_id"].tolist(), data["limit_torque"].tolist())
        )
        log._solver = list(
            zip(
                data["solver_qps"].tolist(),
                data["solver_iterations"].tolist(),
                data["solver_kkt_residual"].tolist(),
                data["solver_status"].tolist(),
            )
        )
        return log

    # -- analysis --------------------------------------------------------------------------------------

    def contact_records(self) -> dict[str, list]:
        """Per-contact force time series as columns: t, contact, geometry, obstacle, point, normal,
        force and gap (x, y, z split) — what :meth:`contact_forces` and the CSV export hold."""
        c = self.contact_arrays()
        t = self.t
        columns: dict[str, list] = {
            "t": t[c["step"] + 1].tolist(),
            "contact": [self.contact_names[i] for i in c["id"]],
            "geometry": [self.contact_geometry[i] for i in c["id"]],
            "obstacle": [self.contact_obstacle[i] for i in c["id"]],
        }
        for name in ("point", "normal", "force"):
            for axis, column in zip("xyz", c[name].T):
                columns[f"{name}_{axis}"] = column.tolist()
        columns["gap"] = c["gap"].tolist()
        return columns

    def contact_forces(self):  # type: ignore[no-untyped-def]
        """The per-contact time series as a pandas DataFrame (``pip install pandas``)."""
        try:
            import pandas as pd
        except ImportError as err:
            raise GaussimError("contact_forces() needs pandas: pip install 'gaussim[analysis]'") from err
        return pd.DataFrame(self.contact_records())

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
        failed = int(np.sum(~np.isin(s["status"], [*CONVERGED, "NO_QP"])))
        if failed:
            found.append(
                f"{failed} steps did not converge (max KKT residual {s['kkt_residual'].max():.2e}, "
                f"eps_abs = {o.eps_abs:g}): on_failure = '{o.on_failure}' kept their iterates, which need "
                "not be the Gauss principle's motion"
            )
        return found

    def summary(self) -> str:
        """A plain-text summary: run, solver and per-contact force statistics, and a WARNING line for
        each of :meth:`warnings`."""
        c, s = self.contact_arrays(), self.solver_arrays()
        wall_time = self.wall_time
        failed = int(np.sum(~np.isin(s["status"], [*CONVERGED, "NO_QP"])))
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
            lines.append("")
            lines.append(
                f"{'contact':<30} {'steps':>6} {'mean fn [N]':>12} {'max fn [N]':>11}"
                f" {'max |ft|/fn':>12} {'min gap [mm]':>13}"
            )
            for i, name in enumerate(self.contact_names):
                mine = c["id"] == i
                fn = np.einsum("ij,ij->i", c["force"][mine], c["normal"][mine])
                ft = np.linalg.norm(c["force"][mine] - fn[:, None] * c["normal"][mine], axis=1)
                ratio = np.max(np.where(fn > 1e-9, ft / np.maximum(fn, 1e-300), 0.0))
                lines.append(
                    f"{name:<30} {int(mine.sum()):>6} {fn.mean():>12.3f} {fn.max():>11.3f} {ratio:>12.3f}"
                    f" {1e3 * c['gap'][mine].min():>13.4f}"
                )
        return "\n".join(lines)


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _read(path: Path) -> dict[str, np.ndarray]:
    """The arrays of the run log at ``path``, each checked against LAYOUT and the others' sizes."""
    try:
        archive = np.load(path, allow_pickle=False)
        if not isinstance(archive, np.lib.npyio.NpzFile):
            raise RunLogError(f"{path}: not a gaussim run log (a single .npy array, not a .npz archive)")
        with archive as f:
            data = {k: f[k] for k in f.files}
    except RunLogError:
        raise
    except OSError as err:
        raise RunLogError(f"{path}: cannot read it: {err.strerror or err}") from err
    except (
        ValueError
    ) as err:  # not numpy's words: they advise allow_pickle=True, which runs what a file holds
        raise RunLogError(f"{path}: not a gaussim run log (one is a .npz archive of plain arrays)") from err
    except Exception as err:  # zipfile reads a damaged archive's bytes as anything: encryption, a method
        what = f"{type(err).__name__}: {err}"
        raise RunLogError(f"{path}: a truncated or damaged .npz archive ({what})") from err
    if "format_version" not in data:
        raise RunLogError(f"{path}: not a gaussim run log (no format_version)")
    version = data["format_version"]
    if version.shape != () or version.dtype.kind != "i" or not 1 <= int(version) <= FORMAT_VERSION:
        newer = version.shape == () and version.dtype.kind == "i" and int(version) > FORMAT_VERSION
        raise RunLogError(
            f"{path}: format_version {shown(version.tolist())} is "
            + ("newer than this gaussim reads" if newer else "unknown")
            + f" (it reads format {FORMAT_VERSION})"
            + ("; upgrade gaussim" if newer else "")
        )
    sizes: dict[str, int] = {"3": 3}
    origin = {"3": "a point"}  # the array each size was read from
    for key, (kind, shape) in LAYOUT.items():
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
    for ids, names in (("contact_id", "contact_names"), ("limit_id", "limit_names")):
        if len(data[ids]) and not (0 <= data[ids].min() and data[ids].max() < len(data[names])):
            raise RunLogError(f"{path}: damaged run log: '{ids}' refers to entries not in '{names}'")
    for steps in ("contact_step", "limit_step"):
        if len(data[steps]) and not (0 <= data[steps].min() and data[steps].max() < sizes["N"]):
            raise RunLogError(f"{path}: damaged run log: '{steps}' refers to steps the log does not hold")
    return data
