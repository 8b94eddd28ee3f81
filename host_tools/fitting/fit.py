"""Numeric core of the host fitter of the 17-term bias model (firmware_ref/terms.py, eq. (8) of
Chen et al. 2022):  y ~ sum_k c_k x_k(u, v, z), c in deg/h.

Inputs are arrays of one length n (any real dtype, 1-D):

* ``u``  normalized temperature proxy, dimensionless, nominally in [-1, 1];
* ``v``  normalized proxy rate, dimensionless, nominally in [-1, 1];
* ``z``  auxiliary regressor of k7 (any unit; the unit of k7 is deg/h per unit of z), or None;
* ``y``  target bias, deg/h (the mode-reversal combined output of the golden pipeline);
* ``w``  weight >= 0 or boolean mask, or None (all 1).  Samples with w == 0 never enter (their
  u, v, z, y may hold anything, even NaN); w > 0 samples must be finite.  The fit minimizes
  sum w r^2 (weights are relative inverse variances; a mask gives ordinary least squares).

Design (what the CLI and other stages rely on):

1. One streaming pass (host_tools/fitting/fit_kernel.py).  :class:`Accumulator` keeps mergeable sufficient statistics, never the
   n x 17 design: the weighted moments ``M[a, b] = sum w P_a(u) P_b(v)`` (a, b = 0..6, P = Legendre
   polynomials), ``Y[a, b] = sum w y P_a(u) P_b(v)`` and ``Z[a, b] = sum w z P_a(u) P_b(v)``
   (a, b = 0..3), and the scalars sum w, n, sum w y^2, sum w z y, sum w z^2, min/max of u and v.
   The Gram matrix of the 17 regressors follows exactly from these by the Legendre linearization
   P_a P_c = sum_x L[a, c, x] P_x.  Accumulators add (runs, devices, chunks) and subtract
   (cross-validation: train = total - fold).  Memory is O(1) in n (inputs are converted chunk by
   chunk).
2. Stable solve.  The Gram matrix is formed in the well-conditioned internal basis
   q_k = P_i(u) P_j(v) (k7: z) and factored by diagonally pivoted Cholesky, G = R^T R (numerical
   rank r, scaled tolerance 1e-14); R acts as the triangular factor of the never-built design.
   A monomial term set S is the small problem  min || R A_S c - t ||  with A the exact change of
   basis (u^i v^j = sum C[i,a] C[j,b] P_a(u) P_b(v)) and R^T t = X_q^T y; it is solved by
   Householder QR, so the monomial design's condition number is not squared.  A term whose
   (unit-normalized) column keeps a relative residual <= rcond (default 1e-6) after the terms
   before it in index order is unidentifiable (Cholesky/QR with pivoting of deficient columns
   only, like LINPACK dqrdc2): :class:`UnidentifiableError` names it and the terms it is collinear
   with, or with ``drop_unidentifiable=True`` it is dropped and listed in ``FitResult.dropped``.
3. Term selection ``terms='auto'``: forward stepwise from {k0} plus backward pruning, scored by
   cross-validated held-out squared error over groups (runs, or contiguous time blocks of one
   run: never random samples, the data are autocorrelated); the smallest model whose CV error is
   within max(min_gain x, significance standard errors of) the best CV error is kept (see
   :func:`select_terms`).  Every fold is its training factor R (of the accumulated Gram matrix
   minus the fold's) and the fold's own 17 x 17 system, built once; a candidate term set's fold
   solve is the QR of the columns of R A_S (rank x |S|), all candidates of a step scored in one
   compiled call (host_tools.fitting.solve_kernel): time and memory do not grow with n.

Residual RMS is from the normal equations (sum w y^2 - fitted part): its absolute accuracy is
about 1e-8 x rms(y), ample unless the model is nearly exact.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from host_tools.fitting.solve_kernel import heldout_sse_sets, pivoted_cholesky
from host_tools.fitting.fit_kernel import TERM_BASIS, term_label, predict_kernel, Accumulator, accumulate_groups  # noqa: F401
from host_tools.golden.model import jsonable
from firmware_ref.terms import K_AUX, N_TERMS, PAPER_TERMS, TERM_NAMES, TERM_POWERS, parse_terms
from host_tools.errors import HdrgError

__all__ = [
    "Accumulator", "FitResult", "UnidentifiableError", "accumulate_groups", "block_groups",
    "design_matrix", "fit", "fit_accumulators", "predict", "select_terms", "solve",
]

RCOND = 1e-6             # default identifiability threshold (relative column residual)
_BASIS_TOL = 1e-14       # truncation of the pivoted Cholesky of the scaled internal Gram


class UnidentifiableError(HdrgError, ValueError):
    """The data cannot identify some requested terms.  ``collinear`` maps each unidentifiable
    term index to the tuple of kept term indices it is (numerically) a combination of."""

    def __init__(self, message, collinear):
        super().__init__(message)
        self.collinear = dict(collinear)


def block_groups(n: int, n_blocks: int) -> np.ndarray:
    """Group ids 0..n_blocks-1 for n samples in contiguous, equal-length time blocks (the one
    fold definition: host_tools.fitting.cv.block_ids; every block is its own fold here)."""
    from host_tools.fitting.cv import block_ids
    return block_ids(n, n_blocks)


# ---------------------------------------------------------------------------------------------
# the solve
# ---------------------------------------------------------------------------------------------
class _Factor:
    """Diagonally pivoted Cholesky G = R^T R (R: rank x 17) of an internal-basis system
    (G, b, yy), stopped when the largest remaining diagonal of the unit-diagonal scaled G is
    <= _BASIS_TOL; and t with R^T t = b, so that ||X w - y||^2 = ||R w - t||^2 + yy - t.t."""

    def __init__(self, G, b, yy):
        d = np.sqrt(np.clip(np.diag(G), 0.0, None))
        live = np.flatnonzero(d > 0)               # all-zero regressors stay out
        work = G[np.ix_(live, live)] / np.outer(d[live], d[live])
        m = len(live)
        perm = np.arange(m)
        L = np.zeros((m, m))
        r = pivoted_cholesky(work, _BASIS_TOL, L, perm)
        cols = live[perm]
        self.R = np.zeros((r, N_TERMS))
        self.R[:, cols] = L[:, :r].T * d[cols]
        self.t = np.linalg.solve(self.R[:, cols[:r]].T, b[cols[:r]]) if r else np.zeros(0)
        self.yy = yy


def _factor(acc: Accumulator) -> _Factor:
    return _Factor(*acc.system())


def _solve_terms(fac: _Factor, terms, rcond, explain=True):
    """Least squares over the monomial terms (sorted indices): min ||W c - t|| with W = R A_S.
    Columns are scaled to unit norm and taken in order; a column whose residual after the kept
    ones is <= rcond is dropped (QR pivoting of deficient columns only).  Returns a dict: coef
    (17), kept, collinear {dropped: kept terms it is a combination of (if explain)}, Rk (R of
    the scaled kept columns), norms (their norms), rss."""
    terms = list(terms)
    W = fac.R @ TERM_BASIS[:, terms]
    norms = np.sqrt(np.einsum("ij,ij->j", W, W))
    keep = [j for j in range(len(terms)) if norms[j] > 0]
    dropped = [j for j in range(len(terms)) if norms[j] == 0]
    Q = Rk = None
    while keep:
        Q, Rk = np.linalg.qr(W[:, keep] / norms[keep])   # kept when no column is dropped
        diag = np.abs(np.diag(Rk))
        bad = np.flatnonzero(diag <= rcond)
        if len(bad):
            dropped.append(keep.pop(int(bad[0])))
        elif len(keep) > len(diag):               # more columns than the rank of R
            dropped.append(keep.pop(len(diag)))
        else:
            break
    coef = np.zeros(N_TERMS)
    kept = [terms[j] for j in keep]
    qt = np.zeros(0)
    if not keep:
        Rk = np.zeros((0, 0))
    else:
        qt = Q.T @ fac.t
        coef[kept] = np.linalg.solve(Rk, qt) / norms[keep]
    collinear = {}
    for j in sorted(dropped):
        with_ = ()
        if explain and norms[j] > 0 and keep:
            x = np.linalg.lstsq(W[:, keep], W[:, j], rcond=None)[0]
            with_ = tuple(kept[i] for i in np.flatnonzero(np.abs(x) * norms[keep] > 1e-3 * norms[j]))
        collinear[terms[j]] = with_
    return {"coef": coef, "kept": tuple(kept), "collinear": collinear, "Rk": Rk,
            "norms": norms[keep], "rss": max(fac.yy - float(qt @ qt), 0.0)}


def _unidentifiable_message(collinear):
    parts = []
    for k, with_ in collinear.items():
        if not with_:
            parts.append(f"{term_label(k)} is zero on all used samples" + (" (no z given)" if k == K_AUX else ""))
        else:
            parts.append(f"{term_label(k)} is collinear with " + ", ".join(term_label(j) for j in with_))
    hint = ""
    if any(TERM_POWERS[k] is not None and TERM_POWERS[k][1] > 0 for k in collinear):
        hint = ("  Typical cause: too few distinct rates, e.g. one run at one constant rate (the rate "
                "terms then repeat the constant and temperature terms); fit runs at several rates.")
    return ("the data cannot identify " + ", ".join(term_label(k) for k in collinear) + ": "
            + "; ".join(parts) + "." + hint + "  Select fewer terms or pass drop_unidentifiable=True.")


def _check_terms(terms, acc_has_z):
    if terms is None or (isinstance(terms, str) and terms.strip().lower() == "all"):
        return tuple(sorted(PAPER_TERMS + ((K_AUX,) if acc_has_z else ())))
    if isinstance(terms, str):
        return parse_terms(terms)
    out = []
    for k in terms:
        if isinstance(k, str) or not float(k).is_integer() or not 0 <= int(k) < N_TERMS:
            raise ValueError(f"unknown term {k!r}: terms are indices 0..{N_TERMS - 1}")
        out.append(int(k))
    if not out:
        raise ValueError("empty term selection")
    if len(set(out)) != len(out):
        raise ValueError(f"duplicate terms in {tuple(terms)}")
    return tuple(sorted(out))


@dataclass
class FitResult:
    """A fitted model.  coef: 17 coefficients in deg/h (per unit of z for k7), 0 for terms not
    enabled; terms: enabled (fitted) term indices; requested: the terms asked for (or the
    candidates of 'auto'); dropped: requested terms dropped as unidentifiable, collinear:
    {dropped term: kept terms it is collinear with}; stderr: 17 standard errors in deg/h (0 for
    terms not enabled; they assume white residuals with the weights as inverse variances, and are
    optimistic, often by a large factor, for autocorrelated data such as drift records);
    cond: 2-norm condition number of the enabled design with unit-norm columns; rms: weighted
    residual RMS, deg/h; sigma: residual scale sqrt(RSS_w / (n - p) * n / sum_w) in deg/h
    (sqrt(RSS / (n - p)) for a mask); n: samples used
    (w > 0); sum_w: their total weight; dof = n - p; u_range, v_range: data ranges; cv: None or
    the cross-validation record (method, groups, path, cv_rms); extra: free metadata for the
    caller (device, files, normalization), kept in to_dict()."""

    coef: np.ndarray
    terms: tuple
    requested: tuple
    dropped: tuple
    collinear: dict
    stderr: np.ndarray
    cond: float
    rms: float
    sigma: float
    n: int
    sum_w: float
    dof: int
    u_range: tuple
    v_range: tuple
    cv: dict | None = None
    rcond: float = RCOND
    extra: dict = field(default_factory=dict)
    coef_mode2: np.ndarray | None = None
    stderr_mode2: np.ndarray | None = None

    def predict(self, u, v, z=None) -> np.ndarray:
        """Model bias in deg/h at (u, v, z)."""
        return predict(self.coef, u, v, z)

    def to_dict(self) -> dict:
        """Plain JSON-serializable dict (non-finite floats become None)."""
        return jsonable({
            "model": "hdrg-17-term", "coef": self.coef, "terms": self.terms,
            "term_names": [TERM_NAMES[k] for k in range(N_TERMS)], "requested": self.requested,
            "dropped": self.dropped, "collinear": {f"k{k}": [int(j) for j in v] for k, v in self.collinear.items()},
            "stderr": self.stderr, "cond": self.cond, "rms": self.rms, "sigma": self.sigma, "n": self.n,
            "sum_w": self.sum_w, "dof": self.dof, "u_range": self.u_range, "v_range": self.v_range,
            "cv": self.cv, "rcond": self.rcond, "extra": self.extra,
            "stderr_note": "assumes white residuals; optimistic for autocorrelated data",
            **({} if self.coef_mode2 is None else {"coef_mode2": self.coef_mode2,
                                                  "stderr_mode2": self.stderr_mode2}),
        })


def _result(sol, requested, n, sum_w, u_range, v_range, rcond, cv=None):
    kept = sol["kept"]
    p = len(kept)
    dof = n - p
    rss = sol["rss"]
    rms = math.sqrt(rss / sum_w) if sum_w > 0 else math.nan
    sigma = math.sqrt(rss / dof * n / sum_w) if dof > 0 and sum_w > 0 else math.nan
    stderr = np.zeros(N_TERMS)
    cond = math.nan
    if p:
        Rk = sol["Rk"]
        rinv = np.linalg.solve(Rk, np.eye(p))  # scaled-column covariance factor
        # weighted: cov = s2 (X^T W X)^-1 with s2 = RSS/dof (weights as relative inverse variances)
        s2 = rss / dof if dof > 0 else math.nan
        stderr[list(kept)] = math.sqrt(s2) * np.sqrt(np.einsum("ij,ij->i", rinv, rinv)) / sol["norms"]
        sv = np.linalg.svd(Rk, compute_uv=False)
        cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    return FitResult(coef=sol["coef"], terms=tuple(kept), requested=tuple(requested),
                     dropped=tuple(sol["collinear"]), collinear=sol["collinear"], stderr=stderr,
                     cond=cond, rms=rms, sigma=sigma, n=n, sum_w=sum_w, dof=dof, u_range=u_range,
                     v_range=v_range, cv=cv, rcond=rcond)


def solve(acc: Accumulator, terms=None, *, drop_unidentifiable=False, rcond=RCOND) -> FitResult:
    """Fit the terms to the accumulated data.  terms: None or 'all' (the paper's 16 terms, plus
    k7 when some z was non-zero), 'paper', a spec for ``parse_terms`` ('k0,k1,k4', 'const,temp'),
    or a sequence of indices.  Raises :class:`UnidentifiableError` (a ValueError) when the data
    cannot identify some term (relative column residual <= rcond), unless drop_unidentifiable,
    which drops such terms (in index order, later terms first to go) and lists them."""
    if not isinstance(acc, Accumulator):
        raise TypeError(f"solve needs an Accumulator, got {type(acc).__name__}")
    if isinstance(terms, str) and terms.strip().lower() == "auto":
        raise ValueError("terms='auto' needs groups: use fit(..., groups=...) or fit_accumulators({run: acc, ...})")
    terms = _check_terms(terms, acc.has_z)
    if acc.n == 0:
        raise ValueError("no samples to fit: every w is 0 (or no data was added)")
    fac = _factor(acc)
    sol = _solve_terms(fac, terms, rcond)
    if sol["collinear"] and not drop_unidentifiable:
        raise UnidentifiableError(_unidentifiable_message(sol["collinear"]), sol["collinear"])
    return _result(sol, terms, acc.n, acc.sum_w, acc.u_range, acc.v_range, rcond)


# ---------------------------------------------------------------------------------------------
# cross-validation and term selection
# ---------------------------------------------------------------------------------------------
def _heldout_sse(coef, G, b, yy):
    """sum w (y - X c)^2 on a held-out system, from its internal-basis sums (host_tools.fitting.cv.heldout_sse)."""
    from host_tools.fitting.cv import heldout_sse
    return max(heldout_sse(TERM_BASIS @ coef, yy, b, G), 0.0)


def heldout_error(train: Accumulator, test: Accumulator, terms, *, rcond=RCOND) -> float:
    """sum w (y - X c)^2 [(deg/h)^2 x weight] over the samples of ``test`` of the coefficients
    of ``terms`` fitted on ``train`` (terms unidentifiable on ``train`` dropped): one fold of
    :class:`_CV`, for callers with their own folds (host_tools.fitting.legs.leg_cv)."""
    if test.n == 0:
        return 0.0
    return _fold_sse(_factor(train) if train.n else None, test.system(), tuple(sorted(terms)), rcond)


def heldout_errors(train: Accumulator, test: Accumulator, terms, *, rcond=RCOND) -> tuple:
    """(:func:`heldout_error`, the same about the held-out samples' own mean residual): the second
    leaves out the held-out part's level (its offset), as a std of its output does."""
    if test.n == 0:
        return 0.0, 0.0
    from host_tools.fitting.cv import heldout_sse
    fac = _factor(train) if train.n else None
    terms = tuple(sorted(terms))
    coef = np.zeros(N_TERMS) if fac is None else _solve_terms(fac, terms, rcond, explain=False)["coef"]
    G, b, yy = test.system()
    one = np.zeros(N_TERMS)
    one[0] = 1.0                      # k0: the constant regressor
    sse = heldout_sse(TERM_BASIS @ coef, yy, b, G)
    moved = heldout_sse(TERM_BASIS @ (coef + one), yy, b, G)    # sse - 2 sum(w r) + sum(w)
    sw = test.sum_w
    level = (sse + sw - moved) / 2.0                             # sum(w r)
    return max(sse, 0.0), max(sse - level * level / sw, 0.0) if sw > 0 else 0.0


def _fold_sse(fac, test, terms, rcond) -> float:
    """Held-out sum of squared errors on the system ``test`` = (G, b, yy) of ``terms`` (sorted)
    fitted through the training factor ``fac`` (None: no training sample, all coefficients 0)."""
    coef = np.zeros(N_TERMS) if fac is None else _solve_terms(fac, terms, rcond, explain=False)["coef"]
    return _heldout_sse(coef, *test)


def _banks_of(group) -> tuple:
    """A CV group as a tuple of per-bank Accumulators (an Accumulator is one bank)."""
    return group if isinstance(group, tuple) else (group,)


class _CV:
    """Held-out errors per group.  A group is an Accumulator, or a tuple of per-bank Accumulators
    (regress_first: (mode-1 samples, mode-2 samples)); every bank is fitted with the same terms
    on the other groups' samples of that bank, and a group's error is the sum over its banks.
    The per-fold training factors and held-out systems are built once (17 x 17 each, whatever the
    number of samples); :meth:`sse_many` scores many term sets in one compiled call
    (host_tools.fitting.solve_kernel), the fold solve of :func:`_solve_terms`."""

    def __init__(self, accs, rcond):
        self.accs = [_banks_of(a) for a in accs]
        if len(self.accs) < 2:
            raise ValueError(f"cross-validation needs at least 2 groups (runs or time blocks), got {len(self.accs)}")
        nb = len(self.accs[0])
        if any(len(g) != nb for g in self.accs):
            raise ValueError("cross-validation groups differ in their number of banks")
        totals = [sum(g[b] for g in self.accs) for b in range(nb)]
        self.total = sum(totals)
        nf = len(self.accs)
        self.W = np.zeros((nf, nb, N_TERMS, N_TERMS))
        self.t = np.zeros((nf, nb, N_TERMS))
        self.rank = np.zeros((nf, nb), np.int64)
        self.G = np.zeros((nf, nb, N_TERMS, N_TERMS))
        self.b = np.zeros((nf, nb, N_TERMS))
        self.yy = np.zeros((nf, nb))
        for f, g in enumerate(self.accs):
            for k in range(nb):
                self.G[f, k], self.b[f, k], self.yy[f, k] = g[k].system()
                if totals[k].n - g[k].n > 0:
                    fac = _factor(totals[k] - g[k])
                    r = fac.R.shape[0]
                    self.W[f, k, :r] = fac.R @ TERM_BASIS
                    self.t[f, k, :r] = fac.t
                    self.rank[f, k] = r
        self.sum_w = self.total.sum_w
        self.rcond = rcond
        self.cache = {}

    def sse_many(self, term_sets) -> list:
        """Per-group held-out errors (arrays of length groups) of each term set, in order."""
        keys = [tuple(sorted(terms)) for terms in term_sets]
        todo = list(dict.fromkeys(k for k in keys if k not in self.cache))
        if todo:
            out = heldout_sse_sets(self.W, self.t, self.rank, self.G, self.b, self.yy, TERM_BASIS, todo, self.rcond)
            self.cache.update(zip(todo, out))
        return [self.cache[k] for k in keys]

    def sse(self, terms):
        return self.sse_many([terms])[0]

    def rms(self, terms):
        return math.sqrt(float(self.sse(terms).sum()) / self.sum_w)


def _cv_se(e, sw):
    """Standard error of the CV mean squared error (host_tools.fitting.cv.cv_se)."""
    from host_tools.fitting.cv import cv_se
    return cv_se(e, sw)


def select_terms(accs, candidates=None, *, start=(0,), significance=1.0, min_gain=0.02, rcond=RCOND):
    """Term selection by cross-validation over groups: a forward stepwise path, the smallest
    model on it whose CV error is within a tolerance of the best one, then backward pruning.

    accs: sequence or mapping of per-group :class:`Accumulator` (runs, or contiguous time blocks
    of one run; at least 2), or of per-group tuples of per-bank Accumulators (regress_first: the
    banks share the term set and a group's error is the sum over its banks).  Fold f trains on total - group f and is scored by the group's
    held-out weighted squared error e_f (from its sums); CV MSE = sum_f e_f / sum w.  From
    ``start`` (default {k0}, always kept) the candidate that lowers the CV MSE most is added,
    step by step, until no candidate is left; let b be the step of least CV MSE.  Tolerance =
    max(``min_gain`` x MSE_b, ``significance`` x SE_b), SE_b the standard error of MSE_b from
    the spread of the per-fold MSEs (the one-standard-error rule; min_gain guards against tiny
    gains when folds agree too well).  The first step within MSE_b + tolerance is selected
    (scoring the path against b, not each step alone, keeps pairs of terms that only help
    together, e.g. v and u*v); then terms are removed one at a time (least harmful first) while
    the smaller model stays within the tolerance (this undoes early greedy picks such as v^3
    standing in for v).  Terms unidentifiable on a training fold are dropped in that fold.
    Returns (terms, cv): cv = {"method", "groups", "significance", "min_gain", "tolerance_mse"
    (deg/h)^2, "path": [{"step", "added" or "removed", "terms", "cv_rms" (deg/h), "excess" (CV
    MSE above b in tolerances), "candidates": {"k<i>": cv_rms} (forward steps)}],
    "selected_step", "cv_rms"}."""
    accs = list(accs.values()) if isinstance(accs, Mapping) else list(accs)
    cv = _CV(accs, rcond)
    has_z = cv.total.has_z
    cand = _check_terms(candidates, has_z)
    fixed = tuple(sorted(_check_terms(start, has_z))) if start else ()
    chosen = fixed
    g = len(accs)
    errs = [cv.sse(chosen) if chosen else np.array([sum(b.system()[2] for b in g) for g in cv.accs])]
    path = [{"step": 0, "added": None, "terms": list(chosen)}]
    while True:
        rest = [k for k in cand if k not in chosen]
        if not rest:
            break
        trials = dict(zip(rest, cv.sse_many([chosen + (k,) for k in rest])))
        best = min(rest, key=lambda k: trials[k].sum())
        chosen = tuple(sorted(chosen + (best,)))
        errs.append(trials[best])
        path.append({"step": len(path), "added": best, "terms": list(chosen),
                     "candidates": {f"k{k}": math.sqrt(trials[k].sum() / cv.sum_w) for k in rest}})
    eb = errs[int(np.argmin([e.sum() for e in errs]))]
    sw = np.array([sum(b.sum_w for b in g) for g in cv.accs])
    tol = max(min_gain * eb.sum() / cv.sum_w, significance * _cv_se(eb, sw))  # in MSE

    def excess(e):  # CV MSE above the best, in units of the tolerance
        return float((e.sum() - eb.sum()) / cv.sum_w / tol) if tol > 0 else 0.0

    selected = None
    for j, e in enumerate(errs):
        path[j].update(cv_rms=math.sqrt(e.sum() / cv.sum_w), excess=excess(e))
        if selected is None and excess(e) <= 1.0:
            selected = j
    terms = tuple(path[selected]["terms"])
    while True:  # backward pruning
        drop = [k for k in terms if k not in fixed]
        trials = dict(zip(drop, cv.sse_many([tuple(x for x in terms if x != k) for k in drop])))
        ok = [k for k, e in trials.items() if excess(e) <= 1.0]
        if not ok:
            break
        k = min(ok, key=lambda k: trials[k].sum())
        terms = tuple(x for x in terms if x != k)
        path.append({"step": len(path), "removed": k, "terms": list(terms),
                     "cv_rms": math.sqrt(trials[k].sum() / cv.sum_w), "excess": excess(trials[k])})
        selected = len(path) - 1
    return terms, {"method": "forward-stepwise+prune", "groups": g, "significance": significance,
                   "min_gain": min_gain, "tolerance_mse": tol, "path": path,
                   "selected_step": selected, "cv_rms": path[selected]["cv_rms"]}


def fit_accumulators(accs, terms=None, *, drop_unidentifiable=False, rcond=RCOND, significance=1.0,
                     min_gain=0.02, candidates=None) -> FitResult:
    """Fit from one Accumulator, or a sequence/mapping of per-group Accumulators (runs, devices,
    time blocks) which are merged.  terms as in :func:`solve`, or 'auto' (needs >= 2 groups;
    :func:`select_terms` over ``candidates``, default all terms).  With >= 2 groups the result's
    cv holds the cross-validated RMS of the final term set (and the selection path for 'auto')."""
    if isinstance(accs, Accumulator):
        groups = [accs]
    else:
        groups = list(accs.values()) if isinstance(accs, Mapping) else list(accs)
    if not groups:
        raise ValueError("no accumulators to fit")
    if isinstance(groups[0], tuple):
        return _fit_banks(groups, terms, drop_unidentifiable=drop_unidentifiable, rcond=rcond,
                          significance=significance, min_gain=min_gain, candidates=candidates)
    total = sum(groups)
    cv = None
    if isinstance(terms, str) and terms.strip().lower() == "auto":
        if len(groups) < 2:
            raise ValueError("terms='auto' needs at least 2 groups (runs or time blocks) to cross-validate")
        if total.n == 0:
            raise ValueError("no samples to fit: every w is 0 (or no data was added)")
        terms, cv = select_terms(groups, candidates, significance=significance, min_gain=min_gain, rcond=rcond)
        res = solve(total, terms, drop_unidentifiable=True, rcond=rcond)
        res.requested = _check_terms(candidates, total.has_z)
    else:
        res = solve(total, terms, drop_unidentifiable=drop_unidentifiable, rcond=rcond)
        if len(groups) >= 2:
            cvo = _CV(groups, rcond)
            cv = {"method": "fixed", "groups": len(groups), "cv_rms": cvo.rms(res.terms)}
    res.cv = cv
    return res


def _fit_banks(groups, terms, *, drop_unidentifiable, rcond, significance, min_gain, candidates) -> FitResult:
    """Two-bank (regress_first) fit: groups are (mode-1 Accumulator, mode-2 Accumulator) tuples.
    One term set for both banks (selected jointly for 'auto'); a term unidentifiable in either
    bank is dropped from both (or refused).  Returns one FitResult: coef/stderr of bank 1,
    coef_mode2/stderr_mode2 of bank 2; rms, n, sum_w, dof over both; cond the larger one."""
    if any(len(g) != 2 for g in groups):
        raise ValueError("a two-bank fit needs (mode 1, mode 2) accumulator pairs")
    totals = [sum(g[b] for g in groups) for b in range(2)]
    for b, t in enumerate(totals):
        if t.n == 0:
            raise ValueError(f"no samples of mode {b + 1} to fit its coefficient bank")
    merged = totals[0] + totals[1]
    cv = None
    auto = isinstance(terms, str) and terms.strip().lower() == "auto"
    if auto:
        if len(groups) < 2:
            raise ValueError("terms='auto' needs at least 2 groups (runs or time blocks) to cross-validate")
        terms, cv = select_terms(groups, candidates, significance=significance, min_gain=min_gain, rcond=rcond)
        requested = _check_terms(candidates, merged.has_z)
    else:
        requested = _check_terms(terms, merged.has_z)
    keep = tuple(requested if not auto else terms)
    sols = [_solve_terms(_factor(t), keep, rcond) for t in totals]
    collinear = {}
    for sol in sols:
        collinear.update(sol["collinear"])
    if collinear and not (drop_unidentifiable or auto):
        raise UnidentifiableError(_unidentifiable_message(collinear), collinear)
    if collinear:
        keep = tuple(k for k in keep if k not in collinear)
        sols = [_solve_terms(_factor(t), keep, rcond) for t in totals]
    res = [_result(sol, keep, t.n, t.sum_w, t.u_range, t.v_range, rcond) for sol, t in zip(sols, totals)]
    rss = sum(r.rms ** 2 * r.sum_w for r in res)
    n, sw, dof = merged.n, merged.sum_w, merged.n - 2 * len(keep)
    if len(groups) >= 2 and cv is None:
        cv = {"method": "fixed", "groups": len(groups), "cv_rms": _CV(groups, rcond).rms(keep)}
    return FitResult(coef=res[0].coef, terms=keep, requested=tuple(requested), dropped=tuple(collinear),
                     collinear=collinear, stderr=res[0].stderr, cond=max(r.cond for r in res),
                     rms=math.sqrt(rss / sw), sigma=math.sqrt(rss / dof * n / sw) if dof > 0 else math.nan,
                     n=n, sum_w=sw, dof=dof, u_range=merged.u_range, v_range=merged.v_range, cv=cv,
                     rcond=rcond, coef_mode2=res[1].coef, stderr_mode2=res[1].stderr)


def fit(u, v, z, y, w=None, *, terms=None, groups=None, cv_blocks=8, drop_unidentifiable=False,
        rcond=RCOND, significance=1.0, min_gain=0.02, candidates=None) -> FitResult:
    """Fit the 17-term model to arrays in one pass (see the module docstring for the inputs).
    groups: per-sample group ids (runs) for cross-validation; if None and terms='auto', the
    samples are split into ``cv_blocks`` contiguous time blocks."""
    auto = isinstance(terms, str) and terms.strip().lower() == "auto"
    if groups is None and auto:
        groups = block_groups(np.asarray(u).shape[0], cv_blocks)
    accs = accumulate_groups(u, v, z, y, w, groups)
    return fit_accumulators(accs, terms, drop_unidentifiable=drop_unidentifiable, rcond=rcond,
                            significance=significance, min_gain=min_gain, candidates=candidates)


def predict(coef, u, v, z=None) -> np.ndarray:
    """Evaluate the model sum_k coef[k] x_k(u, v, z) (deg/h) at arrays u, v (and z for k7)."""
    coef = np.asarray(coef, dtype=np.float64)
    if coef.shape != (N_TERMS,):
        raise ValueError(f"coef must have {N_TERMS} entries, got shape {coef.shape}")
    u = np.ascontiguousarray(u, dtype=np.float64)
    v = np.ascontiguousarray(v, dtype=np.float64)
    if u.shape != v.shape or u.ndim != 1:
        raise ValueError(f"u and v must be 1-D arrays of one length, got {u.shape} and {v.shape}")
    # coefficient grid c[i*4 + j] of u^i v^j, and k7 at slot 16
    flat = np.zeros(17)
    for k, pw in enumerate(TERM_POWERS):
        if pw is not None:
            flat[pw[0] * 4 + pw[1]] = coef[k]
    flat[16] = coef[K_AUX]
    has_z = z is not None
    zz = np.ascontiguousarray(z, dtype=np.float64) if has_z else np.zeros(1)
    if has_z and zz.shape != u.shape:
        raise ValueError(f"z has shape {zz.shape}, u has {u.shape}")
    if not has_z and coef[K_AUX] != 0:
        raise ValueError("coef has a non-zero k7 (z) term but no z was given")
    out = np.empty_like(u)
    predict_kernel(flat, u, v, zz, has_z, out)
    return out


def design_matrix(u, v, z=None, terms=range(N_TERMS)) -> np.ndarray:
    """The explicit n x len(terms) monomial design, Fortran order (for tests, references and
    small data only: 8 * 17 * n bytes)."""
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    up = [np.ones_like(u), u, u * u, u * u * u]
    vp = [np.ones_like(v), v, v * v, v * v * v]
    terms = list(terms)
    X = np.empty((len(u), len(terms)), order="F")
    for col, k in enumerate(terms):
        pw = TERM_POWERS[k]
        if pw is None:
            X[:, col] = 0.0 if z is None else np.asarray(z, dtype=np.float64)
        else:
            np.multiply(up[pw[0]], vp[pw[1]], out=X[:, col])
    return X


# -- run-log glue and the `hdrg fit` command ------------------------------------------------------

def fit_logs(logs, config, terms=None, *, drop_unidentifiable=False, cv_blocks=8, significance=None,
             min_gain=0.02, blocks=None, masks=None):
    """Fit a :class:`host_tools.golden.model.BiasModel` with ``config`` (a ModelConfig) to RunLogs.

    Each log goes through the golden pipeline (:func:`host_tools.golden.compensate.prepare`): only its
    used samples enter (``Prepared.used``: exchange samples, rate-estimator warm-up and settling
    never do; FTR and combine_first: nor the samples before the first valid mode-reversal
    output).  One accumulator per run; with a single run and ``terms='auto'`` the run is cut into
    ``cv_blocks`` contiguous time blocks for the cross-validation.  A regress_first config fits
    two banks: target c = s * rate on the used samples, bank 1 on mode-1 samples, bank 2 on
    mode-2 samples, one term set (see :func:`fit_accumulators`).  ``terms`` None ->
    host_tools.golden.compensate.DEFAULT_TERMS.  ``blocks`` True: cut a single run into ``cv_blocks``
    time blocks whatever the terms (so fixed terms get a cross-validated rms too); None: only for
    'auto'.  ``significance`` of the 'auto' selection (:func:`select_terms`): None ->
    host_tools.golden.compensate.DEFAULT_SIGNIFICANCE.  ``masks``: None, or one bool array per log
    (its length) AND-ed with the used samples (e.g. the samples valid for several rate estimators,
    host_tools.fitting.fit_rate.fit_auto_rate).
    Returns (model, FitResult)."""
    from host_tools.golden.compensate import DEFAULT_SIGNIFICANCE, DEFAULT_TERMS, prepare
    from host_tools.golden.model import BiasModel

    terms = DEFAULT_TERMS if terms is None else terms
    significance = DEFAULT_SIGNIFICANCE if significance is None else significance
    check_cv_blocks(cv_blocks)
    auto = isinstance(terms, str) and terms.strip().lower() == "auto"
    two = config.reversal is not None and config.reversal.order == "regress_first"
    accs = {}
    if masks is not None and len(masks) != len(logs):
        raise ValueError(f"masks: one per log expected, got {len(masks)} for {len(logs)} logs")
    for i, log in enumerate(logs):
        pr = prepare(log, config)
        if masks is not None:
            if np.shape(masks[i]) != pr.used.shape:
                raise ValueError(f"{log.source}: mask of shape {np.shape(masks[i])}, the log has {len(pr.used)} samples")
            pr.used = pr.used & np.asarray(masks[i], bool)
        if not pr.used.any():
            raise ValueError(f"{log.source}: no valid sample to fit (all exchange, warm-up or before the first pair)")
        bank_w = [pr.used & (pr.mode == 1), pr.used & (pr.mode == 2)] if two else [pr.used]
        if (auto if blocks is None else blocks) and len(logs) == 1:
            groups = block_groups(len(pr.y), cv_blocks)
            per = [accumulate_groups(pr.u, pr.v, pr.z, pr.y, w, groups) for w in bank_w]
            for g in per[0]:
                accs[f"{log.source}#block{g}"] = tuple(p[g] for p in per) if two else per[0][g]
        else:
            banks = tuple(Accumulator().add(pr.u, pr.v, pr.z, pr.y, w) for w in bank_w)
            accs[f"{log.source}#{i}"] = banks if two else banks[0]
    res = fit_accumulators(accs, terms, drop_unidentifiable=drop_unidentifiable,
                           significance=significance, min_gain=min_gain)
    info = res.to_dict()
    info["train"] = [log.source for log in logs]
    # terms the data do not support: |coef| < 2 standard errors (the standard errors are already
    # optimistic for autocorrelated residuals, so these are certainly not identified)
    info["insignificant"] = [int(k) for k in res.terms if k != 0 and abs(res.coef[k]) < 2.0 * res.stderr[k]
                             and (res.coef_mode2 is None or abs(res.coef_mode2[k]) < 2.0 * res.stderr_mode2[k])]
    model = BiasModel(config, tuple(res.terms), np.asarray(res.coef, np.float64), info,
                      coef_mode2=None if res.coef_mode2 is None else np.asarray(res.coef_mode2, np.float64))
    return model, res


MAX_CV_BLOCKS = 64   # more time blocks than this: each is seconds long, the fit slows with no gain


def check_cv_blocks(cv_blocks) -> None:
    """Refuse a number of cross-validation time blocks outside 2..MAX_CV_BLOCKS (ValueError)."""
    if isinstance(cv_blocks, bool) or not isinstance(cv_blocks, (int, np.integer)) or not 2 <= cv_blocks <= MAX_CV_BLOCKS:
        raise ValueError(f"cv_blocks (--cv-blocks) must be an integer in 2..{MAX_CV_BLOCKS}, not {cv_blocks!r}")


MIN_SAMPLES_PER_TERM = 10   # `hdrg fit` refuses fewer valid samples per coefficient unless --force
