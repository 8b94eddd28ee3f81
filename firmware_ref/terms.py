"""The 17-term bias model of Chen et al. 2022, eq. (8): the one table that the golden model, the
fitter, the quantizer, the fixed-point evaluator, the C twin and the docs all read.

B = sum_k k_k * x_k with, in the paper's numbering,

==========  =====================  ==========================================
 k          regressor x_k           meaning
==========  =====================  ==========================================
 k0         1                       constant bias
 k1..k3     u, u^2, u^3             cubic in the normalized temperature proxy
 k4..k6     v, v^2, v^3             cubic in the normalized proxy rate
 k7         z                       auxiliary regressor (ours; 0 until the
                                    closed loop assigns a generator)
 k8..k10    u v, u v^2, u v^3       cross terms
 k11..k13   u^2 v, u^2 v^2, u^2 v^3
 k14..k16   u^3 v, u^3 v^2, u^3 v^3
==========  =====================  ==========================================

u and v are dimensionless, in [-1, 1] over the declared operating range; coefficients are in deg/h.
"""
from __future__ import annotations

N_TERMS = 17
K_AUX = 7  # index of the auxiliary term k7 * z

# (power of u, power of v) for every term but k7; k7 is None (it multiplies z)
TERM_POWERS: tuple = (
    (0, 0),
    (1, 0), (2, 0), (3, 0),
    (0, 1), (0, 2), (0, 3),
    None,
    (1, 1), (1, 2), (1, 3),
    (2, 1), (2, 2), (2, 3),
    (3, 1), (3, 2), (3, 3),
)

# index k of the term u^i v^j (i, j in 0..3), for Horner evaluation: POLY_INDEX[i][j]
POLY_INDEX: tuple = tuple(tuple(TERM_POWERS.index((i, j)) for j in range(4)) for i in range(4))

TERM_NAMES: tuple = tuple(
    "z" if p is None else ("1" if p == (0, 0) else "*".join(
        ([f"u^{p[0]}" if p[0] > 1 else "u"] if p[0] else []) + ([f"v^{p[1]}" if p[1] > 1 else "v"] if p[1] else [])))
    for p in TERM_POWERS
)

# the paper's groups: which terms a gyroscope may drop together
GROUPS = {
    "const": (0,),
    "temp": (1, 2, 3),
    "rate": (4, 5, 6),
    "aux": (7,),
    "cross": (8, 9, 10, 11, 12, 13, 14, 15, 16),
}
PAPER_TERMS = tuple(k for k in range(N_TERMS) if k != K_AUX)  # the 16 terms of eq. (8)


def parse_terms(spec: str) -> tuple:
    """Parse a term selection: 'all' (the paper's 16 terms, plus k7 when an aux generator is set
    elsewhere), 'paper', or a comma list like 'k0,k1,k4' or '0,1,4' or group names 'const,temp'.
    Returns a sorted tuple of term indices. 'auto' is handled by the fitter, not here."""
    spec = spec.strip().lower()
    if spec in ("all", "paper"):
        return PAPER_TERMS
    out = set()
    for item in spec.split(","):
        item = item.strip()
        if not item:
            continue
        if item in GROUPS:
            out.update(GROUPS[item])
            continue
        num = item[1:] if item.startswith("k") else item
        if not num.isdigit() or not 0 <= int(num) < N_TERMS:
            raise ValueError(f"unknown term {item!r}: use k0..k16, a group ({', '.join(GROUPS)}), 'all' or 'auto'")
        out.add(int(num))
    if not out:
        raise ValueError(f"empty term selection {spec!r}")
    return tuple(sorted(out))
