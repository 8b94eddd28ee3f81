"""The 17 regressors x_k(u, v, z) of eq. (8) and the bias B = sum_k k_k x_k (golden model, float64).

Terms (firmware_ref/terms.py): ``x_k = u**i * v**j`` with ``(i, j) = TERM_POWERS[k]`` for every k
but k7; ``x_7 = z``, the auxiliary regressor (0 until a generator is configured, see
:class:`AuxConfig`).  u, v, z are dimensionless in [-1, 1]; coefficients are deg/h, so B is deg/h.

Two evaluations of B, equal up to float rounding:

* :func:`bias_plain`: ``B = X @ coef`` with ``X = regressor_matrix(u, v, z)`` (the fitter's form);
* :func:`bias_horner`: the form the firmware uses, nested Horner in two variables.  With
  ``c[i][j] = coef[POLY_INDEX[i][j]]`` (the coefficient of u^i v^j), exactly in this order::

      for i in 3, 2, 1, 0:
          q_i = ((c[i][3] * v + c[i][2]) * v + c[i][1]) * v + c[i][0]
      B = ((q_3 * u + q_2) * u + q_1) * u + q_0
      B = B + coef[7] * z

  i.e. ``B = sum_i u^i (sum_j c_ij v^j) + k7 z``.  Disabled terms have coefficient 0 and are
  evaluated like the others (no branches).

Auxiliary regressor: :func:`aux_regressor` ``(log, aux_config) -> z`` float64[n].  Generators:
``"none"`` (z = 0 everywhere).  Future generators (closed-loop issue: a recursive filter of the
proxy, a decay since power-on or since the last exchange, an external ``aux_*`` column) must be
causal, restart at every segment start like the rate estimator, and produce z in [-1, 1].
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from firmware_ref.terms import K_AUX, N_TERMS, POLY_INDEX, TERM_POWERS

AUX_GENERATORS = ("none",)


@dataclass(frozen=True)
class AuxConfig:
    """Generator of the auxiliary regressor z (term k7): ``generator`` (one of AUX_GENERATORS)
    and its ``params`` (a dict, empty for 'none')."""

    generator: str = "none"
    params: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.generator not in AUX_GENERATORS:
            raise ValueError(f"aux generator must be one of {AUX_GENERATORS}, not {self.generator!r}")
        if not isinstance(self.params, dict):
            raise ValueError(f"aux params must be a dict, not {self.params!r}")

    def to_dict(self) -> dict:
        return {"generator": self.generator, **({"params": dict(self.params)} if self.params else {})}

    @classmethod
    def from_dict(cls, d: dict) -> "AuxConfig":
        return cls(d.get("generator", "none"), dict(d.get("params", {})))


def aux_regressor(log, aux_config: AuxConfig | None = None) -> np.ndarray:
    """z float64[len(log)] from the run log; 'none' (or None) gives zeros."""
    cfg = AuxConfig() if aux_config is None else aux_config
    if cfg.generator == "none":
        return np.zeros(len(log))
    raise ValueError(f"aux generator {cfg.generator!r} is not implemented")  # pragma: no cover


def regressor_matrix(u, v, z=None) -> np.ndarray:
    """X float64[n, 17]: column k is x_k(u, v, z) (z = 0 if None)."""
    u = np.asarray(u, np.float64)
    v = np.asarray(v, np.float64)
    upow = [np.ones_like(u), u, u * u, u * u * u]
    vpow = [np.ones_like(v), v, v * v, v * v * v]
    X = np.empty((u.shape[0], N_TERMS))
    for k, pw in enumerate(TERM_POWERS):
        if pw is None:
            X[:, k] = 0.0 if z is None else np.asarray(z, np.float64)
        else:
            X[:, k] = upow[pw[0]] * vpow[pw[1]]
    return X


def _check_coef(coef) -> np.ndarray:
    coef = np.asarray(coef, np.float64)
    if coef.shape != (N_TERMS,):
        raise ValueError(f"coefficients must be {N_TERMS} values k0..k16, not shape {coef.shape}")
    return coef


def bias_plain(coef, u, v, z=None) -> np.ndarray:
    """B = sum_k coef[k] x_k [deg/h], as ``regressor_matrix(u, v, z) @ coef``."""
    return regressor_matrix(u, v, z) @ _check_coef(coef)


def bias_horner(coef, u, v, z=None) -> np.ndarray:
    """B [deg/h] by nested Horner in the exact order of the module doc (the firmware's form)."""
    c = _check_coef(coef)
    u = np.asarray(u, np.float64)
    v = np.asarray(v, np.float64)
    q = []
    for i in range(4):
        row = [c[POLY_INDEX[i][j]] for j in range(4)]
        q.append(((row[3] * v + row[2]) * v + row[1]) * v + row[0])
    b = ((q[3] * u + q[2]) * u + q[1]) * u + q[0]
    zz = np.zeros_like(u) if z is None else np.asarray(z, np.float64)
    return b + c[K_AUX] * zz
