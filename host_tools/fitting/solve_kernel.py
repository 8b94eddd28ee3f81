"""Compiled kernels of the fitter's small solves (host_tools.fitting.fit), which work on 17 x 17
sufficient statistics only (no sample is read, memory and time do not depend on the number of
samples):

* :func:`pivoted_cholesky`: the diagonally pivoted Cholesky of a scaled internal-basis Gram
  matrix (host_tools.fitting.fit._Factor), the same operations as its former NumPy loop;
* :func:`heldout_sse_sets`: the fold solves of the cross-validated term selection
  (host_tools.fitting.fit: ``_CV`` and ``select_terms``), many term sets on every fold in one
  call instead of one small Python-level QR per (term set, fold, bank).

A fold is given by the statistics the fitter already keeps:

* the training side as its triangular factor in the monomial basis, ``W = R @ TERM_BASIS``
  (rank r x 17, R from the pivoted Cholesky of the fold's accumulated 17 x 17 Gram matrix)
  and ``t`` with R^T t = X^T W y, so that the training least squares of a term set S is
  min || W[:, S] c - t ||;
* the held-out side as its Gram matrix G (17 x 17), X^T W y (17) and sum w y^2, in the internal
  basis (host_tools.fitting.fit_kernel.Accumulator.system).

A term set's fold solve is the one of host_tools.fitting.fit._solve_terms: the columns W[:, S]
scaled to unit norm, Householder QR taken column by column in index order, a column whose
residual after the kept ones is <= rcond (or that comes after r kept columns) is dropped; the
coefficients c (deg/h per unit regressor) follow by back substitution, and the held-out squared
error is sum w (y - x.c)^2 = yy - 2 beta.b + beta.G beta with beta = TERM_BASIS c (the internal
basis).  Its results equal LAPACK's QR of the same r x |S| matrix to float rounding.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

__all__ = ["heldout_sse_sets", "pivoted_cholesky"]


@nb.njit(cache=True, nogil=True)
def pivoted_cholesky(work, tol, L, perm) -> int:
    """Diagonally pivoted Cholesky, in place: ``work`` (m x m, symmetric, unit diagonal) is
    reduced step by step, the pivot being the largest remaining diagonal (the first of equal
    ones); it stops when that is <= ``tol``.  Fills ``L`` (m x m, zeros on entry: the first r
    columns are the factor, rows in pivot order) and ``perm`` (m, 0..m-1 on entry: the pivot
    order).  Returns the rank r."""
    m = work.shape[0]
    r = 0
    while r < m:
        p = r
        for i in range(r + 1, m):
            if work[i, i] > work[p, p]:
                p = i
        if work[p, p] <= tol:
            break
        for j in range(m):
            tmp = work[r, j]
            work[r, j] = work[p, j]
            work[p, j] = tmp
        for i in range(m):
            tmp = work[i, r]
            work[i, r] = work[i, p]
            work[i, p] = tmp
        for j in range(m):
            tmp = L[r, j]
            L[r, j] = L[p, j]
            L[p, j] = tmp
        k = perm[r]
        perm[r] = perm[p]
        perm[p] = k
        L[r, r] = math.sqrt(work[r, r])
        for i in range(r + 1, m):
            L[i, r] = work[i, r] / L[r, r]
        for i in range(r + 1, m):
            for j in range(r + 1, m):
                work[i, j] -= L[i, r] * L[j, r]
        r += 1
    return r


@nb.njit(cache=True, nogil=True, inline="always")
def _reflect(V, tau, kept, r, x):
    """x <- H_{kept-1} ... H_0 x in place: the Householder reflectors h < ``kept`` (vectors V[:, h],
    factors tau[h]) on the first ``r`` entries (the order of operations of LAPACK's dormqr)."""
    for h in range(kept):
        d = 0.0
        for i in range(h, r):
            d += V[i, h] * x[i]
        d *= tau[h]
        for i in range(h, r):
            x[i] -= d * V[i, h]


@nb.njit(cache=True, nogil=True)
def _sse_sets(W, t, rank, G, b, yy, basis, sets, lens, rcond, out):
    """out[s, f] = sum over banks k of the held-out squared error of term set s on fold f.

    W: (F, K, 17, 17) training factors in the monomial basis (rows >= rank[f, k] unused);
    t: (F, K, 17); rank: (F, K) int64 (0: no training sample, all coefficients 0);
    G: (F, K, 17, 17), b: (F, K, 17), yy: (F, K) held-out systems (internal basis);
    basis: (17, 17) TERM_BASIS; sets: (S, 17) int64 term indices (sorted, first lens[s] used);
    rcond: relative column residual under which a column is dropped; out: (S, F) float64."""
    nf, nk, m = W.shape[0], W.shape[1], W.shape[3]
    x = np.empty(m)
    qt = np.empty(m)
    V = np.empty((m, m))          # Householder vectors (column h: rows h..r-1, V[h, h] = 1)
    tau = np.empty(m)
    R = np.empty((m, m))          # triangular factor of the kept scaled columns
    cols = np.empty(m, np.int64)  # term index of each kept column
    scale = np.empty(m)           # its norm
    c = np.empty(m)
    beta = np.empty(m)
    for s in range(sets.shape[0]):
        p = lens[s]
        for f in range(nf):
            total = 0.0
            for kb in range(nk):
                r = rank[f, kb]
                kept = 0
                for j in range(p):
                    col = sets[s, j]
                    nrm2 = 0.0
                    for i in range(r):
                        nrm2 += W[f, kb, i, col] * W[f, kb, i, col]
                    nrm = math.sqrt(nrm2)
                    if not nrm > 0.0 or kept >= r:
                        continue                      # zero column, or beyond the rank of R
                    for i in range(r):
                        x[i] = W[f, kb, i, col] / nrm
                    _reflect(V, tau, kept, r, x)      # apply the reflectors so far
                    a2 = 0.0
                    for i in range(kept, r):
                        a2 += x[i] * x[i]
                    alpha = math.sqrt(a2)
                    if alpha <= rcond:
                        continue                      # (numerically) a combination of the kept ones
                    x0 = x[kept]
                    bet = -alpha if x0 >= 0.0 else alpha
                    tau[kept] = (bet - x0) / bet
                    inv = 1.0 / (x0 - bet)
                    V[kept, kept] = 1.0
                    for i in range(kept + 1, r):
                        V[i, kept] = x[i] * inv
                    for i in range(kept):
                        R[i, kept] = x[i]
                    R[kept, kept] = bet
                    cols[kept] = col
                    scale[kept] = nrm
                    kept += 1
                for i in range(m):
                    beta[i] = 0.0
                if kept:
                    for i in range(r):
                        qt[i] = t[f, kb, i]
                    _reflect(V, tau, kept, r, qt)
                    for i in range(kept - 1, -1, -1):   # back substitution R c = Q^T t
                        acc = qt[i]
                        for j in range(i + 1, kept):
                            acc -= R[i, j] * c[j]
                        c[i] = acc / R[i, i]
                    for j in range(kept):               # internal-basis coefficients
                        cj = c[j] / scale[j]
                        for i in range(m):
                            beta[i] += basis[i, cols[j]] * cj
                bb = 0.0
                bgb = 0.0
                for i in range(m):
                    bb += beta[i] * b[f, kb, i]
                    gi = 0.0
                    for j in range(m):
                        gi += G[f, kb, i, j] * beta[j]
                    bgb += beta[i] * gi
                e = yy[f, kb] - 2.0 * bb + bgb
                total += e if e > 0.0 else 0.0
            out[s, f] = total


def heldout_sse_sets(W, t, rank, G, b, yy, basis, term_sets, rcond) -> np.ndarray:
    """Held-out squared errors [(deg/h)^2 x weight] of each term set (sequence of term-index
    tuples) on every fold, summed over the banks: array (len(term_sets), F).  Arrays as in
    :func:`_sse_sets` (the module doc); term sets are sorted here."""
    m = W.shape[3]
    sets = np.zeros((len(term_sets), m), np.int64)
    lens = np.zeros(len(term_sets), np.int64)
    for s, terms in enumerate(term_sets):
        terms = sorted(terms)
        sets[s, :len(terms)] = terms
        lens[s] = len(terms)
    out = np.zeros((len(term_sets), W.shape[0]))
    _sse_sets(W, t, rank, G, b, yy, basis, sets, lens, float(rcond), out)
    return out
