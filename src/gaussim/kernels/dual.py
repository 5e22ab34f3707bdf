"""Compiled kernels of the dual active-set solve (:mod:`gaussim.solver.dual`).

The Gauss problem min 1/2 x^T H x + g^T x over rows a_k^T x >= d_k (and = d_k) is posed in least-distance
form: with H = L L^T (L lower, Cholesky on H's envelope), z = L^T x, z0 = -L^-1 g and m_k = L^-1 a_k it
is min 1/2 |z - z0|^2 over m_k^T z >= d_k. L factors H in reversed order of the coordinates (z, L and
the m_k live in that order): Pinocchio puts a joint after its parent, so that order eliminates a tree's
leaves before its root, as Featherstone's L^T D L factorization does, and L has no fill beyond each
coordinate's ancestors (a robot's contact row stays on its limb and base).

A dual active-set method (Goldfarb and Idnani's, in the form DAQP takes: Arnström, Bemporad, Axehill
2022) keeps a linearly independent working set W of rows, the LDL^T factors of their Gram matrix
G = M_W M_W^T and dual-feasible multipliers lam >= 0: each iteration solves G lam* = d_W - M_W z0,
steps from lam towards lam* until a multiplier would turn negative (that row leaves), or takes lam* and
adds the row z = z0 + M_W^T lam* violates most. A row dependent on W enters by moving the multipliers
along the null direction of the rows until one of W reaches zero.

Every row is stored sparse (CSR): a free body's m_k reads the 6 coordinates of its block of L, so a
pile's rows cost what their nonzeros do, where a dense solver pays for every coordinate of the island
in each iteration.
"""

from __future__ import annotations

import numpy as np
from numba import njit

OPTIMAL, ITERATION_CAP, INFEASIBLE = 1, -1, -2


@njit(cache=True, fastmath={"reassoc", "contract"})
def envelope_cholesky(H, L, first, parent):  # type: ignore[no-untyped-def]
    """P H P = L L^T (P the reversal of the coordinates) on that matrix's envelope (first[i]: the first
    column of row i within it) and the elimination tree of that envelope (parent[j]: the first row below
    j whose envelope reaches column j, -1 at a root); False when H is not positive definite."""
    n = H.shape[0]
    last = n - 1
    for i in range(n):
        j = 0
        while j < i and H[last - i, last - j] == 0.0:
            j += 1
        first[i] = j
        parent[i] = -1
    for i in range(n):
        for j in range(first[i], i + 1):
            total = H[last - i, last - j]
            for k in range(max(first[i], first[j]), j):
                total -= L[i, k] * L[j, k]
            if j < i:
                L[i, j] = total / L[j, j]
                if parent[j] < 0:
                    parent[j] = i
            elif total > 0.0:
                L[i, i] = np.sqrt(total)
            else:  # NaN too
                return False
    return True


@njit(cache=True, fastmath={"reassoc", "contract"})
def transformed_rows(L, first, parent, rows, ptr, idx, val, masks, w, mark):  # type: ignore[no-untyped-def]
    """m_k = L^-1 P a_k of each row a_k of ``rows`` into the CSR arrays (ptr, idx, val): its nonzeros lie on
    the elimination-tree paths from P a_k's own (``w`` zero and ``mark`` -1 on entry, as they are left);
    masks[k] has bit b set when m_k reads a coordinate of the b-th of 64 equal ranges of them (two rows
    of disjoint masks are orthogonal)."""
    m, n = rows.shape
    last = n - 1
    nnz = 0
    ptr[0] = 0
    nonzero = np.empty(n, dtype=np.int64)
    for k in range(m):
        start, count = nnz, 0
        for c in range(n):  # read in memory order
            if rows[k, c] != 0.0:
                nonzero[count] = last - c
                count += 1
        for a in range(count - 1, -1, -1):  # the union of the paths, each entry once, nearly in order
            j = nonzero[a]
            while j >= 0 and mark[j] != k:
                mark[j] = k
                idx[nnz] = j
                nnz += 1
                j = parent[j]
        for a in range(start + 1, nnz):  # in increasing order (a few entries: insertion sort)
            key, b = idx[a], a - 1
            while b >= start and idx[b] > key:
                idx[b + 1] = idx[b]
                b -= 1
            idx[b + 1] = key
        mask = 0
        for t in range(start, nnz):  # forward substitution over those entries
            i = idx[t]
            w[i] = (rows[k, last - i] - _segment_dot(L[i, first[i] : i], w[first[i] : i])) / L[i, i]
            mask |= np.int64(1) << (i * 64 // n)
        for t in range(start, nnz):
            val[t] = w[idx[t]]
            w[idx[t]] = 0.0
            mark[idx[t]] = -1
        ptr[k + 1], masks[k] = nnz, mask
    return nnz


@njit(cache=True, fastmath={"reassoc", "contract"})
def free_products(L, first, g, ptr, idx, val, z0, e):  # type: ignore[no-untyped-def]
    """z0 = -L^-1 P g, the unconstrained minimum in z, and e_k = m_k^T z0 of every row."""
    last = len(g) - 1
    for i in range(len(g)):
        total = -g[last - i]
        for j in range(first[i], i):
            total -= L[i, j] * z0[j]
        z0[i] = total / L[i, i]
    for k in range(len(e)):
        e[k] = _dot(ptr, idx, val, k, z0)


@njit(cache=True, fastmath={"reassoc", "contract"}, inline="always")
def _dot(ptr, idx, val, k, w):  # type: ignore[no-untyped-def]
    """m_k^T w for a dense w."""
    total = 0.0
    for t in range(ptr[k], ptr[k + 1]):
        total += val[t] * w[idx[t]]
    return total


@njit(cache=True, fastmath={"reassoc", "contract"}, inline="always")
def _segment_dot(a, b):  # type: ignore[no-untyped-def]
    """a . b over slices: indices from zero let LLVM vectorize, where a loop from a start held in an
    array did not (numba's wraparound of a possibly negative index: 4 times slower)."""
    total = 0.0
    for i in range(len(a)):
        total += a[i] * b[i]
    return total


@njit(cache=True, fastmath={"reassoc", "contract"})
def _append(p, ptr, idx, val, masks, W, n_w, Lw, Dw, F, w, u, dependence):  # type: ignore[no-untyped-def]
    """Row p's column of the Gram matrix, forward-solved (u = (Lw)^-1 M_W m_p), and, when p is independent
    of the working set (its pivot above ``dependence`` times |m_p|^2, and the set not full), its row of
    the factors at n_w, which starts at the first working row p shares a coordinate with (F[n_w]); True
    then (``w`` zero on entry and exit)."""
    norm = 0.0
    for t in range(ptr[p], ptr[p + 1]):
        w[idx[t]] = val[t]
        norm += val[t] * val[t]
    start, mask = n_w, masks[p]  # u is zero before its first nonzero, and so is its forward solve
    for j in range(n_w):
        u[j] = _dot(ptr, idx, val, W[j], w) if masks[W[j]] & mask else 0.0
        if u[j] != 0.0 and start == n_w:
            start = j
    for t in range(ptr[p], ptr[p + 1]):
        w[idx[t]] = 0.0
    pivot = norm
    for j in range(start, n_w):
        f = max(F[j], start)
        total = u[j] - _segment_dot(Lw[j, f:j], u[f:j])
        u[j] = total
        pivot -= total * total / Dw[j]
    if not pivot > dependence * norm or n_w == len(W):  # a full set spans every m_p
        return False
    for j in range(start, n_w):
        Lw[n_w, j] = u[j] / Dw[j]
    Dw[n_w], W[n_w], F[n_w] = pivot, p, start
    return True


@njit(cache=True, fastmath={"reassoc", "contract"})
def _remove(r, n_w, W, Lw, Dw, F, lam, pos, rhs, P, B):  # type: ignore[no-untyped-def]
    """Drop the working row at place r: the factors of the rows after it take the rank-one update that
    their column r leaves (Gill, Golub, Murray and Saunders' method C1, row by row: each of the column's
    multipliers P and B is made at its row's diagonal), and each row moves up one place. A row that
    starts after column r has a zero there: the update leaves its columns before its start zero."""
    alpha = Dw[r]
    pos[W[r]] = -1
    for i in range(r + 1, n_w):
        f = F[i]
        t = Lw[i, r] if f <= r else 0.0
        for j in range(max(f, r + 1), i):
            t -= P[j] * Lw[i, j]
            Lw[i, j] += B[j] * t
        d = Dw[i] + alpha * t * t
        P[i], B[i] = t, t * alpha / d
        alpha = Dw[i] * alpha / d
        for j in range(f, r):
            Lw[i - 1, j] = Lw[i, j]
        for j in range(max(f, r + 1), i):
            Lw[i - 1, j - 1] = Lw[i, j]
        F[i - 1] = f if f < r else max(f, r + 1) - 1
        Dw[i - 1], W[i - 1], lam[i - 1], rhs[i - 1] = d, W[i], lam[i], rhs[i]
        pos[W[i - 1]] = i - 1


@njit(cache=True, fastmath={"reassoc", "contract"})
def _solve_gram(n_w, Lw, Dw, F, rhs, y, fresh, out):  # type: ignore[no-untyped-def]
    """out = G^-1 rhs on the factors of the working set, where y = Lw^-1 rhs is kept from before for the
    places below ``fresh`` (the rows before the first one that changed)."""
    for j in range(fresh, n_w):
        y[j] = rhs[j] - _segment_dot(Lw[j, F[j] : j], y[F[j] : j])
    _backward(n_w, Lw, Dw, F, y, out)


@njit(cache=True, fastmath={"reassoc", "contract"}, inline="always")
def _backward(n_w, Lw, Dw, F, y, out):  # type: ignore[no-untyped-def]
    """out = Lw^-T D^-1 y (``out`` may be ``y``)."""
    for j in range(n_w):
        out[j] = y[j] / Dw[j]
    for i in range(n_w - 1, 0, -1):  # by rows of Lw, which lie in memory in order
        value, row, part = out[i], Lw[i, F[i] : i], out[F[i] : i]
        for j in range(len(row)):
            part[j] -= row[j] * value


@njit(cache=True, fastmath={"reassoc", "contract"}, inline="always")
def _primal(ptr, idx, val, n_w, W, lam, z0, z):  # type: ignore[no-untyped-def]
    """z = z0 + M_W^T lam."""
    z[:] = z0
    for j in range(n_w):
        k = W[j]
        for t in range(ptr[k], ptr[k + 1]):
            z[idx[t]] += lam[j] * val[t]


@njit(cache=True)
def _banded(ptr, idx, rows, n):  # type: ignore[no-untyped-def]
    """``rows`` in reverse Cuthill-McKee order on the graph of rows that share a coordinate (of ``n``):
    breadth first from a row of fewest neighbours, reversed. The factors of their Gram matrix then
    keep within a narrow envelope (a settled pile's: a fifth of the dense triangle, where the order of
    the multipliers filled four fifths)."""
    m = len(rows)
    start = np.zeros(n + 1, dtype=np.int64)  # the rows of each coordinate, CSC
    for r in range(m):
        for t in range(ptr[rows[r]], ptr[rows[r] + 1]):
            start[idx[t] + 1] += 1
    for c in range(n):
        start[c + 1] += start[c]
    members, fill = np.empty(start[n], dtype=np.int64), start[:n].copy()
    degree = np.zeros(m, dtype=np.int64)
    for r in range(m):
        for t in range(ptr[rows[r]], ptr[rows[r] + 1]):
            members[fill[idx[t]]] = r
            fill[idx[t]] += 1
            degree[r] += start[idx[t] + 1] - start[idx[t]]
    order, seen = np.empty(m, dtype=np.int64), np.zeros(m, dtype=np.bool_)
    head = tail = 0
    while tail < m:
        first = -1  # a component's start: its row of fewest neighbours
        for r in range(m):
            if not seen[r] and (first < 0 or degree[r] < degree[first]):
                first = r
        seen[first], order[tail] = True, first
        tail += 1
        while head < tail:
            r = order[head]
            head += 1
            for t in range(ptr[rows[r]], ptr[rows[r] + 1]):
                c = idx[t]
                for s in range(start[c], start[c + 1]):
                    o = members[s]
                    if not seen[o]:
                        seen[o], order[tail] = True, o
                        tail += 1
    return rows[order[::-1]]


@njit(cache=True, fastmath={"reassoc", "contract"})
def start_set(ptr, idx, val, masks, n_eq, start, dependence, W, Lw, Dw, F, lam, pos, w, u):  # type: ignore[no-untyped-def]
    """A working set for a new problem: its equality rows, then the inequality rows of positive ``start``
    (the multipliers of the last solution, matched to these rows) in the order of :func:`_banded`, each
    that is independent of those before; lam their start. Returns its size."""
    pos[:] = -1
    n_w = 0
    for k in range(n_eq):
        if _append(k, ptr, idx, val, masks, W, n_w, Lw, Dw, F, w, u, dependence):
            lam[n_w], pos[k] = start[k], n_w
            n_w += 1
    for k in _banded(ptr, idx, np.nonzero(start[n_eq:] > 0.0)[0] + n_eq, len(w)):
        if n_w == len(W):
            break
        if _append(k, ptr, idx, val, masks, W, n_w, Lw, Dw, F, w, u, dependence):
            lam[n_w], pos[k] = start[k], n_w
            n_w += 1
    return n_w


@njit(cache=True, fastmath={"reassoc", "contract"})
def dual_iterations(
    ptr, idx, val, masks, e, d, n_eq, tolerance, dependence, cap, n_w, W, Lw, Dw, F, lam, pos, z0, z, work
):  # type: ignore[no-untyped-def]
    """Run the dual active-set method from the working set of size n_w (W, its factors Lw, Dw, the
    first column F[j] of row j of Lw, zero before it; multipliers lam >= 0 on its inequality rows; pos[k]
    the place of row k in it, else -1) until z = z0 + M_W^T lam meets every row to ``tolerance``
    (OPTIMAL), for at most ``cap`` iterations (ITERATION_CAP), or a violated row's dependence on the
    working set shows the rows infeasible (INFEASIBLE); ``masks`` those of :func:`transformed_rows`.
    ``work`` holds 5 scratch vectors of at least the coordinates and the working set's capacity.
    Returns (status, iterations, size of the working set)."""
    star, rhs, w, u, y = work[0], work[1], work[2], work[3], work[4]
    fresh = 0  # the places of the working set whose forward-solved right-hand side y holds
    for j in range(n_w):
        rhs[j] = d[W[j]] - e[W[j]]
        if W[j] >= n_eq:  # dual feasible, whatever the set was given with
            lam[j] = max(lam[j], 0.0)
    for iteration in range(1, cap + 1):
        _solve_gram(n_w, Lw, Dw, F, rhs, y, fresh, star)
        fresh = n_w
        step, block = np.inf, -1
        for j in range(n_w):
            if W[j] >= n_eq and star[j] < 0.0:
                ratio = lam[j] / (lam[j] - star[j])  # in [0, 1], 1 itself in round-off
                if ratio < step:
                    step, block = ratio, j
        if block >= 0:  # towards lam* until a multiplier reaches zero: that row leaves
            step = min(step, 1.0)
            for j in range(n_w):
                lam[j] += step * (star[j] - lam[j])
                if W[j] >= n_eq:  # >= 0 in round-off too: the next ratio's denominator is positive
                    lam[j] = max(lam[j], 0.0)
            _remove(block, n_w, W, Lw, Dw, F, lam, pos, rhs, star, u)
            n_w, fresh = n_w - 1, min(fresh, block)
            continue
        for j in range(n_w):
            lam[j] = star[j]
        _primal(ptr, idx, val, n_w, W, lam, z0, z)
        p = _most_violated(ptr, idx, val, d, n_eq, pos, z, tolerance)
        refined = False  # whether z was refined since the last solve for lam*
        entered = 0.0  # p's multiplier, grown along the null direction of a dependent p
        while p < 0 or not _append(p, ptr, idx, val, masks, W, n_w, Lw, Dw, F, w, u, dependence):
            block = -1
            if p >= 0 and n_w:
                # m_p = M_W^T c: raising lam_p by s and lowering lam_W by s c leaves z, raises the dual
                _backward(n_w, Lw, Dw, F, u, u)
                move = np.inf
                for j in range(n_w):
                    if W[j] >= n_eq and u[j] > 0.0 and lam[j] / u[j] < move:
                        move, block = lam[j] / u[j], j
            if block < 0:  # optimal (p -1), or nothing limits the dual's rise: no z meets the rows
                if not refined and entered == 0.0:  # unless the factors' drift made a row look violated
                    _refine(ptr, idx, val, d, n_eq, n_w, W, Lw, Dw, F, lam, z0, z, star, y, u)
                    refined, fresh = True, 0
                    p = _most_violated(ptr, idx, val, d, n_eq, pos, z, tolerance)
                    continue
                return (OPTIMAL if p == -1 else INFEASIBLE), iteration, n_w
            for j in range(n_w):
                lam[j] -= move * u[j]
                if W[j] >= n_eq:
                    lam[j] = max(lam[j], 0.0)
            entered += move
            _remove(block, n_w, W, Lw, Dw, F, lam, pos, rhs, star, u)
            n_w, fresh = n_w - 1, min(fresh, block)
        lam[n_w], pos[p], rhs[n_w] = entered, n_w, d[p] - e[p]
        n_w += 1
    return ITERATION_CAP, cap, n_w


@njit(cache=True, fastmath={"reassoc", "contract"})
def _most_violated(ptr, idx, val, d, n_eq, pos, z, tolerance):  # type: ignore[no-untyped-def]
    """The row outside the working set that z violates most by more than ``tolerance``, -1 when none
    does, -2 when an equality left out (dependent on the set) is not met."""
    worst, p = -tolerance, -1
    for k in range(len(d)):
        if pos[k] < 0:
            slack = _dot(ptr, idx, val, k, z) - d[k]
            if k < n_eq:
                if abs(slack) > tolerance:
                    return -2
            elif slack < worst:
                worst, p = slack, k
    return p


@njit(cache=True, fastmath={"reassoc", "contract"})
def _refine(ptr, idx, val, d, n_eq, n_w, W, Lw, Dw, F, lam, z0, z, residual, y, step):  # type: ignore[no-untyped-def]
    """One step of iterative refinement of the working set's equations M_W z = d_W: the factors drift
    from the rows' Gram matrix over many updates (a pile's cold start: 200-odd), which leaves the working
    rows' slacks at 1e-10 and more; lam and z move by G^-1 times those (inequality multipliers kept >= 0)."""
    for j in range(n_w):
        residual[j] = d[W[j]] - _dot(ptr, idx, val, W[j], z)
    _solve_gram(n_w, Lw, Dw, F, residual, y, 0, step)
    for j in range(n_w):
        lam[j] += step[j]
        if W[j] >= n_eq:
            lam[j] = max(lam[j], 0.0)
    _primal(ptr, idx, val, n_w, W, lam, z0, z)


@njit(cache=True, fastmath={"reassoc", "contract"})
def primal_answer(L, first, z, n_w, W, lam, x, multipliers):  # type: ignore[no-untyped-def]
    """x = P L^-T z and the multipliers of every row (the working set's lam, zero elsewhere)."""
    n = len(z)
    y = z.copy()
    for k in range(n - 1, -1, -1):
        y[k] /= L[k, k]
        for j in range(first[k], k):
            y[j] -= L[k, j] * y[k]
    for k in range(n):
        x[k] = y[n - 1 - k]
    multipliers[:] = 0.0
    for j in range(n_w):
        multipliers[W[j]] = lam[j]
