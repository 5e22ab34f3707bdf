"""The solve: DAQP first, then ProxQP's warm starts that cannot go stale; certificates that are checked."""

import gc
import subprocess
import sys
import warnings
import weakref
from pathlib import Path

import numpy as np
import pytest

import gaussim
from gaussim.assembly import GaussProblem, assemble
from gaussim.constraints.base import ROW_ID_BITS, ConstraintModule, Context, Rows
from gaussim.kernels.solver import violates
from gaussim.solver import KKT_RTOL, GaussSolver, Status, kkt_residual
from gaussim.solver.active_set import ACTIVE_SET_FLOOR, active_set_candidate
from gaussim.solver.certificate import kkt_residuals
from gaussim.solver.dual import DaqpActiveSet, SparseDualActiveSet
from gaussim.solver.proxqp import _initialise, _sides

DATA = Path(__file__).parent / "data"
# The ProxQP path's tests solve without DAQP, which answers their problems before ProxQP is asked.
PROXQP = gaussim.Options(solver="proxqp")
# The dual active-set solvers (gaussim's own, DAQP) and the status of their answers
DUAL_SOLVERS = ["dual", "daqp"]
SOLVED_BY = {"dual": Status.DUAL_SOLVED, "daqp": Status.DUAL_ACTIVE_SET_SOLVED}
DUAL_CLASSES = {"dual": SparseDualActiveSet, "daqp": DaqpActiveSet}
SETUPS_FOR_A_NEW_G = {"dual": 1, "daqp": 2}


def _problem(lower: float) -> GaussProblem:
    """min 1/2 |x|^2 + 9.81e-3 x_3  s.t.  x_3 >= lower: a ball's normal velocity under gravity."""
    C = np.array([[0.0, 0.0, 1.0]])
    return GaussProblem(
        np.eye(3), np.array([0, 0, 9.81e-3]), np.zeros((0, 3)), np.zeros(0), C, np.array([lower]), []
    )


def test_warm_start_is_not_stale_when_only_bounds_change(monkeypatch):
    """ProxQP's own warm start (the active-set candidates refused, as on a problem they cannot solve)
    is checked: a stale answer is solved again from a cold start."""
    from gaussim.solver import proxqp

    monkeypatch.setattr(proxqp.active_set_candidate, "call", lambda *args: (0, (np.nan,) * 5))
    solver = GaussSolver(PROXQP)
    resting = solver.solve(_problem(0.0))
    assert resting.lambda_in[0] == pytest.approx(9.81e-3, abs=1e-7)
    freed = solver.solve(_problem(-0.5))  # same H, g, C: only the bound moved
    assert freed.x[2] == pytest.approx(-9.81e-3, rel=1e-9)
    assert abs(freed.lambda_in[0]) < 1e-12
    assert freed.certificate.restarted, "ProxQP 0.8 returns the stale warm start here"
    assert freed.certificate.kkt_residual < 1e-12


def test_the_previous_solution_is_kept_only_when_it_still_solves_the_problem():
    """A problem the last solution still solves to eps_abs (gaussim's KKT check) gets it back without
    a ProxQP call; one it does not solve (the load moved by 1e-6) is solved on its active set, also
    without ProxQP; one whose active set changed (the row left, then joined again) by the active-set
    steps, exactly."""
    solver = GaussSolver(PROXQP)
    first = solver.solve(_problem(0.0))
    again = solver.solve(_problem(0.0))
    assert again.certificate.status == Status.PREVIOUS_SOLUTION_CERTIFIED and again.certificate.converged
    assert again.certificate.iterations == 0 and again.certificate.relative_kkt_residual <= 1e-9
    np.testing.assert_array_equal(again.x, first.x)
    np.testing.assert_array_equal(again.multipliers, first.multipliers)
    heavier = _problem(0.0)
    heavier.g[2] += 1e-6
    moved = solver.solve(heavier)
    assert moved.certificate.status == Status.ACTIVE_SET_CERTIFIED and moved.certificate.converged
    assert moved.lambda_in[0] == pytest.approx(9.81e-3 + 1e-6, abs=1e-15)
    assert moved.x[2] == pytest.approx(0.0, abs=1e-15)
    lifted = solver.solve(_problem(-0.5))  # the row is no longer active: its multiplier would pull
    assert lifted.certificate.status == Status.ACTIVE_SET_CERTIFIED
    assert lifted.x[2] == pytest.approx(-9.81e-3, rel=1e-15) and lifted.lambda_in[0] == 0.0
    landed = solver.solve(_problem(0.0))  # a row that becomes active: the free x violates it
    assert landed.certificate.status == Status.ACTIVE_SET_CERTIFIED
    assert landed.lambda_in[0] == pytest.approx(9.81e-3, rel=1e-15)


def _sticking_point(push: float) -> GaussProblem:
    """A unit point mass on the ground (friction 0.5, a 4-facet pyramid), weight 9.81e-3 and a
    tangential push ``push`` along x (velocity level, dt = 1e-3): its four rows span three directions."""
    mu, normal = 0.5, np.array([0.0, 0.0, 1.0])
    tangents = [np.array([np.cos(a), np.sin(a), 0.0]) for a in np.arange(4) * np.pi / 2]
    C = np.array([normal + mu * t for t in tangents])
    return GaussProblem(
        np.eye(3), np.array([-push, 0.0, 9.81e-3]), np.zeros((0, 3)), np.zeros(0), C, np.zeros(4), []
    )


def test_the_active_set_solve_handles_dependent_rows_and_matches_proxqp():
    """A sticking contact's pyramid rows are dependent; with the push changed, the solve on the last
    active set is certified and gives ProxQP's x and contact force, without a ProxQP call; pushed
    beyond the cone, the active-set steps find the sliding contact's rows and ProxQP's answer."""
    solver = GaussSolver(PROXQP)
    solver.solve(_sticking_point(1e-3))
    warm = solver.solve(_sticking_point(2e-3))
    assert warm.certificate.status == Status.ACTIVE_SET_CERTIFIED
    assert np.all(warm.lambda_in >= 0.0)
    cold = GaussSolver(PROXQP).solve(_sticking_point(2e-3))
    assert cold.certificate.status == Status.SOLVED
    C = _sticking_point(2e-3).C
    # the exact answer: the point sticks, the ground pushing back with (-push, 0, weight); ProxQP's is within
    # KKT_RTOL eps_abs of it, the active-set solve's within round-off
    np.testing.assert_allclose(warm.x, 0.0, atol=1e-15)
    np.testing.assert_allclose(C.T @ warm.lambda_in, [-2e-3, 0.0, 9.81e-3], atol=1e-15)
    np.testing.assert_allclose(cold.x, 0.0, atol=1e-7)
    np.testing.assert_allclose(C.T @ cold.lambda_in, [-2e-3, 0.0, 9.81e-3], atol=1e-7)
    sliding = solver.solve(_sticking_point(1.0))  # beyond mu m g: the contact slides, rows drop out
    assert sliding.certificate.status == Status.ACTIVE_SET_CERTIFIED
    assert sliding.x[0] > 0.5
    fresh = GaussSolver(PROXQP).solve(_sticking_point(1.0))
    np.testing.assert_allclose(sliding.x, fresh.x, atol=1e-7)


def test_kkt_residual_measures_complementarity():
    problem = _problem(-0.5)
    x = np.array([0.0, 0.0, 0.0])
    assert kkt_residual(problem, x, np.zeros(0), np.array([9.81e-3])) == pytest.approx(0.5 * 9.81e-3)
    assert kkt_residual(problem, np.array([0, 0, -9.81e-3]), np.zeros(0), np.zeros(1)) == 0.0


def test_kkt_residual_is_nan_when_anything_is_not_finite():
    """A NaN in the solution, a multiplier or a bound must not hide behind a max."""
    problem = _problem(-0.5)
    solution = np.array([0, 0, -9.81e-3])
    assert kkt_residual(problem, solution, np.zeros(0), np.zeros(1)) == 0.0
    assert np.isnan(kkt_residual(problem, np.array([np.nan, 0, 0]), np.zeros(0), np.zeros(1)))
    assert np.isnan(kkt_residual(problem, solution, np.zeros(0), np.array([np.nan])))
    assert np.isnan(kkt_residual(_problem(np.nan), solution, np.zeros(0), np.zeros(1)))
    anchored = GaussProblem(np.eye(3), problem.g, np.eye(3)[:1], np.zeros(1), problem.C, problem.l, [])
    assert kkt_residual(anchored, solution, np.zeros(1), np.zeros(1)) == 0.0
    assert np.isnan(kkt_residual(anchored, solution, np.array([np.inf]), np.zeros(1)))


def test_kkt_residuals_are_numpys_on_a_problem_of_a_piles_size():
    """The compiled check, whose sums run in any order, against numpy's products on a problem of a
    settling bin's size (120 coordinates, 10 equality and 330 inequality rows, a fifth of them active)."""
    rng = np.random.default_rng(3)
    n, n_eq, n_in = 120, 10, 330
    root = rng.normal(size=(n, n))
    H, g = root @ root.T + n * np.eye(n), rng.normal(size=n)
    A, C = rng.normal(size=(n_eq, n)), rng.normal(size=(n_in, n))
    x, y = rng.normal(size=n), rng.normal(size=n_eq)
    z = np.where(rng.random(n_in) < 0.2, rng.random(n_in), 0.0)
    slack = rng.random(n_in) * (z == 0)  # the active rows met, the others slack
    b, l = A @ x + 1e-7 * rng.normal(size=n_eq), C @ x - slack
    stationarity = H @ x + g - A.T @ y - C.T @ z
    primal = max(np.abs(A @ x - b).max(), (l - C @ x).max())
    complementarity = np.abs(z * (C @ x - l)).max()
    expected = max(primal, complementarity, np.abs(stationarity).max())
    got = kkt_residuals(H, g, A, b, C, l, x, y, z)
    assert got[0] == pytest.approx(expected, rel=1e-9)
    assert got[3] == pytest.approx(np.abs(stationarity).max(), rel=1e-9)
    assert got[4] == pytest.approx(abs(z @ (C @ x - l)), rel=1e-6, abs=1e-12)


def test_a_violated_row_refuses_a_point_before_its_check():
    """``violates``: a row violated beyond the tolerance, not within it, and not a NaN (which the KKT
    check refuses on its own)."""
    C, l = np.array([[1.0, 0.0], [0.0, 1.0]]), np.array([0.0, 1.0])
    assert violates(C, l, np.array([0.0, 1.0 - 1e-9]), 1e-8) is False
    assert violates(C, l, np.array([0.0, 1.0 - 1e-7]), 1e-8) is True
    assert violates(C, l, np.array([np.nan, 1.0]), 1e-8) is False
    assert violates(np.zeros((0, 2)), np.zeros(0), np.zeros(2), 1e-8) is False


def test_sign_violation_is_judged_relative_to_the_problem_scale():
    """A -1.6e-7 multiplier on a light row beside a 1e4 load (a 1e6 kg box on a 1 kg one, as ProxQP
    returned it at eps_abs 1e-9) is a round-off, not a pull: accepted relative to max(1, |g|), still
    counted in the absolute residual; the same multiplier in a problem of unit scale is not."""

    def residuals(load: float, z: float) -> tuple[float, float]:
        H, g = np.eye(2), np.array([load, 0.0])
        C, l = np.eye(2), np.array([0.0, 0.0])  # x >= 0: the load presses row 0, row 1 is idle
        x, multipliers = np.zeros(2), np.array([load, z])
        return kkt_residuals(H, g, np.zeros((0, 2)), np.zeros(0), C, l, x, np.zeros(0), multipliers)[:2]

    absolute, relative = residuals(1e4, -1.6e-7)
    assert absolute == pytest.approx(1.6e-7)
    assert relative == pytest.approx(1.6e-11) and relative <= KKT_RTOL * 1e-9
    unit = residuals(1.0, -1.6e-7)[1]
    assert unit == pytest.approx(1.6e-7) and unit > KKT_RTOL * 1e-9


@pytest.mark.parametrize(
    ("conflict", "status"), [(1e-8, Status.CERTIFIED_AT_MAX_ITER), (1e-6, Status.MAX_ITER_REACHED)]
)
def test_iteration_cap_is_accepted_only_when_the_kkt_check_certifies_the_point(conflict, status):
    """Two rows that conflict by ``conflict`` (x_3 >= 0 and x_3 <= -conflict, as redundant contact rows
    do in round-off): ProxQP cannot bring its primal residual below eps_abs and stops at its cap. A
    round-off conflict is certified by the KKT check (relative residual conflict / 2 <= KKT_RTOL
    eps_abs) and accepted; a real one is reported as ProxQP's failure."""
    C = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    problem = GaussProblem(
        np.eye(3), np.array([0, 0, 9.81e-3]), np.zeros((0, 3)), np.zeros(0), C, np.array([0.0, conflict]), []
    )
    solution = GaussSolver(gaussim.Options(on_failure="report")).solve(problem)
    assert solution.certificate.status == status
    assert solution.certificate.converged == (status != Status.MAX_ITER_REACHED)
    assert solution.x[2] == pytest.approx(-conflict / 2, rel=1e-6)


def test_a_stalling_warm_start_is_cut_short():
    """A QP saved from the box_stack scene (3 boxes, 56 contact rows, 18 unknowns): its redundant
    rows conflict by ~1e-9 m/s (bounds gap/dt with round-off gaps), so ProxQP cannot reach eps_abs.
    Warm-started from the previous step's solution, ProxQP 0.8 ran 1.65 million inner iterations
    (94 s) to its 10000-iteration cap; the warm start is now capped at WARM_START_ITERATIONS and
    the point it reaches is certified by the KKT check."""
    data = np.load(DATA / "stalled_warm_start.npz")
    no_rows = np.zeros((0, len(data["g"])))

    def problem(g: np.ndarray, l: np.ndarray) -> GaussProblem:
        return GaussProblem(data["H"], g, no_rows, np.zeros(0), data["C"], l, [])

    solver = GaussSolver(PROXQP)
    assert solver.solve(problem(data["g_previous"], data["l_previous"])).certificate.converged
    solution = solver.solve(problem(data["g"], data["l"]))  # warm-started from the previous solution
    c = solution.certificate
    assert c.converged and c.relative_kkt_residual < 1e-8, c
    assert c.iterations < 10_000, f"{c.iterations} ProxQP iterations"  # capped: about 100


def _saved_problem(name: str) -> GaussProblem:
    """A QP saved from a run (H, g, C, l: inequality rows only)."""
    data = np.load(DATA / name)
    no_rows = np.zeros((0, len(data["g"])))
    return GaussProblem(data["H"], data["g"], no_rows, np.zeros(0), data["C"], data["l"], [])


def _proxqp_alone(solver: GaussSolver, problem: GaussProblem) -> tuple[np.ndarray, np.ndarray]:
    """ProxQP's answer (x, the inequality multipliers -z) from a cold start, set up as the solver
    sets it up, without gaussim's check or recovery."""
    dims, equalities, inequalities = _sides(problem)
    qp = solver._new(*dims)
    _initialise(qp, problem, equalities, inequalities)
    qp.solve()
    return qp.results.x.copy(), -qp.results.z


def test_an_uncertified_proxqp_answer_is_solved_on_its_active_set():
    """A QP saved from Talos standing at dt = 0.02 (18 unknowns, 40 contact rows): ProxQP stops at a
    relative KKT residual of about 1e-6, which the check refuses (it once failed that benchmark run).
    Its answer names the active rows (ten multipliers of 0.01 to 0.6; the inactive rows' are 1e-172
    or 0, below ACTIVE_SET_FLOOR of the largest); solved on them the problem is exact, before any
    cold restart."""
    problem = _saved_problem("talos_dt002_unconverged.npz")
    options = PROXQP.replace(dt=0.02)
    solver = GaussSolver(options)
    p, (x, z) = problem, _proxqp_alone(solver, problem)
    relative = kkt_residuals(p.H, p.g, p.A, p.b, p.C, p.l, x, np.zeros(0), z)[1]
    assert relative > KKT_RTOL * options.eps_abs, "ProxQP now certifies it: the test rescues nothing"
    solution = solver.solve(problem)
    c = solution.certificate
    assert c.status == Status.ACTIVE_SET_CERTIFIED and not c.restarted and c.converged, c
    assert c.relative_kkt_residual < 1e-14, c
    np.testing.assert_allclose(solution.x, x, atol=1e-5)
    assert np.all(p.C @ solution.x >= p.l - 1e-12)


def _thrown_solo12_run(solo12: gaussim.Robot, steps: int) -> np.ndarray:
    """Velocities of Solo-12 thrown spinning onto the ground (a chaotic landing: ten contact sets
    come and go, ProxQP makes new QP objects), one row per step."""
    feet = [(f"{leg}_FOOT_0", "ground") for leg in ("FL", "FR", "HL", "HR")]
    sim = gaussim.Simulator(gaussim.Scene(solo12, ground=gaussim.Ground(friction=0.8), contacts=feet))
    q = solo12.configuration("standing")
    q[2] += 0.3
    v = np.zeros(solo12.model.nv)
    v[[0, 2, 3, 5]] = 0.5, 1.0, 2.0, 3.0
    state, rows = sim.reset(q, v), []
    for _ in range(steps):
        state = sim.step(state, np.zeros(12))
        rows.append(state.v)
    return np.array(rows)


def test_runs_repeat_bit_for_bit(solo12):
    """The same run twice gives the same numbers to the last bit: ProxQP's AVX builds answer one
    problem differently from one QP object to the next (this landing drifted apart from step 312),
    its portable build, which gaussim loads, does not."""
    first, second = _thrown_solo12_run(solo12, 450), _thrown_solo12_run(solo12, 450)
    np.testing.assert_array_equal(first, second)


@pytest.mark.parametrize("proxsuite_first", [True, False])
def test_proxsuite_keeps_the_build_already_loaded(proxsuite_first):
    """gaussim loads proxsuite's portable build unless the process loaded proxsuite before it; then
    it uses that build (loading a second one would abort the process)."""
    imports = ["import proxsuite", "import gaussim"]
    code = "; ".join([*(imports if proxsuite_first else imports[::-1]), "print(proxsuite.proxqp.__name__)"])
    chosen = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert chosen.returncode == 0, chosen.stderr
    build = chosen.stdout.split(".")[1]
    if proxsuite_first:
        own = subprocess.run(
            [sys.executable, "-c", "import proxsuite; print(proxsuite.proxqp.__name__)"],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert build == own.stdout.split(".")[1]
    else:
        assert build == "proxsuite_pywrap"


def test_a_refused_answer_is_solved_again_to_a_tighter_tolerance():
    """A QP saved from ANYmal C collapsing onto the ground (the corpus' zero-torque pass: 18 unknowns,
    156 pyramid rows of its feet and body): ProxQP's own test passes at a relative KKT residual of
    9e-6, above the 1e-7 the check accepts, and the rows it holds active are too dependent for the
    active-set solve. Solved again at eps_abs / KKT_RTOL, it is certified."""
    problem = _saved_problem("anymal_collapse_refused.npz")
    options = PROXQP
    solver = GaussSolver(options)
    p, (x, z) = problem, _proxqp_alone(solver, problem)
    assert kkt_residuals(p.H, p.g, p.A, p.b, p.C, p.l, x, np.zeros(0), z)[1] > KKT_RTOL * options.eps_abs
    candidate = np.empty(len(x)), np.empty(len(z))
    tolerance = options.eps_abs
    how, _ = active_set_candidate(p.H, p.g, p.A, p.b, p.C, p.l, x, z, tolerance, ACTIVE_SET_FLOOR, *candidate)
    assert how == 0
    solution = solver.solve(problem)
    c = solution.certificate
    assert c.status is Status.SOLVED and c.restarted, c  # ProxQP itself, at the tighter tolerance
    assert c.relative_kkt_residual <= KKT_RTOL * options.eps_abs
    assert np.all(p.C @ solution.x >= p.l - 1e-9)


@pytest.mark.parametrize(
    "saved", ["pile_wrong_sign_multiplier.npz", "pile_wrong_sign_multiplier_full_rank.npz"]
)
def test_an_answer_with_a_wrong_sign_multiplier_is_certified_by_nonnegative_ones(saved):
    """QPs saved from 20 free bodies settling in a bin (120 unknowns; 284 contact rows of rank 119,
    and 320 rows of rank 120): ProxQP's answer (and its cold restarts, at eps_abs and at eps_abs /
    KKT_RTOL) holds a multiplier of -9e-6 N s (-7.6e-6 N s), the active-set solve of its 176 active
    rows fails (they are too dependent), and the run stopped there with a SolverError. Its x is
    optimal all the same: nonnegative multipliers of the rows at their bound certify it, and it is
    ProxQP's certified solution at eps_abs = 1e-12 (to 5e-10 in the norm of M)."""
    problem = _saved_problem(saved)
    options = PROXQP
    solver = GaussSolver(options)
    p, (x, z) = problem, _proxqp_alone(solver, problem)
    assert z.min() < -KKT_RTOL * options.eps_abs, "ProxQP's answer is now certified: nothing to rescue"
    candidate = np.empty(len(x)), np.empty(len(z))
    assert (
        active_set_candidate(
            p.H, p.g, p.A, p.b, p.C, p.l, x, z, options.eps_abs, ACTIVE_SET_FLOOR, *candidate
        )[0]
        == 0
    )
    solution = solver.solve(problem)
    c = solution.certificate
    assert c.status is Status.MULTIPLIERS_CERTIFIED and c.restarted and c.converged, c
    lam, slack = solution.lambda_in, p.C @ solution.x - p.l
    assert lam.min() >= 0 and slack.min() > -1e-10
    assert np.abs(p.H @ solution.x + p.g - p.C.T @ lam).max() < 1e-10  # stationarity
    assert np.abs(lam * slack).max() < 1e-10  # complementarity
    tight = solver._new(*_sides(p)[0])
    tight.settings.eps_abs = tight.settings.eps_duality_gap_abs = 1e-12
    _initialise(tight, p, *_sides(p)[1:])
    tight.solve()
    x_tight, z_tight = tight.results.x, -tight.results.z
    assert kkt_residuals(p.H, p.g, p.A, p.b, p.C, p.l, x_tight, np.zeros(0), z_tight)[1] < 1e-11
    difference = solution.x - x_tight  # in the norm of M [sqrt(kg) m/s]: its rotations are light
    assert np.sqrt(difference @ p.H @ difference) < 1e-9


def _tight_proxqp(problem: GaussProblem) -> np.ndarray:
    """ProxQP's x at eps_abs = 1e-12 from a cold start (the reference of the DAQP tests)."""
    solver = GaussSolver(PROXQP)
    dims, equalities, inequalities = _sides(problem)
    qp = solver._new(*dims)
    qp.settings.eps_abs = qp.settings.eps_duality_gap_abs = 1e-12
    _initialise(qp, problem, equalities, inequalities)
    qp.solve()
    p, x, y, z = problem, qp.results.x.copy(), -qp.results.y, -qp.results.z
    assert kkt_residuals(p.H, p.g, p.A, p.b, p.C, p.l, x, y, z)[1] < 1e-9  # rows conflict by ~1e-9
    return x


@pytest.mark.parametrize(
    "saved",
    [
        "pile_wrong_sign_multiplier.npz",
        "pile_wrong_sign_multiplier_full_rank.npz",
        "anymal_collapse_refused.npz",
        "talos_dt002_unconverged.npz",
        "stalled_warm_start.npz",
    ],
)
@pytest.mark.parametrize("solver", DUAL_SOLVERS)
def test_daqp_certifies_the_dependent_rows_proxqp_struggles_with(saved, solver):
    """The saved QPs whose dependent contact rows cost ProxQP a refused answer, a cold restart or its
    iteration cap: DAQP, tried first, answers each with nonnegative multipliers that the KKT check
    certifies, and x is ProxQP's at eps_abs = 1e-12 (to 1e-8 in the norm of M)."""
    problem = _saved_problem(saved)
    solution = GaussSolver(gaussim.Options(solver=solver)).solve(problem)
    c, p = solution.certificate, problem
    assert c.status is SOLVED_BY[solver] and c.converged and not c.restarted, c
    assert c.relative_kkt_residual <= KKT_RTOL * gaussim.Options().eps_abs
    assert solution.lambda_in.min() >= 0.0
    difference = solution.x - _tight_proxqp(problem)
    assert np.sqrt(difference @ p.H @ difference) < 1e-8


@pytest.mark.parametrize("solver", DUAL_SOLVERS)
def test_daqp_solves_equality_rows_as_proxqp_does(solver):
    """Bilateral rows (a loop closure's) with contact rows: DAQP holds the equalities and gives
    ProxQP's x (at eps_abs = 1e-12) and multipliers that certify it; a problem DAQP finds infeasible
    (two rows that conflict by 1e-6) goes on to ProxQP, which reports it."""
    rng = np.random.default_rng(7)
    n = 12
    B = rng.normal(size=(n, n))
    A, C, x = rng.normal(size=(3, n)), rng.normal(size=(20, n)), rng.normal(size=n)  # x admissible
    H, g, b, l = B @ B.T + np.eye(n), rng.normal(size=n) * 10, A @ x, C @ x - rng.uniform(0, 1, 20)
    problem = GaussProblem(H, g, A, b, C, l, [])
    solution = GaussSolver(gaussim.Options(solver=solver)).solve(problem)
    assert solution.certificate.status is SOLVED_BY[solver], solution.certificate
    np.testing.assert_allclose(A @ solution.x, b, atol=1e-9)
    assert solution.lambda_in.min() >= 0.0 and np.count_nonzero(solution.lambda_in) > 0
    np.testing.assert_allclose(solution.x, _tight_proxqp(problem), atol=1e-8)
    C = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    no_rows, l = np.zeros((0, 3)), np.array([0.0, 1e-6])
    conflict = GaussProblem(np.eye(3), np.array([0, 0, 9.81e-3]), no_rows, np.zeros(0), C, l, [])
    refused = GaussSolver(gaussim.Options(solver=solver, on_failure="report")).solve(conflict)
    assert refused.certificate.status is Status.MAX_ITER_REACHED


def _pyramid_problem(
    rng: np.random.Generator, bodies: int, contacts: int, dense: bool, n_eq: int
) -> GaussProblem:
    """A random Gauss problem shaped like a pile's or a robot's: H block diagonal (free bodies of 6
    coordinates) or dense (a robot), each contact a normal row and four pyramid facets (mu n +- t1,
    mu n +- t2: five rows of rank 3) reading one body or two, ``n_eq`` equality rows, every row met
    by some x0 (feasible), and g pushing the bodies into their rows (many rows active)."""
    n = 6 * bodies
    if dense:
        B = rng.normal(size=(n, n))
        H = B @ B.T + n * np.eye(n)
    else:
        H = np.zeros((n, n))
        for k in range(bodies):
            B = rng.normal(size=(6, 6))
            H[6 * k : 6 * k + 6, 6 * k : 6 * k + 6] = B @ B.T + 6 * np.eye(6)
    rows = []
    for _ in range(contacts):
        J = np.zeros((3, n))
        for body in rng.choice(bodies, size=rng.integers(1, 3), replace=False):
            J[:, 6 * body : 6 * body + 6] = rng.normal(size=(3, 6))
        normal, t1, t2 = J
        mu = rng.uniform(0.2, 1.0)
        rows += [normal, mu * normal + t1, mu * normal - t1, mu * normal + t2, mu * normal - t2]
    C, x0 = np.array(rows), rng.normal(size=n)
    A = rng.normal(size=(n_eq, n))
    l = C @ x0 - rng.uniform(0.0, 0.1, len(C)) * (rng.uniform(size=len(C)) < 0.5)
    g = H @ (C.T @ rng.uniform(0.0, 1.0, len(C)) * 0.1 - x0) * 3.0
    return GaussProblem(H, g, A, A @ x0, C, l, [])


@pytest.mark.parametrize(
    "bodies, contacts, dense, n_eq", [(4, 12, False, 0), (8, 40, False, 2), (3, 8, True, 0), (3, 10, True, 3)]
)
def test_gaussims_dual_method_gives_daqps_answers_on_contact_pyramids(bodies, contacts, dense, n_eq):
    """gaussim's dual active-set method (kernels.dual) against DAQP, Arnström et al.'s (not gaussim's), at
    a tight tolerance: random problems of free bodies or a robot, whose contacts' pyramid rows are
    dependent (five rows of rank 3), some with equality rows; a sequence of them on one solver, each
    problem's g and bounds moved from the last (its working set starts from the last one's): each is
    answered by the method itself (no ProxQP), certified, with DAQP's x to 1e-8 in the norm of H."""
    import daqp

    rng = np.random.default_rng(bodies * 100 + contacts + n_eq)
    base = _pyramid_problem(rng, bodies, contacts, dense, n_eq)
    gauss = GaussSolver(gaussim.Options())
    active = []
    for k in range(6):
        p = base
        if k:
            p = GaussProblem(
                p.H, p.g * (1 + 0.1 * rng.normal(size=len(p.g))), p.A, p.b, p.C, p.l - 1e-3 * k, []
            )
        solution = gauss.solve(p, warm=False)  # not the last solution's active set: the method itself
        assert solution.certificate.status is Status.DUAL_SOLVED, solution.certificate
        assert solution.lambda_in.min() >= 0.0
        sense = np.r_[np.full(n_eq, 5), np.zeros(len(p.l))].astype(np.int32)  # 5: an equality row
        model = daqp.Model()
        settings = model.settings
        settings["primal_tol"] = 1e-10
        model.settings = settings
        upper = np.r_[p.b, np.full(len(p.l), 1e30)]
        model.setup(p.H.copy(), p.g.copy(), np.vstack([p.A, p.C]), upper, np.r_[p.b, p.l], sense)
        x, _, flag, _ = model.solve()
        assert flag == 1
        difference = solution.x - x
        assert np.sqrt(difference @ p.H @ difference) < 1e-8
        active.append(np.count_nonzero(solution.lambda_in))
    assert min(active) > 3  # contacts pressed: the pyramids' rows matter


@pytest.mark.parametrize("solver", DUAL_SOLVERS)
def test_daqp_solves_a_problem_whose_bounds_moved_on_the_factors_it_holds(monkeypatch, solver):
    """A friction pass shifts the normal rows' bounds of a problem whose H, g and rows stay: DAQP
    updates the bounds of the workspace it holds (one setup for both solves) and gives ProxQP's x of
    the shifted problem (at eps_abs = 1e-12), not the first problem's."""
    setups = []
    kind = DUAL_CLASSES[solver]
    setup = kind._setup
    monkeypatch.setattr(kind, "_setup", lambda self, *args: setups.append(1) or setup(self, *args))
    problem = _saved_problem("pile_wrong_sign_multiplier_full_rank.npz")
    gauss = GaussSolver(gaussim.Options(solver=solver))
    first = gauss.solve(problem)
    shifted = GaussProblem(problem.H, problem.g, problem.A, problem.b, problem.C, problem.l + 1e-3, [])
    shifted.rows_key = problem.rows_key  # the same rows, as assemble keeps them (the next test)
    second = gauss.solve(shifted)
    assert second.certificate.status is SOLVED_BY[solver] and len(setups) == 1
    difference = second.x - _tight_proxqp(shifted)
    assert np.sqrt(difference @ problem.H @ difference) < 1e-8
    assert np.abs(second.x - first.x).max() > 1e-4  # the shift moved the answer


@pytest.mark.parametrize("solver", DUAL_SOLVERS)
def test_a_later_pass_on_the_rows_the_dual_method_holds_goes_to_it_first(monkeypatch, solver):
    """A robot-sized problem (18 coordinates: small enough for the active-set candidate) that the dual
    method solved: its friction pass (the same rows, bounds shifted) is solved by the method on the
    factors and working set it holds, the candidate not tried, with ProxQP's x of the shifted problem
    (eps_abs 1e-12); a problem of new rows goes to the candidate first, as before."""
    from gaussim.solver import proxqp

    problem = _pyramid_problem(np.random.default_rng(3), 3, 8, True, 0)
    tried = []
    candidate = proxqp.active_set_candidate.dispatcher
    monkeypatch.setattr(proxqp.active_set_candidate, "call", lambda *a: tried.append(1) or candidate(*a))
    gauss = GaussSolver(gaussim.Options(solver=solver))
    first = gauss.solve(problem)  # no last solution: the dual method answers
    assert first.certificate.status is SOLVED_BY[solver] and not tried
    shifted = GaussProblem(problem.H, problem.g, problem.A, problem.b, problem.C, problem.l - 1e-3, [])
    shifted.rows_key = problem.rows_key  # the same rows, as assemble keeps them for a friction pass
    second = gauss.solve(shifted)
    assert second.certificate.status is SOLVED_BY[solver] and not tried
    difference = second.x - _tight_proxqp(shifted)
    assert np.sqrt(difference @ problem.H @ difference) < 1e-8
    assert np.abs(second.x - first.x).max() > 1e-5  # the shift moved the answer
    anew = GaussProblem(problem.H, problem.g, problem.A, problem.b, problem.C.copy(), shifted.l, [])
    gauss.solve(anew)
    assert tried  # new rows: the candidate first


class _Given(ConstraintModule):
    """A module whose rows a test hands to assemble."""

    name = "given"

    def rows(self, ctx: Context) -> None:
        return None


@pytest.mark.parametrize("solver", DUAL_SOLVERS)
def test_a_pass_that_moves_bounds_alone_keeps_the_stacked_rows_and_daqps_factors(monkeypatch, solver):
    """A friction pass poses the same J arrays with new bounds: assembly keeps the last pass's
    stacked rows and its key, and DAQP updates the bounds of the factors it holds without comparing
    H and the rows (one setup, ProxQP's x of the shifted problem). New J arrays are set up again,
    and so is a new g under the same key for DAQP (gaussim's method keeps the factors of H and the
    rows, and solves for the new unconstrained minimum on them)."""
    from gaussim.solver import dual

    saved = _saved_problem("pile_wrong_sign_multiplier_full_rank.npz")
    module, half = _Given(), len(saved.l) // 2

    def parts(C: np.ndarray, l: np.ndarray) -> list:  # two blocks: assembly stacks them
        return [
            (module, Rows(C[:half], l[:half], False, list)),
            (module, Rows(C[half:], l[half:], False, list)),
        ]

    first = assemble(saved.H, saved.g, parts(saved.C, saved.l))
    blocks = [rows for _, rows, _ in first.blocks]
    moved = [(module, Rows(rows.J, rows.bound + 1e-3, False, list)) for rows in blocks]
    shifted = assemble(saved.H, saved.g, moved, first)
    assert shifted.C is first.C and shifted.rows_key is first.rows_key
    np.testing.assert_array_equal(shifted.l, saved.l + 1e-3)
    anew = assemble(saved.H, saved.g, parts(saved.C.copy(), saved.l), first)
    assert anew.C is not first.C and anew.rows_key is not first.rows_key

    setups = []
    kind = DUAL_CLASSES[solver]
    setup = kind._setup
    monkeypatch.setattr(kind, "_setup", lambda self, *args: setups.append(1) or setup(self, *args))
    compared = []
    same = dual._same
    monkeypatch.setattr(dual, "_same", lambda *args: compared.append(1) or same(*args))
    gauss = GaussSolver(gaussim.Options(solver=solver))
    gauss.solve(first)
    second = gauss.solve(shifted)
    assert second.certificate.status is SOLVED_BY[solver]
    assert len(setups) == 1 and not compared
    difference = second.x - _tight_proxqp(shifted)
    assert np.sqrt(difference @ saved.H @ difference) < 1e-8
    pushed = GaussProblem(saved.H, saved.g * (1 + 1e-3), shifted.A, shifted.b, shifted.C, shifted.l, [])
    pushed.rows_key = shifted.rows_key
    third = gauss.solve(pushed)
    assert third.certificate.status is SOLVED_BY[solver]  # its own answer, not ProxQP's after a refusal
    assert len(setups) == SETUPS_FOR_A_NEW_G[solver]
    difference = third.x - _tight_proxqp(pushed)
    assert np.sqrt(difference @ saved.H @ difference) < 1e-8


@pytest.mark.parametrize("solver", DUAL_SOLVERS)
def test_daqp_starts_a_new_problem_from_its_last_working_set(solver):
    """A problem with a new g (the next step's) starts from the rows DAQP held active in the last
    one: a few iterations where a cold start takes its 100-odd, to the same answer."""
    problem = _saved_problem("pile_wrong_sign_multiplier_full_rank.npz")
    nudged = GaussProblem(problem.H, problem.g * (1 + 1e-6), problem.A, problem.b, problem.C, problem.l, [])
    gauss = GaussSolver(gaussim.Options(solver=solver))
    cold = gauss.solve(problem).certificate.iterations
    warm = gauss.solve(nudged)
    again = GaussSolver(gaussim.Options(solver=solver)).solve(nudged)
    assert warm.certificate.status is again.certificate.status is SOLVED_BY[solver]
    assert warm.certificate.iterations < 10 < again.certificate.iterations and cold > 10
    difference = warm.x - again.x
    assert np.sqrt(difference @ problem.H @ difference) < 1e-8


@pytest.mark.parametrize("solver", DUAL_SOLVERS)
def test_daqp_starts_from_the_last_working_set_matched_by_row_ids(solver):
    """The next step's rows come in another order, with a new one among them (a contact appeared, a
    patch's points shifted the rows after it): DAQP starts from the rows the last solution held active,
    found by their ids (Rows.ids), in a few iterations, to the answer of a cold start of that problem
    (its rows by position would start it from the wrong ones)."""
    saved = _saved_problem("pile_wrong_sign_multiplier_full_rank.npz")
    module, n = _Given(), len(saved.l)

    def posed(order: np.ndarray, C: np.ndarray, l: np.ndarray, ids: np.ndarray) -> GaussProblem:
        rows = Rows(C[order], l[order], False, lambda: [], ids=lambda: ids[order])
        return assemble(saved.H, saved.g * (1 + 1e-6), [(module, rows)])

    first = assemble(
        saved.H, saved.g, [(module, Rows(saved.C, saved.l, False, lambda: [], ids=lambda: np.arange(n)))]
    )
    # the new row: the first one shifted far down (inactive), with an id of its own
    C, l = np.vstack([saved.C, saved.C[:1]]), np.append(saved.l, saved.l[0] - 1.0)
    order = np.r_[n, np.arange(n)[::-1]]
    nxt = posed(order, C, l, np.arange(n + 1))
    gauss = GaussSolver(gaussim.Options(solver=solver))
    assert gauss.solve(first).certificate.iterations > 10
    warm = gauss.solve(nxt)
    cold = GaussSolver(gaussim.Options(solver=solver)).solve(posed(order, C, l, np.arange(n + 1)))
    assert warm.certificate.status is cold.certificate.status is SOLVED_BY[solver]
    assert warm.certificate.iterations < 10 < cold.certificate.iterations
    difference = warm.x - cold.x
    assert np.sqrt(difference @ saved.H @ difference) < 1e-8
    held = weakref.ref(nxt)  # the solver keeps the ids of its last rows, not their problem
    del nxt
    gc.collect()
    assert held() is None


@pytest.mark.parametrize(
    "ids",
    [
        lambda n: np.arange(n, dtype=np.int32),
        lambda n: list(range(n)),
        lambda n: np.arange(n - 1),
        lambda n: np.arange(n) * 0.5,
        lambda n: np.arange(n) - 1,
        lambda n: np.arange(n) + 2**ROW_ID_BITS - n + 1,  # the last one 2**ROW_ID_BITS: out of range
        lambda n: np.arange(n, dtype=np.uint64) + np.uint64(2**63),  # beyond int64's range
    ],
)
def test_a_modules_row_ids_are_integers_per_row_or_their_places(ids):
    """Integers of any kind, one per row in [0, 2**ROW_ID_BITS), name the rows; ids of another
    length, of floats or out of range name them by their places, with a warning naming the module."""
    n, module = 5, _Given()
    rows = Rows(np.eye(n), np.zeros(n), False, lambda: [], ids=lambda: ids(n))
    given = np.asarray(ids(n))
    good = (
        given.shape == (n,) and given.dtype.kind == "i" and given.min() >= 0 and given.max() < 2**ROW_ID_BITS
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        problem = assemble(np.eye(n), np.zeros(n), [(module, rows)])
        own = problem.row_ids & (2**ROW_ID_BITS - 1)
    np.testing.assert_array_equal(own, given if good else np.arange(n))
    assert len({i >> ROW_ID_BITS for i in problem.row_ids.tolist()}) == 1
    said = [str(w.message) for w in caught if issubclass(w.category, gaussim.GaussimWarning)]
    assert (not said) if good else ("module 'given': Rows.ids" in said[0])


def test_a_new_problems_dual_start_is_the_last_multiplier_of_each_row_id():
    """The start of a new problem's rows: each row's multiplier in the last solution by its id (the
    first row of an id repeated), 0 for ids it did not have; None when no row keeps a nonzero one.
    Checked against a dictionary on random ids."""
    from gaussim.solver.dual import matched_start

    rng = np.random.default_rng(4)
    for _ in range(50):
        ids = rng.choice(60, size=rng.integers(1, 40)).astype(np.int64)  # repeats too
        multipliers = np.where(rng.random(len(ids)) < 0.5, 0.0, rng.random(len(ids)))
        new = rng.integers(0, 80, size=rng.integers(1, 50)).astype(np.int64)
        first: dict[int, float] = {}
        for i, lam in zip(ids.tolist(), multipliers.tolist()):
            first.setdefault(i, lam)
        expected = np.array([first.get(i, 0.0) for i in new.tolist()])
        start = matched_start((ids, multipliers), new)
        if expected.any():
            np.testing.assert_array_equal(start, expected)
        else:
            assert start is None
    assert matched_start(None, new) is None
    assert matched_start((np.zeros(0, np.int64), np.zeros(0)), new) is None


@pytest.mark.parametrize("solver", DUAL_SOLVERS)
def test_daqp_answers_the_check_refuses_or_inputs_it_refuses_go_to_proxqp(monkeypatch, solver):
    """Rows of integers in a read-only array (a module of the user's) are DAQP's as floats; an
    answer the KKT check refuses goes on to ProxQP."""
    C = np.array([[0, 0, 1], [1, 0, 1]])
    C.flags.writeable = False
    problem = GaussProblem(
        np.eye(3), np.array([0, 0, 9.81e-3]), np.zeros((0, 3)), np.zeros(0), C, np.zeros(2), []
    )
    solution = GaussSolver(gaussim.Options(solver=solver)).solve(problem)
    assert solution.certificate.status is SOLVED_BY[solver]
    assert solution.lambda_in == pytest.approx([9.81e-3, 0.0], abs=1e-12)
    from gaussim.solver import dual

    monkeypatch.setattr(dual, "checked", lambda *args: None)  # the check refuses DAQP's answer
    refused = GaussSolver(gaussim.Options(solver=solver)).solve(problem)
    assert refused.certificate.status is Status.SOLVED
    assert refused.lambda_in == pytest.approx([9.81e-3, 0.0], abs=1e-7)


def test_gaussims_dual_method_answers_rows_near_dependence_and_rows_that_change_kind():
    """Four small problems whose nearly dependent rows leave the working set's Gram matrix ill-conditioned
    (found by a review's fuzzing: round-off showed a row as violated, and dependent, and the method said
    infeasible): each is answered by the method, with DAQP's x (at a tight tolerance) to 1e-10 in the
    norm of H. Then a row that was an equality comes back an inequality, the other arrays the same: the
    held working set is not reused (its negative multiplier divided by zero)."""
    import daqp

    data = np.load(DATA / "dual_near_dependent.npz")
    for k in range(4):
        H, g, A, b, C, l = (data[f"{name}{k}"] for name in ("H", "g", "A", "b", "C", "l"))
        solution = GaussSolver(gaussim.Options()).solve(GaussProblem(H, g, A, b, C, l, []), warm=False)
        assert solution.certificate.status is Status.DUAL_SOLVED, (k, solution.certificate)
        sense = np.r_[np.full(len(b), 5), np.zeros(len(l))].astype(np.int32)
        x, _, flag, _ = daqp.solve(
            H, g, np.vstack([A, C]), np.r_[b, np.full(len(l), 1e30)], np.r_[b, l], sense
        )
        difference = solution.x - np.asarray(x)
        assert flag == 1 and np.sqrt(difference @ H @ difference) < 1e-10, k
    H, g, rows = np.eye(2), np.array([-2.0, -1.0]), np.eye(2)
    gauss = GaussSolver(gaussim.Options())
    with_equality = GaussProblem(H, g, rows[:1], np.array([1.0]), rows[1:], np.array([5.0]), [])
    inequalities = GaussProblem(H, g, rows[:0], np.zeros(0), rows, np.array([1.0, 5.0]), [])
    for problem, x, multipliers in [
        (with_equality, [1.0, 5.0], [-1.0, 4.0]),
        (inequalities, [2.0, 5.0], [0.0, 4.0]),
        (with_equality, [1.0, 5.0], [-1.0, 4.0]),  # an equality outside the held set: not infeasible
    ]:
        solution = gauss.solve(problem, warm=False)
        assert solution.certificate.status is Status.DUAL_SOLVED, solution.certificate
        np.testing.assert_allclose(solution.x, x, atol=1e-12)
        np.testing.assert_allclose(solution.multipliers, multipliers, atol=1e-12)


def test_a_start_set_in_banded_order_keeps_its_factors_in_a_narrow_envelope():
    """A chain of bodies, each touching the next, its rows in shuffled order (row k reads coordinates
    c_k and c_k + 1) and so are their start multipliers: the working set comes in chain order (reverse
    Cuthill-McKee), each factor row starts at the row before it, and the factors are still those of
    the rows' Gram matrix."""
    from gaussim.kernels import dual

    n, rng = 40, np.random.default_rng(3)
    m = n - 1
    ptr = np.arange(0, 2 * m + 1, 2, dtype=np.int64)
    chain = rng.permutation(m)
    idx = np.repeat(chain, 2) + np.tile([0, 1], m)
    val = rng.uniform(0.5, 1.5, 2 * m)
    masks = np.array([(1 << (c * 64 // n)) | (1 << ((c + 1) * 64 // n)) for c in chain], dtype=np.int64)
    start = rng.permutation(np.arange(1.0, m + 1.0))
    W, F, pos = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64), np.empty(m, dtype=np.int64)
    Lw, Dw, lam = np.zeros((n, n)), np.empty(n), np.empty(n)
    size = dual.start_set(
        ptr, idx, val, masks, 0, start, 1e-10, W, Lw, Dw, F, lam, pos, np.zeros(n), np.zeros(n)
    )
    assert size == m
    assert np.all(np.abs(np.diff(chain[W[:m]])) == 1)  # the chain, from one end
    np.testing.assert_array_equal(F[1:m], np.arange(m - 1))
    rows = np.zeros((m, n))
    for k in range(m):
        rows[k, idx[ptr[k] : ptr[k + 1]]] = val[ptr[k] : ptr[k + 1]]
    factor = np.tril(Lw[:m, :m], -1) + np.eye(m)
    np.testing.assert_allclose(factor @ np.diag(Dw[:m]) @ factor.T, rows[W[:m]] @ rows[W[:m]].T, atol=1e-12)


def test_a_robots_rows_stay_on_their_limb_in_least_distance_form(solo12):
    """The dual method factors M leaves first (its coordinates reversed: Pinocchio puts a joint after its
    parent), so L^-1 a of a foot's contact row reads the base and that leg alone (9 of Solo-12's 18
    coordinates), as the row does; M's factor is exact (L L^T is M reversed) and so are the rows' Gram
    products (m_i . m_j = a_i M^-1 a_j)."""
    import pinocchio as pin

    from gaussim.kernels import dual

    model, data = solo12.model, solo12.model.createData()
    q = pin.neutral(model)
    M = pin.crba(model, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    feet = [f.name for f in model.frames if f.name.endswith("_FOOT")]
    rows = np.vstack(
        [pin.getFrameJacobian(model, data, model.getFrameId(f), pin.LOCAL_WORLD_ALIGNED)[:3] for f in feet]
    )
    n, m = model.nv, len(rows)
    L, first, parent = np.zeros((n, n)), np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
    assert dual.envelope_cholesky(M, L, first, parent)
    np.testing.assert_allclose(L @ L.T, M[::-1, ::-1], atol=1e-12)
    ptr, idx, val = np.empty(m + 1, dtype=np.int64), np.empty(m * n, dtype=np.int64), np.empty(m * n)
    masks = np.empty(m, dtype=np.int64)
    dual.transformed_rows(
        L, first, parent, rows, ptr, idx, val, masks, np.zeros(n), np.full(n, -1, dtype=np.int64)
    )
    assert np.all(np.diff(ptr) <= 9) and len(feet) == 4
    dense = np.zeros((m, n))
    for k in range(m):
        dense[k, idx[ptr[k] : ptr[k + 1]]] = val[ptr[k] : ptr[k + 1]]
    np.testing.assert_allclose(dense @ dense.T, rows @ np.linalg.solve(M, rows.T), atol=1e-9)


def test_the_bound_response_is_the_derivative_of_daqps_solution():
    """bound_response's R[i, j] = V[i] . dx, dx the move of the solution when group j's active bounds
    rise by 1, against DAQP's solutions (Arnström et al.'s solver, not gaussim's) of the problem with
    those bounds raised by 1e-7: on 12 coordinates, 2 equality rows and 30 inequality rows, one of
    them a copy of an active row (dependent: left out of the factorization, its group's move
    consistent), a group of active rows, one of a single active row, one of inactive rows (its column
    0: they carry no force). Equality rows read only through the active set."""
    import daqp

    from gaussim.kernels.solver import ACTIVE_SET_FLOOR as FLOOR
    from gaussim.kernels.solver import bound_response

    rng = np.random.default_rng(5)
    n, n_eq, n_in = 12, 2, 30
    B = rng.normal(size=(n, n))
    H, g = B @ B.T + n * np.eye(n), rng.normal(size=n) * 10
    A, C, inside = rng.normal(size=(n_eq, n)), rng.normal(size=(n_in, n)), rng.normal(size=n)
    b, l = A @ inside, C @ inside - rng.uniform(0.0, 1.0, n_in)  # feasible: inside meets every row

    def solved(lower: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        sense = np.r_[np.full(n_eq, 5), np.zeros(len(lower))].astype(np.int32)  # 5: equality
        upper = np.r_[b, np.full(len(lower), 1e30)]
        x, _, flag, info = daqp.solve(H, g, np.vstack([A, C_]), upper, np.r_[b, lower], sense)
        assert flag == 1
        return np.asarray(x), -np.asarray(info["lam"])[n_eq:]

    C_ = C
    x, z = solved(l)
    active = np.flatnonzero(z > 1e-9)
    assert 4 <= len(active) <= n - n_eq
    C_, l = np.vstack([C, C[active[0]]]), np.r_[l, l[active[0]]]  # a copy of an active row
    x, z = solved(l)
    group = np.full(n_in + 1, -1)
    group[[active[0], n_in]] = 0  # the row and its copy: a consistent move
    group[active[1:3]] = 1
    group[active[3]] = 2
    inactive = np.flatnonzero(z <= 0.0)[:3]
    group[inactive] = 3
    V = rng.normal(size=(4, n))
    R = bound_response(H, A, C_, z, FLOOR, group, V)
    step = 1e-7
    for j in range(4):
        moved = l.copy()
        moved[group == j] += step
        x_moved, z_moved = solved(moved)
        assert np.array_equal(z_moved > 1e-9, z > 1e-9)  # the active set stays
        np.testing.assert_allclose(R[:, j], V @ (x_moved - x) / step, rtol=1e-5, atol=1e-6)
    assert np.all(R[:, 3] == 0.0) and np.abs(R[:, :3]).min() > 1e-3


def test_the_independent_cholesky_leaves_out_the_rows_that_depend_on_the_ones_before():
    """Rows 3 (= row 0 + row 1) and 5 (= 2 row 2) of W make G = W W^T singular: the factor keeps the
    others, whose L L^T is G there, and leaves the identity's rows in place of the two."""
    from gaussim.linalg import independent_cholesky

    W = np.random.default_rng(2).normal(size=(6, 8))
    W[3], W[5] = W[0] + W[1], 2.0 * W[2]
    G = W @ W.T
    L, kept = independent_cholesky(G, 1e-6)
    assert kept.tolist() == [True, True, True, False, True, False]
    np.testing.assert_allclose((L @ L.T)[np.ix_(kept, kept)], G[np.ix_(kept, kept)], rtol=1e-12)
    np.testing.assert_array_equal(L[~kept], np.eye(6)[~kept])
    np.testing.assert_array_equal(L[:, ~kept][kept], 0.0)
