"""Apply a bias model to a run log (golden model, float64): `hdrg compensate`.

Data flow, per sample i, all causal (sample i uses samples <= i only)::

    run log --(mode-reversal combination, host_tools.golden.reversal)--> y, combined-valid
            --(proxy column p, host_tools.golden.proxy)--------------> u, proxy-clamped
            --(rate estimator on p, host_tools.golden.rate)----------> v, rate-clamped, warm-up
            --(aux generator, host_tools.golden.regressors)----------> z
            --(B = model, Horner form)-------------------------> B
    output: rate_dph = y - B, bias_dph = B, valid

or, for a mode-reversal model of order ``regress_first`` (host_tools.golden.reversal, the default)::

    run log --> y = c = s * rate (rate-corrected, not combined); u, v, z as above
            --(B = bank of the sample's mode)------------------> B
            --(combiner on the residual r = c - B, host_tools.golden.reversal)--> out, valid
    output: rate_dph = out, bias_dph = B, valid

Exact semantics (the fixed-point reference copies them):

* **Target y** [deg/h]: FTR model (``reversal`` None): the log must be all mode 0; ``y = rate_dph``
  and the combined output is valid at every sample.  Mode-reversal model: the log must use mode
  reversal (modes 1/2/3); ``y, combined_valid = host_tools.golden.reversal.combine(log, combiner,
  max_stale_s, settle_s, fs_hz=rate.fs)`` (the model's nominal fs, as in firmware).  A model/log
  mismatch is an error.  regress_first model: ``y = c = s * rate`` (0 at exchange samples);
  ``used`` = mode 1/2, past settling, rate estimator warm (the samples a fit uses, bank by mode);
  combined-valid = the validity of the model's combiner on these (it does not depend on values).
* **u** from the proxy column of the model's kind (host_tools.golden.proxy); **v** from the same column
  by the model's rate estimator, restarted at every ``RunLog.segments`` start
  (host_tools.golden.rate); **z** from the aux generator (0 for 'none').
* **Input-invalid samples** ``bad[i]`` (host_tools.golden.input_check.input_flags on ``rate_dph``,
  the model's proxy column and the freq_hz / temp_c its k7 generators read,
  input_check.model_columns: outside what the sensor can report): the rate estimator restarts
  at a bad sample and at the one after it (host_tools.golden.input_check.rate_restarts: the bad
  word never enters its memory; the estimator re-warms as after a gap, flag 4); the combiner never
  uses a bad sample and does not commit a window that held one (host_tools.golden.reversal), so
  every pairing that would use it is not valid (flag 16) until a clean window of that mode
  replaces it.  The aux generators (host_tools.golden.regressors) never take a bad sample's input
  into their memory: an input filter holds its state, an aux rate term re-warms with the model's.
* **valid[i]** = ``combined_valid[i] and not warmup[i] and mode[i] != 3 and not bad[i]``.
  Clamping of u or v does not invalidate a sample (it is flagged only).
* **flags[i]** (uint8 bit field): ``FLAG_PROXY_CLAMPED`` 1 (u was clamped), ``FLAG_RATE_CLAMPED``
  2 (v was clamped), ``FLAG_WARMUP`` 4 (rate estimator in warm-up), ``FLAG_EXCHANGE`` 8 (mode 3),
  ``FLAG_STALE`` 16 (mode-reversal output not valid at a mode 1/2 sample: settling, no
  complete window of the other mode yet, or that window older than max_stale_s, or only a tainted
  one), ``FLAG_INPUT_SAT`` 64 (the sample is input-invalid: the same bit as the fixed point's,
  whose host also sets it for a saturated aux word).
* **B[i]** = ``model.evaluate(u[i], v[i], z[i], mode[i])`` at every sample (Horner form,
  host_tools.golden.regressors; bank by mode for regress_first), deg/h.
* **Output** (:func:`compensate`): where valid, ``rate_dph = y - B`` (regress_first: the
  combiner's output on the residual r = y - B, :func:`residual`) and ``bias_dph = B``; where
  not valid, both are NaN (no number: an empty cell in CSV, NaN in NPZ; the firmware's output
  words hold their last valid values instead, host_tools.fixed.fixed_point); ``valid`` = 1 / 0
  (int64).  The raw input rate stays in the input file.

The compensated run log keeps every other column and the metadata, and adds the metadata
``compensated: yes``, ``compensation_model``, ``compensation_impl``, ``compensation_terms``,
``compensation_valid``, and the ``flags`` column with ``compensation_flags`` (its non-zero counts;
host_tools.golden.flags, docs/RUN_LOG.md).  A log that is already compensated is refused.

The log's sample rate (``RunLog.sample_rate_hz``) must match the model's ``rate.fs`` within 1 %
(the rate scaling uses the nominal fs).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from host_tools.golden import runlog as rl
from host_tools.golden.checks import check_sample_rate
from host_tools.golden.flags import POWER_ON_KEY, STALE_KEY, add_flags, note_aux_inputs
from host_tools.golden.model import BiasModel, ModelConfig
from host_tools.golden.proxy import ProxyConfig, parse_range
from host_tools.golden.rate import RateConfig, parse_rate_range
from host_tools.golden.regressors import AuxConfig, aux_inputs_clamped, aux_regressor
from host_tools.golden import reversal as _reversal
from host_tools.golden.reversal import (ReversalConfig, check_modes, combine, combine_values, max_stale_for,
                                        sign_of, window_ages)

from host_tools.golden.input_check import INPUT_KEY, STUCK_KEY, input_flags, model_columns, rate_restarts
from firmware_ref.vocabulary import (FLAG_EXCHANGE, FLAG_INPUT_SAT, FLAG_PROXY_CLAMPED, FLAG_RATE_CLAMPED,  # noqa: F401
                                     FLAG_STALE, FLAG_WARMUP, GOLDEN_FLAG_NAMES as FLAG_NAMES)
# Defaults of a new model, the one place: fit_config_from_logs (and fit_logs for the terms) fill
# what is not given, so hdrg fit / diagnose / demo and everything reading their model files follow.
# Chosen on held-out runs at another temperature rate (docs/REGRESS_THEN_REVERSE.md "Defaults").
DEFAULT_ORDER, DEFAULT_COMBINER = _reversal.DEFAULT_ORDER, _reversal.DEFAULT_COMBINER  # defined in host_tools.golden.reversal
DEFAULT_SETTLE_S = _reversal.DEFAULT_SETTLE_S  # defined in host_tools.golden.reversal
DEFAULT_RATE = {"estimator": "diff", "n": 8, "shift": 4}   # robust: no long warm-up, any fs, bursty logs
DEFAULT_TERMS = "auto"
DEFAULT_SIGNIFICANCE = 1.0   # of terms 'auto' in fit_logs: keep the smallest model within this many CV standard errors
# `hdrg fit` on mode-reversal logs without --rate-estimator/--rate-n/--rate-shift: 'auto'
# (host_tools.fitting.fit_rate.fit_auto_rate: iir shift 9 unless another candidate's cross-validated rms
# is below half of its own) or 'fixed' (DEFAULT_RATE).
# FTR logs: DEFAULT_RATE_SELECTION_FTR, kept "fixed" (on the measured FTR logs 'auto' picks iir and extrapolates badly).
DEFAULT_RATE_SELECTION_MR = "auto"
DEFAULT_RATE_SELECTION_FTR = "fixed"   # the same choice for FTR logs in fit_default ('auto' | 'fixed')
DEFAULT_LAG_BLOCK = "auto"   # hdrg fit: lag-state block of the proxy as k7 when CV supports it (host_tools.fitting.fit_lag); "off"
IMPLS = ("float", "fixed")


@dataclass
class Prepared:
    """Per-sample inputs of the model and the target, all float64[n] / bool[n] / uint8[n]:
    ``p`` proxy [Hz or degC], ``u``, ``v``, ``z`` (normalized regressors), ``y`` target [deg/h]
    (FTR rate_dph, the combine_first combined output, or for regress_first the rate-corrected
    c = s * rate), ``valid`` (final output valid), ``flags`` (FLAG_* bits); ``mode`` int64[n],
    ``segments`` (segment starts), ``used`` (the samples a fit uses: = valid, except for
    regress_first: mode 1/2, past settling, rate estimator warm), ``order`` (None for FTR)."""

    p: np.ndarray
    u: np.ndarray
    v: np.ndarray
    z: np.ndarray
    y: np.ndarray
    valid: np.ndarray
    flags: np.ndarray
    source: str = "<memory>"
    mode: np.ndarray | None = None
    segments: np.ndarray | None = None
    used: np.ndarray | None = None
    order: str | None = None

    def __len__(self) -> int:
        return len(self.y)

    def flag_counts(self) -> dict:
        """{flag name: number of samples with that flag}."""
        return {name: int(np.count_nonzero(self.flags & bit)) for bit, name in FLAG_NAMES.items()}


def _config_of(config) -> ModelConfig:
    if isinstance(config, BiasModel):
        return config.config
    if not isinstance(config, ModelConfig):
        raise TypeError(f"expected a ModelConfig or BiasModel, not {type(config).__name__}")
    return config


def prepare(log, config) -> Prepared:
    """Per-sample u, v, z, y, valid, flags of ``log`` under ``config`` (a ModelConfig or a
    BiasModel); see the module doc for the exact semantics."""
    cfg = _config_of(config)
    check_sample_rate(log, cfg.rate.fs)
    _, p = log.proxy(cfg.proxy.kind)
    bad, _ = input_flags(log, model_columns(log, cfg))
    u, u_clamped = cfg.proxy.normalize(p)
    v, v_clamped, warm = cfg.rate.normalize(p, rate_restarts(log.segments, bad))
    z = aux_regressor(log, cfg.aux, bad)
    mode = np.asarray(log.mode)
    if cfg.reversal is None:
        if log.reversal:
            raise ValueError(f"{log.source}: the model is for force-to-rebalance (no mode reversal) "
                             f"but the log uses mode reversal (modes 1/2/3)")
        y = np.array(log.rate_dph, np.float64)
        combined_valid = ~bad
    else:
        if not log.reversal:
            raise ValueError(f"{log.source}: the model is for mode reversal "
                             f"(combiner {cfg.reversal.combiner!r}) but the log is FTR (all mode 0)")
        if cfg.reversal.order == "regress_first":
            check_modes(log)
            y = sign_of(mode) * np.asarray(log.rate_dph, np.float64)
            _, combined_valid, used = combine_values(mode, y, ~warm, log.segments, cfg.reversal, cfg.rate.fs, bad)
        else:
            comb = combine(log, combiner=cfg.reversal.combiner, max_stale_s=cfg.reversal.max_stale_s,
                           settle_s=cfg.reversal.settle_s, fs_hz=cfg.rate.fs, bad=bad)
            y = np.asarray(comb.out_dph, np.float64)
            combined_valid = np.asarray(comb.valid, bool)
    exchange = mode == rl.MODE_EXCHANGE
    valid = combined_valid & ~warm & ~exchange & ~bad
    flags = (u_clamped * FLAG_PROXY_CLAMPED + v_clamped * FLAG_RATE_CLAMPED + warm * FLAG_WARMUP
             + exchange * FLAG_EXCHANGE + (~combined_valid & ~exchange) * FLAG_STALE
             + bad * FLAG_INPUT_SAT).astype(np.uint8)
    order = None if cfg.reversal is None else cfg.reversal.order
    return Prepared(np.asarray(p, np.float64), u, v, z, y, valid, flags, log.source, np.asarray(mode, np.int64),
                    np.asarray(log.segments, np.int64), used if order == "regress_first" else valid, order)


def residual(pr: Prepared, model: BiasModel):
    """(out, B) per sample [deg/h], not held: B = the model's bias (bank by mode), out = y - B, or
    for a regress_first model the combiner's output on the residual r = y - B (host_tools.golden.reversal;
    valid where ``pr.valid``)."""
    bias = model.evaluate(pr.u, pr.v, pr.z, mode=pr.mode)
    rev = model.config.reversal
    if rev is None or rev.order != "regress_first":
        return pr.y - bias, bias
    if pr.order != "regress_first":
        raise ValueError(f"{pr.source}: prepared for order {pr.order!r}, the model is regress_first")
    warm = (pr.flags & FLAG_WARMUP) != 0
    bad = (pr.flags & FLAG_INPUT_SAT) != 0
    out, _, _ = combine_values(pr.mode, pr.y - bias, ~warm, pr.segments, rev, model.config.rate.fs, bad)
    return out, bias


def blank_invalid(out) -> rl.RunLog:
    """The compensated log ``out`` with no number where it is not valid: ``rate_dph`` and
    ``bias_dph`` NaN (an empty cell in CSV) where ``valid`` is 0, ``valid`` int64 0/1."""
    valid = np.asarray(out["valid"]) != 0
    return out.with_columns(rate_dph=np.where(valid, out["rate_dph"], np.nan),
                            bias_dph=np.where(valid, out["bias_dph"], np.nan), valid=valid.astype(np.int64))


def check_impl(impl: str) -> None:
    """Refuse an implementation that is not one of IMPLS ('float', 'fixed')."""
    if impl not in IMPLS:
        raise ValueError(f"--impl must be one of {IMPLS}, not {impl!r}")


def stale_by_age(log, config, prep: Prepared | None = None) -> tuple:
    """(samples, age_s): how many samples of mode-reversal ``log`` are not valid only because the
    other mode's latest window is older than ``config``'s max_stale_s (exactly the samples that
    would be valid with no age limit), and the oldest window age any used sample of it meets [s]
    (host_tools.golden.reversal.window_ages: the windows the combiner commits, after settling and
    warm-up).  ``prep``: :func:`prepare` of ``log`` under ``config`` when already computed.  (0, 0.0)
    for FTR and for the 'none' combiner."""
    cfg = _config_of(config)
    if cfg.reversal is None or not log.reversal:
        return 0, 0.0
    if prep is None:
        prep = prepare(log, cfg)
    warm = (prep.flags & FLAG_WARMUP) != 0
    bad = (prep.flags & FLAG_INPUT_SAT) != 0
    ok = ~warm if cfg.reversal.order == "regress_first" else np.ones(len(warm), bool)
    ages = window_ages(prep.mode, ok, prep.segments, cfg.reversal, cfg.rate.fs, bad)
    seen = (ages >= 0) & ~warm & ~bad & (prep.mode != rl.MODE_EXCHANGE)
    k = int(np.count_nonzero(seen & (ages > int(round(cfg.reversal.max_stale_s * cfg.rate.fs)))))
    return k, float(ages[seen].max()) / cfg.rate.fs if seen.any() else 0.0


def note_host_checks(out, log, model: BiasModel, prep: Prepared | None = None, word_range: bool = False):
    """The compensated log ``out`` (either impl) with the checks the firmware flags cannot make
    recorded in its metadata, where host_tools.golden.flags.problems and the user find them: aux
    inputs outside their fitted range (flags.note_aux_inputs), :func:`stale_by_age` (STALE_KEY:
    'N samples; ...', only when some sample went stale by age), the input-invalid samples and the
    stuck proxy runs (host_tools.golden.input_check: INPUT_KEY 'N samples; column K (first row R:
    value, limit)', STUCK_KEY 'column rows A..B (N samples)'); ones copied from the input's metadata
    are dropped; ``word_range``: the fixed-point path's input test, input_check.input_flags)."""
    out = note_aux_inputs(out, aux_inputs_clamped(log, model.config.aux))
    for key in (STALE_KEY, INPUT_KEY, STUCK_KEY):
        out.metadata.pop(key, None)
    _, rep = input_flags(log, model_columns(log, model.config), word_range)
    if rep.flagged:
        out.metadata[INPUT_KEY] = rep.invalid_text()
    if rep.stuck:
        out.metadata[STUCK_KEY] = rep.stuck_text()
    out.metadata.pop(POWER_ON_KEY, None)
    caveat = power_on_caveat(log, model)
    if caveat:
        out.metadata[POWER_ON_KEY] = caveat
    k, age = stale_by_age(log, model, prep)
    if k:
        out.metadata[STALE_KEY] = (f"{k} samples; the log's windows reach {age:g} s before the other mode's is "
                                   f"renewed, the model allows max_stale_s {model.config.reversal.max_stale_s:g} s")
    return out


POWER_ON_TOLERANCE_S = 1.0   # a log starts at its power-on when its first t_s is within this (or 2 samples)


def starts_at_power_on(log) -> bool:
    """True when ``log`` was recorded from its power-on: t_s is the time since power-on
    (docs/RUN_LOG.md), so its first t_s is within POWER_ON_TOLERANCE_S or two sample periods of 0
    (a leg cut from a longer run, or a capture started later, is not)."""
    t = np.asarray(log.t_s, np.float64)
    period = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    return bool(len(t)) and 0.0 <= float(t[0]) <= max(POWER_ON_TOLERANCE_S, 2.0 * period)


def power_on_caveat(log, model: BiasModel) -> str:
    """'' or why ``model``'s time-since-power-on term (an aux ``decay_on`` generator, which counts
    from the log's first sample and restarts after each gap, as the firmware after a restart) does
    not fit ``log``: the log did not start at its power-on (first t_s later than 1 s or two
    samples), or it has gaps (each restarts the term as if the gyroscope had been powered on)."""
    if not any(t.get("gen") == "decay_on" for t in model.config.aux.terms) or not len(log):
        return ""
    said = []
    if not starts_at_power_on(log):
        said.append(f"the log starts at t_s = {float(log.t_s[0]):g} s, not at its power-on")
    gaps = len(log.segments) - 1
    if gaps > 0:
        said.append(f"{gaps} gap(s) restart it (first at row {int(log.segments[1])})")
    if not said:
        return ""
    return ("the model's term in the time since power-on (decay_on) counts from the log's first sample: "
            + "; ".join(said) + "; the output there carries a turn-on that did not happen")


def compensate(log, model: BiasModel, impl: str = "float", table=None) -> rl.RunLog:
    """The compensated run log (see the module doc): ``rate_dph = y - B``, ``bias_dph = B``,
    ``valid`` 1/0, other columns and metadata kept, ``compensated: yes`` added.

    ``impl='fixed'``: the bit-accurate fixed-point firmware reference
    (host_tools.fixed.fixed_point.compensate_log; ``table`` a firmware_ref.table.Table, or None to
    quantize the model on the fly); same columns, output words converted back to deg/h."""
    check_impl(impl)
    if impl == "fixed":
        from host_tools.fixed.fixed_point import compensate_log
        return note_host_checks(blank_invalid(add_flags(*compensate_log(log, model, table=table, return_flags=True))),
                                log, model, word_range=True)
    if table is not None:
        raise ValueError("a coefficient table is only used with --impl fixed")
    if str(log.metadata.get("compensated", "")).strip().lower() == "yes" or "bias_dph" in log:
        raise ValueError(f"{log.source}: the log is already compensated (metadata 'compensated: yes' "
                         f"or a 'bias_dph' column)")
    prep = prepare(log, model)
    value, bias = residual(prep, model)
    out = log.with_columns(rate_dph=value, bias_dph=bias, valid=prep.valid.astype(np.float64))
    nvalid = int(np.count_nonzero(prep.valid))
    out.metadata.update({
        "compensated": "yes",
        "compensation_model": model.source,
        "compensation_impl": impl,
        "compensation_terms": ",".join(f"k{k}" for k in model.terms),
        "compensation_valid": f"{nvalid} of {len(prep)} samples",
    })
    return note_host_checks(blank_invalid(add_flags(out, prep.flags)), log, model, prep)


def checked(log, model: BiasModel) -> rl.RunLog:
    """What :func:`compensate` would report about ``log`` under ``model`` (float), without the
    output columns: the input log (its arrays shared) with ``flags`` and the host checks' metadata, for
    host_tools.golden.flags.problems (e.g. `hdrg fit`'s look at its training runs; memory: one
    prepare, not a compensated copy of the log)."""
    prep = prepare(log, model)
    out = log.with_columns(flags=np.asarray(prep.flags, np.int64))   # the input's columns shared, not copied
    out.metadata["compensation_impl"] = "float"
    return note_host_checks(out, log, model, prep)


def fit_config_from_logs(logs, proxy_kind: str | None = None, rate_estimator: str | None = None,
                         n: int | None = None, shift: int | None = None, proxy_range=None, rate_range: float | None = None,
                         proxy_margin: float = 0.1, rate_margin: float = 0.1, rate_percentile: float = 99.9,
                         reversal=None, aux=None, fs: float | None = None) -> ModelConfig:
    """The default ModelConfig for training ``logs`` (RunLogs, all FTR or all mode reversal).

    * proxy kind: ``proxy_kind`` or 'freq' if every log has ``freq_hz``, else 'temp';
    * rate estimator: ``rate_estimator``, ``n``, ``shift``; each None -> DEFAULT_RATE;
    * fs [Hz]: ``fs`` or the first log's sample rate; every log must match it within 1 %;
    * proxy range: ``proxy_range`` (LO, HI) in proxy units, else ProxyConfig.from_data over the
      logs' non-exchange samples that are not input-invalid (host_tools.golden.input_check)
      widened by ``proxy_margin``;
    * rate span: ``rate_range`` [proxy units/s], else RateConfig.from_data (``rate_percentile``
      of |dp/dt| past warm-up on non-exchange samples, times 1 + ``rate_margin``);
    * reversal: None for FTR logs (giving one is an error); for mode-reversal logs ``reversal``
      (a ReversalConfig, used as is; or a dict, whose missing or None "combiner" / "order" are
      DEFAULT_COMBINER / DEFAULT_ORDER, "settle_s" DEFAULT_SETTLE_S for regress_first + pair,
      else 0 s, and "max_stale_s" host_tools.golden.reversal.max_stale_for the logs: 300 s, or
      longer when their dwell is) or the same defaults;
    * aux: ``aux`` (AuxConfig or dict) or AuxConfig() ('none').
    """
    logs = list(logs)
    if not logs:
        raise ValueError("no training logs")
    if proxy_kind is None:
        proxy_kind = "freq" if all("freq_hz" in log for log in logs) else "temp"
    column = ProxyConfig(proxy_kind, 0.0, 1.0).column
    for log in logs:
        if column not in log:
            raise rl.RunLogError(log.source, None, f"proxy '{proxy_kind}' needs column '{column}', which the log lacks")
    if fs is None:
        fs = logs[0].sample_rate_hz
        if not np.isfinite(fs):
            raise ValueError(f"{logs[0].source}: cannot tell the sample rate (one sample, no metadata)")
    for log in logs:
        check_sample_rate(log, fs)
    kinds = {log.reversal for log in logs}
    if len(kinds) > 1:
        names = ", ".join(f"{log.source} ({'reversal' if log.reversal else 'FTR'})" for log in logs)
        raise ValueError(f"training logs mix FTR and mode reversal: {names}")
    if kinds == {False}:
        if reversal is not None:
            raise ValueError("reversal settings given but the training logs are FTR (all mode 0)")
        rev = None
    else:
        if isinstance(reversal, ReversalConfig):
            rev = reversal
        else:
            given = {k: v for k, v in dict(reversal or {}).items() if v is not None}
            kw = {"combiner": DEFAULT_COMBINER, "order": DEFAULT_ORDER, **given}
            # settle default only where the benchmark measured it (regress_first + pair); 0 s elsewhere
            # (hdrg paper's combine_first and regression-alone rows get worse with 5 s)
            if "settle_s" not in kw:
                kw["settle_s"] = DEFAULT_SETTLE_S if (kw["order"], kw["combiner"]) == ("regress_first", "pair") else 0.0
            if "max_stale_s" not in kw:
                kw["max_stale_s"] = max_stale_for(logs, fs)
            rev = ReversalConfig(**kw)
    if rate_estimator == "auto":
        raise ValueError("rate estimator 'auto' is chosen by fitting every candidate: use hdrg fit "
                         "(host_tools.fitting.fit_rate.fit_auto_rate), not a fixed model configuration")
    rate_estimator = DEFAULT_RATE["estimator"] if rate_estimator is None else rate_estimator
    n = DEFAULT_RATE["n"] if n is None else n
    shift = DEFAULT_RATE["shift"] if shift is None else shift
    aux_cfg = AuxConfig() if aux is None else (aux if isinstance(aux, AuxConfig) else AuxConfig.from_dict(dict(aux)))
    # input-invalid samples (host_tools.golden.input_check) set neither the proxy range nor the rate span
    bads = [input_flags(log, ("rate_dph", column))[0] for log in logs]
    keep = [(np.asarray(log.mode) != rl.MODE_EXCHANGE) & ~bad for log, bad in zip(logs, bads)]
    ps = [log[column] for log in logs]
    if proxy_range is not None:
        lo, hi = parse_range(proxy_range) if isinstance(proxy_range, str) else proxy_range
        proxy = ProxyConfig.from_range(proxy_kind, float(lo), float(hi))
    else:
        proxy = ProxyConfig.from_data([p[m] for p, m in zip(ps, keep)], proxy_kind, proxy_margin)
    if rate_range is not None:
        span = parse_rate_range(rate_range) if isinstance(rate_range, str) else float(rate_range)
        rate = RateConfig(rate_estimator, n, shift, span, fs)
    else:
        rate = RateConfig.from_data(ps, fs, rate_estimator, n, shift,
                                    restarts=[rate_restarts(log.segments, bad) for log, bad in zip(logs, bads)],
                                    percentile=rate_percentile, margin=rate_margin, masks=keep)
    return ModelConfig(proxy, rate, rev, aux_cfg)
