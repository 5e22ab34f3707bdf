"""Islands: the Gauss problem split into the independent problems of the bodies that touch."""

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

import gaussim
from gaussim import FreeBody, pose
from gaussim.assembly import GaussProblem
from gaussim.kernels.solver import warm_islands
from gaussim.solver import GaussSolver, kkt_residual
from gaussim.solver import islands as island_module
from gaussim.solver.certificate import Status
from gaussim.solver.islands import IslandSolver, islands, members, trees

# Two runs of the same physics through different but equal models agree to this [m, m/s]: round-off
# differences decide between two certified answers (the active set's or ProxQP's), which differ within
# the QP's tolerance (eps_abs 1e-9 on the stationarity) divided by the contact's conditioning.
SAME = 1e-7
# One QP a step: the accurate friction's fixed-point iteration, whose tolerance is looser, runs over all
# islands at once.
OPTIONS = gaussim.Options(friction_mode="pyramid")


@pytest.mark.parametrize("seed", range(20))
def test_islands_are_the_connected_components_of_trees_and_rows(seed):
    """The islands of random row patterns are scipy's connected components of the graph whose nodes
    are the trees and whose edges join the trees one row reads (scanned, or told by its joints)."""
    rng = np.random.default_rng(seed)
    n_trees = int(rng.integers(1, 12))
    tree = np.sort(rng.integers(0, n_trees, size=int(rng.integers(n_trees, 40))))
    tree = np.unique(tree, return_inverse=True)[1]  # every tree holds a coordinate
    n_trees, nv = int(tree.max()) + 1, len(tree)
    rows = np.zeros((int(rng.integers(1, 15)), nv))
    for r in range(len(rows)):
        rows[r, rng.choice(nv, size=int(rng.integers(1, 3)), replace=False)] = rng.normal(size=1)
    n_eq = int(rng.integers(0, len(rows)))
    A, C = rows[:n_eq], rows[n_eq:]
    applied = np.zeros(nv)
    applied[rng.integers(0, nv)] = 1.0
    # half the rows say which joints they read (one joint per coordinate, joint 0 the world): the
    # same partition as scanning them
    joint_tree = np.concatenate([[-1], tree])
    read = np.full((len(rows), 2), -1)
    for r, row in enumerate(rows):
        if rng.random() < 0.5:
            columns = np.flatnonzero(row)
            read[r] = columns[0] + 1, (columns[-1] + 1 if len(columns) > 1 else 0)
    island_of_tree, island_of_row, n = islands(A, C, read, joint_tree, applied, tree, n_trees)

    edges = [(tree[k], tree[j]) for row in rows for k in np.flatnonzero(row) for j in np.flatnonzero(row)]
    i, j = np.array(edges).T
    graph = coo_matrix((np.ones(len(i)), (i, j)), shape=(n_trees, n_trees))
    _, component = connected_components(graph, directed=False)
    touched = np.zeros(n_trees, bool)
    touched[tree[np.flatnonzero(np.abs(rows).sum(0))]] = True
    touched[tree[np.flatnonzero(applied)]] = True
    assert (island_of_tree >= 0).tolist() == touched.tolist()
    assert n == len(np.unique(component[touched]))
    for a in range(n_trees):  # the same partition of the touched trees
        for b in range(n_trees):
            if touched[a] and touched[b]:
                assert (island_of_tree[a] == island_of_tree[b]) == (component[a] == component[b])
    for r, row in enumerate(rows):
        assert island_of_row[r] == island_of_tree[tree[np.flatnonzero(row)[0]]]
    order, start = members(island_of_tree, n)
    for island in range(n):
        expected = np.flatnonzero(island_of_tree == island)
        assert order[start[island] : start[island + 1]].tolist() == expected.tolist()


def _world(n):
    bodies = {f"b{i}": FreeBody.box(f"b{i}", (0.1, 0.1, 0.1), mass=1.0 + i) for i in range(n)}
    return gaussim.Scene(bodies=bodies, ground=gaussim.Ground()).robot.model


def _islands_problem(rng, shift=0.5):
    """Four free bodies' Gauss problem, rows on three of them (one joins body 0 and body 2, an
    equality holds body 1): the rows C x >= C x_free + ``shift``, so all active for a shift > 0."""
    blocks = []
    for _ in range(4):
        root = rng.normal(size=(6, 6))
        blocks.append(root @ root.T + 6 * np.eye(6))
    H = np.zeros((24, 24))
    for b, block in enumerate(blocks):
        H[6 * b : 6 * b + 6, 6 * b : 6 * b + 6] = block
    x_free = rng.normal(size=24)
    g = -H @ x_free
    C = np.zeros((7, 24))
    C[0:3, 0:6] = rng.normal(size=(3, 6))
    C[3, 0:6], C[3, 12:18] = rng.normal(size=6), rng.normal(size=6)
    C[4:7, 6:12] = rng.normal(size=(3, 6))
    l = C @ x_free + shift
    A, b = np.zeros((1, 24)), np.zeros(1)
    A[0, 7] = 1.0
    return GaussProblem(H, g, A, b, C, l, []), x_free


def test_the_islands_solution_is_the_whole_problems():
    """Three free bodies, rows on two of them (one row joins body 0 and body 2): the islands' x and
    multipliers solve the whole QP (gaussim's KKT check on it) and equal ProxQP's on the whole."""
    model = _world(4)
    assert trees(model).tolist() == [0] * 6 + [1] * 6 + [2] * 6 + [3] * 6
    problem, x_free = _islands_problem(np.random.default_rng(3))
    x, multipliers, certificates = IslandSolver(model, gaussim.Options()).solve(problem, x_free)
    assert len(certificates) == 2 and all(c.converged for c in certificates)
    assert kkt_residual(problem, x, multipliers[:1], multipliers[1:]) < 1e-8
    np.testing.assert_array_equal(x[18:], x_free[18:])  # body 3: no row, its free motion
    whole = GaussSolver(gaussim.Options()).solve(problem)
    np.testing.assert_allclose(x, whole.x, atol=1e-7)
    np.testing.assert_allclose(multipliers, whole.multipliers, atol=1e-6)


def test_an_islands_rows_key_is_its_sources_and_its_cut(monkeypatch):
    """A friction pass cuts the same islands from a problem with the same rows (its key) and moved
    bounds: each island's key equals the last pass's, so gaussim's dual method solves it on the
    factors it holds (one setup for the two passes); another cut, or rows posed anew, is another key."""
    from gaussim.solver.dual import SparseDualActiveSet

    problem, _ = _islands_problem(np.random.default_rng(3))
    moved = GaussProblem(problem.H, problem.g, problem.A, problem.b, problem.C, problem.l + 0.01, [])
    moved.rows_key = problem.rows_key
    anew = GaussProblem(problem.H, problem.g, problem.A, problem.b, problem.C, problem.l, [])
    cols, eq, ineq = np.arange(6), np.zeros(0, dtype=np.int64), np.arange(3)
    key = problem.island(cols, eq, ineq).rows_key
    assert moved.island(cols, eq, ineq).rows_key == key
    assert problem.island(cols, eq, ineq[:2]).rows_key != key
    assert anew.island(cols, eq, ineq).rows_key != key
    setups = []
    setup = SparseDualActiveSet._setup
    monkeypatch.setattr(SparseDualActiveSet, "_setup", lambda self, *a: setups.append(1) or setup(self, *a))
    solver = SparseDualActiveSet(1e-9, 1e-7)
    first, second = (solver.solve(p.island(cols, eq, ineq)) for p in (problem, moved))
    assert first is not None and second is not None and len(setups) == 1
    assert np.abs(second.x - first.x).max() > 1e-4  # the moved bounds' answer


@pytest.mark.parametrize("refused", [False, True])
def test_each_island_starts_from_its_own_last_solution(refused, monkeypatch):
    """The islands solved again: the same problem from each one's last solution, bounds moved a
    little on its active set (twice: the second time from the first's answer), every row let go.
    Each answer is the whole problem's (DAQP's, on the whole), multipliers in their rows; where the
    compiled pass over the islands certifies no candidate (``refused``: made to say so), each
    island's own solver solves it (and does not try it again)."""
    if refused:

        def refuses(*args):  # the pass as made, then every island refused
            warm_islands(*args)
            args[-4][:] = 0

        monkeypatch.setattr(island_module.warm_islands, "call", refuses)
    model = _world(4)
    solver = IslandSolver(model, gaussim.Options())
    problem, x_free = _islands_problem(np.random.default_rng(3))
    solver.solve(problem, x_free)
    last, active = Status.PREVIOUS_SOLUTION_CERTIFIED, Status.ACTIVE_SET_CERTIFIED
    warm = [last, active, last, active]  # the moved problem again: its own last solution
    for move, status in zip((0.0, 0.01, 0.01, -2.0), warm, strict=True):
        moved = GaussProblem(problem.H, problem.g, problem.A, problem.b, problem.C, problem.l + move, [])
        x, multipliers, certificates = solver.solve(moved, x_free)
        if refused:  # DAQP's answers or the free motion, not a candidate tried again
            assert not {c.status for c in certificates} & set(warm)
        else:
            assert [c.status for c in certificates] == [status] * 2
        whole = GaussSolver(gaussim.Options()).solve(moved)
        np.testing.assert_allclose(x, whole.x, atol=1e-7)
        np.testing.assert_allclose(multipliers, whole.multipliers, atol=1e-6)


def test_a_kept_split_serves_only_the_same_islands_all_answered_by_the_pass(monkeypatch):
    """Splits whose islands the compiled pass answers all are kept for the next split of the same
    islands. Two problems of the same sizes and different islands (one row joins bodies 0 and 2, or
    bodies 1 and 3) in turn, each again; then a problem whose body 1 island the pass is made to
    refuse (its solver answers) and that problem again, which starts from its solver's answer, not
    from the kept split's: every answer is the whole problem's, and each island's status says where
    it came from."""
    refuse = [False]

    def passes(*args):  # the pass as made; then, told to, body 1's island (the last) refused
        last_x, last_m, how = args[8], args[9], args[11]
        before = last_x[12:].copy(), last_m[4:].copy()
        warm_islands(*args)
        if refuse[0]:
            how[1] = 0
            last_x[12:], last_m[4:] = before

    monkeypatch.setattr(island_module.warm_islands, "call", passes)
    model = _world(4)
    solver = IslandSolver(model, gaussim.Options())
    rng = np.random.default_rng(5)
    joined, x_free = _islands_problem(rng)
    other = joined.C.copy()
    other[3] = 0.0
    other[3, 6:12], other[3, 18:24] = rng.normal(size=6), rng.normal(size=6)
    regrouped = GaussProblem(joined.H, joined.g, joined.A, joined.b, other, other @ x_free + 0.5, [])
    sequence = [(joined, 0.0), (joined, 0.0), (joined, 0.01), (regrouped, 0.0), (regrouped, 0.0)]
    sequence += [(regrouped, 0.01), (joined, 0.02), (joined, 0.03), (joined, 0.03)]
    statuses = []
    for k, (problem, move) in enumerate(sequence):
        refuse[0] = k == 7
        moved = GaussProblem(problem.H, problem.g, problem.A, problem.b, problem.C, problem.l + move, [])
        x, multipliers, certificates = solver.solve(moved, x_free)
        statuses.append([c.status for c in certificates])
        whole = GaussSolver(gaussim.Options()).solve(moved)
        np.testing.assert_allclose(x, whole.x, atol=1e-7)
        np.testing.assert_allclose(multipliers, whole.multipliers, atol=1e-6)
    last, active = Status.PREVIOUS_SOLUTION_CERTIFIED, Status.ACTIVE_SET_CERTIFIED
    assert statuses[1] == statuses[4] == [last, last]  # each problem again: its own last solutions
    assert statuses[2] == statuses[5] == statuses[6] == [active, active]
    assert statuses[7][0] == active and statuses[7][1] not in (last, active)
    assert statuses[8] == [last, last]


def test_bodies_landing_far_apart_evolve_as_each_alone():
    """A box tumbling onto the ground and a ball rolling, far apart in one world: one QP each (their
    islands) while both touch, and each follows its own run through the landing, the contacts and the
    friction."""
    shapes = {
        "box": FreeBody.box("box", (0.2, 0.3, 0.1), mass=1.5),
        "ball": FreeBody.sphere("ball", 0.1, mass=0.7),
    }
    starts = {
        "box": (pose(z=0.3, rpy=(0.4, 0.2, 0.1)), [0.5, 0.0, 0.0, 2.0, -3.0, 1.0]),
        "ball": (pose(x=3.0, z=0.15), [1.0, -0.5, 0.0, 0.0, 0.0, 4.0]),
    }
    ground = gaussim.Ground()
    together = gaussim.Simulator(gaussim.Scene(bodies=shapes, ground=ground), OPTIONS)
    state = together.reset({k: s[0] for k, s in starts.items()}, {k: s[1] for k, s in starts.items()})
    alone = {}
    for name, body in shapes.items():
        sim = gaussim.Simulator(gaussim.Scene(bodies={name: body}, ground=ground), OPTIONS)
        alone[name] = (sim, sim.reset({name: starts[name][0]}, {name: starts[name][1]}))
    solved = 0
    for _ in range(400):
        state = together.step(state)
        solved += len(together.last_step.certificates) == 2
        for name, (sim, own) in alone.items():
            alone[name] = (sim, sim.step(own))
            np.testing.assert_allclose(state.body(name).q, alone[name][1].q, rtol=0, atol=SAME)
            np.testing.assert_allclose(state.body(name).v, alone[name][1].v, rtol=0, atol=SAME)
    assert solved > 100  # both touched the ground
