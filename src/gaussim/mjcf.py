"""An MJCF file read beside Pinocchio's parser, which builds the model (``pin.buildModelFromMJCF``) but
departs from MuJoCo's reading of the same file without a word (measured on Pinocchio 4.1 against
MuJoCo on the same files): it reads only the first body of ``<worldbody>``; gives each mesh geom
1 kg and a unit inertia whatever its mass; takes every ``range`` as a limit, ``limited="false"``
or not, subtracts ``ref`` from it, and converts a slide joint's range from degrees; reads the first
``<asset>`` section alone (dm_control's files, whose ``<include>``s bring several: their materials
are then missing); takes a ``<default>`` class's geom density but not its mass; leaves the geoms that
collide with nothing (contype = conaffinity = 0) out of their body's inertia; ignores ``<compiler
settotalmass>``. This module finds those cases in the file: the first two are reported, the limits
are set as MuJoCo sets them, and Pinocchio reads a rewrite of the file that states the rest
(:func:`for_pinocchio`, :func:`set_total_mass`)."""

from __future__ import annotations

import copy
import math
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pinocchio as pin

from .exceptions import InvalidRobot, _meant

JOINT_TYPES = ("hinge", "slide", "ball", "free")
# the numeric attributes of the elements that place and weigh bodies
NUMERIC = (
    "pos", "quat", "euler", "axisangle", "xyaxes", "zaxis", "axis", "fromto", "size", "range", "ref",
    "mass", "density", "diaginertia", "fullinertia", "armature", "damping",
)  # fmt: skip


def read(path: Path, main: Path | None = None) -> ET.Element:
    """The ``<mujoco>`` element of the MJCF at ``path``, its ``<include>`` files inlined in place (each
    found, as MuJoCo finds it, in the folder of the ``main`` file, default ``path``'s, else in the
    including file's); raises :class:`InvalidRobot` naming the file when it is not well-formed XML or
    not an MJCF, or an included file is missing."""
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as err:
        raise InvalidRobot(f"{path}: not well-formed XML ({err})") from err
    if root.tag != "mujoco":
        raise InvalidRobot(f"{path}: an MJCF file's root element is <mujoco>, got <{root.tag}>")
    _inline(root, path, path.parent if main is None else main)
    return root


def _inline(element: ET.Element, path: Path, main: Path) -> None:
    """``element`` of the file at ``path`` with each ``<include>`` below it replaced by the included
    file's elements, in order."""
    children = []
    for child in element:
        if child.tag != "include":
            _inline(child, path, main)
            children.append(child)
            continue
        file = child.get("file", "")
        found = next((d / file for d in (main, path.parent) if file and (d / file).is_file()), None)
        if found is None:
            folders = " or ".join(dict.fromkeys(str(d) for d in (main, path.parent)))
            raise InvalidRobot(f'{path}: <include file="{file}">: no such file in {folders}')
        children.extend(read(found, main))
    element[:] = children


def check_file(path: Path, root: ET.Element) -> None:
    """Raise :class:`InvalidRobot` naming the element for what Pinocchio's parser would take without a
    word or with an error naming nothing: a number that is not finite, a joint of unknown type, a
    world without bodies, global coordinates (which MuJoCo 3 refuses too), ``<frame>`` and
    ``<replicate>`` (whose bodies and geoms Pinocchio leaves out)."""
    if compiler(root, "coordinate", "local") == "global":
        raise InvalidRobot(
            f'{path}: <compiler coordinate="global"> is not read (MuJoCo 3 refuses it too): convert the file '
            "to local coordinates (load it in MuJoCo 2.3.3 or older and save it with mujoco.mj_saveLastXML)"
        )
    for tag in ("frame", "replicate"):
        found = next(root.iter(tag), None)
        if found is not None:
            raise InvalidRobot(
                f"{path}: {_named(found)}: Pinocchio's MJCF reader leaves out the bodies and geoms of a "
                f"<{tag}>: move them into its parent body (MuJoCo's mj_saveLastXML writes them out)"
            )
    for element in root.iter():
        for key in NUMERIC:
            text = element.get(key)
            if text is None:
                continue
            try:
                values = [float(x) for x in text.split()]
            except ValueError:
                values = []
            if not values or not all(math.isfinite(v) for v in values):
                raise InvalidRobot(f"{path}: {_named(element)}: {key} must be finite numbers, got '{text}'")
    defaults = _defaults(root)
    for body, classname in _bodies_with_class(root, defaults):
        for joint in body.findall("joint"):
            kind = _attribute(joint, "type", joint.get("class", classname), defaults, "hinge")
            if kind not in JOINT_TYPES:
                raise InvalidRobot(
                    f"{path}: {_named(joint)} of body '{body.get('name', '')}' has type '{kind}'; known: "
                    f"{', '.join(JOINT_TYPES)}"
                )
    if not bodies(root):
        raise InvalidRobot(f"{path}: <worldbody> has no <body>: nothing in it moves")


@contextmanager
def for_pinocchio(path: Path, root: ET.Element, body: str | int | None = None) -> Iterator[tuple[str, str]]:
    """(the file Pinocchio builds the model from, the one it builds the geometry from): ``root`` (the
    file at ``path``, its includes inlined) with one top-level body of ``<worldbody>``, ``body`` (by
    name or place; the first when None; the world's own geoms go with the first), its keyframes cut
    to that body's coordinates, its ``<asset>`` sections merged into one and its asset folders
    absolute; for the model, besides, each geom's mass as its ``<default>`` class gives it, and every
    geom counted in its body's inertia (see the module's docstring). Temporary files, removed when the
    block ends."""
    tree = copy.deepcopy(root)
    _one_body(path, tree, body)
    tops = tree.findall("default")
    if not tops:  # before the bodies, which Pinocchio reads in order
        tops = [ET.Element("default")]
        tree.insert(0, tops[0])
    for top in tops:
        top.set("class", top.get("class", "main"))  # MuJoCo's name of it, which Pinocchio does not know
    sections = tree.findall("asset")
    for section in sections[1:]:
        sections[0].extend(list(section))
        tree.remove(section)
    _absolute_folders(tree, path.parent)
    weighed = copy.deepcopy(tree)
    defaults, groups = _defaults(weighed), _weighed_groups(weighed)
    for element, classname in _bodies_with_class(weighed, defaults):
        for geom in element.findall("geom"):
            mass = _mass(geom, geom.get("class", classname), defaults, groups)
            if mass == 0.0:  # Pinocchio would weigh a mesh 1 kg, any geom of another group
                element.remove(geom)
                continue
            if mass is not None:
                geom.set("mass", repr(mass))
            # MuJoCo weighs every geom, whether it collides or not
            geom.set("contype", "1")
            geom.set("conaffinity", "1")
    with tempfile.TemporaryDirectory(prefix="gaussim-mjcf-") as folder:
        model, geometry = Path(folder, path.name), Path(folder, "geometry-" + path.name)
        ET.ElementTree(weighed).write(model)
        ET.ElementTree(tree).write(geometry)
        yield str(model), str(geometry)


def top_index(path: Path, root: ET.Element, name: str | int | None) -> int:
    """The place among the top-level bodies of ``<worldbody>`` of the body ``name`` (by name or place;
    the first when None); raises :class:`InvalidRobot` for a name the file does not have."""
    if name is None or isinstance(name, int):
        return name or 0
    names = [str(b.get("name", "")) for b in bodies(root)]
    if name not in names:
        listed = ", ".join(repr(n) for n in names)
        raise InvalidRobot(
            f"{path}: no top-level body '{name}' in <worldbody>{_meant(name, names)}; its bodies: {listed}"
        )
    return names.index(name)


def _one_body(path: Path, root: ET.Element, name: str | int | None) -> None:
    """Keep the top-level body ``name`` of ``root`` (see :func:`top_index`) and cut each keyframe's
    qpos to its coordinates (MuJoCo's qpos holds every body's, in their order, where Pinocchio's
    reader wants the model's alone: "Keyframe size does not match model size")."""
    top = bodies(root)
    index = top_index(path, root, name)
    kept = top[index]
    defaults = _defaults(root)
    sizes = [_coordinates(b, "main", defaults) for b in top]
    for world in root.iter("worldbody"):
        for element in list(world):
            # the world's own geoms are the first body's robot's (as a file of one body has them)
            if (element.tag == "body" and element is not kept) or (
                element.tag == "geom" and kept is not top[0]
            ):
                world.remove(element)
    if len(top) == 1:
        return
    offset, size = sum(sizes[:index]), sizes[index]
    for key in root.iter("key"):
        for other in ("qvel", "act", "ctrl", "mpos", "mquat"):  # sized by the whole file too
            key.attrib.pop(other, None)
        values = key.get("qpos", "").split()
        if len(values) >= offset + size:
            key.set("qpos", " ".join(values[offset : offset + size]))
        elif "qpos" in key.attrib:  # MuJoCo fills the rest with qpos0, which the file does not state
            key.attrib.pop("qpos")


# the qpos size of each joint type (MuJoCo's: a free joint's position and quaternion, a ball's quaternion)
COORDINATES = {"free": 7, "ball": 4, "hinge": 1, "slide": 1}


def _coordinates(body: ET.Element, classname: str, defaults: dict[str, tuple[ET.Element, str | None]]) -> int:
    """The qpos size of ``body`` and the bodies below it, as MuJoCo counts it."""
    classname = body.get("childclass", classname)
    count = 7 * len(body.findall("freejoint"))
    for joint in body.findall("joint"):
        count += COORDINATES.get(
            _attribute(joint, "type", joint.get("class", classname), defaults, "hinge"), 0
        )
    return count + sum(_coordinates(child, classname, defaults) for child in body.findall("body"))


def _absolute_folders(root: ET.Element, base: Path) -> None:
    """One ``<compiler>`` first in ``root`` (Pinocchio reads the first alone), of every attribute as MuJoCo
    takes it (the last given wins), its mesh and texture folders absolute: each relative to ``base``,
    the file's folder, and ``assetdir`` where not given (as MuJoCo takes them), so that a copy of the
    file elsewhere finds its assets."""
    base = base.absolute()
    merged: dict[str, str] = {}
    for parent in list(root.iter()):
        for settings in parent.findall("compiler"):
            merged.update(settings.attrib)
            parent.remove(settings)
    assets = merged.pop("assetdir", "")
    for key in ("meshdir", "texturedir"):
        merged[key] = str(base / merged.get(key, assets))
    root.insert(0, ET.Element("compiler", merged))


def total_mass(root: ET.Element) -> float | None:
    """``<compiler settotalmass>`` [kg], or None when not positive (MuJoCo then leaves the masses)."""
    total = float(compiler(root, "settotalmass", "-1"))
    return total if total > 0 else None


def set_total_mass(model: pin.Model, factor: float) -> None:
    """Scale every body's mass and inertia by ``factor``, as MuJoCo's compiler does for ``<compiler
    settotalmass>`` (the factor that brings the whole file's mass to it), the bodies welded to the world
    (Pinocchio's universe, joint 0) too."""
    for j in range(model.njoints):
        inertia = model.inertias[j]
        model.inertias[j] = pin.Inertia(factor * inertia.mass, inertia.lever, factor * inertia.inertia)


def compiler(root: ET.Element, attribute: str, default: str) -> str:
    """A ``<compiler>`` attribute (the last one given wins, as in MuJoCo)."""
    values = [c.get(attribute) for c in root.iter("compiler") if c.get(attribute) is not None]
    return str(values[-1]) if values else default


def bodies(root: ET.Element) -> list[ET.Element]:
    """The top-level bodies of ``<worldbody>``."""
    return [b for world in root.iter("worldbody") for b in world.findall("body")]


def check(path: Path, root: ET.Element, body: str | None = None) -> list[str]:
    """Raise :class:`InvalidRobot` when a body of the loaded top-level body ``body`` (the first when
    None) takes its inertia from a mesh geom that weighs (one that collides with nothing too; Pinocchio
    gives such a geom 1 kg and a unit inertia [kg m^2]); return what the model leaves out of the file:
    the top-level bodies after the first (when no ``body`` of them was chosen) and the ``<equality>``
    constraints, each a sentence."""
    from_geoms = compiler(root, "inertiafromgeom", "auto")
    defaults, groups = _defaults(root), _weighed_groups(root)
    loaded = bodies(root)[top_index(path, root, body)]
    meshes = sorted(
        {
            str(element.get("name", ""))
            for element, classname in _bodies_with_class(root, defaults, [loaded])
            if from_geoms == "true" or element.find("inertial") is None
            for geom in element.findall("geom")
            if _attribute(geom, "type", geom.get("class", classname), defaults, "sphere") == "mesh"
            and _mass(geom, geom.get("class", classname), defaults, groups) != 0.0
        }
    )
    if from_geoms != "false" and meshes:
        raise InvalidRobot(
            f"{path}: the bodies {', '.join(repr(b) for b in meshes)} take their inertia from mesh geoms, "
            "which Pinocchio's MJCF parser does not compute (it gives each 1 kg and a unit inertia): give "
            'them an <inertial> (MuJoCo writes every body\'s: add saveinertial="true" to <compiler>, load '
            "the file with mujoco.MjModel.from_xml_path and save it with mujoco.mj_saveLastXML)"
        )
    left_out = []
    top = bodies(root)
    if len(top) > 1 and body is None:
        names = ", ".join(repr(b.get("name", "")) for b in top[1:])
        left_out.append(
            f"Pinocchio's MJCF parser reads one body of <worldbody>, the first ('{top[0].get('name', '')}'): "
            f"the bodies {names} are left out (load each with gaussim.load_robot(path, body=...), or in a "
            "scene file's [[bodies]] table of mjcf = PATH with body = NAME, and give the scene all of them)"
        )
    equalities = [e for section in root.iter("equality") for e in section]
    if equalities:
        names = ", ".join(f"<{e.tag} {e.get('name', '')}>".replace(" >", ">") for e in equalities)
        left_out.append(
            f"the <equality> constraints {names} are not honoured "
            "(declare them as gaussim bilaterals: gaussim.Anchor, gaussim.LoopClosure)"
        )
    return left_out


def set_joint_limits(root: ET.Element, model: pin.Model) -> None:
    """Set the position limits of the model's hinge and slide joints as MuJoCo reads them [rad or m]:
    a joint is limited by its ``range`` when ``limited`` is true, or "auto" with ``autolimits`` and a
    range given; the range of a hinge is in degrees unless ``<compiler angle="radian">``; ``ref``
    moves no limit."""
    degrees = compiler(root, "angle", "degree") == "degree"
    auto = compiler(root, "autolimits", "true") == "true"
    defaults = _defaults(root)
    for body, classname in _bodies_with_class(root, defaults):
        for joint in body.findall("joint"):
            name = joint.get("name")
            if name is None or not model.existJointName(name):
                continue
            pin_joint = model.joints[model.getJointId(name)]
            if pin_joint.nq != 1:
                continue
            scope = joint.get("class", classname)
            text = _attribute(joint, "range", scope, defaults, "")
            limited = _attribute(joint, "limited", scope, defaults, "auto")
            lower, upper = -np.inf, np.inf
            if text and (limited == "true" or (limited == "auto" and auto)):
                lower, upper = (float(x) for x in text.split())
                if degrees and _attribute(joint, "type", scope, defaults, "hinge") == "hinge":
                    lower, upper = math.radians(lower), math.radians(upper)
            model.lowerPositionLimit[pin_joint.idx_q] = lower
            model.upperPositionLimit[pin_joint.idx_q] = upper


def _defaults(root: ET.Element) -> dict[str, tuple[ET.Element, str | None]]:
    """Each ``<default>`` class: (its element, the class it inherits from); the top one is "main"."""
    classes: dict[str, tuple[ET.Element, str | None]] = {}

    def visit(element: ET.Element, parent: str | None) -> None:
        name = element.get("class", "main")
        classes[name] = (element, parent)
        for child in element.findall("default"):
            visit(child, name)

    for top in root.findall("default"):
        visit(top, None)
    return classes


def _bodies_with_class(
    root: ET.Element,
    defaults: dict[str, tuple[ET.Element, str | None]],
    tops: list[ET.Element] | None = None,
) -> list[tuple[ET.Element, str]]:
    """Every body (of the top-level bodies ``tops``, default all) with the class its elements take when
    they name none (the nearest ``childclass``)."""
    found: list[tuple[ET.Element, str]] = []

    def visit(body: ET.Element, classname: str) -> None:
        classname = body.get("childclass", classname)
        found.append((body, classname))
        for child in body.findall("body"):
            visit(child, classname)

    for body in bodies(root) if tops is None else tops:
        visit(body, "main")
    return found


def _attribute(
    element: ET.Element,
    key: str,
    classname: str,
    defaults: dict[str, tuple[ET.Element, str | None]],
    default: str,
) -> str:
    """An attribute of ``element``, or of its class's defaults for its tag, up the class chain."""
    if element.get(key) is not None:
        return str(element.get(key))
    current: str | None = classname
    while current is not None and current in defaults:
        scope, current = defaults[current]
        for entry in scope.findall(element.tag):
            if entry.get(key) is not None:
                return str(entry.get(key))
    return default


def _mass(
    geom: ET.Element,
    classname: str,
    defaults: dict[str, tuple[ET.Element, str | None]],
    groups: tuple[int, int],
) -> float | None:
    """A geom's mass as MuJoCo takes it, its own or its class's [kg]: None when its density weighs it,
    0 when that density is 0 or its group is outside ``groups`` (:func:`_weighed_groups`)."""
    group = int(_attribute(geom, "group", classname, defaults, "0"))
    if not groups[0] <= group <= groups[1]:
        return 0.0
    mass = _attribute(geom, "mass", classname, defaults, "")
    if mass:
        return float(mass)
    return 0.0 if float(_attribute(geom, "density", classname, defaults, "1000")) == 0.0 else None


def _weighed_groups(root: ET.Element) -> tuple[int, int]:
    """The geom groups that weigh in their body's inertia: ``<compiler inertiagrouprange>``."""
    low, high = compiler(root, "inertiagrouprange", "0 5").split()
    return int(low), int(high)


def _named(element: ET.Element) -> str:
    return f"<{element.tag} {element.get('name')}>" if element.get("name") else f"<{element.tag}>"
