"""Every bad input gets a clear error that names the cause (one test per class)."""

import os
import re
import stat
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import gaussim

from .conftest import at_height

SCENES = Path(__file__).resolve().parents[1] / "robots" / "scenes"


@pytest.fixture
def sim(ball):
    return gaussim.Simulator(gaussim.Scene(ball, ground=gaussim.Ground()))


def test_wrong_shapes(sim, ball):
    with pytest.raises(gaussim.InvalidState, match=r"q must have shape \(7,\)"):
        sim.reset(np.zeros(3))
    with pytest.raises(gaussim.InvalidState, match=r"v must have shape \(6,\)"):
        sim.reset(at_height(ball, 1.0), np.zeros(7))
    state = sim.reset(at_height(ball, 1.0))
    with pytest.raises(gaussim.InvalidState, match=r"tau must have shape \(6,\) or \(0,\)"):
        sim.step(state, np.zeros(2))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_state_and_torque(sim, ball, bad):
    q = at_height(ball, 1.0)
    q[0] = bad
    with pytest.raises(gaussim.InvalidState, match=r"q has non-finite entries at \[0\]"):
        sim.reset(q)
    v = np.zeros(6)
    v[4] = bad
    with pytest.raises(gaussim.InvalidState, match=r"v has non-finite entries at \[4\]"):
        sim.reset(at_height(ball, 1.0), v)
    tau = np.zeros(6)
    tau[2] = bad
    with pytest.raises(gaussim.InvalidState, match=r"tau has non-finite entries at \[2\]"):
        sim.step(sim.reset(at_height(ball, 1.0)), tau)
    with pytest.raises(gaussim.InvalidState, match=r"tau has non-finite entries at \[2\]"):
        sim.full_torque(tau)


def test_non_finite_actuated_torque_names_its_entry(solo12):
    """The torques of a floating robot's actuated joints (nv - 6,) are checked where the dynamics
    read them; the error names the entry of the array the user gave."""
    sim = gaussim.Simulator(gaussim.Scene(solo12))
    state = sim.reset(solo12.configuration("standing"))
    tau = np.zeros(12)
    tau[7] = np.nan
    with pytest.raises(gaussim.InvalidState, match=r"tau has non-finite entries at \[7\]"):
        sim.step(state, tau)
    assert sim.last_step is None
    state = sim.step(state)  # free flight from here on: the next step runs ABA, not CRBA + RNEA
    with pytest.raises(gaussim.InvalidState, match=r"tau has non-finite entries at \[7\]"):
        sim.step(state, tau)


def test_a_non_finite_free_acceleration_at_a_valid_state_is_a_solver_error(solo12, monkeypatch):
    """ABA's answer is checked where the free velocity is made: NaN there (forced: a broken ABA) with
    a finite torque is the dynamics' failure, named as such, not the user's input."""
    from gaussim import dynamics

    sim = gaussim.Simulator(gaussim.Scene(solo12))
    state = sim.step(sim.reset(solo12.configuration("standing")))
    monkeypatch.setattr(dynamics.pin, "aba", lambda *args: np.full(solo12.model.nv, np.nan))
    with pytest.raises(gaussim.SolverError, match="free motion .*ABA.* is not finite"):
        sim.step(state, np.zeros(12))


def test_non_finite_velocity_never_reaches_the_state(sim, ball, monkeypatch):
    """A non-finite free motion (forced here: a broken dynamics stage) stops the step with a
    SolverError; the state given stays valid and no new state is made."""
    from gaussim.dynamics import DynamicsStage

    real = DynamicsStage.free_motion

    def broken(self, *args):
        return np.full_like(real(self, *args), np.nan)

    state = sim.reset(at_height(ball, 1.0))  # free flight: the free motion is the next velocity
    monkeypatch.setattr(DynamicsStage, "free_motion", broken)
    with pytest.raises(gaussim.SolverError, match="non-finite velocity"):
        sim.step(state)
    assert np.isfinite(state.q).all() and sim.last_step is None


def test_non_unit_quaternion(sim, ball):
    q = at_height(ball, 1.0)
    q[3:7] = [0, 0, 0, 2.0]
    with pytest.raises(
        gaussim.InvalidState, match=r"q\[3:7\] of joint 'root_joint' must be a unit quaternion"
    ):
        sim.reset(q)


def test_unknown_robot_lists_choices():
    with pytest.raises(
        gaussim.RobotNotFound, match=r"no robot 'solo13'.*did you mean solo12.*known names:.*solo12"
    ):
        gaussim.load_robot("solo13")
    with pytest.raises(gaussim.RobotNotFound) as caught:
        gaussim.load_robot("no_such_robot_at_all")
    assert str(caught.value).count("double_pendulum,") == 1, "a name of robots/ and example-robot-data, once"
    with pytest.raises(gaussim.RobotNotFound, match=r"^no robot file: no such file: missing.urdf$"):
        gaussim.load_robot("missing.urdf")


def test_a_mistyped_scene_name_is_offered_the_close_ones(capsys):
    code, err = _cli(capsys, "inspect", "box_stak")
    assert (
        code == 2
        and "box_stak: file: cannot read it: No such file or directory (did you mean box_stack?" in err
    )


def test_a_mistyped_file_is_offered_the_files_of_its_kind_in_its_folder(tmp_path):
    """A URDF path with a typo said only "no such file"."""
    robots = Path(__file__).resolve().parents[1] / "robots"
    scene = tmp_path / "s.toml"
    scene.write_text(f'[robot]\nurdf = "{robots / "box_stak.urdf"}"\n')
    with pytest.raises(gaussim.GaussimError) as raised:
        gaussim.load_scene(scene)
    assert str(raised.value) == (
        f"{scene}: robot.urdf: no such file: {robots / 'box_stak.urdf'} (did you mean box_stack.urdf?)"
    )
    with pytest.raises(gaussim.RobotNotFound, match=r"bal.urdf \(did you mean ball.urdf\?\)$"):
        gaussim.load_robot(robots / "bal.urdf")
    with pytest.raises(
        gaussim.RobotNotFound, match=r"no such file: .*robot/ball.urdf \(no folder .*robot\)$"
    ):
        gaussim.load_robot(robots.parent / "robot" / "ball.urdf")


def test_malformed_urdf_names_the_file(tmp_path):
    path = tmp_path / "broken.urdf"
    path.write_text("<robot name='x'><link name='a'>")
    with pytest.raises(gaussim.InvalidRobot, match=r"broken.urdf: not well-formed XML .*line 1"):
        gaussim.load_robot(path)


_URDF = """<?xml version="1.0"?>
<robot name="r">
  <link name="base">
    <inertial>
      <mass value="{mass}"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/>
    </inertial>
    <collision><origin xyz="{origin}"/><geometry>{geometry}</geometry></collision>
  </link>
  <link name="arm">{arm}</link>
  <joint name="j" type="{joint}"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>
"""
_ARM = (
    '<inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>'
)
_GOOD = {
    "mass": "1",
    "origin": "0 0 0",
    "geometry": '<box size="0.1 0.1 0.1"/>',
    "arm": _ARM,
    "joint": "revolute",
}


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"origin": "0 nan 0"}, r"link 'base': <origin xyz> must be 3 finite number\(s\), got '0 nan 0'"),
        ({"geometry": '<box size="0.1 0.1"/>'}, r"link 'base': <box size> must be 3 finite"),
        ({"mass": "-2"}, r"link 'base': negative mass -2"),
        ({"mass": "inf"}, r"link 'base': <mass value> must be 1 finite"),
        ({"joint": "screwy"}, r"joint 'j' has type 'screwy'; known: revolute"),
        (
            {"geometry": '<mesh filename="meshes/foot.stl"/>'},
            r"link 'base': mesh file 'meshes/foot.stl' not found",
        ),
    ],
    ids=[
        "nan-origin",
        "short-size",
        "negative-mass",
        "infinite-mass",
        "joint-type",
        "missing-mesh",
    ],
)
def test_malformed_urdf_names_the_element(tmp_path, change, message):
    """Each fault names the file and the element (urdfdom alone drops a collision whose origin does
    not parse, without an error: that robot fell through the ground)."""
    path = tmp_path / "robot.urdf"
    path.write_text(_URDF.format(**{**_GOOD, **change}))
    with pytest.raises(gaussim.InvalidRobot, match=message) as info:
        gaussim.load_robot(path, floating_base=True)
    assert str(path) in str(info.value)


@pytest.mark.parametrize(
    ("content", "reason"),
    [
        (b"solid x\n facet nonsense 1 2\nendsolid\n", "invalid primitive type"),
        (bytes(range(256)) * 2, "STL storage representation"),
        (b"", "File is empty"),
    ],
    ids=["bad-ascii", "random-bytes", "empty"],
)
def test_corrupt_mesh_names_the_file_and_the_reason(tmp_path, content, reason):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "foot.stl").write_bytes(content)
    path = tmp_path / "robot.urdf"
    path.write_text(_URDF.format(**{**_GOOD, "geometry": '<mesh filename="meshes/foot.stl"/>'}))
    with pytest.raises(
        gaussim.InvalidRobot, match=rf"link 'base': mesh file 'meshes/foot.stl' cannot be read: .*{reason}"
    ):
        gaussim.load_robot(path, floating_base=True)


FLAT = "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0.1 0.1 0\nf 1 2 3\nf 2 4 3\n"  # a square, no thickness
TRIANGLE = "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 1 2 3\n"


@pytest.mark.parametrize(
    ("obj", "reason"),
    [(FLAT, r"its mesh is flat .*give it a thickness"), (TRIANGLE, "its mesh has 3 vertices")],
    ids=["flat", "three-vertices"],
)
def test_a_mesh_without_a_volume_is_named_not_a_crash(tmp_path, obj, reason):
    """coal's convex hull of a flat mesh crashes the process (and of fewer than 4 vertices raises a
    bare ValueError): a URDF's collision mesh and a free body's mesh are refused by name first. A
    subprocess, so that a crash fails the test rather than the suite."""
    (tmp_path / "plate.obj").write_text(obj)
    urdf = tmp_path / "robot.urdf"
    urdf.write_text(_URDF.format(**{**_GOOD, "geometry": '<mesh filename="plate.obj"/>'}))
    script = (
        "import sys, gaussim\n"
        "for load in (lambda: gaussim.load_robot(sys.argv[1], floating_base=True),\n"
        "             lambda: gaussim.FreeBody.mesh('plate', sys.argv[2], mass=1.0)):\n"
        "    try:\n"
        "        load()\n"
        "    except gaussim.GaussimError as err:\n"
        "        print(type(err).__name__, err)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script, str(urdf), str(tmp_path / "plate.obj")],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    robot, body = done.stdout.splitlines()
    assert re.search(rf"InvalidRobot {re.escape(str(urdf))}: collision geometry '.*': {reason}", robot)
    assert re.search(rf"InvalidOptions plate.mesh: .*plate.obj: {reason}", body)


def test_the_well_formed_urdf_of_those_loads(tmp_path):
    path = tmp_path / "robot.urdf"
    path.write_text(_URDF.format(**_GOOD))
    assert gaussim.load_robot(path, floating_base=True).model.nv == 7


def test_unknown_frame_and_geometry_list_choices(ball, solo12):
    with pytest.raises(gaussim.FrameNotFound, match=r"no frame 'FL_TOE'.*FL_FOOT"):
        gaussim.Scene(solo12, bilaterals=[gaussim.Anchor("FL_TOE", (0, 0, 0))])
    with pytest.raises(
        gaussim.GeometryNotFound,
        match=r"no collision geometry 'FL_TOE_0' in the robot \(did you mean FL_FOOT_0",
    ):
        gaussim.Scene(solo12, ground=gaussim.Ground(), contacts=[("FL_TOE_0", "ground")])
    with pytest.raises(gaussim.GeometryNotFound, match=r"no obstacle or collision geometry 'table' in the"):
        gaussim.Scene(ball, ground=gaussim.Ground(), contacts=[("ball_0", "table")])
    with pytest.raises(
        gaussim.GeometryNotFound,
        match=r"no obstacle or collision geometry 'grund' in the scene \(did you mean ground\?\); known: ",
    ):
        gaussim.Scene(solo12, ground=gaussim.Ground(), contacts=[("FL_FOOT_0", "grund")])
    with pytest.raises(gaussim.FrameNotFound, match=r"no configuration 'sitting'.*standing"):
        solo12.configuration("sitting")


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("dt", -1e-3),
        ("dt", 0.0),
        ("dt", np.nan),
        ("scheme", "implicit"),
        ("friction_mode", "cone"),
        ("friction_facets", 2),
        ("friction_facets", 4.0),
        ("stabilisation", 0.0),
        ("eps_abs", -1.0),
        ("max_iter", 0),
        ("on_failure", "ignore"),
        ("solver", "osqp"),
        ("contact_margin", -1.0),
    ],
)
def test_bad_options_name_the_field(field, value):
    with pytest.raises(gaussim.InvalidOptions, match=rf"^{field}: "):
        gaussim.Options(**{field: value})


@pytest.mark.parametrize(("duration", "steps"), [(1e-4, 1), (0.3, 300), (2.0, 2000), (0.0026, 3)])
def test_a_duration_is_the_nearest_whole_number_of_steps_at_least_one(duration, steps):
    """One rule for gaussim run, the examples and the benchmarks: 0.3 / 1e-3 is 299.99999999999994."""
    assert gaussim.Options(dt=1e-3).steps(duration) == steps


def test_a_bad_override_of_a_scene_file_is_the_callers_not_the_files():
    """``load_scene(path, dt=-1)`` blamed the file: ``pendulum_limits.toml: options.dt: ...``."""
    path = SCENES / "pendulum_limits.toml"
    with pytest.raises(gaussim.InvalidOptions, match=r"^dt: must be a finite number > 0, got -1") as caught:
        gaussim.load_scene(path, dt=-1)
    assert "pendulum_limits" not in str(caught.value)
    assert gaussim.load_scene(path, dt=2e-3).options.dt == 2e-3


@pytest.mark.parametrize("duration", [-1.0, 0.0, float("nan"), float("inf"), "1"])
def test_a_bad_duration_set_on_a_spec_is_refused_by_run(duration):
    """``spec.duration = -1`` ran one step, NaN raised numpy's ValueError (tried as a new user would)."""
    spec = gaussim.load_scene(SCENES / "pendulum_limits.toml")
    spec.duration = duration
    with pytest.raises(gaussim.InvalidOptions, match=r"^duration: must be a finite number > 0 \[s\], got"):
        gaussim.run(spec)


def test_unknown_option_lists_known():
    """Made or replaced (``Options(dtt=...)`` raised a bare TypeError: tried as a new user would)."""
    for make in (lambda: gaussim.Options(dtt=1e-3), lambda: gaussim.Options().replace(timestep=1e-3)):
        with pytest.raises(gaussim.InvalidOptions, match=r"^(dtt|timestep): unknown option; known:.*dt"):
            make()


@pytest.mark.parametrize(
    ("field", "kwargs"),
    [
        ("ground.friction", {"friction": -0.1}),
        ("ground.restitution", {"restitution": 1.5}),
        ("ground.normal", {"normal": (0, 0, 0)}),
    ],
)
def test_bad_materials_name_the_field(field, kwargs):
    with pytest.raises(gaussim.InvalidOptions, match=rf"^{field}: "):
        gaussim.Ground(**kwargs)


def test_a_message_echoes_numpy_values_as_the_file_wrote_them(tmp_path):
    """A scene's colour [1, 2, 3, 4, 5] was echoed as "got array([1., 2., 3., 4., 5.])"."""
    scene = tmp_path / "colour.toml"
    scene.write_text(
        '[[bodies]]\nname = "a"\nshape = "sphere"\nradius = 1\nmass = 1\ncolor = [1, 2, 3, 4, 5]\n'
    )
    with pytest.raises(gaussim.GaussimError) as raised:
        gaussim.load_scene(scene)
    assert str(raised.value).endswith(
        "bodies[0].color: must be [r, g, b] or [r, g, b, a] in [0, 1], got [1.0, 2.0, 3.0, 4.0, 5.0]"
    )
    assert gaussim.exceptions.shown(np.zeros(1000)).startswith("array([0., 0."), "a large one stays cut short"


def test_non_convergence_is_reported_or_raised(box, monkeypatch):
    """One ProxQP iteration for a box landing while it slides and spins: neither ProxQP nor the
    active set of its iterate solves the step (a box landing straight down, the active set does).
    With three, the active-set steps from ProxQP's iterate solve it; refused here, as on a problem
    they cannot solve, the step reports ProxQP's iterate."""
    scene = gaussim.Scene(box, ground=gaussim.Ground(friction=0.8))
    strict = gaussim.Simulator(scene, gaussim.Options(max_iter=1, solver="proxqp"))
    q, v = at_height(box, 0.05), np.array([1.0, 0.0, -1.0, 2.0, 0.0, 0.0])
    # the count the advice is about: max_iter caps ProxQP's outer iterations, not all of them
    stopped = "did not converge: PROXQP_MAX_ITER_REACHED after 1 outer iterations, 1 in all"
    with pytest.raises(gaussim.SolverError, match=stopped):
        for _ in range(5):
            strict.step(strict.reset(q, v))
    from gaussim.solver import proxqp

    monkeypatch.setattr(proxqp.active_set_candidate, "call", lambda *args: (0, (np.nan,) * 5))
    lenient = gaussim.Simulator(scene, gaussim.Options(max_iter=3, on_failure="report", solver="proxqp"))
    with pytest.warns(gaussim.GaussimWarning, match="on_failure='report' kept its iterate"):
        state = lenient.step(lenient.reset(q, v))
    assert not lenient.last_step.converged
    certificate = lenient.last_step.certificates[-1]
    assert certificate.status is gaussim.solver.Status.MAX_ITER_REACHED
    assert certificate.outer_iterations == 3 < certificate.iterations
    assert np.all(np.isfinite(state.q))


def test_infeasible_constraints_name_the_rows(ball):
    """A ball anchored 0.5 m below the ground: both cannot hold."""
    scene = gaussim.Scene(ball, ground=gaussim.Ground(), bilaterals=[gaussim.Anchor("ball", (0, 0, -0.5))])
    sim = gaussim.Simulator(scene)
    with pytest.raises(gaussim.InfeasibleConstraints) as info:
        sim.step(sim.reset(at_height(ball, 0.1)))
    assert any(row.startswith("contact ball_0/ground") for row in info.value.rows)
    assert any(row.startswith("anchor ball") for row in info.value.rows)


def test_infeasibility_names_the_rows_held_at_their_bound(pendulum):
    """The pendulum rests against its upper limit (0.5 rad) and its tip is anchored 0.1 m beyond its
    reach along the rod: the closest feasible motion keeps the pendulum still, so the limit holds at
    its bound while the anchor is violated; the report names both."""
    radial = np.array([-np.sin(0.5), 0.0, -np.cos(0.5)])
    anchor = gaussim.Anchor("tip", np.array([0.0, 0.0, 2.0]) + 1.1 * radial)
    sim = gaussim.Simulator(gaussim.Scene(pendulum, joint_limits=True, bilaterals=[anchor]))
    with pytest.raises(gaussim.InfeasibleConstraints) as info:
        sim.step(sim.reset(np.array([0.5])))
    assert "limit hinge upper" in info.value.rows
    assert any(row.startswith("anchor tip") for row in info.value.rows)


# -- issue 19, items 10-16: a clear answer to every bad input ---------------------------------------------

BALL_SCENE = '[robot]\nname = "ball"\nfloating_base = true\n[initial]\nq = [0, 0, 0.5, 0, 0, 0, 1]\n'


def _cli(capsys, *argv):
    """Run ``gaussim argv`` in this process: (exit code, stderr)."""
    from gaussim.cli import main

    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


def test_a_value_after_an_option_that_starts_with_a_minus_is_told_how_to_give_it(tmp_path, capsys):
    """argparse takes "-1e-3" for an option ("expected one argument"): its error says to write
    --dt=-1e-3, which reaches gaussim's own check of the value."""
    from gaussim.cli import EXIT_BAD_INPUT

    with pytest.raises(SystemExit):
        _cli(capsys, "run", "box_stack", "--dt", "-1e-3")
    hint = "expected one argument (if its value starts with '-', write {}=VALUE)"
    assert "argument --dt: " + hint.format("--dt") in capsys.readouterr().err
    with pytest.raises(SystemExit):  # the short form given: the long one in the hint
        _cli(capsys, "plot", tmp_path / "r", "-o", "-energy.png")
    assert "argument -o/--output: " + hint.format("--output") in capsys.readouterr().err
    code, err = _cli(capsys, "run", "box_stack", "--dt=-1e-3", "--out", tmp_path / "r")
    assert code == EXIT_BAD_INPUT, err
    assert "--dt: must be a finite number > 0, got -0.001" in err


@pytest.mark.parametrize(
    ("inertia", "message"),
    [
        ('izz="-1"', r"principal moments of inertia -1, 0.1, 0.1 \[kg m\^2\]: a negative one"),
        (
            'izz="0.3"',
            r"moments of inertia 0.1, 0.1, 0.3 \[kg m\^2\]: I1 \+ I2 < I3.*on_bad_inertia='balance'",
        ),
        ('ixy="0.2"', r"principal moments of inertia -0.1, 0.1, 0.3 \[kg m\^2\]: a negative one"),
    ],
    ids=["negative", "triangle", "indefinite"],
)
def test_an_unphysical_inertia_names_the_link_and_the_file(tmp_path, inertia, message):
    """Item 10: a link with izz = -1 passed the mass-matrix check at the neutral pose and its run gained
    energy; each body's principal moments are checked now (on_bad_inertia='error': the triangle
    inequality refused too)."""
    path = tmp_path / "robot.urdf"
    arm = _ARM.replace(
        inertia.split("=")[0] + '="' + ("0" if inertia.startswith("ixy") else "0.1") + '"', inertia
    )
    path.write_text(_URDF.format(**{**_GOOD, "arm": arm}))
    with pytest.raises(
        gaussim.InvalidRobot, match=rf"{path}: link 'arm' \(the body of joint 'j'\) .*{message}"
    ):
        gaussim.load_robot(path, floating_base=True, on_bad_inertia="error")


def test_a_triangle_inequality_broken_is_balanced_as_mujoco_does(tmp_path):
    """pybullet_data's xarm and mini_cheetah have links whose moments break I1 + I2 >= I3: by default
    the three are set to their mean with a warning naming the link, the moments and the mean, as
    MuJoCo's compiler does with balanceinertia (compared with MuJoCo's own on the same numbers); the
    robot then runs. An unknown option value is refused naming the option."""
    mujoco = pytest.importorskip("mujoco")
    path = tmp_path / "robot.urdf"
    path.write_text(_URDF.format(**{**_GOOD, "arm": _ARM.replace('izz="0.1"', 'izz="0.3"')}))
    with pytest.warns(
        gaussim.GaussimWarning,
        match=r"balanceinertia.*link 'arm' \(the body of joint 'j'\): 0.1, 0.1, 0.3 -> 0.166667",
    ):
        robot = gaussim.load_robot(path, floating_base=True)
    peer = mujoco.MjModel.from_xml_string(
        '<mujoco><compiler balanceinertia="true"/><worldbody><body><freejoint/>'
        '<inertial pos="0 0 0" mass="1" diaginertia="0.1 0.1 0.3"/></body></worldbody></mujoco>'
    )
    np.testing.assert_allclose(robot.model.inertias[2].inertia, np.diag(peer.body_inertia[1]), rtol=1e-12)
    sim = gaussim.Simulator(gaussim.Scene(robot, gravity=(0.0, 0.0, 0.0)))
    state = sim.reset(v=np.array([0, 0, 0, 0.3, 0.2, 0.1, 1.0]))
    for _ in range(100):
        state = sim.step(state)
    assert np.all(np.isfinite(state.v))
    with pytest.raises(gaussim.InvalidOptions, match="on_bad_inertia.*balance, error"):
        gaussim.load_robot(path, floating_base=True, on_bad_inertia="mean")


def test_joint_limits_lower_above_upper_are_no_limit(tmp_path):
    """Item 16: lower > upper made the limit rows infeasible and the solver advised raising max_iter;
    it is Bullet's convention for no limit (issue 22): warned, and unlimited."""
    path = tmp_path / "robot.urdf"
    path.write_text(_URDF.format(**_GOOD).replace('lower="-1" upper="1"', 'lower="1" upper="-1"'))
    with pytest.warns(gaussim.GaussimWarning, match=rf"{path}: the joints 'j' \(1 > -1\).*no limit"):
        robot = gaussim.load_robot(path)
    assert robot.model.lowerPositionLimit[0] == -np.inf and robot.model.upperPositionLimit[0] == np.inf


def test_a_mimic_joint_is_named_in_a_warning(tmp_path):
    """Item 10: <mimic> was ignored without a word (the mimicking joint moves freely)."""
    path = tmp_path / "robot.urdf"
    path.write_text(_URDF.format(**_GOOD).replace("<axis", '<mimic joint="base_joint"/><axis'))
    with pytest.warns(
        gaussim.GaussimWarning, match=rf"{path}: gaussim does not honour <mimic>: .*'j' \(mimics"
    ):
        gaussim.load_robot(path)


@pytest.mark.parametrize(
    ("initial", "obstacle", "where"),
    [
        ("q = [0, 0, 0.05, 0, 0, 0, 1]", "", "'ball_0' 50 mm inside 'ground'"),
        (
            "q = [0, 0, 0.5, 0, 0, 0, 1]",
            "[[obstacles]]\ntype = 'box'\nname = 'table'\nsize = [1, 1, 1]\nposition = [0, 0, 0.05]\n",
            "'ball_0' 150 mm inside 'table'",
        ),
    ],
    ids=["ground", "box"],
)
def test_a_start_inside_an_obstacle_is_refused(tmp_path, capsys, initial, obstacle, where):
    """Item 11: a start 50 mm inside the ground was pushed out at once (kN forces) and the run reported
    'complete'; reset refuses it naming the pair and the depth, unless start_penetration allows it."""
    path = tmp_path / "scene.toml"
    scene = f'[robot]\nname = "ball"\nfloating_base = true\n[initial]\n{initial}\n[ground]\n{obstacle}'
    path.write_text(scene + "[simulation]\nduration = 0.002\n")
    code, err = _cli(capsys, "run", path, "--out", tmp_path / "log.runlog", "--quiet")
    assert code == 2 and f"{path}: the initial configuration has {where}" in err, err
    assert "start_penetration" in err and not (tmp_path / "log.runlog").exists()
    path.write_text(scene + "[options]\nstart_penetration = 0.2\n[simulation]\nduration = 0.002\n")
    assert _cli(capsys, "run", path, "--out", tmp_path / "log.runlog", "--quiet")[0] == 0


def test_a_negative_ground_clearance_is_refused_at_reset(tmp_path, capsys):
    """Item 11: Solo-12 placed 0.5 m into the ground by ground_clearance = -0.5."""
    path = tmp_path / "solo.toml"
    path.write_text(
        '[robot]\nname = "solo12"\n[initial]\nconfiguration = "standing"\nground_clearance = -0.5\n[ground]\n'
    )
    code, err = _cli(capsys, "run", path, "--out", tmp_path / "log.runlog", "--quiet")
    assert code == 2 and re.search(rf"{path}: .*'[FH][LR]_FOOT_0' 500 mm inside 'ground'", err), err


@pytest.mark.parametrize(
    "pairs",
    [[("ball_0", "ground"), ("ball_0", "ground")], [("FL_FOOT_0", "HR_FOOT_0"), ("HR_FOOT_0", "FL_FOOT_0")]],
)
def test_duplicate_contact_pairs_are_refused(ball, solo12, pairs):
    """Item 12: a pair given twice doubled its rows (the summary counted 348 steps in a 200-step run, a
    foot's mean normal force halved); (a, b) and (b, a) are the same pair."""
    robot = ball if pairs[0][0] == "ball_0" else solo12
    with pytest.raises(gaussim.InvalidOptions, match=r"^contacts\[1\]: .* repeats contacts\[0\]"):
        gaussim.Scene(robot, ground=gaussim.Ground(), contacts=pairs)


def test_a_duplicate_pair_in_a_scene_file_is_named_once(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(
        BALL_SCENE + "[ground]\n[contacts]\npairs = [['ball_0', 'ground'], ['ground', 'ball_0']]\n"
    )
    with pytest.raises(
        gaussim.InvalidOptions, match=rf"^{path}: contacts.pairs\[1\]: \(ground, ball_0\) repeats"
    ):
        gaussim.load_scene(path)


def test_a_robot_without_collision_geometry_among_obstacles_is_refused(tmp_path):
    """Item 13: it fell through the ground without a word."""
    path = tmp_path / "robot.urdf"
    path.write_text(
        _URDF.format(**{**_GOOD, "geometry": ""}).replace(
            '<collision><origin xyz="0 0 0"/><geometry></geometry></collision>', ""
        )
    )
    robot = gaussim.load_robot(path, floating_base=True)
    assert robot.collision_model.ngeoms == 0
    with pytest.raises(gaussim.InvalidOptions, match=r"^robot: 'robot' has no collision geometry .* ground"):
        gaussim.Scene(robot, ground=gaussim.Ground())
    gaussim.Scene(robot)  # nothing to touch: fine


def test_complex_and_text_arrays_are_refused(sim, ball):
    """Item 13: a complex tau lost its imaginary part (numpy's ComplexWarning the only word)."""
    state = sim.reset(at_height(ball, 1.0))
    with pytest.raises(gaussim.InvalidState, match=r"tau must hold real numbers, got complex128"):
        sim.step(state, np.zeros(6) + 1j)
    with pytest.raises(gaussim.InvalidState, match=r"q must hold real numbers, got complex128"):
        gaussim.State(0.0, at_height(ball, 1.0) + 0j, np.zeros(6))
    with pytest.raises(gaussim.InvalidState, match=r"v must hold real numbers"):
        gaussim.State(0.0, at_height(ball, 1.0), ["a"] * 6)


def test_state_arrays_cannot_be_made_writable_again(sim, ball):
    """Item 13: a state's arrays could be made writable, changed, and the simulator stepped the state it
    had returned without checking it again."""
    for state in (sim.reset(at_height(ball, 1.0)), sim.step(sim.reset(at_height(ball, 1.0)))):
        for arr in (state.q, state.v):
            with pytest.raises(ValueError, match="cannot set WRITEABLE flag"):
                arr.setflags(write=True)


def test_kept_unconverged_iterates_warn_once_and_flag_the_summary(tmp_path, box):
    """Item 13: on_failure = 'report' with absurd torques returned |v| = 8.5e20 at a KKT residual of 8.9e38
    and the run 'completed'; the solver warns once, the summary flags every such step."""
    path = tmp_path / "box.toml"
    path.write_text(
        '[robot]\nname = "box"\nfloating_base = true\n[initial]\nq = [0, 0, 0.05, 0, 0, 0, 1]\n'
        "v = [1.0, 0.0, -1.0, 2.0, 0.0, 0.0]\n[ground]\n[options]\nmax_iter = 1\non_failure = 'report'\n"
        "solver = 'proxqp'\n"
        "[simulation]\nduration = 0.005\n"
    )
    with pytest.warns(gaussim.GaussimWarning, match="on_failure='report' kept its iterate") as caught:
        log = gaussim.run(gaussim.load_scene(path))
    assert len([w for w in caught if "kept its iterate" in str(w.message)]) == 1
    assert re.search(
        r"^status: complete, with 1 warning\(s\)\nWARNING: \d+ steps did not converge", log.summary(), re.M
    )


def test_a_coarse_run_is_flagged_by_its_summary():
    """Item 14: the acceleration scheme at dt 0.1 sank a ball 88 mm and its summary said nothing."""
    spec = gaussim.load_scene(SCENES / "ball_bounce.toml", dt=0.1, scheme="acceleration")
    log = gaussim.run(spec)
    depth = -log.contact_arrays()["gap"].min()
    assert depth > gaussim.runlog.PENETRATION_TOLERANCE
    assert f"WARNING: contacts sank {1e3 * depth:.4g} mm, more than 1 mm: dt = 0.1 s" in log.summary()
    fine = gaussim.load_scene(SCENES / "ball_bounce.toml", dt=1e-3)
    fine.duration = 0.6  # past the first landing, at 0.45 s
    fine = gaussim.run(fine)
    assert len(fine.contact_arrays()["gap"]) and "WARNING" not in fine.summary() and fine.warnings() == []


TRACEBACKS = [  # item 15: each of these leaked a Python traceback with exit 1
    ("[robot]\nname = 12\n", "robot.name", "must be a string"),
    ("[robot]\nurdf = 12\n", "robot.urdf", "must be a string"),
    ('[robot]\nname = "ball"\npackage_dirs = 5\n', "robot.package_dirs", "list of folder names"),
    ('[robot]\nname = "ball"\npackage_dirs = "meshes"\n', "robot.package_dirs", "list of folder names"),
    (BALL_SCENE + '[ground]\nheight = "x"\n', "ground.height", r"must be a finite number \[m\], got 'x'"),
    (BALL_SCENE + '[ground]\nnormal = "up"\n', "ground.normal", "must be 3 finite numbers"),
    (
        BALL_SCENE + "[[obstacles]]\ntype = 'sphere'\nname = 's'\nradius = 'big'\n",
        r"obstacles\[0\].radius",
        "finite",
    ),
    (BALL_SCENE + "[ground]\n[contacts]\npairs = [[1, 2]]\n", r"contacts.pairs\[0\]", "two names"),
    (BALL_SCENE + "[options]\nmax_iter = 1e20\n", "options.max_iter", "must be an integer"),
    (BALL_SCENE + "[options]\nmax_iter = 100000000000000000000\n", "options.max_iter", "must be an integer"),
    (BALL_SCENE + "[options]\ndt = 1" + "0" * 400 + "\n", "options.dt", "must be a finite number > 0"),
    (BALL_SCENE + "[ground]\nfriction = 1" + "0" * 400 + "\n", "ground.friction", "must be a finite number"),
    (BALL_SCENE.replace("0.5", "1" + "0" * 400), "initial.q", "must be 7 finite numbers"),
    (BALL_SCENE + "[[obstacles]]\ntype = 'box'\nsize = [1, 1, 1]\n", r"obstacles\[0\].name", "missing"),
    (
        BALL_SCENE + "[[bilaterals]]\ntype = 'loop'\nframes = ['ball', 'ball']\norientation = 'no'\n",
        r"bilaterals\[0\].orientation",
        "must be true or false",
    ),  # item 13: was read as true
    (BALL_SCENE + "[ground]\nfriction = 1e300\n", "ground.friction", "beyond any material"),  # item 16
    (
        "[robot]\nname = 'pendulum'\n[control]\ntype = 'constant'\ntau = [1e300]\n",
        "control.tau",
        "beyond any actuator",
    ),
    (
        BALL_SCENE + "[[bilaterals]]\ntype = 'anchor'\nframe = 'nose'\nposition = [0, 0, 1]\n",
        r"bilaterals\[0\].frame",
        "no frame 'nose'",
    ),  # item 16: was labelled contacts
]


@pytest.mark.parametrize(("text", "key", "message"), TRACEBACKS, ids=[f"{i}" for i in range(len(TRACEBACKS))])
def test_a_malformed_scene_exits_2_naming_the_file_and_key(tmp_path, capsys, text, key, message):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    code, err = _cli(capsys, "inspect", path)
    assert code == 2 and re.fullmatch(rf"gaussim: {path}: {key}: .*{message}.*\n", err, re.S), err
    assert err.count("\n") == 1  # one paragraph


@pytest.mark.parametrize("content", [b"\xff\xfe\x00binary", "name = 'caf\u00e9'".encode("latin-1")])
def test_a_non_utf8_scene_file_is_named(tmp_path, capsys, content):
    path = tmp_path / "scene.toml"
    path.write_bytes(content)
    code, err = _cli(capsys, "inspect", path)
    assert code == 2 and f"{path}: file: not a UTF-8 text file" in err


def test_an_infinite_duration_is_refused(tmp_path, capsys):
    path = tmp_path / "scene.toml"
    path.write_text(BALL_SCENE)
    code, err = _cli(capsys, "run", path, "--duration", "inf")
    assert code == 2 and "--duration: must be a finite number > 0, got inf" in err


@pytest.fixture(scope="module")
def small_log(tmp_path_factory):
    """A 3-step run log of a falling ball, and its arrays."""
    folder = tmp_path_factory.mktemp("log")
    (folder / "scene.toml").write_text(BALL_SCENE + "[ground]\n[simulation]\nduration = 0.003\n")
    path = gaussim.run(gaussim.load_scene(folder / "scene.toml"), folder / "run").save(folder / "log.npz")
    with np.load(path) as f:
        return path, {k: f[k] for k in f.files}


LOG_FAULTS = {  # item 15: each leaked a traceback; item 16: format_version was never read
    "missing-key": ({"q": None}, "damaged run log: no array 'q'"),
    "bad-json": ({"options": np.array("{dt: 1")}, "options: not JSON"),
    "unknown-option": (
        {"options": np.array('{"timestep": 1}')},
        "options.timestep: unknown option; known: active_tolerance",
    ),
    "bad-option": ({"options": np.array('{"dt": -1}')}, "options.dt: must be a finite number > 0"),
    "wrong-shape": ({"v": np.zeros((4, 2))}, "'tau' has shape (3, 6), where 'v' has nv = 2"),
    "wrong-kind": ({"t": np.array(["a", "b", "c", "d"])}, "'t' is a 1-d <U1 array, not the 1-d float array"),
    "bad-ids": (
        {
            "contact_step": np.array([0]),
            "contact_id": np.array([5]),
            **{f"contact_{k}": np.zeros((1, 3)) for k in ("point", "normal", "force")},
            "contact_gap": np.zeros(1),
        },
        "'contact_id' refers to entries not in 'contact_names'",
    ),
    "wrong-length": ({"solver_qps": np.zeros(9, int)}, "'solver_qps' has shape (9,), where 't' has N = 3"),
    "no-bodies": ({"contact_body": None}, "damaged run log: no array 'contact_body'"),
    "bodies-kind": ({"bodies": np.array("ball")}, "'bodies' is a 0-d <U4 array, not the 1-d text array"),
    "sides": (
        {"contact_other": np.array(["ground"])},
        "'contact_other' has shape (1,), where 'contact_names'",
    ),
    "newer": (
        {"format_version": np.array(3)},
        "format_version 3 is newer than this gaussim reads (it reads formats 1 to 2); upgrade",
    ),
    "unknown-version": ({"format_version": np.array("one")}, "format_version 'one' is unknown"),
}


@pytest.mark.parametrize("fault", LOG_FAULTS)
def test_a_tampered_log_exits_2_naming_the_file_and_array(tmp_path, capsys, small_log, fault):
    changes, message = LOG_FAULTS[fault]
    arrays = {k: v for k, v in {**small_log[1], **changes}.items() if v is not None}
    path = tmp_path / "log.npz"
    np.savez(path, **arrays)
    code, err = _cli(capsys, "forces", path, "--csv", tmp_path / "f.csv")
    assert code == 2 and f"gaussim: {path}: " in err and message in err, err


@pytest.mark.parametrize("damage", ["truncated", "flipped", "text", "npy", "pickle"])
def test_a_damaged_or_foreign_file_is_no_log(tmp_path, capsys, small_log, damage):
    """Item 16: a non-log file was told to use allow_pickle (which would run what a pickle holds)."""
    raw = small_log[0].read_bytes()
    path = tmp_path / "log.npz"
    if damage == "truncated":
        path.write_bytes(raw[: len(raw) // 2])
    elif damage == "flipped":
        path.write_bytes(raw[:2000] + bytes(b ^ 0xFF for b in raw[2000:2100]) + raw[2100:])
    elif damage == "text":
        path.write_text("hello\n")
    else:
        with path.open("wb") as f:
            np.save(
                f, np.zeros(3) if damage == "npy" else np.array([{"a": 1}], dtype=object), allow_pickle=True
            )
    for command in (
        ["forces", path, "--csv", tmp_path / "f.csv"],
        ["replay", path, "--html", tmp_path / "r.html"],
    ):
        code, err = _cli(capsys, *command)
        assert code == 2 and f"gaussim: {path}: " in err and "allow_pickle" not in err, err


def test_unwritable_outputs_exit_2_naming_the_path(tmp_path, capsys, small_log):
    """Item 15: CSV, PNG and HTML outputs that cannot be written leaked tracebacks; item 16: a --plot path
    without a format's suffix was written elsewhere (matplotlib adds .png) than reported."""
    log = small_log[0]
    (tmp_path / "folder.png").mkdir()
    code, err = _cli(capsys, "forces", log, "--csv", tmp_path)
    assert code == 2 and f"--csv {tmp_path}: is a directory" in err, err
    code, err = _cli(capsys, "plot", log, "-o", tmp_path / "folder.png")
    assert code == 2 and f"--output {tmp_path / 'folder.png'}: is a directory" in err, err
    code, err = _cli(capsys, "replay", log, "--html", tmp_path)
    assert code == 2 and f"--html {tmp_path}: is a directory" in err, err
    code, err = _cli(capsys, "plot", log, "-o", tmp_path / "forces")
    assert code == 2 and f"--output {tmp_path / 'forces'}: the image's suffix must be one of .png, " in err
    scene = tmp_path / "scene.toml"
    scene.write_text(BALL_SCENE)
    code, err = _cli(capsys, "run", scene, "--plot", tmp_path / "forces", "--out", tmp_path / "l.runlog")
    assert code == 2 and not (tmp_path / "l.runlog").exists(), "refused before the run"
    assert f"--plot {tmp_path / 'forces'}: the image's suffix" in err, "the flag named, as --html's is"


def test_echoed_values_are_cut_to_a_line(tmp_path, capsys):
    """Item 16: an 8-million-element value was echoed back as 40 MB."""
    path = tmp_path / "scene.toml"
    path.write_text(BALL_SCENE.replace("q = [0, 0, 0.5, 0, 0, 0, 1]", "q = [" + "0, " * 100_000 + "1]"))
    code, err = _cli(capsys, "inspect", path)
    assert code == 2 and "initial.q: must be 7 finite numbers, got [0, 0, 0, 0, 0, 0, 0, 0, ...]" in err
    assert len(err) < 300
    with pytest.raises(gaussim.InvalidOptions) as info:
        gaussim.Options(dt=list(range(8_000_000)))
    assert len(str(info.value)) < 200


def test_numpy_integers_are_integers():
    """Item 16: numpy integers were refused where ints are asked; kept as Python's (a run log's JSON)."""
    options = gaussim.Options(max_iter=np.int64(50), friction_facets=np.int32(8), dt=np.float32(0.5))
    assert (options.max_iter, options.friction_facets, options.dt) == (50, 8, 0.5)
    assert type(options.max_iter) is int and type(options.dt) is float


def test_terminal_escape_codes_are_printed_escaped(tmp_path, capsys):
    """Item 16: a name holding escape codes was printed raw (it could clear the terminal)."""
    path = tmp_path / "scene.toml"
    path.write_text(BALL_SCENE + '[ground]\n[contacts]\npairs = [["ball_0", "\\u001b[2Jwall"]]\n')
    code, err = _cli(capsys, "inspect", path)
    assert code == 2 and "\x1b" not in err and r"'\x1b[2Jwall'" in err, err


def test_a_log_follows_the_umask(tmp_path, small_log):
    """Item 16: logs were written 0600 (mkstemp's) while every other output follows the umask."""
    mask = os.umask(0o027)
    try:
        path = gaussim.RunLog.load(small_log[0]).save(tmp_path / "log.npz")
    finally:
        os.umask(mask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o640


def test_ctrl_c_before_the_first_step_writes_no_log(tmp_path, capsys, monkeypatch):
    """Item 16: a Ctrl-C while the scene loaded claimed 'the log of the steps made was written'."""
    import gaussim.runner

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    path = tmp_path / "scene.toml"
    path.write_text(BALL_SCENE)
    monkeypatch.setattr(gaussim.runner, "run", interrupted)
    code, err = _cli(capsys, "run", path, "--out", tmp_path / "log.runlog")
    assert code == 1 and "interrupted; no log written" in err and not (tmp_path / "log.runlog").exists()


DIRECTORY_FAULTS = {  # the run log directory (header.json and its chunks), as LOG_FAULTS for the .npz
    "newer": (
        lambda h, c: {**h, "format_version": 4},
        None,
        "format_version 4 is newer than this gaussim reads (it reads formats 2 to 3)",
    ),
    "bodies": (lambda h, c: {**h, "bodies": "solo"}, None, "'bodies' must be a list of body names"),
    "robot": (lambda h, c: {**h, "robot": 12}, None, "'robot' must be a str, got 12"),
    "options": (lambda h, c: {**h, "options": {"timestep": 1}}, None, "options.timestep: unknown option"),
    "not-options": (lambda h, c: {**h, "options": [1]}, None, "options: must be a JSON object"),
    "shape": (None, {"v": np.zeros((4, 2))}, "damaged run log: 'v' has shape (4, 2)"),
    "missing": (None, {"q": None}, "damaged run log: no array 'q'"),
}


@pytest.mark.parametrize("fault", DIRECTORY_FAULTS)
def test_a_tampered_log_directory_exits_2_naming_the_file(tmp_path, capsys, fault):
    import json

    header_change, chunk_change, message = DIRECTORY_FAULTS[fault]
    (tmp_path / "scene.toml").write_text(BALL_SCENE + "[ground]\n[simulation]\nduration = 0.003\n")
    path = tmp_path / "run"
    gaussim.run(gaussim.load_scene(tmp_path / "scene.toml"), path)
    if header_change is not None:
        header = json.loads((path / "header.json").read_text())
        (path / "header.json").write_text(json.dumps(header_change(header, None)))
    if chunk_change is not None:
        for chunk in sorted(path.glob("chunk-*.npz"))[1:]:
            chunk.unlink()  # the log is then the first chunk's steps
        with np.load(path / "chunk-000000.npz") as f:
            arrays = {k: f[k] for k in f.files}
        arrays = {k: v for k, v in {**arrays, **chunk_change}.items() if v is not None}
        np.savez(path / "chunk-000000.npz", **arrays)
    code, err = _cli(capsys, "forces", path, "--csv", tmp_path / "f.csv")
    assert code == 2 and f"gaussim: {path}" in err and message in err, err


def test_absurd_torques_are_named_as_the_cause_not_the_solver_settings(solo12):
    """Item 16: tau = 1e12 on Solo-12's feet against the ground stopped ProxQP at its cap, and the error
    advised raising max_iter, which cannot help."""
    sim = gaussim.Simulator(gaussim.Scene(solo12, ground=gaussim.Ground()))
    q = solo12.configuration("standing")
    q[2] = 0.24
    with pytest.raises(gaussim.SolverError) as info:
        state = sim.reset(q)
        for _ in range(5):
            state = sim.step(state, np.full(12, 1e12))
    assert "check the inputs" in str(info.value) and "max_iter" not in str(info.value)


@pytest.mark.parametrize(
    ("args", "told"),
    [
        (
            ["--dt", "1", "--duration", "0.1"],
            "the duration 0.1 s is shorter than one step of dt = 1 s: the run takes 1 step, 1 s",
        ),
        (
            ["--dt", "0.03", "--duration", "0.1"],
            "the duration 0.1 s is not a whole number of steps of dt = 0.03 s: the run takes 3 steps, 0.09 s",
        ),
    ],
    ids=["shorter than dt", "not a multiple of dt"],
)
def test_a_duration_the_steps_cannot_make_is_told(tmp_path, capsys, args, told):
    """--dt 1 --duration 0.1 simulated 1 s, ten times the time asked for, and --dt 0.03 --duration 0.1
    0.09 s, without a word: the run says what it simulates instead (the command prints it as
    ``gaussim: warning: ...``), before it starts."""
    with pytest.warns(gaussim.GaussimWarning, match=re.escape(told)):
        code, err = _cli(capsys, "run", "pendulum_limits", *args, "--out", tmp_path / "r", "--quiet")
    assert code == 0, err
    spec = gaussim.load_scene("pendulum_limits", dt=1e-3)
    spec.duration = 0.3  # 0.3 / 1e-3 is 299.99999999999994: 300 steps, no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error", gaussim.GaussimWarning)
        assert gaussim.run(spec).steps == 300
    spec.duration = 0.0004
    with pytest.warns(gaussim.GaussimWarning, match="the run takes 1 step, 0.001 s"):
        assert gaussim.run(spec).steps == 1


def test_the_reactions_of_a_family_the_simulator_does_not_pose_are_refused_by_name(sim, ball):
    """report.reactions("contacts") returned [] where report.reactions("contact") held the ball's
    weight: a misspelt family read as a step without reactions. gaussim's own families answer in any
    scene (no limit rows: no limit reaction)."""
    sim.step(sim.reset(at_height(ball, 0.1)))
    report = sim.last_step
    assert np.allclose(sum(c.force for c in report.reactions("contact")), [0.0, 0.0, 9.81])
    assert report.reactions("limit") == [] and report.reactions("bilateral") == []
    with pytest.raises(
        gaussim.InvalidOptions,
        match=r"no constraint family 'contacts' in this simulator "
        r"\(did you mean contact\?\); its families: bilateral, contact, joint_friction, limit",
    ):
        report.reactions("contacts")


def test_a_run_log_named_npz_is_refused_before_the_run(tmp_path, capsys):
    """gaussim run ... --out x.npz made a folder named x.npz (a run log is a folder of chunks), where a
    user expects one .npz file, as RunLog.save writes: refused before the run, naming both ways."""
    from gaussim.cli import EXIT_BAD_INPUT

    out = tmp_path / "x.npz"
    code, err = _cli(capsys, "run", "pendulum_limits", "--duration", "0.01", "--out", out, "--quiet")
    assert code == EXIT_BAD_INPUT and not out.exists(), err
    folder = tmp_path / "x.runlog"
    assert f"--out: {out}: a run log is a folder of chunks written as the run goes" in err, err
    assert f"name it without .npz (e.g. {folder})" in err
    assert f"gaussim.RunLog.load('{folder}').save('{out}')" in err
    code, err = _cli(capsys, "run", "pendulum_limits", "--duration", "0.01", "--out", folder, "--quiet")
    assert code == 0 and gaussim.RunLog.load(gaussim.RunLog.load(folder).save(out)).steps == 10, err


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (
            lambda ball: gaussim.Simulator(ball),
            r"scene: must be a gaussim.Scene, got Robot\(.*gaussim.Scene\(robot",
        ),
        (
            lambda ball: gaussim.Simulator(gaussim.Scene(ball), {"dt": 1e-3}),
            r"options: must be a gaussim.Options or None, got \{'dt': 0.001\}: gaussim.Options\(\*\*fields\)",
        ),
        (lambda ball: gaussim.Scene(ball, ground=True), "ground: must be a gaussim.Ground or None, got True"),
        (
            lambda ball: gaussim.Scene(ball, obstacles=gaussim.Box("b", (1, 1, 1), (0, 0, 2))),
            r"obstacles: must be a list of gaussim.Box and gaussim.Sphere, got one: give \[Box\(",
        ),
        (
            lambda ball: gaussim.Scene(ball, obstacles=[gaussim.Ground()]),
            r"obstacles\[0\]: must be one of gaussim.Box and gaussim.Sphere, got Ground\(",
        ),
        (
            lambda ball: gaussim.Scene(ball, bilaterals=gaussim.Anchor("ball", (0, 0, 1))),
            r"bilaterals: must be a list of gaussim.Anchor and gaussim.LoopClosure, got one",
        ),
        (lambda ball: gaussim.load_robot(12), r"name: must be a robot's name or a file's path, got 12"),
        (
            lambda ball: gaussim.load_scene(None),
            "path: must be a scene file's path or a shipped scene's name",
        ),
    ],
    ids=[
        "robot as scene",
        "dict as options",
        "ground",
        "one obstacle",
        "ground as obstacle",
        "one anchor",
        "robot int",
        "scene None",
    ],  # fmt: skip
)
def test_an_argument_of_the_wrong_type_is_refused_naming_it(ball, call, message):
    """Simulator(robot) raised AttributeError: 'Robot' object has no attribute 'world'; Scene(ground=True)
    'bool' object has no attribute 'name'; obstacles=Box(...) "'Box' object is not iterable";
    load_robot(12) a TypeError of pathlib: each now names the argument and what it takes."""
    with pytest.raises(gaussim.InvalidOptions, match=message):
        call(ball)
