"""An SDF file (SDFormat 1.4 to 1.11) rewritten as a URDF, which Pinocchio's URDF parser then builds:
the Pinocchio of PyPI is built without SDFormat (``pin.WITH_SDFORMAT`` is False, so
``pin.buildModelsFromSdf`` cannot read a file).

One model is read (a ``<world>``'s static models, the ground planes, are left out): its links with
their inertial, collision and visual elements (box, sphere, cylinder, mesh), its revolute, continuous,
prismatic and fixed joints, and their poses as SDFormat places them (``relative_to``, ``<frame>``,
``degrees``, ``quat_xyzw``; a joint's pose in its child link; an axis in the joint frame, or in the
model frame for ``use_parent_model_frame`` and SDFormat 1.4). The model's own ``<pose>`` is not read:
the root link is the robot's base frame, as in a URDF. Anything else that changes the dynamics (other
joint types, closed loops, nested models) is refused naming its element.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from .exceptions import InvalidRobot

JOINT_TYPES = {"revolute": "revolute", "continuous": "continuous", "prismatic": "prismatic", "fixed": "fixed"}
SHAPES = ("box", "sphere", "cylinder", "mesh")
# SDFormat's default joint limits: a range this wide is no limit
UNLIMITED = 1e16
# the effort [N m] and velocity [rad/s] of a URDF joint that SDFormat leaves unlimited (-1): a URDF needs
# a number, and Pinocchio's URDF parser gives an unlimited free flyer this one
NO_LIMIT = float(np.finfo(float).max)
# where model:// URIs are looked up besides the package directories and the models folder
RESOURCE_PATHS = ("GZ_SIM_RESOURCE_PATH", "IGN_GAZEBO_RESOURCE_PATH", "GAZEBO_MODEL_PATH", "SDF_PATH")


@dataclass(frozen=True)
class Converted:
    """An SDF model as a URDF.

    Attributes:
        urdf: the URDF text, mesh files given by absolute paths.
        world_joint: the joint that attaches the model to the world, or None.
        notes: what the URDF leaves out of the file or fills in by SDFormat's defaults, each a sentence.
    """

    urdf: str
    world_joint: str | None
    notes: list[str]


def to_urdf(path: Path, package_dirs: Iterable[str] = ()) -> Converted:
    """The URDF of the SDF model at ``path``; raises :class:`InvalidRobot` naming the file and element
    for what it cannot read."""
    return _Reader(path, list(package_dirs)).convert()


class _Reader:
    def __init__(self, path: Path, package_dirs: list[str]) -> None:
        self.path = path
        self.package_dirs = package_dirs
        try:
            self.root = ET.parse(path).getroot()
        except ET.ParseError as err:
            raise InvalidRobot(f"{path}: not well-formed XML ({err})") from err
        if self.root.tag != "sdf":
            raise InvalidRobot(f"{path}: an SDF file's root element is <sdf>, got <{self.root.tag}>")
        major, _, minor = self.root.get("version", "1.11").partition(".")
        self.version = (int(major or 1), int(minor or 0))
        self.notes: list[str] = []
        self.frames: dict[str, tuple[pin.SE3, str]] = {}  # name: (pose, the frame it is relative to)

    def fail(self, where: str, message: str) -> InvalidRobot:
        return InvalidRobot(f"{self.path}: {where}: {message}")

    def convert(self) -> Converted:
        model = self.model()
        if model.find("model") is not None or model.find("include") is not None:
            raise self.fail(f"model '{model.get('name')}'", "nested models and <include> are not read")
        links = {link.get("name", ""): link for link in model.findall("link")}
        joints = model.findall("joint")
        self.world_link(links, joints)
        for name, link in links.items():
            self.frames[name] = self.pose(link, f"link '{name}'", "__model__")
        for joint in joints:
            name = joint.get("name", "")
            self.frames[name] = self.pose(
                joint, f"joint '{name}'", self.text(joint, "child", f"joint '{name}'")
            )
        for frame in model.findall("frame"):
            name = frame.get("name", "")
            self.frames[name] = self.pose(frame, f"frame '{name}'", frame.get("attached_to", "__model__"))

        parent_joint: dict[str, ET.Element] = {}
        world_joint = None
        for joint in joints:
            name, where = joint.get("name", ""), f"joint '{joint.get('name')}'"
            parent, child = self.text(joint, "parent", where), self.text(joint, "child", where)
            for role, target in (("parent", parent), ("child", child)):
                if target not in links and not (role == "parent" and target == "world"):
                    raise self.fail(
                        where, f"{role} link '{target}' does not exist; links: {', '.join(links)}"
                    )
            if child in parent_joint:
                other = parent_joint[child].get("name")
                raise self.fail(
                    where,
                    f"link '{child}' is also the child of joint '{other}': a closed kinematic loop, which "
                    "a URDF cannot hold (close it with a gaussim.LoopClosure)",
                )
            parent_joint[child] = joint
            if parent == "world":
                world_joint = name
        roots = [name for name in links if name not in parent_joint]
        if len(roots) + (world_joint is not None) != 1:
            loose = ", ".join(repr(r) for r in roots)
            raise self.fail(
                f"model '{model.get('name')}'",
                f"links {loose} have no parent joint: the model is not one tree (join them with joints)",
            )
        base = "world" if world_joint is not None else roots[0]
        frame_of = {name: self.placement(parent_joint[name].get("name", "")) for name in parent_joint}
        frame_of[base] = pin.SE3.Identity() if base == "world" else self.placement(base)

        robot = ET.Element("robot", name=model.get("name", self.path.stem))
        if base == "world":
            ET.SubElement(robot, "link", name="world")
        for name, link in links.items():
            robot.append(self.link(name, link, frame_of[name]))
        for joint in joints:
            robot.append(self.joint(joint, frame_of))
        bare = [name for name, link in links.items() if link.find("inertial") is None]
        if bare:
            self.notes.append(
                f"the links {', '.join(repr(b) for b in bare)} have no <inertial>: SDFormat's default, "
                "1 kg with a unit inertia [kg m^2], is used"
            )
        return Converted(ET.tostring(robot, encoding="unicode"), world_joint, self.notes)

    def world_link(self, links: dict[str, ET.Element], joints: list[ET.Element]) -> None:
        """Drop a link named 'world' that a joint names as its parent, when it is the world frame
        itself (bare: no <inertial> or <collision>, at the model's frame; PyBullet fixes such a massless
        base, pybullet_data's WSG 50 grippers); refuse another, which gaussim cannot tell from the world."""
        link = links.get("world")
        parents = [j.get("name", "") for j in joints if j.findtext("parent", "").strip() == "world"]
        if link is None or not parents:
            return
        named = ", ".join(repr(p) for p in parents)
        held = [f"<{tag}>" for tag in ("inertial", "collision") if link.find(tag) is not None]
        if held or not self.pose(link, "link 'world'", "__model__")[0].isIdentity():
            raise self.fail(
                "link 'world'",
                f"has the name of the world frame, which joint {named} names as its parent, and "
                f"{' and '.join(held) or 'a <pose>'} of its own: rename the link and that parent (the link "
                "is then the model's base), or leave it bare (the model is fixed to the world)",
            )
        del links["world"]
        unseen = (
            " (its <visual> is not drawn: the world frame carries none)"
            if link.find("visual") is not None
            else ""
        )
        self.notes.append(
            f"the link 'world' has no <inertial>: joint {named} attaches the model to the world{unseen}"
        )

    def model(self) -> ET.Element:
        """The one model that moves: the file's, or the non-static one of its world."""
        models = self.root.findall("model") + self.root.findall("world/model")
        moving = [m for m in models if self.flag(m, "static") is not True]
        static = [m.get("name", "") for m in models if m not in moving]
        if len(moving) != 1:
            names = ", ".join(repr(m.get("name")) for m in moving) or "none"
            raise InvalidRobot(
                f"{self.path}: gaussim reads one moving <model> per SDF file, this one has {names}"
                + (" (<include> is not read)" if self.root.find("world/include") is not None else "")
            )
        if static:
            self.notes.append(
                f"the static models {', '.join(repr(s) for s in static)} are left out (a gaussim Scene holds "
                "the ground and the fixed obstacles)"
            )
        return moving[0]

    def link(self, name: str, link: ET.Element, frame: pin.SE3) -> ET.Element:
        """A URDF link whose frame is ``frame`` (its parent joint's), in the model frame."""
        out = ET.Element("link", name=name)
        inertial = link.find("inertial")
        body = ET.SubElement(out, "inertial")
        if inertial is not None:
            where = f"link '{name}' <inertial>"
            placement = self.placement_in(inertial, where, name)
            mass = self.number(inertial, "mass", where, 1.0)
            moments = {
                key: self.number(
                    inertial.find("inertia"), key, where, 1.0 if key in ("ixx", "iyy", "izz") else 0.0
                )
                for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
            }
        else:
            placement, mass = self.placement(name), 1.0
            moments = {"ixx": 1.0, "iyy": 1.0, "izz": 1.0, "ixy": 0.0, "ixz": 0.0, "iyz": 0.0}
        body.append(_origin(frame.actInv(placement)))
        ET.SubElement(body, "mass", value=repr(mass))
        ET.SubElement(body, "inertia", {k: repr(v) for k, v in moments.items()})
        for kind in ("collision", "visual"):
            for element in link.findall(kind):
                where = f"link '{name}' <{kind} {element.get('name', '')}>"
                shape = self.geometry(element, where)
                if shape is None:
                    continue
                item = ET.SubElement(out, kind, name=element.get("name", f"{name}_{kind}"))
                item.append(_origin(frame.actInv(self.placement_in(element, where, name))))
                item.append(shape)
                diffuse = element.findtext("material/diffuse")
                if kind == "visual" and diffuse:
                    material = ET.SubElement(item, "material", name=f"{name}_{element.get('name', '')}")
                    ET.SubElement(material, "color", rgba=" ".join(diffuse.split()))
        return out

    def geometry(self, element: ET.Element, where: str) -> ET.Element | None:
        geometry = element.find("geometry")
        shapes = list(geometry) if geometry is not None else []
        if not shapes or shapes[0].tag == "empty":
            return None
        shape = shapes[0]
        out = ET.Element("geometry")
        if shape.tag == "box":
            ET.SubElement(out, "box", size=" ".join(repr(x) for x in self.numbers(shape, "size", where, 3)))
        elif shape.tag == "sphere":
            ET.SubElement(out, "sphere", radius=repr(self.number(shape, "radius", where)))
        elif shape.tag == "cylinder":
            radius, length = self.number(shape, "radius", where), self.number(shape, "length", where)
            ET.SubElement(out, "cylinder", radius=repr(radius), length=repr(length))
        elif shape.tag == "mesh":
            if shape.find("submesh") is not None:
                raise self.fail(where, "<submesh> is not read: export the submesh to its own file")
            scale = self.numbers(shape, "scale", where, 3) if shape.find("scale") is not None else [1.0] * 3
            mesh = self.mesh(self.text(shape, "uri", where), where)
            ET.SubElement(out, "mesh", filename=mesh, scale=" ".join(repr(x) for x in scale))
        else:
            raise self.fail(where, f"geometry <{shape.tag}> is not read; known: {', '.join(SHAPES)}")
        return out

    def mesh(self, uri: str, where: str) -> str:
        """The absolute path of a mesh URI: ``model://`` in the package directories, the resource
        paths of Gazebo and the models folder holding this file's; ``package://`` in the package
        directories and ROS_PACKAGE_PATH; a relative path in this file's folder."""
        env = [d for key in RESOURCE_PATHS for d in os.environ.get(key, "").split(os.pathsep) if d]
        ros = [d for d in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if d]
        if uri.startswith("model://"):
            relative = uri[len("model://") :]
            folders = [*self.package_dirs, *env, str(self.path.parent.parent)]
            candidates = [Path(d) / relative for d in folders]
        elif uri.startswith("package://"):
            relative = uri[len("package://") :]
            candidates = [Path(d) / relative for d in (*self.package_dirs, *ros)]
        else:
            local = Path(uri.removeprefix("file://"))
            candidates = [local if local.is_absolute() else self.path.parent / local]
        for candidate in candidates:
            if candidate.is_file():
                return str(candidate.resolve())
        looked = ", ".join(str(c) for c in candidates)
        raise self.fail(where, f"mesh '{uri}' not found (looked in: {looked})")

    def joint(self, joint: ET.Element, frame_of: dict[str, pin.SE3]) -> ET.Element:
        name, kind = joint.get("name", ""), joint.get("type", "")
        where = f"joint '{name}'"
        if kind not in JOINT_TYPES:
            raise self.fail(where, f"type '{kind}' is not read; known: {', '.join(JOINT_TYPES)}")
        parent, child = self.text(joint, "parent", where), self.text(joint, "child", where)
        placement = self.placement(name)
        axis = joint.find("axis")
        lower = self.number(axis, "limit/lower", where, -UNLIMITED) if axis is not None else -UNLIMITED
        upper = self.number(axis, "limit/upper", where, UNLIMITED) if axis is not None else UNLIMITED
        limited = lower > -UNLIMITED or upper < UNLIMITED
        if kind == "revolute" and not limited:
            kind = "continuous"
        out = ET.Element("joint", name=name, type=JOINT_TYPES[kind])
        out.append(_origin(frame_of[parent].actInv(placement)))
        ET.SubElement(out, "parent", link=parent)
        ET.SubElement(out, "child", link=child)
        if kind == "fixed":
            return out
        if axis is None:
            raise self.fail(where, f"a {kind} joint needs an <axis>")
        direction = np.array(self.numbers(axis, "xyz", where, 3))
        if np.linalg.norm(direction) == 0:
            raise self.fail(where, "<axis><xyz> is the zero vector")
        direction = self.axis_frame(axis, placement, where) @ (direction / np.linalg.norm(direction))
        ET.SubElement(out, "axis", xyz=" ".join(repr(float(x)) for x in direction))
        effort = self.number(axis, "limit/effort", where, -1.0)
        velocity = self.number(axis, "limit/velocity", where, -1.0)
        ET.SubElement(
            out,
            "limit",
            lower=repr(lower),
            upper=repr(upper),
            effort=repr(effort if effort >= 0 else NO_LIMIT),
            velocity=repr(velocity if velocity >= 0 else NO_LIMIT),
        )
        damping = self.number(axis, "dynamics/damping", where, 0.0)
        friction = self.number(axis, "dynamics/friction", where, 0.0)
        ET.SubElement(out, "dynamics", damping=repr(damping), friction=repr(friction))
        return out

    def axis_frame(self, axis: ET.Element, joint: pin.SE3, where: str) -> np.ndarray:
        """The rotation from the frame the axis is written in to the joint frame, shape (3, 3)."""
        xyz = axis.find("xyz")
        expressed = xyz.get("expressed_in") if xyz is not None else None
        if expressed is not None:
            frame = pin.SE3.Identity() if expressed in ("__model__", "world") else self.placement(expressed)
            return joint.rotation.T @ frame.rotation
        if self.flag(axis, "use_parent_model_frame") or self.version < (1, 5):
            return joint.rotation.T
        return np.eye(3)

    def pose(self, element: ET.Element, where: str, default: str) -> tuple[pin.SE3, str]:
        """An element's pose and the frame it is relative to."""
        pose = element.find("pose")
        if pose is None:
            return pin.SE3.Identity(), default
        if pose.get("rotation_format", "euler_rpy") == "quat_xyzw":
            x, y, z, qx, qy, qz, qw = _parse(self, f"{where} <pose>", pose.text or "", 7)
            rotation = pin.Quaternion(qw, qx, qy, qz).normalized().matrix()
        else:
            x, y, z, *rpy = _parse(self, f"{where} <pose>", pose.text or "", 6)
            if pose.get("degrees", "false") in ("true", "1"):
                rpy = [math.radians(a) for a in rpy]
            rotation = pin.rpy.rpyToMatrix(*rpy)
        return pin.SE3(rotation, np.array([x, y, z])), pose.get("relative_to") or pose.get("frame") or default

    def placement(self, name: str, seen: tuple[str, ...] = ()) -> pin.SE3:
        """The placement of a named frame in the model frame."""
        if name in ("__model__", "world", ""):
            return pin.SE3.Identity()
        if name not in self.frames:
            raise InvalidRobot(f"{self.path}: no frame '{name}'; known: {', '.join(sorted(self.frames))}")
        if name in seen:
            raise InvalidRobot(f"{self.path}: the poses of {' -> '.join((*seen, name))} form a cycle")
        local, relative_to = self.frames[name]
        return self.placement(relative_to, (*seen, name)) * local

    def placement_in(self, element: ET.Element, where: str, link: str) -> pin.SE3:
        """The placement in the model frame of an element of ``link`` (its pose is in the link's)."""
        local, relative_to = self.pose(element, where, link)
        return self.placement(relative_to) * local

    def text(self, element: ET.Element, key: str, where: str) -> str:
        value = element.findtext(key)
        if value is None or not value.strip():
            raise self.fail(where, f"<{key}> is missing")
        return value.strip()

    def numbers(self, element: ET.Element | None, key: str, where: str, count: int) -> list[float]:
        return _parse(
            self, f"{where} <{key}>", self.text(element, key, where) if element is not None else "", count
        )

    def number(self, element: ET.Element | None, key: str, where: str, default: float | None = None) -> float:
        if element is None or element.find(key) is None:
            if default is None:
                raise self.fail(where, f"<{key}> is missing")
            return default
        return self.numbers(element, key, where, 1)[0]

    def flag(self, element: ET.Element, key: str) -> bool | None:
        value = element.findtext(key)
        return None if value is None else value.strip() in ("1", "true")


def _parse(reader: _Reader, where: str, text: str, count: int) -> list[float]:
    try:
        values = [float(x) for x in text.split()]
    except ValueError:
        values = []
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise reader.fail(where, f"must be {count} finite number(s), got '{text.strip()}'")
    return values


def _origin(placement: pin.SE3) -> ET.Element:
    rpy = pin.rpy.matrixToRpy(placement.rotation)
    return ET.Element(
        "origin",
        xyz=" ".join(repr(float(x)) for x in placement.translation),
        rpy=" ".join(repr(float(x)) for x in rpy),
    )
