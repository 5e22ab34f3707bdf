"""Robots from every source: MJCF against MuJoCo's reading of the same file, SDF against a URDF of
the same robot (written by hand, and pybullet_data's KUKA iiwa pair), the Pinocchio objects users
hold through ``as_robot``; each falls or steps in a Simulator, and each bad input names its fault."""

from __future__ import annotations

import warnings
from pathlib import Path

import coal
import example_robot_data
import mujoco
import numpy as np
import pinocchio as pin
import pybullet_data
import pytest

import gaussim
from gaussim import mjcf
from gaussim.robot import as_robot

DATA = Path(__file__).resolve().parent / "data"
HOPPER, WALKER, WALKER_URDF = DATA / "hopper.xml", DATA / "walker.sdf", DATA / "walker.urdf"
KUKA = Path(pybullet_data.getDataPath()) / "kuka_iiwa"
EXACT = 1e-12  # two readings of the same numbers
KUKA_ROUNDING = 1e-4  # pybullet_data's model.sdf rounds its angles to 6 digits (1.5708 for pi / 2)
PENETRATION = 1e-4  # [m] the deepest a resting contact may sink
FALL_TIME = 0.4  # [s]


@pytest.fixture(autouse=True)
def _mujoco_logs_kept_out(tmp_path, monkeypatch):
    """Each test in its own folder: MuJoCo writes the MUJOCO_LOG.TXT of its warnings (settotalmass) and
    of the files it refuses in the working folder."""
    monkeypatch.chdir(tmp_path)


def load_quietly(path: Path, **kwargs) -> gaussim.Robot:
    """A robot whose file leaves out what a Scene holds (a floor, static models): that is warned."""
    with pytest.warns(gaussim.GaussimWarning, match="left out"):
        return gaussim.load_robot(path, **kwargs)


@pytest.fixture(scope="module")
def hopper() -> gaussim.Robot:
    return load_quietly(HOPPER)


@pytest.fixture(scope="module")
def walker() -> gaussim.Robot:
    return load_quietly(WALKER)


def symmetric(M: np.ndarray) -> np.ndarray:
    return np.triu(M) + np.triu(M, 1).T


def mass_matrix(robot: gaussim.Robot, q: np.ndarray) -> np.ndarray:
    return symmetric(pin.crba(robot.model, robot.model.createData(), q))


def random_configurations(robot: gaussim.Robot, count: int = 3) -> list[np.ndarray]:
    np.random.seed(0)  # pin.randomConfiguration draws from numpy's global generator
    bound = np.ones(robot.model.nq)
    return [pin.randomConfiguration(robot.model, -bound, bound) for _ in range(count)]


def mujoco_configuration(q: np.ndarray) -> np.ndarray:
    """A free-floating robot's q in MuJoCo's order (its quaternion w, x, y, z; Pinocchio's x, y, z, w)."""
    return np.concatenate([q[:3], [q[6]], q[3:6], q[7:]])


# --- MJCF -----------------------------------------------------------------------------------------


def test_mjcf_hopper_is_mujocos_robot(hopper):
    """nq, nv, masses, the mass matrix at random configurations, the joint limits and the keyframe
    are MuJoCo's for the same file."""
    reference = mujoco.MjModel.from_xml_path(str(HOPPER))
    data = mujoco.MjData(reference)
    assert (hopper.model.nq, hopper.model.nv) == (reference.nq, reference.nv) == (10, 9)
    assert hopper.floating
    assert hopper.mass == pytest.approx(reference.body_mass.sum(), abs=EXACT)
    assert [hopper.model.inertias[i].mass for i in range(1, 5)] == pytest.approx(reference.body_mass[1:])
    for q in random_configurations(hopper):
        data.qpos[:] = mujoco_configuration(q)
        mujoco.mj_forward(reference, data)
        M = np.zeros((reference.nv, reference.nv))
        mujoco.mj_fullM(reference, data, M)
        # MuJoCo's free joint moves its linear velocity in the world frame, Pinocchio's in the body's
        T = np.eye(reference.nv)
        T[:3, :3] = pin.Quaternion(q[6], *q[3:6]).matrix()
        np.testing.assert_allclose(mass_matrix(hopper, q), T.T @ M @ T, atol=EXACT)
    for k, name in enumerate(["hip", "knee", "ankle"], start=1):
        iq = hopper.model.joints[hopper.model.getJointId(name)].idx_q
        limits = reference.jnt_range[k] if reference.jnt_limited[k] else (-np.inf, np.inf)
        assert (hopper.model.lowerPositionLimit[iq], hopper.model.upperPositionLimit[iq]) == pytest.approx(
            limits
        )
    np.testing.assert_allclose(
        mujoco_configuration(hopper.configuration("crouch")), reference.key_qpos[0], atol=EXACT
    )


# Each a way Pinocchio's MJCF reader weighs a file otherwise than MuJoCo, which gaussim's rewrite
# (mjcf.for_pinocchio, mjcf.set_total_mass) states for it; the arm: two hinged capsules and a box.
ARM = (
    '<mujoco>{head}<worldbody><body name="upper" pos="0 0 1"{upper}><joint name="shoulder" axis="0 1 0"/>'
    '<geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.05"{geom}/><body name="lower" pos="0 0 -0.5">'
    '<joint name="elbow" axis="1 0 0"/><geom type="box" pos="0 0 -0.2" size="0.04 0.05 0.2"{geom}/>'
    "</body></body></worldbody></mujoco>"
)
WEIGHED = {
    "default mass": ('<default><geom mass="2"/></default>', "", ""),
    "class mass": (
        '<default><default class="arm"><geom mass="0.7" density="10"/></default></default>',
        ' childclass="arm"',
        "",
    ),
    "no collisions": ('<default><geom contype="0" conaffinity="0"/></default>', "", ""),
    "one geom colliding with nothing": ("", "", ' contype="0" conaffinity="0"'),
    "total mass": ('<compiler settotalmass="7.5"/>', "", ""),
    "groups that weigh": ('<compiler inertiagrouprange="0 2"/><default><geom group="1"/></default>', "", ""),
    "a group that does not": (
        '<compiler inertiagrouprange="0 2"/><default><default class="drawn"><geom group="3" mass="5"/>'
        "</default></default>",
        "",
        '/><geom class="drawn" type="sphere" size="0.1"',
    ),
}


@pytest.mark.parametrize("case", WEIGHED)
def test_mjcf_masses_are_mujocos(tmp_path, case):
    """A class's geom mass, geoms that collide with nothing and <compiler settotalmass> weigh the arm as
    MuJoCo weighs it: its bodies' masses and its mass matrix at random configurations (Pinocchio alone
    left out the class's mass, weighed such geoms 0 kg and ignored the total mass)."""
    head, upper, geom = WEIGHED[case]
    path = tmp_path / "arm.xml"
    path.write_text(ARM.format(head=head, upper=upper, geom=geom))
    robot = gaussim.load_robot(path)
    reference = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(reference)
    assert [robot.model.inertias[j].mass for j in (1, 2)] == pytest.approx(reference.body_mass[1:], rel=1e-12)
    for q in random_configurations(robot):
        data.qpos[:] = q
        mujoco.mj_forward(reference, data)
        M = np.zeros((2, 2))
        mujoco.mj_fullM(reference, data, M)
        np.testing.assert_allclose(mass_matrix(robot, q), M, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("collides", ["", 'contype="0" conaffinity="0"'])
@pytest.mark.parametrize("weight", ['density="0"', 'mass="0"', ""])
def test_mjcf_a_mesh_weighs_as_in_mujoco(tmp_path, weight, collides):
    """A mesh geom, drawn only or colliding, in a body weighed by its geoms: weighing nothing (density
    or mass 0) the arm loads with MuJoCo's masses; weighing something it is refused as every mesh that
    weighs (Pinocchio would give it 1 kg and a unit inertia)."""
    (tmp_path / "tetra.obj").write_text((DATA / "tetra.obj").read_text())
    drawn = f'<geom type="mesh" mesh="tetra" {collides} {weight}/>'
    path = tmp_path / "arm.xml"
    path.write_text(
        ARM.format(head='<asset><mesh name="tetra" file="tetra.obj"/></asset>', upper="", geom="").replace(
            "</body></body></worldbody>", drawn + "</body></body></worldbody>"
        )
    )
    if not weight:
        with pytest.raises(
            gaussim.InvalidRobot, match=r"the bodies 'lower' take their inertia from mesh geoms"
        ):
            gaussim.load_robot(path)
        return
    robot = gaussim.load_robot(path)
    reference = mujoco.MjModel.from_xml_path(str(path))
    assert [robot.model.inertias[j].mass for j in (1, 2)] == pytest.approx(reference.body_mass[1:], rel=1e-12)


PYBULLET_MJCF = sorted((Path(pybullet_data.getDataPath()) / "mjcf").glob("*.xml"))


@pytest.mark.parametrize("path", PYBULLET_MJCF, ids=lambda path: path.name)
def test_pybullet_mjcf_files_have_mujocos_mass_matrix(path):
    """Each MJCF of pybullet_data that MuJoCo 3 loads (it refuses 8 of 26: global coordinates, undefined
    materials, ...): gaussim loads it with MuJoCo's mass matrix at random configurations, or refuses it
    by name, or leaves out its other top-level bodies with a warning (then only nv differs). The
    weighing rules themselves are checked on small files above (test_mjcf_masses_are_mujocos)."""
    try:
        reference = mujoco.MjModel.from_xml_path(str(path))
    except ValueError:  # MuJoCo 3 refuses it too (global coordinates, an undefined material, ...)
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gaussim.GaussimWarning)
        try:
            robot = gaussim.load_robot(path)
        except gaussim.InvalidRobot as err:
            assert str(path) in str(err)
            return
    nv = robot.model.nv  # the first body's block of MuJoCo's (block diagonal by body) where there are more
    assert nv == reference.nv or len(mjcf.bodies(mjcf.read(path))) > 1
    data = mujoco.MjData(reference)
    for q in random_configurations(robot):
        if robot.floating:
            q[3:7] /= np.linalg.norm(q[3:7])
        data.qpos[: len(q)] = mujoco_configuration(q) if robot.floating else q
        mujoco.mj_forward(reference, data)
        M = np.zeros((reference.nv, reference.nv))
        mujoco.mj_fullM(reference, data, M)
        M = M[:nv, :nv]
        T = np.eye(nv)
        if robot.floating:  # MuJoCo's free joint moves its linear velocity in the world frame
            T[:3, :3] = pin.Quaternion(q[6], *q[3:6]).matrix()
        # thrower's is 2e-9 of its largest entry off; a misread file's, percents
        np.testing.assert_allclose(mass_matrix(robot, q), T.T @ M @ T, rtol=1e-8, atol=1e-8 * np.abs(M).max())


TWO_BODIES = """<mujoco>
  <worldbody>
    <geom name="table" type="box" pos="0 0 -0.05" size="1 1 0.05"/>
    <body name="arm" pos="0 0 0.5"><joint type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/></body>
    <body name="ball" pos="0.5 0 0.3"><freejoint/><geom type="sphere" size="0.05" density="800"/></body>
  </worldbody>
  <keyframe><key name="home" qpos="0.3  0.5 0.1 0.3  0.8 0 0.6 0"/></keyframe>
</mujoco>"""


def test_mjcf_top_level_bodies_each_load(tmp_path):
    """A file of two top-level bodies and a keyframe of both (Pinocchio refused it: "Keyframe size does
    not match model size"): the first loads by default with the world's geoms, the other with
    body=...; each has MuJoCo's mass, mass matrix (its block of MuJoCo's) and its part of the
    keyframe; a Scene of both runs, the ball coming to rest on the first body's table."""
    path = tmp_path / "two.xml"
    path.write_text(TWO_BODIES)
    reference = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(reference)
    mujoco.mj_resetDataKeyframe(reference, data, 0)
    mujoco.mj_forward(reference, data)
    M = np.zeros((reference.nv, reference.nv))
    mujoco.mj_fullM(reference, data, M)
    with pytest.warns(gaussim.GaussimWarning, match=r"the bodies 'ball' are left out \(load each with"):
        arm = gaussim.load_robot(path)
    ball = gaussim.load_robot(path, body="ball")
    assert (arm.name, arm.floating, ball.name, ball.floating) == ("two", False, "ball", True)
    assert [g.name for g in arm.collision_model.geometryObjects][0] == "table"
    assert "table" not in [g.name for g in ball.collision_model.geometryObjects]
    assert (arm.mass, ball.mass) == pytest.approx(reference.body_mass[1:], rel=1e-12)
    q_arm, q_ball = arm.configuration("home"), ball.configuration("home")
    np.testing.assert_array_equal(
        np.concatenate([q_arm, mujoco_configuration(q_ball)]), reference.key_qpos[0]
    )
    np.testing.assert_allclose(mass_matrix(arm, q_arm), M[:1, :1], rtol=1e-12)
    T = np.eye(6)
    T[:3, :3] = pin.Quaternion(q_ball[6], *q_ball[3:6]).matrix()
    np.testing.assert_allclose(mass_matrix(ball, q_ball), T.T @ M[1:, 1:] @ T, rtol=1e-12, atol=1e-15)
    with pytest.raises(
        gaussim.InvalidRobot, match=r"no top-level body 'bal' in <worldbody> \(did you mean ball\?\)"
    ):
        gaussim.load_robot(path, body="bal")
    with pytest.raises(gaussim.InvalidOptions, match=r"body: selects a top-level body of an MJCF file"):
        gaussim.load_robot(WALKER_URDF, body="torso")

    scene = gaussim.Scene(bodies={"arm": arm, "ball": ball}, ground=gaussim.Ground(height=-1.0))
    sim = gaussim.Simulator(scene)
    state = sim.reset({"arm": q_arm, "ball": q_ball})
    for _ in range(1000):
        state = sim.step(state)
    assert state.body("ball").q[2] == pytest.approx(0.05, abs=1e-4)  # on the table top (z = 0), radius 0.05


def test_mjcf_compiler_settings_are_mujocos(tmp_path, monkeypatch):
    """Every <compiler>'s settings, the last given winning (the rewrite's own compiler hid the file's:
    angle="radian" read as degrees, 61 % off the mass matrix), a mesh folder relative to assetdir and a
    file loaded by a relative path (its mesh was looked up in the temporary folder): MuJoCo's masses and
    mass matrix."""
    (tmp_path / "assets" / "meshes").mkdir(parents=True)
    (tmp_path / "assets" / "meshes" / "tetra.obj").write_text((DATA / "tetra.obj").read_text())
    (tmp_path / "arm.xml").write_text(
        '<mujoco><compiler angle="degree" assetdir="assets"/>'
        '<compiler angle="radian" meshdir="assets/meshes"/>'
        '<asset><mesh name="tetra" file="tetra.obj"/></asset><worldbody><body name="a" pos="0 0 1">'
        '<joint axis="0 1 0"/><geom type="box" size="0.3 0.05 0.1" euler="0 0 1.0"/>'
        '<geom type="mesh" mesh="tetra" density="0"/><body name="b" pos="0 0 -0.5" euler="1.2 0 0">'
        '<joint axis="1 0 0"/><geom type="capsule" fromto="0 0 0 0.3 0 -0.2" size="0.05"/></body></body>'
        "</worldbody></mujoco>"
    )
    monkeypatch.chdir(tmp_path)
    robot = gaussim.load_robot("arm.xml")
    reference = mujoco.MjModel.from_xml_path("arm.xml")
    data = mujoco.MjData(reference)
    for q in random_configurations(robot):
        data.qpos[:] = q
        mujoco.mj_forward(reference, data)
        M = np.zeros((2, 2))
        mujoco.mj_fullM(reference, data, M)
        np.testing.assert_allclose(mass_matrix(robot, q), M, rtol=1e-12)


@pytest.mark.parametrize("body", ["a", "other"])
def test_mjcf_total_mass_is_the_whole_files(tmp_path, body):
    """<compiler settotalmass> scales the whole file by one factor: a body welded to the world (Pinocchio's
    universe) and each top-level body loaded by itself weigh MuJoCo's share (each weighed the whole total)."""
    path = tmp_path / "two.xml"
    path.write_text(
        '<mujoco><compiler settotalmass="10"/><worldbody><body name="a" pos="0 0 1"><freejoint/>'
        '<geom type="box" size="0.1 0.1 0.1"/><body name="welded" pos="0 0 0.3">'
        '<geom type="sphere" size="0.1"/><body name="b" pos="0 0 0.3"><joint axis="0 1 0"/>'
        '<geom type="sphere" size="0.1"/></body></body></body>'
        '<body name="other" pos="2 0 1"><freejoint/><geom type="box" size="0.1 0.2 0.1"/></body>'
        "</worldbody></mujoco>"
    )
    robot = gaussim.load_robot(path, body=body)
    reference = mujoco.MjModel.from_xml_path(str(path))
    named = {
        mujoco.mj_id2name(reference, mujoco.mjtObj.mjOBJ_BODY, k): m
        for k, m in enumerate(reference.body_mass)
    }
    expected = named["other"] if body == "other" else named["a"] + named["welded"] + named["b"]
    assert robot.mass == pytest.approx(expected, rel=1e-12)


def test_mjcf_a_geom_of_class_main_loads(tmp_path):
    """class="main" names MuJoCo's top default (Pinocchio's reader knew no such class: 'unordered_map::at'),
    with a top default of the file's and without one: MuJoCo's mass."""
    for default in ('<default><geom density="500"/></default>', ""):
        path = tmp_path / "ball.xml"
        path.write_text(
            f'<mujoco>{default}<worldbody><body name="a" pos="0 0 1"><freejoint/>'
            '<geom class="main" type="sphere" size="0.1"/></body></worldbody></mujoco>'
        )
        reference = mujoco.MjModel.from_xml_path(str(path))
        assert gaussim.load_robot(path).mass == pytest.approx(reference.body_mass[1], rel=1e-12)


def test_mjcf_a_weighing_mesh_refuses_its_own_body_alone(tmp_path):
    """The mesh check reads the top-level body loaded: a weighing mesh of another body refused the
    first one too."""
    (tmp_path / "tetra.obj").write_text((DATA / "tetra.obj").read_text())
    path = tmp_path / "two.xml"
    path.write_text(
        '<mujoco><asset><mesh name="tetra" file="tetra.obj"/></asset><worldbody>'
        '<body name="arm" pos="0 0 0.5"><joint axis="0 1 0"/><geom type="sphere" size="0.05"/></body>'
        '<body name="rock" pos="1 0 0.5"><freejoint/><geom type="mesh" mesh="tetra"/></body>'
        "</worldbody></mujoco>"
    )
    with pytest.warns(gaussim.GaussimWarning, match=r"the bodies 'rock' are left out"):
        assert gaussim.load_robot(path).name == "two"
    with pytest.raises(gaussim.InvalidRobot, match=r"the bodies 'rock' take their inertia from mesh geoms"):
        gaussim.load_robot(path, body="rock")


def test_mjcf_included_assets_are_read(tmp_path):
    """dm_control's files include their materials, so that a file holds several <asset> sections, of
    which Pinocchio read the first ("Cannot find material grid"); a mesh of an included file is found
    from the main file's folder, as MuJoCo finds it."""
    (tmp_path / "common").mkdir()
    (tmp_path / "common" / "materials.xml").write_text(
        '<mujoco><asset><material name="self" rgba=".7 .5 .3 1"/></asset></mujoco>'
    )
    (tmp_path / "common" / "meshes.xml").write_text(
        '<mujoco><asset><mesh name="tetra" file="tetra.obj"/></asset></mujoco>'
    )
    (tmp_path / "tetra.obj").write_text(
        "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n"
    )
    path = tmp_path / "arm.xml"
    path.write_text(
        ARM.format(
            head='<include file="./common/meshes.xml"/><include file="./common/materials.xml"/>',
            upper="",
            geom=' material="self"',
        ).replace(
            "</body></body></worldbody>",
            '<body name="tip" pos="0 0 -0.4"><inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>'
            '<geom type="mesh" mesh="tetra"/></body></body></body></worldbody>',
        )
    )
    robot = gaussim.load_robot(path)
    reference = mujoco.MjModel.from_xml_path(str(path))
    assert robot.mass == pytest.approx(reference.body_mass.sum(), rel=1e-12)
    assert robot.collision_model.ngeoms == 3
    assert robot.visual_model.geometryObjects[0].meshColor.tolist() == pytest.approx([0.7, 0.5, 0.3, 1.0])


def test_mjcf_includes_are_found_and_placed_as_mujoco_does(tmp_path):
    """An included file is looked for in the main file's folder first, then in the including file's
    (a nested include of common/ found common/'s copy where MuJoCo takes the main folder's); the
    elements of two includes keep their order (the second include's body was put between the first's
    two, so that the coordinates were not in MuJoCo's order); a missing one is named."""
    (tmp_path / "common").mkdir()
    ball = (
        '<mujoco><body name="{0}" pos="{1} 0 0"><joint name="{0}" type="slide"/><geom size="0.1"/>'
        "</body></mujoco>"
    )
    (tmp_path / "common" / "bodies.xml").write_text('<mujoco><include file="ball.xml"/></mujoco>')
    (tmp_path / "common" / "ball.xml").write_text(ball.format("common_ball", 0))
    (tmp_path / "ball.xml").write_text(ball.format("main_ball", 0))
    (tmp_path / "two.xml").write_text(ball.format("second", 1)[:-9] + ball.format("third", 2)[8:])
    path = tmp_path / "world.xml"
    path.write_text(
        '<mujoco><worldbody><body name="base" pos="0 0 1"><include file="two.xml"/>'
        '<include file="common/bodies.xml"/><body name="last" pos="3 0 0"><joint name="last" type="slide"/>'
        '<geom size="0.1"/></body></body></worldbody></mujoco>'
    )
    reference = mujoco.MjModel.from_xml_path(str(path))
    expected = [reference.joint(j).name for j in range(reference.njnt)]
    assert expected == ["second", "third", "main_ball", "last"]
    assert list(gaussim.load_robot(path).model.names)[1:] == expected
    (tmp_path / "ball.xml").unlink()  # then the including file's folder
    assert gaussim.load_robot(path).model.names[3] == "common_ball"
    (tmp_path / "common" / "ball.xml").unlink()
    with pytest.raises(gaussim.InvalidRobot, match=r'bodies.xml: <include file="ball.xml">: no such file in'):
        gaussim.load_robot(path)


def test_mjcf_geometry(hopper):
    """Collision geometry is what collides in MuJoCo (the visual-only sphere is drawn, not collided);
    the floor plane is left out; the mesh foot has its convex hull."""
    assert [g.name for g in hopper.collision_model.geometryObjects] == ["torso", "thigh", "shin", "foot"]
    assert [g.name for g in hopper.visual_model.geometryObjects] == [
        "torso",
        "torso_light",
        "thigh",
        "shin",
        "foot",
    ]
    foot = hopper.collision_model.geometryObjects[hopper.geometry_id("foot")].geometry
    assert isinstance(foot, coal.BVHModelBase) and foot.convex is not None
    assert hopper.urdf == str(HOPPER) and hopper.source == str(HOPPER)


def test_mjcf_floating_base(tmp_path):
    """A <freejoint> floats the robot: floating_base=True honours it, False is refused; a fixed MJCF
    gets a free flyer when asked."""
    with pytest.warns(gaussim.GaussimWarning):
        assert gaussim.load_robot(HOPPER, floating_base=True).model.nq == 10
    with pytest.raises(
        gaussim.InvalidRobot, match=r"hopper.xml: body 'torso' has a <freejoint>.*floating_base=False"
    ):
        gaussim.load_robot(HOPPER, floating_base=False)
    arm = tmp_path / "arm.xml"
    arm.write_text(
        '<mujoco><worldbody><body name="base"><geom type="box" size="0.1 0.1 0.1" mass="2"/>'
        '<body name="link" pos="0 0 0.1"><joint name="j" axis="0 1 0"/>'
        '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="1"/></body></body>'
        "</worldbody></mujoco>"
    )
    fixed, floating = gaussim.load_robot(arm), gaussim.load_robot(arm, floating_base=True)
    assert (fixed.model.nq, fixed.floating, fixed.mass) == (1, False, 3.0)  # the base's 2 kg on the universe
    assert (floating.model.nq, floating.floating, floating.mass) == (8, True, 3.0)
    hinged = tmp_path / "hinged.xml"  # a base on its own hinge: Pinocchio adds no free root above it
    hinged.write_text(arm.read_text().replace('<body name="base">', '<body name="base"><joint name="spin"/>'))
    with pytest.raises(
        gaussim.InvalidRobot,
        match=r"hinged.xml: floating_base=True: body 'base' hangs from the world by its own joint 'spin'.*"
        r"<freejoint/>",
    ):
        gaussim.load_robot(hinged, floating_base=True)
    assert gaussim.load_robot(hinged).model.nq == 2


def test_mjcf_equality_to_the_world_is_left_out_with_a_warning(tmp_path):
    """A <connect> to body2="world", valid in MuJoCo, is warned as left out like any <equality> (the
    reader of Pinocchio's constraints refused the file: no body named world)."""
    path = tmp_path / "pinned.xml"
    path.write_text(
        '<mujoco><worldbody><body name="link" pos="0 0 0.5"><joint name="j" axis="0 1 0"/>'
        '<geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.02" mass="0.5"/></body></worldbody>'
        '<equality><connect name="pin" body1="link" body2="world" anchor="0.2 0 0"/></equality></mujoco>'
    )
    with pytest.warns(gaussim.GaussimWarning, match=r"<equality> constraints <connect pin> are not honoured"):
        robot = gaussim.load_robot(path)
    assert (robot.model.nq, robot.mass) == (1, 0.5)
    free = path.with_name("free.xml")  # no joint of its own: floating_base=True adds the free root
    free.write_text(path.read_text().replace('<joint name="j" axis="0 1 0"/>', ""))
    with pytest.warns(gaussim.GaussimWarning, match=r"<equality> constraints <connect pin> are not honoured"):
        robot = gaussim.load_robot(free, floating_base=True)
    assert (robot.model.nq, robot.floating) == (7, True)


MJCF_FAULTS = {
    "not xml": ("<mujoco><worldbody>", r"not well-formed XML"),
    "number": (
        '<mujoco><worldbody><body name="a" pos="0 nan 1"><freejoint/><geom size="0.1"/></body>'
        "</worldbody></mujoco>",
        r"<body a>: pos must be finite numbers, got '0 nan 1'",
    ),
    "joint type": (
        '<mujoco><worldbody><body name="a"><joint name="j" type="fixed"/><geom size="0.1"/></body>'
        "</worldbody></mujoco>",
        r"<joint j> of body 'a' has type 'fixed'; known: hinge, slide, ball, free",
    ),
    "no body": (
        '<mujoco><worldbody><geom type="plane" size="1 1 1"/></worldbody></mujoco>',
        r"has no <body>",
    ),
    "mesh inertia": (
        '<mujoco><asset><mesh name="m" file="tetra.obj"/></asset><worldbody><body name="a"><freejoint/>'
        '<geom type="mesh" mesh="m" mass="0.3"/></body></worldbody></mujoco>',
        r"bodies 'a' take their inertia from mesh geoms.*give them an <inertial>",
    ),
    "inline mesh inertia": (
        '<mujoco><asset><mesh name="m" vertex="0 0 0  0.1 0 0  0 0.1 0  0 0 0.1"/></asset><worldbody>'
        '<body name="a"><freejoint/><geom type="mesh" mesh="m"/></body></worldbody></mujoco>',
        r"bodies 'a' take their inertia from mesh geoms.*give them an <inertial>",
    ),
    "missing mesh": (
        '<mujoco><asset><mesh name="m" file="absent.stl"/></asset><worldbody><body name="a"><freejoint/>'
        '<inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/><geom type="mesh" mesh="m"/></body>'
        "</worldbody></mujoco>",
        r"cannot build a model from this MJCF: Could not load resource .*absent.stl",
    ),
    "global coordinates": (
        '<mujoco><compiler coordinate="global"/><worldbody><body name="a"><freejoint/>'
        '<geom type="sphere" size="0.1"/></body></worldbody></mujoco>',
        r'<compiler coordinate="global"> is not read \(MuJoCo 3 refuses it too\)',
    ),
    "frame": (
        '<mujoco><worldbody><body name="a"><freejoint/><geom type="sphere" size="0.1"/>'
        '<frame name="f" pos="0 0 1"><geom type="box" size="0.1 0.1 0.1"/></frame></body></worldbody>'
        "</mujoco>",
        r"<frame f>: Pinocchio's MJCF reader leaves out the bodies and geoms of a <frame>",
    ),
    "not a robot file": (
        "<scene/>",
        r"root element <scene> is no robot format gaussim reads; known: <robot>",
    ),
}


@pytest.mark.parametrize("fault", MJCF_FAULTS)
def test_mjcf_faults_name_the_file_and_cause(tmp_path, fault):
    text, message = MJCF_FAULTS[fault]
    path = tmp_path / "robot.xml"
    path.write_text(text)
    (tmp_path / "tetra.obj").write_text((DATA / "tetra.obj").read_text())
    with pytest.raises(gaussim.InvalidRobot, match=str(path) + ".*" + message):
        gaussim.load_robot(path)


def test_mjcf_left_out_bodies_are_warned(tmp_path):
    """Pinocchio reads one body of <worldbody>, the first by default: the others are named."""
    path = tmp_path / "two.xml"
    body = '<body name="{0}" pos="{1} 0 1"><freejoint/><geom size="0.1" mass="1"/></body>'
    path.write_text(f"<mujoco><worldbody>{body.format('a', 0)}{body.format('b', 1)}</worldbody></mujoco>")
    with pytest.warns(
        gaussim.GaussimWarning, match=r"one body of <worldbody>, the first \('a'\): the bodies 'b' are"
    ):
        assert gaussim.load_robot(path).model.nq == 7


# --- SDF ------------------------------------------------------------------------------------------


def test_sdf_walker_is_its_urdf(walker):
    """walker.sdf (SDFormat frames, degrees, quaternions, axes in the model frame) is walker.urdf: the
    same nq, masses, limits, mass matrix and geometry placements at random configurations."""
    urdf = gaussim.load_robot(WALKER_URDF, floating_base=True)
    assert walker.floating  # no joint attaches it to the world
    assert (walker.model.nq, walker.model.nv) == (urdf.model.nq, urdf.model.nv) == (11, 9)
    assert walker.mass == pytest.approx(urdf.mass, abs=EXACT) and walker.mass == pytest.approx(4.7)
    np.testing.assert_allclose(walker.model.lowerPositionLimit[7:], urdf.model.lowerPositionLimit[7:])
    np.testing.assert_allclose(walker.model.upperPositionLimit[7:], urdf.model.upperPositionLimit[7:])
    for q in random_configurations(urdf):
        np.testing.assert_allclose(mass_matrix(walker, q), mass_matrix(urdf, q), atol=EXACT)
        placed = []
        for robot in (walker, urdf):
            geometry = robot.collision_model.createData()
            pin.updateGeometryPlacements(
                robot.model, robot.model.createData(), robot.collision_model, geometry, q
            )
            placed.append([g.homogeneous for g in geometry.oMg])
        np.testing.assert_allclose(placed[0], placed[1], atol=EXACT)
    assert walker.visual_model.geometryObjects[0].meshColor == pytest.approx([0.2, 0.4, 0.8, 1.0])


def test_sdf_kuka_is_its_urdf():
    """pybullet_data's KUKA iiwa, SDFormat 1.6 with meshes, is its model.urdf (to the SDF's rounding)."""
    sdf = gaussim.load_robot(KUKA / "model.sdf", floating_base=False)
    urdf = gaussim.load_robot(KUKA / "model.urdf")
    assert (sdf.model.nq, sdf.floating, sdf.mass) == (7, False, pytest.approx(17.5))
    assert sdf.collision_model.ngeoms == 8
    assert all(g.geometry.convex is not None for g in sdf.collision_model.geometryObjects)
    for q in random_configurations(urdf):
        np.testing.assert_allclose(mass_matrix(sdf, q), mass_matrix(urdf, q), atol=KUKA_ROUNDING)
    assert gaussim.load_robot(KUKA / "model.sdf").model.nq == 14  # an SDF model without a world joint floats


def sdf_model(body: str) -> str:
    link = (
        '<link name="{0}"><inertial><mass>1</mass></inertial>'
        "<collision name='c'><geometry><sphere><radius>0.1</radius></sphere></geometry></collision></link>"
    )
    return f'<sdf version="1.9"><model name="m">{link.format("a")}{link.format("b")}{body}</model></sdf>'


def joint(name: str, kind: str, parent: str, child: str) -> str:
    return (
        f'<joint name="{name}" type="{kind}"><parent>{parent}</parent><child>{child}</child>'
        "<axis><xyz>0 0 1</xyz></axis></joint>"
    )


SDF_FAULTS = {
    "joint type": (
        sdf_model(joint("j", "ball", "a", "b")),
        r"joint 'j': type 'ball' is not read; known: revolute",
    ),
    "missing link": (
        sdf_model(joint("j", "revolute", "a", "c")),
        r"joint 'j': child link 'c' does not exist",
    ),
    "loop": (
        sdf_model(joint("j", "revolute", "a", "b") + joint("k", "revolute", "a", "b")),
        r"joint 'k': link 'b' is also the child of joint 'j': a closed kinematic loop",
    ),
    "two trees": (sdf_model(""), r"links 'a', 'b' have no parent joint"),
    "number": (
        sdf_model(joint("j", "revolute", "a", "b").replace("0 0 1", "0 0 x")),
        r"joint 'j' <xyz>: must be 3 finite number\(s\), got '0 0 x'",
    ),
    "mesh": (
        sdf_model(joint("j", "revolute", "a", "b")).replace(
            "<sphere><radius>0.1</radius></sphere>", "<mesh><uri>model://m/absent.stl</uri></mesh>", 1
        ),
        r"link 'a' <collision c>: mesh 'model://m/absent.stl' not found \(looked in: ",
    ),
    "shape": (
        sdf_model(joint("j", "revolute", "a", "b")).replace(
            "<sphere><radius>0.1</radius></sphere>",
            "<capsule><radius>0.1</radius><length>1</length></capsule>",
            1,
        ),
        r"geometry <capsule> is not read; known: box, sphere, cylinder, mesh",
    ),
    "frame": (
        sdf_model(joint("j", "revolute", "a", "b")).replace(
            '<link name="a">', '<link name="a"><pose relative_to="nowhere">0 0 0 0 0 0</pose>'
        ),
        r"no frame 'nowhere'; known: a, b, j",
    ),
    "two models": (
        '<sdf version="1.9"><world name="w"><model name="x"/><model name="y"/></world></sdf>',
        r"one moving <model> per SDF file, this one has 'x', 'y'",
    ),
}


@pytest.mark.parametrize("fault", SDF_FAULTS)
def test_sdf_faults_name_the_file_and_element(tmp_path, fault):
    text, message = SDF_FAULTS[fault]
    path = tmp_path / "robot.sdf"
    path.write_text(text)
    with pytest.raises(gaussim.InvalidRobot, match=str(path) + ": .*" + message):
        gaussim.load_robot(path)


def test_an_sdf_link_without_inertial_is_warned_the_free_root_too(tmp_path):
    """SDFormat's default inertia (1 kg, 1 kg m^2) is warned for every link that takes it, the free
    root's included (a one-link model's crate was let through without a word)."""
    path = tmp_path / "crate.sdf"
    path.write_text(
        '<sdf version="1.9"><model name="crate"><link name="crate"><collision name="c"><geometry>'
        "<box><size>0.1 0.1 0.1</size></box></geometry></collision></link></model></sdf>"
    )
    with pytest.warns(gaussim.GaussimWarning, match=r"crate.sdf: the links 'crate' have no <inertial>"):
        robot = gaussim.load_robot(path)
    assert (robot.floating, robot.mass) == (True, 1.0)


def test_sdf_world_joint_fixes_the_base(tmp_path):
    """A joint to the world fixes the model; floating_base=True is refused."""
    path = tmp_path / "arm.sdf"
    path.write_text(sdf_model(joint("j", "revolute", "a", "b") + joint("anchor", "fixed", "world", "a")))
    robot = gaussim.load_robot(path)
    assert (robot.model.nq, robot.floating) == (2, False)  # the unlimited revolute is continuous (cos, sin)
    with pytest.raises(gaussim.InvalidRobot, match=r"joint 'anchor' attaches the model to the world"):
        gaussim.load_robot(path, floating_base=True)


def test_a_bare_sdf_link_named_world_is_the_world(tmp_path):
    """A link named 'world' that a joint names as its parent, bare (no inertial, collision or pose), is
    the world frame (as PyBullet fixes such a massless base): the model is the one whose joint names the
    world itself; pybullet_data's WSG 50 gripper loads fixed, with PyBullet's moving joints and mass."""
    import pybullet

    body = joint("j", "revolute", "a", "b") + joint("anchor", "fixed", "world", "a")
    reference, bare = tmp_path / "reference.sdf", tmp_path / "bare.sdf"
    reference.write_text(sdf_model(body))
    bare.write_text(sdf_model('<link name="world"/>' + body))
    with pytest.warns(gaussim.GaussimWarning, match=r"the link 'world' has no <inertial>: joint 'anchor'"):
        robot = gaussim.load_robot(bare)
    expected = gaussim.load_robot(reference)
    assert (robot.model.nq, robot.floating, robot.mass) == (expected.model.nq, False, expected.mass)
    q = pin.neutral(robot.model)
    np.testing.assert_array_equal(mass_matrix(robot, q), mass_matrix(expected, q))
    shown = tmp_path / "shown.sdf"  # a visual of the world link is dropped, and said so
    shown.write_text(sdf_model('<link name="world"><visual name="plate"/></link>' + body))
    with pytest.warns(gaussim.GaussimWarning, match=r"its <visual> is not drawn"):
        gaussim.load_robot(shown)

    path = KUKA.parent / "gripper" / "wsg50_one_motor_gripper_new.sdf"
    with pytest.warns(gaussim.GaussimWarning):
        gripper = gaussim.load_robot(path)
    client = pybullet.connect(pybullet.DIRECT)
    try:
        (body_id,) = pybullet.loadSDF(str(path), physicsClientId=client)
        joints = [
            pybullet.getJointInfo(body_id, j, client) for j in range(pybullet.getNumJoints(body_id, client))
        ]
        moving = [info[1].decode() for info in joints if info[2] != pybullet.JOINT_FIXED]
        masses = [pybullet.getDynamicsInfo(body_id, k, client)[0] for k in range(-1, len(joints))]
    finally:
        pybullet.disconnect(client)
    assert masses[0] == 0.0  # PyBullet's base: massless, fixed
    assert (gripper.floating, list(gripper.model.names)[1:]) == (False, moving)
    assert gripper.mass == pytest.approx(sum(masses))


@pytest.mark.parametrize("inside", ["<inertial><mass>0.1</mass></inertial>", "<pose>0 0 1 0 0 0</pose>"])
def test_an_sdf_link_named_world_of_its_own_is_refused(tmp_path, inside):
    """A link named 'world' with a body or a pose of its own cannot be told from the world frame its
    joint names as parent (pybullet_data's free-base WSG 50: 0.1 kg): refused, naming both."""
    path = tmp_path / "gripper.sdf"
    body = joint("j", "revolute", "a", "b") + joint("anchor", "fixed", "world", "a")
    path.write_text(sdf_model(f'<link name="world">{inside}</link>' + body))
    with pytest.raises(
        gaussim.InvalidRobot, match=r"link 'world': has the name of the world frame, which joint 'anchor'"
    ):
        gaussim.load_robot(path)


# --- falling onto the ground ----------------------------------------------------------------------


@pytest.mark.parametrize("robot, start", [("hopper", "qpos0"), ("walker", None)])
def test_falls_onto_the_ground(request, robot, start):
    """Dropped from its start, the robot lands on a gaussim Ground and does not sink into it."""
    robot = request.getfixturevalue(robot)
    q = robot.configuration(start) if start else robot.neutral()
    if start is None:
        q[2] = 1.0
    sim = gaussim.Simulator(gaussim.Scene(robot, ground=gaussim.Ground()), gaussim.Options(dt=1e-3))
    state = sim.reset(q)
    landed = False
    while state.t < FALL_TIME:
        state = sim.step(state)
        report = sim.last_step
        assert report is not None and report.converged
        assert all(c.gap >= -PENETRATION for c in report.contacts)
        landed = landed or bool(report.contacts)
    assert landed and state.q[2] < q[2] - 0.05
    contacts = sim.last_step.contacts  # points on the robot, at their gap above the ground
    assert all(abs(c.point[2] - c.gap) < 1e-12 for c in contacts) and min(c.gap for c in contacts) < 1e-3


# --- as_robot -------------------------------------------------------------------------------------


def hand_built() -> tuple[pin.Model, pin.GeometryModel]:
    """A free box with a mesh (a cube's corners, no convex hull built) and a sphere, made by hand."""
    model = pin.Model()
    model.name = "crate"
    root = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "root")
    model.appendBodyToJoint(root, pin.Inertia.FromBox(2.0, 0.2, 0.2, 0.2), pin.SE3.Identity())
    model.addBodyFrame("crate", root, pin.SE3.Identity(), 0)
    corners = np.array([[x, y, z] for x in (-0.1, 0.1) for y in (-0.1, 0.1) for z in (-0.1, 0.1)])
    mesh = coal.BVHModelOBBRSS()
    mesh.beginModel(12, 8)
    mesh.addVertices(corners)
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1)]
    faces += [(2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    mesh.addTriangles(np.array(faces))
    mesh.endModel()
    geometry = pin.GeometryModel()
    geometry.addGeometryObject(pin.GeometryObject("crate_mesh", root, pin.SE3.Identity(), mesh))
    ball = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.15]))
    geometry.addGeometryObject(pin.GeometryObject("crate_ball", root, ball, coal.Sphere(0.05)))
    return model, geometry


def steps(robot: gaussim.Robot, q: np.ndarray | None = None) -> gaussim.State:
    """Ten steps of the robot on the ground (without one when it has no collision geometry)."""
    ground = gaussim.Ground() if robot.collision_model.ngeoms else None
    sim = gaussim.Simulator(gaussim.Scene(robot, ground=ground))
    state = sim.reset(q)
    for _ in range(10):
        state = sim.step(state)
    assert np.all(np.isfinite(state.q))
    return state


def test_a_hand_built_robot_steps_on_the_ground():
    """The crash of issue 20: a Robot of one's own model, with a mesh, stepped into computeLocalAABB of
    a convex hull never built; a Robot builds it when made."""
    model, geometry = hand_built()
    robot = gaussim.Robot("crate", model, geometry, geometry, "")
    q = robot.neutral()
    q[2] = 0.1  # resting on its mesh
    state = steps(robot, q)
    assert state.q[2] == pytest.approx(0.1, abs=1e-3)


@pytest.mark.parametrize("form", ["robot", "wrapper", "model", "pair", "triple", "path", "name"])
def test_as_robot_takes_what_users_hold(form, hopper):
    solo = example_robot_data.load("solo12")
    model, geometry = hand_built()
    held = {
        "robot": hopper,
        "wrapper": solo,
        "model": model,
        "pair": (model, geometry),
        "triple": (model, geometry, geometry),
        "path": str(WALKER),
        "name": "pendulum",
    }[form]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gaussim.GaussimWarning)  # walker.sdf's static ground is left out
        robot, renamed = as_robot(held), as_robot(held, name="other")
    assert renamed.name == "other"
    if form == "robot":
        assert robot is hopper
    if form == "wrapper":
        assert robot.name == "solo" and robot.urdf == "" and "standing" in robot.reference_configurations
        assert robot.collision_model.ngeoms == solo.collision_model.ngeoms
        q = robot.configuration("standing")
    else:
        q = robot.neutral()
        if robot.floating:
            q[2] = 1.0
    if form in ("model", "pair", "triple"):
        assert robot.name == "crate" and robot.source == "the in-memory model 'crate'"
        assert robot.collision_model.ngeoms == (0 if form == "model" else 2)
        assert robot.visual_model.ngeoms == robot.collision_model.ngeoms
    steps(robot, q)


def test_as_robot_copies():
    """Changing the model after as_robot does not reach the robot (a Robot is immutable)."""
    model, geometry = hand_built()
    robot = as_robot((model, geometry))
    model.inertias[1] = pin.Inertia.Zero()
    geometry.removeGeometryObject("crate_ball")
    assert robot.mass == 2.0 and robot.collision_model.ngeoms == 2


def test_as_robot_bad_inputs():
    model, geometry = hand_built()
    with pytest.raises(
        gaussim.InvalidRobot,
        match=r"cannot make a robot of int 3; accepted: a gaussim.Robot, a pinocchio.RobotWrapper",
    ):
        as_robot(3)
    with pytest.raises(
        gaussim.InvalidRobot, match=r"the collision_model must be a pinocchio.GeometryModel .*got str"
    ):
        as_robot((model, "box"))
    with pytest.raises(gaussim.RobotNotFound, match=r"no robot 'nobody'"):
        as_robot("nobody")
    stray = pin.GeometryModel()
    stray.addGeometryObject(pin.GeometryObject("stray", 5, pin.SE3.Identity(), coal.Sphere(0.1)))
    with pytest.raises(
        gaussim.InvalidRobot,
        match=r"collision geometry 'stray' is attached to joint 5, which the model does not have "
        r"\(its joints: 0 'universe', 1 'root'\): is it the geometry model of another model\?",
    ):
        as_robot((model, stray))
    solo = example_robot_data.load("solo12")
    humanoid = pin.buildSampleModelHumanoid()  # more joints than Solo-12: its frames are the ones that differ
    with pytest.raises(
        gaussim.InvalidRobot,
        match=r"collision geometry 'base_link_0' is attached to joint 'root_joint' and to frame",
    ):
        as_robot((humanoid, solo.collision_model))
    plane = pin.GeometryModel()
    plane.addGeometryObject(
        pin.GeometryObject("floor", 0, pin.SE3.Identity(), coal.Halfspace(np.array([0, 0, 1.0]), 0.0))
    )
    with pytest.raises(
        gaussim.InvalidRobot, match=r"collision geometry 'floor' is an unbounded Halfspace.*gaussim.Ground"
    ):
        as_robot((model, plane))
    heavy = pin.Model(model)
    heavy.inertias[1] = pin.Inertia(-1.0, np.zeros(3), np.eye(3))
    with pytest.raises(
        gaussim.InvalidRobot, match=r"the in-memory model 'crate': body of joint 'root' has mass -1.0"
    ):
        as_robot(heavy)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the checks raise; they do not warn
        as_robot(model)


# -- the corpora's faults (issue 22), each in a small hand-written URDF of tests/data/corpus ----------
CORPUS = DATA / "corpus"


def test_a_transmission_names_no_joint():
    robot = gaussim.load_robot(CORPUS / "transmission.urdf")
    assert [robot.model.names[j] for j in range(1, robot.model.njoints)] == ["shoulder"]


def test_a_tilted_continuous_joint_is_a_unit_pair():
    robot = gaussim.load_robot(CORPUS / "tilted_continuous.urdf")
    assert robot.model.joints[1].shortname() == "JointModelRevoluteUnboundedUnaligned"
    sim = gaussim.Simulator(gaussim.Scene(robot))
    sim.reset(robot.neutral())  # (cos, sin) = (1, 0): a unit pair
    with pytest.raises(gaussim.InvalidState, match=r"q\[0:2\] of joint 'wheel' must be a unit \(cos, sin\)"):
        sim.reset(np.array([1.0, 1.0]))


def test_bullets_lower_above_upper_is_no_limit():
    with pytest.warns(gaussim.GaussimWarning, match=r"'slider' \(1 > -1\).*Bullet's convention for no limit"):
        robot = gaussim.load_robot(CORPUS / "bullet_no_limit.urdf")
    scene = gaussim.Scene(robot, joint_limits=True, gravity=(1.0, 0.0, 0.0))  # pushes the slider along x
    sim = gaussim.Simulator(scene)
    state = sim.reset()
    for _ in range(200):
        state = sim.step(state)
    assert state.q[0] == pytest.approx(0.5 * 1.0 * 0.2**2, rel=0.02)  # free: x = g t^2 / 2 past any bound


def test_massless_links_are_lumped_or_refused_by_name():
    with pytest.warns(gaussim.GaussimWarning, match=r"links \['finger'\] have no mass or no inertia"):
        robot = gaussim.load_robot(CORPUS / "massless_finger.urdf")
    assert np.linalg.eigvalsh(pin.crba(robot.model, robot.model.createData(), robot.neutral())).min() > 0
    with pytest.raises(
        gaussim.InvalidRobot, match=r"massless_finger.urdf: the links \['finger'\].*on_massless='lump'"
    ):
        gaussim.load_robot(CORPUS / "massless_finger.urdf", on_massless="error")
    with pytest.raises(gaussim.InvalidOptions, match="on_massless.*lump, error"):
        gaussim.load_robot(CORPUS / "massless_finger.urdf", on_massless="drop")


def test_a_centre_of_mass_far_outside_its_geometry_is_warned():
    with pytest.warns(gaussim.GaussimWarning, match=r"centre of mass of the links 'box' \(1.95 m\)"):
        gaussim.load_robot(CORPUS / "com_outside.urdf", floating_base=True)


def test_a_start_outside_the_limits_is_clamped_with_a_warning():
    robot = gaussim.load_robot(CORPUS / "limited_start.urdf")
    sim = gaussim.Simulator(gaussim.Scene(robot, joint_limits=True))
    with pytest.warns(gaussim.GaussimWarning, match=r"'elbow' at 0 \(limits 0.5, 1\)"):
        state = sim.reset()
    assert state.q[0] == 0.5
    sim = gaussim.Simulator(gaussim.Scene(robot))  # no limits declared: nothing to clamp into
    assert sim.reset().q[0] == 0.0


def test_the_parsers_reason_is_in_the_error():
    with pytest.raises(
        gaussim.InvalidRobot,
        match=r"missing_child.urdf: .*child link \[forearm\] of joint \[elbow\] not found",
    ):
        gaussim.load_robot(CORPUS / "missing_child.urdf")
    with pytest.raises(
        gaussim.InvalidRobot, match=r"deformable.urdf: no <link> element.*found: <deformable>"
    ):
        gaussim.load_robot(CORPUS / "deformable.urdf")


def test_a_hull_with_a_crowded_vertex_is_built_coarser(tmp_path):
    # a cone of 400 rim points: qhull's hull gives its apex 400 neighbours, coal's hull stores 255
    angles = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    rim = np.column_stack([0.1 * np.cos(angles), 0.1 * np.sin(angles), np.zeros_like(angles)])
    points = np.vstack([rim, [0.0, 0.0, 0.2], [0.0, 0.0, 0.0]])
    faces = [(k, (k + 1) % 400, 400) for k in range(400)] + [((k + 1) % 400, k, 401) for k in range(400)]
    mesh = tmp_path / "cone.obj"
    mesh.write_text(
        "".join(f"v {x} {y} {z}\n" for x, y, z in points)
        + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)
    )
    urdf = tmp_path / "cone.urdf"
    urdf.write_text(
        '<robot name="cone"><link name="cone"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" '
        'iyy="0.01" iyz="0" izz="0.01"/></inertial><collision><geometry><mesh filename="cone.obj"/>'
        "</geometry></collision></link></robot>"
    )
    with pytest.warns(gaussim.GaussimWarning, match="collision geometry 'cone_0'.*more neighbours than coal"):
        robot = gaussim.load_robot(urdf, floating_base=True)
    hull = robot.collision_model.geometryObjects[0].geometry.convex
    assert hull.num_points < 402
    # the coarser hull still holds the cone to its tolerance: its apex and rim are within 1 mm
    assert np.asarray(hull.points()).max(axis=0)[2] == pytest.approx(0.2, abs=gaussim.robot.HULL_COARSENING)


def test_cassies_sdf_is_read_by_gaussim():
    # example-robot-data builds it with Pinocchio's SDF parser, which pin's wheels leave out (ImportError)
    with pytest.raises(gaussim.InvalidRobot, match=r"cassie.sdf: joint '.*a closed kinematic loop"):
        gaussim.load_robot("cassie")


def test_a_single_free_body_without_a_floating_base_is_refused_with_the_fix():
    """A one-link URDF loaded without floating_base has no degree of freedom: the error says how to
    give it one."""
    with pytest.raises(gaussim.InvalidRobot, match=r"ball\.urdf: .*floating_base=True"):
        gaussim.load_robot("ball")


def test_talos_legs_loads_without_a_warning_its_collision_geometry_cut_to_its_legs():
    """example-robot-data's TalosLegsLoader cuts Talos's model and visual geometry to the legs (joints
    below 14) but keeps all 52 collision geometries: the 39 of the torso and arms, on joints its model
    does not have, are left out as its visual ones are, without the warning that every run of the
    shipped talos_standing printed."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", gaussim.GaussimWarning)
        robot = gaussim.load_robot("talos_legs")
    for geometry in (robot.collision_model, robot.visual_model):
        assert geometry.ngeoms == 13
        assert all(g.parentJoint < robot.model.njoints for g in geometry.geometryObjects)


def test_geometry_of_joints_a_model_does_not_have_is_left_out_with_a_warning():
    """Where nothing says the loader meant it (its visual geometry is not cut the same way), the
    geometry of joints the model lacks is still left out with a warning naming it."""
    from gaussim.robot import _own_geometry

    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "hinge")
    geometry = pin.GeometryModel()
    for name, parent in (("kept", joint), ("stray", joint + 5)):
        geometry.addGeometryObject(pin.GeometryObject(name, parent, pin.SE3.Identity(), coal.Sphere(0.1)))
    with pytest.warns(gaussim.GaussimWarning, match=r"'arm' holds 1 geometries of joints .*\['stray'\]"):
        kept = _own_geometry("arm", model, geometry)
    assert [g.name for g in kept.geometryObjects] == ["kept"]
