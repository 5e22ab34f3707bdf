"""The kernels the build compiles ahead (gaussim.kernels.prebuild): the signatures it compiles are the
ones every shipped scene and each primitive pair family call, and its signature codes read back as written."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

import gaussim.kernels.bound as bound_module
from gaussim.kernels.bound import Bound
from gaussim.kernels.prebuild import SIGNATURES, code_of, kernel, parse

# What the build's kernels must cover: every shipped scene for 50 ms (the main job in both schemes), and a
# free body of each primitive shape touching another, a fixed box or the ground (several bodies: islands).
WORKLOAD = """
import numpy as np
import pinocchio as pin
import gaussim
from gaussim import FreeBody
from gaussim.robot import ROBOTS_DIR

for path in sorted((ROBOTS_DIR / "scenes").glob("*.toml")):
    for scheme in ("velocity", "acceleration") if path.stem == "solo12_standing" else (None,):
        spec = gaussim.load_scene(path, **({"scheme": scheme} if scheme else {}))
        spec.duration = 0.05
        gaussim.run(spec)
# every primitive shape as a free body, each touching another or the ground, on a fixed box
bodies = {
    "box": FreeBody.box("box", (0.1, 0.1, 0.1), mass=1.0),
    "ball": FreeBody.sphere("ball", 0.05, mass=1.0),
    "capsule": FreeBody.capsule("capsule", 0.03, 0.2, mass=1.0),
    "cylinder": FreeBody.cylinder("cylinder", 0.05, 0.1, mass=1.0),
}
poses = {
    "box": pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.1505])),  # on the table's top
    "ball": pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.2515])),  # on the box
    "capsule": pin.SE3(pin.rpy.rpyToMatrix(np.pi / 2, 0, 0), np.array([0.4, 0.0, 0.0305])),  # lying
    "cylinder": pin.SE3(np.eye(3), np.array([0.4, 0.3, 0.0505])),  # standing
}
table = gaussim.Box("table", (0.3, 0.3, 0.1), position=(0.0, 0.0, 0.05))
scene = gaussim.Scene(bodies=bodies, ground=gaussim.Ground(), obstacles=[table])
sim = gaussim.Simulator(scene)
state = sim.reset(poses)
for _ in range(100):
    state = sim.step(state)
assert len(sim.last_step.contacts) >= 8, sim.last_step.contacts
"""

# The workload, with every call of a kernel from Python (the stage modules' names) written down as
# prebuild's code of its argument types.
CALLED = (
    """
import importlib
import numba
from numba.core.registry import CPUDispatcher
from gaussim.kernels.bound import Bound
from gaussim.kernels.prebuild import code_of

def recording(name, dispatcher):
    def call(*args):
        print(name, "=", code_of(tuple(numba.typeof(a) for a in args)))
        return dispatcher(*args)
    return call

STAGES = ("actuation", "assembly", "collision.boxes", "collision.cylinders", "collision.ground",
          "collision.driver", "collision.margin", "collision.narrow", "collision.primitives",
          "constraints.base", "constraints.limits",
          "constraints.contact", "dynamics", "integrator", "solver.active_set", "solver.certificate",
          "solver.dual", "solver.islands", "solver.proxqp", "solver.reactions")
for stage in STAGES:
    module = importlib.import_module("gaussim." + stage)
    for attribute, value in list(vars(module).items()):
        if isinstance(value, CPUDispatcher) and value.py_func.__module__.startswith("gaussim.kernels."):
            kernel = value.py_func.__module__.rsplit(".", 1)[1] + "." + value.py_func.__name__
            setattr(module, attribute, recording(kernel, value))
        elif isinstance(value, Bound):  # each call through the dispatcher, recorded
            value.call = recording(value.name, value.dispatcher)
"""
    + WORKLOAD
)


@pytest.mark.parametrize("name", sorted(SIGNATURES))
def test_a_signature_code_reads_back_as_written(name):
    for code in SIGNATURES[name]:
        assert code_of(parse(code)) == code
    assert kernel(name).py_func.__module__ == f"gaussim.kernels.{name.split('.')[0]}"


def test_the_build_compiles_every_signature_the_workload_calls():
    """A signature left out compiles at the first run (a kernel called with a read-only array where it
    took a writable one is another signature); the wheel's test runs the workload without compiling."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    result = subprocess.run(
        [sys.executable, "-c", CALLED], capture_output=True, text=True, timeout=900, cwd=root
    )
    assert result.returncode == 0, result.stderr
    called = {tuple(line.split(" = ")) for line in result.stdout.splitlines() if " = " in line}
    families = {"boxes.box_pairs", "primitives.primitive_pairs", "cylinders.ground_cylinders"}
    assert {name for name, _ in called} >= {
        "contact.pyramids",
        "solver.islands",
        "dual.dual_iterations",
        "solver.least_norm",
        *families,
    }, called
    missing = sorted((name, code) for name, code in called if code not in SIGNATURES.get(name, ()))
    assert not missing, missing


def _move_bases_arguments(q_order: str = "C") -> tuple:
    """move_bases' arguments for one free body turned about z: (q, q_next, v, dt, configuration, velocity)."""
    q = np.array([0.1, 0.2, 0.3, 0.0, 0.0, np.sin(0.2), np.cos(0.2)], order=q_order)
    return q, q + 0.0, np.array([1.0, -2.0, 0.5, 0.0, 0.0, 3.0]), 0.01, np.array([0]), np.array([0])


def test_a_bound_kernel_calls_the_overload_its_first_call_fits_past_the_dispatcher(monkeypatch):
    """In a run (checks off) the bound call is numba's compiled entry point itself, with the answer
    of the dispatcher, for the first call's arguments and for later ones (read-only ones too)."""
    monkeypatch.setattr(bound_module, "CHECK", False)
    kernel = Bound("integrator.move_bases")
    expected = _move_bases_arguments()
    kernel.dispatcher(*expected)
    arguments = _move_bases_arguments()
    kernel.call(*arguments)
    assert type(kernel.call).__name__ == "builtin_function_or_method"  # no Python frame, no typing
    np.testing.assert_array_equal(arguments[1], expected[1])
    np.testing.assert_array_equal(arguments[2], expected[2])
    again = _move_bases_arguments()
    again[0].setflags(write=False)
    kernel.call(*again)
    np.testing.assert_array_equal(again[1], expected[1])


def test_a_bound_kernel_under_the_check_refuses_arguments_of_other_types():
    """The test suite's setting (conftest): a call whose arguments would need another overload (another
    dtype, rank or memory order) raises TypeError naming the kernel instead of reading its memory
    wrongly; one that differs in read-only flags alone runs."""
    assert bound_module.CHECK
    kernel = Bound("integrator.move_bases")
    kernel.call(*_move_bases_arguments())
    q, q_next, v, dt, configuration, velocity = _move_bases_arguments()
    with pytest.raises(TypeError, match="kernel integrator.move_bases bound to"):
        kernel.call(q, q_next, v.astype(np.float32), dt, configuration, velocity)
    with pytest.raises(TypeError, match="int32"):
        kernel.call(q, q_next, v, dt, configuration.astype(np.int32), velocity)
    with pytest.raises(TypeError):
        kernel.call(q, q_next, v[::2], dt, configuration, velocity)  # not contiguous
    with pytest.raises(TypeError):
        kernel.call(q, q_next, v, 1, configuration, velocity)  # an int where a float goes
    q.setflags(write=False)
    kernel.call(q, q_next, v, dt, configuration, velocity)


def test_a_bound_kernel_takes_the_first_declared_memory_order_a_matrix_of_both_fits():
    """mirrored is declared for Pinocchio's column-major M first, then for C order: a 1 x 1 matrix is
    both, and binds the column-major overload, which then answers for any column-major M and refuses
    a C-ordered one (under the check; which a run's call sites never pass it)."""
    kernel = Bound("dynamics.mirrored")
    out = np.zeros((1, 1))
    kernel.call(np.ones((1, 1)), np.array([1]), out)
    assert out[0, 0] == 1.0
    upper = np.asfortranarray(np.triu(np.arange(9.0).reshape(3, 3)))
    M = np.zeros((3, 3))
    kernel.call(upper, np.array([3, 2, 1]), M)
    np.testing.assert_array_equal(M, np.triu(upper) + np.triu(upper, 1).T)
    with pytest.raises(TypeError, match="dynamics.mirrored"):
        kernel.call(np.ascontiguousarray(upper), np.array([3, 2, 1]), M)


def test_a_call_that_fits_no_declared_signature_leaves_the_kernel_to_the_dispatcher(monkeypatch):
    """In a run, arguments the build declared no signature for (integer matrices where floats go) are
    typed by numba at each call, as without the binding; under the check they raise, so that a test
    sees a call site whose types the build does not cover."""
    with pytest.raises(TypeError, match="no declared signature"):
        Bound("dynamics.mirrored").call(np.eye(3, dtype=int), np.array([3, 2, 1]), np.eye(3, dtype=int))
    monkeypatch.setattr(bound_module, "CHECK", False)
    kernel = Bound("dynamics.mirrored")
    upper, M = np.triu(np.arange(9).reshape(3, 3)), np.zeros((3, 3), dtype=np.int64)
    kernel.call(upper, np.array([3, 2, 1]), M)
    np.testing.assert_array_equal(M, np.triu(upper) + np.triu(upper, 1).T)
    assert kernel.call is kernel.dispatcher


def test_arrays_of_a_users_making_reach_the_bound_kernels_as_the_kernels_read_them():
    """The kernels are bound to C-ordered floats; a user's torque and damping may be strided views, a
    GaussProblem of a user's making (or a module's rows) column-major, as np.load gives back a
    Fortran array, or of integers: each step and answer is the one of C-ordered float copies."""
    import gaussim
    from gaussim.assembly import GaussProblem
    from gaussim.solver import GaussSolver

    robot = gaussim.load_robot("double_pendulum")
    sim, other = gaussim.Simulator(gaussim.Scene(robot)), gaussim.Simulator(gaussim.Scene(robot))
    wide = np.array([[0.3, 9.0], [-0.2, 9.0]]).ravel()  # the torque in every other entry
    import pinocchio as pin

    strided = copied = sim.reset(pin.neutral(robot.model), np.array([0.5, -0.2]))
    damping = np.array([[0.1, 9.0], [0.2, 9.0]]).ravel()
    for k in range(20):  # the first step's arrays C-ordered (they bind the kernels), then strided
        given = (wide[::2], damping[::2]) if k else (wide[::2].copy(), damping[::2].copy())
        strided = sim.step(strided, *given)  # damped: the torque meets a kernel
        copied = other.step(copied, wide[::2].copy(), damping[::2].copy())
    np.testing.assert_array_equal(strided.q, copied.q)

    rng = np.random.default_rng(4)
    root = rng.normal(size=(4, 4))
    H, g, C, l = (
        root @ root.T + 4 * np.eye(4),
        rng.normal(size=4),
        rng.normal(size=(3, 4)),
        rng.normal(size=3),
    )
    none = (np.zeros((0, 4)), np.zeros(0))
    expected = GaussSolver(gaussim.Options()).solve(GaussProblem(H, g, *none, C, l, []))
    answer = GaussSolver(gaussim.Options()).solve(
        GaussProblem(np.asfortranarray(H), g, *none, np.asfortranarray(C), l, [])
    )
    np.testing.assert_allclose(answer.x, expected.x, atol=1e-12)
    integral = GaussSolver(gaussim.Options()).solve(
        GaussProblem(
            np.eye(2, dtype=int), np.array([1, -1]), np.zeros((0, 2)), np.zeros(0), np.eye(2), np.zeros(2), []
        )
    )
    np.testing.assert_allclose(integral.x, [0.0, 1.0], atol=1e-9)
    # a user's module's rows, column-major integers, as the Gauss stage checks them
    from gaussim.assembly import assemble
    from gaussim.constraints.base import ConstraintModule, Rows, checked_rows

    class Floor(ConstraintModule):
        name = "floor"

        def rows(self, ctx):
            return None

    J = np.asfortranarray(np.array([[1, 0, 0, 0], [0, 1, 1, 0]]))
    masks = np.ones((5, 4))  # Supports.masks of a model of 5 joints and 4 coordinates
    users = checked_rows("floor", Rows(J, np.array([1, -2]), False, lambda: ["a", "b"]), masks)
    mine = Rows(J.astype(float, order="C"), np.array([1.0, -2.0]), False, lambda: ["a", "b"])
    expected = GaussSolver(gaussim.Options()).solve(assemble(H, g, [(Floor(), mine)]))
    answer = GaussSolver(gaussim.Options()).solve(assemble(H, g, [(Floor(), users)]))
    np.testing.assert_allclose(answer.x, expected.x, atol=1e-12)
    assert expected.x[0] >= 1.0 - 1e-9


def test_an_integer_friction_is_the_same_friction_to_the_bound_kernels():
    """Ground(friction=1) is an int; the contact kernels, bound by a scene of float friction first, read
    C-ordered floats: a box pushed along the ground slides as with friction=1.0."""
    import gaussim
    from gaussim import FreeBody

    def slide(friction: object) -> np.ndarray:
        box = {"box": FreeBody.box("box", (0.1, 0.1, 0.1), mass=1.0)}
        sim = gaussim.Simulator(gaussim.Scene(bodies=box, ground=gaussim.Ground(friction=friction)))
        state = sim.reset({"box": gaussim.pose(z=0.05)}, {"box": np.array([1.0, 0, 0, 0, 0, 0])})
        for _ in range(50):
            state = sim.step(state)
        return state.q

    first = slide(0.5)  # binds the kernels to float friction
    np.testing.assert_array_equal(slide(1), slide(1.0))
    assert slide(1)[0] < first[0] - 1e-3  # more friction, a shorter slide


def _unusual(a: np.ndarray) -> dict[str, object]:
    """``a`` in forms a user may hand over: the kernels read C-ordered native float64 alone."""
    return {
        "int": a.astype(int),
        "big-endian": a.astype(">f8"),
        "strided": np.repeat(a, 2)[::2],
        "list": a.tolist(),
    }


def test_a_velocity_of_any_make_is_damped_as_a_float_one(solo12):
    """Simulator.full_torque's v reaches the damping kernel; damping without v, or v of another size,
    is refused by name."""
    import gaussim

    sim = gaussim.Simulator(gaussim.Scene(solo12))
    tau, damping, v = np.ones(12), np.full(12, 0.5), np.arange(18.0)
    expected = sim.full_torque(tau, damping, v)
    assert expected[6] == pytest.approx(1.0 - 0.5 * 6.0)
    for form, given in _unusual(v).items():
        np.testing.assert_array_equal(sim.full_torque(tau, damping, given), expected, err_msg=form)
    with pytest.raises(gaussim.InvalidState, match="damping needs the velocity v"):
        sim.full_torque(tau, damping)
    with pytest.raises(gaussim.InvalidState, match=r"v must have shape \(18,\)"):
        sim.full_torque(tau, damping, np.zeros(12))


def test_an_adopted_state_of_any_make_steps_as_a_float_one():
    """A State.adopt of arrays the kernels cannot read as they are is stepped as its float copy."""
    import gaussim
    from gaussim import FreeBody

    sim = gaussim.Simulator(gaussim.Scene(bodies={"box": FreeBody.box("box", (0.1,) * 3, mass=1.0)}))
    start = sim.reset({"box": gaussim.pose(z=0.05)}, {"box": np.array([1.0, 0, 0, 0, 0, 2.0])})
    expected = sim.step(sim.step(start))
    for form in ("big-endian", "strided"):
        q, v = (_unusual(np.array(a))[form] for a in (start.q, start.v))
        state = gaussim.State.adopt(0.0, q, v, start.world)
        moved = sim.step(sim.step(state))
        np.testing.assert_array_equal(moved.v, expected.v, err_msg=form)
        np.testing.assert_array_equal(moved.q, expected.q, err_msg=form)


def test_a_big_endian_reference_holds_as_a_float_one(solo12):
    """PDHold's q_ref reaches Pinocchio, which reads native float64 bytes."""
    import gaussim
    from gaussim.control import PDHold

    q_ref = solo12.configuration("standing")
    state = gaussim.Simulator(gaussim.Scene(solo12)).reset(solo12.neutral())
    expected = PDHold(solo12.model, q_ref, 5.0, 0.2, slice(6, None))(state)
    assert np.abs(expected).max() > 1.0  # the neutral pose is far from standing: a torque to compare
    np.testing.assert_array_equal(
        PDHold(solo12.model, q_ref.astype(">f8"), 5.0, 0.2, slice(6, None))(state), expected
    )


def test_rows_and_activity_of_the_wrong_shape_are_refused_by_name(ball):
    """The kernels read a module's arrays at the shapes they expect and check none: a user's module's
    Rows, and is_active's arrays, of another shape, values or dtype are refused, naming the module and
    the field; so is gaussim's own family handed over as a user's (made for another model)."""
    import gaussim
    from gaussim.constraints import ConstraintModule, LimitModule, Rows, is_active

    class Lid(ConstraintModule):  # v_z <= 1, its rows posed as given
        name = "lid"

        def __init__(self, phi: object = (0.0,), rate: object = (0.0,), **given: object) -> None:
            self.phi, self.rate, self.given = phi, rate, given

        def rows(self, ctx):
            if not is_active(ctx, self.phi, self.rate, 5)[0]:  # lists, an int margin
                return None
            arrays = {"J": -np.eye(6)[2:3], "bound": np.array([-1.0]), **self.given}
            return Rows(arrays.pop("J"), arrays.pop("bound"), False, lambda: ["lid"], **arrays)

    def climb(*constraints: ConstraintModule) -> float:
        sim = gaussim.Simulator(gaussim.Scene(ball), constraints=constraints)
        return sim.step(sim.reset(ball.neutral(), [0, 0, 3.0, 0, 0, 0])).v[2]

    assert climb(Lid()) == pytest.approx(1.0)
    assert climb(Lid(joints=np.array([[1, 0]], np.int32))) == pytest.approx(1.0)  # the ball's joint
    assert climb(Lid(J=np.array([[0, 0, -1, 0, 0, 0]]), bound=[-1], joints=[[1, 0]])) == pytest.approx(1.0)
    assert climb(Lid(joints=[[1.0, 0.0]])) == pytest.approx(1.0)  # whole numbers of any real dtype
    for message, given in {
        r"Rows.J: must have shape \(rows, 6\), got \(6,\)": {"J": -np.eye(6)[2]},
        r"Rows.J: must have shape \(rows, 6\), got \(1, 1, 6\)": {"J": -np.eye(6)[None, 2:3]},
        r"Rows.J: must have shape \(rows, 6\), got \(1, 5\)": {"J": -np.eye(6)[2:3, :5]},
        r"Rows.J: must hold real numbers, got complex128": {"J": -np.eye(6)[2:3] * 1j},
        r"Rows.J: must be a rectangular array of real numbers": {"J": [[0, 0, -1, 0, 0, 0], [0]]},
        r"Rows.bound: must have shape \(1,\), got \(2,\)": {"bound": np.zeros(2)},
        r"Rows.bound: must have shape \(1,\), got \(\)": {"bound": -1.0},
        r"Rows.force: must have shape \(6,\), got \(1,\)": {"force": np.zeros(1)},
        r"Rows.joints: must be joint indices of shape \(1, 2\), got int64 \(2,\)": {
            "joints": np.zeros(2, np.int64)
        },
        r"Rows.joints: must be joint indices of shape \(1, 2\), got <U1": {"joints": [["a", "b"]]},
        r"Rows.joints: must be whole numbers, got 1.7": {"joints": [[1.7, 0.0]]},
        r"Rows.joints: must be whole numbers, got nan": {"joints": [[np.nan, 0.0]]},
        r"Rows.joints: must be joint indices in \[0, 2\), got 0 to 3": {"joints": [[3, 0]]},
        r"Rows.joints: must be joint indices in \[0, 2\), got -1 to 0": {"joints": [[-1, 0]]},
        r"Rows.joints: must name the joints .*row 0 reads v\[2\], which moves neither joint 0 nor joint 0": {
            "joints": [[0, 0]]
        },
    }.items():
        with pytest.raises(gaussim.InvalidOptions, match="module 'lid': " + message):
            climb(Lid(**given))
    with pytest.raises(gaussim.InvalidOptions, match=r"module 'lid': is_active: phi: must hold real numbers"):
        climb(Lid([0j], [0.0]))
    with pytest.raises(gaussim.InvalidOptions, match=r"module 'lid': is_active: phi and rate must have one"):
        climb(Lid([[0.0]], [[0.0]]))
    with pytest.raises(gaussim.InvalidOptions, match=r"module 'lid': is_active: .*got \(1,\), \(2,\)"):
        climb(Lid([0.0], [0.0, 0.0]))
    with pytest.raises(
        gaussim.InvalidOptions, match=r"constraints\[0\]: gaussim's LimitModule comes from the scene"
    ):
        climb(LimitModule(gaussim.load_robot("solo12").model))  # under another name too:
    solo_limits = LimitModule(gaussim.load_robot("solo12").model)
    solo_limits.name = "solo's"
    with pytest.raises(gaussim.InvalidOptions, match=r"gaussim's LimitModule comes from the scene"):
        climb(solo_limits)


def test_a_problem_and_a_point_of_the_wrong_shape_are_refused_by_name():
    """A GaussProblem and a KKT check's point of a user's making reach kernels that read the shapes
    they expect: others are refused by field (one aborted the process in freeing memory)."""
    import gaussim
    from gaussim.assembly import GaussProblem
    from gaussim.solver import kkt_residual

    H, g, none = np.eye(4), -np.array([1.0, 1.0, 0.0, 0.0]), (np.zeros((0, 4)), np.zeros(0))
    problem = GaussProblem(H, g, *none, np.eye(4)[:2], np.ones(2), [])  # x_0, x_1 >= 1: met at -g
    assert kkt_residual(problem, -g, np.zeros(0), np.zeros(2)) == 0.0
    assert kkt_residual(problem, np.zeros(4), np.zeros(0), np.zeros(2)) >= 1.0  # x_0 >= 1 missed by 1
    for message, arrays in {
        r"GaussProblem.C: must have shape \(rows, 4\), got \(2, 2\)": (H, g, *none, np.eye(2), np.ones(5)),
        r"GaussProblem.l: must have shape \(2,\), got \(5,\)": (H, g, *none, np.eye(4)[:2], np.ones(5)),
        r"GaussProblem.H: must be a square matrix, got shape \(3, 4\)": (H[:3], g, *none, *none),
        r"GaussProblem.g: must have shape \(3,\), got \(4,\)": (np.eye(3), g, *none, *none),
        r"GaussProblem.g: must have shape \(4,\), got \(\)": (H, 1.0, *none, *none),
        r"GaussProblem.A: must hold real numbers, got <U1": (H, g, [["a"]], [0.0], *none),
    }.items():
        with pytest.raises(gaussim.InvalidOptions, match=message):
            GaussProblem(*arrays, [])
    with pytest.raises(
        gaussim.InvalidOptions, match=r"GaussProblem.applied: must have shape \(4,\), got \(3,\)"
    ):
        GaussProblem(H, g, *none, *none, [], np.ones(3))
    with pytest.raises(gaussim.InvalidOptions, match=r"kkt_residual's x: must have shape \(4,\), got \(\)"):
        kkt_residual(problem, 0.0, np.zeros(0), np.zeros(2))
    with pytest.raises(gaussim.InvalidOptions, match=r"kkt_residual's x: must have shape \(4,\), got \(1,\)"):
        kkt_residual(problem, np.zeros(1), np.zeros(0), np.zeros(2))
    with pytest.raises(gaussim.InvalidOptions, match=r"kkt_residual's lambda_in: must have shape \(2,\)"):
        kkt_residual(problem, np.ones(4), np.zeros(0), np.zeros(0))
