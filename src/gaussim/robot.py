"""Robots: a Pinocchio model with its collision and visual geometry, read from a URDF, MJCF or SDF
file or a robot name (:func:`load_robot`), or made of the Pinocchio objects a user already holds
(:func:`as_robot`). A :class:`Robot` is checked when made, whatever it was made from: masses,
inertias, limits, a positive definite mass matrix, and geometry attached to its own model's joints."""

from __future__ import annotations

import contextlib
import dataclasses
import importlib.resources
import os
import re
import sys
import tempfile
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin

from . import mjcf, sdf
from .exceptions import (
    FrameNotFound,
    GaussimWarning,
    GeometryNotFound,
    InvalidOptions,
    InvalidRobot,
    RobotNotFound,
    finite_numbers,
    shown,
)
from .urdfcheck import check_urdf, mesh_fault, mimic_joints


def _shipped() -> Path:
    """The shipped robots and scenes: package data of an installed gaussim (``pip install .``), or the
    repository's ``robots/`` for a source checkout (``pip install -e .``, whose package is src/gaussim)."""
    installed = Path(str(importlib.resources.files("gaussim"))) / "robots"
    return installed if installed.is_dir() else Path(__file__).resolve().parents[2] / "robots"


ROBOTS_DIR = _shipped()
# How far a body's principal moments may miss positivity and the triangle inequality I1 + I2 >= I3,
# relative to its largest moment, plus an absolute floor [kg m^2] (URDFs round their inertias: an
# iCub link's moments are +-2e-35)
INERTIA_RTOL, INERTIA_ATOL = 1e-6, 1e-12
# a robot file's format, told by its root element
FORMATS = {"robot": "URDF", "mujoco": "MJCF", "sdf": "SDF"}
SUFFIXES = (".urdf", ".xml", ".mjcf", ".sdf")
# shapes no body has: a ground is a Scene's gaussim.Ground
UNBOUNDED = (coal.Halfspace, coal.Plane)
ON_MASSLESS = ("lump", "error")
ON_BAD_INERTIA = ("balance", "error")
# A joint's block of the mass matrix is singular when its smallest eigenvalue is below this fraction of
# the matrix's largest; "lump" gives its link this fraction of the typical link's mass and inertia.
SINGULAR_RTOL, MASSLESS_FRACTION = 1e-12, 1e-3
# A link's centre of mass farther than this from its collision geometry's bounding box, and than half
# the geometry's size, gets a warning: the file has it wrong (pybullet's teddy_large: 1 m outside) [m]
COM_OUTSIDE = 0.25
# A mesh whose vertices lie within this fraction of its size of a plane has no convex hull qhull
# takes (measured: it crashes the process up to 1e-8, builds from 1e-7).
FLATNESS = 1e-6
# coal's hull of a mesh stores at most 255 neighbours per vertex; one with more is rebuilt dropping the
# points within this distance of the hull (qhull's W option) [m]
HULL_COARSENING = 1e-3
ACCEPTED = (
    "a gaussim.Robot, a pinocchio.RobotWrapper (example_robot_data.load(...) returns one), a "
    "pinocchio.Model, a tuple (model, collision_model) or (model, collision_model, visual_model), a URDF, "
    "MJCF or SDF path, or a robot name"
)


@dataclass(frozen=True)
class Robot:
    """An immutable robot model, checked when made (:class:`InvalidRobot` says what is wrong); the
    meshes of its collision model get their convex hulls, which contacts are computed on.

    Attributes:
        name: the name it was loaded by.
        model: Pinocchio kinematic/dynamic model.
        collision_model: Pinocchio geometry model used for contacts.
        visual_model: Pinocchio geometry model used for display.
        urdf: the file it was read from (a URDF, MJCF or SDF file); "" for a model made in memory.
        package_dirs: directories where ``package://`` meshes are resolved.
        reference_configurations: named configurations (e.g. ``standing``), shape (nq,) each.
        on_massless: what to do with a joint whose moving links have no mass or no inertia about its
            motion (the mass matrix is then singular): ``"lump"`` (default, PyBullet accepts such
            files) gives the joint's link MASSLESS_FRACTION of the robot's typical link mass and
            inertia, with a warning naming each; ``"error"`` refuses the robot naming them.
        on_bad_inertia: what to do with a body whose principal moments of inertia break the triangle
            inequality I1 + I2 >= I3 (no mass distribution has them; pybullet_data's xarm and
            mini_cheetah): ``"balance"`` (default; PyBullet accepts such files) sets its three moments
            to their mean (MuJoCo's ``balanceinertia``), with a warning naming each; ``"error"``
            refuses the robot naming it. A negative moment is always refused.
    """

    name: str
    model: pin.Model
    collision_model: pin.GeometryModel
    visual_model: pin.GeometryModel
    urdf: str
    package_dirs: tuple[str, ...] = ()
    reference_configurations: dict[str, np.ndarray] = field(default_factory=dict)
    on_massless: str = "lump"
    on_bad_inertia: str = "balance"

    def __post_init__(self) -> None:
        # one data for the checks: Pinocchio's grows as nv^3 (a second-order tensor; 4.5 s and 3.3 GB
        # to make at nv 384)
        data = self.model.createData()
        _conventions(self, data)
        _check(self, data)
        _warn_oddities(self)
        for geometry in self.collision_model.geometryObjects:
            if isinstance(geometry.geometry, coal.BVHModelBase) and geometry.geometry.convex is None:
                # Contacts are detected on the convex hull of a mesh (coal's GJK/EPA needs convex shapes
                # to give signed distances and contact patches); built once here.
                _convex_hull(self, geometry)

    @classmethod
    def of_checked_parts(
        cls,
        name: str,
        model: pin.Model,
        geometry: tuple[pin.GeometryModel, pin.GeometryModel],
        urdf: str,
        package_dirs: tuple[str, ...],
        reference_configurations: dict[str, np.ndarray],
    ) -> Robot:
        """A robot made of robots each already checked, with their convex hulls (``geometry``: its
        collision and visual models): a world's bodies side by side (``pin.appendModel``), whose mass
        matrix is theirs block by block. It is not checked again: the checks make a Pinocchio data of
        the whole model, whose size grows as nv^3 (3.3 GB and 4.5 s for 64 free bodies)."""
        values = {
            "name": name,
            "model": model,
            "collision_model": geometry[0],
            "visual_model": geometry[1],
            "urdf": urdf,
            "package_dirs": package_dirs,
            "reference_configurations": reference_configurations,
        }
        for f in dataclasses.fields(cls):  # the policies at their defaults: each part's did their work
            values.setdefault(f.name, f.default)
        assert dataclasses.MISSING not in values.values()  # every field set, as __init__ sets them
        robot = object.__new__(cls)
        for key, value in values.items():
            object.__setattr__(robot, key, value)  # frozen: past __setattr__, as dataclasses' __init__
        return robot

    @property
    def source(self) -> str:
        """What the robot was made from, for messages: its file, or its in-memory model."""
        return self.urdf or f"the in-memory model '{self.name}'"

    @property
    def floating(self) -> bool:
        """True when the root joint is a free flyer."""
        return _floats(self.model)

    @property
    def actuated(self) -> np.ndarray:
        """The velocity coordinates torques drive, shape (k,): all but the six of each free-flyer joint
        hung from the world (a floating base; each box of a file of free boxes)."""
        from .dynamics import FloatingBases  # the project's definition of a free root

        driven = np.ones(self.model.nv, dtype=bool)
        for first in FloatingBases.of(self.model).velocity:
            driven[first : first + 6] = False
        return np.flatnonzero(driven)

    @property
    def mass(self) -> float:
        """Total mass [kg]."""
        return float(sum(inertia.mass for inertia in self.model.inertias))

    def neutral(self) -> np.ndarray:
        """Neutral configuration, shape (nq,)."""
        return pin.neutral(self.model)

    def configuration(self, name: str) -> np.ndarray:
        """A named reference configuration, shape (nq,)."""
        if name == "neutral":
            return self.neutral()
        if name not in self.reference_configurations:
            raise FrameNotFound(name, ["neutral", *self.reference_configurations], "configuration")
        return self.reference_configurations[name].copy()

    def frame_id(self, name: str) -> int:
        """Index of a frame; raises :class:`FrameNotFound` listing every frame name. A URDF may give a
        link and a joint the same name: the link's (body) frame is the one meant."""
        matches = [i for i, frame in enumerate(self.model.frames) if frame.name == name]
        if not matches:
            raise FrameNotFound(name, [f.name for f in self.model.frames])
        bodies = [i for i in matches if self.model.frames[i].type == pin.FrameType.BODY]
        return (bodies or matches)[0]

    def geometry_id(self, name: str) -> int:
        """Index of a collision geometry; raises :class:`GeometryNotFound` listing them."""
        if not self.collision_model.existGeometryName(name):
            raise GeometryNotFound(name, [g.name for g in self.collision_model.geometryObjects])
        return int(self.collision_model.getGeometryId(name))


def example_robot_names() -> list[str]:
    """Names of the robots example-robot-data can load."""
    from example_robot_data.robots_loader import ROBOTS

    return sorted(ROBOTS)


def load_robot(
    name: str | os.PathLike[str],
    *,
    package_dirs: list[str] | tuple[str, ...] = (),
    floating_base: bool | None = None,
    on_massless: str = "lump",
    on_bad_inertia: str = "balance",
    body: str | None = None,
) -> Robot:
    """Load a robot.

    Args:
        name: a URDF, MJCF or SDF path (told apart by the root element: ``<robot>``, ``<mujoco>``,
            ``<sdf>``), a robot of the project's ``robots/`` folder (``"ball"``), or an
            example-robot-data name (``"solo12"``, ``"talos"``); a name in both is the project's
            robot, with a warning that names the other.
        package_dirs: where ``package://`` meshes of a URDF, and ``package://`` and ``model://``
            meshes of an SDF, are looked up.
        floating_base: give the robot a free-flyer root joint. Default: as the file says, where it
            can: an MJCF whose first body has a ``<freejoint>`` floats, an SDF model floats unless a
            joint attaches it to the world; a URDF is fixed-base; example-robot-data decides for its
            robots (mobile robots float). A file that says the opposite of the value given is refused.
        on_massless: ``"lump"`` or ``"error"``: see :class:`Robot`.
        on_bad_inertia: ``"balance"`` or ``"error"``: see :class:`Robot`.
        body: of an MJCF file, the top-level body of ``<worldbody>`` to load (default: the first, with
            the world's own geoms); the robot is named after it. Each top-level body is its own robot:
            load each and give a :class:`Scene` all of them.

    Raises:
        RobotNotFound: the name is none of the above (the message lists the known names).
        InvalidRobot: the file could not be read or describes an unusable model.
    """
    policies = {"on_massless": on_massless, "on_bad_inertia": on_bad_inertia}
    if not isinstance(name, (str, os.PathLike)):  # a model or wrapper is as_robot's
        raise InvalidOptions(
            "name",
            f"must be a robot's name or a file's path, got {shown(name)} (gaussim.as_robot takes a Pinocchio "
            "model or RobotWrapper)",
        )
    path = Path(name)
    local = ROBOTS_DIR / f"{name}.urdf"
    if path.suffix in SUFFIXES or path.exists():
        if not path.is_file():
            raise RobotNotFound(str(name), _known_names(), file=True)
        return _from_file(path, tuple(package_dirs), floating_base, policies, body)
    if body is not None:
        raise InvalidOptions("body", f"selects a top-level body of an MJCF file; '{name}' is no file")
    if local.is_file():
        if str(name) in example_robot_names():  # the shipped robot comes first: say so
            warnings.warn(
                f"robot '{name}' is gaussim's shipped {local.name}; load example-robot-data's robot of "
                f"that name by its URDF path (example_robot_data.robots_loader.ROBOTS['{name}']().df_path)",
                GaussimWarning,
                stacklevel=2,
            )
        return _from_urdf(local, (str(ROBOTS_DIR), *package_dirs), bool(floating_base), policies)
    known = example_robot_names()
    if str(name) not in known:
        raise RobotNotFound(str(name), _known_names())
    from example_robot_data.robots_loader import ROBOTS
    from example_robot_data.utils import getModelPath

    kind = ROBOTS[str(name)]
    if kind.sdf_filename and not kind.urdf_filename:  # its loader needs Pinocchio's SDF parser: gaussim's
        relative = os.path.join(kind.path, kind.sdf_subpath, kind.sdf_filename)
        model_path = Path(getModelPath(relative))
        robot = _from_sdf(model_path / relative, (str(model_path.parent.parent),), floating_base, policies)
        return dataclasses.replace(robot, name=str(name))
    try:
        with _stderr_kept() as stderr:
            loader = kind()
    except (RuntimeError, ValueError, OSError) as err:
        raise InvalidRobot(
            f"example-robot-data's '{name}' cannot be built: {_cause(err)}{_said(stderr)}"
        ) from err
    if floating_base is not None and floating_base != loader.free_flyer:
        base = "floating" if loader.free_flyer else "fixed"
        raise InvalidRobot(
            f"robot '{name}' has a {base} base in example-robot-data; to change it, load its "
            f"URDF by path: load_robot('{loader.df_path}', floating_base={floating_base})"
        )
    model = loader.robot.model
    _warn_mimics(Path(loader.df_path), model)
    # a loader that cut its model and its visual geometry to some joints but left its collision geometry
    # whole (talos_legs: Talos's legs) meant the same cut for both; only an unexplained one is warned
    visual = loader.robot.visual_model
    cut = visual.ngeoms > 0 and not _stray(model, visual)
    return Robot(
        str(name),
        model,
        _own_geometry(str(name), model, loader.robot.collision_model, warn=not cut),
        _own_geometry(str(name), model, visual),
        str(loader.df_path),
        (str(loader.model_path),),
        _configurations(model),
        **policies,
    )


def _stray(model: pin.Model, geometry: pin.GeometryModel) -> list[str]:
    """The names of the geometries of ``geometry`` attached to joints ``model`` does not have."""
    return [g.name for g in geometry.geometryObjects if g.parentJoint >= model.njoints]


def _own_geometry(
    name: str, model: pin.Model, geometry: pin.GeometryModel, *, warn: bool = True
) -> pin.GeometryModel:
    """The geometry of an example-robot-data robot attached to joints of its model: a loader that
    reduces a model may keep the geometry of the joints it removed (talos_legs keeps the collision
    geometry of Talos's torso and arms, though it cuts its visual geometry to the legs), which is left
    out, with a warning when ``warn``."""
    stray = _stray(model, geometry)
    for geometry_name in stray:
        geometry.removeGeometryObject(geometry_name)
    if stray and warn:
        warnings.warn(
            f"example-robot-data's '{name}' holds {len(stray)} geometries of joints its model does not have "
            f"({shown(stray)}): left out",
            GaussimWarning,
            stacklevel=3,
        )
    return geometry


def as_robot(
    obj: object, name: str | None = None, *, on_massless: str = "lump", on_bad_inertia: str = "balance"
) -> Robot:
    """A :class:`Robot` of what a user holds, passed as it is.

    Args:
        obj: a :class:`Robot` (returned as it is, renamed if ``name`` is given); a
            ``pinocchio.RobotWrapper`` (``example_robot_data.load("solo12")`` returns one); a
            ``pinocchio.Model`` (no geometry: it touches nothing); a tuple ``(model, collision_model)``
            (its collision geometry is also drawn) or ``(model, collision_model, visual_model)``; a
            path or robot name (see :func:`load_robot`). Pinocchio objects are copied: changing them
            later does not change the robot.
        name: the robot's name; default the model's name (``model.name``), or "robot".
        on_massless: ``"lump"`` or ``"error"``: see :class:`Robot` (for a model it makes).
        on_bad_inertia: ``"balance"`` or ``"error"``: see :class:`Robot` (for a model it makes).

    Raises:
        InvalidRobot: ``obj`` is none of these, or its model is unusable, or a geometry is attached to
            a joint or frame its model does not have (the geometry model of another model).
        RobotNotFound: a name that is no robot.
    """
    if isinstance(obj, Robot):
        return obj if name is None else dataclasses.replace(obj, name=name)
    if isinstance(obj, str | os.PathLike):
        robot = load_robot(obj, on_massless=on_massless, on_bad_inertia=on_bad_inertia)
        return robot if name is None else dataclasses.replace(robot, name=name)
    if isinstance(obj, pin.RobotWrapper):
        parts: tuple[object, ...] = (obj.model, obj.collision_model, obj.visual_model)
    elif isinstance(obj, tuple) and len(obj) in (2, 3):
        parts = obj
    else:
        parts = (obj,)
    model, collision, visual = (*parts, None, None)[:3]
    if not isinstance(model, pin.Model):
        raise InvalidRobot(f"as_robot: cannot make a robot of {_described(obj)}; accepted: {ACCEPTED}")
    geometries = []
    for role, geometry in (("collision_model", collision), ("visual_model", visual)):
        if geometry is not None and not isinstance(geometry, pin.GeometryModel):
            raise InvalidRobot(
                f"as_robot: the {role} must be a pinocchio.GeometryModel (or None), got "
                f"{_described(geometry)}; accepted: {ACCEPTED}"
            )
        geometries.append(geometry.clone() if geometry is not None else None)
    collision, visual = geometries
    collision = collision if collision is not None else pin.GeometryModel()
    visual = visual if visual is not None else collision.clone()
    model = pin.Model(model)
    configurations = _configurations(model)
    return Robot(
        name or model.name or "robot",
        model,
        collision,
        visual,
        "",
        (),
        configurations,
        on_massless,
        on_bad_inertia,
    )


def _described(obj: object) -> str:
    """Its type and, when it fits a line, its value."""
    if isinstance(obj, tuple):
        return f"a tuple of ({', '.join(type(item).__name__ for item in obj)})"
    text = shown(obj)
    return type(obj).__name__ + ("" if "\n" in text else f" {text}")


def _known_names() -> list[str]:
    local = [p.stem for p in ROBOTS_DIR.glob("*.urdf")] if ROBOTS_DIR.is_dir() else []
    return local + example_robot_names()


def _from_file(
    path: Path,
    package_dirs: tuple[str, ...],
    floating: bool | None,
    policies: Mapping[str, str],
    body: str | None = None,
) -> Robot:
    """A robot of a URDF, MJCF or SDF file, told apart by its root element."""
    try:
        tag = ET.parse(path).getroot().tag.rpartition("}")[2]  # without an XML namespace
    except ET.ParseError as err:
        raise InvalidRobot(f"{path}: not well-formed XML ({err})") from err
    if tag == "mujoco":
        return _from_mjcf(path, floating, policies, body)
    if body is not None:
        raise InvalidOptions("body", f"selects a top-level body of an MJCF file; {path} is no MJCF")
    if tag == "sdf":
        return _from_sdf(path, package_dirs, floating, policies)
    if tag == "robot":
        return _from_urdf(path, package_dirs, bool(floating), policies)
    known = ", ".join(f"<{t}> ({f})" for t, f in FORMATS.items())
    raise InvalidRobot(f"{path}: the root element <{tag}> is no robot format gaussim reads; known: {known}")


def _from_urdf(
    path: Path, package_dirs: tuple[str, ...] | list[str], floating: bool, policies: Mapping[str, str]
) -> Robot:
    dirs = [str(d) for d in (*package_dirs, path.parent)]
    check_urdf(path)
    try:
        with _stderr_kept() as stderr:
            if floating:
                model, collision, visual = pin.buildModelsFromUrdf(str(path), dirs, pin.JointModelFreeFlyer())
            else:
                model, collision, visual = pin.buildModelsFromUrdf(str(path), dirs)
    except (RuntimeError, ValueError, OSError) as err:
        cause = mesh_fault(path, dirs, str(err)) or _cause(err) + _said(stderr)
        raise InvalidRobot(f"{path}: cannot build a model from this URDF: {cause}") from err
    _warn_mimics(path, model)
    return Robot(path.stem, model, collision, visual, str(path), tuple(dirs), {}, **policies)


def _from_mjcf(
    path: Path, floating: bool | None, policies: Mapping[str, str], body: str | None = None
) -> Robot:
    root = mjcf.read(path)
    mjcf.check_file(path, root)
    with mjcf.for_pinocchio(path, root, body) as (weighed, shaped):
        model, collision, visual = _mjcf_models(path, weighed, shaped, floating)
    total = mjcf.total_mass(root)
    if total is not None:
        mjcf.set_total_mass(model, total / _file_mass(path, root, body, model))
    notes = mjcf.check(path, root, body)
    mjcf.set_joint_limits(root, model)
    planes = [
        g.name for g in collision.geometryObjects if isinstance(g.geometry, UNBOUNDED) and g.parentJoint == 0
    ]
    for geometry in (collision, visual):
        for plane in planes:
            if geometry.existGeometryName(plane):
                geometry.removeGeometryObject(plane)
    if planes:
        notes.append(
            f"the world's planes {', '.join(repr(p) for p in planes)} are left out (a gaussim Scene has its "
            "own ground: gaussim.Ground)"
        )
    for note in notes:
        warnings.warn(f"{path}: {note}", GaussimWarning, stacklevel=4)
    dirs = (str(path.parent),)
    name = path.stem if body is None else body
    return Robot(name, model, collision, visual, str(path), dirs, _configurations(model), **policies)


def _file_mass(path: Path, root: ET.Element, body: str | None, model: pin.Model) -> float:
    """The mass of every body of the MJCF at ``path`` as Pinocchio reads it (before ``settotalmass``):
    ``model``'s (that of ``body``, or of the first top-level body) and each other top-level body's."""
    loaded = mjcf.top_index(path, root, body)
    mass = sum(inertia.mass for inertia in model.inertias)
    for k in range(len(mjcf.bodies(root))):
        if k != loaded:
            with mjcf.for_pinocchio(path, root, k) as (weighed, _):
                other = pin.buildModelFromMJCF(weighed)
            mass += sum(inertia.mass for inertia in other.inertias)
    if mass <= 0:
        raise InvalidRobot(f"{path}: <compiler settotalmass> scales the masses of a file that weighs nothing")
    return mass


def _mjcf_models(
    path: Path, weighed: str, shaped: str, floating: bool | None
) -> tuple[pin.Model, pin.GeometryModel, pin.GeometryModel]:
    """The model, collision and visual geometry of the MJCF at ``path``, from Pinocchio's reading of
    its rewrites (:func:`.mjcf.for_pinocchio`): ``weighed`` for the model, ``shaped`` for the geometry."""
    try:
        # the model alone (here and with a root joint): the reader of its <equality> constraints, which
        # gaussim leaves out (see mjcf.check), fails on valid ones (body2="world")
        model = pin.buildModelFromMJCF(weighed)
        floats = _floats(model)
        if floating is False and floats:
            raise InvalidRobot(
                f"{path}: body '{_root_body(model)}' has a <freejoint>, so the robot floats: "
                "floating_base=False cannot fix it (remove the <freejoint> to fix the base)"
            )
        if floating and not floats:
            model = pin.buildModelFromMJCFAndRootJoint(weighed, pin.JointModelFreeFlyer(), "root_joint")
            if not _floats(model):
                raise InvalidRobot(
                    f"{path}: floating_base=True: body '{_root_body(model)}' hangs from the world by its "
                    f"own joint '{model.names[1]}', above which Pinocchio's MJCF reader adds no free root: "
                    "put it in a body of its own with a <freejoint/> to make the robot float"
                )
        collision = pin.buildGeomFromMJCF(model, shaped, pin.GeometryType.COLLISION)
        visual = pin.buildGeomFromMJCF(model, shaped, pin.GeometryType.VISUAL)
    except (RuntimeError, ValueError, OSError, IndexError) as err:  # IndexError: a name Pinocchio misses
        raise InvalidRobot(f"{path}: cannot build a model from this MJCF: {_cause(err)}") from err
    return model, collision, visual


def _floats(model: pin.Model) -> bool:
    """Whether the model's first joint is a free flyer."""
    return model.njoints > 1 and model.joints[1].shortname() == "JointModelFreeFlyer"


def _root_body(model: pin.Model) -> str:
    """The name of the body the model's first joint moves."""
    return next(f.name for f in model.frames if f.type == pin.FrameType.BODY and f.parentJoint == 1)


def _from_sdf(
    path: Path, package_dirs: tuple[str, ...], floating: bool | None, policies: Mapping[str, str]
) -> Robot:
    converted = sdf.to_urdf(path, package_dirs)
    floats = converted.world_joint is None if floating is None else floating
    if floats and converted.world_joint is not None:
        raise InvalidRobot(
            f"{path}: joint '{converted.world_joint}' attaches the model to the world: floating_base=True "
            "cannot make it float (remove that joint)"
        )
    try:
        if floats:
            model = pin.buildModelFromXML(converted.urdf, pin.JointModelFreeFlyer())
        else:
            model = pin.buildModelFromXML(converted.urdf)
        collision = pin.buildGeomFromUrdfString(model, converted.urdf, pin.GeometryType.COLLISION)
        visual = pin.buildGeomFromUrdfString(model, converted.urdf, pin.GeometryType.VISUAL)
    except (RuntimeError, ValueError, OSError) as err:
        raise InvalidRobot(f"{path}: cannot build a model from this SDF: {_cause(err)}") from err
    for note in converted.notes:
        warnings.warn(f"{path}: {note}", GaussimWarning, stacklevel=4)
    dirs = (*package_dirs, str(path.parent))
    return Robot(path.stem, model, collision, visual, str(path), dirs, {}, **policies)


@contextlib.contextmanager
def _stderr_kept() -> Iterator[list[str]]:
    """Capture what C++ code (urdfdom, which tells why a URDF is refused only there) writes to the
    process's stderr, file descriptor 2, into the list yielded; written on to stderr afterwards."""
    said: list[str] = []
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as capture:
        os.dup2(capture.fileno(), 2)
        try:
            yield said
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            capture.seek(0)
            text = capture.read().decode(errors="replace")
            said.append(text)
            sys.stderr.write(text)


def _said(stderr: list[str]) -> str:
    """What the parser said on stderr, for a message: its non-empty lines joined, or nothing."""
    lines = [line.strip() for text in stderr for line in text.splitlines() if line.strip()]
    return f" (the parser said: {'; '.join(lines)})" if lines else ""


def _cause(err: Exception) -> str:
    """The message of a Pinocchio error, without the C++ function and line it carries."""
    text = str(err)
    found = re.search(r"message:\s*(.+)", text, re.S)
    return " ".join((found[1] if found else text).split())


def _configurations(model: pin.Model) -> dict[str, np.ndarray]:
    """The model's named configurations (an SRDF's, an MJCF's keyframes)."""
    return {e.key(): np.array(e.data()) for e in model.referenceConfigurations}


def _warn_mimics(path: Path, model: pin.Model) -> None:
    mimics = [(j, target) for j, target in mimic_joints(path) if model.existJointName(j)]
    if mimics:
        listed = ", ".join(f"'{j}' (mimics '{target}')" for j, target in mimics)
        warnings.warn(
            f"{path}: gaussim does not honour <mimic>: the joints {listed} move as free joints",
            GaussimWarning,
            stacklevel=4,
        )


def _check(robot: Robot, data: pin.Data) -> None:
    """Raise :class:`InvalidRobot` unless the robot is simulable (``data``: its model's, for the mass
    matrix)."""
    where, model = robot.source, robot.model
    if not isinstance(model, pin.Model):
        raise InvalidRobot(f"{where}: the model must be a pinocchio.Model, got {type(model).__name__}")
    for role in ("collision_model", "visual_model"):
        geometry = getattr(robot, role)
        if not isinstance(geometry, pin.GeometryModel):
            raise InvalidRobot(
                f"{where}: the {role} must be a pinocchio.GeometryModel, got {type(geometry).__name__}"
            )
    if model.nv == 0:
        raise InvalidRobot(
            f"{where}: the model has no degree of freedom (a single free body needs a floating base: "
            "load_robot(..., floating_base=True); in a scene file, floating_base = true in [robot] or "
            "floating = true in [[bodies]])"
        )
    for joint_id in range(1, model.njoints):
        inertia = model.inertias[joint_id]
        if not np.isfinite(inertia.mass) or inertia.mass < 0:
            raise InvalidRobot(f"{where}: body of joint '{model.names[joint_id]}' has mass {inertia.mass}")
    _check_inertias(model, where, robot.on_bad_inertia)
    for joint_id in range(1, model.njoints):
        joint = model.joints[joint_id]
        lower = model.lowerPositionLimit[joint.idx_q : joint.idx_q + joint.nq]
        upper = model.upperPositionLimit[joint.idx_q : joint.idx_q + joint.nq]
        if np.any(lower > upper):  # a one-coordinate joint's are Bullet's "no limit" (_conventions)
            raise InvalidRobot(
                f"{where}: joint '{model.names[joint_id]}' has its lower limit {lower.tolist()} "
                f"above its upper limit {upper.tolist()}"
            )
    for key, q in robot.reference_configurations.items():
        if np.shape(q) != (model.nq,) or not np.all(np.isfinite(q)):
            raise InvalidRobot(
                f"{where}: configuration '{key}' must be {finite_numbers(model.nq)}, got {shown(q)}"
            )
    mass_matrix = pin.crba(model, data, pin.neutral(model))
    if not np.all(np.isfinite(mass_matrix)):
        raise InvalidRobot(f"{where}: the mass matrix at the neutral configuration is not finite")
    values, vectors = np.linalg.eigh(mass_matrix)
    if values[0] <= SINGULAR_RTOL * values[-1]:
        weights = np.abs(vectors[:, 0])
        moving = [model.names[j] for j in range(1, model.njoints) if _joint_part(model, j, weights) > 0.1]
        raise InvalidRobot(
            f"{where}: the mass matrix is singular at the neutral configuration: a motion of the joints "
            f"{shown(moving)} together moves no mass (joints that repeat one another's motion, e.g. "
            "prismatic joints under a floating base, or links without inertia)"
        )
    _check_geometry(model, robot.collision_model, where, "collision")
    _check_geometry(model, robot.visual_model, where, "visual")


def _check_geometry(model: pin.Model, geometry: pin.GeometryModel, where: str, role: str) -> None:
    """Refuse a geometry attached to a joint or frame that is not the model's, or a collision shape
    without bounds."""
    joints = ", ".join(f"{i} '{n}'" for i, n in enumerate(model.names))
    unset = np.iinfo(np.uint64).max  # the frame of a GeometryObject made without one
    for g in geometry.geometryObjects:
        name = f"{role} geometry '{g.name}'"
        if g.geometry is None:
            raise InvalidRobot(f"{where}: {name} has no shape")
        if g.parentJoint >= model.njoints:
            raise InvalidRobot(
                f"{where}: {name} is attached to joint {g.parentJoint}, which the model does not have "
                f"(its joints: {joints}): is it the geometry model of another model?"
            )
        if g.parentFrame != unset and (
            g.parentFrame >= model.nframes or model.frames[g.parentFrame].parentJoint != g.parentJoint
        ):
            frame = (
                f"frame '{model.frames[g.parentFrame].name}' (on joint "
                f"'{model.names[model.frames[g.parentFrame].parentJoint]}')"
                if g.parentFrame < model.nframes
                else f"frame {g.parentFrame}, which the model does not have"
            )
            raise InvalidRobot(
                f"{where}: {name} is attached to joint '{model.names[g.parentJoint]}' and to {frame}: "
                "is it the geometry model of another model?"
            )
        if role == "collision" and isinstance(g.geometry, UNBOUNDED):
            raise InvalidRobot(
                f"{where}: {name} is an unbounded {type(g.geometry).__name__}, which no body is: give the "
                "scene a ground instead (gaussim.Scene(robot, ground=gaussim.Ground()))"
            )


def _check_inertias(model: pin.Model, where: str, on_bad_inertia: str) -> None:
    """Refuse a body whose principal moments of inertia are negative (a run gains energy); balance or
    refuse (``on_bad_inertia``) one whose moments break the triangle inequality I1 + I2 >= I3 (no mass
    distribution has them). Checked on Pinocchio's bodies, each the sum of a moving link and the links
    fixed to it: the example-robot-data robots whose URDF links break it (allegro, go1, anymal) have
    valid sums."""
    balanced = []
    for joint_id in range(1, model.njoints):
        inertia = model.inertias[joint_id]
        moments = np.linalg.eigvalsh(inertia.inertia)
        tolerance = INERTIA_RTOL * np.abs(moments).max() + INERTIA_ATOL
        if moments[0] >= -tolerance and moments[0] + moments[1] >= moments[2] - tolerance:
            continue
        listed = ", ".join(f"{m:.6g}" for m in moments)
        body = f"link '{_link(model, joint_id)}' (the body of joint '{model.names[joint_id]}')"
        negative = not moments[0] >= -tolerance  # NaN too
        if negative or on_bad_inertia == "error":
            fault = "a negative one" if negative else "I1 + I2 < I3"
            option = "" if negative else "; or load with on_bad_inertia='balance'"
            raise InvalidRobot(
                f"{where}: {body} has principal moments of inertia {listed} [kg m^2]: {fault}, which no "
                f"body has (check the <inertia> of it and of the links fixed to it{option})"
            )
        mean = float(np.mean(moments))  # MuJoCo's balanceinertia: the three moments set to their mean
        model.inertias[joint_id] = pin.Inertia(inertia.mass, inertia.lever, mean * np.eye(3))
        balanced.append(f"{body}: {listed} -> {mean:.6g}")
    if balanced:
        warnings.warn(
            f"{where}: principal moments of inertia [kg m^2] that break the triangle inequality I1 + I2 >= "
            f"I3, which no body has, are set to their mean (MuJoCo's balanceinertia; on_bad_inertia='error' "
            f"refuses the robot instead): {'; '.join(balanced)}",
            GaussimWarning,
            stacklevel=6,
        )


def _link(model: pin.Model, joint_id: int) -> str:
    """The name of the link a joint moves (its first body frame), else the joint's name."""
    return next(
        (f.name for f in model.frames if f.type == pin.FrameType.BODY and f.parentJoint == joint_id),
        model.names[joint_id],
    )


def _conventions(robot: Robot, data: pin.Data) -> None:
    """Read the files' well-known conventions, with a warning naming what is read so: a joint's lower
    limit above its upper one is Bullet's "no limit" (unlimited here); a body whose moments of inertia
    break the triangle inequality is balanced or refused as ``robot.on_bad_inertia`` says; joints whose
    moving links have no inertia about their motion are lumped or refused as ``robot.on_massless`` says
    (``data``: the model's)."""
    model, where = robot.model, robot.source
    for option, value, known in (
        ("on_massless", robot.on_massless, ON_MASSLESS),
        ("on_bad_inertia", robot.on_bad_inertia, ON_BAD_INERTIA),
    ):
        if value not in known:
            raise InvalidOptions(option, f"must be one of {', '.join(known)}, got {shown(value)}")
    swapped = []
    for joint_id in range(1, model.njoints):
        joint = model.joints[joint_id]
        iq = joint.idx_q
        if joint.nq == 1 and model.lowerPositionLimit[iq] > model.upperPositionLimit[iq]:
            lower, upper = model.lowerPositionLimit[iq], model.upperPositionLimit[iq]
            swapped.append(f"'{model.names[joint_id]}' ({lower:g} > {upper:g})")
            model.lowerPositionLimit[iq], model.upperPositionLimit[iq] = -np.inf, np.inf
    if swapped:
        warnings.warn(
            f"{where}: the joints {', '.join(swapped)} have their lower limit above their upper one, "
            "Bullet's convention for no limit: gaussim leaves them unlimited",
            GaussimWarning,
            stacklevel=5,
        )
    if not all(i.mass >= 0 and np.all(np.isfinite(i.inertia)) for i in model.inertias[1:]):
        return  # refused by _check, naming the body
    _check_inertias(model, where, robot.on_bad_inertia)  # a negative moment is refused, not lumped
    lumped: list[int] = []
    for _ in range(model.nv):
        massless = _massless(model, data)
        if not massless:
            break
        if robot.on_massless == "error":
            raise InvalidRobot(
                f"{where}: the links {shown([_link(model, j) for j in massless])} have no mass or no inertia "
                "about their joints' motion, so the mass matrix is singular: give them an <inertial>, or "
                "load with on_massless='lump'"
            )
        masses = [i.mass for i in model.inertias[1:] if i.mass > 0]
        moments = [np.trace(i.inertia) / 3 for i in model.inertias[1:] if np.trace(i.inertia) > 0]
        mass = MASSLESS_FRACTION * (float(np.mean(masses)) if masses else 1.0)
        moment = MASSLESS_FRACTION * (float(np.mean(moments)) if moments else 1e-4)
        for joint_id in massless:
            inertia = model.inertias[joint_id]
            added = pin.Inertia(mass if inertia.mass <= 0 else 0.0, inertia.lever, moment * np.eye(3))
            model.inertias[joint_id] = inertia + added
        lumped += [j for j in massless if j not in lumped]
    if lumped:
        warnings.warn(
            f"{where}: the links {shown([_link(model, j) for j in lumped])} have no mass or no inertia about "
            f"their joints' motion: each is given {MASSLESS_FRACTION:g} of the robot's typical link mass "
            "(where it has none) and inertia (on_massless='error' refuses the robot instead)",
            GaussimWarning,
            stacklevel=5,
        )


def _massless(model: pin.Model, data: pin.Data) -> list[int]:
    """The joints whose links move, with no kinetic energy, along the mass matrix's null direction (at
    the neutral configuration; none when the matrix is regular or the direction moves no link: joints
    that repeat one another's motion)."""
    q = pin.neutral(model)
    mass_matrix = pin.crba(model, data, q)
    if not np.all(np.isfinite(mass_matrix)):
        return []
    values, vectors = np.linalg.eigh(mass_matrix)
    if values[0] > SINGULAR_RTOL * values[-1]:
        return []
    pin.forwardKinematics(model, data, q, vectors[:, 0])
    return [j for j in range(1, model.njoints) if np.linalg.norm(data.v[j].vector) > 0.1]


def _joint_part(model: pin.Model, joint_id: int, weights: np.ndarray) -> float:
    """The largest of a joint's entries in a vector of the velocity space, shape (nv,)."""
    joint = model.joints[joint_id]
    return float(weights[joint.idx_v : joint.idx_v + joint.nv].max(initial=0.0))


def _warn_oddities(robot: Robot) -> None:
    """Warn about what a file likely has wrong: a robot read from a file without collision geometry (it
    touches nothing), a link whose centre of mass lies far outside its collision geometry."""
    model, collision = robot.model, robot.collision_model
    if robot.urdf and not collision.ngeoms:
        warnings.warn(
            f"{robot.source}: no collision geometry: the robot touches nothing (a ground or obstacle is "
            "refused in its scene); give its links <collision> elements",
            GaussimWarning,
            stacklevel=5,
        )
    far = []
    for joint_id in range(1, model.njoints):
        com = model.inertias[joint_id].lever
        distances, sizes = [], []
        for g in collision.geometryObjects:
            if g.parentJoint == joint_id and not isinstance(g.geometry, UNBOUNDED):
                g.geometry.computeLocalAABB()
                box, point = g.geometry.aabb_local, g.placement.actInv(com)
                distances.append(
                    float(np.linalg.norm(np.maximum(np.maximum(box.min_ - point, point - box.max_), 0)))
                )
                sizes.append(g.geometry.aabb_radius)
        if (
            distances
            and model.inertias[joint_id].mass > 0
            and min(distances) > max(COM_OUTSIDE, max(sizes) / 2)
        ):
            far.append(f"'{_link(model, joint_id)}' ({min(distances):.3g} m)")
    if far:
        warnings.warn(
            f"{robot.source}: the centre of mass of the links {', '.join(far)} lies that far outside their "
            "collision geometry: check their <inertial> origin (the robot will tip or sink about it)",
            GaussimWarning,
            stacklevel=5,
        )


def hull_problem(points: np.ndarray) -> str:
    """Why a mesh's vertices ``points`` (n, 3) [m] have no convex hull ("" when they have one): fewer
    than 4, or all within one plane up to FLATNESS of their size (coal's qhull call crashes the
    process on such a mesh rather than raising)."""
    if len(points) < 4:
        return f"its mesh has {len(points)} vertices: a convex hull needs 4 that are not in one plane"
    centred = points - points.mean(axis=0)
    axes = np.linalg.svd(centred, full_matrices=False)[2]
    spans = np.ptp(centred @ axes.T, axis=0)  # along the principal axes, the widest first
    if spans[2] <= FLATNESS * max(spans[0], float(np.abs(points).max())):
        return (
            f"its mesh is flat (its vertices lie within {spans[2]:.3g} m of a plane over {spans[0]:.3g} m): "
            "a collision mesh needs a volume; give it a thickness, or use a box"
        )
    return ""


def _convex_hull(robot: Robot, geometry: pin.GeometryObject) -> None:
    """The convex hull of a mesh; where qhull's hull has a vertex with more neighbours than coal's hull
    can store, the hull without the points within HULL_COARSENING of it, with a warning."""
    problem = hull_problem(geometry.geometry.vertices())
    if problem:
        raise InvalidRobot(f"{robot.source}: collision geometry '{geometry.name}': {problem}")
    try:
        geometry.geometry.buildConvexHull(True, "Qt")
    except RuntimeError as err:
        if "Too many neighbors" not in str(err):
            raise InvalidRobot(
                f"{robot.source}: collision geometry '{geometry.name}': {_cause(err)}"
            ) from err
        geometry.geometry.buildConvexHull(True, f"Qt W{HULL_COARSENING:g}")
        warnings.warn(
            f"{robot.source}: collision geometry '{geometry.name}': its mesh's convex hull has a vertex with "
            "more neighbours than coal stores (255): the hull leaves out the points within "
            f"{1e3 * HULL_COARSENING:g} mm of it",
            GaussimWarning,
            stacklevel=5,
        )
