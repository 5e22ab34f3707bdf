"""Scene files: every shipped scene loads and runs; every malformed file is named precisely."""

import re
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import gaussim
from gaussim import Body, FreeBody, Material, pose
from gaussim.robot import ROBOTS_DIR
from gaussim.scenefile import SceneFileError, load_scene

SCENES = sorted((Path(__file__).resolve().parents[1] / "robots" / "scenes").glob("*.toml"))
STEPS = 200


def test_every_robot_of_the_library_has_a_scene():
    assert {p.stem for p in SCENES} >= {
        "solo12_standing",
        "talos_standing",
        "box_incline",
        "ball_bounce",
        "fourbar",
        "pendulum_limits",
        "double_pendulum",
        "box_stack",
        "solo12_crate",
    }


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_shipped_scene_loads_and_runs(path):
    """... without a warning: one on every run of a shipped scene (talos_standing's geometry of joints
    that talos_legs does not have, double_pendulum's name in both robot collections) taught a user to
    pass over warnings."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", gaussim.GaussimWarning)
        spec = gaussim.load_scene(path)
        spec.duration = STEPS * spec.options.dt
        log = gaussim.run(spec)
    assert log.complete and log.steps == STEPS
    assert np.all(np.isfinite(log.q)) and np.all(np.isfinite(log.v))
    assert log.solver_arrays()["kkt_residual"].max() < 1e-6


def _write(tmp_path, text):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    return path


BALL = '[robot]\nname = "ball"\nfloating_base = true\n'
PENDULUM = '[robot]\nname = "pendulum"\n'  # a one-joint robot: q holds one number


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        (BALL + "[grond]\n", "grond", "unknown section; known:.*ground"),
        (BALL + "[ground]\nfriction = -1\n", "ground.friction", "must be a finite number >= 0"),
        (BALL + "[ground]\nfrction = 0.5\n", "ground.frction", "unknown key; known:.*friction"),
        (BALL + "[options]\nscheme = 'implicit'\n", "options.scheme", "not one of velocity, acceleration"),
        (BALL + "[options]\ndt = -1\n", "options.dt", "must be a finite number > 0"),
        (BALL + "[initial]\nq = [0, 0]\n", "initial.q", "must be 7 finite numbers"),
        (PENDULUM + "[initial]\nq = [0, 0]\n", "initial.q", "must be 1 finite number, got"),
        (
            BALL + "[initial]\nconfiguration = 'standing'\n",
            "initial.configuration",
            "no configuration 'standing'",
        ),
        (
            BALL + "[ground]\n[contacts]\npairs = [['ball_9', 'ground']]\n",
            r"contacts.pairs",
            "no collision geometry 'ball_9'.*ball_0",
        ),
        (
            BALL + "[ground]\n[contacts]\npairs = [['ball_0', 'table']]\n",
            r"contacts.pairs",
            "no obstacle or collision geometry 'table'.*ground",
        ),
        (
            BALL + "[[obstacles]]\ntype = 'cone'\nname = 'c'\n",
            r"obstacles\[0\].type",
            "'cone' is not one of box, sphere",
        ),
        (
            BALL + "[[bilaterals]]\ntype = 'anchor'\nframe = 'nose'\nposition = [0, 0, 1]\n",
            r"bilaterals\[0\].frame",
            "no frame 'nose'",
        ),
        (
            "[robot]\nname = \"pendulum\"\n[control]\ntype = 'pd'\nkp = -1.0\n",
            "control",
            "gains must be >= 0",
        ),
        # gains or torques that would act on no joint (box_stack's PD hold was accepted and did nothing)
        (
            BALL + "[control]\ntype = 'pd'\nkp = 5.0\n",
            "control.type",
            r"'pd': robot 'ball' has no actuated joint \(its joints are free roots\); leave \[control\]",
        ),
        # a key the type does not read is refused, not ignored (a gain under the default zero control)
        (
            BALL + "[control]\nkp = 5.0\nkd = 0.1\n",
            "control.kd",
            "type 'zero' \\(the default\\) does not read it; type = \"pd\" does",
        ),
        (BALL + "[control]\ntype = 'pd'\ntau = []\n", "control.tau", 'type = "constant" does'),
        (BALL + "[control]\ntype = []\n", "control.type", "not one of"),  # a type that is no word
        (BALL + "[[bilaterals]]\ntype = []\n", r"bilaterals\[0\].type", r"\[\] is not one of anchor, loop"),
        (
            BALL + "[[bilaterals]]\ntype = 'loop'\nframes = ['a', 'b']\nposition = [0, 0, 1]\n",
            r"bilaterals\[0\].position",
            "type 'loop' does not read it; type = \"anchor\" does",
        ),
        (BALL + "[simulation]\nduration = 0\n", "simulation.duration", "must be > 0"),
        ('[robot]\nname = "solo13"\n', "robot.name", "no robot 'solo13'.*solo12"),
        ('[robot]\nurdf = "missing.urdf"\n', "robot.urdf", "no such file"),
        (
            '[robot]\nname = "pendulum"\n[initial]\nground_clearance = 0.01\n[ground]\n',
            "initial.ground_clearance",
            "needs a floating-base robot",
        ),
        ("[robot\n", "toml", ""),
    ],
)
def test_malformed_scene_names_file_and_key(tmp_path, text, key, message):
    path = _write(tmp_path, text)
    with pytest.raises(SceneFileError, match=rf"^{path}: {key}: .*{message}"):
        gaussim.load_scene(path)


def test_overrides_replace_the_scene_options(tmp_path):
    spec = gaussim.load_scene(
        _write(tmp_path, BALL + "[options]\ndt = 0.002\n"), dt=5e-4, scheme="acceleration"
    )
    assert spec.options.dt == 5e-4 and spec.options.scheme == "acceleration"


def test_relative_urdf_path_is_taken_from_the_scene_folder(tmp_path):
    (tmp_path / "models").mkdir()
    urdf = Path(gaussim.robot.ROBOTS_DIR / "ball.urdf").read_text()
    (tmp_path / "models" / "b.urdf").write_text(urdf)
    spec = gaussim.load_scene(_write(tmp_path, '[robot]\nurdf = "models/b.urdf"\nfloating_base = true\n'))
    assert spec.robot.floating and spec.robot.model.nq == 7


def test_ground_clearance_places_the_feet(tmp_path):
    text = (
        '[robot]\nname = "solo12"\n[initial]\nconfiguration = "standing"\nground_clearance = 0.02\n'
        '[ground]\n[contacts]\npairs = [["FL_FOOT_0", "ground"], ["HR_FOOT_0", "ground"]]\n'
    )
    spec = gaussim.load_scene(_write(tmp_path, text))
    sim = gaussim.Simulator(spec.scene, spec.options.replace(contact_margin=1.0))
    sim.step(sim.reset(spec.initial.q))
    assert min(c.gap for c in sim.last_step.contacts) == pytest.approx(0.02, abs=1e-9)


# a fixed-base pendulum placed on a stand, a floating ball and a free box, from one file
BODIES = """
[[bodies]]
name = "arm"
urdf = "models/pendulum.urdf"
position = [1.0, 0.0, 0.5]
rpy = [0.0, 0.0, 0.3]
configuration = [0.2]
friction = 0.4
[bodies.control]
type = "constant"
tau = [0.5]

[[bodies]]
name = "ball"
robot = "ball"
floating = true
position = [0.0, 0.0, 0.4]
velocity = [0.5, 0.0, 0.0, 0.0, 0.0, 0.0]
contype = 2
conaffinity = 2
color = [1.0, 0.0, 0.0]

[[bodies]]
name = "crate"
shape = "box"
size = [0.3, 0.2, 0.1]
density = 500.0
position = [0.4, 0.0, 0.2]
rpy = [0.0, 0.0, 0.5]
restitution = 0.2
ground_clearance = 0.001

[ground]
friction = 0.8

[simulation]
duration = 0.05
"""


def _bodies_scene(tmp_path, text=BODIES):
    (tmp_path / "models").mkdir(exist_ok=True)
    (tmp_path / "models" / "pendulum.urdf").write_text(
        (gaussim.robot.ROBOTS_DIR / "pendulum.urdf").read_text()
    )
    return _write(tmp_path, text)


def test_a_scene_of_bodies_is_the_scene_built_in_python(tmp_path):
    """Three [[bodies]] tables give the world gaussim.Scene(bodies=...) gives (the same pairs and
    materials), their initial states where the tables put them, and the same run, bit for bit."""
    spec = gaussim.load_scene(_bodies_scene(tmp_path))
    arm = gaussim.load_robot(tmp_path / "models" / "pendulum.urdf")
    ball = gaussim.load_robot("ball", floating_base=True)
    crate = FreeBody.box("crate", (0.3, 0.2, 0.1), density=500.0)
    scene = gaussim.Scene(
        bodies={
            "arm": Body(arm, placement=pose(1.0, 0.0, 0.5, rpy=(0, 0, 0.3)), material=Material(friction=0.4)),
            "ball": Body(ball, contype=2, conaffinity=2, color=(1.0, 0.0, 0.0, 1.0)),
            "crate": Body(crate, material=Material(restitution=0.2)),
        },
        ground=gaussim.Ground(friction=0.8),
    )
    assert list(spec.scene.bodies) == ["arm", "ball", "crate"]
    assert crate.mass == pytest.approx(500.0 * 0.3 * 0.2 * 0.1)
    assert [(p.name, p.friction, p.restitution) for p in spec.scene.pairs] == [
        (p.name, p.friction, p.restitution) for p in scene.pairs
    ]
    assert spec.scene.bodies["ball"].color == (1.0, 0.0, 0.0, 1.0)
    initial = spec.initial
    assert initial.body("arm").q.tolist() == [0.2]
    np.testing.assert_array_equal(initial.body("ball").q, [0, 0, 0.4, 0, 0, 0, 1])
    np.testing.assert_array_equal(initial.body("ball").v, [0.5, 0, 0, 0, 0, 0])
    # the crate at its pose, lowered to 1 mm above the ground (its half height 0.05 m)
    crate_q = initial.body("crate").q
    np.testing.assert_allclose(crate_q[:3], [0.4, 0.0, 0.051], atol=1e-12)
    np.testing.assert_allclose(crate_q[3:], pin.Quaternion(pin.rpy.rpyToMatrix(0, 0, 0.5)).coeffs())
    # the pendulum's base where its placement puts it: its hinge at (1, 0, 2.5)
    data = spec.robot.model.createData()
    pin.forwardKinematics(spec.robot.model, data, initial.q)
    np.testing.assert_allclose(data.oMi[1].translation, [1.0, 0.0, 2.5], atol=1e-15)
    log = gaussim.run(spec)
    sim = gaussim.Simulator(scene, spec.options)
    state = sim.reset({"arm": [0.2], "ball": pose(z=0.4), "crate": crate_q}, {"ball": [0.5, 0, 0, 0, 0, 0]})
    for k in range(log.steps):
        state = sim.step(state, {"arm": [0.5]})
        assert np.array_equal(state.q, log.q[k + 1]) and np.array_equal(state.v, log.v[k + 1]), k
    assert log.tau[:, 0].tolist() == [0.5] * log.steps  # the arm's control, the others none


def test_one_body_table_is_the_one_robot_form(tmp_path):
    """A single [[bodies]] table and the [robot] form read the same scene (names unprefixed)."""
    one = gaussim.load_scene(
        _write(
            tmp_path,
            BALL + "[initial]\nq = [0, 0, 0.3, 0, 0, 0, 1]\n[ground]\n[simulation]\nduration = 0.05\n",
        )
    )
    table = gaussim.load_scene(
        _bodies_scene(
            tmp_path,
            '[[bodies]]\nname = "ball"\nrobot = "ball"\nfloating = true\n'
            "configuration = [0, 0, 0.3, 0, 0, 0, 1]\n[ground]\n[simulation]\nduration = 0.05\n",
        )
    )
    assert [p.name for p in table.scene.pairs] == [p.name for p in one.scene.pairs] == ["ball_0/ground"]
    np.testing.assert_array_equal(gaussim.run(table).q, gaussim.run(one).q)


def test_a_mesh_body_takes_its_path_from_the_scene_folder(tmp_path):
    """A convex mesh (a 0.2 m cube written as STL) by density: the mass of its volume."""
    (tmp_path / "meshes").mkdir()
    corners = np.array([[x, y, z] for x in (0, 0.2) for y in (0, 0.2) for z in (0, 0.2)])
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1)]
    faces += [(2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    facets = "".join(
        "facet normal 0 0 0\nouter loop\n"
        + "".join(f"vertex {' '.join(map(str, corners[k]))}\n" for k in face)
        + "endloop\nendfacet\n"
        for face in faces
    )
    (tmp_path / "meshes" / "cube.stl").write_text(f"solid cube\n{facets}endsolid cube\n")
    text = '[[bodies]]\nname = "cube"\nshape = "mesh"\npath = "meshes/cube.stl"\ndensity = 1000.0\n'
    spec = gaussim.load_scene(_write(tmp_path, text))
    assert spec.robot.mass == pytest.approx(1000.0 * 0.2**3)
    missing = _write(tmp_path, text.replace("cube.stl", "ball.stl"))
    with pytest.raises(SceneFileError, match=rf"^{missing}: bodies\[0\].path: no such file"):
        gaussim.load_scene(missing)


def test_bilaterals_name_the_frames_of_bodies(tmp_path):
    text = (
        BODIES
        + "[[bilaterals]]\ntype = 'anchor'\nframe = 'arm/tip'\nposition = [1.0, 0.0, 1.5]\n"
        + "[[bilaterals]]\ntype = 'loop'\nframes = ['arm/tip', 'crate/crate']\n"
    )
    spec = gaussim.load_scene(_bodies_scene(tmp_path, text))
    assert [b.name for b in spec.scene.bilaterals] == ["anchor arm/tip", "loop arm/tip-crate/crate"]


def test_the_bodies_of_an_mjcf_file_are_a_scene(tmp_path):
    """[[bodies]] tables take each top-level body of one MJCF file (body = ...): an arm and a ball, the
    ball coming to rest on the table, the world's geom that goes with the first body."""
    (tmp_path / "two.xml").write_text(
        '<mujoco><worldbody><geom name="table" type="box" pos="0 0 -0.05" size="1 1 0.05"/>'
        '<body name="arm" pos="0 0 0.5"><joint type="hinge" axis="0 1 0"/>'
        '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/></body>'
        '<body name="ball" pos="0.5 0 0.3"><freejoint/><geom type="sphere" size="0.05"/></body>'
        "</worldbody></mujoco>"
    )
    path = _write(
        tmp_path,
        '[[bodies]]\nname = "arm"\nmjcf = "two.xml"\nbody = "arm"\n'
        '[[bodies]]\nname = "ball"\nmjcf = "two.xml"\nbody = "ball"\nconfiguration = "qpos0"\n'
        "[ground]\nheight = -1.0\n[simulation]\nduration = 1.0\n",
    )
    spec = gaussim.load_scene(path)
    assert [b.robot.name for b in spec.scene.bodies.values()] == ["arm", "ball"]
    sim = gaussim.Simulator(spec.scene, spec.options)
    state = sim.reset(spec.initial.q, spec.initial.v)
    for _ in range(spec.options.steps(1.0)):
        state = sim.step(state)
    assert state.body("ball").q[2] == pytest.approx(0.05, abs=1e-4)


BOX = '[[bodies]]\nname = "crate"\nshape = "box"\nsize = [0.2, 0.2, 0.2]\nmass = 1.0\n'
SOLO = '[[bodies]]\nname = "solo"\nrobot = "solo12"\n'


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        (BOX + "[[bodies]]\nshape = 'sphere'\nradius = 0.1\nmass = 1.0\n", r"bodies\[1\].name", "missing"),
        (BOX + BOX, r"bodies\[1\].name", "'crate' is also the name of bodies\\[0\\]"),
        (BOX.replace('"crate"', '"a/b"'), r"bodies\[0\].name", "without '/'"),
        (BOX + 'robot = "solo12"\n', r"bodies\[0\]", "give exactly one of robot.*got robot, shape"),
        ('[[bodies]]\nname = "x"\n', r"bodies\[0\]", "give exactly one of robot"),
        (BOX.replace('"box"', '"cone"'), r"bodies\[0\].shape", "'cone' is not one of box, sphere"),
        (BOX.replace("mass = 1.0", "mass = 0.0"), r"bodies\[0\].mass", "must be a finite number > 0"),
        (BOX.replace("mass = 1.0", "mass = -2"), r"bodies\[0\].mass", "must be a finite number > 0"),
        (BOX + "density = 10.0\n", r"bodies\[0\].mass", "give the mass .* or the density"),
        (BOX.replace("mass = 1.0", 'mass = "heavy"'), r"bodies\[0\].mass", "must be a finite number"),
        (BOX.replace("0.2, 0.2, 0.2", "0.2, 0.2"), r"bodies\[0\].size", "must be 3 finite numbers"),
        (BOX.replace("0.2, 0.2, 0.2", "0.2, -1, 0.2"), r"bodies\[0\].size", "must be a finite number > 0"),
        (BOX + "radius = 0.1\n", r"bodies\[0\].radius", "a box has size, not a radius"),
        (
            BOX.replace('"box"', '"capsule"').replace("size = [0.2, 0.2, 0.2]", "radius = 0.1"),
            r"bodies\[0\].length",
            "missing: a capsule needs radius and length",
        ),
        (BOX + "floating = true\n", r"bodies\[0\].floating", "only a robot takes it"),
        (SOLO + 'body = "base"\n', r"bodies\[0\].body", "a top-level body of an mjcf file, not of a robot"),
        (SOLO + "body = 3\n", r"bodies\[0\].body", "must be a string"),
        (SOLO + "mass = 3.0\n", r"bodies\[0\].mass", "only a shape takes it"),
        (SOLO.replace("solo12", "solo13"), r"bodies\[0\].robot", "no robot 'solo13'.*solo12"),
        ('[[bodies]]\nname = "m"\nmjcf = "missing.xml"\n', r"bodies\[0\].mjcf", "no such file"),
        ('[[bodies]]\nname = "m"\nsdf = "missing.sdf"\n', r"bodies\[0\].sdf", "no such file"),
        (BOX + "contype = -1\n", r"bodies\[0\].contype", "must be an integer bit mask >= 0"),
        (BOX + "conaffinity = true\n", r"bodies\[0\].conaffinity", "must be an integer bit mask"),
        (BOX + "friction = -1.0\n", r"bodies\[0\].friction", "must be a finite number >= 0"),
        (BOX + "restitution = 2.0\n", r"bodies\[0\].restitution", "must be in \\[0, 1\\]"),
        (BOX + "color = [1, 0, 2]\n", r"bodies\[0\].color", "in \\[0, 1\\]"),
        (BOX + "self_collision = 1\n", r"bodies\[0\].self_collision", "must be true or false"),
        (BOX + "position = [0, 0]\n", r"bodies\[0\].position", "must be 3 finite numbers"),
        (BOX + "spin = 1\n", r"bodies\[0\].spin", "unknown key; known:.*shape"),
        (BOX + 'configuration = "standing"\n', r"bodies\[0\].configuration", "no configuration 'standing'"),
        (BOX + "configuration = [0, 0, 1]\n", r"bodies\[0\].configuration", "must be 7 finite numbers"),
        (BOX + "velocity = [0, 0, 1]\n", r"bodies\[0\].velocity", "must be 6 finite numbers"),
        (BOX + "ground_clearance = 0.01\n", r"bodies\[0\].ground_clearance", "needs a \\[ground\\]"),
        (
            '[[bodies]]\nname = "arm"\nrobot = "pendulum"\nground_clearance = 0.01\n[ground]\n',
            r"bodies\[0\].ground_clearance",
            "needs a floating-base robot",
        ),
        (SOLO + "[bodies.control]\ntype = 'pd'\nkp = -1.0\n", r"bodies\[0\].control", "gains must be >= 0"),
        (SOLO + "[bodies.control]\ntype = 'constant'\ntau = [1]\n", r"bodies\[0\].control.tau", "must be 12"),
        (SOLO + "[bodies.control]\nkd = 'x'\ntype = 'pd'\n", r"bodies\[0\].control.kd", "finite number"),
        (SOLO + "[bodies.control]\ngain = 1\n", r"bodies\[0\].control.gain", "unknown key"),
        (BOX + BALL, "robot", r"a scene of \[\[bodies\]\] gives each body's robot"),
        (BOX + "[initial]\nq = [0]\n", "initial", "in its own table"),
        (BOX + "[control]\ntype = 'zero'\n", "control", "in its own table"),
        ("bodies = []\n", "bodies", "give at least one"),
        (
            BOX + "[ground]\n[contacts]\npairs = [['crate/lid', 'ground']]\n",
            "contacts.pairs",
            "no collision geometry 'crate/lid'",
        ),
        (BOX.replace('"crate"', '"ground"') + "[ground]\n", "obstacles", "name both an obstacle and a body"),
        (
            BOX + "[[bilaterals]]\ntype = 'anchor'\nframe = 'solo/base'\nposition = [0, 0, 1]\n",
            r"bilaterals\[0\].frame",
            "no frame 'solo/base'",
        ),
    ],
)
def test_a_bad_body_names_its_field(tmp_path, text, key, message):
    path = _write(tmp_path, text)
    with pytest.raises(SceneFileError, match=rf"^{path}: {key}: .*{message}"):
        gaussim.load_scene(path)


def test_a_bare_name_reads_the_shipped_scene(tmp_path, monkeypatch):
    """``gaussim run solo12_standing`` from anywhere (an installed package has no robots/ beside the
    user): a bare name that is no file reads the shipped scene; one that is not shipped says which are."""
    monkeypatch.chdir(tmp_path)
    shipped = load_scene(ROBOTS_DIR / "scenes" / "solo12_standing.toml")
    for name in ("solo12_standing", "solo12_standing.toml"):
        spec = load_scene(name)
        assert spec.scene.robot.name == shipped.scene.robot.name and spec.options == shipped.options
    listed = r"solo12_walk: file: cannot read it: .*shipped scenes: .*solo12_standing"
    with pytest.raises(SceneFileError, match=listed):
        load_scene("solo12_walk")


DATA = Path(__file__).parent / "data"


def _lowest_gap(spec):
    """The least gap to the ground at the scene's start (the first step detects from it)."""
    sim = gaussim.Simulator(spec.scene, spec.options.replace(contact_margin=10.0))
    sim.step(sim.reset(spec.initial.q))
    return min(c.gap for c in sim.last_step.contacts)


def test_a_robot_given_for_a_scene_runs_held_on_the_ground(tmp_path, monkeypatch):
    """``gaussim run ROBOT``: a robot's name or its URDF, MJCF or SDF file loads as the scene of that robot
    alone: its first named configuration, 1 cm above the ground (a fixed base: the ground 1 cm below its
    lowest geometry), every collision geometry against it, limits on, held by a PD posture hold."""
    monkeypatch.chdir(tmp_path)
    solo = load_scene("solo12")  # a name: floating, from its standing configuration
    standing = solo.robot.configuration("standing")
    assert solo.robot.floating and solo.scene.joint_limits
    assert np.array_equal(solo.initial.q[3:], standing[3:]) and _lowest_gap(solo) == pytest.approx(
        0.01, abs=1e-9
    )
    assert len(solo.scene.pairs) == len(solo.robot.collision_model.geometryObjects)
    solo.duration = 0.5
    log = gaussim.run(solo)
    joints = log.q[:, 7:]
    # held: the legs keep their posture under the robot's weight, the base rests above the ground
    assert np.abs(joints - standing[7:]).max() < 0.05 and log.q[-1, 2] > 0.8 * solo.initial.q[2]
    for path, key in (
        (ROBOTS_DIR / "pendulum.urdf", "urdf"),
        (DATA / "hopper.xml", "mjcf"),
        (DATA / "walker.sdf", "sdf"),
    ):
        spec = load_scene(path)
        assert f'{key} = "{path.resolve()}"' in spec.text
        assert _lowest_gap(spec) == pytest.approx(0.01, abs=1e-6), path.name
        spec.duration = 0.05
        assert gaussim.run(spec).complete


def test_a_file_of_several_free_bodies_run_by_itself_is_sent_to_a_scene_file(tmp_path, monkeypatch):
    """robots/box_stack.urdf (three boxes, each on its own free-flyer joint) run as a robot: one start
    pose would put them inside each other and one posture hold would hold their free coordinates, so
    it is refused naming its free joints and the scene file that runs it."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(
        gaussim.InvalidRobot, match=r"its 3 free-flyer joints \(bottom_joint, middle_joint, top_joint\)"
    ):
        load_scene(ROBOTS_DIR / "box_stack.urdf")
    assert load_scene(ROBOTS_DIR / "scenes" / "box_stack.toml").robot.model.nv == 18  # its scene runs


def test_a_robot_without_collision_geometry_runs_without_a_ground(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.warns(gaussim.GaussimWarning, match="no collision geometry"):
        spec = load_scene("asr_twodof")
    assert not spec.scene.obstacles and "[ground]" not in spec.text
    spec.duration = 0.05
    assert gaussim.run(spec).complete


def test_gaussim_run_robot_writes_its_scene_to_edit(tmp_path, monkeypatch, capsys):
    """The CLI writes the scene it made beside the run log; running that file runs the same; a file of
    that name the user changed is left alone."""
    from gaussim.cli import main

    monkeypatch.chdir(tmp_path)
    urdf = str(ROBOTS_DIR / "double_pendulum.urdf")
    assert main(["run", urdf, "--duration", "0.05", "--quiet"]) == 0
    written = tmp_path / "out" / "double_pendulum.toml"
    assert f"written to {Path('out') / 'double_pendulum.toml'}" in capsys.readouterr().err
    assert written.read_text() == load_scene(urdf).text
    assert main(["run", str(written), "--duration", "0.05", "--quiet", "--out", "again.runlog"]) == 0
    first, again = gaussim.RunLog.load("out/double_pendulum.runlog"), gaussim.RunLog.load("again.runlog")
    assert np.array_equal(first.q, again.q)
    written.write_text(written.read_text().replace("kp = ", "kp = 1"))
    assert main(["run", urdf, "--duration", "0.05", "--quiet"]) == 0
    assert "is left as it is" in capsys.readouterr().err and "kp = 1" in written.read_text()


def test_a_robot_whose_named_start_is_outside_its_limits_starts_clamped_and_placed(tmp_path, monkeypatch):
    """kinova's arm_up has a joint 1.9 rad outside its limits: its scene starts (and holds) it clamped
    into them, with the ground placed 1 cm below that configuration, not the named one."""
    import warnings

    monkeypatch.chdir(tmp_path)
    spec = load_scene("kinova")
    model = spec.robot.model
    assert "clamped into the joint limits: 'j2s6s200_joint_3' at -1.571" in spec.text
    assert np.all(spec.initial.q >= model.lowerPositionLimit) and np.all(
        spec.initial.q <= model.upperPositionLimit
    )
    assert _lowest_gap(spec) == pytest.approx(0.01, abs=1e-6)
    spec.duration = 0.05
    with warnings.catch_warnings():
        warnings.simplefilter("error", gaussim.GaussimWarning)  # no start clamped by the run
        assert gaussim.run(spec).complete


def test_a_file_of_one_rigid_body_floats_and_comes_to_rest_on_the_ground(tmp_path, monkeypatch):
    """robots/box.urdf (no joint: fixed, nothing would move) runs floating, as PyBullet loads such a file:
    dropped from 1 cm it rests on its 0.1 m side, its centre at 0.05 m; a file that fails for another
    reason keeps its own error."""
    monkeypatch.chdir(tmp_path)
    spec = load_scene("box")
    assert spec.robot.floating and spec.robot.model.nv == 6 and "floating_base = true" in spec.text
    assert "[control]" not in spec.text and _lowest_gap(spec) == pytest.approx(0.01, abs=1e-9)
    spec.duration = 0.5
    log = gaussim.run(spec)
    assert log.q[-1, 2] == pytest.approx(0.05, abs=1e-4) and np.abs(log.v[-1]).max() < 1e-3
    broken = tmp_path / "broken.urdf"
    broken.write_text("<robot name='b'><link name='a'>")
    with pytest.raises(gaussim.InvalidRobot, match="not well-formed XML"):
        load_scene(broken)


def test_a_robot_run_by_itself_is_loaded_once(tmp_path, monkeypatch):
    """Writing the robot's scene loads it; reading that scene takes the same robot (a mesh-heavy robot's
    load is seconds: G1 with hands, 3.3 s)."""
    import gaussim.scenefile as scenefile

    calls = []
    load = scenefile.load_robot
    monkeypatch.setattr(scenefile, "load_robot", lambda *a, **k: calls.append(a) or load(*a, **k))
    monkeypatch.chdir(tmp_path)
    spec = load_scene("solo12")
    assert len(calls) == 1 and spec.robot.name == "solo12"


def test_gaussim_run_robot_leaves_the_scene_of_another_robot_and_says_so(tmp_path, monkeypatch, capsys):
    """kuka_iiwa/model.sdf then kuka_iiwa/model.urdf (one stem, out/model.toml for both): the second run
    said 'out/model.toml, which differs from it, is left as it is (run that file to use it)', and that
    file runs the first robot. It now says whose scene the file is, and that this robot's is not
    written."""
    from gaussim.cli import main

    monkeypatch.chdir(tmp_path)
    for folder, robot in (("a", "pendulum"), ("b", "double_pendulum")):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "robot.urdf").write_text((ROBOTS_DIR / f"{robot}.urdf").read_text())
    assert main(["run", "a/robot.urdf", "--duration", "0.01", "--quiet"]) == 0
    first = (tmp_path / "out" / "robot.toml").read_text()
    capsys.readouterr()
    assert main(["run", "b/robot.urdf", "--duration", "0.01", "--quiet"]) == 0
    err = capsys.readouterr().err
    first_urdf = tmp_path / "a" / "robot.urdf"
    told = f'{Path("out") / "robot.toml"} is the scene of urdf = "{first_urdf}", not of this robot'
    assert told in err and "this robot's scene is not written" in err, err
    assert "run that file to use it" not in err
    assert (tmp_path / "out" / "robot.toml").read_text() == first


def test_a_pair_with_the_ground_in_a_scene_without_one_says_the_ground_is_missing(tmp_path):
    """A [[bodies]] scene file has no ground unless it has a [ground] section: its pairs with "ground"
    said only "no obstacle or collision geometry 'ground' in the scene", as for a misspelt name."""
    path = _write(
        tmp_path,
        '[[bodies]]\nname = "ball"\nshape = "sphere"\nradius = 0.1\nmass = 1.0\nposition = [0, 0, 0.2]\n'
        '[contacts]\npairs = [["ball", "ground"]]\n',
    )
    told = "it has no ground: give ground=gaussim.Ground(); a scene file, a [ground] section"
    with pytest.raises(
        SceneFileError,
        match=re.escape(f"contacts.pairs: no obstacle or collision geometry 'ground' in the scene ({told})"),
    ):
        load_scene(path)
    path.write_text(path.read_text() + "[ground]\n")
    assert len(load_scene(path).scene.pairs) == 1
