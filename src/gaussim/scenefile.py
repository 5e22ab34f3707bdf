"""Scene files: a TOML description of what to simulate, validated with errors that name the key.

    [robot]        name = "solo12" | urdf = "path.urdf", package_dirs = [...], floating_base = bool
    [initial]      configuration = "standing" | q = [...];  v = [...];  ground_clearance = 0.01
    [ground]       friction, restitution, height, normal
    [[obstacles]]  type = "box" | "sphere", name, size | radius, position, rpy, friction, restitution
    [contacts]     pairs = [["FL_FOOT_0", "ground"], ["a_0", "b_0"], ...]  (default: every geometry x
                   obstacle); friction, restitution: of the pairs of two robot geometries
    [limits]       enabled = true
    [[bilaterals]] type = "anchor", frame, position, rpy  |  type = "loop", frames = [a, b], orientation
    [control]      type = "zero" | "constant" (tau = [...]) | "pd" (target = name | [...], kp, kd)
    [simulation]   duration = 2.0
    [options]      any field of gaussim.Options (dt, scheme, friction_mode, ...)

Relative paths are taken from the scene file's folder. Unknown keys are errors.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import pinocchio as pin

from .control import Controller, PDHold, constant_torque, zero_torque
from .exceptions import GaussimError, InvalidOptions, shown
from .options import Options, is_real
from .robot import Robot, load_robot
from .scene import Anchor, Box, Ground, LoopClosure, Scene, Sphere
from .state import State

SECTIONS = {
    "robot": {"name", "urdf", "package_dirs", "floating_base"},
    "initial": {"configuration", "q", "v", "ground_clearance"},
    "ground": {"friction", "restitution", "height", "normal"},
    "obstacles": {"type", "name", "size", "radius", "position", "rpy", "friction", "restitution"},
    "contacts": {"pairs", "friction", "restitution"},
    "limits": {"enabled"},
    "bilaterals": {"type", "frame", "position", "rpy", "frames", "orientation"},
    "control": {"type", "tau", "target", "kp", "kd", "implicit"},
    "simulation": {"duration"},
    "options": {f.name for f in fields(Options)},
}
# The largest joint torque a scene may command [N m] (Talos's strongest joint gives 300): beyond it the
# QP's rows span hundreds of orders of magnitude and ProxQP stops without a motion (tau = 1e300)
MAX_TORQUE = 1e6
# where a field a Scene names (its constructor's argument) sits in a scene file
SCENE_FIELDS = {"contacts": "contacts.pairs", "self_contact": "contacts"}


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
        scene: the robot and its constraints.
        options: the step options.
        initial: the initial state.
        controller: joint torques as a function of the state.
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


def load_scene(path: str | Path, **overrides: Any) -> SceneSpec:
    """Read and validate a scene file; ``overrides`` replace fields of its ``[options]`` (e.g. dt=1e-4).

    Raises:
        SceneFileError: unreadable TOML, unknown key, wrong type or value (names file and key).
        GaussimError: an unknown robot, frame or geometry (the message lists the valid names).
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise SceneFileError(path, "file", f"cannot read it: {err.strerror}") from err
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise SceneFileError(
            path, "file", f"not a UTF-8 text file (byte {raw[err.start]:#04x} at offset {err.start})"
        ) from err
    return load_scene_text(text, path, **overrides)


def load_scene_text(text: str, path: str | Path, **overrides: Any) -> SceneSpec:
    """Like :func:`load_scene`, for scene text said to come from ``path`` (relative robot paths are
    resolved against its folder; a run log keeps its scene this way)."""
    path = Path(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise SceneFileError(path, "toml", str(err)) from err
    reader = _Reader(path, data)
    return reader.build(text, overrides)


class _Reader:
    def __init__(self, path: Path, data: dict[str, Any]) -> None:
        self.path, self.data = path, data
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
        wanted = f"must be {'a list of' if size is None else size} finite numbers, got {shown(value)}"
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
        robot = self.robot()
        obstacles = [self.obstacle(i, o) for i, o in enumerate(self.list("obstacles"))]
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
        bilaterals = [self.bilateral(i, b, robot) for i, b in enumerate(self.list("bilaterals"))]
        try:
            scene = Scene(
                robot,
                ground=ground,
                obstacles=obstacles,
                contacts=None if contacts is None else [tuple(p) for p in contacts],
                joint_limits=limits,
                bilaterals=bilaterals,
                self_contact=self_contact,
            )
        except InvalidOptions as err:
            owner = re.match(r"\w*", err.field)[0]  # type: ignore[index]
            place = SCENE_FIELDS.get(owner, owner) + err.field[len(owner) :]
            raise SceneFileError(self.path, place, str(err)[len(err.field) + 2 :]) from err
        except GaussimError as err:  # an unknown geometry or obstacle of a pair
            raise SceneFileError(self.path, "contacts.pairs", str(err)) from err
        options = self.options(overrides)
        duration = self.number("simulation.duration", self.table("simulation").get("duration", 1.0))
        if duration <= 0:
            self.fail("simulation.duration", f"must be > 0, got {duration}")
        initial = self.initial(scene)
        controller = self.controller(robot, options.dt)
        return SceneSpec(self.path, text, scene, options, initial, controller, duration)

    def wrap(self, key: str, build, owned: bool = False):  # type: ignore[no-untyped-def]
        """Run ``build``; a GaussimError it raises is prefixed with the file and key (``owned``: the
        error's field starts with the owner's name, which ``key`` replaces)."""
        try:
            return build()
        except SceneFileError:
            raise
        except InvalidOptions as err:
            field = err.field.split(".", 1)[-1] if owned else err.field
            raise SceneFileError(self.path, f"{key}.{field}", str(err)[len(err.field) + 2 :]) from err
        except GaussimError as err:
            raise SceneFileError(self.path, key, str(err)) from err

    def list(self, name: str) -> list[Any]:
        value = self.data.get(name, [])
        if not isinstance(value, list):
            self.fail(name, f"must be an array of tables ([[{name}]]), got {type(value).__name__}")
        return value

    def robot(self) -> Robot:
        section = self.table("robot")
        if ("name" in section) == ("urdf" in section):
            self.fail("robot", "give exactly one of name (example-robot-data or robots/) or urdf (a path)")
        floating = section.get("floating_base")
        if floating is not None:
            self.boolean("robot.floating_base", floating)
        dirs = section.get("package_dirs", [])
        if not (isinstance(dirs, list) and all(isinstance(d, str) for d in dirs)):
            self.fail("robot.package_dirs", f"must be a list of folder names, got {shown(dirs)}")
        dirs = [str(self.path.parent / d) for d in dirs]
        if "urdf" in section:
            target = self.path.parent / self.string("robot.urdf", section["urdf"])
            if not target.is_file():
                self.fail("robot.urdf", f"no such file: {target}")
            return self.wrap(
                "robot.urdf", lambda: load_robot(target, package_dirs=dirs, floating_base=floating)
            )
        name = self.string("robot.name", section["name"])
        return self.wrap("robot.name", lambda: load_robot(name, package_dirs=dirs, floating_base=floating))

    def ground(self) -> Ground | None:
        if "ground" not in self.data:
            return None
        section = self.table("ground")
        return self.wrap("ground", lambda: Ground(**section), owned=True)

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
        self.string(f"{key}.name", section["name"])
        if kind == "box":
            return self.wrap(key, lambda: Box(rotation=pin.rpy.rpyToMatrix(rpy), **section), owned=True)
        return self.wrap(key, lambda: Sphere(**section), owned=True)

    def bilateral(self, i: int, entry: Any, robot: Robot) -> Anchor | LoopClosure:
        key = f"bilaterals[{i}]"
        section = self.table("bilaterals", entry, key)
        kind = section.get("type")
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

    def frame(self, key: str, name: Any, robot: Robot) -> str:
        """``name``, a frame of ``robot``."""
        name = self.string(key, name)
        self.wrap(key, lambda: robot.frame_id(name))
        return name

    def options(self, overrides: dict[str, Any]) -> Options:
        section = dict(self.table("options"))
        section.update({k: v for k, v in overrides.items() if v is not None})
        return self.wrap("options", lambda: Options(**section))

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
            q = self.wrap("initial.ground_clearance", lambda: place_on_ground(scene, q, clearance))
        return State(0.0, q, v)

    def controller(self, robot: Robot, dt: float) -> Controller:
        section = self.table("control")
        kind = section.get("type", "zero")
        nv = robot.model.nv
        actuated = slice(6, nv) if robot.floating else slice(0, nv)
        if kind == "zero":
            return zero_torque
        if kind == "constant":
            n = nv - 6 if robot.floating else nv
            tau = self.array("control.tau", section.get("tau"), n)
            if np.abs(tau).max(initial=0.0) > MAX_TORQUE:
                self.fail(
                    "control.tau", f"beyond any actuator (|tau| <= {MAX_TORQUE:g} N m), got {shown(tau)}"
                )
            return constant_torque(tau)
        if kind == "pd":
            target = section.get("target", "neutral")
            if isinstance(target, str):
                q_ref = self.wrap("control.target", lambda: robot.configuration(target))
            else:
                q_ref = self.array("control.target", target, robot.model.nq)
            kp = self.number("control.kp", section.get("kp", 0.0))
            kd = self.number("control.kd", section.get("kd", 0.0))
            if kp < 0 or kd < 0:
                self.fail("control", f"gains must be >= 0, got kp={kp}, kd={kd}")
            implicit = self.boolean("control.implicit", section.get("implicit", True))
            return PDHold(robot.model, q_ref, kp, kd, actuated, dt if implicit else None)
        self.fail("control.type", f"{shown(kind)} is not one of zero, constant, pd")
        raise AssertionError  # unreachable


def _is_number(value: Any) -> bool:
    """True for a finite int or float (a TOML bool is not a number, nor an integer beyond any float)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and is_real(value)


def place_on_ground(scene: Scene, q: np.ndarray, clearance: float) -> np.ndarray:
    """Shift a floating base vertically so that its lowest declared contact with the ground is
    ``clearance`` above it [m]."""
    from .collision import ContactDetector

    robot = scene.robot
    if not robot.floating:
        raise InvalidOptions("ground_clearance", "needs a floating-base robot")
    grounds = [o for o in scene.obstacles if isinstance(o, Ground)]
    if not grounds:
        raise InvalidOptions("ground_clearance", "needs a [ground]")
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q)
    contacts = ContactDetector(scene, margin=1e3).detect(data)
    gaps = [gap for gap, obstacle in zip(contacts.gap, contacts.obstacle) if obstacle == grounds[0].name]
    if not gaps:
        raise InvalidOptions("ground_clearance", "no declared contact pair involves the ground")
    q = q.copy()
    q[:3] += (clearance - min(gaps)) * np.asarray(grounds[0].normal)
    return q
