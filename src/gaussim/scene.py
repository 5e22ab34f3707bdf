"""Scenes: a robot, its environment, and the constraints the scene declares (and nothing else)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import coal
import numpy as np
import pinocchio as pin

from .exceptions import GeometryNotFound, InvalidOptions, shown
from .options import is_real
from .robot import Robot

# The largest Coulomb coefficient a scene may declare: real materials stay below 2; a block sliding on
# mu = 1000 is tested to stop without sinking, and Solo-12 standing on mu = 1e6 sinks 3.6 mm
MAX_FRICTION = 1e3


def _vector(field_name: str, value: object, size: int) -> np.ndarray:
    try:
        raw = np.asarray(value)
    except ValueError:  # a ragged list
        raw = np.zeros(0)
    arr = raw.astype(float) if raw.dtype.kind in "iuf" else np.zeros(0)  # not text, bool or complex
    if arr.shape != (size,) or not np.all(np.isfinite(arr)):
        raise InvalidOptions(field_name, f"must be {size} finite numbers, got {shown(value)}")
    return arr


def _material(owner: str, friction: float, restitution: float) -> None:
    if not (is_real(friction) and friction >= 0):
        raise InvalidOptions(f"{owner}.friction", f"must be a finite number >= 0, got {shown(friction)}")
    if friction > MAX_FRICTION:  # type: ignore[operator]
        raise InvalidOptions(
            f"{owner}.friction", f"{friction:g} is beyond any material (at most {MAX_FRICTION:g})"
        )
    if not (is_real(restitution) and 0 <= restitution <= 1):
        raise InvalidOptions(f"{owner}.restitution", f"must be in [0, 1], got {shown(restitution)}")


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
        _material(self.name, self.friction, self.restitution)
        n = _vector(f"{self.name}.normal", self.normal, 3)
        if np.linalg.norm(n) < 1e-12:
            raise InvalidOptions(f"{self.name}.normal", "must be a non-zero vector")
        object.__setattr__(self, "normal", tuple(n / np.linalg.norm(n)))
        _vector(f"{self.name}.height", [self.height], 1)

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
        _material(self.name, self.friction, self.restitution)
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
        _material(self.name, self.friction, self.restitution)
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
    """A robot collision geometry that may touch an obstacle or another robot geometry (indices
    resolved at scene build: exactly one of ``obstacle`` and ``other`` is set)."""

    geometry: int
    obstacle: int | None
    name: str
    other: int | None = None


class Scene:
    """A robot, the world around it and the constraints declared on it.

    Only what is declared here becomes a constraint module (model only what the scene requires).

    Args:
        robot: the robot.
        ground: a ground plane, or None.
        obstacles: fixed boxes and spheres.
        contacts: the (geometry name, obstacle or geometry name) pairs that may touch; default every
            robot collision geometry against every obstacle and the ground (no self-contact).
        self_contact: (friction, restitution) of contacts between two robot geometries.
        joint_limits: enforce the URDF position limits.
        bilaterals: anchors and loop closures.
        gravity: gravity vector [m/s^2], shape (3,).
    """

    def __init__(
        self,
        robot: Robot,
        *,
        ground: Ground | None = None,
        obstacles: Sequence[Box | Sphere] = (),
        contacts: Sequence[tuple[str, str]] | None = None,
        joint_limits: bool = False,
        bilaterals: Sequence[Bilateral] = (),
        gravity: Sequence[float] = (0.0, 0.0, -9.81),
        self_contact: tuple[float, float] = (0.8, 0.0),
    ) -> None:
        self.robot = robot
        self.obstacles: tuple[Obstacle, ...] = ((ground,) if ground else ()) + tuple(obstacles)
        names = [o.name for o in self.obstacles]
        if len(set(names)) != len(names):
            raise InvalidOptions("obstacles", f"names must be unique, got {names}")
        _material("self_contact", *self_contact)
        self.self_contact = (float(self_contact[0]), float(self_contact[1]))
        self.joint_limits = bool(joint_limits)
        self.gravity = _vector("gravity", gravity, 3)
        self.bilaterals = tuple(bilaterals)
        for b in self.bilaterals:
            for frame in (b.frame,) if isinstance(b, Anchor) else (b.frame_a, b.frame_b):
                robot.frame_id(frame)
        self.pairs = tuple(self._pairs(contacts, names))
        if self.obstacles and not robot.collision_model.ngeoms:
            raise InvalidOptions(
                "robot",
                f"'{robot.name}' has no collision geometry ({robot.urdf} declares no <collision>): it would "
                f"pass through {', '.join(names)}; give its links collision elements, or drop the obstacles",
            )

    def _pairs(self, contacts: Sequence[tuple[str, str]] | None, names: list[str]) -> list[ContactPair]:
        geometries = [g.name for g in self.robot.collision_model.geometryObjects]
        if contacts is None:
            contacts = [(g, o) for o in names for g in geometries]
        pairs = []
        seen: dict[frozenset[str], int] = {}
        for k, pair in enumerate(contacts):
            if len(pair) != 2:
                raise InvalidOptions(f"contacts[{k}]", f"must be (geometry, obstacle), got {shown(pair)}")
            geometry, obstacle = pair
            key = frozenset(pair)
            if key in seen:  # the same pair twice would double its rows and halve its reported forces
                raise InvalidOptions(
                    f"contacts[{k}]",
                    f"({geometry}, {obstacle}) repeats contacts[{seen[key]}] {contacts[seen[key]]}",
                )
            seen[key] = k
            first = self.robot.geometry_id(geometry)
            name = f"{geometry}/{obstacle}"
            if obstacle in names:
                pairs.append(ContactPair(first, names.index(obstacle), name))
            elif obstacle in geometries and obstacle != geometry:
                pairs.append(ContactPair(first, None, name, self.robot.geometry_id(obstacle)))
            else:
                raise GeometryNotFound(obstacle, names + [g for g in geometries if g != geometry], "obstacle")
        return pairs
