"""A URDF read before Pinocchio builds its model, so that a broken file gets an error naming the file
and the element: Pinocchio's parser (urdfdom) rejects some faults with a generic message and, worse,
drops a link's collision element whose origin does not parse (measured: ``xyz="0 nan 0"``), leaving
a robot that falls through the ground without a word."""

from __future__ import annotations

import math
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

from .exceptions import InvalidRobot

JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
# the numeric attributes of each element, and how many numbers each holds
NUMBERS = {
    "origin": {"xyz": 3, "rpy": 3},
    "axis": {"xyz": 3},
    "mass": {"value": 1},
    "inertia": {name: 1 for name in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")},
    "box": {"size": 3},
    "sphere": {"radius": 1},
    "cylinder": {"radius": 1, "length": 1},
    "limit": {name: 1 for name in ("lower", "upper", "effort", "velocity")},
}


def check_urdf(path: Path) -> None:
    """Raise :class:`InvalidRobot` naming the file and the element when the URDF at ``path`` is not
    well-formed XML, has no link, holds a number that is not finite, a negative mass, or a joint of
    unknown type."""
    root = _root(path)
    if root.find("link") is None:
        found = ", ".join(sorted({f"<{e.tag}>" for e in root})) or "nothing"
        raise InvalidRobot(f"{path}: no <link> element, of which a URDF robot is made (found: {found})")
    for where, element in _elements(path):
        if element.tag == "joint" and element.get("type") not in JOINT_TYPES:
            raise InvalidRobot(
                f"{path}: {where} has type '{element.get('type')}'; known: {', '.join(JOINT_TYPES)}"
            )
        for attribute, count in NUMBERS.get(element.tag, {}).items():
            text = element.get(attribute)
            if text is not None:
                _numbers(path, f"{where}: <{element.tag} {attribute}>", text, count)
        if element.tag == "mass" and float(element.get("value", "0")) < 0:
            raise InvalidRobot(f"{path}: {where}: negative mass {element.get('value')}")


def mimic_joints(path: Path) -> list[tuple[str, str]]:
    """(joint, the joint it mimics) for every joint of the URDF at ``path`` with a <mimic> element."""
    return [
        (owner.get("name", ""), mimic.get("joint", ""))
        for owner in _root(path)
        if owner.tag == "joint"
        for mimic in owner.iter("mimic")
    ]


def mesh_fault(path: Path, package_dirs: list[str], error: str) -> str | None:
    """What is wrong with the meshes of the URDF at ``path``, given the ``error`` Pinocchio raised
    building it: the first mesh that is not where Pinocchio looks for it (``package://`` against
    ``package_dirs`` and ROS_PACKAGE_PATH, other paths against the URDF's folder), or the mesh the
    loader (assimp, through coal) could not read, with its reason; each named with its element.
    None when neither explains the error."""
    ros = [d for d in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if d]
    unreadable = re.search(r"Could not load resource (.+)\n(.*)", error)
    for where, element in _elements(path):
        filename = element.get("filename", "") if element.tag == "mesh" else ""
        if not filename:
            continue
        if filename.startswith("package://"):
            relative = filename[len("package://") :]
            candidates = [Path(d) / relative for d in (*package_dirs, *ros)]
        else:
            local = Path(filename.removeprefix("file://"))
            candidates = [local if local.is_absolute() else path.parent / local]
        found = [c for c in candidates if c.is_file()]
        if not found:
            looked = ", ".join(str(c) for c in candidates)
            return f"{where}: mesh file '{filename}' not found (looked in: {looked})"
        if unreadable and Path(unreadable[1]).resolve() == found[0].resolve():
            reason = unreadable[2].strip() or "unknown format"
            return f"{where}: mesh file '{filename}' cannot be read: {reason}"
    return None


def _root(path: Path) -> ET.Element:
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as err:
        raise InvalidRobot(f"{path}: not well-formed XML ({err})") from err


def _elements(path: Path) -> Iterator[tuple[str, ET.Element]]:
    """(the link or joint it belongs to, element) for every element of the URDF's links and joints
    (a <transmission> or <gazebo> element, which the model ignores, names joints in elements of its own:
    ``<transmission><joint name="...">`` is no joint)."""
    for owner in _root(path):
        if owner.tag not in ("link", "joint"):
            continue
        where = f"{owner.tag} '{owner.get('name')}'"
        for element in owner.iter():
            yield where, element


def _numbers(path: Path, where: str, text: str, count: int) -> None:
    parts = text.split()
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise InvalidRobot(f"{path}: {where} must be {count} finite number(s), got '{text}'")
