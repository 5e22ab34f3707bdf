"""Peer engines for the benchmark, run on the same robot in the same sweep when installed
(``pip install -e '.[bench]'``): MuJoCo (Newton and PGS, pyramidal and elliptic cones), Pinocchio 4's
own ADMM and PGS constraint solvers (driven from Python: :func:`pinocchio_standing`) and PyBullet,
on Solo-12 standing.

Each peer follows the protocol of gaussim's solo12 case (see :func:`standing`) under the same PD hold,
at its default settings and at the settings a user turns to for accuracy (smaller steps, stiffer
contacts, MuJoCo's no-slip pass, tighter tolerances), so that the matched-accuracy table can pick
each engine's cheapest setting that meets a given penetration and slip. Only each engine's own step
is timed (Pinocchio's solvers have no step of their own: the whole Python step is).

Facts this relies on (measured here):
- MuJoCo's URDF import welds the root link to the world (the model is saved as MJCF and given a free
  joint), does not resolve ``package://`` meshes (the feet become spheres of gaussim's foot size),
  and ``fusestatic="false"`` keeps the foot bodies; Pinocchio's quaternions are xyzw, MuJoCo's wxyz.
- MuJoCo's contacts are soft: at its defaults (solref 0.02 s) Solo-12 rests 0.8 mm deep at any time
  step; a time constant of 2 dt with solimp (0.99, 0.999) stiffens them as far as dt allows.
- PyBullet: ``URDF_USE_INERTIA_FROM_FILE`` (else it recomputes inertias from the collision shapes), its
  default velocity motors are disabled for torque control, and it multiplies the two bodies' friction
  coefficients (the ground gets 1, the feet 0.8); restitution is set to 0 on both.
"""

from __future__ import annotations

import re
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..robot import Robot, load_robot
from ..scene import Box, Ground
from ..world import FreeBody
from .cases import LANDING, G, standing_window
from .scenes import FRICTION, Setup, mjcf

FEET = ("FL", "FR", "HL", "HR")
KP, KD = 5.0, 0.2  # robots/scenes/solo12_standing.toml's PD hold
CLEARANCE = 0.01  # the scene's drop [m]
MARGIN = 5e-3  # [m] a foot this close to the ground is a contact of the Pinocchio peers' step

Setting = dict[str, float]


@dataclass(frozen=True)
class Peer:
    """An engine other than gaussim: the cases it runs, how (``run(case, quick, setting)`` -> metrics)
    and its settings by label (the default one is ``{}``)."""

    cases: tuple[str, ...]
    run: Callable[[str, bool, Setting], dict[str, float]]
    settings: dict[str, Setting] = field(default_factory=dict)


def standing(
    control: Callable[[], None],
    advance: Callable[[], None],
    feet: Callable[[], tuple[np.ndarray, np.ndarray]],
    radius: float,
    contacts: Callable[[], tuple[float, float]],
    dt: float,
    quick: bool,
    weight: float,
) -> dict[str, float]:
    """The solo12 case's protocol for a peer: LANDING seconds, then the standing window;
    ``control()`` applies the PD torques (untimed), ``advance()`` steps the
    engine (timed), ``feet()`` gives the feet's orientations (4, 3, 3) and their spheres' centres
    (4, 3) (``radius`` [m]) in the world, ``contacts()`` the deepest penetration [m] and the sum of
    the normal forces [N] now.

    Returns the metrics gaussim's solo12 case reports where the peer has them: error (force balance at
    the end, |sum f_n - m g| / m g), penetration (the whole run) and standing_penetration (the window)
    [m], slip_per_s [m/s] (the largest horizontal displacement over the window of a foot's material
    point that touched the ground at its start: a sphere that rolls does not slip), the step's
    wall time (median and p90 [us], per simulated second [s])."""
    seconds: list[float] = []
    penetration = window_penetration = 0.0
    window = standing_window(quick)
    landing_steps = round(LANDING / dt)
    start, local = np.zeros((len(FEET), 3)), np.zeros((len(FEET), 3))
    for k in range(landing_steps + round(window / dt)):
        if k == landing_steps:  # the feet's lowest points, and where they are on the feet
            rotations, centers = feet()
            start = centers - [0.0, 0.0, radius]
            local = np.einsum("kji,j->ki", rotations, [0.0, 0.0, -radius])
        control()
        tic = time.perf_counter()
        advance()
        seconds.append(time.perf_counter() - tic)
        depth = contacts()[0]
        penetration = max(penetration, depth)
        if k >= landing_steps:
            window_penetration = max(window_penetration, depth)
    rotations, centers = feet()
    end = centers + np.einsum("kij,kj->ki", rotations, local)
    slip = float(np.max(np.linalg.norm((end - start)[:, :2], axis=1))) / window
    times = np.array(seconds)
    return {
        "error": abs(contacts()[1] - weight) / weight,
        "penetration": penetration,
        "standing_penetration": window_penetration,
        "slip_per_s": slip,
        "us_per_step": float(np.median(times)) * 1e6,
        "us_per_step_p90": float(np.percentile(times, 90)) * 1e6,
        "wall_per_sim_s": float(times.sum()) / (len(times) * dt),
    }


def primitive_urdf(robot: Robot) -> tuple[str, float, np.ndarray]:
    """(Solo-12's URDF without visuals or collision meshes, the radius [m] and the centre in the lower
    leg's frame of gaussim's foot (the ball around its collision hull))."""
    text = Path(robot.urdf).read_text()
    text = re.sub(r"<visual>.*?</visual>", "", text, flags=re.S)
    text = re.sub(r"<collision>.*?</collision>", "", text, flags=re.S)
    geometry = robot.collision_model.geometryObjects[robot.geometry_id("FL_FOOT_0")]
    points = np.asarray(geometry.geometry.convex.points())
    radius = float(np.max(np.linalg.norm(points - points.mean(axis=0), axis=1)))
    return text, radius, geometry.placement.act(points.mean(axis=0))


def mujoco_model(robot: Robot, dt: float = 1e-3):  # type: ignore[no-untyped-def]
    """Solo-12 in MuJoCo: sphere feet of gaussim's foot size, a free joint, a floor."""
    import mujoco

    text, radius, center = primitive_urdf(robot)
    text = text.replace(
        "</robot>", '<mujoco><compiler fusestatic="false" discardvisual="true"/></mujoco></robot>'
    )
    spec_model = mujoco.MjModel.from_xml_string(text)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "solo12.xml"
        mujoco.mj_saveLastXML(str(path), spec_model)
        xml = path.read_text()
    pos = " ".join(f"{x:.5f}" for x in center)
    for leg in FEET:
        xml = re.sub(
            rf'(<body name="{leg}_LOWER_LEG"[^>]*>)',
            rf'\1<geom type="sphere" size="{radius:.5f}" pos="{pos}" friction="0.8"/>',
            xml,
        )
    xml = re.sub(r'(<body name="base_link"[^>]*>)', r"\1<freejoint/>", xml, count=1)
    xml = xml.replace("<worldbody>", '<worldbody><geom type="plane" size="5 5 0.1" friction="0.8"/>', 1)
    xml = xml.replace("<compiler", f'<option timestep="{dt}" integrator="implicitfast"/><compiler', 1)
    return mujoco.MjModel.from_xml_string(xml)


def mujoco_standing(solver: str, cone: str) -> Callable[[str, bool, Setting], dict[str, float]]:
    """MuJoCo on Solo-12 standing; a setting may change ``dt``, make the contacts ``stiff`` (solref
    (2 dt, 1), solimp (0.99, 0.999, 0.001)) and run ``noslip`` iterations."""

    def run(case: str, quick: bool, setting: Setting) -> dict[str, float]:
        import mujoco

        robot = load_robot("solo12")
        dt = setting.get("dt", 1e-3)
        model = mujoco_model(robot, dt)
        model.opt.solver = {"newton": mujoco.mjtSolver.mjSOL_NEWTON, "pgs": mujoco.mjtSolver.mjSOL_PGS}[
            solver
        ]
        model.opt.cone = {
            "pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL,
            "elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC,
        }[cone]
        if setting.get("stiff"):
            model.geom_solref[:] = (2 * dt, 1.0)
            model.geom_solimp[:] = (0.99, 0.999, 0.001, 0.5, 2.0)
        model.opt.noslip_iterations = int(setting.get("noslip", 0))
        data = mujoco.MjData(model)
        q_ref = robot.configuration("standing")
        data.qpos[:3] = q_ref[:3]
        data.qpos[2] += CLEARANCE
        data.qpos[3:7] = [q_ref[6], *q_ref[3:6]]  # Pinocchio xyzw -> MuJoCo wxyz
        data.qpos[7:] = q_ref[7:]
        feet = [g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE]
        radius = float(model.geom_size[feet[0], 0])
        wrench = np.zeros(6)

        def control() -> None:
            data.qfrc_applied[6:] = KP * (q_ref[7:] - data.qpos[7:]) - KD * data.qvel[6:]

        def contacts() -> tuple[float, float]:
            if not data.ncon:
                return 0.0, 0.0
            normal = 0.0
            for i in range(data.ncon):
                mujoco.mj_contactForce(model, data, i, wrench)
                normal += wrench[0]  # the normal is the contact frame's first axis
            return max(0.0, -float(data.contact.dist.min())), normal

        return standing(
            control,
            lambda: mujoco.mj_step(model, data),
            lambda: (data.geom_xmat[feet].reshape(-1, 3, 3).copy(), data.geom_xpos[feet].copy()),
            radius,
            contacts,
            dt,
            quick,
            float(np.sum(model.body_mass)) * G,
        )

    return run


def pybullet_standing(case: str, quick: bool, setting: Setting) -> dict[str, float]:
    """PyBullet on Solo-12 standing; a setting may change ``dt`` and the solver's ``iterations``."""
    import pybullet as p

    robot = load_robot("solo12")
    dt = setting.get("dt", 1e-3)
    text, radius, center = primitive_urdf(robot)
    pos = " ".join(f"{x:.6f}" for x in center)
    sphere = (
        f'<collision><origin xyz="{pos}"/><geometry><sphere radius="{radius:.6f}"/></geometry></collision>'
    )
    for leg in FEET:
        text = text.replace(f'<link name="{leg}_LOWER_LEG">', f'<link name="{leg}_LOWER_LEG">{sphere}')
    client = p.connect(p.DIRECT)
    try:
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "solo12.urdf"
            path.write_text(text)
            q_ref = robot.configuration("standing")
            base = q_ref[:3] + [0.0, 0.0, CLEARANCE]
            body = p.loadURDF(
                str(path), base, q_ref[3:7], flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=client
            )
        p.setGravity(0, 0, -G, physicsClientId=client)
        p.setTimeStep(dt, physicsClientId=client)
        p.setPhysicsEngineParameter(
            numSolverIterations=int(setting.get("iterations", 50)), physicsClientId=client
        )
        plane = p.createMultiBody(
            0, p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client), physicsClientId=client
        )
        index = {
            p.getJointInfo(body, j, physicsClientId=client)[1].decode(): j
            for j in range(p.getNumJoints(body, physicsClientId=client))
        }
        joints = [index[robot.model.names[j]] for j in range(2, robot.model.njoints)]  # Pinocchio's order
        legs = [index[f"{leg}_KFE"] for leg in FEET]  # the lower legs (a link's index is its joint's)
        for j, angle in zip(joints, q_ref[7:]):
            p.resetJointState(body, j, angle, physicsClientId=client)
        p.changeDynamics(plane, -1, lateralFriction=1.0, restitution=0.0, physicsClientId=client)
        for link in legs:
            p.changeDynamics(body, link, lateralFriction=0.8, restitution=0.0, physicsClientId=client)
        motors = p.VELOCITY_CONTROL  # PyBullet's default motors, disabled by a zero force
        p.setJointMotorControlArray(body, joints, motors, forces=[0.0] * 12, physicsClientId=client)
        mass = sum(p.getDynamicsInfo(body, j, physicsClientId=client)[0] for j in range(-1, len(index)))

        def control() -> None:
            states = p.getJointStates(body, joints, physicsClientId=client)
            q, v = np.array([s[0] for s in states]), np.array([s[1] for s in states])
            tau = KP * (q_ref[7:] - q) - KD * v
            p.setJointMotorControlArray(body, joints, p.TORQUE_CONTROL, forces=tau, physicsClientId=client)

        def feet() -> tuple[np.ndarray, np.ndarray]:
            rotations, centers = [], []
            for link in legs:
                state = p.getLinkState(body, link, physicsClientId=client)
                rotations.append(np.array(p.getMatrixFromQuaternion(state[5])).reshape(3, 3))
                centers.append(np.array(state[4]) + rotations[-1] @ center)
            return np.array(rotations), np.array(centers)

        def contacts() -> tuple[float, float]:
            points = p.getContactPoints(bodyA=plane, bodyB=body, physicsClientId=client)
            depth = max((-c[8] for c in points), default=0.0)
            return max(0.0, depth), sum(c[9] for c in points)

        return standing(
            control,
            lambda: p.stepSimulation(physicsClientId=client),
            feet,
            radius,
            contacts,
            dt,
            quick,
            mass * G,
        )
    finally:
        p.disconnect(physicsClientId=client)


def pinocchio_standing(solver: str) -> Callable[[str, bool, Setting], dict[str, float]]:
    """Pinocchio 4's own constraint solver (``"admm"`` or ``"pgs"``) on Solo-12 standing, driven from
    Python by the velocity-level time stepping gaussim uses: ABA gives v_free; each foot (a sphere of
    gaussim's foot size) within MARGIN of the ground becomes a PointContactConstraintModel (friction
    0.8) whose two placements coincide at the sphere's lowest point, its frame's z into the ground (the
    constraint's velocity is joint 2's minus joint 1's, evaluated where the placements are); the
    Delassus operator comes from Pinocchio's ContactCholeskyDecomposition; the solver finds the
    impulses of the frictional contact problem with g = J v_free + gap term (gap / dt when open,
    gaussim's stabilisation / dt on a penetration); v+ = v_free + M^-1 J^T lambda; q+ = q (+) dt v+.
    A setting may change ``dt`` and the solver's tolerance ``tol`` (default 1e-6, Pinocchio's). The
    whole step is timed: Pinocchio's solvers have no step of their own."""

    def run(case: str, quick: bool, setting: Setting) -> dict[str, float]:
        import pinocchio as pin

        from ..options import Options

        robot = load_robot("solo12")
        model, data = robot.model, robot.model.createData()
        dt, tolerance = setting.get("dt", 1e-3), setting.get("tol", 1e-6)
        _, radius, center = primitive_urdf(robot)
        legs = [
            robot.collision_model.geometryObjects[robot.geometry_id(f"{leg}_FOOT_0")].parentJoint
            for leg in FEET
        ]
        stabilisation = Options().stabilisation
        if solver == "admm":
            engine, settings, make_result = (
                pin.ADMMConstraintSolver(),
                pin.ADMMSolverSettings(),
                pin.ADMMSolverResult,
            )
        else:
            engine, settings, make_result = (
                pin.PGSConstraintSolver(),
                pin.PGSSolverSettings(),
                pin.PGSSolverResult,
            )
        for name in ("absolute_feasibility_tol", "absolute_complementarity_tol"):
            setattr(settings, name, tolerance)
        down = np.diag([1.0, -1.0, -1.0])  # the contact frame: z into the ground
        q = robot.configuration("standing")
        q_ref = q.copy()
        q[2] += CLEARANCE
        v = np.zeros(model.nv)
        tau = np.zeros(model.nv)
        gaps, normal, unconverged = np.zeros(0), 0.0, 0  # the last step's contact gaps and normal force

        def control() -> None:
            tau[6:] = KP * (q_ref[7:] - q[7:]) - KD * v[6:]

        def advance() -> None:
            nonlocal q, v, gaps, normal, unconverged
            v_free = v + dt * pin.aba(model, data, q, v, tau, pin.Convention.WORLD)
            models, touching = pin.StdVec_ConstraintModel(), []
            for joint in legs:
                placement = data.oMi[joint]
                lowest = placement.act(center) - [0.0, 0.0, radius]
                if lowest[2] < MARGIN:
                    where = pin.SE3(placement.rotation.T @ down, placement.actInv(lowest))
                    contact = pin.PointContactConstraintModel(model, joint, where, 0, pin.SE3(down, lowest))
                    contact.setFriction(0.8)
                    models.append(pin.ConstraintModel(contact))
                    touching.append(lowest[2])
            gaps, normal = np.array(touching), 0.0
            if not touching:
                v = v_free
            else:
                datas = pin.StdVec_ConstraintData()
                for constraint in models:
                    datas.append(constraint.createData())
                pin.crba(model, data, q, pin.Convention.WORLD)
                pin.cholesky.decompose(model, data)  # for M^-1 J^T lambda
                for constraint, constraint_data in zip(models, datas):
                    constraint.calc(model, data, constraint_data)
                cholesky = pin.ContactCholeskyDecomposition(model, data, models, datas)
                cholesky.compute(model, data, models, datas, 1e-10)
                J = pin.getConstraintsJacobian(model, data, models, datas)
                g = J @ v_free
                g[2::3] += np.where(gaps > 0, gaps, stabilisation * gaps) / dt
                result = make_result()
                delassus = cholesky.getDelassusOperatorCholeskyExpression()
                unconverged += not engine.solve(delassus, g, models, datas, settings, result)
                impulses = np.asarray(result.retrieveConstraintImpulses()).ravel()
                normal = float(impulses[2::3].sum()) / dt
                v = v_free + pin.cholesky.solve(model, data, J.T @ impulses)
            q = pin.integrate(model, q, dt * v)

        def feet() -> tuple[np.ndarray, np.ndarray]:
            pin.forwardKinematics(model, data, q)
            placements = [data.oMi[joint] for joint in legs]
            return np.array([m.rotation for m in placements]), np.array([m.act(center) for m in placements])

        def contacts() -> tuple[float, float]:
            return max(0.0, -float(gaps.min(initial=0.0))), normal

        metrics = standing(control, advance, feet, radius, contacts, dt, quick, robot.mass * G)
        return {**metrics, "unconverged_steps": float(unconverged)}

    return run


def _mujoco_settings() -> dict[str, Setting]:
    settings: dict[str, Setting] = {f"dt={dt:g}": {"dt": dt} for dt in (2e-3, 5e-3)}
    for dt in (5e-3, 2e-3, 1e-3, 5e-4, 2e-4):
        settings[f"dt={dt:g} stiff"] = {"dt": dt, "stiff": 1}
    for dt in (5e-3, 2e-3, 1e-3):
        settings[f"dt={dt:g} stiff noslip=10"] = {"dt": dt, "stiff": 1, "noslip": 10}
    return settings


PEERS: dict[str, Peer] = {
    **{
        f"mujoco-{solver}-{cone}": Peer(("solo12",), mujoco_standing(solver, cone), _mujoco_settings())
        for solver in ("newton", "pgs")
        for cone in ("pyramidal", "elliptic")
    },
    **{
        f"pinocchio-{solver}": Peer(
            ("solo12",),
            pinocchio_standing(solver),
            {
                **{f"dt={dt:g}": {"dt": dt} for dt in (1e-2, 5e-3, 2e-3)},  # the explicit PD diverges at 2e-2
                "tol=1e-9": {"tol": 1e-9},
            },
        )
        for solver in ("admm", "pgs")
    },
    "pybullet": Peer(
        ("solo12",),
        pybullet_standing,
        {
            **{f"dt={dt:g}": {"dt": dt} for dt in (5e-3, 2e-3, 5e-4, 2e-4)},
            "iterations=200": {"iterations": 200},
        },
    ),
}


# ---- the scene suite's peers (gaussim.bench.scenes) ------------------------------------------------


class MuJoCo:
    """A scene in MuJoCo: its state set from and read as Pinocchio's (q, v), a step under a torque."""

    def __init__(self, setup: Setup) -> None:
        import mujoco

        self.mujoco = mujoco
        self.spec = mjcf(setup.scene, setup.dt)
        self.model = mujoco.MjModel.from_xml_string(self.spec.xml)
        self.data = mujoco.MjData(self.model)
        self.pin = setup.scene.robot.model
        self.q_index, self.v_index = self._indices()
        if setup.damping is not None:
            self.model.dof_damping[self.v_index] = setup.damping
        self.set_state(setup.q, setup.v)
        mujoco.mj_forward(self.model, self.data)

    def _indices(self) -> tuple[np.ndarray, np.ndarray]:
        """MuJoCo's qpos and qvel indices of Pinocchio's q and v (free joints' quaternions aside)."""
        q, v = np.zeros(self.pin.nq, int), np.zeros(self.pin.nv, int)
        for j in range(1, self.pin.njoints):
            joint = self.model.joint(self.spec.joints[j])
            pj = self.pin.joints[j]
            q[pj.idx_q : pj.idx_q + pj.nq] = joint.qposadr[0] + np.arange(pj.nq)
            v[pj.idx_v : pj.idx_v + pj.nv] = joint.dofadr[0] + np.arange(pj.nv)
        return q, v

    def _free(self) -> list[tuple[int, int]]:
        return [
            (self.pin.joints[j].idx_q, self.pin.joints[j].idx_v)
            for j in range(1, self.pin.njoints)
            if self.pin.joints[j].shortname() == "JointModelFreeFlyer"
        ]

    def set_state(self, q: np.ndarray, v: np.ndarray) -> None:
        qpos, qvel = q.copy(), v.copy()
        for iq, iv in self._free():
            qpos[iq + 3 : iq + 7] = np.roll(q[iq + 3 : iq + 7], 1)  # xyzw -> wxyz
            qvel[iv : iv + 3] = pin.Quaternion(q[iq + 3 : iq + 7]).matrix() @ v[iv : iv + 3]
        self.data.qpos[self.q_index] = qpos
        self.data.qvel[self.v_index] = qvel

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """Pinocchio's (q, v) of MuJoCo's state."""
        q, v = self.data.qpos[self.q_index].copy(), self.data.qvel[self.v_index].copy()
        for iq, iv in self._free():
            q[iq + 3 : iq + 7] = np.roll(q[iq + 3 : iq + 7], -1)  # wxyz -> xyzw
            v[iv : iv + 3] = pin.Quaternion(q[iq + 3 : iq + 7]).matrix().T @ v[iv : iv + 3]
        return q, v

    def apply(self, tau: np.ndarray) -> None:
        self.data.qfrc_applied[self.v_index] = tau

    def step(self) -> None:
        self.mujoco.mj_step(self.model, self.data)

    def contacts(self) -> tuple[int, float]:
        """(contact points, deepest penetration [m]) now."""
        n = int(self.data.ncon)
        return n, max(0.0, -float(self.data.contact.dist[:n].min())) if n else 0.0

    def bodies(self) -> int:
        """The scene's bodies: MuJoCo's bodies whose parent is the world."""
        return int(np.count_nonzero(self.model.body_parentid[1:] == 0))


class Bullet:
    """A scene of free bodies (boxes, spheres, capsules, cylinders; ground and box obstacles) in
    PyBullet: every pair collides (gaussim's automatic pairs of free bodies), each body and obstacle
    has its friction (PyBullet multiplies the two sides': the obstacles get 1 and the bodies the pair's
    coefficient, which every suite scene gives all pairs alike); restitution 0.

    Raises:
        ValueError: the scene holds a robot or a shape PyBullet is not given here.
    """

    def __init__(self, setup: Setup) -> None:
        import pybullet as p

        scene = setup.scene
        sources = [layout.body.source for layout in scene.bodies.values()]
        if not all(isinstance(s, FreeBody) and s.shape != "mesh" for s in sources):
            raise ValueError("PyBullet runs scenes of primitive free bodies only")
        frictions = {p_.friction for p_ in scene.pairs}
        if len(frictions) > 1:
            raise ValueError(f"PyBullet's product of frictions cannot give the pairs' {sorted(frictions)}")
        mu = frictions.pop() if frictions else FRICTION
        self.p, self.client = p, p.connect(p.DIRECT)
        c = self.client
        p.setGravity(*scene.gravity, physicsClientId=c)
        p.setTimeStep(setup.dt, physicsClientId=c)
        for o in scene.obstacles:
            if isinstance(o, Ground):
                shape = p.createCollisionShape(p.GEOM_PLANE, planeNormal=o.normal, physicsClientId=c)
                uid = p.createMultiBody(
                    0, shape, basePosition=o.height * np.asarray(o.normal), physicsClientId=c
                )
            elif isinstance(o, Box):
                shape = p.createCollisionShape(
                    p.GEOM_BOX, halfExtents=np.asarray(o.size) / 2, physicsClientId=c
                )
                orientation = pin.Quaternion(np.asarray(o.rotation)).coeffs()
                uid = p.createMultiBody(
                    0, shape, basePosition=o.position, baseOrientation=orientation, physicsClientId=c
                )
            else:
                raise ValueError(f"{o.name}: PyBullet is given grounds and boxes only")
            p.changeDynamics(uid, -1, lateralFriction=1.0, restitution=0.0, physicsClientId=c)
        self.uids = []
        for source, layout in zip(sources, scene.bodies.values()):
            assert isinstance(source, FreeBody)
            shape = self._shape(source)
            q = setup.q[layout.q]
            uid = p.createMultiBody(
                source.mass, shape, basePosition=q[:3], baseOrientation=q[3:7], physicsClientId=c
            )
            inertia = np.diag(source._inertia)
            p.changeDynamics(
                uid, -1, lateralFriction=mu, restitution=0.0, localInertiaDiagonal=inertia, physicsClientId=c
            )
            self.uids.append(uid)

    def _shape(self, body: FreeBody) -> int:
        p, c = self.p, self.client
        if body.shape == "box":
            return p.createCollisionShape(
                p.GEOM_BOX, halfExtents=np.asarray(body.size) / 2, physicsClientId=c
            )
        if body.shape == "sphere":
            return p.createCollisionShape(p.GEOM_SPHERE, radius=body.size[0], physicsClientId=c)
        kind = p.GEOM_CAPSULE if body.shape == "capsule" else p.GEOM_CYLINDER
        return p.createCollisionShape(kind, radius=body.size[0], height=body.size[1], physicsClientId=c)

    def step(self) -> None:
        self.p.stepSimulation(physicsClientId=self.client)

    def contacts(self) -> tuple[int, float]:
        points = self.p.getContactPoints(physicsClientId=self.client)
        return len(points), max((max(0.0, -c[8]) for c in points), default=0.0)

    def bodies(self) -> int:
        return len(self.uids)

    def close(self) -> None:
        self.p.disconnect(physicsClientId=self.client)


def available() -> list[str]:
    """The peers installed on this machine."""
    names = []
    for module, prefix in (("pinocchio", "pinocchio-"), ("mujoco", "mujoco-"), ("pybullet", "pybullet")):
        try:
            __import__(module)
        except ImportError:
            continue
        names += [name for name in PEERS if name.startswith(prefix)]
    return names
