"""Scenes of several bodies: robots and free objects in one world (gaussim.world)."""

import numpy as np
import pinocchio as pin
import pytest

import gaussim
from gaussim import Body, FreeBody, Material, pose
from gaussim.robot import ROBOTS_DIR

from .conftest import G

# Two runs of the same physics through different but equal models agree to this [m, m/s].
SAME = 1e-12


def crate(name="crate", mass=2.0):
    return FreeBody.box(name, (0.3, 0.3, 0.2), mass=mass)


def test_a_free_body_has_the_inertia_of_its_shape():
    """Mass and inertia from a mass or a density, checked against the closed forms."""
    box = FreeBody.box("b", (0.2, 0.4, 0.6), density=1000.0)
    m = 1000.0 * 0.2 * 0.4 * 0.6
    assert box.mass == pytest.approx(m)
    I = box.robot().model.inertias[1].inertia
    np.testing.assert_allclose(
        np.diag(I), m / 12 * np.array([0.4**2 + 0.6**2, 0.2**2 + 0.6**2, 0.2**2 + 0.4**2])
    )
    ball = FreeBody.sphere("s", 0.1, mass=3.0)
    np.testing.assert_allclose(ball.robot().model.inertias[1].inertia, 0.4 * 3.0 * 0.01 * np.eye(3))
    rod = FreeBody.cylinder("c", 0.05, 1.0, mass=1.0)
    np.testing.assert_allclose(
        np.diag(rod.robot().model.inertias[1].inertia), [(3 * 0.05**2 + 1) / 12] * 2 + [0.05**2 / 2]
    )
    # a capsule's mass is its cylinder's and its two half balls', at one density
    capsule = FreeBody.capsule("k", 0.1, 0.5, density=100.0)
    assert capsule.mass == pytest.approx(100.0 * (np.pi * 0.01 * 0.5 + 4 / 3 * np.pi * 0.001))
    robot = capsule.robot()
    assert robot.floating and robot.model.nv == 6
    assert gaussim.dynamics.FloatingBases.of(robot.model).rigid.all()  # its centre of mass at the joint


def test_two_bodies_far_apart_evolve_as_each_alone():
    """Two spinning, falling free bodies in one world: each follows its own run to round-off."""
    shapes = {
        "a": FreeBody.box("a", (0.2, 0.3, 0.4), mass=1.5),
        "b": FreeBody.capsule("b", 0.1, 0.3, mass=0.7),
    }
    starts = {
        "a": (pose(z=2.0, rpy=(0.3, 0.2, 0.1)), [1.0, 0.0, 2.0, 3.0, -5.0, 1.0]),
        "b": (pose(x=5.0, z=3.0), [0.0, -1.0, 0.5, 8.0, 0.5, -2.0]),
    }
    together = gaussim.Simulator(gaussim.Scene(bodies=shapes))
    state = together.reset({k: s[0] for k, s in starts.items()}, {k: s[1] for k, s in starts.items()})
    alone = {}
    for name, body in shapes.items():
        sim = gaussim.Simulator(gaussim.Scene(bodies={name: body}))
        alone[name] = (sim, sim.reset({name: starts[name][0]}, {name: starts[name][1]}))
    for _ in range(300):
        state = together.step(state)
        for name, (sim, own) in alone.items():
            alone[name] = (sim, sim.step(own))
            np.testing.assert_allclose(state.body(name).q, alone[name][1].q, rtol=0, atol=SAME)
            np.testing.assert_allclose(state.body(name).v, alone[name][1].v, rtol=0, atol=SAME)


def test_a_world_equals_the_hand_merged_model(solo12):
    """Solo-12 and a crate on the ground, as a world, step for step equal to the same bodies merged by
    hand with pinocchio.appendModel (the names prefixed, the pairs listed in the same order)."""
    box = crate()
    pairs = [("solo/*FOOT*", "ground"), ("crate/box", "ground"), ("solo/*", "crate/box")]
    world = gaussim.Scene(bodies={"solo": solo12, "crate": box}, ground=gaussim.Ground(), contacts=pairs)
    model, collision, visual = pin.Model(), pin.GeometryModel(), pin.GeometryModel()
    for prefix, robot in (("solo/", solo12), ("crate/", box.robot())):
        part, part_collision, part_visual = (
            robot.model.copy(),
            robot.collision_model.copy(),
            robot.visual_model.copy(),
        )
        for j in range(1, part.njoints):
            part.names[j] = prefix + part.names[j]
        for i in range(1, len(part.frames)):
            part.frames[i].name = prefix + part.frames[i].name
        for geometries in (part_collision, part_visual):
            for g in geometries.geometryObjects:
                g.name = prefix + g.name
        merged, collision = pin.appendModel(model, part, collision, part_collision, 0, pin.SE3.Identity())
        _, visual = pin.appendModel(model, part, visual, part_visual, 0, pin.SE3.Identity())
        model = merged
    by_hand = gaussim.Scene(
        gaussim.as_robot((model, collision, visual), "by hand"), ground=gaussim.Ground(), contacts=pairs
    )
    assert [p.name for p in world.pairs] == [p.name for p in by_hand.pairs]
    q = np.concatenate([solo12.configuration("standing"), pin.SE3ToXYZQUAT(pose(x=0.45, z=0.1))])
    q[2] += 0.05
    sims = [gaussim.Simulator(scene) for scene in (world, by_hand)]
    states = [sim.reset(q) for sim in sims]
    rng, pressed = np.random.default_rng(0), set()
    for _ in range(200):
        tau = np.r_[np.zeros(6), rng.normal(size=12), np.zeros(6)]
        states = [sim.step(s, tau) for sim, s in zip(sims, states)]
        assert np.array_equal(states[0].q, states[1].q) and np.array_equal(states[0].v, states[1].v)
        pressed |= {c.geometry for c in sims[0].last_step.contacts if c.normal_force > 0}
    assert "crate/box" in pressed and len(pressed) >= 3, pressed  # the feet and the crate touch the ground


def test_forces_between_bodies_obey_action_and_reaction():
    """A box resting on another: the force on the top from the bottom is minus the force on the bottom
    from the top, and carries the top's weight; the ground carries both."""
    top, bottom = (
        FreeBody.box("top", (0.2, 0.2, 0.2), mass=1.0),
        FreeBody.box("bottom", (0.4, 0.4, 0.2), mass=3.0),
    )
    scene = gaussim.Scene(bodies={"bottom": bottom, "top": top}, ground=gaussim.Ground())
    sim = gaussim.Simulator(scene)
    state = sim.reset({"bottom": pose(z=0.1), "top": pose(x=0.05, z=0.3 + 1e-4, rpy=(0, 0, 0.3))})
    for _ in range(300):
        state = sim.step(state)
    report = sim.last_step
    on_top = report.forces_between("top", "bottom")
    np.testing.assert_allclose(on_top, -report.forces_between("bottom", "top"), atol=1e-12)
    np.testing.assert_allclose(on_top, [0, 0, 1.0 * G], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(
        report.forces_between("bottom", "ground"), [0, 0, 4.0 * G], rtol=1e-6, atol=1e-6
    )
    assert report.forces_between("top", "ground") @ np.ones(3) == 0.0  # they do not touch
    with pytest.raises(gaussim.InvalidOptions, match="no body or obstacle 'grund'; .*the obstacles: ground"):
        report.forces_between("top", "grund")  # a misspelt side is named, not summed to zeros
    assert {frozenset(report.body_of(c)) for c in report.contacts} == {
        frozenset(("top", "bottom")),
        frozenset(("bottom", "ground")),
    }


def test_adjacent_links_never_touch_and_self_collision_is_opt_in(solo12):
    """The automatic pairs: a robot's own links only with ``self_collision``, and never two links
    whose joint holds them together."""
    world = gaussim.Scene(bodies={"solo": solo12})
    assert not world.pairs
    selfish = gaussim.Scene(bodies={"solo": Body(solo12, self_collision=True)})
    model, collision = selfish.robot.model, selfish.robot.collision_model
    joints = {
        p.name: (
            collision.geometryObjects[p.geometry].parentJoint,
            collision.geometryObjects[p.other].parentJoint,
        )
        for p in selfish.pairs
    }
    assert joints
    for name, (a, b) in joints.items():
        assert a != b and model.parents[a] != b and model.parents[b] != a, name
    assert "FL_UPPER_LEG_0/HL_UPPER_LEG_0" in joints  # one body: its own names
    # adjacent links are skipped however the pairs are asked for; asked for by name, they are refused
    listed = gaussim.Scene(bodies={"solo": solo12, "c": crate()}, contacts=[("solo/*", "solo/*")])
    assert {p.name.replace("solo/", "") for p in listed.pairs} == set(joints)


def test_masks_filter_bodies_as_mujoco_does():
    """contype / conaffinity: a pair may touch when a.contype & b.conaffinity or b.contype &
    a.conaffinity."""

    def pairs(a, b):
        scene = gaussim.Scene(
            bodies={
                "a": Body(crate("a"), contype=a[0], conaffinity=a[1]),
                "b": Body(crate("b"), contype=b[0], conaffinity=b[1]),
            }
        )
        return len(scene.pairs)

    assert pairs((1, 1), (1, 1)) == 1
    assert pairs((1, 0), (0, 1)) == 1
    assert pairs((2, 2), (1, 1)) == 0
    assert pairs((0, 0), (1, 1)) == 0


def test_materials_combine_by_the_larger_value(solo12):
    """A body's or geometry's material against the ground's: the larger friction and restitution; two
    bodies that declare none take the scene's default."""
    slippery = FreeBody.box(
        "ice", (0.2, 0.2, 0.2), mass=1.0, material=Material(friction=0.1, restitution=0.5)
    )
    scene = gaussim.Scene(
        bodies={"ice": slippery, "solo": solo12, "plain": crate("plain")},
        ground=gaussim.Ground(friction=0.3),
        materials={"solo/FL_FOOT_0": Material(friction=1.2)},
        self_contact=(0.6, 0.1),
    )
    by_name = {p.name: (p.friction, p.restitution) for p in scene.pairs}
    assert by_name["ice/box/ground"] == (0.3, 0.5)
    assert by_name["solo/FL_FOOT_0/ground"] == (1.2, 0.0)
    assert by_name["solo/HL_FOOT_0/ground"] == (0.3, 0.0)
    assert by_name["ice/box/solo/FL_FOOT_0"] == (1.2, 0.5)
    assert by_name["solo/HL_FOOT_0/plain/box"] == (0.6, 0.1)


def test_pairs_take_qualified_names_wildcards_and_bodies(solo12):
    scene = gaussim.Scene(
        bodies={"solo": solo12, "crate": crate()},
        ground=gaussim.Ground(),
        contacts=[("solo/*_FOOT_0", "ground"), ("crate", "ground"), ("FL_FOOT_0", "crate")],
    )
    assert [p.name for p in scene.pairs] == [
        "solo/FL_FOOT_0/ground",
        "solo/FR_FOOT_0/ground",
        "solo/HL_FOOT_0/ground",
        "solo/HR_FOOT_0/ground",
        "crate/box/ground",
        "solo/FL_FOOT_0/crate/box",
    ]


def test_per_body_torques_and_states(solo12):
    """A torque per body is the world torque with the others zero; per-body views are the state's."""
    scene = gaussim.Scene(bodies={"crate": crate(), "solo": solo12}, gravity=(0, 0, 0))
    q = {"crate": pose(z=3.0), "solo": solo12.configuration("standing")}
    tau = np.arange(12.0)
    sims = [gaussim.Simulator(scene) for _ in range(3)]
    given = [{"solo": tau}, np.r_[np.zeros(12), tau], tau]  # per body, the world's (nv,), the actuated
    states = [sim.step(sim.reset(q), t) for sim, t in zip(sims, given)]
    for s in states[1:]:
        assert np.array_equal(s.q, states[0].q) and np.array_equal(s.v, states[0].v)
    solo = states[0].body("solo")
    assert solo.q.shape == (19,) and np.array_equal(solo.v, states[0].v[6:])
    np.testing.assert_allclose(states[0].body("crate").q[:3], [0, 0, 3.0])


def test_no_torque_drives_a_free_root(solo12):
    """The actuated coordinates leave out the six of every free-flyer joint hung from the world: none
    in robots/box_stack.urdf (three free boxes, whose upper two were counted as 12 actuated ones, so a
    torque of 12 entries pushed the boxes apart), 6 to 18 in Solo-12."""
    stack = gaussim.load_robot(ROBOTS_DIR / "box_stack.urdf")
    assert stack.actuated.shape == (0,)
    np.testing.assert_array_equal(solo12.actuated, np.arange(6, 18))
    sim = gaussim.Simulator(gaussim.Scene(bodies={"solo": solo12, "stack": stack}, gravity=(0, 0, 0)))
    state = sim.reset({"solo": solo12.configuration("standing"), "stack": stack.neutral()})
    with pytest.raises(gaussim.InvalidState, match=r"tau\['stack'\] must have shape \(18,\) or \(0,\)"):
        sim.step(state, {"stack": np.ones(12)})
    with pytest.raises(gaussim.InvalidState, match=r"tau must have shape \(36,\) or \(12,\) for the"):
        sim.step(state, np.ones(24))  # 12 of Solo-12's, 12 the stack's upper boxes'
    moved = sim.step(state, np.ones(12))  # Solo-12's joints alone
    assert np.array_equal(moved.body("stack").v, np.zeros(18))


@pytest.mark.parametrize(
    ("make", "error", "message"),
    [
        (lambda s: gaussim.Scene(bodies={}), gaussim.InvalidOptions, r"bodies: must map body names"),
        (lambda s: gaussim.Scene(bodies={"a/b": crate()}), gaussim.InvalidOptions, r"without '/'"),
        (
            lambda s: gaussim.Scene(bodies={"ground": crate()}, ground=gaussim.Ground()),
            gaussim.InvalidOptions,
            r"\['ground'\] name both an obstacle and a body",
        ),
        (
            lambda s: FreeBody.box("b", (1, 1, 1), mass=0.0),
            gaussim.InvalidOptions,
            r"b.mass: must be a finite number > 0",
        ),
        (lambda s: FreeBody.box("b", (1, 1, 1)), gaussim.InvalidOptions, r"give the mass"),
        (lambda s: FreeBody.sphere("b", -1.0, mass=1.0), gaussim.InvalidOptions, r"b.radius"),
        (
            lambda s: gaussim.Scene(bodies={"solo": s, "c": crate()}, contacts=[("solo/NOSE", "c")]),
            gaussim.GeometryNotFound,
            r"no collision geometry 'solo/NOSE'.*solo/FL_FOOT_0",
        ),
        (
            lambda s: gaussim.Scene(bodies={"solo": s, "c": crate()}, contacts=[("solo/FL_FOOT_0", "table")]),
            gaussim.GeometryNotFound,
            r"no obstacle or collision geometry 'table' in the scene",
        ),
        (
            lambda s: gaussim.Scene(
                bodies={"solo": s, "c": crate()}, contacts=[("solo/FL_FOOT_0", "solo/FL_LOWER_LEG_0")]
            ),
            gaussim.InvalidOptions,
            r"adjacent links never touch",
        ),
        (
            lambda s: gaussim.Scene(bodies={"a": s, "b": s}, contacts=[("FL_FOOT_0", "b/HL_FOOT_0")]),
            gaussim.InvalidOptions,
            r"'FL_FOOT_0' is ambiguous",
        ),
        (
            lambda s: gaussim.Simulator(gaussim.Scene(bodies={"c": crate()})).reset({"box": pose()}),
            gaussim.InvalidOptions,
            r"no body 'box'; the bodies: c",
        ),
        (
            lambda s: gaussim.Simulator(gaussim.Scene(bodies={"c": crate()})).reset({"c": np.zeros(3)}),
            gaussim.InvalidState,
            r"q\['c'\] must have shape \(7,\)",
        ),
        (
            lambda s: gaussim.Simulator(gaussim.Scene(bodies={"c": crate(), "d": crate("d")})).reset(),
            gaussim.InvalidState,
            r"'c/box' .* inside 'd/box'",
        ),
        (
            lambda s: (lambda sim: sim.step(sim.reset({"c": pose(z=1)}), {"c": np.zeros(2)}))(
                gaussim.Simulator(gaussim.Scene(bodies={"c": crate()}))
            ),
            gaussim.InvalidState,
            r"tau\['c'\] must have shape \(6,\)",
        ),
        (
            lambda s: gaussim.Scene(bodies={"c": Body(crate(), placement=pose(z=1))}),
            gaussim.InvalidOptions,
            r"bodies.c.placement: a free body is placed by its configuration",
        ),
        (lambda s: gaussim.Scene(bodies={"c": 3}), gaussim.InvalidRobot, r"cannot make a robot of int"),
    ],
)
def test_bad_world_input_is_named(solo12, make, error, message):
    with pytest.raises(error, match=message):
        make(solo12)


def test_a_fixed_base_robot_is_placed_where_told():
    """A fixed-base arm on a table: its base where its Body's placement puts it."""
    arm = gaussim.load_robot("pendulum")
    placed = gaussim.Scene(bodies={"arm": Body(arm, placement=pose(x=1.0, z=0.5)), "c": crate()})
    model, data = placed.robot.model, placed.robot.model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    alone = arm.model.createData()
    pin.forwardKinematics(arm.model, alone, pin.neutral(arm.model))
    np.testing.assert_allclose(data.oMi[1].translation, alone.oMi[1].translation + [1.0, 0, 0.5], atol=1e-15)


def test_a_torque_given_one_way_does_not_linger_into_the_next(solo12):
    """The actuation stage's padding holds no entry of an earlier torque: a wrench on the crate, then
    the actuated joints' torques alone, then the world's, each padded afresh."""
    scene = gaussim.Scene(bodies={"crate": crate(), "solo": solo12}, gravity=(0, 0, 0))
    sim = gaussim.Simulator(scene)
    actuation, rng = sim.actuation, np.random.default_rng(1)
    wrench, joints, world = rng.normal(size=6), rng.normal(size=12), rng.normal(size=24)
    np.testing.assert_array_equal(actuation.torque({"crate": wrench}), np.r_[wrench, np.zeros(18)])
    np.testing.assert_array_equal(actuation.torque(joints), np.r_[np.zeros(12), joints])
    np.testing.assert_array_equal(actuation.torque(world), world)
    np.testing.assert_array_equal(actuation.torque({"solo": joints}), np.r_[np.zeros(12), joints])


def test_bodies_own_their_geometries_whatever_order_pinocchio_merges_them():
    """pin.appendModel puts a fixed base's geometries (on the universe) ahead of the earlier bodies'
    moving ones: a body's geometries are found by name, so no automatic pair joins one body's links,
    and two arms and a cube start apart."""
    panda = gaussim.load_robot("panda")
    scene = gaussim.Scene(
        bodies={"arm": panda, "arm2": Body(panda, placement=pose(y=0.8)), "cube": crate("cube")},
        ground=gaussim.Ground(),
    )
    names = [g.name for g in scene.robot.collision_model.geometryObjects]
    for name, layout in scene.bodies.items():
        assert sorted(names[g] for g in layout.geometries) == sorted(
            n for n in names if n.startswith(name + "/")
        )
    cross = [p for p in scene.pairs if p.other is not None]
    assert cross and all(names[p.geometry].split("/")[0] != names[p.other].split("/")[0] for p in cross)
    gaussim.Simulator(scene).reset({"cube": pose(x=0.5, z=0.1)})


def test_a_world_and_its_simulator_make_one_data_of_its_size(monkeypatch, solo12):
    """Pinocchio's data grows as nv^3 (a second-order tensor: 3.3 GB and 4.5 s for 64 free bodies):
    a world is checked body by body and its Simulator computes a constant M in its own data, so
    building a world of a robot and boxes and its Simulator makes one data of the world's size, and
    the checks of each box one of its own."""
    sizes = []
    make = pin.Model.createData
    monkeypatch.setattr(pin.Model, "createData", lambda self: sizes.append(self.nv) or make(self))
    bodies = {f"box{k}": crate(f"box{k}") for k in range(3)}
    for world in (bodies, {**bodies, "solo": solo12}):
        sizes.clear()
        scene = gaussim.Scene(bodies=world, ground=gaussim.Ground())
        gaussim.Simulator(scene)
        assert sizes.count(scene.robot.model.nv) == 1 and sizes.count(6) == 3, sizes
