"""Parameter studies of a scene file: every combination of the values given to some of its fields,
each run kept (its run log and a summary of it), the summaries gathered in one table.

``gaussim sweep SCENE --vary KEY=VALUES ... [--seeds N]`` (see ``docs/sweeps.md``); from Python,
:func:`plan` then :func:`study` then :func:`table`.

A key names a field of the scene file as the file spells it (:mod:`gaussim.scenefile`):
``ground.friction``, ``contacts.friction``, ``simulation.duration``, ``options.dt`` (any field of
:class:`gaussim.Options`), ``control.kp`` and ``initial.q`` (the one-robot form), a ``[[bodies]]`` or
``[[obstacles]]`` table's field by the table's name or place (``bodies.crate.mass``,
``bodies.solo.control.kd``, ``obstacles[0].friction``, ``bilaterals[0].position``), and one element of
a list with ``[k]`` (``initial.q[2]``, ``bodies.crate.position[2]``). A field the file leaves out is
added. VALUES are TOML values separated by commas: ``1,2,4``, ``1e-3,2e-3``, ``[0, 0, 0.3],[0, 0,
0.5]``, ``pyramid,exact`` (a bare word is a string).

Seeds: with ``seeds = N`` each combination runs N times, seeds 0 to N-1, its initial state perturbed
by :func:`perturbed`: each floating base's start position moved parallel to the ground (keeping its
height above it), then every initial velocity coordinate changed, by normal draws of standard
deviations ``Noise.position`` [m] and ``Noise.velocity`` [m/s or rad/s] from
``numpy.random.default_rng(seed)``.

The output folder holds ``runs.jsonl`` (a line per finished run: its values, seed, status and summary;
a study started again skips the runs it holds, :mod:`gaussim.pool`), ``runs/ID`` (each run's log,
:class:`gaussim.runlog.RunLog`) and ``results.parquet`` (the table). A run that fails is a row whose
``status`` gives the error; the others go on.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import re
import tomllib
import traceback
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from operator import attrgetter
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from .exceptions import GaussimError, InvalidOptions, shown
from .files import atomic_path
from .options import Options, is_real
from .pool import Progress, run_all
from .runlog import ACCEPTED, RunLog, require_parquet
from .scenefile import SECTIONS, SceneSpec, load_scene, load_scene_text, shipped_scene
from .state import State

# the arrays of tables of a scene file, and the key that names an entry (bilaterals have none)
ENTRIES = {"bodies": "name", "obstacles": "name", "bilaterals": None}
# the sections of the one-robot form, which a scene of [[bodies]] gives per body
ONE_ROBOT = ("robot", "initial", "control")
RESULTS, RUNS, TABLE = "runs.jsonl", "runs", "results.parquet"
# the summary of every run (then, per free root B, free_roots: B.x, B.y, B.z, B.displacement, B.speed)
SUMMARY = (
    "steps",
    "t_end",
    "wall_time",
    "max_penetration",
    "max_kkt_residual",
    "unconverged_steps",
    "max_contact_force",
    "kinetic_energy",
)
BODY_SUMMARY = ("x", "y", "z", "displacement", "speed")
# what a record's summary was made by: raise it when summarise changes, and a resumed study summarises
# the runs it holds again, from their logs (its table would mix two summaries' columns)
SUMMARY_FORMAT = 2
_PART = re.compile(r"([^.\[\]]+)(?:\[(\d+)\])?$")
_WORD = re.compile(r"[A-Za-z_][\w.\-]*")
_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


@dataclass(frozen=True)
class Noise:
    """The perturbation of a seeded run's initial state (see the module docstring).

    Attributes:
        position: standard deviation of each free root's start position along each direction
            parallel to the ground (or the world's x-y plane without one) [m].
        velocity: standard deviation added to each initial velocity coordinate [m/s or rad/s].
    """

    position: float = 1e-3
    velocity: float = 1e-2


@dataclass(frozen=True)
class Run:
    """One run of a study: its scene (the file with the run's values set), and its seed.

    Attributes:
        values: each varied key and its value in this run, in the order the keys were given.
        seed: the perturbation's seed, or None for the scene's own initial state.
        noise: the perturbation's size (with a seed).
        text: the scene text the run loads (TOML).
        scene_path: the scene file, absolute (its folder resolves relative robot paths).
        digest: a digest of the original scene text: a study of an edited scene reruns.
        out: the study's output folder, absolute.
    """

    values: tuple[tuple[str, Any], ...]
    seed: int | None
    noise: Noise
    text: str
    scene_path: str
    digest: str
    out: str

    @property
    def key(self) -> str:
        """What identifies the run in ``runs.jsonl``: the scene, the values and the perturbation."""
        perturbation = None if self.seed is None else [self.seed, self.noise.position, self.noise.velocity]
        return json.dumps([self.digest, [list(v) for v in self.values], perturbation], default=str)

    @property
    def id(self) -> str:
        """A short name of the run (its log is ``runs/ID``)."""
        return hashlib.sha1(self.key.encode()).hexdigest()[:12]

    @property
    def label(self) -> str:
        """The run's values and seed, as a progress line shows them."""
        parts = [f"{k}={_toml_value(v)}" for k, v in self.values]
        return " ".join(parts + ([] if self.seed is None else [f"seed={self.seed}"]))


def parse_vary(text: str) -> tuple[str, list[Any]]:
    """``"KEY=VALUES"`` (``--vary``) as the key and its values (TOML values separated by commas, a bare
    word a string).

    Raises:
        InvalidOptions: no ``=``, no value, a value that is none (the field named ``--vary KEY``).
        :func:`plan` checks the key and the values against the scene.
    """
    key, equals, values = text.partition("=")
    key = key.strip()
    if not equals or not key:
        raise InvalidOptions("--vary", f"must be KEY=VALUES (e.g. ground.friction=0.2,0.5), got {text!r}")
    where = f"--vary {key}"
    tokens = _split(values, where)
    if not tokens:
        raise InvalidOptions(where, "no values given: list them after '=', separated by commas")
    return key, [_value(token, where) for token in tokens]


def _split(text: str, where: str) -> list[str]:
    """``text`` cut at its commas outside brackets, braces and quotes."""
    tokens, depth, quote, start = [], 0, "", 0
    for i, char in enumerate(text):
        if quote:
            quote = "" if char == quote and text[i - 1] != "\\" else quote
        elif char in "\"'":
            quote = char
        elif char in "[{":
            depth += 1
        elif char in "]}":
            depth -= 1
        elif char == "," and depth == 0:
            tokens.append(text[start:i])
            start = i + 1
    tokens.append(text[start:])
    tokens = [t.strip() for t in tokens]
    if tokens == [""]:
        return []
    if "" in tokens:
        raise InvalidOptions(where, f"an empty value in {text!r} (two commas, or one at an end)")
    return tokens


def _value(token: str, where: str) -> Any:
    try:
        return tomllib.loads(f"v = {token}")["v"]
    except tomllib.TOMLDecodeError:
        if _WORD.fullmatch(token):
            return token
        raise InvalidOptions(
            where, f'{token!r} is not a value: a number, true or false, a word or "text", a [list]'
        ) from None


def _same(a: Any, b: Any) -> bool:
    """Whether two values set a field alike: numbers by value (1 and 1.0 make the same run, as do
    [0, 1] and [0, 1.0]), the others by type and value (true is not 1)."""
    if is_real(a) and is_real(b):
        return bool(a == b)
    return type(a) is type(b) and a == b


def plan(
    scene: str | Path,
    vary: Mapping[str, Sequence[Any] | np.ndarray],
    out: str | Path,
    seeds: int = 0,
    noise: Noise | None = None,
) -> list[Run]:
    """The runs of a study: every combination of ``vary``'s values (a list, tuple or numpy array per
    key; the first key's values vary slowest), each with seeds 0 to ``seeds`` - 1 when ``seeds`` > 0.

    Every key and every value is checked before any run: the scene loads with each value set alone.
    The runs name the scene file and ``out`` by absolute paths: a Dask worker, which runs in a folder
    of its own, writes each log into ``out`` and resolves the scene's relative paths as here.

    Raises:
        SceneFileError: the scene file itself is malformed.
        InvalidOptions: an unknown key, a key the scene has no place for, two keys that set one field
            (two spellings of it, or a list and its element), a value not in a list, no values, a
            value twice, a value the scene refuses (the field named ``--vary KEY``), no key and no
            seeds, seeds < 0, a noise < 0 or without seeds.
    """
    scene, out = Path(scene), Path(out).absolute()
    path = shipped_scene(scene).absolute()  # a shipped scene's bare name: its file
    spec = load_scene(scene)
    data = tomllib.loads(spec.text)
    if isinstance(seeds, bool) or not isinstance(seeds, int) or seeds < 0:
        raise InvalidOptions("--seeds", f"must be an integer >= 0, got {shown(seeds)}")
    if noise is not None:
        for name in ("position", "velocity"):
            value = getattr(noise, name)
            if not (math.isfinite(value) and value >= 0):
                raise InvalidOptions(f"--{name}-noise", f"must be a finite number >= 0, got {value}")
        if not seeds:
            raise InvalidOptions("--position-noise/--velocity-noise", "perturb seeded runs: give --seeds N")
    if not vary and not seeds:  # a single run of the scene: gaussim run's, with a run log of its own
        raise InvalidOptions(
            "--vary", "nothing varies: give --vary KEY=VALUES or --seeds N (gaussim run runs a scene once)"
        )
    vary = {key: _listed(key, values) for key, values in vary.items()}
    places: dict[str, tuple[Any, ...]] = {}
    for key, values in vary.items():
        place = _place(data, key)
        _disjoint(places, key, place)
        places[key] = place
        for i, value in enumerate(values):
            if any(_same(value, other) for other in values[:i]):
                raise InvalidOptions(f"--vary {key}", f"the value {_toml_value(value)} is given twice")
            try:
                load_scene_text(_scene_text(data, [(places[key], value)], ""), scene)
            except GaussimError as err:
                raise InvalidOptions(f"--vary {key}", f"the value {_toml_value(value)}: {err}") from err
    digest = hashlib.sha1(spec.text.encode()).hexdigest()
    combinations: list[tuple[tuple[str, Any], ...]] = [()]
    for key, values in vary.items():
        combinations = [(*c, (key, v)) for c in combinations for v in values]
    runs = []
    for values in combinations:
        header = (
            f"# {scene}, with " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in values) + " (a sweep)\n"
        )
        text = _scene_text(data, [(places[k], v) for k, v in values], header) if values else spec.text
        for seed in range(seeds) if seeds else [None]:
            runs.append(Run(values, seed, noise or Noise(), text, str(path), digest, str(out)))
    return runs


def _listed(key: str, values: Any) -> list[Any]:
    """``key``'s values as a list, a numpy array's numbers as Python's (their TOML is written from
    Python's types); raises InvalidOptions naming the key for one value given bare (``0.1``, a
    string), a set (its order is not the runs') or no value."""
    if isinstance(values, np.ndarray):
        values = values.tolist()
    if isinstance(values, str | bytes) or not isinstance(values, Sequence):
        raise InvalidOptions(
            f"--vary {key}", f"needs a list of values (one value: [VALUE]), got {shown(values)}"
        )
    if not values:
        raise InvalidOptions(f"--vary {key}", "no values given")
    return [v.item() if isinstance(v, np.generic) else v for v in values]


def _place(data: dict[str, Any], key: str) -> tuple[Any, ...]:
    """Where ``key`` sits in a scene's data: (section, entry index or None, [subtable,] field, element
    index or None); raises InvalidOptions naming the key, with the known choices."""
    where = f"--vary {key}"
    parts = [_PART.fullmatch(p) for p in key.split(".")]
    if not all(parts):
        raise InvalidOptions(where, "must be dotted names, e.g. ground.friction or bodies.crate.mass")
    names: list[tuple[str, int | None]] = [(m[1], None if m[2] is None else int(m[2])) for m in parts]  # type: ignore[index]
    section, index = names.pop(0)
    if section not in SECTIONS:
        options = {f.name for f in fields(Options)}
        hint = f"; did you mean options.{section}?" if section in options else ""
        raise InvalidOptions(
            where, f"unknown section {section!r}; known: {', '.join(sorted(SECTIONS))}{hint}"
        )
    if section in ONE_ROBOT and "bodies" in data:
        raise InvalidOptions(
            where,
            "this scene is of [[bodies]]: give a body's field as bodies.NAME.FIELD (bodies.NAME.control.kp)",
        )
    entry: int | None = None
    if section in ENTRIES:
        entry = _entry(data, section, index, names, where)
    elif index is not None:
        raise InvalidOptions(where, f"[{section}] is a table, not an array of tables")
    table = section
    subtable: tuple[str, ...] = ()
    if section == "bodies" and len(names) == 2 and names[0] == ("control", None):
        table, subtable = "control", ("control",)
        names.pop(0)
    if len(names) != 1:
        raise InvalidOptions(where, f"give one field of [{section}] after it; known: {_known(table)}")
    field, element = names[0]
    if field not in SECTIONS[table]:
        raise InvalidOptions(where, f"unknown field {field!r} of [{table}]; known: {_known(table)}")
    if field == "name" and section in ENTRIES:
        raise InvalidOptions(where, "a table's name says which it is: vary its other fields")
    if field == "control" and not subtable:
        raise InvalidOptions(where, f"give a field of the body's control; known: {_known('control')}")
    place = (section, entry, *subtable, field, element)
    if element is not None:
        current = _container(data, place).get(field)
        if not (isinstance(current, list) and element < len(current)):
            what = (
                f"the scene gives no {field}"
                if current is None
                else f"the scene's {field} is {shown(current)}"
            )
            raise InvalidOptions(where, f"{what}: it has no element [{element}] to vary")
    return place


def _disjoint(places: Mapping[str, tuple[Any, ...]], key: str, place: tuple[Any, ...]) -> None:
    """Raise InvalidOptions when ``key`` sets a field (or an element of it) that a key of ``places``
    sets: two spellings of one field (``bodies[1].mass``, ``bodies.crate.mass``) or a list and its
    element. The later key's value would replace the earlier's in every run, and the table would
    record for the earlier key a value that no run used."""
    for other, earlier in places.items():
        if earlier == place:
            raise InvalidOptions(f"--vary {key}", f"sets the field --vary {other} sets: give it one --vary")
        if earlier[:-1] == place[:-1] and None in (earlier[-1], place[-1]):
            raise InvalidOptions(
                f"--vary {key}",
                f"overlaps --vary {other} (a list and one of its elements): vary the one or the other",
            )


def _entry(data: dict[str, Any], section: str, index: int | None, names: list, where: str) -> int:
    """The index of the ``[[section]]`` table a key addresses: its ``[index]``, or its name (the
    key's next part, popped from ``names``)."""
    listed = data.get(section, [])
    named = ENTRIES[section]
    if index is not None:
        if index >= len(listed):
            raise InvalidOptions(where, f"the scene has {len(listed)} [[{section}]] tables (from [0])")
        return index
    tables = {t.get(named): i for i, t in enumerate(listed) if named is not None}
    if named is None or not names:
        raise InvalidOptions(
            where, f"say which [[{section}]] table: {section}[i]" + (f" or {section}.NAME" if named else "")
        )
    name, element = names.pop(0)
    if name not in tables or element is not None:
        raise InvalidOptions(
            where,
            f"no [[{section}]] table named {name!r}; the scene's: {', '.join(map(str, tables)) or 'none'}",
        )
    return tables[name]


def _known(table: str) -> str:
    return ", ".join(sorted(SECTIONS[table]))


def _container(data: dict[str, Any], place: tuple[Any, ...]) -> dict[str, Any]:
    """The table of ``data`` that holds the field at ``place`` (made when missing)."""
    section, entry, *subtable, _field, _element = place
    table = data.setdefault(section, {}) if entry is None else data[section][entry]
    for name in subtable:
        table = table.setdefault(name, {})
    return table


def _scene_text(data: dict[str, Any], settings: list[tuple[tuple[Any, ...], Any]], header: str) -> str:
    """The TOML text of ``data`` with each (place, value) of ``settings`` set."""
    data = copy.deepcopy(data)
    for place, value in settings:
        table, field, element = _container(data, place), place[-2], place[-1]
        if element is None:
            table[field] = value
        else:
            table[field][element] = value
    return header + to_toml(data)


def to_toml(data: Mapping[str, Any]) -> str:
    """TOML text of ``data`` (the types ``tomllib`` reads, but dates): ``tomllib.loads`` returns it."""
    lines: list[str] = []
    _toml_table(lines, data, ())
    return "\n".join(lines).lstrip("\n") + "\n"


def _toml_table(lines: list[str], table: Mapping[str, Any], prefix: tuple[str, ...]) -> None:
    nested = {k: v for k, v in table.items() if isinstance(v, dict) or _tables(v)}
    lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in table.items() if k not in nested]
    for k, v in nested.items():
        name = ".".join(map(_toml_key, (*prefix, k)))
        for entry in [v] if isinstance(v, dict) else v:
            lines += ["", f"[{name}]" if isinstance(v, dict) else f"[[{name}]]"]
            _toml_table(lines, entry, (*prefix, k))


def _tables(value: Any) -> bool:
    """True for an array of tables (a TOML [[...]])."""
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)


def _toml_key(key: str) -> str:
    return key if _BARE_KEY.fullmatch(key) else _toml_string(key)


def _toml_string(text: str) -> str:
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")  # TOML escapes DEL, JSON not


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else {math.inf: "inf", -math.inf: "-inf"}.get(value, "nan")
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, list):
        return "[" + ", ".join(map(_toml_value, value)) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"no TOML form for {type(value).__name__}")


def perturbed(spec: SceneSpec, seed: int, noise: Noise) -> State:
    """``spec``'s initial state perturbed by ``seed``: each free root's position moved parallel to
    the ground (the first [ground]'s plane, else the world's x-y plane: a normal draw in 3D with its
    component along the plane's normal removed), body by body, then every velocity coordinate changed,
    drawn from ``numpy.random.default_rng(seed)`` with standard deviations ``noise.position`` [m] (per
    direction in the plane) and ``noise.velocity`` [m/s or rad/s]. A body moved this way keeps its
    height above the ground."""
    from .scene import Ground

    rng = np.random.default_rng(seed)
    grounds = [o for o in spec.scene.obstacles if isinstance(o, Ground)]
    n = np.asarray(grounds[0].normal if grounds else (0.0, 0.0, 1.0))  # a unit normal
    q, v = spec.initial.q.copy(), spec.initial.v.copy()
    for root in free_roots(spec):
        shift = rng.normal(0.0, noise.position, 3)
        q[root.q : root.q + 3] += shift - (shift @ n) * n
    v += rng.normal(0.0, noise.velocity, v.shape)
    return State(spec.initial.t, q, v, spec.initial.world)


class FreeRoot(NamedTuple):
    """A free root of a scene: its summary columns' name, and its first indices in the world's q and v."""

    name: str
    q: int
    v: int


def free_roots(spec: SceneSpec) -> list[FreeRoot]:
    """The scene's free roots (:class:`gaussim.dynamics.FloatingBases`: each free-flyer joint hung from
    the world, a floating base or each box of robots/box_stack.urdf), body by body in the scene's
    order; each named by its body, or ``BODY.JOINT`` in a body of several (``box_stack.top_joint``)."""
    from .dynamics import FloatingBases

    roots = []
    for body, layout in spec.scene.bodies.items():
        model = layout.robot.model
        bases = FloatingBases.of(model)
        joints = np.flatnonzero(bases.of_joint >= 0)  # in the order of bases.configuration
        for joint, q, v in zip(joints.tolist(), bases.configuration.tolist(), bases.velocity.tolist()):
            name = body if len(bases) == 1 else f"{body}.{model.names[joint]}"
            roots.append(FreeRoot(name, layout.q.start + q, layout.v.start + v))
    return roots


def summarise(log: RunLog, spec: SceneSpec) -> dict[str, float]:
    """A run's numbers: SUMMARY (steps, simulated end time [s], wall time [s], deepest penetration
    [m], largest KKT residual, steps whose QP did not converge, largest contact force [N], final
    kinetic energy [J]), then for each free root B (:func:`free_roots`) its final position ``B.x``,
    ``B.y``, ``B.z`` [m], its distance from its start ``B.displacement`` [m] and its final speed
    ``B.speed`` [m/s]."""
    import pinocchio as pin

    c, s = log.contact_arrays(), log.solver_arrays()
    q, v = log.q[-1], log.v[-1]
    model = spec.robot.model
    summary = {
        "steps": float(log.steps),
        "t_end": float(log.t[-1]),
        "wall_time": float(log.wall_time or math.nan),
        "max_penetration": float(max(0.0, -c["gap"].min())) if len(c["gap"]) else 0.0,
        "max_kkt_residual": float(s["kkt_residual"].max()) if log.steps else 0.0,
        "unconverged_steps": float(np.sum(~np.isin(s["status"], ACCEPTED))),
        "max_contact_force": float(np.linalg.norm(c["force"], axis=1).max()) if len(c["gap"]) else 0.0,
        "kinetic_energy": float(pin.computeKineticEnergy(model, model.createData(), q, v)),
    }
    for root in free_roots(spec):
        start, end = log.q[0][root.q : root.q + 3], q[root.q : root.q + 3]
        summary.update({f"{root.name}.{axis}": float(x) for axis, x in zip("xyz", end)})
        summary[f"{root.name}.displacement"] = float(np.linalg.norm(end - start))
        summary[f"{root.name}.speed"] = float(np.linalg.norm(v[root.v : root.v + 3]))
    return summary


def summary_columns(spec: SceneSpec) -> list[str]:
    """The summary's columns for a scene (those of :func:`summarise`)."""
    return [*SUMMARY, *(f"{root.name}.{c}" for root in free_roots(spec) for c in BODY_SUMMARY)]


def run_one(run: Run) -> dict:
    """Simulate one run into its log (``OUT/runs/ID``); its record: its key, id, values, seed,
    "ok" or the error that stopped it, what weakens its accuracy (:meth:`RunLog.warnings`) and its
    summary (:func:`summarise`). A KeyboardInterrupt is not caught: the run is not recorded."""
    from .runner import run as simulate

    log_path = Path(run.out) / RUNS / run.id
    record: dict[str, Any] = {
        "key": run.key,
        "run": run.id,
        "values": [list(v) for v in run.values],
        "seed": run.seed,
        "log": str(Path(RUNS) / run.id),
    }
    try:
        spec = load_scene_text(run.text, run.scene_path)
        if run.seed is not None:
            spec.initial = perturbed(spec, run.seed, run.noise)
        log = simulate(spec, log_path)
        record.update(status="ok", warnings="; ".join(log.warnings()), summary=summarise(log, spec))
        record["summary_format"] = SUMMARY_FORMAT
    except Exception as err:  # a failing run is a result: it is recorded and the study goes on
        record.update(status=f"{type(err).__name__}: {err}", warnings="", summary={})
        record["traceback"] = traceback.format_exc(limit=3)
    return record


def study(
    runs: Sequence[Run],
    out: str | Path,
    workers: int | None = None,
    scheduler: Any = None,
    progress: Progress | None = None,
) -> list[dict]:
    """Run the ``runs`` not already finished in ``out`` (:func:`gaussim.pool.run_all`: a local process
    pool of ``workers``, or the Dask cluster at ``scheduler``); return the records of ``runs``.

    Raises:
        InvalidOptions: a run was planned for another folder (its log would land outside ``out``)."""
    folder = Path(out).absolute()
    elsewhere = sorted({str(r.out) for r in runs if Path(r.out).resolve() != folder.resolve()})
    if elsewhere:
        raise InvalidOptions(
            "out", f"{folder}: the runs were planned for {', '.join(elsewhere)}: give plan() the same folder"
        )
    return run_all(
        runs, attrgetter("key"), run_one, folder / RESULTS, workers, scheduler, progress, resummarised
    )


def resummarised(run: Run, record: dict) -> dict | None:
    """A finished run's record summarised again from its log when an older gaussim summarised it
    (``summary_format``, SUMMARY_FORMAT), else None; None too when its log cannot be read (the
    record, whose summary is the old one, stands)."""
    if record.get("status") != "ok" or record.get("summary_format") == SUMMARY_FORMAT:
        return None
    try:
        log = RunLog.load(Path(run.out) / record["log"])
        summary = summarise(log, load_scene_text(run.text, run.scene_path))
    except (GaussimError, OSError, KeyError, ValueError):
        return None
    return {**record, "summary": summary, "summary_format": SUMMARY_FORMAT}


def rows(records: Sequence[dict]) -> list[dict[str, Any]]:
    """One flat dict per record: the varied keys' values, ``seed``, ``status``, the summary,
    ``warnings``, ``run`` (its id) and ``log`` (its log, relative to the output folder)."""
    flat = []
    for r in records:
        row: dict[str, Any] = dict(r["values"])
        row.update(seed=r["seed"], status=r["status"], **r["summary"], warnings=r["warnings"])
        row.update(run=r["run"], log=r["log"])
        flat.append(row)
    return flat


def require_table() -> None:
    """Raise GaussimError, with the install command, unless pandas and pyarrow are installed."""
    require_parquet("a sweep's table")


def table(records: Sequence[dict]):  # type: ignore[no-untyped-def]
    """The records as a pandas DataFrame, a row per run (columns: :func:`rows`); a column whose values
    Parquet cannot hold together (numbers and words) is kept as text."""
    require_table()
    import pandas as pd

    frame = pd.DataFrame(rows(records))
    for column in frame.columns:
        kinds = {type(x) for x in frame[column] if x is not None}
        if len(kinds - {int, float}) > 1 or (kinds & {int, float} and kinds - {int, float}):
            frame[column] = frame[column].map(lambda x: None if x is None else _toml_value(x))
    return frame


def write_table(records: Sequence[dict], out: str | Path) -> Path:
    """Write the records' table to ``OUT/results.parquet`` (atomically); its path."""
    path = Path(out) / TABLE
    frame = table(records)
    with atomic_path(path) as tmp:
        frame.to_parquet(tmp, index=False)
    return path
