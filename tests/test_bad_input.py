"""Every bad input gets a clear error that names the cause (one test per class)."""

import numpy as np
import pytest

import gaussim

from .conftest import at_height


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
    with pytest.raises(gaussim.RobotNotFound, match=r"no robot 'solo13'.*known names:.*solo12"):
        gaussim.load_robot("solo13")
    with pytest.raises(gaussim.RobotNotFound, match=r"no robot 'missing.urdf'"):
        gaussim.load_robot("missing.urdf")


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
        ({"arm": ""}, r"mass matrix is not positive definite"),  # a moving body with no inertia
    ],
    ids=[
        "nan-origin",
        "short-size",
        "negative-mass",
        "infinite-mass",
        "joint-type",
        "missing-mesh",
        "no-inertia",
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


def test_the_well_formed_urdf_of_those_loads(tmp_path):
    path = tmp_path / "robot.urdf"
    path.write_text(_URDF.format(**_GOOD))
    assert gaussim.load_robot(path, floating_base=True).model.nv == 7


def test_unknown_frame_and_geometry_list_choices(ball, solo12):
    with pytest.raises(gaussim.FrameNotFound, match=r"no frame 'FL_TOE'.*FL_FOOT"):
        gaussim.Scene(solo12, bilaterals=[gaussim.Anchor("FL_TOE", (0, 0, 0))])
    with pytest.raises(gaussim.GeometryNotFound, match=r"no collision geometry 'FL_TOE_0'.*FL_FOOT_0"):
        gaussim.Scene(solo12, ground=gaussim.Ground(), contacts=[("FL_TOE_0", "ground")])
    with pytest.raises(gaussim.GeometryNotFound, match=r"no obstacle 'table'.*ground"):
        gaussim.Scene(ball, ground=gaussim.Ground(), contacts=[("ball_0", "table")])
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
        ("contact_margin", -1.0),
    ],
)
def test_bad_options_name_the_field(field, value):
    with pytest.raises(gaussim.InvalidOptions, match=rf"^{field}: "):
        gaussim.Options(**{field: value})


def test_unknown_option_lists_known():
    with pytest.raises(gaussim.InvalidOptions, match=r"unknown option; known:.*dt"):
        gaussim.Options().replace(timestep=1e-3)


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


def test_non_convergence_is_reported_or_raised(box):
    """One ProxQP iteration for a box landing while it slides and spins: neither ProxQP nor the
    active set of its iterate solves the step (a box landing straight down, the active set does)."""
    scene = gaussim.Scene(box, ground=gaussim.Ground(friction=0.8))
    strict = gaussim.Simulator(scene, gaussim.Options(max_iter=1))
    q, v = at_height(box, 0.05), np.array([1.0, 0.0, -1.0, 2.0, 0.0, 0.0])
    # the count the advice is about: max_iter caps ProxQP's outer iterations, not all of them
    stopped = "did not converge: PROXQP_MAX_ITER_REACHED after 1 outer iterations, 1 in all"
    with pytest.raises(gaussim.SolverError, match=stopped):
        for _ in range(5):
            strict.step(strict.reset(q, v))
    lenient = gaussim.Simulator(scene, gaussim.Options(max_iter=3, on_failure="report"))
    state = lenient.step(lenient.reset(q, v))
    assert not lenient.last_step.converged
    certificate = lenient.last_step.certificates[-1]
    assert certificate.status == "PROXQP_MAX_ITER_REACHED"
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
