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

Auxiliary regressor z (term k7): THE SPEC OF THE FIXED-POINT PORT
=================================================================

:func:`aux_regressor` ``(log, aux_config) -> z`` float64[n].  ``AuxConfig.generator`` is

* ``"none"``: z = 0 at every sample;
* ``"sum"``: z is a fixed weighted sum of one or more *generator terms* (found by ``hdrg diagnose``,
  host_tools/fitting/diagnose.py).  ``params = {"fs": FS, "terms": [TERM, ...]}``; FS [Hz] is the model's
  nominal sample rate (``rate.fs``): every time constant becomes a per-sample coefficient with it,
  the log's ``t_s`` is only used by the power-on counter k below.

Per-sample signals shared by the terms (n = number of rows of the log, i = 0..n-1):

* ``seg_start[i]``: True at row 0 and at every gap-free segment start (``RunLog.segments``); the
  *recursive* generators (``input`` with tau_s > 0, ``decay_on``, ``decay_exchange``, ``rate``)
  restart there exactly as at power-on, like the rate estimator (host_tools.golden.rate).
* ``bad[i]``: the sample's input-invalid bit (host_tools.golden.input_check; firmware_ref/FORMATS.md
  "The input-invalid bit"): the generators never take a flagged sample's input into their memory.
  A filtered ``input`` holds its state over a flagged sample (a restart met on a flagged sample
  zeroes it and is *pending*: the filter re-initializes at the next clean sample; one bit of
  state, ``pend``); a
  ``rate`` term's estimator restarts at a flagged sample and at the one after it, like the model's
  (input_check.rate_restarts).  ``decay_on``, ``decay_exchange``, ``ramp``, ``osc``, ``one`` and an
  unfiltered ``input`` read no past input and do not see the bit.
* ``s[i]``, the mode sign: +1 in modes 0 and 1, -1 in mode 2, 0 in mode 3 (exchange).
* ``k[i] = rint(t_s[i] * FS)`` (numpy.rint: nearest integer, ties to even), the firmware's sample
  counter since power-on (t_s is the time since power-on, shared/formats/run-log.md).  Only
  ``ramp`` and ``osc`` use it; they do NOT restart at segment starts.

Each TERM is a dict with ``gen`` (the generator, below), ``weight`` w (finite float), ``sign``
(bool, default False), its generator's parameters, and optionally ``effect`` (a free label, e.g.
"thermal_lag"; ignored by the evaluation).  With g_j[i] the generator output of term j (each in
[-1, 1] by construction)::

    z[i] = 0.0
    for j in 0 .. m-1 (the order of the list):
        z[i] = z[i] + w_j * (s[i] * g_j[i] if sign_j else g_j[i])
    z[i] = clamp(z[i], -1, 1)

The weights must satisfy sum_j |w_j| <= 1 (checked), so |z| <= 1 everywhere and the final clamp
is only a guard.  Generators (all arithmetic float64, in the order written):

``input`` -- normalized external input, optionally filtered, optionally raised to a power.
    Parameters: ``column`` (run-log column: ``freq_hz``, ``temp_c`` or ``aux_*``), ``ref`` and
    ``span`` (> 0) in the column's unit, ``tau_s`` >= 0 (0: no filter), ``power`` (integer 1..5,
    default 1).  Once: ``inv_span = 1.0 / span``; if tau_s > 0: ``a = exp(-1.0 / (FS * tau_s))``,
    ``b = 1.0 - a``.  Per sample::

        q = (x[i] - ref) * inv_span;  q = +1 if q > 1;  q = -1 if q < -1      (as host_tools.golden.proxy)
        rs = seg_start[i] or pend                       (pend: False at power-on, shared by the terms)
        if tau_s == 0:      y = q
        elif bad[i]:        y = 0.0 if rs else y held  (a flagged sample never enters the state)
        elif rs:            y = q                       (filter state reset to the input)
        else:               y = y + b * (q - y)         (first-order low-pass, y[i-1] -> y[i])
        pend = bad[i] and rs                            (after every term)
        g = y * y * ... * y   (power factors, multiplied left to right; power 1: g = y)

    On a log without
    flagged samples the filter equals ``scipy.signal.lfilter([b], [1, -a], q)`` started at y =
    q[seg start].
    Uses: a lagged copy of the proxy (effect thermal_lag), u^4 / u^5 (proxy_high_order: the
    model's own proxy normalization, tau_s = 0), a second temperature sensor (board_temp), an
    ``aux_*`` channel (aux_<name>), the mode sign times u (imperfect_reversal, sign True).
``rate`` -- the normalized rate v of a column by the rate estimator of host_tools.golden.rate.
    Parameters: ``column``, ``estimator``, ``n``, ``shift``, ``span`` (as RateConfig, with
    fs = FS): ``g = RateConfig(estimator, n, shift, span, FS).normalize(x, rate_restarts(segments,
    bad))[0]`` (0 in warm-up, clamped to [-1, 1]; the restarts of the model's estimator, so a
    flagged sample and the one after it re-warm).  Use: s * v (imperfect_reversal, sign True).
``one`` -- g = 1.  Use: s * 1 (imperfect_reversal, sign True).
``decay_on`` -- decay since power-on.  Parameter ``tau_s`` > 0; once ``a = exp(-1.0 / (FS *
    tau_s))``.  Per sample: ``g = 1.0`` if seg_start[i], else ``g = a * g``.  On a gap-free log
    g[i] = a^i = exp(-i / (FS tau_s)) up to rounding.  Use: turn_on.
``decay_exchange`` -- decay since the end of the last mode exchange.  Parameter ``tau_s`` > 0;
    ``a`` as above.  State g, ex (bool).  Per sample::

        if seg_start[i]:  g = 0.0;  ex = False
        if mode[i] == 3:  g = 0.0;  ex = True          (in the exchange)
        elif ex:          g = 1.0;  ex = False         (first non-exchange sample after mode 3)
        else:             g = a * g                    (0 before the first exchange)

    Use: exchange_transient (sign False: the transient flips like a true rate; sign True, with a
    ``one`` term of sign True beside it: it does not flip, and the combiner leaves s times it
    minus its mean over the other window).
``ramp`` -- normalized time since power-on.  Parameter ``n_samples`` N (integer >= 1); once
    ``inv_n = 1.0 / N``.  Per sample: ``g = min(max(k[i], 0) * inv_n, 1.0)``.  Use: aging.
``osc`` -- periodic term by a rotation recursion.  Parameters ``period_s`` P > 0 and ``part``
    ("sin" or "cos").  Once: ``w = 2 pi / (P * FS)`` [rad/sample], ``cw = cos(w)``, ``sw =
    sin(w)``.  State (c, sn) = (1.0, 0.0) at k = 0 (power-on), advanced once per sample period::

        c, sn = c * cw - sn * sw,  sn * cw + c * sw

    At row i the state has been advanced k[i] times (k[i] - k[i-1] times since the previous row, so
    a log gap advances it like the running firmware; a negative k leaves the k = 0 state);
    ``g = sn`` ("sin") or ``g = c`` ("cos"), i.e. sin / cos(2 pi k / (P FS)) up to the recursion's rounding (|c^2 + sn^2 - 1| grows ~1e-16 per
    step, < 1e-9 after 1e7 samples; no renormalization).  Use: periodic (a sin and a cos term).

:func:`generator_values` evaluates one term (its g, times s if sign; without its weight).  Both
it and :func:`aux_regressor` take ``bad`` (bool[n]); None: ``input_check.input_flags(log)[0]`` (every
checked column the log has: the fit's mask, input_check.fit_mask); host_tools.golden.compensate
passes the mask of ``rate_dph`` and the model's proxy column, the firmware's bit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from firmware_ref.terms import K_AUX, N_TERMS, POLY_INDEX, TERM_POWERS
from firmware_ref.vocabulary import AUX_GENERATORS

# generator of a term of the "sum" -> (required parameters, optional parameters with defaults)
GENERATORS = {
    "input": (("column", "ref", "span"), {"tau_s": 0.0, "power": 1}),
    "rate": (("column", "estimator", "span"), {"n": 8, "shift": 4}),
    "one": ((), {}),
    "decay_on": (("tau_s",), {}),
    "decay_exchange": (("tau_s",), {}),
    "ramp": (("n_samples",), {}),
    "osc": (("period_s", "part"), {}),
}
_COMMON = {"weight": None, "sign": False, "effect": ""}
MAX_POWER = 5
WEIGHT_SUM_TOL = 1e-9    # sum |w| may exceed 1 by this much (float rounding of a normalization)


def _finite(value, what, positive=False, nonneg=False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(value):
        raise ValueError(f"{what} must be a finite number, not {value!r}")
    value = float(value)
    if positive and not value > 0:
        raise ValueError(f"{what} must be > 0, not {value!r}")
    if nonneg and not value >= 0:
        raise ValueError(f"{what} must be >= 0, not {value!r}")
    return value


def _int(value, what, lo, hi=None) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer, float, np.floating)) \
            or not float(value).is_integer():
        raise ValueError(f"{what} must be an integer, not {value!r}")
    value = int(value)
    if value < lo or (hi is not None and value > hi):
        raise ValueError(f"{what} must be in {lo}..{hi if hi is not None else 'inf'}, not {value}")
    return value


def normalize_term(term, where: str = "aux term") -> dict:
    """A checked copy of one generator term of the "sum" (defaults filled in, numbers as float/int).
    Raises ValueError naming the term and the parameter."""
    if not isinstance(term, dict):
        raise ValueError(f"{where}: must be an object, not {term!r}")
    gen = term.get("gen")
    if gen not in GENERATORS:
        raise ValueError(f"{where}: 'gen' must be one of {tuple(GENERATORS)}, not {gen!r}")
    where = f"{where} ({gen})"
    required, optional = GENERATORS[gen]
    known = set(required) | set(optional) | set(_COMMON) | {"gen"}
    unknown = sorted(set(term) - known)
    if unknown:
        raise ValueError(f"{where}: unknown parameter(s) {unknown}; known: {sorted(known - {'gen'})}")
    for name in required + ("weight",):
        if name not in term:
            raise ValueError(f"{where}: parameter '{name}' missing")
    out = {"gen": gen, "weight": _finite(term["weight"], f"{where}: weight")}
    sign = term.get("sign", False)
    if not isinstance(sign, (bool, np.bool_)):
        raise ValueError(f"{where}: sign must be true or false, not {sign!r}")
    out["sign"] = bool(sign)
    effect = term.get("effect", "")
    if not isinstance(effect, str):
        raise ValueError(f"{where}: effect must be a string, not {effect!r}")
    if effect:
        out["effect"] = effect
    p = {**optional, **{k: v for k, v in term.items() if k in required or k in optional}}
    if gen in ("input", "rate"):
        if not isinstance(p["column"], str) or not p["column"]:
            raise ValueError(f"{where}: column must be a run-log column name, not {p['column']!r}")
        out["column"] = p["column"]
    if gen == "input":
        out["ref"] = _finite(p["ref"], f"{where}: ref")
        out["span"] = _finite(p["span"], f"{where}: span", positive=True)
        out["tau_s"] = _finite(p["tau_s"], f"{where}: tau_s", nonneg=True)
        out["power"] = _int(p["power"], f"{where}: power", 1, MAX_POWER)
    elif gen == "rate":
        from host_tools.golden.rate import RateConfig
        try:
            rc = RateConfig(p["estimator"], p["n"], p["shift"], p["span"], 1.0)
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None
        out.update(estimator=rc.estimator, n=rc.n, shift=rc.shift, span=rc.span)
    elif gen in ("decay_on", "decay_exchange"):
        out["tau_s"] = _finite(p["tau_s"], f"{where}: tau_s", positive=True)
    elif gen == "ramp":
        out["n_samples"] = _int(p["n_samples"], f"{where}: n_samples", 1)
    elif gen == "osc":
        out["period_s"] = _finite(p["period_s"], f"{where}: period_s", positive=True)
        if p["part"] not in ("sin", "cos"):
            raise ValueError(f"{where}: part must be 'sin' or 'cos', not {p['part']!r}")
        out["part"] = p["part"]
    return out


@dataclass(frozen=True)
class AuxConfig:
    """Generator of the auxiliary regressor z (term k7): ``generator`` (one of AUX_GENERATORS)
    and its ``params`` (a dict: empty for 'none'; ``{"fs": Hz, "terms": [term, ...]}`` for 'sum',
    see the module doc).  The params are checked and normalized (defaults filled in)."""

    generator: str = "none"
    params: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.generator not in AUX_GENERATORS:
            raise ValueError(f"aux generator must be one of {AUX_GENERATORS}, not {self.generator!r}")
        if not isinstance(self.params, dict):
            raise ValueError(f"aux params must be a dict, not {self.params!r}")
        if self.generator == "none":
            if self.params:
                raise ValueError(f"aux generator 'none' takes no params, got {sorted(self.params)}")
            return
        unknown = sorted(set(self.params) - {"fs", "terms"})
        if unknown:
            raise ValueError(f"aux generator 'sum': unknown params {unknown} (expected fs, terms)")
        if "fs" not in self.params:
            raise ValueError("aux generator 'sum': params.fs (the nominal sample rate, Hz) missing")
        fs = _finite(self.params["fs"], "aux params.fs", positive=True)
        terms = self.params.get("terms")
        if not isinstance(terms, (list, tuple)) or not terms:
            raise ValueError(f"aux generator 'sum': params.terms must be a non-empty list, not {terms!r}")
        terms = [normalize_term(t, f"aux params.terms[{j}]") for j, t in enumerate(terms)]
        total = sum(abs(t["weight"]) for t in terms)
        if total > 1.0 + WEIGHT_SUM_TOL:
            raise ValueError(f"aux generator 'sum': the weights must satisfy sum |w| <= 1 (so |z| <= 1), "
                             f"got {total!r}")
        object.__setattr__(self, "params", {"fs": fs, "terms": terms})

    @property
    def terms(self) -> list:
        """The generator terms ([] for 'none')."""
        return list(self.params.get("terms", []))

    def to_dict(self) -> dict:
        if self.generator == "none":
            return {"generator": "none"}
        return {"generator": self.generator,
                "params": {"fs": self.params["fs"], "terms": [dict(t) for t in self.params["terms"]]}}

    @classmethod
    def from_dict(cls, d: dict) -> "AuxConfig":
        return cls(d.get("generator", "none"), dict(d.get("params", {}) or {}))

    @classmethod
    def from_terms(cls, terms, fs: float) -> "AuxConfig":
        """'sum' of ``terms`` (list of term dicts, weights included) at nominal rate ``fs`` [Hz];
        no terms gives 'none'."""
        terms = list(terms)
        return cls("sum", {"fs": float(fs), "terms": terms}) if terms else cls()


# -- generator kernels (float64, exactly the recursions of the module doc) -----------------------

@numba.njit(cache=True)
def _lowpass_kernel(q, seg_start, b, bad):
    n = q.shape[0]
    y = np.empty(n)
    state = 0.0
    pend = False
    for i in range(n):
        rs = seg_start[i] or pend
        if bad[i]:
            if rs:
                state = 0.0            # a restart waits for the next clean sample
            pend = rs                  # else held
        elif rs:
            state = q[i]
            pend = False
        else:
            state = state + b * (q[i] - state)
        y[i] = state
    return y


@numba.njit(cache=True)
def _decay_on_kernel(seg_start, a):
    n = seg_start.shape[0]
    g = np.empty(n)
    state = 1.0
    for i in range(n):
        if seg_start[i]:
            state = 1.0
        else:
            state = a * state
        g[i] = state
    return g


@numba.njit(cache=True)
def _decay_exchange_kernel(mode, seg_start, a):
    n = mode.shape[0]
    g = np.empty(n)
    state = 0.0
    ex = False
    for i in range(n):
        if seg_start[i]:
            state = 0.0
            ex = False
        if mode[i] == 3:
            state = 0.0
            ex = True
        elif ex:
            state = 1.0
            ex = False
        else:
            state = a * state
        g[i] = state
    return g


@numba.njit(cache=True)
def _osc_kernel(k, cw, sw, want_sin):
    n = k.shape[0]
    g = np.empty(n)
    c = 1.0
    s = 0.0
    at = 0
    for i in range(n):
        while at < k[i]:
            c, s = c * cw - s * sw, s * cw + c * sw
            at += 1
        g[i] = s if want_sin else c
    return g


def _seg_start(log) -> np.ndarray:
    mask = np.zeros(len(log), np.bool_)
    if len(log):
        mask[0] = True
        mask[np.asarray(log.segments, np.int64)] = True
    return mask


def mode_sign(mode) -> np.ndarray:
    """s[i]: +1 in modes 0/1, -1 in mode 2, 0 in mode 3 (float64)."""
    mode = np.asarray(mode)
    return np.where(mode == 2, -1.0, np.where(mode == 3, 0.0, 1.0))


def power_on_counter(t_s, fs: float) -> np.ndarray:
    """k[i] = rint(t_s[i] * fs) (int64): the sample counter since power-on."""
    return np.rint(np.asarray(t_s, np.float64) * float(fs)).astype(np.int64)


def normalized_input(x, ref: float, span: float) -> np.ndarray:
    """q = clamp((x - ref) * (1 / span), -1, 1), float64 (the first step of 'input')."""
    inv_span = 1.0 / float(span)
    return np.clip((np.asarray(x, np.float64) - float(ref)) * inv_span, -1.0, 1.0)


def lowpass(q, seg_start, tau_s: float, fs: float, bad=None) -> np.ndarray:
    """The first-order filter of 'input' (module doc): y = q at segment starts, else
    y += (1 - a) (q - y), a = exp(-1 / (fs tau_s)); held over the input-invalid samples ``bad``
    (bool[n], None: none), a restart on one of them zeroes y and is deferred to the next clean
    sample."""
    a = math.exp(-1.0 / (float(fs) * float(tau_s)))
    q = np.ascontiguousarray(q, np.float64)
    bad = np.zeros(q.shape[0], np.bool_) if bad is None else np.ascontiguousarray(bad, np.bool_)
    return _lowpass_kernel(q, np.ascontiguousarray(seg_start, np.bool_), 1.0 - a, bad)


def _column(log, name, where):
    if name not in log:
        raise ValueError(f"{log.source}: {where} needs column '{name}', which the log lacks "
                         f"(columns: {', '.join(log.columns)})")
    return np.asarray(log[name], np.float64)


def _bad_mask(log, bad) -> np.ndarray:
    """``bad`` as bool[len(log)], or the log's own input-invalid mask when None (module doc)."""
    if bad is None:
        from host_tools.golden.input_check import input_flags
        return input_flags(log)[0]
    bad = np.asarray(bad, np.bool_)
    if bad.shape != (len(log),):
        raise ValueError(f"{log.source}: the input-invalid mask has shape {bad.shape}, expected ({len(log)},)")
    return bad


def generator_values(log, term: dict, fs: float, bad=None) -> np.ndarray:
    """g[i] of one term (times the mode sign s[i] if ``sign``), float64[len(log)], without its
    weight; ``bad`` the input-invalid samples (bool[n]; None: the log's, module doc); see the
    module doc for the exact per-sample rules."""
    t = normalize_term(term)
    fs = _finite(fs, "aux fs", positive=True)
    gen = t["gen"]
    where = f"aux generator '{gen}'"
    n = len(log)
    if gen == "input":
        q = normalized_input(_column(log, t["column"], where), t["ref"], t["span"])
        y = q if t["tau_s"] == 0 else lowpass(q, _seg_start(log), t["tau_s"], fs, _bad_mask(log, bad))
        g = y
        for _ in range(t["power"] - 1):
            g = g * y
    elif gen == "rate":
        from host_tools.golden.input_check import rate_restarts
        from host_tools.golden.rate import RateConfig
        rc = RateConfig(t["estimator"], t["n"], t["shift"], t["span"], fs)
        g = rc.normalize(_column(log, t["column"], where), rate_restarts(log.segments, _bad_mask(log, bad)))[0]
    elif gen == "one":
        g = np.ones(n)
    elif gen == "decay_on":
        g = _decay_on_kernel(_seg_start(log), math.exp(-1.0 / (fs * t["tau_s"])))
    elif gen == "decay_exchange":
        g = _decay_exchange_kernel(np.ascontiguousarray(log.mode, np.int64), _seg_start(log),
                                   math.exp(-1.0 / (fs * t["tau_s"])))
    elif gen == "ramp":
        k = power_on_counter(log.t_s, fs)
        g = np.minimum(np.maximum(k, 0).astype(np.float64) * (1.0 / t["n_samples"]), 1.0)
    else:  # osc
        w = 2.0 * math.pi / (t["period_s"] * fs)
        g = _osc_kernel(power_on_counter(log.t_s, fs), math.cos(w), math.sin(w), t["part"] == "sin")
    g = np.asarray(g, np.float64)
    if t["sign"]:
        g = mode_sign(log.mode) * g
    return g


def aux_inputs_clamped(log, aux_config: AuxConfig | None = None) -> dict:
    """{column: samples of ``log`` whose value lies outside the range an 'input' term of
    ``aux_config`` was fitted on (|x - ref| > span, where the normalization clamps it to the edge)},
    columns with such samples only.  A host check: the firmware's aux_clamped flag (bit 32) covers
    the sum z, which cannot leave [-1, 1] while the weights' |sum| <= 1, so it does not see an input
    clamped on its own."""
    cfg = AuxConfig() if aux_config is None else aux_config
    out = {}
    if cfg.generator == "none":
        return out
    for term in cfg.params["terms"]:
        t = normalize_term(term)
        if t["gen"] != "input":
            continue
        x = _column(log, t["column"], f"aux generator '{t['gen']}'")
        k = int(np.count_nonzero(np.abs(x - float(t["ref"])) > float(t["span"])))
        if k:
            out[t["column"]] = max(k, out.get(t["column"], 0))
    return out


def aux_regressor(log, aux_config: AuxConfig | None = None, bad=None) -> np.ndarray:
    """z float64[len(log)] from the run log; 'none' (or None) gives zeros; 'sum' as in the module
    doc; ``bad`` the input-invalid samples (bool[n]; None: the log's own, module doc)."""
    cfg = AuxConfig() if aux_config is None else aux_config
    if cfg.generator == "none":
        return np.zeros(len(log))
    fs = cfg.params["fs"]
    z = np.zeros(len(log))
    if bad is None and any(t["gen"] == "rate" or (t["gen"] == "input" and t["tau_s"] > 0)
                           for t in cfg.params["terms"]):
        bad = _bad_mask(log, None)                 # once for every term
    for term in cfg.params["terms"]:
        z = z + term["weight"] * generator_values(log, term, fs, bad)
    return np.clip(z, -1.0, 1.0)


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
