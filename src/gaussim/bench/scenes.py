"""The scene suite for speed: each scene stepped by gaussim, by MuJoCo and by PyBullet (where it loads),
the engines taking turns step by step in one process, with the same bodies, masses, sizes, friction
and contact pairs; the per-step cost (median, p90) of each and its ratio to MuJoCo's.

Each peer model is generated from the gaussim scene itself (:func:`mjcf` writes its MJCF: a body per
Pinocchio joint with its inertia, each collision geometry as a primitive or its convex hull, the
obstacles, and the scene's contact pairs; :class:`Bullet` builds PyBullet's bodies of a scene of free
bodies), so that the same description drives every engine. Controllers are a torque computed from the
engine's own state in Pinocchio's coordinates plus a constant implicit joint damping (gaussim's
``damping``, MuJoCo's ``dof_damping`` under its implicitfast integrator).

Facts this relies on: MuJoCo's free joint velocity is the world linear velocity and the body angular
velocity (Pinocchio's is both in the body frame), its quaternions are wxyz (Pinocchio's xyzw); a mesh
geom collides as its convex hull (gaussim's rule too); ``contype``/``conaffinity`` 1 collides every
pair of geoms of two bodies but a parent and its child (not the world), explicit ``<pair>`` elements
(all masks 0) collide exactly those; MuJoCo has no restitution (every suite scene has e = 0).

Run it with ``gaussim bench --scenes [--quick]`` or ``python benchmarks/scene_suite.py``.
"""

from __future__ import annotations

import importlib.util
import sys
import time
import warnings
from collections.abc import Callable, Generator, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from ..control import PDHold
from ..exceptions import GaussimWarning
from ..options import Options
from ..robot import load_robot
from ..scene import Box, Ground, Scene, Sphere
from ..scenefile import load_scene
from ..simulator import Simulator
from ..world import Body, FreeBody, pose
from .cases import SCENES_DIR

if TYPE_CHECKING:
    from .peers import Bullet, MuJoCo

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"
BOX, BOX_MASS, SPACING = 0.1, 1.0, 0.15  # the piles' boxes: side [m], mass [kg], columns' pitch [m]
FRICTION = 0.8
WARM_UP = 5  # untimed first steps of each engine (numba compiles gaussim's kernels on the first)

# a controller: the torque (nv,) from (t [s], q (nq,), v (nv,)) in Pinocchio's coordinates
Drive = Callable[[float, np.ndarray, np.ndarray], np.ndarray]


@dataclass
class Setup:
    """One scene, ready to run: the gaussim scene, its initial state, its drive (or None) and the
    constant implicit damping (nv,) [N m s/rad] of its joints (or None)."""

    scene: Scene
    q: np.ndarray
    v: np.ndarray
    drive: Drive | None = None
    damping: np.ndarray | None = None
    dt: float = 1e-3


@dataclass(frozen=True)
class SceneCase:
    """A suite scene: its name, what it is, and ``build() -> Setup``; ``quick`` scenes are in the
    quick run."""

    name: str
    about: str
    build: Callable[[], Setup]
    quick: bool = False


def example(name: str) -> ModuleType:
    """The example script ``examples/<name>.py`` as a module (its scene builders; its helpers import
    ``_shared`` from that folder)."""
    if str(EXAMPLES) not in sys.path:
        sys.path.insert(0, str(EXAMPLES))
    path = EXAMPLES / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"gaussim_example_{name}", path)
    if not path.exists() or spec is None or spec.loader is None:
        raise FileNotFoundError(f"{path}: this scene is built by an example of a source checkout")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _start(scene: Scene, q: object = None, v: object = None) -> tuple[np.ndarray, np.ndarray]:
    """A validated world (q, v) of ``scene`` from per-body or world values."""
    state = Simulator(scene, Options()).reset(q, v)  # type: ignore[arg-type]
    return state.q.copy(), state.v.copy()


def boxes(n: int, height: int = 2) -> Setup:
    """``n`` boxes (BOX, BOX_MASS) in columns ``height`` high on the ground (friction FRICTION), the
    columns on a square grid SPACING apart, every box touching the one below; all pairs declared."""
    columns = -(-n // height)
    side = int(np.ceil(np.sqrt(columns)))
    bodies, poses = {}, {}
    for k in range(n):
        column, level = divmod(k, height)
        name = f"box{k}"
        bodies[name] = FreeBody.box(name, (BOX,) * 3, mass=BOX_MASS)
        x, y = SPACING * (column % side), SPACING * (column // side)
        poses[name] = pose(x=x, y=y, z=BOX / 2 + level * BOX)
    scene = Scene(bodies=bodies, ground=Ground(friction=FRICTION), self_contact=(FRICTION, 0.0))
    return Setup(scene, *_start(scene, poses))


def bin_pile() -> Setup:
    """examples/bin_pile.py's scene: twenty mixed objects dropped into a tilted bin of five boxes."""
    pile = example("bin_pile")
    frame, walls = pile.bin_walls()
    bodies = pile.objects()
    scene = Scene(
        bodies={name: body for name, (body, _) in bodies.items()},
        obstacles=walls,
        self_contact=(pile.FRICTION, 0.0),
    )
    return Setup(scene, *_start(scene, pile.drop_poses(frame, bodies, 0)))


def _pd(model: pin.Model, q_ref: np.ndarray, kp: float, kd: float, dt: float) -> tuple[Drive, np.ndarray]:
    """An implicit PD hold of a floating robot's joints on ``q_ref``: tau = kp (q_ref (-) q) on the
    actuated coordinates, damping kd + dt kp on them (gaussim's PDHold)."""

    def drive(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        tau = kp * pin.difference(model, q, q_ref)
        tau[:6] = 0.0
        return tau

    damping = np.full(model.nv, kd + dt * kp)
    damping[:6] = 0.0
    return drive, damping


def standing(name: str, contacts: str | None = None) -> Callable[..., Setup]:
    """A shipped standing scene file (its robot, ground, PD hold and start), with its own contact pairs
    or ``contacts="auto"``: every collision geometry against the ground; ``build(dt)`` changes its
    time step [s]."""

    def build(dt: float | None = None) -> Setup:
        with warnings.catch_warnings():  # talos_legs's upper-body geometries are left out, as they must
            warnings.simplefilter("ignore", GaussimWarning)
            spec = load_scene(SCENES_DIR / f"{name}.toml")
        scene = spec.scene
        if contacts is not None:
            ground = next(o for o in scene.obstacles if isinstance(o, Ground))
            scene = Scene(spec.robot, ground=ground, contacts=contacts)
        hold = spec.controller
        assert isinstance(hold, PDHold)  # the standing scenes' controller
        dt = dt or spec.options.dt
        drive, damping = _pd(spec.robot.model, hold.q_ref, hold.kp, hold.kd, dt)
        return Setup(scene, spec.initial.q.copy(), spec.initial.v.copy(), drive, damping, dt)

    return build


def panda_cube() -> Setup:
    """examples/panda_sweeps_cube.py's scene: a table-mounted Panda sweeping a cube across the table
    along the example's smooth first-joint trajectory (PD with gravity compensation, implicit D)."""
    ex = example("panda_sweeps_cube")
    with warnings.catch_warnings():  # its finger joints mimic each other; here they are held apart
        warnings.simplefilter("ignore", GaussimWarning)
        panda = load_robot("panda")
    scene = Scene(
        bodies={
            "arm": Body(panda, placement=pose(z=ex.TABLE_TOP)),
            "cube": FreeBody.box("cube", (ex.CUBE,) * 3, mass=ex.CUBE_MASS),
        },
        ground=Ground(),
        obstacles=[ex.TABLE],
    )
    reach = ex.reach_pose(panda)
    begin = reach.copy()
    begin[0] = ex.SWEEP[0]
    angle = ex.CUBE_ANGLE
    cube = pose(x=ex.REACH * np.cos(angle), y=ex.REACH * np.sin(angle), z=ex.TABLE_TOP + ex.CUBE / 2 + 1e-4)
    q, v = _start(scene, {"arm": begin, "cube": cube})
    arm, duration, dt = scene.bodies["arm"].v, 2.0, 1e-3
    model, data = scene.robot.model, scene.robot.model.createData()

    def drive(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        s = min(1.0, t / duration)  # the example's smooth step from SWEEP[0] to SWEEP[1]
        target, speed = reach.copy(), np.zeros(len(reach))
        target[0] = ex.SWEEP[0] + (ex.SWEEP[1] - ex.SWEEP[0]) * (3 * s**2 - 2 * s**3)
        speed[0] = (ex.SWEEP[1] - ex.SWEEP[0]) * 6 * s * (1 - s) / duration
        tau = np.zeros(model.nv)
        gravity = pin.computeGeneralizedGravity(model, data, q)[arm]
        tau[arm] = gravity + ex.KP * (target - q[arm]) + ex.KD * speed
        return tau

    damping = np.zeros(model.nv)
    damping[arm] = ex.KD + dt * ex.KP
    return Setup(scene, q, v, drive, damping, dt)


PILES = (1, 4, 16, 64)


def _pile(n: int) -> Callable[[], Setup]:
    return lambda: boxes(n)


SCENES: dict[str, SceneCase] = {
    case.name: case
    for case in [
        SceneCase("box", "one box (0.1 m, 1 kg) resting on the ground", lambda: boxes(1, 1), quick=True),
        *(
            SceneCase(
                f"pile_{n}", f"{n} box{'es' * (n > 1)} in 2-high columns on the ground", _pile(n), n <= 4
            )
            for n in PILES
        ),
        SceneCase("stack_3", "a 3-high stack of boxes", lambda: boxes(3, 3), quick=True),
        SceneCase("bin_pile", "20 mixed objects dropped into a bin (examples/bin_pile.py)", bin_pile),
        SceneCase(
            "solo12_feet", "Solo-12 standing, its four feet declared", standing("solo12_standing"), True
        ),
        SceneCase(
            "solo12_all", "Solo-12 standing, every collision geometry", standing("solo12_standing", "auto")
        ),
        SceneCase("talos_legs", "Talos legs standing on its soles", standing("talos_standing")),
        SceneCase("panda_cube", "a Panda sweeping a cube (examples/panda_sweeps_cube.py)", panda_cube),
    ]
}
QUICK_STEPS, STEPS = 100, 2000
ALONE_BLOCK = 100  # steps an engine takes alone before the next engine's turn (see _run_alone)


# ---- MuJoCo ---------------------------------------------------------------------------------------


def _numbers(values: Iterable[float]) -> str:
    return " ".join(f"{x:.9g}" for x in values)


def _frame(placement: pin.SE3) -> str:
    """MJCF ``pos`` and ``quat`` (wxyz) attributes of a placement."""
    x, y, z, w = pin.Quaternion(placement.rotation).coeffs()
    return f'pos="{_numbers(placement.translation)}" quat="{_numbers((w, x, y, z))}"'


def _geom(name: str, shape: object, placement: pin.SE3, assets: list[str]) -> str:
    """A geom of coal ``shape`` (a mesh becomes its convex hull's vertices, an asset)."""
    import coal

    from ..collision.pairs import convex

    where = _frame(placement)
    if isinstance(shape, coal.Box):
        return f'<geom name="{name}" type="box" size="{_numbers(shape.halfSide)}" {where}/>'
    if isinstance(shape, coal.Sphere):
        return f'<geom name="{name}" type="sphere" size="{shape.radius:.9g}" {where}/>'
    if isinstance(shape, coal.Capsule | coal.Cylinder):
        kind = "capsule" if isinstance(shape, coal.Capsule) else "cylinder"
        return f'<geom name="{name}" type="{kind}" size="{shape.radius:.9g} {shape.halfLength:.9g}" {where}/>'
    hull = convex(shape)  # type: ignore[arg-type]
    if not isinstance(hull, coal.ConvexBase):
        raise ValueError(f"{name}: no MJCF geom for a {type(shape).__name__}")
    points = np.asarray(hull.points())
    assets.append(f'<mesh name="{name}_hull" vertex="{_numbers(points.ravel())}"/>')
    return f'<geom name="{name}" type="mesh" mesh="{name}_hull" {where}/>'


def _joint(name: str, joint: pin.JointModel) -> str:
    kind = joint.shortname()
    if kind == "JointModelFreeFlyer":
        return f'<freejoint name="{name}"/>'
    for axis, letter in enumerate("XYZ"):
        for prefix, mjtype in (("JointModelR", "hinge"), ("JointModelP", "slide")):
            if kind in (f"{prefix}{letter}", f"{prefix}UB{letter}"):
                return f'<joint name="{name}" type="{mjtype}" axis="{_numbers(np.eye(3)[axis])}"/>'
    unaligned = {"JointModelRevoluteUnaligned": "hinge", "JointModelPrismaticUnaligned": "slide"}
    if kind in unaligned:
        return f'<joint name="{name}" type="{unaligned[kind]}" axis="{_numbers(joint.extract().axis)}"/>'
    raise ValueError(f"{name}: no MJCF joint for Pinocchio's {kind}")


def _default_pairs(scene: Scene) -> set[frozenset]:
    """The geometry pairs MuJoCo's masks would collide in ``scene``'s model: geometries of different
    joints but a parent and its child, each against every obstacle."""
    model, geometries = scene.robot.model, scene.robot.collision_model.geometryObjects
    joints = [int(g.parentJoint) for g in geometries]
    pairs: set[frozenset] = set()
    for a in range(len(geometries)):
        pairs |= {frozenset((("g", a), ("o", o))) for o in range(len(scene.obstacles))}
        for b in range(a):
            ja, jb = joints[a], joints[b]
            parent = (model.parents[ja] == jb and jb != 0) or (model.parents[jb] == ja and ja != 0)
            if ja != jb and not parent:
                pairs.add(frozenset((("g", a), ("g", b))))
    return pairs


def _declared(scene: Scene) -> set[frozenset]:
    return {
        frozenset((("g", p.geometry), ("o", p.obstacle) if p.other is None else ("g", p.other)))
        for p in scene.pairs
    }


@dataclass
class MjcfScene:
    """A scene's MJCF and how its coordinates map to Pinocchio's (by joint, in Pinocchio's order)."""

    xml: str
    joints: list[str]
    geometries: list[str]
    explicit_pairs: bool


def mjcf(scene: Scene, dt: float) -> MjcfScene:
    """The MJCF of ``scene``: a body per Pinocchio joint (its inertia, its joint, its collision
    geometries), each obstacle a world geom, the contact pairs the scene declares (masks when they
    are the pairs MuJoCo's masks collide, else explicit pairs), Newton with pyramidal cones,
    the implicitfast integrator, time step ``dt`` [s], no joint limits."""
    robot = scene.robot
    model, geometries = robot.model, robot.collision_model.geometryObjects
    explicit = _declared(scene) != _default_pairs(scene)
    masks = ' contype="0" conaffinity="0"' if explicit else ""
    assets: list[str] = []
    names = [f"g{k}" for k in range(len(geometries))]
    # with masks a geom pair takes the larger of its two frictions (MuJoCo's rule, and gaussim's)
    friction = {p.geometry: p.friction for p in scene.pairs}
    by_joint: dict[int, list[str]] = {}
    for k, g in enumerate(geometries):
        geom = _geom(names[k], g.geometry, g.placement, assets)
        if not explicit:
            geom = geom.replace("/>", f' friction="{friction.get(k, scene.self_contact[0])} 0 0"/>')
        by_joint.setdefault(int(g.parentJoint), []).append(geom)
    joints = [f"j{j}" for j in range(model.njoints)]

    def body(j: int) -> str:
        inertia = model.inertias[j]
        I = inertia.inertia
        full = _numbers((I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]))
        children = "".join(body(c) for c in range(j + 1, model.njoints) if model.parents[c] == j)
        armature = model.armature[model.joints[j].idx_v]
        joint = _joint(joints[j], model.joints[j])
        if armature and "freejoint" not in joint:
            joint = joint.replace("/>", f' armature="{armature:.9g}"/>')
        return (
            f'<body name="b{j}" {_frame(model.jointPlacements[j])}>{joint}'
            f'<inertial pos="{_numbers(inertia.lever)}" mass="{inertia.mass:.9g}" fullinertia="{full}"/>'
            + "".join(by_joint.get(j, []))
            + children
            + "</body>"
        )

    world = [body(j) for j in range(1, model.njoints) if model.parents[j] == 0]
    obstacles = []
    for k, o in enumerate(scene.obstacles):
        if isinstance(o, Ground):
            normal = np.asarray(o.normal)
            rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), normal).matrix()
            where = _frame(pin.SE3(rotation, o.height * normal))
            obstacles.append(f'<geom name="o{k}" type="plane" size="0 0 1" {where}/>')
        elif isinstance(o, Box):
            where = _frame(pin.SE3(np.asarray(o.rotation), np.asarray(o.position, float)))
            obstacles.append(
                f'<geom name="o{k}" type="box" size="{_numbers(np.asarray(o.size) / 2)}" {where}/>'
            )
        elif isinstance(o, Sphere):
            obstacles.append(
                f'<geom name="o{k}" type="sphere" size="{o.radius:.9g}" pos="{_numbers(o.position)}"/>'
            )
    pairs = ""
    if explicit:
        elements = []
        for p in scene.pairs:
            other = f"o{p.obstacle}" if p.other is None else names[p.other]
            mu = p.friction
            elements.append(
                f'<pair geom1="{names[p.geometry]}" geom2="{other}" condim="3" friction="{mu} {mu} 0 0 0"/>'
            )
        pairs = "<contact>" + "".join(elements) + "</contact>"
    else:
        obstacles = [
            x.replace("/>", f' friction="{o.friction} 0 0"/>') for x, o in zip(obstacles, scene.obstacles)
        ]
    gravity = _numbers(scene.gravity)
    xml = (
        '<mujoco><compiler angle="radian" inertiafromgeom="false" boundmass="0" boundinertia="0"/>'
        f'<option timestep="{dt}" gravity="{gravity}" integrator="implicitfast" solver="Newton" '
        'cone="pyramidal"/>'
        f'<default><geom condim="3"{masks}/><joint limited="false"/></default>'
        f"<asset>{''.join(assets)}</asset>"
        f"<worldbody>{''.join(obstacles + by_joint.get(0, []) + world)}</worldbody>{pairs}</mujoco>"
    )
    return MjcfScene(xml, joints, names, explicit)


# ---- the suite ------------------------------------------------------------------------------------


@dataclass
class Timing:
    """An engine's run of a scene: its step times [s], contact points per step, deepest penetration
    [m], and gaussim's largest KKT residual."""

    bodies: int = 0
    seconds: list[float] = field(default_factory=list)
    contacts: list[int] = field(default_factory=list)
    penetration: float = 0.0
    kkt_residual: float = float("nan")
    status: str = "ok"
    alone: list[float] = field(default_factory=list)  # the step times of its run alone [s]

    def row(self) -> dict[str, float]:
        return {
            "bodies": float(self.bodies),
            **_spread("us", self.seconds),
            **_spread("us_alone", self.alone),
            "contacts": float(np.mean(self.contacts)) if self.contacts else 0.0,
            "penetration": self.penetration,
            "kkt_residual": self.kkt_residual,
        }


def _spread(key: str, seconds: list[float]) -> dict[str, float]:
    """``key``_median and ``key``_p90 of step times ``seconds`` [s] in us, the first WARM_UP left out."""
    t = np.array(seconds[WARM_UP:]) * 1e6
    if not len(t):
        return {f"{key}_median": float("nan"), f"{key}_p90": float("nan")}
    return {f"{key}_median": float(np.median(t)), f"{key}_p90": float(np.percentile(t, 90))}


def run_scene(case: SceneCase, steps: int, peers: Iterable[str] | None = None) -> dict:
    """Step ``case`` ``steps`` times with gaussim (default options at the scene's dt) and each peer,
    the engines in turn at every step, each step timed (the drives, computed from each engine's own
    state, and the contact readings are not); then each engine again from the start, alone
    (:func:`_run_alone`: its memory warm from its own last step, as in a user's loop, where the turns
    leave each step's cache to the other engines: MuJoCo's step of one box took 3 times longer in
    turns); returns the scene's record: per engine its :meth:`Timing.row`, and the bodies and
    declared pairs of the scene."""
    from .peers import Bullet, MuJoCo, available

    setup = case.build()
    sim = Simulator(setup.scene, Options(dt=setup.dt))
    state = sim.reset(setup.q, setup.v)
    engines: dict[str, MuJoCo | Bullet] = {}
    timings = {"gaussim": Timing(len(setup.scene.bodies), kkt_residual=0.0)}
    installed = [e for e in ("mujoco", "pybullet") if any(p.startswith(e) for p in available())]
    for name in installed if peers is None else peers:
        try:
            engine = engines[name] = _peer(name, setup)
            timings[name] = Timing(engine.bodies())
        except ValueError as err:
            timings[name] = Timing(status=f"not run: {err}")
    for _ in range(steps):
        tau = setup.drive(state.t, state.q, state.v) if setup.drive else None
        tic = time.perf_counter()
        state = sim.step(state, tau, setup.damping)
        timings["gaussim"].seconds.append(time.perf_counter() - tic)
        report = sim.last_step
        assert report is not None
        mine = timings["gaussim"]
        mine.contacts.append(len(report.contacts))
        mine.penetration = max(mine.penetration, max((-c.gap for c in report.contacts), default=0.0))
        mine.kkt_residual = max(mine.kkt_residual, report.max_residual)
        for name, engine in engines.items():
            _drive(engine, setup)
            tic = time.perf_counter()
            engine.step()
            timings[name].seconds.append(time.perf_counter() - tic)
            n, depth = engine.contacts()
            timings[name].contacts.append(n)
            timings[name].penetration = max(timings[name].penetration, depth)
    for engine in engines.values():
        if isinstance(engine, Bullet):
            engine.close()
    _run_alone(setup, ["gaussim", *engines], steps, timings)
    mujoco_pairs = None
    peer = engines.get("mujoco")
    if isinstance(peer, MuJoCo):
        spec = peer.spec
        mujoco_pairs = len(setup.scene.pairs) if spec.explicit_pairs else len(_default_pairs(setup.scene))
    return {
        "scene": case.name,
        "about": case.about,
        "bodies": len(setup.scene.bodies),
        "nv": setup.scene.robot.model.nv,
        "pairs": len(setup.scene.pairs),
        "mujoco_pairs": mujoco_pairs,
        "steps": steps,
        "engines": {name: {**t.row(), "status": t.status} for name, t in timings.items()},
    }


def _peer(name: str, setup: Setup) -> MuJoCo | Bullet:
    """Peer engine ``name`` ("mujoco" or "pybullet") holding ``setup``'s scene at its start."""
    from .peers import Bullet, MuJoCo

    return MuJoCo(setup) if name == "mujoco" else Bullet(setup)


def _drive(engine: MuJoCo | Bullet, setup: Setup) -> None:
    """Apply ``setup``'s drive at the peer's own state (MuJoCo's; PyBullet runs free bodies only)."""
    from .peers import MuJoCo

    if isinstance(engine, MuJoCo) and setup.drive:
        q, v = engine.state()
        engine.apply(setup.drive(engine.data.time, q, v))


def _alone(name: str, setup: Setup) -> Generator[float, None, None]:
    """The step times [s] of engine ``name`` ("gaussim", "mujoco", "pybullet") stepping ``setup`` from
    its start, one per ``next``; closing it closes the engine."""
    from .peers import Bullet

    if name == "gaussim":
        sim = Simulator(setup.scene, Options(dt=setup.dt))
        state = sim.reset(setup.q, setup.v)
        while True:
            tau = setup.drive(state.t, state.q, state.v) if setup.drive else None
            tic = time.perf_counter()
            state = sim.step(state, tau, setup.damping)
            yield time.perf_counter() - tic
    engine = _peer(name, setup)
    try:
        while True:
            _drive(engine, setup)
            tic = time.perf_counter()
            engine.step()
            yield time.perf_counter() - tic
    finally:
        if isinstance(engine, Bullet):
            engine.close()


def _run_alone(setup: Setup, names: list[str], steps: int, timings: dict[str, Timing]) -> None:
    """Each engine of ``names`` stepping ``setup`` ``steps`` times from its start, alone for ALONE_BLOCK
    steps at a time, the engines taking the blocks in turn (a drift of the machine's speed then reaches
    them alike); their times into ``timings[name].alone``."""
    runs = {name: _alone(name, setup) for name in names}
    for first in range(0, steps, ALONE_BLOCK):
        for name, run in runs.items():
            timings[name].alone += [next(run) for _ in range(min(ALONE_BLOCK, steps - first))]
    for run in runs.values():
        run.close()


def run_suite(
    names: Iterable[str] | None = None,
    quick: bool = False,
    peers: Iterable[str] | None = None,
    progress: Callable[[str], None] | None = None,
) -> list[dict]:
    """Run the suite's scenes (default: all, or the quick ones with ``quick``, QUICK_STEPS steps
    instead of STEPS); ``progress`` is told of each scene as it starts and ends."""
    chosen = list(names or [n for n, c in SCENES.items() if c.quick or not quick])
    unknown = sorted(set(chosen) - set(SCENES))
    if unknown:
        raise ValueError(f"unknown scenes {unknown}; known: {', '.join(SCENES)}")
    records = []
    for k, name in enumerate(chosen, start=1):
        if progress:
            progress(f"[{k}/{len(chosen)}] {name}: {SCENES[name].about} ...")
        tic = time.perf_counter()
        try:
            records.append(run_scene(SCENES[name], QUICK_STEPS if quick else STEPS, peers))
        except FileNotFoundError as err:  # an installed package has no examples folder
            if progress:
                progress(f"[{k}/{len(chosen)}] {name}: left out: {err}")
            continue
        if progress:
            progress(f"[{k}/{len(chosen)}] {name}: done in {time.perf_counter() - tic:.1f} s")
    return records


TITLE = "Scene suite for speed"
INTRO = """Each scene is stepped by gaussim (default options, velocity scheme, dt 1 ms), MuJoCo (Newton,
pyramidal cones, implicitfast, its default soft contacts) and PyBullet (scenes of primitive free bodies
only), from models generated from the same gaussim scene (`gaussim.bench.scenes.mjcf`: the same
bodies, inertias, collision geometries or their convex hulls, friction and contact pairs): first the
engines in turn at every step in one process, then each engine alone from the same start, as a user's
loop runs it (in blocks of 100 steps, the engines' blocks in turn, so that a drift of the machine's
speed reaches them alike). `us` is the time of one step, median / p90 over the run (the first steps,
which compile, left out); the ratio is gaussim's time over the peer's. In turns, each engine's step
starts with a cache the others' steps have filled, which slows a small step most: compare the ratios
alone. Contact points are the mean per step of each engine; penetration is gaussim's deepest and the
KKT residual its largest (of the steps' certificates)."""


def write_section(path: Path, title: str, text: str) -> None:
    """Put ``text`` under the heading ``## title`` of the markdown file ``path``, replacing that
    section (up to the next ``## `` heading) when there is one, else appending it. The replaced
    section's ``### `` subsections are hand-written notes on its table: they are kept, after ``text``."""
    from ..files import atomic_path

    old = path.read_text() if path.exists() else ""
    heading = f"## {title}\n"
    section = f"{heading}\n{text.strip()}\n"
    if heading in old:
        before, after = old.split(heading, 1)
        body, *rest = after.split("\n## ", 1)
        notes = body.split("\n### ", 1)
        if len(notes) > 1:
            section += "\n### " + notes[1].rstrip("\n") + "\n"
        new = before + section + ("\n## " + rest[0] if rest else "")
    else:
        new = old.rstrip("\n") + ("\n\n" if old else "") + section
    with atomic_path(path) as tmp:
        tmp.write_text(new)


def markdown(records: list[dict]) -> str:
    """The suite's table: a row per scene, per engine its median and p90 step [us] in turns and alone
    (see :func:`run_scene`), gaussim's ratio to each peer in each, contact points per step (mean), and
    gaussim's deepest penetration and KKT residual."""
    peers = list(dict.fromkeys(e for r in records for e in r["engines"] if e != "gaussim"))
    header = ["scene", "bodies", "nv", "pairs"]
    for how in ("in turns", "alone"):
        header.append(f"gaussim us {how} (median / p90)")
        for peer in peers:
            header += [f"{peer} us {how} (median / p90)", f"ratio to {peer} {how} (median / p90)"]
    header += ["contact points (" + " / ".join(["gaussim", *peers]) + ")", "penetration [m]", "KKT residual"]
    lines = ["| " + " | ".join(header) + " |", "|---|" + "---:|" * (len(header) - 1)]
    for r in records:
        g = r["engines"]["gaussim"]
        cells = [r["scene"], str(r["bodies"]), str(r["nv"]), str(r["pairs"])]
        for key in ("us", "us_alone"):
            cells.append(f"{g[key + '_median']:.0f} / {g[key + '_p90']:.0f}")
            for peer in peers:
                cells += _peer_cells(g, r["engines"].get(peer), key)
        counts = [f"{g['contacts']:.1f}"]
        for peer in peers:
            e = r["engines"].get(peer)
            counts.append(f"{e['contacts']:.1f}" if e is not None and e["status"] == "ok" else "-")
        cells += [" / ".join(counts), f"{g['penetration']:.2e}", f"{g['kkt_residual']:.1e}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _peer_cells(g: dict, e: dict | None, key: str) -> list[str]:
    """A peer's two cells of timing ``key`` ("us" or "us_alone"): its median / p90 step and gaussim's
    ratio to it (``g``: gaussim's row), or its status."""
    if e is None or e["status"] != "ok":
        return [e["status"] if e else "not installed", ""]
    median, p90 = f"{key}_median", f"{key}_p90"
    return [f"{e[median]:.1f} / {e[p90]:.1f}", f"{g[median] / e[median]:.1f} / {g[p90] / e[p90]:.1f}"]
