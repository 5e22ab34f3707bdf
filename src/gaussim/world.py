"""The world: several bodies (robots and free objects) merged into one Pinocchio model.

Each body keeps its own name; in a world of several bodies, its joints, frames and geometries are
named ``"body/name"`` and the world's configuration q and velocity v are the bodies' own, stacked in
the order the scene lists them (:class:`BodyLayout` holds each body's slices). One merged model means
one M(q), block diagonal by body, one ABA and one set of contact rows: the engine's stages need no
notion of bodies, and the bodies that do not touch one another evolve as they would alone.
"""

from __future__ import annotations

import colorsys
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import coal
import numpy as np
import pinocchio as pin

from .exceptions import InvalidOptions, InvalidRobot, finite_numbers, shown
from .options import is_real
from .robot import Robot, as_robot, hull_problem

# Colours given to the bodies in turn (RGBA), for the viewer and the plots.
PALETTE = (
    (0.85, 0.55, 0.25, 1.0),
    (0.25, 0.55, 0.85, 1.0),
    (0.35, 0.70, 0.35, 1.0),
    (0.80, 0.30, 0.35, 1.0),
    (0.60, 0.45, 0.80, 1.0),
    (0.85, 0.75, 0.30, 1.0),
    (0.30, 0.75, 0.75, 1.0),
    (0.55, 0.55, 0.55, 1.0),
)
# Beyond the palette, body k's hue turns by this much from body k - 1's (the golden angle: no two alike).
GOLDEN_HUE = 0.381966


def body_color(k: int) -> tuple[float, float, float, float]:
    """The k-th body's default RGBA: PALETTE's, then hues a golden angle apart (all distinct)."""
    if k < len(PALETTE):
        return PALETTE[k]
    red, green, blue = colorsys.hsv_to_rgb((k * GOLDEN_HUE) % 1.0, 0.6, 0.85)
    return (red, green, blue, 1.0)


SHAPES = ("box", "sphere", "cylinder", "capsule", "mesh")
# The largest Coulomb coefficient a scene may declare: real materials stay below 2; a block sliding on
# mu = 1000 is tested to stop without sinking, and Solo-12 standing on mu = 1e6 sinks 3.6 mm
MAX_FRICTION = 1e3


def check_material(owner: str, friction: object, restitution: object) -> None:
    """Refuse a friction coefficient outside [0, MAX_FRICTION] or a restitution outside [0, 1]."""
    if not (is_real(friction) and friction >= 0):  # type: ignore[operator]
        raise InvalidOptions(f"{owner}.friction", f"must be a finite number >= 0, got {shown(friction)}")
    if friction > MAX_FRICTION:  # type: ignore[operator]
        raise InvalidOptions(
            f"{owner}.friction", f"{friction:g} is beyond any material (at most {MAX_FRICTION:g})"
        )
    if not (is_real(restitution) and 0 <= restitution <= 1):  # type: ignore[operator]
        raise InvalidOptions(f"{owner}.restitution", f"must be in [0, 1], got {shown(restitution)}")


def pose(
    x: float = 0.0,
    y: float = 0.0,
    z: float = 0.0,
    *,
    rpy: Sequence[float] | None = None,
    quaternion: Sequence[float] | None = None,
) -> pin.SE3:
    """A placement in the world: position (x, y, z) [m] and an orientation given as roll, pitch, yaw
    [rad] or a unit quaternion (x, y, z, w) (default: none)."""
    if rpy is not None and quaternion is not None:
        raise InvalidOptions("pose", "give rpy or quaternion, not both")
    position = _numbers("pose position", (x, y, z), 3)
    if quaternion is not None:
        quat = _numbers("pose quaternion", quaternion, 4)
        if abs(np.linalg.norm(quat) - 1.0) > 1e-6:
            raise InvalidOptions("pose quaternion", f"must be a unit (x, y, z, w), got {shown(quaternion)}")
        rotation = pin.Quaternion(quat[3], *quat[:3]).toRotationMatrix()
    else:
        rotation = pin.rpy.rpyToMatrix(*_numbers("pose rpy", (0, 0, 0) if rpy is None else rpy, 3))
    return pin.SE3(rotation, position)


def _numbers(where: str, value: object, size: int) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype.kind not in "iuf" or arr.shape != (size,) or not np.all(np.isfinite(arr)):
        raise InvalidOptions(where, f"must be {finite_numbers(size)}, got {shown(value)}")
    return arr.astype(float)


def _positive(where: str, value: object) -> float:
    if not (is_real(value) and value > 0):  # type: ignore[operator]
        raise InvalidOptions(where, f"must be a finite number > 0, got {shown(value)}")
    return float(value)  # type: ignore[arg-type]


@dataclass(frozen=True)
class Material:
    """Contact properties of a body or geometry; a property left None is the other side's.

    Two sides that both declare one combine by the larger value (MuJoCo's rule for friction), so a
    pair is as rough and as bouncy as its rougher, bouncier side; a pair where neither side declares
    one takes the scene's default (``Scene.self_contact``).

    Attributes:
        friction: Coulomb coefficient mu (>= 0).
        restitution: normal restitution e in [0, 1].
    """

    friction: float | None = None
    restitution: float | None = None

    def __post_init__(self) -> None:
        check_material("material", 0.0 if self.friction is None else self.friction, self.restitution or 0.0)


def combined(*materials: tuple[float, float] | Material | None) -> tuple[float | None, float | None]:
    """The (friction, restitution) of a pair whose sides declare ``materials``: the larger of each
    declared value, None where no side declares it."""
    friction: list[float] = []
    restitution: list[float] = []
    for m in materials:
        f, e = (m.friction, m.restitution) if isinstance(m, Material) else (m or (None, None))
        if f is not None:
            friction.append(f)
        if e is not None:
            restitution.append(e)
    return max(friction, default=None), max(restitution, default=None)


@dataclass(frozen=True)
class FreeBody:
    """A rigid object free in space (six degrees of freedom), of one shape.

    Build one with :meth:`box`, :meth:`sphere`, :meth:`cylinder`, :meth:`capsule` or :meth:`mesh`,
    giving its ``mass`` [kg] or its ``density`` [kg/m^3]. The body frame is at the centre of mass with
    the shape's axes (a cylinder's and a capsule's along z).

    Attributes:
        name: the body's name (its geometry is named after its shape: ``"crate/box"``).
        shape: one of SHAPES.
        size: box side lengths (3,), sphere (radius,), cylinder and capsule (radius, length) [m].
        mass: [kg].
        material: contact properties, or None (the other side's).
        mesh_path: a convex mesh's file (``shape == "mesh"``).
    """

    name: str
    shape: str
    size: tuple[float, ...]
    mass: float
    material: Material | None = None
    mesh_path: str = ""
    _inertia: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)), repr=False, compare=False)
    _offset: np.ndarray = field(default_factory=lambda: np.zeros(3), repr=False, compare=False)

    @classmethod
    def box(
        cls,
        name: str,
        size: Sequence[float],
        *,
        mass: float | None = None,
        density: float | None = None,
        material: Material | None = None,
    ) -> FreeBody:
        """A box of full side lengths ``size`` (3,) [m]."""
        sides = _numbers(f"{name}.size", size, 3)
        for s in sides:
            _positive(f"{name}.size", s)
        m = _mass(name, mass, density, float(np.prod(sides)))
        return cls._made(name, "box", tuple(sides), m, material, pin.Inertia.FromBox(m, *sides))

    @classmethod
    def sphere(
        cls,
        name: str,
        radius: float,
        *,
        mass: float | None = None,
        density: float | None = None,
        material: Material | None = None,
    ) -> FreeBody:
        """A ball of ``radius`` [m]."""
        r = _positive(f"{name}.radius", radius)
        m = _mass(name, mass, density, 4 / 3 * np.pi * r**3)
        return cls._made(name, "sphere", (r,), m, material, pin.Inertia.FromSphere(m, r))

    @classmethod
    def cylinder(
        cls,
        name: str,
        radius: float,
        length: float,
        *,
        mass: float | None = None,
        density: float | None = None,
        material: Material | None = None,
    ) -> FreeBody:
        """A solid cylinder of ``radius`` and ``length`` [m] along its z axis."""
        r, h = _positive(f"{name}.radius", radius), _positive(f"{name}.length", length)
        m = _mass(name, mass, density, np.pi * r**2 * h)
        return cls._made(name, "cylinder", (r, h), m, material, pin.Inertia.FromCylinder(m, r, h))

    @classmethod
    def capsule(
        cls,
        name: str,
        radius: float,
        length: float,
        *,
        mass: float | None = None,
        density: float | None = None,
        material: Material | None = None,
    ) -> FreeBody:
        """A capsule: a cylinder of ``radius`` and ``length`` [m] along z capped by two half balls."""
        r, h = _positive(f"{name}.radius", radius), _positive(f"{name}.length", length)
        m = _mass(name, mass, density, np.pi * r**2 * h + 4 / 3 * np.pi * r**3)
        return cls._made(name, "capsule", (r, h), m, material, pin.Inertia.FromCapsule(m, r, h))

    @classmethod
    def mesh(
        cls,
        name: str,
        path: str,
        *,
        mass: float | None = None,
        density: float | None = None,
        scale: float = 1.0,
        material: Material | None = None,
    ) -> FreeBody:
        """A convex object from a mesh file (STL, OBJ, DAE: what coal reads): its convex hull, whose
        volume, centre of mass and inertia (uniform density) are the body's."""
        hull = _hull(name, path, _positive(f"{name}.scale", scale))
        volume = float(hull.computeVolume())
        if not volume > 0:
            raise InvalidOptions(f"{name}.mesh", f"{path}: the convex hull has no volume")
        m = _mass(name, mass, density, volume)
        com = np.asarray(hull.computeCOM())
        # coal's moment about the centre of mass, of unit density: scaled to the body's mass
        inertia = np.asarray(hull.computeMomentofInertiaRelatedToCOM()) * (m / volume)
        body = cls(name, "mesh", (scale,), m, material, str(path), inertia, com)
        return body

    @classmethod
    def _made(
        cls,
        name: str,
        shape: str,
        size: tuple[float, ...],
        mass: float,
        material: Material | None,
        inertia: pin.Inertia,
    ) -> FreeBody:
        _name(name)
        return cls(name, shape, size, mass, material, "", inertia.inertia.copy())

    def geometry(self) -> coal.CollisionGeometry:
        """The coal shape, in the body frame once placed at ``-offset`` (the mesh's centre of mass)."""
        if self.shape == "box":
            return coal.Box(*self.size)
        if self.shape == "sphere":
            return coal.Sphere(self.size[0])
        if self.shape == "cylinder":
            return coal.Cylinder(*self.size)
        if self.shape == "capsule":
            return coal.Capsule(self.size[0], self.size[1])
        return _hull(self.name, self.mesh_path, self.size[0])

    def robot(self) -> Robot:
        """The body as a one-joint Pinocchio model: a free flyer carrying the body, its centre of mass
        at the joint, and its shape as collision and visual geometry."""
        model = pin.Model()
        model.name = self.name
        joint = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "root_joint")
        model.appendBodyToJoint(joint, pin.Inertia(self.mass, np.zeros(3), self._inertia), pin.SE3.Identity())
        model.addBodyFrame(self.name, joint, pin.SE3.Identity(), 0)
        geometries = []
        for _ in range(2):  # collision and visual
            geometry = pin.GeometryModel()
            placement = pin.SE3(np.eye(3), -self._offset)
            obj = pin.GeometryObject(self.shape, joint, placement, self.geometry())
            obj.meshColor = np.array(PALETTE[0])
            geometry.addGeometryObject(obj)
            geometries.append(geometry)
        return as_robot((model, *geometries), self.name)


def _mass(name: str, mass: float | None, density: float | None, volume: float) -> float:
    if (mass is None) == (density is None):
        raise InvalidOptions(f"{name}.mass", "give the mass [kg] or the density [kg/m^3], one of them")
    if mass is not None:
        return _positive(f"{name}.mass", mass)
    return _positive(f"{name}.density", density) * volume


def _hull(name: str, path: str, scale: float) -> coal.ConvexBase:
    try:
        mesh = coal.MeshLoader().load(str(path), np.full(3, scale))
    except (RuntimeError, ValueError, OSError) as err:
        raise InvalidOptions(f"{name}.mesh", f"cannot read {path}: {err}") from err
    problem = hull_problem(mesh.vertices())
    if problem:
        raise InvalidOptions(f"{name}.mesh", f"{path}: {problem}")
    mesh.buildConvexHull(True, "Qt")
    return mesh.convex


def _name(name: object) -> str:
    if not isinstance(name, str) or not name or "/" in name:
        raise InvalidOptions("body name", f"must be a non-empty text without '/', got {shown(name)}")
    return name


@dataclass(frozen=True)
class Body:
    """A body of a scene with its per-body settings (a bare robot or :class:`FreeBody` in a scene's
    ``bodies`` stands for ``Body(it)``).

    Attributes:
        source: a :class:`Robot`, a :class:`FreeBody`, or what :func:`gaussim.robot.as_robot` accepts.
        placement: where a fixed-base robot's base is in the world (default: the origin); a floating
            body is placed by its configuration (:meth:`Simulator.reset`).
        self_collision: contacts between this robot's own links (never adjacent ones).
        material: contact properties of its geometries, or None (the other side's).
        contype, conaffinity: collision bit masks (MuJoCo's): two bodies may touch when
            ``a.contype & b.conaffinity or b.contype & a.conaffinity``.
        color: RGBA (4,) in the viewer, or None (body_color of its index: each body its own).
    """

    source: object
    placement: pin.SE3 | None = None
    self_collision: bool = False
    material: Material | None = None
    contype: int = 1
    conaffinity: int = 1
    color: tuple[float, float, float, float] | None = None


@dataclass(frozen=True)
class BodyLayout:
    """Where one body sits in the world.

    Attributes:
        name: the body's name.
        robot: the body on its own (its unprefixed names).
        q, v: its slices of the world's configuration (nq_b,) and velocity (nv_b,).
        joints: its joints' indices in the world model (a range).
        geometries: its collision geometries' indices in the world's collision model.
        floating: its root joint is a free flyer.
        free: it is a :class:`FreeBody`.
        color: its RGBA colour.
        prefix: what its names carry in the world (``"name/"``, or "" in a one-body world).
        body: its declaration.
        actuated: the world's velocity coordinates torques drive in it, shape (k,) (its robot's
            :attr:`Robot.actuated`).
    """

    name: str
    robot: Robot
    q: slice
    v: slice
    joints: range
    geometries: tuple[int, ...]
    floating: bool
    free: bool
    color: tuple[float, float, float, float]
    prefix: str
    body: Body
    actuated: np.ndarray = field(repr=False, compare=False)


class World:
    """The bodies of a scene, merged (see the module's docstring).

    Attributes:
        robot: the merged robot (in a one-body world, the body itself: names and results unchanged).
        bodies: each body's :class:`BodyLayout`, in order.
        obstacles: the names of the scene's obstacles (``forces_between`` takes them).
    """

    def __init__(self, bodies: Mapping[str, object], obstacles: Sequence[str] = ()) -> None:
        if not isinstance(bodies, Mapping) or not bodies:
            raise InvalidOptions(
                "bodies", f"must map body names to robots or free bodies, got {shown(bodies)}"
            )
        specs = {_name(name): b if isinstance(b, Body) else Body(b) for name, b in bodies.items()}
        robots = {name: _robot(name, spec) for name, spec in specs.items()}
        single = len(specs) == 1
        if single:
            ((name, robot),) = robots.items()
            merged = robot if specs[name].placement is None else _merged({name: robot}, specs, "")
        else:
            merged = _merged(robots, specs, "/")
        self.robot: Robot = merged
        self.obstacles = tuple(obstacles)  # the scene's obstacles' names, which reports name
        self.bodies: dict[str, BodyLayout] = {}
        model, collision = merged.model, merged.collision_model
        for k, (name, spec) in enumerate(specs.items()):
            prefix = "" if single else f"{name}/"
            # found by name: pin.appendModel keeps the joints in order, not the geometries
            joints = [j for j in range(1, model.njoints) if model.names[j].startswith(prefix)]
            first, last = model.joints[joints[0]], model.joints[joints[-1]]
            self.bodies[name] = BodyLayout(
                name,
                robots[name],
                slice(first.idx_q, last.idx_q + last.nq),
                slice(first.idx_v, last.idx_v + last.nv),
                range(joints[0], joints[-1] + 1),
                tuple(g for g, obj in enumerate(collision.geometryObjects) if obj.name.startswith(prefix)),
                robots[name].floating,
                isinstance(spec.source, FreeBody),
                spec.color or body_color(k),
                prefix,
                spec,
                robots[name].actuated + first.idx_v,
            )
        self._owner = {g: layout for layout in self.bodies.values() for g in layout.geometries}

    def __len__(self) -> int:
        return len(self.bodies)

    def body(self, name: str) -> BodyLayout:
        """A body's layout; raises :class:`InvalidOptions` listing the bodies."""
        if name not in self.bodies:
            raise InvalidOptions("body", f"no body '{name}'; the bodies: {', '.join(self.bodies)}")
        return self.bodies[name]

    def other(self, name: str) -> str:
        """``name``, a body or an obstacle of the scene; raises :class:`InvalidOptions` listing them."""
        if name not in self.bodies and name not in self.obstacles:
            raise InvalidOptions(
                "body",
                f"no body or obstacle '{name}'; the bodies: {', '.join(self.bodies)}; "
                f"the obstacles: {', '.join(self.obstacles) or 'none'}",
            )
        return name

    def owner(self, geometry: int) -> BodyLayout:
        """The body a world collision geometry belongs to."""
        return self._owner[geometry]

    def body_of(self, geometry_name: str) -> str | None:
        """The body a world collision geometry's name belongs to (None: no such geometry)."""
        cm = self.robot.collision_model
        return (
            self._owner[cm.getGeometryId(geometry_name)].name if cm.existGeometryName(geometry_name) else None
        )

    def adjacent(self, a: int, b: int) -> bool:
        """Whether two world joints are the same, or one is the other's parent (their links touch by
        construction)."""
        parents = self.robot.model.parents
        return a == b or parents[a] == b or parents[b] == a


def _robot(name: str, spec: Body) -> Robot:
    source = spec.source
    if isinstance(source, FreeBody):
        if spec.placement is not None:
            raise InvalidOptions(
                f"bodies.{name}.placement", "a free body is placed by its configuration (Simulator.reset)"
            )
        return source.robot()
    # a robot keeps its own name (inspect, logs); an in-memory model is named after its body
    robot = as_robot(source, None if isinstance(source, Robot | str | os.PathLike) else name)
    if spec.placement is not None:
        if robot.floating:
            raise InvalidOptions(
                f"bodies.{name}.placement",
                "a floating robot is placed by its configuration (Simulator.reset)",
            )
        if not isinstance(spec.placement, pin.SE3):
            raise InvalidOptions(
                f"bodies.{name}.placement",
                f"must be a pinocchio.SE3 (gaussim.pose), got {shown(spec.placement)}",
            )
    for what, value in (("contype", spec.contype), ("conaffinity", spec.conaffinity)):
        if not isinstance(value, int) or value < 0:
            raise InvalidOptions(f"bodies.{name}.{what}", f"must be an int bit mask >= 0, got {shown(value)}")
    return robot


def _prefixed(robot: Robot, prefix: str) -> tuple[pin.Model, pin.GeometryModel, pin.GeometryModel]:
    model = robot.model.copy()
    for j in range(1, model.njoints):
        model.names[j] = prefix + model.names[j]
    for i in range(1, len(model.frames)):
        model.frames[i].name = prefix + model.frames[i].name
    geometries = []
    for source in (robot.collision_model, robot.visual_model):
        geometry = source.copy()
        for obj in geometry.geometryObjects:
            obj.name = prefix + obj.name
        geometries.append(geometry)
    return model, geometries[0], geometries[1]


def _merged(robots: Mapping[str, Robot], specs: Mapping[str, Body], separator: str) -> Robot:
    """One robot of all the bodies, their names prefixed with "body/" (pin.appendModel)."""
    model, collision, visual = pin.Model(), pin.GeometryModel(), pin.GeometryModel()
    configurations: dict[str, np.ndarray] = {}
    for name, robot in robots.items():
        placement = specs[name].placement or pin.SE3.Identity()
        prefix = f"{name}{separator}" if separator else ""
        part, part_collision, part_visual = _prefixed(robot, prefix)
        try:
            merged, collision = pin.appendModel(model, part, collision, part_collision, 0, placement)
            _, visual = pin.appendModel(model, part, visual, part_visual, 0, placement)
        except (RuntimeError, ValueError) as err:
            raise InvalidRobot(f"body '{name}' cannot join the world: {err}") from err
        model = merged
    model.name = "+".join(robots)
    for key in set.intersection(*(set(r.reference_configurations) for r in robots.values())):
        configurations[key] = np.concatenate([r.reference_configurations[key] for r in robots.values()])
    (first,) = robots.values() if len(robots) == 1 else (None,)
    urdf = first.urdf if first is not None else ""
    dirs = tuple(d for r in robots.values() for d in r.package_dirs)
    return Robot.of_checked_parts("+".join(robots), model, (collision, visual), urdf, dirs, configurations)
