"""Compiled kernels of the solve (:mod:`gaussim.solver`): the KKT residuals, the active-set candidate,
ProxQP's results read out, the islands of a problem and its part on one of them."""

from __future__ import annotations

import numpy as np
from numba import njit

from ..linalg import backward, cholesky, dot, forward, forward_columns, independent_cholesky, matvec


@njit(cache=True, fastmath={"reassoc", "contract"})  # summed in any order: its products vectorize
def kkt_residuals(H, g, A, b, C, l, x, y, z):  # type: ignore[no-untyped-def]
    """(the residual of :func:`gaussim.solver.certificate.kkt_residual`, the same with each term relative to
    its size, the primal violation, the stationarity residual, the duality gap sum_i z_i s_i): the relative
    residual takes the stationarity residual and the sign violation -z_i (both in the units of g) relative to
    max(1, |g|_inf), a complementarity |z_i s_i| relative to max(1, |z_i|), which makes it the slack of a row
    with a large multiplier (a heavy body's contact). All NaN when any term is not finite."""
    primal = relative = gap = 0.0
    complementarity = 0.0
    finite = True
    size = 1.0
    for i in range(len(g)):
        size = max(size, abs(g[i]))
    stationarity = np.empty(len(g))
    for k in range(len(g)):
        stationarity[k] = dot(H[k], x) + g[k]
    for i in range(len(b)):
        if y[i] != 0.0:  # most rows carry no force (a row's non-finite entry shows in its violation)
            for k in range(len(g)):  # loops, not array expressions: those allocate a temporary each
                stationarity[k] -= y[i] * A[i, k]
        violation = abs(dot(A[i], x) - b[i])
        primal, finite = max(primal, violation), finite and np.isfinite(violation) and np.isfinite(y[i])
    for i in range(len(l)):
        if z[i] != 0.0:
            for k in range(len(g)):
                stationarity[k] -= z[i] * C[i, k]
        slack = dot(C[i], x) - l[i]
        gap += z[i] * slack
        primal = max(primal, -slack)
        complementarity = max(complementarity, -z[i], abs(z[i] * slack))
        relative = max(relative, -z[i] / size, abs(z[i] * slack) / max(1.0, abs(z[i])))
        finite = finite and np.isfinite(slack) and np.isfinite(z[i])
    dual = 0.0
    for i in range(len(g)):
        dual, finite = max(dual, abs(stationarity[i])), finite and np.isfinite(stationarity[i])
    worst = max(primal, complementarity, dual)
    relative = max(relative, primal, dual / size)
    if not finite:
        return np.nan, np.nan, np.nan, np.nan, np.nan
    return worst, relative, primal, dual, abs(gap)


@njit(cache=True, fastmath={"reassoc", "contract"})
def violates(C, l, x, tolerance):  # type: ignore[no-untyped-def]
    """Whether x violates a row of C x >= l by more than ``tolerance`` (a NaN does not: the KKT check
    refuses it); stops at the first such row."""
    for i in range(len(l)):
        if dot(C[i], x) - l[i] < -tolerance:
            return True
    return False


# In ProxQP's answer, an inequality row is active when its multiplier exceeds this fraction of the
# largest one: ProxQP leaves multipliers of 1e-172 on inactive rows, which would make them equalities.
# (The last solution keeps every positive multiplier's row: with this floor there, Talos with 16
# friction facets met a QP that neither ProxQP nor its active set solves.)
ACTIVE_SET_FLOOR = 1e-12

# Rounds of iterative refinement of the active-set solve: each divides the error of a multiplier
# direction of curvature c by 1 + c / (ACTIVE_SET_SHIFT max diag G).
ACTIVE_SET_REFINEMENTS = 2


# Primal-dual active-set steps after the first working set (:func:`active_set_candidate`).
ACTIVE_SET_ITERATIONS = 3


# The relative shift that makes the active rows' Delassus matrix G positive definite when those rows
# are dependent (a sticking contact's four pyramid rows span three directions).
ACTIVE_SET_SHIFT = 1e-12


@njit(cache=True)
def active_floor(z, floor):  # type: ignore[no-untyped-def]
    """The multiplier an active inequality row's exceeds: ``floor`` times the largest of ``z``, and 0."""
    largest = 0.0
    for value in z:
        largest = max(largest, value)
    return max(floor * largest, 0.0)


@njit(cache=True, fastmath={"reassoc", "contract"})
def _delassus(L, A, C, chosen):  # type: ignore[no-untyped-def]
    """(the rows K: the equalities A, then the inequalities C whose ``chosen`` is True, in order; the
    index in C of each of those; W = K L^-T; G = W W^T, the rows' Delassus matrix for H = L L^T)."""
    n_eq, nv = A.shape[0], L.shape[0]
    rows = np.flatnonzero(chosen)
    k = n_eq + len(rows)
    KT = np.empty((nv, k))  # K^T: L^-1 K^T solves its columns at once (forward_columns)
    for j in range(nv):
        for i in range(n_eq):
            KT[j, i] = A[i, j]
        for i in range(len(rows)):
            KT[j, n_eq + i] = C[rows[i], j]
    W = forward_columns(L, KT).T.copy()
    G = np.empty((k, k))
    for i in range(k):
        for j in range(i + 1):
            G[i, j] = G[j, i] = dot(W[i], W[j])
    return rows, W, G


@njit(cache=True, fastmath={"reassoc", "contract"})
def active_set_candidate(H, g, A, b, C, l, x, multipliers, tolerance, floor, x_out, multipliers_out):  # type: ignore[no-untyped-def]
    """(how, the residuals of :func:`kkt_residuals`) for the first candidate built from a solution
    (x, multipliers) that the relative KKT residual certifies (<= ``tolerance``): that solution itself
    (how 1), then the solutions of the problem with a working set of rows as equalities (how 2, written
    into ``x_out`` and ``multipliers_out``; see the docstring of :mod:`gaussim.solver.active_set`).
    how 0: none is certified.

    The first working set is the rows the solution held active (its equalities and the inequalities
    with a multiplier above ``floor`` times the largest, and > 0); each of at most
    ACTIVE_SET_ITERATIONS more is the last one's rows with a multiplier >= 0 and the rows its solution
    violates by more than ``tolerance`` (a primal-dual active-set step), while that changes it and
    holds at most as many rows as coordinates: more are dependent, and the shifted solve on them splits
    their multipliers anyhow (over the zero-torque corpus runs of solo12, a1, anymal and go2, 1467 such
    steps failed and 22 were certified; DAQP, which keeps its working set independent, solves them).

    G is shifted by ACTIVE_SET_SHIFT max diag G and the solve refined ACTIVE_SET_REFINEMENTS times
    (dependent rows make G singular; their multipliers' split is then one of many, which the check
    accepts when it is >= 0)."""
    n_eq, nv = len(b), len(g)
    residuals = kkt_residuals(H, g, A, b, C, l, x, multipliers[:n_eq], multipliers[n_eq:])
    if residuals[1] <= tolerance:
        return 1, residuals
    least = active_floor(multipliers[n_eq:], floor)
    working = np.empty(len(l), np.bool_)
    for i in range(len(l)):
        working[i] = multipliers[n_eq + i] > least
    L = cholesky(H, 0.0)
    if L is None:
        return 0, residuals
    h = np.empty((1, nv))
    for j in range(nv):
        h[0, j] = g[j]
    h = forward(L, h)[0]  # L^-1 g
    for _ in range(1 + ACTIVE_SET_ITERATIONS):
        if not _solve_on(L, h, A, b, C, l, working, x_out, multipliers_out):
            return 0, residuals
        residuals = kkt_residuals(H, g, A, b, C, l, x_out, multipliers_out[:n_eq], multipliers_out[n_eq:])
        if residuals[1] <= tolerance:
            return 2, residuals
        changed, count = False, n_eq
        for i in range(len(l)):
            keep = multipliers_out[n_eq + i] >= 0.0 if working[i] else dot(C[i], x_out) - l[i] < -tolerance
            changed |= keep != working[i]
            working[i] = keep
            count += keep
        if not changed or count > nv:  # more rows than coordinates: see the docstring
            break
    return 0, residuals


@njit(cache=True, fastmath={"reassoc", "contract"})
def _solve_on(L, h, A, b, C, l, working, x_out, multipliers_out):  # type: ignore[no-untyped-def]
    """The Gauss problem (H = L L^T, h = L^-1 g) with the equalities and the ``working`` inequalities
    as equalities, solved into ``x_out`` and ``multipliers_out`` (0 off the working set); False when
    the shifted G is not positive definite."""
    n_eq, nv = len(b), len(h)
    rows, W, G = _delassus(L, A, C, working)
    k = n_eq + len(rows)
    rhs, largest = np.empty(k), 0.0
    for i in range(k):
        rhs[i] = (b[i] if i < n_eq else l[rows[i - n_eq]]) + dot(W[i], h)
        largest = max(largest, G[i, i])
    LG = cholesky(G, ACTIVE_SET_SHIFT * largest)
    if LG is None:
        return False
    lam, step = np.zeros(k), np.empty((1, k))
    for _ in range(ACTIVE_SET_REFINEMENTS):
        product = matvec(G, lam)
        for i in range(k):
            step[0, i] = rhs[i] - product[i]
        correction = backward(LG, forward(LG, step)[0])
        for i in range(k):
            lam[i] += correction[i]
    y = np.empty(nv)  # W^T lam - h, then L^-T of it
    for j in range(nv):
        y[j] = -h[j]
    for i in range(k):
        for j in range(nv):
            y[j] += lam[i] * W[i, j]
    backward(L, y)
    for j in range(nv):
        x_out[j] = y[j]
    for i in range(len(multipliers_out)):
        multipliers_out[i] = lam[i] if i < n_eq else 0.0
    for i in range(k - n_eq):
        multipliers_out[n_eq + rows[i]] = lam[n_eq + i]
    return True


# The least ratio of a Cholesky pivot of the active rows' Delassus matrix to its diagonal for which
# :func:`bound_response` takes them as independent.
INDEPENDENT = 1e-6


@njit(cache=True, fastmath={"reassoc", "contract"})
def bound_response(H, A, C, z, floor, group, V):  # type: ignore[no-untyped-def]
    """R (k, k), k = len(V): R[i, j] = V[i] . dx, dx the change of the solution x of the Gauss
    problem (H, rows A x = b and C x >= l) when the bounds of group j's rows (``group``: the group of
    each inequality row, -1 for none) that the solution holds active rise by 1. The active rows K (the
    equalities and the inequalities with a multiplier ``z`` above ``floor`` times the largest, and
    > 0) stay active: dx = H^-1 K^T G^-1 e_j, G = K H^-1 K^T, on the rows of K independent of the
    ones before (a row whose Cholesky pivot of G is at most INDEPENDENT times its diagonal is left
    out: a sticking contact's fourth pyramid row, a flat box's fourth corner; a move of the kept
    rows' bounds moves x as it would with the left-out rows, when their move is consistent). An
    empty R when H is not positive definite."""
    n_eq, k = A.shape[0], V.shape[0]
    L = cholesky(H, 0.0)
    if L is None:
        return np.empty((0, 0))
    active = np.empty(len(z), np.bool_)
    least = active_floor(z, floor)
    for i in range(len(z)):
        active[i] = z[i] > least
    rows, W, G = _delassus(L, A, C, active)
    count = n_eq + len(rows)
    owner = np.full(count, -1)
    for t in range(len(rows)):
        owner[n_eq + t] = group[rows[t]]
    LG, kept = independent_cholesky(G, INDEPENDENT)
    P = forward(L, V.copy())  # the rows of V L^-T
    R, q = np.zeros((k, k)), np.empty((1, count))
    for i in range(k):  # row i of V H^-1 K^T G^-1, summed over each group's rows
        for t in range(count):
            q[0, t] = dot(P[i], W[t]) if kept[t] else 0.0
        row = backward(LG, forward(LG, q)[0])
        for t in range(count):
            if owner[t] >= 0:
                R[i, owner[t]] += row[t]
    return R


@njit(cache=True)
def read_results(H, g, A, b, C, l, x, y, z):  # type: ignore[no-untyped-def]
    """(x, the multipliers [-y; -z], the residuals of :func:`kkt_residuals` there), copied out of
    ProxQP's results."""
    n_eq, n_in = len(b), len(l)
    x, multipliers = x.copy(), np.empty(n_eq + n_in)
    for i in range(n_eq):
        multipliers[i] = -y[i]
    for i in range(n_in):
        multipliers[n_eq + i] = -z[i]
    return (x, multipliers, *kkt_residuals(H, g, A, b, C, l, x, multipliers[:n_eq], multipliers[n_eq:]))


@njit(cache=True)
def cut(H, g, A, b, C, l, cols, eq, ineq):  # type: ignore[no-untyped-def]
    """(H, g, A, b, C, l) on the coordinates ``cols`` and the rows ``eq``, ``ineq``."""
    n = len(cols)
    H_, A_, C_ = np.empty((n, n)), np.empty((len(eq), n)), np.empty((len(ineq), n))
    for j in range(n):
        for k in range(n):
            H_[j, k] = H[cols[j], cols[k]]
    for i in range(len(eq)):
        for k in range(n):
            A_[i, k] = A[eq[i], cols[k]]
    for i in range(len(ineq)):
        for k in range(n):
            C_[i, k] = C[ineq[i], cols[k]]
    return H_, g[cols], A_, b[eq], C_, l[ineq]


@njit(cache=True)
def warm_islands(H, g, A, b, C, l, islands, tried, last_x, last_m, tolerance, how, residuals, x, multipliers):  # type: ignore[no-untyped-def]
    """:func:`active_set_candidate` (floor 0) on the ``tried`` islands of one problem, each from its own
    last solution: island t's coordinates ``cols[col_start[t]:col_start[t + 1]]`` and its equality and
    inequality rows ``eqs[eq_start[t]:...]``, ``ineqs[ineq_start[t]:...]`` (``islands``: those six
    arrays; its problem :func:`cut` from the whole one); the tried islands' last x and multipliers
    [eq; ineq] concatenated in island order in ``last_x`` and ``last_m``. Where a candidate is
    certified (``how[t]`` 1 or 2, else 0; its residuals in ``residuals[t]``), its x and multipliers
    are written over its last solution's in ``last_x`` and ``last_m``, and into ``x`` and
    ``multipliers`` (the whole problem's: at its coordinates, and at its rows of [lambda_eq;
    lambda_in])."""
    cols, col_start, eqs, eq_start, ineqs, ineq_start = islands
    n_eq = len(b)
    x_at = m_at = 0
    for t in range(len(tried)):
        how[t] = 0
        if not tried[t]:
            continue
        c = cols[col_start[t] : col_start[t + 1]]
        eq, ineq = eqs[eq_start[t] : eq_start[t + 1]], ineqs[ineq_start[t] : ineq_start[t + 1]]
        nx, nm = len(c), len(eq) + len(ineq)
        Hi, gi, Ai, bi, Ci, li = cut(H, g, A, b, C, l, c, eq, ineq)
        xi, mi = last_x[x_at : x_at + nx], last_m[m_at : m_at + nm]
        x_out, m_out = np.empty(nx), np.empty(nm)
        how[t], found = active_set_candidate(Hi, gi, Ai, bi, Ci, li, xi, mi, tolerance, 0.0, x_out, m_out)
        for j in range(5):
            residuals[t, j] = found[j]
        if how[t] == 2:
            xi[:], mi[:] = x_out, m_out
        if how[t]:
            for k in range(nx):
                x[c[k]] = xi[k]
            for k in range(len(eq)):
                multipliers[eq[k]] = mi[k]
            for k in range(len(ineq)):
                multipliers[n_eq + ineq[k]] = mi[len(eq) + k]
        x_at, m_at = x_at + nx, m_at + nm


@njit(cache=True)
def _root(parent, t):  # type: ignore[no-untyped-def]
    while parent[t] != t:
        parent[t] = parent[parent[t]]
        t = parent[t]
    return t


@njit(cache=True)
def _join(parent, s, t):  # type: ignore[no-untyped-def]
    """Union of the sets of s and t (the smaller root stays)."""
    a, b = _root(parent, s), _root(parent, t)
    if a != b:
        parent[max(a, b)] = min(a, b)


@njit(cache=True)
def islands(A, C, read, joint_tree, applied, tree, n_trees):  # type: ignore[no-untyped-def]
    """(the island of each tree, -1 for a tree no row reads; the island of each row of [A; C], -1
    for a row that reads no coordinate; the number of islands). A row reads the trees of its two
    joints ``read[r]`` (``joint_tree``: each joint's tree, -1 for the world), or the trees of its
    nonzero entries where ``read[r, 0]`` is -1. The trees of ``applied`` (nv,), the force the
    modules apply outside the QP, are islands too."""
    parent = np.arange(n_trees)
    touched = np.zeros(n_trees, dtype=np.bool_)
    n_eq, nv = A.shape[0], len(tree)
    first = np.full(n_eq + C.shape[0], -1)
    for r in range(len(first)):
        if read[r, 0] >= 0:
            for joint in (read[r, 0], read[r, 1]):
                t = joint_tree[joint]
                if t < 0:
                    continue
                touched[t] = True
                if first[r] < 0:
                    first[r] = t
                else:
                    _join(parent, first[r], t)
            continue
        last = -1
        for k in range(nv):
            value = A[r, k] if r < n_eq else C[r - n_eq, k]
            if value == 0.0 or tree[k] == last:
                continue
            last = tree[k]
            touched[last] = True
            if first[r] < 0:
                first[r] = last
            else:
                _join(parent, first[r], last)
    for k in range(nv):
        if applied[k] != 0.0:
            touched[tree[k]] = True
    island_of_root = np.full(n_trees, -1)
    island_of_tree = np.full(n_trees, -1)
    n = 0
    for t in range(n_trees):
        if touched[t]:
            r = _root(parent, t)
            if island_of_root[r] < 0:
                island_of_root[r], n = n, n + 1
            island_of_tree[t] = island_of_root[r]
    island_of_row = np.full(len(first), -1)
    for r in range(len(first)):
        if first[r] >= 0:
            island_of_row[r] = island_of_tree[first[r]]
    return island_of_tree, island_of_row, n


@njit(cache=True)
def members(labels, n):  # type: ignore[no-untyped-def]
    """(the indices of labels 0, ..., n - 1 in label order, ascending within each; where each label's
    run starts, (n + 1,)); labels < 0 are left out."""
    start = np.zeros(n + 1, dtype=np.int64)
    for label in labels:
        if label >= 0:
            start[label + 1] += 1
    for i in range(n):
        start[i + 1] += start[i]
    order, fill = np.empty(start[n], dtype=np.int64), start[:n].copy()
    for k in range(len(labels)):
        if labels[k] >= 0:
            order[fill[labels[k]]] = k
            fill[labels[k]] += 1
    return order, start


@njit(cache=True)
def within(values, limit):  # type: ignore[no-untyped-def]
    """Whether every entry of ``values`` is in [0, limit)."""
    for value in values:
        if value < 0 or value >= limit:
            return False
    return True


@njit(cache=True)
def matched_values(ids, values, new, out):  # type: ignore[no-untyped-def]
    """out[i] = the value of the entry of ``ids`` whose id is ``new[i]`` (the first such), 0 where none
    is; whether any of them is nonzero. What a step carries to the next by id (rows and contacts come
    and go): the dual start (:func:`gaussim.solver.dual.matched_start`), the contacts that stuck
    (:class:`gaussim.constraints.contact.ContactModule`)."""
    order = np.argsort(ids, kind="mergesort")  # stable: equal ids keep their order
    found = False
    for i in range(len(new)):
        low, high = 0, len(order)
        while low < high:  # the first sorted id >= new[i]
            middle = (low + high) // 2
            if ids[order[middle]] < new[i]:
                low = middle + 1
            else:
                high = middle
        out[i] = values[order[low]] if low < len(order) and ids[order[low]] == new[i] else 0.0
        found |= out[i] != 0.0
    return found


# The least-norm multipliers' Tikhonov shift, relative to the trace of K K^T, and the refinements that
# take its answer to the least-norm one (iterated Tikhonov: each divides the error by 1 + sigma^2 / shift).
LEAST_NORM_SHIFT = 1e-12
LEAST_NORM_REFINEMENTS = 3


@njit(cache=True, fastmath={"reassoc", "contract"})
def least_norm(H, g, A, C, l, x, tolerance, out):  # type: ignore[no-untyped-def]
    """The multipliers [y; z] of least norm with A^T y + C^T z = H x + g and z_i = 0 on the rows x does
    not hold to ``tolerance`` (C_i x - l_i > tolerance max(1, |l_i|)), into ``out`` (n_eq + n_in), their
    signs unconstrained (see :mod:`gaussim.solver.reactions`); returns the least of its z (-inf when
    the system is not positive definite once shifted)."""
    n_eq, nv = A.shape[0], H.shape[0]
    columns = np.empty(n_eq + C.shape[0], np.int64)  # the rows that may carry a multiplier, of [A; C]
    for i in range(n_eq):
        columns[i] = i
    m = n_eq
    for i in range(C.shape[0]):
        if dot(C[i], x) - l[i] <= tolerance * max(1.0, abs(l[i])):
            columns[m] = n_eq + i
            m += 1
    K = np.empty((m, nv))  # K^T: the rows' generalized directions
    for j in range(m):
        K[j] = A[columns[j]] if columns[j] < n_eq else C[columns[j] - n_eq]
    r = matvec(H, x) + g
    G = np.zeros((nv, nv))  # K^T K, by loops: the build compiles without scipy's BLAS
    for j in range(m):
        for a in range(nv):
            if K[j, a] != 0.0:
                for c in range(nv):
                    G[a, c] += K[j, a] * K[j, c]
    trace = 0.0
    for i in range(nv):
        trace += G[i, i]
    L = cholesky(G, max(LEAST_NORM_SHIFT * trace, 1e-300))
    out[:] = 0.0
    if L is None:
        return -np.inf
    lam = np.zeros(m)
    error = r.copy()
    for _ in range(LEAST_NORM_REFINEMENTS + 1):  # lam += K (G + shift)^-1 (r - K^T lam)
        mu = backward(L, forward(L, error.reshape(1, nv))[0])
        lam += matvec(K, mu)
        error = r.copy()
        for j in range(m):
            for a in range(nv):
                error[a] -= K[j, a] * lam[j]
    least = np.inf
    for j in range(m):
        out[columns[j]] = lam[j]
        if columns[j] >= n_eq:
            least = min(least, lam[j])
    return least


# The proximal rounds of :func:`box_minimum` end when a round moves no coordinate by more than this
# fraction of its bound.
PROXIMAL_TOLERANCE = 1e-9


@njit(cache=True, fastmath={"reassoc", "contract"})
def box_minimum(W, c, bound, start, shift, release, p):  # type: ignore[no-untyped-def]
    """argmin 1/2 p^T W p + c^T p over -bound <= p <= bound (W symmetric positive semi-definite), into
    ``p``, by proximal rounds: each the minimum of the objective plus shift/2 |p - centre|^2 (shift > 0:
    a positive definite problem however singular W is; centre the last round's answer, ``start`` at
    first), found by the primal active-set method from the last round's working set (the coordinates at
    a bound held there): a Newton step on the free ones, cut short at the first bound it crosses (held
    from then on); at a working set's minimum, the held coordinate whose gradient pulls it inside by
    more than ``release`` most is freed. Returns the number of active-set iterations, or -1 when the
    rounds did not settle within their budget or W + shift I has no Cholesky factor (``p`` is then
    the last round's, within the box)."""
    k = len(c)
    side, centre = np.zeros(k), np.empty(k)
    for i in range(k):
        p[i] = min(max(start[i], -bound[i]), bound[i])
        if abs(p[i]) >= bound[i] * (1.0 - 1e-6):
            side[i] = 1.0 if p[i] > 0.0 else -1.0
            p[i] = side[i] * bound[i]
    gradient, step = np.empty(k), np.empty(k)
    iterations = 0
    for _ in range(4 * k + 8):  # proximal rounds
        centre[:] = p
        finished = False
        for _ in range(4 * k + 8):
            iterations += 1
            _box_gradient(W, c, shift, p, centre, gradient)
            free = np.flatnonzero(side == 0.0)
            n = len(free)
            if n:
                G = np.empty((n, n))
                for a in range(n):
                    for b in range(n):
                        G[a, b] = W[free[a], free[b]]
                L = cholesky(G, shift)
                if L is None:  # W not positive semi-definite
                    return -1
                rhs = np.empty((1, n))
                for a in range(n):
                    rhs[0, a] = -gradient[free[a]]
                newton = backward(L, forward(L, rhs)[0])
                blocking, ratio = -1, 1.0
                for a in range(n):
                    i = free[a]
                    if abs(p[i] + newton[a]) > bound[i]:  # crosses its bound: the step stops at the first
                        room = (bound[i] if newton[a] > 0.0 else -bound[i]) - p[i]
                        r = max(room / newton[a], 0.0)
                        if r < ratio:
                            blocking, ratio = i, r
                step[:] = 0.0
                for a in range(n):
                    step[free[a]] = newton[a]
                if ratio > 0.0:  # (not 0 * inf: a step that overflows where W is 0)
                    for i in range(k):
                        p[i] += ratio * step[i]
                if blocking >= 0:
                    side[blocking] = 1.0 if step[blocking] > 0.0 else -1.0
                    p[blocking] = side[blocking] * bound[blocking]
                    continue
                _box_gradient(W, c, shift, p, centre, gradient)
            freed, pull = -1, release
            for i in range(k):  # pull > 0: the held coordinate would move inside
                if side[i] != 0.0 and gradient[i] * side[i] > pull:
                    freed, pull = i, gradient[i] * side[i]
            if freed < 0:
                finished = True
                break
            side[freed] = 0.0
        if not finished:
            return -1
        moved = False
        for i in range(k):
            moved = moved or abs(p[i] - centre[i]) > PROXIMAL_TOLERANCE * bound[i]
        if not moved:
            return iterations
    return -1


@njit(cache=True, fastmath={"reassoc", "contract"})
def _box_gradient(W, c, shift, p, centre, out):  # type: ignore[no-untyped-def]
    """The gradient of 1/2 p^T W p + c^T p + shift/2 |p - centre|^2, into ``out``."""
    for i in range(len(c)):
        total = c[i] + shift * (p[i] - centre[i])
        for j in range(len(c)):
            total += W[i, j] * p[j]
        out[i] = total
