"""Streaming accumulator of the 17-term fit (split out of host_tools/fitting/fit.py): the Legendre
tables, the numba kernel that folds samples into mergeable weighted moments, and
:class:`Accumulator` / :func:`accumulate_groups`.  The design (moments M, Y, Z and the scalar
slots; the Gram matrix by Legendre linearization) is described in host_tools/fitting/fit.py.

The kernel `_flush` is deliberately unrolled (fixed 7 x 7 / 4 x 4 moment orders, blocks of
_BLOCK samples) for speed under numba; keep it that way."""
from __future__ import annotations

import math

import numba as nb
import numpy as np
from numpy.polynomial import legendre as _leg

from firmware_ref.terms import K_AUX, N_TERMS, POLY_INDEX, TERM_NAMES, TERM_POWERS

__all__ = ["Accumulator", "accumulate_groups"]

CHUNK = 1 << 20          # samples converted per kernel call (bounds memory for non-float64 inputs)
_BLOCK = 256             # samples per vectorized block inside the kernel
_NM, _NQ = 7, 4          # moment orders 0..6, regressor orders 0..3
# scalar slots of the accumulator state
_SW, _N, _YY, _ZY, _ZZ, _UMIN, _UMAX, _VMIN, _VMAX = range(9)
_NS = 9




# ---------------------------------------------------------------------------------------------
# constant tables: Legendre <-> monomial, linearization
# ---------------------------------------------------------------------------------------------
def _tables():
    c = np.zeros((_NQ, _NQ))          # x^i = sum_a C[i, a] P_a(x)
    for i in range(_NQ):
        e = np.zeros(i + 1)
        e[i] = 1.0
        c[i, :i + 1] = _leg.poly2leg(e)
    lin = np.zeros((_NQ, _NQ, _NM))   # P_a P_c = sum_x L[a, c, x] P_x
    for a in range(_NQ):
        for b in range(_NQ):
            ea = np.zeros(a + 1)
            ea[a] = 1.0
            eb = np.zeros(b + 1)
            eb[b] = 1.0
            p = _leg.legmul(ea, eb)
            lin[a, b, :len(p)] = p
    amat = np.zeros((N_TERMS, N_TERMS))  # monomial term k = sum_m A[m, k] q_m
    for k, pw in enumerate(TERM_POWERS):
        if pw is None:
            amat[k, k] = 1.0
            continue
        for a in range(pw[0] + 1):
            for b in range(pw[1] + 1):
                amat[POLY_INDEX[a][b], k] = c[pw[0], a] * c[pw[1], b]
    return c, lin, amat


_C, _LIN, TERM_BASIS = _tables()
_POLY_TERMS = tuple(k for k in range(N_TERMS) if k != K_AUX)
_PT = np.array(_POLY_TERMS)                              # the polynomial terms k and their powers
_PI = np.array([TERM_POWERS[k][0] for k in _POLY_TERMS])  # (i, j) of u^i v^j
_PJ = np.array([TERM_POWERS[k][1] for k in _POLY_TERMS])


def term_label(k):
    return f"k{k} ({TERM_NAMES[k]})"


# ---------------------------------------------------------------------------------------------
# the streaming kernel
# ---------------------------------------------------------------------------------------------
@nb.njit(cache=True, nogil=True, fastmath={"reassoc", "contract", "nsz"})
def _flush(m, bu, bv, by, bz, bw, has_z, pu, pv, wpu, ypu, zpu, M, Y, Z, S, nm, nq):
    """Add the m buffered samples to one group's sums (vectorizable dot products)."""
    for j in range(m):
        pu[0, j] = 1.0
        pu[1, j] = bu[j]
        pv[0, j] = 1.0
        pv[1, j] = bv[j]
    for a in range(2, nm):
        c1 = (2.0 * a - 1.0) / a
        c2 = (a - 1.0) / a
        for j in range(m):
            pu[a, j] = c1 * bu[j] * pu[a - 1, j] - c2 * pu[a - 2, j]
        for j in range(m):
            pv[a, j] = c1 * bv[j] * pv[a - 1, j] - c2 * pv[a - 2, j]
    for a in range(nm):
        for j in range(m):
            wpu[a, j] = bw[j] * pu[a, j]
    for a in range(nm):
        for b in range(nm):
            s = 0.0
            for j in range(m):
                s += wpu[a, j] * pv[b, j]
            M[a, b] += s
    for a in range(nq):
        for j in range(m):
            ypu[a, j] = by[j] * wpu[a, j]
    for a in range(nq):
        for b in range(nq):
            s = 0.0
            for j in range(m):
                s += ypu[a, j] * pv[b, j]
            Y[a, b] += s
    s = 0.0
    for j in range(m):
        s += ypu[0, j] * by[j]
    S[_YY] += s
    s = 0.0
    for j in range(m):
        s += bw[j]
    S[_SW] += s
    S[_N] += m
    if has_z:
        for a in range(nq):
            for j in range(m):
                zpu[a, j] = bz[j] * wpu[a, j]
        for a in range(nq):
            for b in range(nq):
                s = 0.0
                for j in range(m):
                    s += zpu[a, j] * pv[b, j]
                Z[a, b] += s
        s = 0.0
        s2 = 0.0
        for j in range(m):
            s += zpu[0, j] * by[j]
            s2 += zpu[0, j] * bz[j]
        S[_ZY] += s
        S[_ZZ] += s2
    for j in range(m):
        S[_UMIN] = min(S[_UMIN], bu[j])
        S[_UMAX] = max(S[_UMAX], bu[j])
        S[_VMIN] = min(S[_VMIN], bv[j])
        S[_VMAX] = max(S[_VMAX], bv[j])


@nb.njit(cache=True, nogil=True)
def _accumulate(u, v, z, y, w, g, has_z, has_w, has_g, M, Y, Z, S, nm, nq):
    """Accumulate samples into M (G,7,7), Y (G,4,4), Z (G,4,4), S (G,9) by group g (0..G-1).
    Returns -1, or the index of the first w != 0 sample with a non-finite value or w < 0
    (the sums are then partial: callers pass zeroed scratch and commit only on success)."""
    n = u.shape[0]
    B = _BLOCK
    bu = np.empty(B)
    bv = np.empty(B)
    by = np.empty(B)
    bz = np.empty(B)
    bw = np.empty(B)
    pu = np.empty((_NM, B))
    pv = np.empty((_NM, B))
    wpu = np.empty((_NM, B))
    ypu = np.empty((_NQ, B))
    zpu = np.empty((_NQ, B))
    m = 0
    cur = 0
    for i in range(n):
        wi = w[i] if has_w else 1.0
        if wi == 0.0:
            continue
        gi = g[i] if has_g else 0
        ui = u[i]
        vi = v[i]
        yi = y[i]
        zi = z[i] if has_z else 0.0
        if not (wi > 0.0 and math.isfinite(wi) and math.isfinite(ui) and math.isfinite(vi)
                and math.isfinite(yi) and math.isfinite(zi)):
            return i
        if m == B or (gi != cur and m > 0):
            _flush(m, bu, bv, by, bz, bw, has_z, pu, pv, wpu, ypu, zpu, M[cur], Y[cur], Z[cur], S[cur], nm, nq)
            m = 0
        cur = gi
        bu[m] = ui
        bv[m] = vi
        by[m] = yi
        bz[m] = zi
        bw[m] = wi
        m += 1
    if m > 0:
        _flush(m, bu, bv, by, bz, bw, has_z, pu, pv, wpu, ypu, zpu, M[cur], Y[cur], Z[cur], S[cur], nm, nq)
    return -1


@nb.njit(cache=True, nogil=True)
def predict_kernel(coef, u, v, z, has_z, out):
    for i in range(u.shape[0]):
        ui = u[i]
        vi = v[i]
        acc = 0.0
        for a in range(3, -1, -1):
            inner = 0.0
            for b in range(3, -1, -1):
                inner = inner * vi + coef[a * 4 + b]
            acc = acc * ui + inner
        if has_z:
            acc += coef[16] * z[i]
        out[i] = acc


def _scratch(groups):
    S = np.zeros((groups, _NS))
    S[:, _UMIN] = S[:, _VMIN] = np.inf
    S[:, _UMAX] = S[:, _VMAX] = -np.inf
    return np.zeros((groups, _NM, _NM)), np.zeros((groups, _NQ, _NQ)), np.zeros((groups, _NQ, _NQ)), S


def _as_arrays(u, v, z, y, w, g=None):
    """Check shapes; return the arrays (not converted) and n."""
    arrs = {"u": u, "v": v, "y": y}
    if z is not None:
        arrs["z"] = z
    if w is not None:
        arrs["w"] = w
    if g is not None:
        arrs["groups"] = g
    out = {}
    n = None
    for key, a in arrs.items():
        a = np.asarray(a)
        if a.ndim != 1:
            raise ValueError(f"fit input {key!r} must be a 1-D array, got shape {a.shape}")
        if key != "groups" and not (np.issubdtype(a.dtype, np.number) or a.dtype == bool):
            raise ValueError(f"fit input {key!r} must be numeric, got dtype {a.dtype}")
        if n is None:
            n = a.shape[0]
        elif a.shape[0] != n:
            raise ValueError(f"fit input {key!r} has {a.shape[0]} samples, 'u' has {n}")
        out[key] = a
    return out, n


def _run_kernel(arrs, n, gidx, groups):
    """Stream the arrays chunk by chunk into fresh sums; raise ValueError on bad samples."""
    M, Y, Z, S = _scratch(groups)
    has_z, has_w, has_g = "z" in arrs, "w" in arrs, gidx is not None
    dummy = np.zeros(1)
    dummy_g = np.zeros(1, dtype=np.int64)
    for s in range(0, n, CHUNK):
        e = min(n, s + CHUNK)
        f = {k: np.ascontiguousarray(arrs[k][s:e], dtype=np.float64) for k in ("u", "v", "y")}
        zc = np.ascontiguousarray(arrs["z"][s:e], dtype=np.float64) if has_z else dummy
        wc = np.ascontiguousarray(arrs["w"][s:e], dtype=np.float64) if has_w else dummy
        gc = gidx[s:e] if has_g else dummy_g
        bad = _accumulate(f["u"], f["v"], zc, f["y"], wc, gc, has_z, has_w, has_g, M, Y, Z, S, _NM, _NQ)
        if bad >= 0:
            i = s + bad
            vals = {"w": wc[bad] if has_w else 1.0, "u": f["u"][bad], "v": f["v"][bad],
                    "z": zc[bad] if has_z else 0.0, "y": f["y"][bad]}
            if not (vals["w"] >= 0):
                raise ValueError(f"fit input 'w' is {vals['w']} at sample {i}: weights must be finite and >= 0")
            which = next(k for k in ("w", "u", "v", "z", "y") if not math.isfinite(vals[k]))
            raise ValueError(f"fit input {which!r} is {vals[which]} at sample {i}, which has w != 0: "
                             f"non-finite samples must be masked with w = 0")
    return M, Y, Z, S


# ---------------------------------------------------------------------------------------------
# accumulator
# ---------------------------------------------------------------------------------------------
class Accumulator:
    """Mergeable sufficient statistics of the 17-term model (see module docstring).

    ``acc.add(u, v, z, y, w)`` streams samples in; ``a + b`` / ``a.merge(b)`` combine runs,
    devices or chunks; ``a - b`` removes a part (cross-validation).  ``n`` = samples used
    (w > 0), ``sum_w`` = their total weight, ``has_z`` = some z was non-zero."""

    __slots__ = ("M", "Y", "Z", "S")

    def __init__(self):
        M, Y, Z, S = _scratch(1)
        self.M, self.Y, self.Z, self.S = M[0], Y[0], Z[0], S[0]

    def add(self, u, v, z, y, w=None) -> "Accumulator":
        """Accumulate samples (arrays of one length; z, w may be None).  Returns self.  On a bad
        sample it raises ValueError and leaves the accumulator unchanged."""
        arrs, n = _as_arrays(u, v, z, y, w)
        M, Y, Z, S = _run_kernel(arrs, n, None, 1)
        part = Accumulator._from_arrays(M[0], Y[0], Z[0], S[0])
        self._iadd(part, 1.0)
        return self

    @classmethod
    def _from_arrays(cls, M, Y, Z, S):
        acc = cls.__new__(cls)
        acc.M, acc.Y, acc.Z, acc.S = M, Y, Z, S
        return acc

    def copy(self) -> "Accumulator":
        return Accumulator._from_arrays(self.M.copy(), self.Y.copy(), self.Z.copy(), self.S.copy())

    def _iadd(self, other, sign):
        if not isinstance(other, Accumulator):
            raise TypeError(f"cannot combine Accumulator with {type(other).__name__}")
        self.M += sign * other.M
        self.Y += sign * other.Y
        self.Z += sign * other.Z
        for k in (_SW, _N, _YY, _ZY, _ZZ):
            self.S[k] += sign * other.S[k]
        if sign > 0:  # ranges merge; a difference keeps the ranges of the minuend
            self.S[_UMIN] = min(self.S[_UMIN], other.S[_UMIN])
            self.S[_VMIN] = min(self.S[_VMIN], other.S[_VMIN])
            self.S[_UMAX] = max(self.S[_UMAX], other.S[_UMAX])
            self.S[_VMAX] = max(self.S[_VMAX], other.S[_VMAX])
        return self

    def merge(self, other) -> "Accumulator":
        """New accumulator holding the samples of both."""
        return self.copy()._iadd(other, 1.0)

    __add__ = merge

    def __radd__(self, other):  # lets sum(list_of_accumulators) work
        if other == 0:
            return self.copy()
        return self.merge(other)

    def __iadd__(self, other):
        return self._iadd(other, 1.0)

    def __sub__(self, other) -> "Accumulator":
        """Samples of self not in other (other must be a part of self); ranges stay those of self."""
        return self.copy()._iadd(other, -1.0)

    @property
    def n(self) -> int:
        return int(round(self.S[_N]))

    @property
    def sum_w(self) -> float:
        return float(self.S[_SW])

    @property
    def has_z(self) -> bool:
        return bool(self.S[_ZZ] > 0)

    @property
    def u_range(self) -> tuple:
        return (float(self.S[_UMIN]), float(self.S[_UMAX]))

    @property
    def v_range(self) -> tuple:
        return (float(self.S[_VMIN]), float(self.S[_VMAX]))

    def system(self):
        """(G, b, yy): Gram matrix (17 x 17) and X^T W y (17) in the internal basis
        q_k = P_i(u) P_j(v) (k7: z), and sum w y^2."""
        gp = np.einsum("acx,bdy,xy->abcd", _LIN, _LIN, self.M)
        G = np.zeros((N_TERMS, N_TERMS))
        b = np.zeros(N_TERMS)
        b[_PT] = self.Y[_PI, _PJ]
        G[K_AUX, _PT] = G[_PT, K_AUX] = self.Z[_PI, _PJ]
        G[_PT[:, None], _PT[None, :]] = gp[_PI[:, None], _PJ[:, None], _PI[None, :], _PJ[None, :]]
        G[K_AUX, K_AUX] = self.S[_ZZ]
        b[K_AUX] = self.S[_ZY]
        return G, b, float(self.S[_YY])

    def to_dict(self) -> dict:
        """JSON-serializable state (lists of floats); inverse of :meth:`from_dict`."""
        s = [float(x) if math.isfinite(x) else None for x in self.S]
        return {"format": "hdrg-fit-accumulator-1", "M": self.M.tolist(), "Y": self.Y.tolist(),
                "Z": self.Z.tolist(), "S": s}

    @classmethod
    def from_dict(cls, d) -> "Accumulator":
        if d.get("format") != "hdrg-fit-accumulator-1":
            raise ValueError(f"not an hdrg fit accumulator: format {d.get('format')!r}")
        acc = cls()
        acc.M[:] = d["M"]
        acc.Y[:] = d["Y"]
        acc.Z[:] = d["Z"]
        acc.S[:] = [x if x is not None else (np.inf if i in (_UMIN, _VMIN) else -np.inf)
                    for i, x in enumerate(d["S"])]
        return acc

    def __repr__(self):
        return f"Accumulator(n={self.n}, sum_w={self.sum_w:g}, has_z={self.has_z})"


def accumulate_groups(u, v, z, y, w=None, groups=None) -> dict:
    """One pass over the arrays into one :class:`Accumulator` per distinct value of ``groups``
    (run index, time block, ...; any 1-D array of length n).  Returns {group value: Accumulator}
    in sorted order of the values.  groups=None gives {0: Accumulator}.  Contiguous groups are
    fastest (interleaved groups are correct but slower)."""
    arrs, n = _as_arrays(u, v, z, y, w, groups)
    if groups is None:
        M, Y, Z, S = _run_kernel(arrs, n, None, 1)
        keys = [0]
    else:
        keys, gidx = np.unique(arrs.pop("groups"), return_inverse=True)
        M, Y, Z, S = _run_kernel(arrs, n, gidx.astype(np.int64).ravel(), len(keys))
        keys = keys.tolist()
    return {k: Accumulator._from_arrays(M[i], Y[i], Z[i], S[i]) for i, k in enumerate(keys)}
