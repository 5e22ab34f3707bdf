"""Unilateral contacts, restitution and Coulomb friction against analytic solutions."""

import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import gaussim

from .conftest import G, at_height, run

SCENES = Path(__file__).resolve().parents[1] / "robots" / "scenes"

SCHEMES = ["velocity", "acceleration"]
RESTING_PENETRATION = 1e-6  # [m]
SLIDING_DISTANCE_RTOL = 0.01
LIFT_OFF_TOLERANCE = 1e-6  # [m]
INCLINE_RTOL = 0.01
STICK_SPEED = 1e-6  # [m/s]
FORCE_BALANCE_RTOL = 1e-3
SLIP_ATOL = 1e-5  # [m/s]: the accurate mode stops its De Saxce iteration near its fixed point
HOP_RTOL = 0.02  # the discrete flight's apex is higher by about v_n dt / 2
RADIUS = 0.1  # ball radius [m]
HALF_HEIGHT = 0.05  # box half height [m]


def _ball_drop(ball, scheme, restitution, height=1.0, steps=3000):
    scene = gaussim.Scene(ball, ground=gaussim.Ground(friction=0.8, restitution=restitution))
    sim = gaussim.Simulator(scene, gaussim.Options(scheme=scheme, dt=1e-3))
    z = []
    run(
        sim,
        sim.reset(at_height(ball, height + RADIUS)),
        steps,
        each=lambda s: z.append((s.q[2] - RADIUS, s.v[2])),
    )
    return sim, np.array(z)


@pytest.mark.parametrize("scheme", SCHEMES)
def test_ball_comes_to_rest_without_penetration(ball, scheme):
    sim, z = _ball_drop(ball, scheme, 0.0)
    settled = z[1000:]
    assert settled[:, 0].min() > -RESTING_PENETRATION
    assert np.abs(settled[:, 1]).max() < 1e-6
    assert sim.last_step.contacts[0].normal_force == pytest.approx(G * ball.mass, rel=1e-6)


@pytest.mark.parametrize("scheme", SCHEMES)
def test_rebound_height_with_restitution(ball, scheme):
    h, e, dt = 1.0, 0.5, 1e-3
    _, z = _ball_drop(ball, scheme, e, height=h, steps=1500)
    rising = np.flatnonzero(z[:, 1] > 0)[0]
    falling = rising + np.flatnonzero(z[rising:, 1] < 0)[0]
    apex = z[rising : falling + 1, 0].max()
    # The impact is resolved at the step the gap closes, up to one step's travel early:
    # the apex error is at most |v_impact| dt (documented in docs/accuracy in the README).
    v_impact = np.sqrt(2 * G * h)
    assert abs(apex - e**2 * h) <= v_impact * dt


def _sliding_box(box, mode, heading, scheme="velocity", mu=0.5, steps=400):
    scene = gaussim.Scene(box, ground=gaussim.Ground(friction=mu))
    sim = gaussim.Simulator(scene, gaussim.Options(scheme=scheme, friction_mode=mode, friction_facets=4))
    v0 = np.array([np.cos(heading), np.sin(heading), 0, 0, 0, 0])
    heights = []
    state = run(sim, sim.reset(at_height(box, HALF_HEIGHT), v0), steps, each=lambda s: heights.append(s.q[2]))
    return state, np.array(heights)


@pytest.mark.parametrize("heading", [0.0, np.pi / 12, np.pi / 6, np.pi / 4])
@pytest.mark.parametrize("scheme", SCHEMES)
def test_sliding_block_stopping_distance_and_no_lift_off(box, heading, scheme):
    mu = 0.5
    state, heights = _sliding_box(box, "accurate", heading, scheme, mu)
    distance = np.linalg.norm(state.q[:2])
    assert distance == pytest.approx(1.0 / (2 * mu * G), rel=SLIDING_DISTANCE_RTOL)
    assert np.abs(heights - HALF_HEIGHT).max() < LIFT_OFF_TOLERANCE
    assert np.linalg.norm(state.v) < STICK_SPEED
    heading_drift = np.arctan2(state.q[1], state.q[0]) - heading
    assert abs(heading_drift) < 1e-6, "the pyramid turned against the slip has no anisotropy"


@pytest.mark.parametrize("dt", [1e-3, 1e-4])
def test_pyramid_relaxation_hops_as_its_dual_cone_says(box, dt):
    """The plain convex relaxation (Anitescu's, MuJoCo's) puts the contact velocity in the dual of the
    pyramid: sliding along a facet, the normal velocity is mu |slip|. A box launched at v0 is
    projected onto that boundary in its first step, leaves at v_t = v0 / (1 + mu^2), v_n = mu v_t, and
    flies ballistically to (mu v_t)^2 / (2 g) (32.6 mm at v0 = 2 m/s, mu = 0.5), whatever dt."""
    mu, v0 = 0.5, 2.0
    scene = gaussim.Scene(box, ground=gaussim.Ground(friction=mu))
    sim = gaussim.Simulator(scene, gaussim.Options(dt=dt, friction_mode="pyramid"))
    state = sim.step(sim.reset(at_height(box, HALF_HEIGHT), np.array([v0, 0, 0, 0, 0, 0])))
    slip, normal = state.v[0], state.v[2]
    assert normal == pytest.approx(mu * slip, rel=1e-9), "on the dual cone's boundary"
    assert slip == pytest.approx((v0 - mu * G * dt) / (1 + mu**2), rel=1e-9)  # the projection of v_free
    heights = []
    run(sim, state, round(0.12 / dt), each=lambda s: heights.append(s.q[2]))
    hop = max(heights) - HALF_HEIGHT
    assert hop == pytest.approx((mu * v0 / (1 + mu**2)) ** 2 / (2 * G), rel=HOP_RTOL)


def test_restitution_threshold_separates_elastic_from_inelastic_impacts(ball):
    """An approach slower than Options.restitution_threshold lands inelastically, a faster one
    rebounds at e times its speed (the ball starts touching the ground: its first step is the impact;
    gravity changes the speed by at most g dt within it)."""
    e, threshold, dt = 0.5, 0.3, 1e-3
    scene = gaussim.Scene(ball, ground=gaussim.Ground(restitution=e))
    for scheme in SCHEMES:
        options = gaussim.Options(scheme=scheme, dt=dt, restitution_threshold=threshold)
        for speed, rebound in ((0.8 * threshold, 0.0), (1.2 * threshold, e * 1.2 * threshold)):
            sim = gaussim.Simulator(scene, options)
            state = sim.step(sim.reset(at_height(ball, RADIUS), np.array([0, 0, -speed, 0, 0, 0])))
            assert abs(state.v[2] - rebound) <= G * dt + 1e-9, (scheme, speed)


@pytest.mark.parametrize("heading", [0.0, np.pi / 6])
def test_acceleration_scheme_reports_the_sliding_friction(box, heading):
    """In the acceleration scheme a sliding contact's friction is applied outside the QP; the reported
    forces include it: a box sliding flat carries m g up and mu m g against its slip."""
    mu = 0.5
    scene = gaussim.Scene(box, ground=gaussim.Ground(friction=mu))
    sim = gaussim.Simulator(scene, gaussim.Options(scheme="acceleration"))
    slip = np.array([np.cos(heading), np.sin(heading), 0.0])
    state = sim.reset(at_height(box, HALF_HEIGHT), np.r_[slip, 0, 0, 0])
    weight = box.mass * G
    for _ in range(50):  # 0.05 s: it slows from 1 to 0.75 m/s
        state = sim.step(state)
        np.testing.assert_allclose(
            sim.last_step.total_contact_force(),
            weight * (np.array([0, 0, 1.0]) - mu * slip),
            atol=1e-6 * weight,
        )


def test_slow_approach_is_an_impact(ball):
    """Acceleration scheme: a resting contact approached at 1 mm/s is an impact (Simulator's
    IMPACT_TOLERANCE is 1e-9 m/s): the velocity after the step satisfies the contact row, where the
    Baumgarte term alone would leave it sinking at 0.6 mm/s."""
    sim = gaussim.Simulator(
        gaussim.Scene(ball, ground=gaussim.Ground()), gaussim.Options(scheme="acceleration")
    )
    state = sim.step(sim.reset(at_height(ball, RADIUS), np.array([0, 0, -1e-3, 0, 0, 0])))
    assert sim.last_step.impact is not None
    assert -1e-9 < state.v[2] < 1e-6, "the approach stopped, the contact row held"


def test_robot_robot_contact_takes_the_scene_self_contact_materials(tmp_path):
    """Contacts between two robot geometries use Scene.self_contact = (friction, restitution).
    Restitution: two free cubes 1 and 10 kg, no gravity, meet at 1 m/s and part at e m/s, momentum
    kept. Friction: the 10 kg cube slides at 1 m/s on the 1 kg one, itself on frictionless ground;
    mu 10 g decelerates the top at mu g and drives the bottom at 10 mu g."""
    from gaussim.bench.cases import BOX_SIDE, two_boxes

    mu, e, dt = 0.3, 0.6, 1e-3
    robot = two_boxes(tmp_path / "pair.urdf", 1.0, 10.0)
    q = robot.neutral()
    q[2], q[9] = BOX_SIDE / 2, 1.5 * BOX_SIDE  # the top cube rests on the bottom one
    pairs = [("top_0", "bottom_0")]
    scene = gaussim.Scene(robot, contacts=pairs, self_contact=(mu, e), gravity=(0, 0, 0))
    sim = gaussim.Simulator(scene, gaussim.Options(dt=dt))
    v = np.zeros(robot.model.nv)
    v[8] = -1.0  # the top cube's vertical velocity
    state = sim.step(sim.reset(q, v))
    np.testing.assert_allclose([state.v[8] - state.v[2], state.v[2] + 10 * state.v[8]], [e, -10.0], atol=1e-9)

    ground = gaussim.Ground(friction=0.0)
    scene = gaussim.Scene(
        robot, ground=ground, contacts=[("bottom_0", "ground"), *pairs], self_contact=(mu, e)
    )
    sim = gaussim.Simulator(scene, gaussim.Options(dt=dt))
    v = np.zeros(robot.model.nv)
    v[6] = 1.0  # the top cube slides along x
    steps = 20
    state = run(sim, sim.reset(q, v), steps)
    t = steps * dt
    np.testing.assert_allclose([state.v[6], state.v[0]], [1 - mu * G * t, 10 * mu * G * t], atol=SLIP_ATOL)


def test_exact_mode_reaches_the_fixed_point(box):
    _, heights = _sliding_box(box, "exact", np.pi / 6)
    assert np.abs(heights - HALF_HEIGHT).max() < 1e-9


def _incline(box, slope, scheme, mu=0.5, steps=1000):
    theta = np.arctan(slope)
    normal = np.array([-np.sin(theta), 0.0, np.cos(theta)])
    scene = gaussim.Scene(box, ground=gaussim.Ground(friction=mu, normal=normal))
    sim = gaussim.Simulator(scene, gaussim.Options(scheme=scheme))
    q = box.neutral()
    q[:3] = HALF_HEIGHT * normal
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0, -theta, 0)).coeffs()
    state = run(sim, sim.reset(q), steps)
    return theta, state, q


@pytest.mark.parametrize("scheme", SCHEMES)
def test_block_sticks_on_a_gentle_incline(box, scheme):
    _, state, q0 = _incline(box, 0.5 - 0.02, scheme)
    assert np.linalg.norm(state.v) < STICK_SPEED
    assert np.linalg.norm(state.q[:3] - q0[:3]) < 1e-6, "no creep"


@pytest.mark.parametrize("scheme", SCHEMES)
def test_block_slides_on_a_steep_incline(box, scheme):
    mu = 0.5
    theta, state, _ = _incline(box, mu + 0.02, scheme, mu)
    acceleration = G * (np.sin(theta) - mu * np.cos(theta))
    assert np.linalg.norm(state.v[:3]) == pytest.approx(acceleration * state.t, rel=INCLINE_RTOL)


@pytest.mark.parametrize("scheme", SCHEMES)
def test_solo12_dropped_settles_on_its_feet(solo12, scheme):
    scene = gaussim.Scene(solo12, ground=gaussim.Ground(friction=0.8))
    sim = gaussim.Simulator(scene, gaussim.Options(scheme=scheme, dt=1e-3))
    q_ref = solo12.configuration("standing")
    q0 = q_ref.copy()
    q0[2] += 0.01

    def hold(state):
        return 5.0 * (q_ref[7:] - state.q[7:]) - 0.2 * state.v[6:]

    state = run(sim, sim.reset(q0), 2000, tau=hold)
    report = sim.last_step
    assert np.linalg.norm(state.v) < 1e-5, "at rest after 2 s"
    weight = solo12.mass * G
    assert report.total_contact_force()[2] == pytest.approx(weight, rel=FORCE_BALANCE_RTOL)
    assert min(c.gap for c in report.contacts) > -RESTING_PENETRATION
    loaded = {c.geometry for c in report.contacts if c.normal_force > 1e-6}
    assert loaded == {"FL_FOOT_0", "FR_FOOT_0", "HL_FOOT_0", "HR_FOOT_0"}, "it stands on its feet"
    for contact in report.contacts:
        assert np.linalg.norm(contact.tangential_force) <= 0.8 * contact.normal_force + 1e-9


def test_box_face_contact_is_flagged_redundant(box):
    sim = gaussim.Simulator(gaussim.Scene(box, ground=gaussim.Ground()))
    run(sim, sim.reset(at_height(box, HALF_HEIGHT)), 10)
    report = sim.last_step
    assert len(report.contacts) == 4, "a box face on the ground touches at its four corners"
    assert report.redundant
    assert report.total_contact_force()[2] == pytest.approx(box.mass * G, rel=1e-6)


EVEN_SPLIT_RTOL = 1e-6  # the reported split's distance from the least-norm one, relative to the load


@pytest.mark.parametrize("solver", ["dual", "proxqp"])
def test_redundant_contacts_report_the_even_split_whichever_solver(box, solver):
    """A box resting on its face: each corner carries a quarter of its weight and no friction. A dual
    active-set answer is a vertex of the multipliers' set (3.68, 1.23, 1.23, 3.68 N, each at the cone's
    edge, the corners pushing each other sideways: tried as a new user would, on box_stack); the least-norm
    one of that set is reported, whichever solver found the (unique) motion."""
    sim = gaussim.Simulator(gaussim.Scene(box, ground=gaussim.Ground()), gaussim.Options(solver=solver))
    run(sim, sim.reset(at_height(box, HALF_HEIGHT)), 50)
    report, weight = sim.last_step, box.mass * G
    assert report.redundant and len(report.contacts) == 4
    for contact in report.contacts:
        assert contact.normal_force == pytest.approx(weight / 4, rel=EVEN_SPLIT_RTOL)
        assert np.linalg.norm(contact.tangential_force) <= EVEN_SPLIT_RTOL * weight


def test_a_resting_stack_reports_no_friction_and_each_box_its_load():
    """robots/scenes/box_stack.toml at rest: every contact's friction is zero, and each box's four corners
    share what rests on them evenly (the stack's weight above each interface: the top box's, two boxes',
    all three)."""
    spec = gaussim.load_scene(SCENES / "box_stack.toml")
    sim = gaussim.Simulator(spec.scene, spec.options)
    run(sim, sim.reset(spec.initial.q, spec.initial.v), 500)
    report = sim.last_step
    loads = {}
    for contact in report.contacts:
        pair = contact.geometry.split("_")[0] + "/" + contact.obstacle.split("_")[0]
        loads.setdefault(pair, []).append(contact.normal_force)
        assert np.linalg.norm(contact.tangential_force) <= EVEN_SPLIT_RTOL * contact.normal_force, (
            contact.name
        )
    for pair in ("bottom/ground", "top/middle"):
        forces = loads[pair]
        assert len(forces) == 4 and np.ptp(forces) <= EVEN_SPLIT_RTOL * max(forces), (pair, forces)
    assert sum(loads["bottom/ground"]) == pytest.approx(spec.robot.mass * G, rel=1e-6)


def test_the_reported_reactions_certify_the_step_as_the_solvers_do(box):
    """The reported multipliers of a resting box (a dual active-set vertex is the solver's) are another
    point of the multipliers' set: they satisfy the step's KKT conditions, and their total force is the
    solver's."""
    from gaussim.solver.certificate import kkt_residuals

    sim = gaussim.Simulator(gaussim.Scene(box, ground=gaussim.Ground()))
    run(sim, sim.reset(at_height(box, HALF_HEIGHT)), 50)
    report = sim.last_step
    problem, x, solver_multipliers, eps_abs = report.solved
    spread = np.concatenate([lam for _, _, lam in report._spread])
    assert not np.allclose(spread, solver_multipliers), "the even split is another point of the set"
    n_eq = len(problem.b)
    relative = kkt_residuals(
        problem.H, problem.g, problem.A, problem.b, problem.C, problem.l, x, spread[:n_eq], spread[n_eq:]
    )[1]
    assert relative <= 100 * eps_abs
    solvers = [
        force
        for module, rows, lam in report.blocks
        if module.name == "contact"
        for force in module.reactions(rows, lam, report.scale)
    ]
    total = sum(c.force for c in solvers)
    assert report.total_contact_force() == pytest.approx(total, rel=1e-7, abs=1e-9 * box.mass * G)


@pytest.mark.parametrize("extra", [0, 1])
def test_two_equal_rows_share_their_load_up_to_the_size_cap(extra):
    """min 1/2 |x|^2 s.t. x_0 >= 1, posed twice: x = e_0, and any z >= 0 with z_1 + z_2 = 1 certifies it.
    The reported split is (1/2, 1/2) (closed form), up to LEAST_NORM_UP_TO coordinates; beyond, the
    solver's (1, 0)."""
    from gaussim.assembly import GaussProblem
    from gaussim.solver.reactions import LEAST_NORM_UP_TO, least_norm_multipliers

    n = LEAST_NORM_UP_TO + extra
    C = np.zeros((2, n))
    C[:, 0] = 1.0
    problem = GaussProblem(np.eye(n), np.zeros(n), np.zeros((0, n)), np.zeros(0), C, np.ones(2), [])
    x, solvers = np.eye(n)[0], np.array([1.0, 0.0])
    expected = solvers if extra else np.array([0.5, 0.5])
    assert least_norm_multipliers(problem, x, solvers, 1e-9) == pytest.approx(expected, abs=1e-12)


def test_ball_is_not_redundant(ball):
    sim = gaussim.Simulator(gaussim.Scene(ball, ground=gaussim.Ground()))
    run(sim, sim.reset(at_height(ball, RADIUS)), 10)
    assert len(sim.last_step.contacts) == 1
    assert not sim.last_step.redundant


def test_ball_rests_on_a_box_obstacle(ball):
    obstacle = gaussim.Box("table", size=(1, 1, 0.5), position=(0, 0, 0.25))
    sim = gaussim.Simulator(gaussim.Scene(ball, obstacles=[obstacle]))
    state = run(sim, sim.reset(at_height(ball, 0.5 + RADIUS + 0.05)), 1000)
    assert state.q[2] == pytest.approx(0.5 + RADIUS, abs=RESTING_PENETRATION)
    assert sim.last_step.contacts[0].obstacle == "table"


def test_no_stale_contact_force_after_lift_off(ball):
    """A resting ball pulled up loses its contact force at once (tests/test_solver.py checks the
    stale warm start of ProxQP 0.8 that would keep it)."""
    sim = gaussim.Simulator(gaussim.Scene(ball, ground=gaussim.Ground()))
    state = run(sim, sim.reset(at_height(ball, RADIUS)), 50)
    assert sim.last_step.contacts[0].normal_force == pytest.approx(G * ball.mass, rel=1e-6)
    lift = np.array([0, 0, 2 * G * ball.mass, 0, 0, 0])  # a 2 m g upward force on the free flyer
    for _ in range(3):
        v_before = state.v[2]
        state = sim.step(state, lift)
        if sim.last_step.contacts:  # still within the detection margin
            assert np.linalg.norm(sim.last_step.contacts[0].force) < 1e-9
        assert (state.v[2] - v_before) / sim.options.dt == pytest.approx(G, rel=1e-9)


def test_very_high_friction_neither_sinks_nor_gains_energy(box):
    """mu = 1000, a block sliding at 1 m/s: the De Saxce shift's fixed point is out of reach (each pass
    divides its error by 1 + 1/mu^2), and the lagged shift let the block sink through the ground under
    a tiny normal force, then threw it 0.9 m up. The step now drops the shift (and says so): the
    block stops at once and tips on its leading edge, never below the ground nor above the height its
    kinetic energy allows. (ProxQP may stop at its cap on one step of the 500, seen in 1 process of 8:
    that step is reported, not fatal, and counted.)"""
    sim = gaussim.Simulator(
        gaussim.Scene(box, ground=gaussim.Ground(friction=1000.0)), gaussim.Options(on_failure="report")
    )
    state = sim.reset(at_height(box, HALF_HEIGHT), np.array([1.0, 0, 0, 0, 0, 0]))
    state = sim.step(state)
    assert sim.last_step.friction_relaxed
    lowest = highest = HALF_HEIGHT
    unconverged = 0
    for _ in range(500):
        state = sim.step(state)
        assert min(c.gap for c in sim.last_step.contacts) > -1e-6 if sim.last_step.contacts else True
        lowest, highest = min(lowest, state.q[2]), max(highest, state.q[2])
        unconverged += not sim.last_step.converged
    assert unconverged <= 2
    assert lowest > HALF_HEIGHT - 1e-6
    assert highest < HALF_HEIGHT + 1.0 / (2 * G)
    assert np.linalg.norm(state.q[:2]) < 1e-3, "it stops at once"


@pytest.mark.parametrize("dt", [5e-3, 2e-2, 5e-2])
def test_velocity_scheme_closes_a_fast_approach_at_any_step(ball, dt):
    """The contact margin grows with what a step can travel, so a ball falling 1 m is found the step
    before it lands and never penetrates, whatever dt (a fixed 5 mm margin let it sink 4.3 mm at
    dt = 5e-3); at rest it is back near Options.contact_margin plus a free step's fall, g dt^2."""
    sim = gaussim.Simulator(gaussim.Scene(ball, ground=gaussim.Ground()), gaussim.Options(dt=dt))
    lowest = []
    run(sim, sim.reset(at_height(ball, RADIUS + 1.0)), round(2.0 / dt), each=lambda s: lowest.append(s.q[2]))
    assert min(lowest) - RADIUS > -1e-9
    assert abs(lowest[-1] - RADIUS) < 1e-6
    assert sim.detector.schedule.margin <= 3 * (sim.options.contact_margin + G * dt**2)


def _slips_reference(J, slip, starts, x, normal, mu, rows, bound):
    """The slip update of gaussim.kernels.contact.slips, written plainly with numpy."""
    from gaussim.kernels.contact import SLIP_SPEED

    result, residual = slip.copy(), 0.0
    for i in range(len(slip)):
        if starts[i + 1] - starts[i] == 1:
            continue
        u = J[i] @ x
        u -= (u @ normal[i]) * normal[i]
        if np.linalg.norm(slip[i]) > SLIP_SPEED or np.linalg.norm(u) > SLIP_SPEED:
            mine = slice(starts[i], starts[i + 1])
            slack = max((rows[mine] @ x - bound[mine]).min(), 0.0)
            residual = max(residual, mu[i] * abs(np.linalg.norm(u) - np.linalg.norm(slip[i])) - slack)
            result[i] = u
    return result, residual


def test_slip_update_matches_its_plain_statement():
    """The compiled slip update (scalars) gives the plain one's answer: every moving contact's new
    slip, and the largest error of the shifted bounds, mu times the change of a slip's norm less the
    slack of its rows; sticking contacts (one row) and resting ones (slow) keep their slip."""
    from gaussim.kernels.contact import SLIP_SPEED, slips

    rng = np.random.default_rng(7)
    m, nv, facets = 6, 9, 4
    starts = np.array([0, 4, 5, 9, 13, 17, 21])  # contact 1 sticks: one row
    J, x = rng.normal(size=(m, 3, nv)), rng.normal(size=nv)
    J[3] *= 1e-9  # contact 3 barely moves ...
    normal = rng.normal(size=(m, 3))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    slip = rng.normal(size=(m, 3))
    slip[3] = 0.1 * SLIP_SPEED  # ... and has not moved: it keeps its slip
    mu = np.array([0.5, 0.8, 0.7, 0.3, 0.6, 0.9])  # below 1, where the old max(1, mu) rule would differ
    R = starts[-1]
    rows = rng.normal(size=(R, nv))
    bound = rows @ x - rng.uniform(-0.05, 0.05, R)  # slacks of either sign
    # the slips the QP used are given apart from the buffer (a later pass's): the packed ones are not read
    packed = np.concatenate(
        [J.ravel(), rng.normal(size=3 * R), rng.normal(size=3 * m), rng.normal(size=3 * m)]
    )
    assert facets * m - 3 == R
    # every row reads all nv coordinates: joint 1's support is all of them, the world's (0) none
    joints, world, support = np.ones(m, np.int64), np.zeros(m, np.int64), np.array([0, 0, nv])

    def both(bound):
        start = np.empty((m, 3))
        got, residual, stuck = slips(
            packed, slip, starts, x, normal, mu, rows, bound, joints, world, support, np.arange(nv), start
        )
        sticks = np.linalg.norm(got, axis=1) <= SLIP_SPEED  # the next solve starts them stuck
        np.testing.assert_array_equal(start, np.where(sticks[:, None], np.zeros((m, 3)), np.nan))
        assert stuck == sticks.any()
        return (got, residual), _slips_reference(J, slip, starts, x, normal, mu, rows, bound)

    (got, residual), (expected, expected_residual) = both(bound)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)
    assert np.linalg.norm(got[3]) < SLIP_SPEED  # the resting one sticks
    np.testing.assert_array_equal(got[[1, 3]], slip[[1, 3]])  # the sticking and the resting
    assert residual == pytest.approx(expected_residual, rel=1e-12)
    assert residual > 0.1  # the moving contacts' changes are of order one
    # a contact whose rows keep more slack than its shift's change counts for nothing: all of them
    (got, residual), (_, expected_residual) = both(bound - 1e3)
    assert residual == expected_residual == 0.0
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)  # the slips move all the same


@pytest.mark.parametrize("scheme", SCHEMES)
def test_stage_timings_only_when_asked_and_the_motion_unchanged(ball, scheme):
    """Options(timings=True): each stage of a step has its wall time, their sum within the step's, and
    an impact's QP its own; by default nothing is recorded. The motion is the same bit for bit."""
    scene = gaussim.Scene(ball, ground=gaussim.Ground(friction=0.8))
    trajectories = {}
    for timed in (False, True):
        sim = gaussim.Simulator(scene, gaussim.Options(scheme=scheme, timings=timed))
        state = sim.reset(at_height(ball, RADIUS + 0.01), np.array([0, 0, -1.0, 0, 0, 0]))
        trajectories[timed], stages, impacts = [], set(), 0
        for _ in range(40):  # the ball lands at the 10th step and stays
            start = time.perf_counter()
            state = sim.step(state)
            wall = time.perf_counter() - start
            report = sim.last_step
            trajectories[timed].append(np.concatenate([state.q, state.v]))
            if not timed:
                assert report.timings == {} and (report.impact is None or report.impact.timings == {})
                continue
            assert all(seconds > 0 for seconds in report.timings.values())
            assert sum(report.timings.values()) <= wall
            stages |= set(report.timings)
            if report.impact is not None:
                impacts += 1
                assert set(report.impact.timings) == {"assembly", "solve"}
        if timed:
            assert stages == {"dynamics", "collision", "assembly", "solve", "integrate"}
            assert (impacts > 0) == (scheme == "acceleration")  # the velocity scheme has no impact phase
    np.testing.assert_array_equal(trajectories[False], trajectories[True])


def test_the_secant_reaches_each_contacts_fixed_point_where_plain_passes_cycle():
    """Slips s -> F(s) = a s + c per contact (a the slope of its own map; -1 is a contact that each
    pass switches between sticking and sliding): the secant passes reach s* = c / (1 - a) (the
    closed form) at the third pass for slopes whose scale 1 / (1 - a) is within SECANT_SCALES, and
    within 1e-6 in 12 passes at 0.6 (capped), where plain passes cycle at a = -1."""
    from gaussim.constraints.contact import _secant

    slopes = np.array([-1.0, -0.5, 0.3, 0.5, 0.6])
    c = np.random.default_rng(3).normal(size=(len(slopes), 3))
    fixed = c / (1.0 - slopes)[:, None]
    s, last = np.zeros_like(c), None
    for passes in range(1, 13):
        s, last = _secant(s, slopes[:, None] * s + c, last)
        if passes == 2:
            np.testing.assert_allclose(s[:4], fixed[:4], atol=1e-12)
    np.testing.assert_allclose(s, fixed, atol=1e-6)
    plain = np.zeros_like(c)
    for _ in range(8):
        plain = slopes[:, None] * plain + c
    assert np.abs(plain - fixed)[0].max() > 0.1


def test_the_passes_stall_when_two_of_them_do_not_halve_the_residual():
    from gaussim.constraints.contact import _stalled

    assert not _stalled([1e-3, 9e-4])  # too few to judge
    assert not _stalled([1e-3, 8e-4, 4.9e-4])  # halved over two passes: still converging
    assert _stalled([1e-3, 8e-4, 5.1e-4])
    assert _stalled([1e-3, 2e-3, 1e-3, 6e-4, 9e-4])  # a cycle


def test_a_turning_box_does_not_sink_the_corners_its_turn_brings_down(box):
    """A box (0.2 m wide) resting on one bottom edge, tilted 0.03 rad, turning back to flat at
    20 rad/s about that edge: its other edge, 6 mm up, comes down at 4 m/s, 4 mm a step. Its corners
    are contact points before they reach the ground (the patch as deep as the box's turn in the
    step times its size), so no corner goes below it (the eight corners from the placement, not from
    the contacts; without the widening, 2 mm)."""
    theta, w, a, h = 0.03, 20.0, 0.1, HALF_HEIGHT
    R = pin.rpy.rpyToMatrix(0.0, theta, 0.0)
    corners = np.array([[x, y, z] for x in (-a, a) for y in (-a, a) for z in (-h, h)])
    pivot = R @ np.array([a, 0.0, -h])  # the low edge's midpoint from the centre
    q = box.neutral()
    q[:3] = [0.0, 0.0, -pivot[2]]
    q[3:7] = pin.Quaternion(R).coeffs()
    omega = np.array([0.0, -w, 0.0])
    v = np.concatenate([R.T @ np.cross(omega, -pivot), R.T @ omega])  # the low edge at rest
    assert (R @ corners.T)[2].min() + q[2] == pytest.approx(0.0, abs=1e-12)
    sim = gaussim.Simulator(gaussim.Scene(box, ground=gaussim.Ground(friction=0.8)))
    lowest = []

    def record(state):
        rotation = pin.Quaternion(state.q[3:7]).toRotationMatrix()
        lowest.append(state.q[2] + (rotation @ corners.T)[2].min())

    run(sim, sim.reset(q, v), 5, each=record)
    assert min(lowest) > -1e-6, lowest


def test_a_friction_pass_moves_the_bounds_as_posing_the_rows_again_would(box, monkeypatch):
    """A box sliding to a stop: each friction pass after a step's first changes the De Saxce shift
    alone, so the last pass's rows with new bounds are taken; they equal the rows the kernel poses
    again from the lagged slip (to round-off), and the kernel poses a step's rows once."""
    from gaussim.constraints import contact

    scene = gaussim.Scene(box, ground=gaussim.Ground(friction=0.5))
    sim = gaussim.Simulator(scene, gaussim.Options(dt=1e-3))
    state = sim.reset(at_height(box, HALF_HEIGHT + 1e-4), np.array([1.0, 0.3, 0, 0, 0, 0]))
    module = next(m for m in sim.gauss.modules if isinstance(m, contact.ContactModule))
    posed, compared = [], []
    pose = contact.pyramid_rows
    refine = contact.ContactModule.refine
    monkeypatch.setattr(contact, "pyramid_rows", lambda *args: posed.append(1) or pose(*args))

    def checking(self, ctx, rows, x, multipliers):
        again = refine(self, ctx, rows, x, multipliers)
        if again and self is module:
            shifted = self.rows(ctx)
            self._posed = None  # the kernel poses them (and they are the next pass's)
            fresh = self.rows(ctx)
            np.testing.assert_array_equal(shifted.J, fresh.J)
            np.testing.assert_allclose(shifted.bound, fresh.bound, rtol=0, atol=1e-15)
            for part in ("J", "generators", "slip", "friction"):  # the record (its buffer is shared)
                np.testing.assert_array_equal(getattr(shifted.data, part), getattr(fresh.data, part))
            compared.append(shifted.bound - rows.bound)
        return again

    passes = 0
    for _ in range(150):
        state = sim.step(state)
        passes += len(sim.last_step.certificates)
    assert len(posed) == 150 < passes  # once a step; more QPs: the friction passes
    monkeypatch.setattr(contact.ContactModule, "refine", checking)
    run(sim, state, 100)
    assert len(compared) >= 50 and max(np.abs(c).max() for c in compared) > 1e-4  # the bounds moved


def test_a_contact_that_stuck_starts_the_next_step_stuck(monkeypatch):
    """A tall box set down on an edge, tilted with its centre still over its base, falls back onto its
    face pivoting on that edge, which sticks: the edge's vertices slip at the step's start velocity by
    the turn of the box (fast near the end of the fall), and a start from that slip takes a second QP
    to find them stuck again; started from the last step's stuck contacts, one QP a step does, and the
    motion is the fixed point the iteration reaches from the current slip (within its tolerance)."""
    from gaussim.constraints import contact

    body = gaussim.FreeBody.box("b", (0.1, 0.1, 0.3), mass=1.0)
    tilt = 0.2
    start = gaussim.pose(z=0.15 * np.cos(tilt) + 0.05 * np.sin(tilt), rpy=(tilt, 0.0, 0.0))

    def tipping():
        scene = gaussim.Scene(bodies={"b": body}, ground=gaussim.Ground(friction=0.8))
        sim = gaussim.Simulator(scene, gaussim.Options(dt=1e-3))
        state, qps, q, edge = sim.reset({"b": start}), [], [], []
        for _ in range(250):
            state = sim.step(state)
            qps.append(len(sim.last_step.certificates))
            q.append(state.q)
            edge.append(np.array([c.point for c in sim.last_step.contacts]))
        return np.array(qps), np.array(q), edge

    remembered, q, edge = tipping()
    monkeypatch.setattr(contact.ContactModule, "_stuck_start", lambda self, contacts, current: current)
    from_current, q_current, _ = tipping()
    assert (from_current[200:] > 1).sum() >= 20  # the fall's end: two QPs a step from the current slip
    assert (remembered[200:] > 1).sum() <= 3
    pivot = np.array(edge[:230])  # the edge's two vertices while it pivots (then the face comes near)
    assert pivot.shape == (230, 2, 3) and np.abs(pivot - pivot[0]).max() < 1e-5
    assert q[0][2] - q[230][2] > 5e-3  # it did fall back
    np.testing.assert_allclose(q, q_current, rtol=0, atol=1e-6)


@pytest.mark.parametrize(
    ("scheme", "passes", "friction", "level", "relaxed"),
    [("acceleration", 10, 0.5, "impulse", False), ("velocity", 2, 1000.0, "velocity", True)],
)
def test_a_friction_pass_at_an_impact_or_relaxed_reshifts_as_posing_again(
    box, monkeypatch, scheme, passes, friction, level, relaxed
):
    """The bounds-only passes where the rows are a subset (the acceleration scheme's impacts keep the
    closing contacts) and where the last QP drops the shift (two passes and mu = 1000, far from the
    fixed point): each pass's re-shifted rows equal the rows the kernel poses again."""
    from gaussim.constraints import contact

    scene = gaussim.Scene(box, ground=gaussim.Ground(friction=friction))
    sim = gaussim.Simulator(scene, gaussim.Options(dt=1e-3, scheme=scheme, friction_iterations=passes))
    tilt = pin.SE3ToXYZQUAT(pin.SE3(pin.rpy.rpyToMatrix(0.3, 0.2, 0.0), np.array([0.0, 0.0, 0.1])))
    state = sim.reset(tilt, np.array([1.0, 0.3, -1.0, 2.0, -3.0, 1.0]))
    module = next(m for m in sim.gauss.modules if isinstance(m, contact.ContactModule))
    refine, seen = contact.ContactModule.refine, []

    def checking(self, ctx, rows, x, multipliers):
        again = refine(self, ctx, rows, x, multipliers)
        if again and self is module and ctx.level != "acceleration":
            shifted = self.rows(ctx)
            self._posed = None
            fresh = self.rows(ctx)
            np.testing.assert_array_equal(shifted.J, fresh.J)
            np.testing.assert_allclose(shifted.bound, fresh.bound, rtol=0, atol=1e-12)
            for part in ("J", "generators", "slip", "friction"):  # the record (its buffer is shared)
                np.testing.assert_array_equal(getattr(shifted.data, part), getattr(fresh.data, part))
            assert shifted.data.relaxed == fresh.data.relaxed
            seen.append((ctx.level, shifted.data.relaxed))
        return again

    monkeypatch.setattr(contact.ContactModule, "refine", checking)
    run(sim, state, 300)
    assert (level, relaxed) in seen, sorted(set(seen))


def test_the_secant_step_matches_its_plain_statement():
    """The compiled secant step gives the numpy statement's: each contact's residual F(s) - s scaled
    by 1 / (1 - slope) within SECANT_SCALES, the slope along the last move (none at the first pass,
    none along a zero move), and the next slips s + that step."""
    from gaussim.constraints.contact import SECANT_SCALES, _secant

    rng = np.random.default_rng(11)
    m = 40
    used, mapped = rng.normal(size=(m, 3)), rng.normal(size=(m, 3))
    move, previous = rng.normal(size=(m, 3)), rng.normal(size=(m, 3))
    move[:5] = 0.0  # no move: no slope
    previous[5:10] = move[5:10] + (mapped - used)[5:10] + 5.0 * move[5:10]  # slope -5: the scale's floor

    residual = mapped - used
    length = np.einsum("mi,mi->m", move, move)
    slope = np.einsum("mi,mi->m", residual + move - previous, move) / np.where(length > 0, length, np.inf)
    scale = np.clip(1.0 / np.maximum(1.0 - slope, 1e-12), *SECANT_SCALES)
    assert {SECANT_SCALES[0], 1.0} <= set(np.round(scale, 12)) and scale.max() == SECANT_SCALES[1]

    following, (moved, got_residual) = _secant(used, mapped, (move, previous))
    np.testing.assert_allclose(got_residual, residual, rtol=0, atol=1e-15)
    np.testing.assert_allclose(moved, scale[:, None] * residual, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(following, used + scale[:, None] * residual, rtol=1e-12, atol=1e-15)
    first, (moved, _) = _secant(used, mapped, None)  # the first pass: the plain step
    np.testing.assert_allclose(first, mapped, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("velocity", [(1.0, 0.3, 0.0), (0.5, 0.2, 5.0)])
def test_the_newton_step_on_the_shifts_takes_fewer_passes_to_the_same_motion(box, monkeypatch, velocity):
    """A box sliding on its four corners at 1 m/s (and at 0.5 m/s spinning at 5 rad/s about the vertical),
    mu = 0.5, for 300 steps: the sliding corners' Newton step on their shifts (coupled through the box)
    makes fewer QPs than the secant alone (NEWTON_UP_TO = 0), 509 against 718 and 486 against 645 when
    measured. Sliding straight, the passes reach the secant's fixed point: the same motion to 1e-9.
    Spinning, the box stays on the ground as with the secant (no pass left far from the fixed point
    drops the shift, which would lift it at mu |u_t|) and comes to rest within 3 mm of where the
    secant's does (its four corners' normal forces are not unique, nor then the friction's turn)."""
    from gaussim.constraints import contact

    def slide(newton: bool) -> tuple[int, np.ndarray, int]:
        monkeypatch.setattr(contact, "NEWTON_UP_TO", 64 if newton else 0)
        sim = gaussim.Simulator(gaussim.Scene(box, ground=gaussim.Ground(friction=0.5)))
        vx, vy, spin = velocity
        state = sim.reset(at_height(box, HALF_HEIGHT + 1e-4), np.array([vx, vy, 0, 0, 0, spin]))
        qps, relaxed, path = 0, 0, []
        for _ in range(300):
            state = sim.step(state)
            qps += len(sim.last_step.certificates)
            relaxed += sim.last_step.friction_relaxed
            path.append(np.concatenate([state.q, state.v]))
        return qps, np.array(path), relaxed

    qps, path, relaxed = slide(True)
    secant_qps, secant_path, _ = slide(False)
    assert qps < 0.8 * secant_qps, (qps, secant_qps)
    assert relaxed == 0 and path[:, 2].max() < HALF_HEIGHT + 2e-4  # on the ground
    assert np.abs(path[-1, 7:]).max() < 1e-5  # at rest
    if velocity[2] == 0.0:
        np.testing.assert_allclose(path, secant_path, rtol=0, atol=1e-9)
    else:
        assert np.abs(path[-1, :2] - secant_path[-1, :2]).max() < 3e-3


@pytest.mark.parametrize("scheme", SCHEMES)
def test_a_resting_contacts_rows_do_not_turn_with_the_round_off_of_its_slip(box, scheme):
    """A box resting flat, its velocity a round-off's (1e-9 m/s along the ground, in three
    directions): its four contacts pose the same rows whatever the direction, so that a resting pile's
    QP stays the same from step to step and its last solution answers the next. A slow slip (half the
    speed below which a contact sticks) turns the friction pyramid with it: the rows then differ with
    its direction."""
    from gaussim.kernels.contact import SLIP_SPEED

    scene = gaussim.Scene(box, ground=gaussim.Ground(friction=0.5))
    sim = gaussim.Simulator(scene, gaussim.Options(scheme=scheme, dt=1e-3))
    q = at_height(box, HALF_HEIGHT)
    for speed, same in ((1e-9, True), (0.5 * SLIP_SPEED, False)):
        rows = []
        for angle in (0.3, 2.0, 4.0):
            v = np.zeros(6)
            v[:2] = speed * np.cos(angle), speed * np.sin(angle)
            sim.step(sim.reset(q, v))
            (_, posed, _), *_ = sim.last_step.blocks
            assert posed.J.shape[0] == 16  # four corners, four facets each: sticking
            rows.append(posed.J)
        assert all(np.array_equal(rows[0], r) for r in rows[1:]) == same


@pytest.mark.parametrize("noise", [1e-10, 1e-9])
def test_the_round_off_of_a_resting_contacts_gap_does_not_make_it_jitter(box, monkeypatch, noise):
    """A box resting flat whose contacts' gaps carry a narrowphase's round-off (capsules and boxes on
    one another: 1e-10 to 1e-9 m, either sign, from step to step). A closing row that let such a gap
    close within the step moved the box by gap / dt (a micro-metre per second at 1e-9 m and dt 1 ms),
    and a settled bin jittered forever at that speed (its QPs solved again at every step); within
    GAP_TOLERANCE a gap is contact, and the box rests exactly."""
    from gaussim.collision import driver
    from gaussim.kernels.contact import GAP_TOLERANCE

    assert noise <= GAP_TOLERANCE
    rng = np.random.default_rng(7)
    found = driver.ContactDetector.contacts

    def noisy(self, *args):
        contacts = found(self, *args)
        contacts.gap = contacts.gap + noise * rng.uniform(-1.0, 1.0, len(contacts.gap))
        return contacts

    monkeypatch.setattr(driver.ContactDetector, "contacts", noisy)
    scene = gaussim.Scene(box, ground=gaussim.Ground(friction=0.5))
    sim = gaussim.Simulator(scene, gaussim.Options(dt=1e-3))
    speeds = []
    run(sim, sim.reset(at_height(box, HALF_HEIGHT)), 200, each=lambda s: speeds.append(np.abs(s.v).max()))
    assert max(speeds[100:]) < 1e-12


@pytest.mark.parametrize("dt", [2e-2, 5e-3])
def test_a_box_sliding_and_spinning_stays_on_the_ground_and_stops_both_at_once(dt):
    """A flat box (0.2 x 0.2 x 0.02 m, 1 kg, mu 0.5) launched at 1 m/s spinning at 10 rad/s about the
    vertical: its corners slide in four directions, and the De Saxce passes of a step may spend the
    step's QPs closing in on the fixed point (within 1e-3 m/s) without settling. The last QP then
    dropped the shift: the plain relaxation threw the box 9 to 12 mm up, tumbling. It keeps the pass
    nearest the fixed point: the box stays on the ground and stops sliding and spinning at the same
    time (the coupled sliding and spinning friction's known result), at the time the uniformly
    loaded 4-corner planar model gives (0.248 s, scipy at rtol 1e-10) to 10 %."""
    crate = gaussim.FreeBody.box("b", (0.2, 0.2, 0.02), mass=1.0)
    sim = gaussim.Simulator(
        gaussim.Scene(bodies={"b": crate}, ground=gaussim.Ground(friction=0.5)), gaussim.Options(dt=dt)
    )
    state = sim.reset({"b": gaussim.pose(z=0.01)}, {"b": np.array([1.0, 0, 0, 0, 0, 10.0])})
    stopped: dict[str, float] = {}
    while state.t < 0.4:
        state = sim.step(state)
        assert not sim.last_step.friction_relaxed
        assert abs(state.q[2] - 0.01) < 5e-4  # a pass's residual sinks it 0.2 mm at dt = 2e-2
        if np.linalg.norm(state.v[:2]) < 1e-3:
            stopped.setdefault("sliding", state.t)
        if 0.1 * abs(state.v[5]) < 1e-3:
            stopped.setdefault("spinning", state.t)
    assert abs(stopped["sliding"] - stopped["spinning"]) <= 2.5 * dt
    assert stopped["sliding"] == pytest.approx(0.248, rel=0.1)
