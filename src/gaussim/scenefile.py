"""Scene files: a TOML description of what to simulate, validated with errors that name the key.

One robot:
    [robot]        name = "solo12" | urdf | mjcf | sdf = "path", package_dirs = [...], floating_base = bool
    [initial]      configuration = "standing" | q = [...];  v = [...];  ground_clearance = 0.01
    [control]      type = "zero" | "constant" (tau = [...]) | "pd" (target = name | [...], kp, kd)
or several bodies, one table each (in place of [robot], [initial] and [control]):
    [[bodies]]     name; robot = "solo12" | urdf | mjcf | sdf = "path" (package_dirs, floating for
                   a URDF, body: a top-level body of an MJCF) | shape = "box" (size = [x, y, z]) |
                   "sphere" (radius) | "cylinder" | "capsule" (radius, length) | "mesh" (path, scale)
                   with mass or density;
                   position, rpy: a floating body's start pose, a fixed-base robot's placement;
                   configuration = name | [...] (nq_b), velocity = [...] (nv_b), ground_clearance;
                   self_collision, friction, restitution, contype, conaffinity, color = [r, g, b, a]
    [bodies.control]  as [control], for the body it follows (its own joints)
                   (the other sections then name frames and geometries "body/name": "solo/FL_FOOT_0")
then:
    [ground]       friction, restitution, height, normal
    [[obstacles]]  type = "box" | "sphere", name, size | radius, position, rpy, friction, restitution
    [contacts]     pairs = [["FL_FOOT_0", "ground"], ["a_0", "b_0"], ["solo/*", "crate"], ...]
                   (default "auto": see gaussim.Scene); friction, restitution: of the pairs of two
                   geometries where neither side declares a material
    [limits]       enabled = true
    [joint_friction] enabled = true  (the joints' damping and dry friction of the robot files)
    [[bilaterals]] type = "anchor", frame, position, rpy  |  type = "loop", frames = [a, b], orientation
    [simulation]   duration = 2.0
    [options]      any field of gaussim.Options (dt, scheme, friction_mode, ...)

Relative paths are taken from the scene file's folder. Unknown keys are errors. A robot in place of a
scene file (a URDF, MJCF or SDF path, or a robot's name) runs in the scene :func:`robot_scene_text`
writes for it.
"""

from __future__ import annotations

import json
import os
import re
import tomllib
import warnings
from dataclasses import dataclass, fields
from difflib import get_close_matches
from functools import partial
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import pinocchio as pin

from .control import Command, Controller, PDHold, command, constant_torque, zero_torque
from .dynamics import FloatingBases
from .exceptions import GaussimError, InvalidOptions, InvalidRobot, finite_numbers, missing_file, shown
from .options import Options, is_real
from .robot import ROBOTS_DIR, SUFFIXES, Robot, example_robot_names, load_robot
from .scene import Anchor, Box, Ground, LoopClosure, Scene, Sphere
from .state import BodyState, State
from .world import SHAPES, Body, FreeBody, Material, World, pose

# the keys each type of a [control] or [[bilaterals]] table reads (the others are refused, not ignored)
TYPE_KEYS = {
    "control": {"zero": (), "constant": ("tau",), "pd": ("target", "kp", "kd", "implicit")},
    "bilaterals": {"anchor": ("frame", "position", "rpy"), "loop": ("frames", "orientation")},
}
SECTIONS = {
    "robot": {"name", "urdf", "mjcf", "sdf", "package_dirs", "floating_base"},
    "bodies": {
        "name",
        "robot",
        "urdf",
        "mjcf",
        "sdf",
        "package_dirs",
        "floating",
        "body",
        "shape",
        "size",
        "radius",
        "length",
        "path",
        "scale",
        "mass",
        "density",
        "position",
        "rpy",
        "configuration",
        "velocity",
        "ground_clearance",
        "self_collision",
        "friction",
        "restitution",
        "contype",
        "conaffinity",
        "color",
        "control",
    },
    "initial": {"configuration", "q", "v", "ground_clearance"},
    "ground": {"friction", "restitution", "height", "normal"},
    "obstacles": {"type", "name", "size", "radius", "position", "rpy", "friction", "restitution"},
    "contacts": {"pairs", "friction", "restitution"},
    "limits": {"enabled"},
    "joint_friction": {"enabled"},
    **{
        table: {"type", *(key for keys in types.values() for key in keys)}
        for table, types in TYPE_KEYS.items()
    },
    "simulation": {"duration"},
    "options": {f.name for f in fields(Options)},
}
# what a body is made from: a robot (by name or file) or a shape
ROBOT_SOURCES = ("robot", "urdf", "mjcf", "sdf")
# the dimensions each shape takes (the first ones required)
SHAPE_DIMENSIONS = {
    "box": ("size",),
    "sphere": ("radius",),
    "cylinder": ("radius", "length"),
    "capsule": ("radius", "length"),
    "mesh": ("path", "scale"),
}
# the keys of a [[bodies]] table that only a robot, or only a shape, takes
ROBOT_KEYS = ("package_dirs", "floating", "body")
SHAPE_KEYS = ("size", "radius", "length", "path", "scale", "mass", "density")
# The largest joint torque a scene may command [N m] (Talos's strongest joint gives 300): beyond it the
# QP's rows span hundreds of orders of magnitude and ProxQP stops without a motion (tau = 1e300)
MAX_TORQUE = 1e6
# robots already loaded, by (source, floating_base) as a [robot] table gives them
Loaded = dict[tuple[str, bool | None], Robot]
# where a field a Scene names (its constructor's argument) sits in a scene file
SCENE_FIELDS = {"contacts": "contacts.pairs", "self_contact": "contacts"}
# The scene of a robot run by itself: it starts this high above the ground [m] from its first named
# configuration of these (else its first, else neutral), held there by a PD posture hold of gains per
# kilogram of robot (at least 1 kg) [N m/rad], [N m s/rad], for this long [s].
ROBOT_CLEARANCE = 0.01
START_CONFIGURATIONS = ("standing", "half_sitting")
HOLD_KP_PER_KG, HOLD_KD_PER_KG = 20.0, 0.5
ROBOT_DURATION = 2.0
# A body is placed at its clearance above the ground again from nearer, up to this many times, until
# within this [m] of it.
PLACEMENTS, PLACED = 3, 1e-9


def start_configuration(robot: Robot) -> str:
    """The configuration a robot run by itself starts from: its first named one of
    START_CONFIGURATIONS, else its first, else neutral."""
    named = robot.reference_configurations
    return next((n for n in (*START_CONFIGURATIONS, *named) if n in named), "neutral")


class SceneFileError(InvalidOptions):
    """A scene file is malformed; the message starts with ``file: key:``."""

    def __init__(self, path: Path | str, key: str, message: str) -> None:
        super().__init__(f"{path}: {key}", message)


@dataclass
class SceneSpec:
    """Everything a scene file declares, built and validated.

    Attributes:
        path: the scene file.
        text: its text (stored in run logs, so that a run can be reproduced).
        scene: the bodies and their constraints.
        options: the step options.
        initial: the initial state of every body (``initial.body("crate")``).
        controller: joint torques as a function of the state (per body: ``{body: tau_b}``).
        duration: simulated time [s].
    """

    path: Path
    text: str
    scene: Scene
    options: Options
    initial: State
    controller: Controller
    duration: float

    @property
    def robot(self) -> Robot:
        return self.scene.robot


@dataclass
class _BodyEntry:
    """A [[bodies]] table read: its body, and what its initial state and control take from it."""

    key: str
    name: str
    body: Body
    section: dict[str, Any]
    position: np.ndarray | None
    rpy: np.ndarray | None


def load_scene(path: str | Path, **overrides: Any) -> SceneSpec:
    """Read and validate a scene file, or the shipped scene a bare name names (:func:`shipped_scene`);
    ``overrides`` replace fields of its ``[options]`` (e.g. dt=1e-4).

    Raises:
        SceneFileError: unreadable TOML, unknown key, wrong type or value (names file and key).
        GaussimError: an unknown robot, frame or geometry (the message lists the valid names).
    """
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidOptions(
            "path", f"must be a scene file's path or a shipped scene's name, got {shown(path)}"
        )
    path = Path(path)
    if names_robot(path):
        text, robot, source = _robot_scene(str(path))
        return _read(text, path, overrides, {source: robot})  # the robot is loaded once
    path = shipped_scene(path)
    try:
        raw = path.read_bytes()
    except OSError as err:
        from .runlog import is_run_log

        if is_run_log(path):  # the commands that read a log would be the user's next try
            raise SceneFileError(
                path,
                "file",
                f"a run log, not a scene file: `gaussim inspect {path}` shows it and the scene it was made "
                "from; gaussim replay, plot and forces read it",
            ) from err
        scenes = sorted(p.stem for p in (ROBOTS_DIR / "scenes").glob("*.toml"))
        close = get_close_matches(str(path), [*scenes, *example_robot_names()], n=3)
        meant = f"did you mean {' or '.join(close)}? " if close and path.parent == Path() else ""
        raise SceneFileError(
            path,
            "file",
            f"cannot read it: {err.strerror} ({meant}shipped scenes: {', '.join(scenes)}; or a robot: a "
            "URDF, MJCF or SDF file, or a robot's name such as solo12)",
        ) from err
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise SceneFileError(
            path, "file", f"not a UTF-8 text file (byte {raw[err.start]:#04x} at offset {err.start})"
        ) from err
    return load_scene_text(text, path, **overrides)


def shipped_scene(path: Path) -> Path:
    """``path``, or the shipped scene it names when no such file exists (``solo12_standing`` or
    ``solo12_standing.toml``: robots/scenes in a clone, the package's copy in an install)."""
    if path.exists() or path.parent != Path():
        return path
    shipped = ROBOTS_DIR / "scenes" / path.with_suffix(".toml").name
    return shipped if shipped.is_file() else path


def names_robot(path: Path) -> bool:
    """Whether a scene argument names a robot rather than a scene file: a URDF, MJCF or SDF file (told
    by its suffix), or a robot's name (of robots/ or example-robot-data) that is no shipped scene."""
    if path.suffix in SUFFIXES:
        return True
    if path.exists() or path.parent != Path() or shipped_scene(path) != path:
        return False
    return (ROBOTS_DIR / f"{path}.urdf").is_file() or str(path) in example_robot_names()


def robot_scene_text(source: str) -> str:
    """The scene file of a robot run by itself (``gaussim run ROBOT``): the robot ``source`` (a URDF,
    MJCF or SDF path, or a robot's name, as :func:`~gaussim.robot.load_robot` takes them) on a ground,
    every collision geometry against it, joint limits on, from :func:`start_configuration` (clamped
    into the limits) ROBOT_CLEARANCE above the ground (a fixed-base robot: the ground that far below
    its lowest geometry), held there by a PD posture hold, for ROBOT_DURATION. A robot without
    collision geometry gets no ground (it would fall through it); a file of one rigid body floats."""
    return _robot_scene(source)[0]


def _robot_scene(source: str) -> tuple[str, Robot, tuple[str, bool | None]]:
    """:func:`robot_scene_text`'s text, the robot it loaded, and the (source, floating_base) that the
    text's [robot] table loads it from."""
    from .simulator import within_limits

    robot, floated = _robot_of(source)
    free = [
        robot.model.names[j] for j in np.flatnonzero(FloatingBases.of(robot.model).of_joint >= 0).tolist()
    ]
    if len(free) > 1:  # one start pose and one posture hold cannot place and hold several free bodies
        raise InvalidRobot(
            f"{source}: its {len(free)} free-flyer joints ({', '.join(free)}) move {len(free)} bodies, which "
            "a robot run by itself cannot place apart: give each its pose in a scene file ([initial] q, "
            "or one [[bodies]] table per body; robots/scenes/box_stack.toml runs robots/box_stack.urdf)"
        )
    path = Path(source)
    if path.suffix in SUFFIXES:
        key, value = {".urdf": "urdf", ".sdf": "sdf"}.get(path.suffix, "mjcf"), str(path.resolve())
    else:
        key, value = "name", source
    start = start_configuration(robot)
    q, outside = within_limits(robot.model, robot.configuration(start))
    # the named configuration, or the one clamped into the limits as numbers
    posture = json.dumps(start) if not outside else json.dumps(q.tolist())
    touches = bool(robot.collision_model.ngeoms)
    actuated = len(robot.actuated) > 0
    base = "floating" if robot.floating else "fixed (floating_base = true drops it)"
    lines = [
        f"# {robot.name} run by itself (gaussim run {source}), its base {base}: "
        + (
            "on the ground, every collision geometry\n# against it"
            if touches
            else "no collision geometry, no\n# ground"
        )
        + (f", joint limits on, a PD hold of its {start} configuration" if actuated else ", no joint")
        + ". Edit it and run it as a scene file.",
        *([f"# Its {start} configuration clamped into the joint limits: {outside}."] if outside else []),
        "[robot]",
        f"{key} = {json.dumps(value)}",
        *(["floating_base = true  # a lone rigid body moves only with a floating base"] if floated else []),
        "",
        "[initial]",
        f"{'q' if outside else 'configuration'} = {posture}",
    ]
    if touches and robot.floating:
        lines += [f"ground_clearance = {ROBOT_CLEARANCE}", "", "[ground]"]
    elif touches:
        height = ground_below(robot, q, ROBOT_CLEARANCE)
        lines += ["", "[ground]", f"height = {height:.6g}"]
    lines += ["", "[limits]", "enabled = true"]
    if robot.model.damping.any() or robot.model.friction.any():
        lines += [
            "",
            "[joint_friction]  # the damping and dry friction its file gives its joints",
            "enabled = true",
        ]
    if actuated:
        gain = max(robot.mass, 1.0)
        lines += [
            "",
            "[control]",
            'type = "pd"',
            f"target = {posture}",
            f"kp = {HOLD_KP_PER_KG * gain:.4g}",
            f"kd = {HOLD_KD_PER_KG * gain:.4g}",
        ]
    lines += ["", "[simulation]", f"duration = {ROBOT_DURATION}", "", "[options]", "dt = 1e-3"]
    return "\n".join(lines) + "\n", robot, (value, True if floated else None)


def _robot_of(source: str) -> tuple[Robot, bool]:
    """The robot ``source`` names, as its file or name says, and False; or, for a file of one rigid
    body (no joint: nothing would move), that body floating, and True (PyBullet's default). The
    warnings of the load that made it are given, once."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            robot, floated = load_robot(source), False
        except InvalidRobot as err:
            caught.clear()
            try:
                robot, floated = load_robot(source, floating_base=True), True
            except GaussimError:
                raise err from None
            if robot.model.nv != 6:  # more than one body: the first error stands
                raise err from None
    for warning in caught:
        warnings.warn(warning.message, warning.category, stacklevel=4)
    return robot, floated


def ground_below(robot: Robot, q: np.ndarray, clearance: float) -> float:
    """The height [m] of a ground ``clearance`` below the lowest collision geometry of the fixed-base
    ``robot`` at ``q``."""
    from .collision import ContactDetector

    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q)
    height = 0.0
    for _ in range(PLACEMENTS):  # as place_on_ground's
        detector = ContactDetector(Scene(robot, ground=Ground(height=height)), margin=1e3)
        error = float(detector.detect(data).gap.min()) - clearance
        height += error
        if abs(error) <= PLACED:
            break
    return height


def load_scene_text(text: str, path: str | Path, **overrides: Any) -> SceneSpec:
    """Like :func:`load_scene`, for scene text said to come from ``path`` (relative robot paths are
    resolved against its folder; a run log keeps its scene this way)."""
    return _read(text, Path(path), overrides)


def _read(text: str, path: Path, overrides: dict[str, Any], loaded: Loaded | None = None) -> SceneSpec:
    """:func:`load_scene_text`, its [robot] table taken from ``loaded`` where that holds the robot it
    names ((source, floating_base): a robot already loaded to write the text)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise SceneFileError(path, "toml", str(err)) from err
    return _Reader(path, data, loaded or {}).build(text, overrides)


class _Reader:
    def __init__(self, path: Path, data: dict[str, Any], loaded: Loaded) -> None:
        self.path, self.data, self.loaded = path, data, loaded
        for key in data:
            if key not in SECTIONS:
                self.fail(key, f"unknown section; known: {', '.join(sorted(SECTIONS))}")

    def fail(self, key: str, message: str) -> NoReturn:
        raise SceneFileError(self.path, key, message)

    def table(self, name: str, entry: Any = None, key: str | None = None) -> dict[str, Any]:
        value = self.data.get(name, {}) if entry is None else entry
        key = key or name
        if not isinstance(value, dict):
            self.fail(key, f"must be a table, got {type(value).__name__}")
        for k in value:
            if k not in SECTIONS[name]:
                self.fail(f"{key}.{k}", f"unknown key; known: {', '.join(sorted(SECTIONS[name]))}")
        return value

    def array(self, key: str, value: Any, size: int | None = None) -> np.ndarray:
        wanted = f"must be {finite_numbers(size)}, got {shown(value)}"
        if not isinstance(value, (list, np.ndarray)) or any(not _is_number(x) for x in value):
            self.fail(key, wanted)
        arr = np.asarray(value, dtype=float)
        if arr.ndim != 1 or (size is not None and arr.shape != (size,)) or not np.all(np.isfinite(arr)):
            self.fail(key, wanted)
        return arr

    def number(self, key: str, value: Any) -> float:
        if not _is_number(value):
            self.fail(key, f"must be a finite number, got {shown(value)}")
        return float(value)

    def string(self, key: str, value: Any) -> str:
        if not isinstance(value, str):
            self.fail(key, f"must be a string, got {shown(value)}")
        return value

    def boolean(self, key: str, value: Any) -> bool:
        if not isinstance(value, bool):
            self.fail(key, f"must be true or false, got {shown(value)}")
        return value

    def build(self, text: str, overrides: dict[str, Any]) -> SceneSpec:
        entries = self.bodies() if "bodies" in self.data else None
        robot = self.robot() if entries is None else None
        bodies = None if entries is None else {e.name: e.body for e in entries}
        obstacles = [self.obstacle(i, o) for i, o in enumerate(self.tables("obstacles"))]
        ground = self.ground()
        contacts_section = self.table("contacts")
        contacts = contacts_section.get("pairs")
        self_contact = (
            self.number("contacts.friction", contacts_section.get("friction", 0.8)),
            self.number("contacts.restitution", contacts_section.get("restitution", 0.0)),
        )
        if contacts is not None:
            if not isinstance(contacts, list):
                self.fail(
                    "contacts.pairs", f"must be a list of [geometry, obstacle] pairs, got {shown(contacts)}"
                )
            for k, pair in enumerate(contacts):
                if not (isinstance(pair, list) and len(pair) == 2 and all(isinstance(n, str) for n in pair)):
                    self.fail(
                        f"contacts.pairs[{k}]", f"must be [geometry, obstacle] (two names), got {shown(pair)}"
                    )
        limits = self.boolean("limits.enabled", self.table("limits").get("enabled", False))
        friction = self.table("joint_friction").get("enabled", False)
        friction = self.boolean("joint_friction.enabled", friction)
        listed = self.tables("bilaterals")
        # the robot whose frames the bilaterals name: the one robot, or the bodies merged
        framed = robot or (self.scene_part(lambda: World(bodies).robot) if listed else None)  # type: ignore[arg-type]
        bilaterals = [self.bilateral(i, b, framed) for i, b in enumerate(listed)]  # type: ignore[arg-type]
        scene = self.scene_part(
            lambda: Scene(
                robot,
                bodies=bodies,
                ground=ground,
                obstacles=obstacles,
                contacts=None if contacts is None else [tuple(p) for p in contacts],
                joint_limits=limits,
                joint_friction=friction,
                bilaterals=bilaterals,
                self_contact=self_contact,
            )
        )
        options = self.options(overrides)
        duration = self.number("simulation.duration", self.table("simulation").get("duration", 1.0))
        if duration <= 0:
            self.fail("simulation.duration", f"must be > 0, got {duration}")
        if entries is None:
            assert robot is not None
            initial = self.initial(scene)
            controller = self.controller("control", self.table("control"), robot, options.dt)
        else:
            initial = self.initial_of_bodies(scene, entries)
            controller = self.controllers(scene, entries, options.dt)
        return SceneSpec(self.path, text, scene, options, initial, controller, duration)

    def scene_part(self, build):  # type: ignore[no-untyped-def]
        """Run ``build`` (the Scene, or its bodies merged); an error it raises is told where it sits in
        the file (the bodies' own fields are checked as they are read)."""
        try:
            return build()
        except InvalidOptions as err:
            owner = re.match(r"\w*", err.field)[0]  # type: ignore[index]
            place = SCENE_FIELDS.get(owner, owner) + err.field[len(owner) :]
            raise SceneFileError(self.path, place, err.message) from err
        except InvalidRobot as err:  # a body that cannot join the others
            raise SceneFileError(self.path, "bodies", str(err)) from err
        except GaussimError as err:  # an unknown geometry or obstacle of a pair
            raise SceneFileError(self.path, "contacts.pairs", str(err)) from err

    def wrap(self, key: str, build, owner: str | None = None, aliases: dict[str, str] | None = None):  # type: ignore[no-untyped-def]
        """Run ``build``; a GaussimError it raises is prefixed with the file and key (an error's field
        that starts with ``owner`` has it replaced by ``key``, and is renamed by ``aliases``)."""
        try:
            return build()
        except SceneFileError:
            raise
        except InvalidOptions as err:
            field = err.field
            if owner is not None and field.startswith(owner + "."):
                field = field[len(owner) + 1 :]
            field = (aliases or {}).get(field, field)
            raise SceneFileError(self.path, f"{key}.{field}", err.message) from err
        except GaussimError as err:
            raise SceneFileError(self.path, key, str(err)) from err

    def tables(self, name: str) -> list[Any]:
        value = self.data.get(name, [])
        if not isinstance(value, list):
            self.fail(name, f"must be an array of tables ([[{name}]]), got {type(value).__name__}")
        return value

    def robot(self) -> Robot:
        section = self.table("robot")
        given = [key for key in ("name", "urdf", "mjcf", "sdf") if key in section]
        if len(given) != 1:
            self.fail(
                "robot",
                "give exactly one of name (example-robot-data or robots/), urdf, mjcf or sdf (a path)",
            )
        key = f"robot.{given[0]}"
        floating = section.get("floating_base")
        if floating is not None:
            self.boolean("robot.floating_base", floating)
        dirs = self.folders("robot.package_dirs", section.get("package_dirs", []))
        if given[0] != "name":
            return self.load(key, self.file(key, section[given[0]]), dirs, floating)
        return self.load(key, self.string(key, section["name"]), dirs, floating)

    def folders(self, key: str, dirs: Any) -> list[str]:
        if not (isinstance(dirs, list) and all(isinstance(d, str) for d in dirs)):
            self.fail(key, f"must be a list of folder names, got {shown(dirs)}")
        return [str(self.path.parent / d) for d in dirs]

    def file(self, key: str, value: Any) -> Path:
        """``value``, a path relative to the scene file, of a file that exists."""
        target = self.path.parent / self.string(key, value)
        if not target.is_file():
            self.fail(key, missing_file(target))
        return target

    def load(
        self, key: str, source: str | Path, dirs: list[str], floating: bool | None, body: str | None = None
    ) -> Robot:
        if not dirs and body is None and (str(source), floating) in self.loaded:
            return self.loaded[str(source), floating]
        return self.wrap(
            key, lambda: load_robot(source, package_dirs=dirs, floating_base=floating, body=body)
        )

    def bodies(self) -> list[_BodyEntry]:
        for section in ("robot", "initial", "control"):
            if section in self.data:
                self.fail(
                    section,
                    "a scene of [[bodies]] gives each body's robot, initial state and control in its "
                    "own table ([robot], [initial] and [control] are the one-robot form)",
                )
        listed = self.tables("bodies")
        if not listed:
            self.fail("bodies", "give at least one [[bodies]] table")
        entries: list[_BodyEntry] = []
        for i, entry in enumerate(listed):
            body = self.body(i, entry)
            twin = next((e for e in entries if e.name == body.name), None)
            if twin is not None:
                self.fail(f"{body.key}.name", f"'{body.name}' is also the name of {twin.key}")
            entries.append(body)
        return entries

    def body(self, i: int, entry: Any) -> _BodyEntry:
        key = f"bodies[{i}]"
        section = self.table("bodies", entry, key)
        if "name" not in section:
            self.fail(f"{key}.name", "missing: every body has a name")
        name = self.string(f"{key}.name", section["name"])
        if not name or "/" in name:
            self.fail(f"{key}.name", f"must be a non-empty text without '/', got {shown(name)}")
        sources = [k for k in (*ROBOT_SOURCES, "shape") if k in section]
        if len(sources) != 1:
            self.fail(
                key,
                "give exactly one of robot (a name), urdf, mjcf, sdf (a file) or shape"
                + (f", got {', '.join(sources)}" if sources else ""),
            )
        position, rpy = (
            self.array(f"{key}.{k}", section[k], 3) if k in section else None for k in ("position", "rpy")
        )
        source: Robot | FreeBody
        if sources[0] == "shape":
            source = self.shape(key, name, section)
        else:
            source = self.robot_of(key, sources[0], section)
        placement = None
        if isinstance(source, Robot) and not source.floating and (position is not None or rpy is not None):
            x, y, z = np.zeros(3) if position is None else position
            placement = pose(x, y, z, rpy=None if rpy is None else list(rpy))
        material = None
        if "friction" in section or "restitution" in section:
            friction, restitution = (
                self.number(f"{key}.{k}", section[k]) if k in section else None
                for k in ("friction", "restitution")
            )
            material = self.wrap(key, lambda: Material(friction, restitution), owner="material")
        masks = [self.mask(f"{key}.{k}", section.get(k, 1)) for k in ("contype", "conaffinity")]
        color: tuple[float, float, float, float] | None = None
        if "color" in section:
            rgba = self.array(f"{key}.color", section["color"])
            if len(rgba) not in (3, 4) or np.any((rgba < 0) | (rgba > 1)):
                self.fail(f"{key}.color", f"must be [r, g, b] or [r, g, b, a] in [0, 1], got {shown(rgba)}")
            r, g, b, a = map(float, np.r_[rgba, 1.0][:4])  # opaque unless told
            color = (r, g, b, a)
        body = Body(
            source,
            placement,
            self_collision=self.boolean(f"{key}.self_collision", section.get("self_collision", False)),
            material=material,
            contype=masks[0],
            conaffinity=masks[1],
            color=color,
        )
        return _BodyEntry(key, name, body, section, position, rpy)

    def mask(self, key: str, value: Any) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            self.fail(key, f"must be an integer bit mask >= 0, got {shown(value)}")
        return value

    def robot_of(self, key: str, kind: str, section: dict[str, Any]) -> Robot:
        """The robot of a [[bodies]] table: by ``robot`` name, or from its urdf, mjcf or sdf file."""
        wrong = next((k for k in SHAPE_KEYS if k in section), None)
        if wrong is not None:
            self.fail(f"{key}.{wrong}", "a robot's mass and geometry are its model's; only a shape takes it")
        floating = section.get("floating")
        if floating is not None:
            self.boolean(f"{key}.floating", floating)
        dirs = self.folders(f"{key}.package_dirs", section.get("package_dirs", []))
        body = section.get("body")
        if body is not None:
            self.string(f"{key}.body", body)
            if kind != "mjcf":
                self.fail(f"{key}.body", f"selects a top-level body of an mjcf file, not of a {kind}")
        where = f"{key}.{kind}"
        source = self.string(where, section[kind]) if kind == "robot" else self.file(where, section[kind])
        return self.load(where, source, dirs, floating, body)

    def shape(self, key: str, name: str, section: dict[str, Any]) -> FreeBody:
        """The free body of a [[bodies]] table that gives a ``shape``."""
        kind = section["shape"]
        if kind not in SHAPES:
            self.fail(f"{key}.shape", f"{shown(kind)} is not one of {', '.join(SHAPES)}")
        wrong = next((k for k in ROBOT_KEYS if k in section), None)
        if wrong is not None:
            self.fail(f"{key}.{wrong}", "a shape is a free body: only a robot takes it")
        dimensions = SHAPE_DIMENSIONS[kind]
        required = dimensions[:1] if kind == "mesh" else dimensions
        needs = " and ".join(required)
        for k in ("size", "radius", "length", "path", "scale"):
            if k in section and k not in dimensions:
                self.fail(f"{key}.{k}", f"a {kind} has {', '.join(dimensions)}, not a {k}")
        for k in required:
            if k not in section:
                self.fail(f"{key}.{k}", f"missing: a {kind} needs {needs}")
        mass, density = (
            self.number(f"{key}.{k}", section[k]) if k in section else None for k in ("mass", "density")
        )
        if kind == "box":
            size = self.array(f"{key}.size", section["size"], 3)
            build = lambda: FreeBody.box(name, list(size), mass=mass, density=density)  # noqa: E731
        elif kind == "sphere":
            radius = self.number(f"{key}.radius", section["radius"])
            build = lambda: FreeBody.sphere(name, radius, mass=mass, density=density)  # noqa: E731
        elif kind == "mesh":
            path = self.file(f"{key}.path", section["path"])
            scale = self.number(f"{key}.scale", section.get("scale", 1.0))
            build = lambda: FreeBody.mesh(name, str(path), scale=scale, mass=mass, density=density)  # noqa: E731
        else:
            radius = self.number(f"{key}.radius", section["radius"])
            length = self.number(f"{key}.length", section["length"])
            make = FreeBody.cylinder if kind == "cylinder" else FreeBody.capsule
            build = lambda: make(name, radius, length, mass=mass, density=density)  # noqa: E731
        return self.wrap(key, build, owner=name, aliases={"mesh": "path"})

    def ground(self) -> Ground | None:
        if "ground" not in self.data:
            return None
        section = self.table("ground")
        return self.wrap("ground", lambda: Ground(**section), owner="ground")

    def obstacle(self, i: int, entry: Any) -> Box | Sphere:
        key = f"obstacles[{i}]"
        section = dict(self.table("obstacles", entry, key))
        kind = section.pop("type", None)
        rpy = self.array(f"{key}.rpy", section.pop("rpy", [0, 0, 0]), 3)
        if kind not in ("box", "sphere"):
            self.fail(f"{key}.type", f"{shown(kind)} is not one of box, sphere")
        dimension, other = ("size", "radius") if kind == "box" else ("radius", "size")
        if other in section:
            self.fail(f"{key}.{other}", f"a {kind} has a {dimension}, not a {other}")
        for required in ("name", dimension):
            if required not in section:
                self.fail(f"{key}.{required}", f"missing: a {kind} needs a name and a {dimension}")
        name = self.string(f"{key}.name", section["name"])
        if kind == "box":
            return self.wrap(key, lambda: Box(rotation=pin.rpy.rpyToMatrix(rpy), **section), owner=name)
        return self.wrap(key, lambda: Sphere(**section), owner=name)

    def bilateral(self, i: int, entry: Any, robot: Robot) -> Anchor | LoopClosure:
        key = f"bilaterals[{i}]"
        section = self.table("bilaterals", entry, key)
        kind = section.get("type")
        self.typed("bilaterals", key, section, kind)
        if kind == "anchor":
            frame = self.frame(f"{key}.frame", section.get("frame"), robot)
            position = self.array(f"{key}.position", section.get("position"), 3)
            rpy = section.get("rpy")
            rotation = None if rpy is None else pin.rpy.rpyToMatrix(self.array(f"{key}.rpy", rpy, 3))
            return Anchor(frame, position, rotation)
        if kind == "loop":
            frames = section.get("frames")
            if not (isinstance(frames, list) and len(frames) == 2):
                self.fail(f"{key}.frames", f"must be two frame names, got {shown(frames)}")
            frames = [self.frame(f"{key}.frames", frame, robot) for frame in frames]
            orientation = self.boolean(f"{key}.orientation", section.get("orientation", False))
            return LoopClosure(frames[0], frames[1], orientation)
        self.fail(f"{key}.type", f"{shown(kind)} is not one of anchor, loop")
        raise AssertionError  # unreachable

    def typed(self, table: str, key: str, section: dict[str, Any], kind: Any) -> None:
        """Refuse a key of ``section`` (a ``table`` at ``key``) that its type ``kind`` does not read,
        naming the types that read it: a gain under a zero controller would be ignored."""
        reads = TYPE_KEYS[table]
        if not isinstance(kind, str) or kind not in reads:
            return  # an unknown type, or no word (a list is no key of reads): its own error follows
        for name in sorted(set(section) - {"type", *reads[kind]}):
            readers = " or ".join(f'type = "{t}"' for t, keys in reads.items() if name in keys)
            default = "" if "type" in section else " (the default)"
            self.fail(f"{key}.{name}", f"type {shown(kind)}{default} does not read it; {readers} does")

    def frame(self, key: str, name: Any, robot: Robot) -> str:
        """``name``, a frame of ``robot``."""
        name = self.string(key, name)
        self.wrap(key, lambda: robot.frame_id(name))
        return name

    def options(self, overrides: dict[str, Any]) -> Options:
        given = {k: v for k, v in overrides.items() if v is not None}
        Options(**given)  # a bad override is the caller's, not the file's: its error names no file
        return self.wrap("options", lambda: Options(**{**self.table("options"), **given}))

    def initial(self, scene: Scene) -> State:
        robot = scene.robot
        section = self.table("initial")
        if "q" in section and "configuration" in section:
            self.fail("initial", "give configuration or q, not both")
        if "q" in section:
            q = self.array("initial.q", section["q"], robot.model.nq)
        else:
            name = self.string("initial.configuration", section.get("configuration", "neutral"))
            q = self.wrap("initial.configuration", lambda: robot.configuration(name))
        v = self.array("initial.v", section.get("v", np.zeros(robot.model.nv)), robot.model.nv)
        if "ground_clearance" in section:
            clearance = self.number("initial.ground_clearance", section["ground_clearance"])
            q = self.wrap("initial", lambda: place_on_ground(scene, q, clearance))
        return State(0.0, q, v, scene.world)

    def initial_of_bodies(self, scene: Scene, entries: list[_BodyEntry]) -> State:
        """The world's initial state: each body's configuration, its start pose when it floats, its
        velocity; then each ``ground_clearance`` applied, in the order of the tables."""
        q, v = scene.robot.neutral(), np.zeros(scene.robot.model.nv)
        for e in entries:
            layout, key, section = scene.bodies[e.name], e.key, e.section
            robot = layout.robot
            configuration = section.get("configuration", "neutral")
            if isinstance(configuration, str):
                q_b = self.wrap(f"{key}.configuration", partial(robot.configuration, configuration))
            else:
                q_b = self.array(f"{key}.configuration", configuration, robot.model.nq)
            if layout.floating and e.position is not None:
                q_b[:3] = e.position
            if layout.floating and e.rpy is not None:
                q_b[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(e.rpy)).coeffs()
            q[layout.q] = q_b
            v[layout.v] = self.array(f"{key}.velocity", section.get("velocity", v[layout.v]), robot.model.nv)
        for e in entries:
            if "ground_clearance" in e.section:
                clearance = self.number(f"{e.key}.ground_clearance", e.section["ground_clearance"])
                q = self.wrap(e.key, partial(place_on_ground, scene, q, clearance, e.name))
        return State(0.0, q, v, scene.world)

    def controllers(self, scene: Scene, entries: list[_BodyEntry], dt: float) -> Controller:
        """The controller of a scene of bodies: each ``[bodies.control]``'s on its body's state."""
        own = {
            e.name: self.controller(f"{e.key}.control", control, scene.bodies[e.name].robot, dt)
            for e in entries
            if (control := self.table("control", e.section.get("control", {}), f"{e.key}.control"))
        }
        return _per_body(own) if own else zero_torque

    def controller(self, key: str, section: dict[str, Any], robot: Robot, dt: float) -> Controller:
        """The ``[control]`` table ``section`` (at ``key``), for ``robot``'s joints."""
        kind = section.get("type", "zero")
        self.typed("control", key, section, kind)
        actuated = robot.actuated
        if kind == "zero":
            return zero_torque
        if kind in ("constant", "pd") and not len(actuated):  # its torques or gains would act on nothing
            self.fail(
                f"{key}.type",
                f"{shown(kind)}: robot '{robot.name}' has no actuated joint (its joints are free roots); "
                'leave [control] out or give type = "zero"',
            )
        if kind == "constant":
            tau = self.array(f"{key}.tau", section.get("tau"), len(actuated))
            if np.abs(tau).max(initial=0.0) > MAX_TORQUE:
                self.fail(
                    f"{key}.tau", f"beyond any actuator (|tau| <= {MAX_TORQUE:g} N m), got {shown(tau)}"
                )
            return constant_torque(tau)
        if kind == "pd":
            target = section.get("target", "neutral")
            if isinstance(target, str):
                q_ref = self.wrap(f"{key}.target", lambda: robot.configuration(target))
            else:
                q_ref = self.array(f"{key}.target", target, robot.model.nq)
            kp = self.number(f"{key}.kp", section.get("kp", 0.0))
            kd = self.number(f"{key}.kd", section.get("kd", 0.0))
            if kp < 0 or kd < 0:
                self.fail(key, f"gains must be >= 0, got kp={kp}, kd={kd}")
            implicit = self.boolean(f"{key}.implicit", section.get("implicit", True))
            return PDHold(robot.model, q_ref, kp, kd, actuated, dt if implicit else None)
        self.fail(f"{key}.type", f"{shown(kind)} is not one of zero, constant, pd")
        raise AssertionError  # unreachable


def _per_body(controllers: dict[str, Controller]) -> Controller:
    """One controller of the bodies' own: each called on its body's state, their torques and damping
    given per body (``{body: tau_b}``)."""

    def control(state: State | BodyState) -> Command:
        assert isinstance(state, State)
        tau: dict[str, Any] = {}
        damping: dict[str, Any] = {}
        for name, controller in controllers.items():
            out = command(controller(state.body(name)))
            if out.tau is not None:
                tau[name] = out.tau
            if out.damping is not None:
                damping[name] = out.damping
        return Command(tau or None, damping or None)

    return control


def _is_number(value: Any) -> bool:
    """True for a finite int or float (a TOML bool is not a number, nor an integer beyond any float)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and is_real(value)


def place_on_ground(scene: Scene, q: np.ndarray, clearance: float, body: str | None = None) -> np.ndarray:
    """Shift a floating base vertically so that its lowest declared contact with the ground is
    ``clearance`` above it [m]: the base of ``body`` (default: the first body, the one robot's)."""
    from .collision import ContactDetector

    layout = scene.world.body(body) if body is not None else next(iter(scene.bodies.values()))
    if not layout.floating:
        raise InvalidOptions("ground_clearance", "needs a floating-base robot")
    grounds = [o for o in scene.obstacles if isinstance(o, Ground)]
    if not grounds:
        raise InvalidOptions("ground_clearance", "needs a [ground]")
    robot = scene.robot
    data = robot.model.createData()
    q = q.copy()
    # again from nearer: coal estimates a mesh's distance from afar, and its depth deep in the ground
    for _ in range(PLACEMENTS):
        pin.forwardKinematics(robot.model, data, q)
        contacts = ContactDetector(scene, margin=1e3).detect(data)
        gaps = [
            gap
            for gap, geometry, obstacle in zip(contacts.gap, contacts.geometry, contacts.obstacle)
            if obstacle == grounds[0].name and scene.world.body_of(geometry) == layout.name
        ]
        if not gaps:
            raise InvalidOptions("ground_clearance", "no declared contact pair involves the ground")
        q[layout.q.start : layout.q.start + 3] += (clearance - min(gaps)) * np.asarray(grounds[0].normal)
        if abs(clearance - min(gaps)) <= PLACED:
            break
    return q
