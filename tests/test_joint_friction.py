"""The joints' viscous damping and dry friction of the robot files (Scene(joint_friction=True)), against
closed forms."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import gaussim

PENDULUM = (Path(__file__).parents[1] / "robots" / "pendulum.urdf").read_text()
I = 1.0 + 0.001  # the pendulum's inertia about its hinge [kg m^2]: the bob at 1 m, and its own
G = 9.81


def pendulum(tmp_path, damping=0.0, friction=0.0, gravity=True):
    """robots/pendulum.urdf with <dynamics damping friction> on its hinge, in a scene that applies them."""
    path = tmp_path / "pendulum.urdf"
    path.write_text(
        PENDULUM.replace(
            '<axis xyz="0 1 0"/>', f'<axis xyz="0 1 0"/><dynamics damping="{damping}" friction="{friction}"/>'
        )
    )
    robot = gaussim.load_robot(path)
    return gaussim.Scene(robot, joint_friction=True, gravity=(0.0, 0.0, -G if gravity else 0.0))


@pytest.mark.parametrize("scheme", ["velocity", "acceleration"])
def test_the_files_damping_slows_a_joint_as_implicit_damping_does(tmp_path, scheme):
    """v_n = v0 / (1 + dt D / I)^n exactly (backward Euler of I v' = -D v); off without joint_friction."""
    scene, dt, D, v0 = pendulum(tmp_path, damping=2.0, gravity=False), 1e-2, 2.0, 3.0
    sim = gaussim.Simulator(scene, gaussim.Options(dt=dt, scheme=scheme))
    state = sim.reset(np.zeros(1), np.array([v0]))
    for n in range(1, 101):
        state = sim.step(state)
        assert state.v[0] == pytest.approx(v0 / (1.0 + dt * D / I) ** n, rel=1e-12)
    free = gaussim.Scene(
        scene.robot, gravity=(0.0, 0.0, 0.0)
    )  # joint_friction off: the file's damping unread
    sim = gaussim.Simulator(free, gaussim.Options(dt=dt, scheme=scheme))
    assert sim.step(sim.reset(np.zeros(1), np.array([v0]))).v[0] == v0


@pytest.mark.parametrize("scheme", ["velocity", "acceleration"])
def test_dry_friction_stops_a_spinning_joint_at_a_constant_rate_then_holds_it(tmp_path, scheme):
    """Without gravity, friction f decelerates the joint by f / I until it stops, exactly at each step,
    and then holds it with no torque; each step reports the friction torque, sliding then sticking."""
    scene, dt, f, v0 = pendulum(tmp_path, friction=0.5, gravity=False), 1e-3, 0.5, 0.3
    sim = gaussim.Simulator(scene, gaussim.Options(dt=dt, scheme=scheme))
    state = sim.reset(np.zeros(1), np.array([v0]))
    stop = v0 * I / f  # [s]
    for n in range(1, 1000):
        state = sim.step(state)
        expected = max(v0 - n * dt * f / I, 0.0)
        assert state.v[0] == pytest.approx(expected, abs=1e-9)
        (reaction,) = sim.last_step.joint_friction
        assert reaction.joint == "hinge"
        if n * dt < stop - dt:
            assert reaction.sliding and reaction.torque == pytest.approx(-f, rel=1e-9)
        elif n * dt > stop + dt:
            assert not reaction.sliding and abs(reaction.torque) < 1e-6
    assert state.q[0] == pytest.approx(v0 * stop / 2, abs=2 * v0 * dt)


@pytest.mark.parametrize("scheme", ["velocity", "acceleration"])
@pytest.mark.parametrize("angle", [0.2, 0.3])
def test_dry_friction_holds_a_pendulum_while_gravity_pulls_less_than_it(tmp_path, scheme, angle):
    """Started at rest at an angle: held when m g l sin(angle) <= f (the reported torque is the gravity
    torque it holds), else it swings with the friction torque f against it (I a = -m g l sin q + f)."""
    f = G * np.sin(0.25)  # holds below 0.25 rad
    scene = pendulum(tmp_path, friction=f)
    sim = gaussim.Simulator(scene, gaussim.Options(dt=1e-3, scheme=scheme))
    state = sim.step(sim.reset(np.array([angle])))
    (reaction,) = sim.last_step.joint_friction
    if angle < 0.25:
        assert abs(state.q[0] - angle) < 1e-12 and abs(state.v[0]) < 1e-12
        assert not reaction.sliding and reaction.torque == pytest.approx(G * np.sin(angle), rel=1e-9)
    else:
        assert reaction.sliding and reaction.torque == pytest.approx(f, rel=1e-9)
        assert state.v[0] == pytest.approx(1e-3 * (f - G * np.sin(angle)) / I, rel=1e-6)


def test_friction_in_one_of_several_joints_of_a_moving_robot(tmp_path):
    """A double pendulum whose elbow has friction: energy never rises, and the elbow's reported torque
    never exceeds its bound; the shoulder, frictionless, has no row."""
    text = (Path(__file__).parents[1] / "robots" / "double_pendulum.urdf").read_text()
    head, _, tail = text.partition("</joint>")
    second = tail.replace("<axis", '<dynamics friction="0.2"/><axis', 1)
    path = tmp_path / "double.urdf"
    path.write_text(head + "</joint>" + second)
    robot = gaussim.load_robot(path)
    assert robot.model.friction.tolist() == [0.0, 0.2]
    sim = gaussim.Simulator(gaussim.Scene(robot, joint_friction=True), gaussim.Options(dt=1e-3))
    model, data = sim.model, sim.model.createData()

    def energy(s):
        return pin.computeKineticEnergy(model, data, s.q, s.v) + pin.computePotentialEnergy(model, data, s.q)

    state = sim.reset(np.array([np.cos(1.0), np.sin(1.0), np.cos(-0.5), np.sin(-0.5)]))
    start, torques = energy(state), []
    for _ in range(2000):
        state = sim.step(state)
        assert energy(state) <= start + 1e-9
        torques += [r.torque for r in sim.last_step.joint_friction]
    assert max(np.abs(torques)) <= 0.2 * (1 + 1e-9) and max(np.abs(torques)) > 0.19
    assert energy(state) < start - 0.01, "friction takes energy"


def test_a_negative_damping_in_a_file_is_refused_naming_the_joint(tmp_path):
    with pytest.raises(gaussim.InvalidRobot, match=r"joints \['hinge'\] have a damping of \[-1.0\]"):
        pendulum(tmp_path, damping=-1.0)


def test_a_scene_file_declares_joint_friction_and_a_robots_own_scene_has_it_where_its_file_gives_any(
    tmp_path,
):
    from gaussim.scenefile import load_scene_text, robot_scene_text

    scene = pendulum(tmp_path, friction=0.5)
    text = f'[robot]\nurdf = "{scene.robot.source}"\n\n[joint_friction]\nenabled = true\n'
    spec = load_scene_text(text, tmp_path / "scene.toml")
    assert spec.scene.joint_friction and [m.name for m in gaussim.Simulator(spec.scene).modules] == [
        "joint_friction"
    ]
    assert not load_scene_text(text.replace("true", "false"), tmp_path / "scene.toml").scene.joint_friction
    with pytest.raises(gaussim.InvalidOptions, match=r"joint_friction.enabled"):
        load_scene_text(text.replace("true", '"yes"'), tmp_path / "scene.toml")
    assert "[joint_friction]" in robot_scene_text("panda")  # damping 0.3 in its URDF
    assert "[joint_friction]" not in robot_scene_text("solo12")


def test_an_mjcf_hinges_damping_and_frictionloss_slow_it_as_mujoco_does(tmp_path):
    """A spinning arm whose MJCF hinge has damping 0.3 and frictionloss 0.2: gaussim's velocity follows
    MuJoCo's (implicitfast, dt 1 ms) to 1e-10 while it slides, and both hold it once stopped (MuJoCo's
    soft friction row lets it creep at 1e-10 rad/s)."""
    mujoco = pytest.importorskip("mujoco")
    path = tmp_path / "spin.xml"
    path.write_text(
        '<mujoco><option gravity="0 0 0" timestep="0.001" integrator="implicitfast"/><worldbody>'
        '<body name="arm"><joint name="a" type="hinge" axis="0 0 1" damping="0.3" frictionloss="0.2"/>'
        '<geom type="capsule" fromto="0 0 0 1 0 0" size="0.05" mass="1"/></body></worldbody></mujoco>'
    )
    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    data.qvel[0] = 2.0
    robot = gaussim.load_robot(path)
    sim = gaussim.Simulator(
        gaussim.Scene(robot, joint_friction=True, gravity=(0, 0, 0)), gaussim.Options(dt=1e-3)
    )
    state = sim.reset(None, np.array([2.0]))
    sliding = 0
    for _ in range(2500):
        mujoco.mj_step(model, data)
        state = sim.step(state)
        if data.qvel[0] > 0.05:
            sliding += 1
            assert state.v[0] == pytest.approx(data.qvel[0], abs=1e-10)
    assert sliding > 1000 and abs(data.qvel[0]) < 1e-9 and abs(state.v[0]) < 1e-12


def test_an_arm_falling_onto_the_ground_with_friction_in_its_joints_gives_way_to_the_contacts():
    """example-robot-data's z1 (dry friction in its joints) let go with zero torques falls onto the
    ground under it: where holding its joints still contradicts the ground pushing it out (a row for each
    stuck joint made its step's QP infeasible at step 189), the friction, a bounded force, gives way."""
    import sys

    sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
    from corpus import scene_and_start

    robot = gaussim.load_robot("z1")
    assert robot.model.friction.any()
    scene, q0 = scene_and_start(robot)
    assert scene.joint_friction
    sim = gaussim.Simulator(scene, gaussim.Options(dt=1e-3))
    state = sim.reset(q0)
    bounds = dict(zip(sim.modules[-1].labels, sim.modules[-1].bounds))
    touched = 0
    for _ in range(400):
        state = sim.step(state)
        touched += bool(sim.last_step.contacts)
        for r in sim.last_step.joint_friction:
            assert abs(r.torque) <= bounds[r.joint] * (1 + 1e-9)
    assert touched > 100


def test_a_quadruped_collapsing_with_friction_in_its_joints_sticks_or_slides_against_them():
    """example-robot-data's go1 (damping and dry friction in its joints) let go with zero torques
    collapses onto the ground, its feet and legs sliding: each step's friction meets Coulomb's law at
    the step's end (a joint within its bound does not move; one at its bound moves against it), and the
    passes settle in nearly every step (they once cycled between two sets of active contact rows and
    spent the 10 QPs a step allows on one step in ten)."""
    import sys

    sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
    from corpus import scene_and_start

    robot = gaussim.load_robot("go1")
    scene, q0 = scene_and_start(robot)
    sim = gaussim.Simulator(scene, gaussim.Options(dt=1e-3))
    state = sim.reset(q0)
    model = sim.model
    index = {name: model.joints[model.getJointId(name)].idx_v for name in sim.modules[-1].labels}
    bound = dict(zip(sim.modules[-1].labels, sim.modules[-1].bounds))
    unsettled, sliding, along = 0, 0, 0
    for _ in range(400):
        state = sim.step(state)
        report = sim.last_step
        unsettled += report.friction_unsettled
        if report.friction_unsettled:
            continue
        for r in report.joint_friction:
            u = state.v[index[r.joint]]
            assert abs(r.torque) <= bound[r.joint] * (1 + 1e-9)
            if r.sliding:  # it moves against the friction
                sliding += 1
                # but where the contacts' rows alone set its speed (no friction changes it) and the
                # contacts' own passes turn it at the last (within their 1e-3 m/s: 5e-3 rad/s at 0.2 m)
                along += u * np.sign(r.torque) > 1e-6
                assert u * np.sign(r.torque) <= 5e-3, (r, u)
            else:
                assert abs(u) <= 2e-5, (r, u)  # it sticks, to what the QPs resolve of its speed
    assert sliding > 500
    assert along <= 0.02 * sliding
    assert unsettled <= 15  # of 400: the passes ran to their cap (a step seen to move u is taken)


def test_the_box_minimum_matches_proxqp_on_random_boxes_singular_ones_included():
    """The friction's box QP (the primal active-set kernel, from a warm start) against ProxQP at a tight
    tolerance: min 1/2 p^T W p + c^T p over |p| <= bound, W positive semi-definite and often singular
    (a joint the active rows hold)."""
    import proxsuite

    from gaussim.constraints.joint_friction import _box_minimum

    rng = np.random.default_rng(7)
    for _ in range(300):
        k = int(rng.integers(1, 13))
        B = rng.normal(size=(k, int(rng.integers(1, k + 1))))
        W = B @ B.T * 10 ** rng.uniform(-3, 6)
        c = rng.normal(size=k) * 10 ** rng.uniform(-6, 0)
        bound = 10 ** rng.uniform(-6, 0, size=k)
        p = _box_minimum(W, c, bound, rng.uniform(-1.2, 1.2, size=k) * bound)
        qp = proxsuite.proxqp.dense.QP(k, 0, k)
        qp.settings.eps_abs, qp.settings.eps_rel, qp.settings.verbose = 1e-14, 0.0, False
        qp.settings.max_iter = 100000
        qp.init(W, c, None, None, np.eye(k), -bound, bound)
        qp.solve()
        reference = np.clip(qp.results.x, -bound, bound)
        ours, theirs = (0.5 * x @ W @ x + c @ x for x in (p, reference))
        assert np.all(np.abs(p) <= bound)
        assert ours <= theirs + 1e-6 * (abs(theirs) + 1e-3 * np.abs(c) @ bound)


@pytest.mark.parametrize("scheme", ["velocity", "acceleration"])
def test_a_joint_resting_on_its_limit_keeps_one_friction_torque_and_sticks(tmp_path, scheme):
    """The pendulum pushed by a tilted gravity onto its upper limit (0.5 rad), friction 0.5 N m: at rest
    the limit holds it, and its friction (any torque within the bound balances it) once flipped between
    +-0.5 N m with the sign of round-off in its speed (1e-13 rad/s), the limit's torque with it. It now
    keeps one value, sticks, and with the limit balances gravity's torque (Pinocchio's)."""
    robot = pendulum(tmp_path, friction=0.5).robot
    gravity = (-G, 0.0, -G)
    scene = gaussim.Scene(robot, joint_friction=True, joint_limits=True, gravity=gravity)
    sim = gaussim.Simulator(scene, gaussim.Options(dt=1e-3, scheme=scheme))
    state = sim.reset(np.array([0.3]))
    torques = []
    model = robot.model.copy()
    model.gravity.linear = np.array(gravity)
    data = model.createData()
    for n in range(1500):
        state = sim.step(state)
        if n >= 1000:
            (friction,) = sim.last_step.joint_friction
            limit = sum(r.torque for r in sim.last_step.reactions("limit"))
            assert not friction.sliding
            weight = pin.computeGeneralizedGravity(model, data, state.q)[0]
            assert friction.torque + limit == pytest.approx(weight, abs=1e-6)
            torques.append(friction.torque)
    assert state.q[0] == pytest.approx(0.5, abs=1e-6)
    assert np.ptp(torques) <= 1e-9
