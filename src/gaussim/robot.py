"""Robots: a Pinocchio model with its collision and visual geometry, loaded from a URDF."""

from __future__ import annotations

import importlib.resources
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin

from .exceptions import FrameNotFound, GaussimWarning, GeometryNotFound, InvalidRobot, RobotNotFound
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


@dataclass(frozen=True)
class Robot:
    """An immutable robot model.

    Attributes:
        name: the name it was loaded by.
        model: Pinocchio kinematic/dynamic model.
        collision_model: Pinocchio geometry model used for contacts.
        visual_model: Pinocchio geometry model used for display.
        urdf: path of the URDF file.
        package_dirs: directories where ``package://`` meshes are resolved.
        reference_configurations: named configurations (e.g. ``standing``), shape (nq,) each.
    """

    name: str
    model: pin.Model
    collision_model: pin.GeometryModel
    visual_model: pin.GeometryModel
    urdf: str
    package_dirs: tuple[str, ...] = ()
    reference_configurations: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def floating(self) -> bool:
        """True when the root joint is a free flyer."""
        return self.model.njoints > 1 and self.model.joints[1].shortname() == "JointModelFreeFlyer"

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
) -> Robot:
    """Load a robot.

    Args:
        name: a URDF path, a robot of the project's ``robots/`` folder (``"ball"``), or an
            example-robot-data name (``"solo12"``, ``"talos"``); a name in both is the project's
            robot, with a warning that names the other.
        package_dirs: where ``package://`` meshes of a URDF are looked up.
        floating_base: add a free-flyer root joint. Default: example-robot-data decides for its
            robots (mobile robots float); a URDF path is fixed-base unless told.

    Raises:
        RobotNotFound: the name is none of the above (the message lists the known names).
        InvalidRobot: the URDF could not be parsed or describes an unusable model.
    """
    path = Path(name)
    local = ROBOTS_DIR / f"{name}.urdf"
    if path.suffix == ".urdf" or path.exists():
        if not path.is_file():
            raise RobotNotFound(str(name), _known_names())
        return _from_urdf(path, package_dirs, bool(floating_base))
    if local.is_file():
        if str(name) in example_robot_names():  # the shipped robot comes first: say so
            warnings.warn(
                f"robot '{name}' is gaussim's shipped {local.name}; load example-robot-data's robot of "
                f"that name by its URDF path (example_robot_data.robots_loader.ROBOTS['{name}']().df_path)",
                GaussimWarning,
                stacklevel=2,
            )
        return _from_urdf(local, (str(ROBOTS_DIR), *package_dirs), bool(floating_base))
    known = example_robot_names()
    if str(name) not in known:
        raise RobotNotFound(str(name), _known_names())
    from example_robot_data.robots_loader import ROBOTS

    loader = ROBOTS[str(name)]()
    model = loader.robot.model
    if floating_base is not None and floating_base != loader.free_flyer:
        base = "floating" if loader.free_flyer else "fixed"
        raise InvalidRobot(
            f"robot '{name}' has a {base} base in example-robot-data; to change it, load its "
            f"URDF by path: load_robot('{loader.df_path}', floating_base={floating_base})"
        )
    configurations = {e.key(): np.array(e.data()) for e in model.referenceConfigurations}
    return _finish(
        str(name),
        model,
        loader.robot.collision_model,
        loader.robot.visual_model,
        str(loader.df_path),
        (str(loader.model_path),),
        configurations,
    )


def as_robot(source: object, name: str | None = None) -> Robot:
    """A :class:`Robot` from what a user holds: a Robot (as is), a URDF path or a robot name
    (:func:`load_robot`), or a ``(model, collision_model, visual_model)`` tuple of Pinocchio models.

    Raises:
        InvalidRobot: ``source`` is none of these, or its model is not simulable.
    """
    if isinstance(source, Robot):
        return source
    if isinstance(source, (str, os.PathLike)):
        return load_robot(source)
    if isinstance(source, tuple) and len(source) == 3 and isinstance(source[0], pin.Model):
        model, collision, visual = source
        return _finish(name or model.name or "robot", model, collision, visual, "", (), {})
    raise InvalidRobot(
        f"cannot make a robot of {type(source).__name__} {name or ''}: give a gaussim.Robot, a URDF "
        "path, a robot name, or a (pinocchio.Model, collision GeometryModel, visual GeometryModel) tuple"
    )


def _known_names() -> list[str]:
    local = [p.stem for p in ROBOTS_DIR.glob("*.urdf")] if ROBOTS_DIR.is_dir() else []
    return local + example_robot_names()


def _from_urdf(
    path: Path, package_dirs: tuple[str, ...] | list[str], floating: bool, name: str | None = None
) -> Robot:
    dirs = [str(d) for d in (*package_dirs, path.parent)]
    check_urdf(path)
    try:
        if floating:
            model, collision, visual = pin.buildModelsFromUrdf(str(path), dirs, pin.JointModelFreeFlyer())
        else:
            model, collision, visual = pin.buildModelsFromUrdf(str(path), dirs)
    except (RuntimeError, ValueError, OSError) as err:
        cause = mesh_fault(path, dirs, str(err)) or str(err)
        raise InvalidRobot(f"{path}: cannot build a model from this URDF: {cause}") from err
    return _finish(name or path.stem, model, collision, visual, str(path), tuple(dirs), {})


def _finish(
    name: str,
    model: pin.Model,
    collision: pin.GeometryModel,
    visual: pin.GeometryModel,
    urdf: str,
    package_dirs: tuple[str, ...],
    configurations: dict[str, np.ndarray],
) -> Robot:
    """Check the model is simulable and prepare the collision geometry for contact detection."""
    if model.nv == 0:
        raise InvalidRobot(f"{urdf or name}: the model has no degree of freedom")
    for joint_id in range(1, model.njoints):
        inertia = model.inertias[joint_id]
        if not np.isfinite(inertia.mass) or inertia.mass < 0:
            raise InvalidRobot(
                f"{urdf or name}: body of joint '{model.names[joint_id]}' has mass {inertia.mass}"
            )
    _check_inertias(model, urdf or name)
    for joint_id in range(1, model.njoints):
        joint = model.joints[joint_id]
        lower = model.lowerPositionLimit[joint.idx_q : joint.idx_q + joint.nq]
        upper = model.upperPositionLimit[joint.idx_q : joint.idx_q + joint.nq]
        if np.any(lower > upper):
            raise InvalidRobot(
                f"{urdf or name}: joint '{model.names[joint_id]}' has its lower limit {lower.tolist()} "
                f"above its upper limit {upper.tolist()}"
            )
    mimics = (
        [(j, target) for j, target in mimic_joints(Path(urdf)) if model.existJointName(j)] if urdf else []
    )
    if mimics:
        listed = ", ".join(f"'{j}' (mimics '{target}')" for j, target in mimics)
        warnings.warn(
            f"{urdf}: gaussim does not honour <mimic>: the joints {listed} move as free joints",
            GaussimWarning,
            stacklevel=3,
        )
    data = model.createData()
    mass_matrix = pin.crba(model, data, pin.neutral(model))
    if not np.all(np.isfinite(mass_matrix)) or np.linalg.eigvalsh(mass_matrix).min() <= 0:
        raise InvalidRobot(
            f"{urdf or name}: the mass matrix is not positive definite at the neutral "
            "configuration (a moving body without mass or inertia?)"
        )
    for geometry in collision.geometryObjects:
        if isinstance(geometry.geometry, coal.BVHModelBase):
            # Contacts are detected on the convex hull of a mesh (coal's GJK/EPA needs convex shapes
            # to give signed distances and contact patches); built once here.
            geometry.geometry.buildConvexHull(True, "Qt")
    return Robot(name, model, collision, visual, urdf, package_dirs, configurations)


def _check_inertias(model: pin.Model, where: str) -> None:
    """Refuse a body whose principal moments of inertia are negative (a run gains energy) or break the
    triangle inequality I1 + I2 >= I3 (no mass distribution has them). Checked on Pinocchio's bodies,
    each the sum of a moving link and the links fixed to it: the example-robot-data robots whose URDF
    links break it (allegro, go1, anymal) have valid sums."""
    for joint_id in range(1, model.njoints):
        moments = np.linalg.eigvalsh(model.inertias[joint_id].inertia)
        tolerance = INERTIA_RTOL * np.abs(moments).max() + INERTIA_ATOL
        if moments[0] >= -tolerance and moments[0] + moments[1] >= moments[2] - tolerance:
            continue
        body = next(
            (f.name for f in model.frames if f.type == pin.FrameType.BODY and f.parentJoint == joint_id),
            model.names[joint_id],
        )
        fault = "a negative one" if moments[0] < -tolerance else "I1 + I2 < I3"
        raise InvalidRobot(
            f"{where}: link '{body}' (the body of joint '{model.names[joint_id]}') has principal moments of "
            f"inertia {', '.join(f'{m:.6g}' for m in moments)} [kg m^2]: {fault}, which no body has "
            "(check the <inertia> of it and of the links fixed to it)"
        )
