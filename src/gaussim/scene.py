"""Scenes: a robot, its environment, and the constraints the scene declares (and nothing else)."""

from __future__ import annotations

import fnmatch
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import coal
import numpy as np
import pinocchio as pin

from .exceptions import GeometryNotFound, InvalidOptions, InvalidRobot, finite_numbers, shown
from .options import is_real
from .robot import Robot
from .world import BodyLayout, FreeBody, Material, World, check_material, combined


def _vector(field_name: str, value: object, size: int) -> np.ndarray:
    try:
        raw = np.asarray(value)
    except ValueError:  # a ragged list
        raw = np.zeros(0)
    arr = raw.astype(float) if raw.dtype.kind in "iuf" else np.zeros(0)  # not text, bool or complex
    if arr.shape != (size,) or not np.all(np.isfinite(arr)):
        raise InvalidOptions(field_name, f"must be {finite_numbers(size)}, got {shown(value)}")
    return arr


@dataclass(frozen=True)
class Ground:
    """A plane bounding the half-space the robot may occupy.

    Attributes:
        friction: Coulomb coefficient mu (>= 0).
        restitution: normal restitution e in [0, 1].
        height: signed offset of the plane along its normal [m].
        normal: outward unit normal, shape (3,); tilt it for an incline.
        name: name used in contact reports.
    """

    friction: float = 0.8
    restitution: float = 0.0
    height: float = 0.0
    normal: Sequence[float] = (0.0, 0.0, 1.0)
    name: str = "ground"

    def __post_init__(self) -> None:
        check_material(self.name, self.friction, self.restitution)
        n = _vector(f"{self.name}.normal", self.normal, 3)
        if np.linalg.norm(n) < 1e-12:
            raise InvalidOptions(f"{self.name}.normal", "must be a non-zero vector")
        object.__setattr__(self, "normal", tuple(n / np.linalg.norm(n)))
        if not is_real(self.height):
            raise InvalidOptions(
                f"{self.name}.height", f"must be a finite number [m], got {shown(self.height)}"
            )

    def shape(self) -> coal.CollisionGeometry:
        return coal.Halfspace(np.asarray(self.normal), float(self.height))

    def placement(self) -> pin.SE3:
        return pin.SE3.Identity()


@dataclass(frozen=True)
class Box:
    """A box fixed in the world.

    Attributes:
        name: name used in contact pairs and reports.
        size: full side lengths, shape (3,) [m].
        position: centre in the world, shape (3,) [m].
        rotation: orientation, (3, 3) rotation matrix.
    """

    name: str
    size: Sequence[float]
    position: Sequence[float] = (0.0, 0.0, 0.0)
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    friction: float = 0.8
    restitution: float = 0.0

    def __post_init__(self) -> None:
        check_material(self.name, self.friction, self.restitution)
        if np.any(_vector(f"{self.name}.size", self.size, 3) <= 0):
            raise InvalidOptions(f"{self.name}.size", f"must be > 0, got {shown(self.size)}")
        _vector(f"{self.name}.position", self.position, 3)
        R = np.asarray(self.rotation, dtype=float)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9):
            raise InvalidOptions(f"{self.name}.rotation", "must be a 3x3 rotation matrix")

    def shape(self) -> coal.CollisionGeometry:
        return coal.Box(*map(float, self.size))

    def placement(self) -> pin.SE3:
        return pin.SE3(np.asarray(self.rotation, dtype=float), np.asarray(self.position, dtype=float))


@dataclass(frozen=True)
class Sphere:
    """A sphere fixed in the world (radius [m], centre position (3,) [m])."""

    name: str
    radius: float
    position: Sequence[float] = (0.0, 0.0, 0.0)
    friction: float = 0.8
    restitution: float = 0.0

    def __post_init__(self) -> None:
        check_material(self.name, self.friction, self.restitution)
        if not (is_real(self.radius) and self.radius > 0):
            raise InvalidOptions(
                f"{self.name}.radius", f"must be a finite number > 0, got {shown(self.radius)}"
            )
        _vector(f"{self.name}.position", self.position, 3)

    def shape(self) -> coal.CollisionGeometry:
        return coal.Sphere(float(self.radius))

    def placement(self) -> pin.SE3:
        return pin.SE3(np.eye(3), np.asarray(self.position, dtype=float))


Obstacle = Ground | Box | Sphere


@dataclass(frozen=True)
class Anchor:
    """Bilateral constraint: hold a robot frame at a world point (3 rows) or placement (6 rows).

    Attributes:
        frame: robot frame name.
        position: target origin of the frame in the world, shape (3,) [m].
        rotation: target orientation (3, 3); when given the whole placement is held (6 rows).
    """

    frame: str
    position: Sequence[float] | np.ndarray
    rotation: np.ndarray | None = None

    def __post_init__(self) -> None:
        _vector(f"anchor {self.frame}.position", self.position, 3)

    @property
    def name(self) -> str:
        return f"anchor {self.frame}"


@dataclass(frozen=True)
class LoopClosure:
    """Bilateral constraint: two robot frames joined at their origins (3 rows) or rigidly (6 rows)."""

    frame_a: str
    frame_b: str
    orientation: bool = False

    @property
    def name(self) -> str:
        return f"loop {self.frame_a}-{self.frame_b}"


Bilateral = Anchor | LoopClosure


@dataclass(frozen=True)
class ContactPair:
    """A collision geometry of the world that may touch an obstacle or another geometry (indices
    resolved at scene build: exactly one of ``obstacle`` and ``other`` is set), with the pair's
    material (see :class:`~gaussim.world.Material` for how two sides combine).

    Attributes:
        geometry: index in the world's collision model.
        obstacle: index in ``Scene.obstacles``, or None.
        name: ``"geometry/obstacle"``.
        other: index of the other geometry, or None.
        friction, restitution: the pair's coefficients.
    """

    geometry: int
    obstacle: int | None
    name: str
    other: int | None = None
    friction: float = 0.8
    restitution: float = 0.0


def _listed(field: str, items: object, kinds: tuple[type, ...], named: str) -> tuple:
    """``items`` as a tuple, when it is a list (or tuple, ...) of ``kinds``; else InvalidOptions naming
    ``field`` (one item given bare, ``obstacles=Box(...)``, is told to be put in a list)."""
    if isinstance(items, kinds):
        raise InvalidOptions(field, f"must be a list of {named}, got one: give [{shown(items)}]")
    if isinstance(items, (str, bytes, Mapping)) or not isinstance(items, Iterable):
        raise InvalidOptions(field, f"must be a list of {named}, got {shown(items)}")
    found = tuple(items)
    for i, item in enumerate(found):
        if not isinstance(item, kinds):
            raise InvalidOptions(f"{field}[{i}]", f"must be one of {named}, got {shown(item)}")
    return found


class Scene:
    """Bodies (robots and free objects), the world around them and the constraints declared on them.

    Only what is declared here becomes a constraint module (model only what the scene requires).

    Args:
        robot: the one robot of a one-body scene (or give ``bodies``).
        bodies: name -> a :class:`Robot`, a :class:`~gaussim.world.FreeBody`, what
            :func:`~gaussim.robot.as_robot` accepts, or a :class:`~gaussim.world.Body` with per-body
            settings; in a scene of several, names are qualified: ``"solo/FL_FOOT_0"``.
        ground: a ground plane, or None.
        obstacles: fixed boxes and spheres.
        contacts: ``"auto"`` (or None): every geometry against every obstacle, every pair of
            geometries of two bodies whose masks allow it, and a body's own non-adjacent links when its
            ``self_collision`` is on; or a list of (name, name) pairs, each name an obstacle, a
            geometry (``"body/geometry"``, or bare when one body has it), a body (all its geometries)
            or a wildcard pattern (``"solo/*_FOOT_0"``).
        self_contact: (friction, restitution) of pairs where no side declares a material.
        materials: name or pattern of a body or geometry -> :class:`~gaussim.world.Material`
            (a geometry's entry overrides its body's).
        joint_limits: enforce the URDF position limits.
        joint_friction: apply the joints' viscous damping and dry friction that the robot files give
            (URDF ``<dynamics damping friction>``, MJCF ``damping`` and ``frictionloss``; Pinocchio's
            ``model.damping`` and ``model.friction``): the damping as an implicit one, the dry friction
            as a constraint family (:mod:`gaussim.constraints.joint_friction`).
        bilaterals: anchors and loop closures.
        gravity: gravity vector [m/s^2], shape (3,).
    """

    def __init__(
        self,
        robot: Robot | None = None,
        *,
        bodies: Mapping[str, object] | None = None,
        ground: Ground | None = None,
        obstacles: Sequence[Box | Sphere] = (),
        contacts: str | Sequence[tuple[str, str]] | None = None,
        joint_limits: bool = False,
        joint_friction: bool = False,
        bilaterals: Sequence[Bilateral] = (),
        gravity: Sequence[float] = (0.0, 0.0, -9.81),
        self_contact: tuple[float, float] = (0.8, 0.0),
        materials: Mapping[str, Material] | None = None,
    ) -> None:
        if (robot is None) == (bodies is None):
            raise InvalidOptions("bodies", "give one robot, or bodies={name: robot or free body, ...}")
        if robot is not None and not isinstance(robot, Robot):
            raise InvalidOptions("robot", f"must be a gaussim.Robot (gaussim.load_robot), got {shown(robot)}")
        if ground is not None and not isinstance(ground, Ground):
            raise InvalidOptions("ground", f"must be a gaussim.Ground or None, got {shown(ground)}")
        self.obstacles: tuple[Obstacle, ...] = ((ground,) if ground else ()) + _listed(
            "obstacles", obstacles, (Box, Sphere), "gaussim.Box and gaussim.Sphere"
        )
        names = [o.name for o in self.obstacles]
        self.world = World({robot.name: robot} if robot is not None else bodies, names)  # type: ignore[dict-item, arg-type]
        self.robot = robot = self.world.robot
        if len(set(names)) != len(names):
            raise InvalidOptions("obstacles", f"names must be unique, got {names}")
        clash = set(names) & set(self.world.bodies)
        if clash:
            raise InvalidOptions("obstacles", f"{sorted(clash)} name both an obstacle and a body")
        check_material("self_contact", *self_contact)
        self.self_contact = (float(self_contact[0]), float(self_contact[1]))
        self.joint_limits = bool(joint_limits)
        self.joint_friction = bool(joint_friction)
        if self.joint_friction:
            _check_joint_friction(robot)
        self.gravity = _vector("gravity", gravity, 3)
        self.bilaterals = _listed(
            "bilaterals", bilaterals, (Anchor, LoopClosure), "gaussim.Anchor and gaussim.LoopClosure"
        )
        for b in self.bilaterals:
            for frame in (b.frame,) if isinstance(b, Anchor) else (b.frame_a, b.frame_b):
                robot.frame_id(frame)
        self._names = _Names(self.world, names)
        self._materials = self._geometry_materials(materials or {})
        self.pairs = tuple(self._pairs(contacts))
        if self.obstacles and not robot.collision_model.ngeoms:
            raise InvalidOptions(
                "robot",
                f"'{robot.name}' has no collision geometry ({robot.source} declares none): it would "
                f"pass through {', '.join(names)}; give its links collision elements, or drop the obstacles",
            )

    @property
    def bodies(self) -> dict[str, BodyLayout]:
        """Each body's layout in the world (its slices of q and v, its geometries)."""
        return self.world.bodies

    def _geometry_materials(self, materials: Mapping[str, Material]) -> list[Material | None]:
        """Each world geometry's material: its own entry, its body's, or its free body's."""
        if not isinstance(materials, Mapping):
            raise InvalidOptions("materials", f"must map names to gaussim.Material, got {shown(materials)}")
        chosen: list[Material | None] = []
        for g in range(self.robot.collision_model.ngeoms):
            body = self.world.owner(g)
            source = body.body.source
            chosen.append(body.body.material or (source.material if isinstance(source, FreeBody) else None))
        for key, material in materials.items():
            if not isinstance(material, Material):
                raise InvalidOptions(f"materials.{key}", f"must be a gaussim.Material, got {shown(material)}")
            geometries = self._names.geometries(key, "materials")
            for g in geometries:
                chosen[g] = material
        return chosen

    def _pairs(self, contacts: str | Sequence[tuple[str, str]] | None) -> list[ContactPair]:
        if contacts is None or contacts == "auto":
            candidates = self._automatic()
        elif isinstance(contacts, str):
            raise InvalidOptions(
                "contacts", f"must be 'auto' or a list of (name, name) pairs, got {shown(contacts)}"
            )
        else:
            candidates = self._listed(contacts)
        return [self._pair(a, b) for a, b in candidates]

    def _automatic(self) -> list[tuple[int, tuple[str, int]]]:
        """The default pairs: geometries x obstacles, then geometries of two bodies, then a body's own."""
        world, joints = self.world, self._names.joints
        moving = [
            g for g in range(len(joints)) if joints[g] != 0
        ]  # one fixed in the world touches nothing fixed
        pairs: list[tuple[int, tuple[str, int]]] = [
            (g, ("obstacle", o)) for o in range(len(self.obstacles)) for g in moving
        ]
        layouts = list(world.bodies.values())
        for i, a in enumerate(layouts):
            for b in layouts[i + 1 :]:
                if a.body.contype & b.body.conaffinity or b.body.contype & a.body.conaffinity:
                    pairs += [
                        (g, ("geometry", h))
                        for g in a.geometries
                        for h in b.geometries
                        if joints[g] or joints[h]
                    ]
            if a.body.self_collision:
                pairs += [
                    (g, ("geometry", h))
                    for g in a.geometries
                    for h in a.geometries
                    if g < h and (joints[g] or joints[h]) and not world.adjacent(joints[g], joints[h])
                ]
        return pairs

    def _listed(self, contacts: Sequence[tuple[str, str]]) -> list[tuple[int, tuple[str, int]]]:
        """The pairs of a list: each entry's names expanded, adjacent links dropped from patterns."""
        pairs: list[tuple[int, tuple[str, int]]] = []
        seen: dict[frozenset, int] = {}
        joints = self._names.joints
        for k, pair in enumerate(contacts):
            if isinstance(pair, str) or len(pair) != 2:
                raise InvalidOptions(f"contacts[{k}]", f"must be (geometry, obstacle), got {shown(pair)}")
            first, second = pair
            if first in self._names.obstacles:  # (obstacle, geometry): the same pair
                first, second = second, first
            for g in self._names.geometries(first, f"contacts[{k}]"):
                for other in self._names.sides(second, f"contacts[{k}]"):
                    kind, h = other
                    if kind == "geometry" and (h == g or self.world.adjacent(joints[g], joints[h])):
                        if self._names.exact(first) and self._names.exact(second):
                            raise InvalidOptions(
                                f"contacts[{k}]",
                                f"({first}, {second}): "
                                + (
                                    "a geometry cannot touch itself"
                                    if h == g
                                    else "adjacent links never touch (their joint holds them together)"
                                ),
                            )
                        continue
                    key = frozenset([("geometry", g), other])
                    if key in seen:  # the same pair twice would double its rows and halve its forces
                        if self._names.exact(first) and self._names.exact(second):
                            raise InvalidOptions(
                                f"contacts[{k}]",
                                f"({pair[0]}, {pair[1]}) repeats contacts[{seen[key]}] {contacts[seen[key]]}",
                            )
                        continue
                    seen[key] = k
                    pairs.append((g, other))
        return pairs

    def _pair(self, g: int, other: tuple[str, int]) -> ContactPair:
        kind, h = other
        name = self._names.geometry_names[g]
        if kind == "obstacle":
            obstacle = self.obstacles[h]
            friction, restitution = combined(self._materials[g], (obstacle.friction, obstacle.restitution))
            return ContactPair(g, h, f"{name}/{obstacle.name}", None, friction, restitution)  # type: ignore[arg-type]
        friction, restitution = combined(self._materials[g], self._materials[h])
        default_friction, default_restitution = self.self_contact
        return ContactPair(
            g,
            None,
            f"{name}/{self._names.geometry_names[h]}",
            h,
            default_friction if friction is None else friction,
            default_restitution if restitution is None else restitution,
        )


_WILDCARDS = set("*?[")


class _Names:
    """How a scene's names resolve: obstacles, world geometries (bare or body-qualified), bodies, and
    wildcard patterns of those."""

    def __init__(self, world: World, obstacles: list[str]) -> None:
        collision = world.robot.collision_model
        self.world, self.obstacles = world, obstacles
        self.geometry_names = [g.name for g in collision.geometryObjects]
        self.joints = [int(g.parentJoint) for g in collision.geometryObjects]
        # every geometry by its world name and by "body/name" (the same in a world of several bodies)
        self.qualified = [
            f"{world.owner(g).name}/{name[len(world.owner(g).prefix) :]}"
            for g, name in enumerate(self.geometry_names)
        ]
        self.index: dict[str, list[int]] = {}
        for g, name in enumerate(self.geometry_names):
            self.index.setdefault(name, []).append(g)
            if self.qualified[g] != name:
                self.index.setdefault(self.qualified[g], []).append(g)
        for body in world.bodies.values():
            self.index.setdefault(body.name, []).extend(body.geometries)
        # a bare geometry name of a world of several bodies, where it is unambiguous
        if len(world) > 1:
            bare: dict[str, list[int]] = {}
            for g, name in enumerate(self.qualified):
                bare.setdefault(name.split("/", 1)[1], []).append(g)
            for name, found in bare.items():
                self.index.setdefault(name, found if len(found) == 1 else [])

    def exact(self, name: str) -> bool:
        return not (_WILDCARDS & set(name)) and name not in self.world.bodies

    def geometries(self, name: object, where: str) -> list[int]:
        """The world geometries ``name`` stands for (at least one)."""
        if not isinstance(name, str):
            raise InvalidOptions(where, f"names must be text, got {shown(name)}")
        if _WILDCARDS & set(name):
            found = [g for g, q in enumerate(self.qualified) if fnmatch.fnmatchcase(q, name)]
            found += [
                g
                for g, n in enumerate(self.geometry_names)
                if fnmatch.fnmatchcase(n, name) and g not in found
            ]
            if found:
                return sorted(found)
        elif self.index.get(name):
            return self.index[name]
        elif name in self.index:  # a bare name that several bodies have
            owners = [self.qualified[g] for g, q in enumerate(self.qualified) if q.split("/", 1)[1] == name]
            raise InvalidOptions(where, f"'{name}' is ambiguous: qualify it with its body, one of {owners}")
        raise GeometryNotFound(name, self.geometry_names + list(self.world.bodies) * (len(self.world) > 1))

    def sides(self, name: object, where: str) -> list[tuple[str, int]]:
        """What the second name of a pair stands for: obstacles or geometries."""
        if isinstance(name, str):
            obstacles = [
                ("obstacle", o)
                for o, n in enumerate(self.obstacles)
                if n == name or (_WILDCARDS & set(name) and fnmatch.fnmatchcase(n, name))
            ]
            if obstacles and not (_WILDCARDS & set(name)):
                return obstacles
            try:
                return obstacles + [("geometry", g) for g in self.geometries(name, where)]
            except GeometryNotFound:
                if obstacles:
                    return obstacles
                known = self.obstacles + self.geometry_names
                scene = "the scene"
                if name == Ground().name:  # not a typo: the ground was left out
                    scene += (
                        " (it has no ground: give ground=gaussim.Ground(); a scene file, a [ground] section)"
                    )
                raise GeometryNotFound(name, known, "obstacle or collision geometry", scene) from None
        return [("geometry", g) for g in self.geometries(name, where)]


def _check_joint_friction(robot: Robot) -> None:
    """Refuse joint damping or dry friction (of the robot files) that is not finite and >= 0, naming
    the joints."""
    model = robot.model
    for values, what in ((model.damping, "damping"), (model.friction, "friction")):
        bad = np.flatnonzero(~(np.isfinite(values) & (values >= 0.0)))
        if len(bad):
            owners = {
                model.names[j]
                for j in range(1, model.njoints)
                for i in bad
                if model.joints[j].idx_v <= i < model.joints[j].idx_v + model.joints[j].nv
            }
            raise InvalidRobot(
                f"{robot.source}: joints {sorted(owners)} have a {what} of {values[bad].tolist()}: "
                "joint_friction=True needs finite values >= 0"
            )
