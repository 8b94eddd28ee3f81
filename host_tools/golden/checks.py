"""Input checks of the CLI stages that would otherwise reinterpret their input silently.

* :func:`check_fit_inputs`: training logs of `hdrg fit` / `hdrg diagnose` - a compensated log
  (output of `hdrg compensate`) is refused; without ``--proxy`` the proxy is ``freq_hz`` when
  every log has it, ``temp_c`` with a named warning when none has it, and a mix is an error
  (never a silent switch from the drive frequency to a temperature sensor); a run given twice (the
  same data under one or two names; `hdrg diagnose`: also a held-out run that is a training run) is
  refused.
* :func:`coverage_advice`: a training run (of several) without which the others cover a sliver of
  the joint proxy range is named (leave-one-run-out term selection can keep only the offset).
* :func:`check_sample_rate`: a log to compensate (float golden or fixed point) whose sample rate is
  not the model's nominal fs (within ``FS_TOLERANCE``) is refused.
* :func:`check_raw_logs`: a compensated log given where raw run logs are needed is refused.
* :func:`mode_swap_warnings` (mode-reversal training or evaluation runs) and
  :func:`compensated_swap_warning` (a compensated mode-reversal log): modes 1 and 2 swapped in a
  log's ``mode`` column.  Swapping them flips the sign of the combined output (the true rate and
  the non-reversing bias) and leaves the damping term unchanged, so one log alone cannot show it;
  it shows against other runs of the sensor (a combined output of the opposite sign) or against
  the model (a compensated output near -2x the model's bias).

The run-log reader (host_tools.golden.runlog) refuses metadata that contradicts the data (``reversal:
on`` without modes, ``sample_rate_hz`` against ``t_s``) and non-positive ``freq_hz``.
"""
from __future__ import annotations

import hashlib
import warnings

import numpy as np

from host_tools.golden.fields import check_fields  # noqa: F401  (re-exported: the config readers' field check)

FS_TOLERANCE = 0.01  # relative mismatch allowed between the log's sample rate and the model's fs


class ProxyWarning(UserWarning):
    """The temperature proxy was chosen from the columns present (the text says which)."""


def is_compensated(log) -> bool:
    """True for the output of `hdrg compensate` (metadata ``compensated: yes`` or a ``bias_dph``
    or ``flags`` column)."""
    return (str(log.metadata.get("compensated", "")).strip().lower() == "yes"
            or "bias_dph" in log or "flags" in log)


def _fingerprint(log) -> bytes:
    """A digest of a run's data (t_s, mode, rate_dph): equal for the same run read twice or copied."""
    h = hashlib.sha1()
    for a in (log.t_s, log.mode, log.rate_dph):
        h.update(np.ascontiguousarray(a, np.float64).tobytes())
    return h.digest()


def same_runs(logs, others=None) -> list:
    """[(a.source, b.source)]: pairs of runs with the same data, within ``logs`` (others None) or
    between ``logs`` and ``others``."""
    fa = [_fingerprint(log) for log in logs]
    if others is None:
        return [(logs[i].source, logs[j].source) for i in range(len(logs)) for j in range(i + 1, len(logs))
                if fa[i] == fa[j]]
    fb = [_fingerprint(log) for log in others]
    return [(a.source, b.source) for a, x in zip(logs, fa) for b, y in zip(others, fb) if x == y]


def check_distinct_runs(logs) -> None:
    """ValueError when two training runs hold the same data: the run would count twice, the
    cross-validation would predict it from itself and the error bars would shrink by sqrt(2)."""
    for a, b in same_runs(logs):
        raise ValueError(f"{b}: the same data as training run {a} (given twice?); each run may be given once")


def check_fit_inputs(logs, proxy: str | None) -> None:
    """ValueError for a compensated training log, a run given twice (:func:`check_distinct_runs`)
    or a mix of logs with and without ``freq_hz`` when ``proxy`` is None; ProxyWarning when no log
    has ``freq_hz`` (temp_c is used); ModeSwapWarning for a mode-reversal run whose modes 1 and 2
    look swapped against the other runs (:func:`mode_swap_warnings`)."""
    check_raw_logs(logs, "the fit")
    lacking = [log.source for log in logs if "freq_hz" not in log] if proxy is None else []
    if lacking and len(lacking) < len(logs):
        raise ValueError(f"no 'freq_hz' column in {', '.join(lacking)} while the other logs have one: the proxy "
                         f"would switch to temp_c for all; fix the column names or pass --proxy temp")
    check_distinct_runs(logs)
    for text in mode_swap_warnings(logs):
        warnings.warn(text, ModeSwapWarning, stacklevel=2)
    if lacking:
        warnings.warn(f"no 'freq_hz' column in {', '.join(lacking)}: the temperature proxy is 'temp_c' "
                      f"(pass --proxy temp to choose it explicitly)", ProxyWarning, stacklevel=2)


COVERAGE_MIN = 0.25   # the other training runs covering less than this share of the joint proxy range: named


def coverage_advice(logs, proxy: str | None = None) -> list:
    """One sentence per training run without which the other runs together cover less than
    COVERAGE_MIN of the joint proxy range (0.5 .. 99.5 percentiles):
    the cross-validation that leaves that run out must predict it from a sliver, and term
    selection can keep only the offset.  The union of the others counts, so short power-ons at
    room temperature beside chamber runs that cover the range (the power-on term's runs) draw
    nothing."""
    if len(logs) < 2:
        return []
    rng = []
    for log in logs:
        p = np.asarray(log.proxy(proxy)[1], np.float64)
        p = p[np.isfinite(p)]
        rng.append((float(np.percentile(p, 0.5)), float(np.percentile(p, 99.5))) if len(p) else None)
    if any(r is None for r in rng):
        return []
    joint = max(h for _, h in rng) - min(lo for lo, _ in rng)
    if not joint > 0:
        return []
    out = []
    for i, log in enumerate(logs):
        others = [r for j, r in enumerate(rng) if j != i]
        share = (max(h for _, h in others) - min(lo for lo, _ in others)) / joint
        if share < COVERAGE_MIN:
            out.append(f"without {log.source} the other training runs cover {100 * share:.0f} % of the joint proxy "
                       f"range: the cross-validation that leaves it out extrapolates and term selection can keep "
                       f"only the offset; record a second run over the whole range")
    return out


SAMPLES_RTOL = 1e-9      # float error allowed when a time [s] x a rate [Hz] is a whole number of samples


def shorter_than_a_sample(value_s: float, fs: float) -> bool:
    """True when the time ``value_s`` [s] is less than one sample at ``fs`` [Hz] (a schedule phase
    or a timing field of that length would be empty or rounded up to one sample)."""
    return value_s * fs < 1 - SAMPLES_RTOL


def whole_samples(value_s: float, fs: float) -> bool:
    """True when the time ``value_s`` [s] is a whole number of samples at ``fs`` [Hz] (a sequencer
    counts samples: another time is rounded, or lasts one sample more or less by turns)."""
    n = value_s * fs
    return abs(n - round(n)) <= SAMPLES_RTOL * max(1.0, n)


def check_sample_rate(log, fs: float) -> None:
    """Refuse a log whose sample rate differs from the model's nominal fs [Hz] by more than
    ``FS_TOLERANCE`` (1 %): the rate estimator assumes the nominal period.  Both the log's
    declared rate (metadata ``sample_rate_hz``, which the reader lets differ from t_s by 2 %) and
    its rate from t_s (1 / the median step) are compared."""
    data = 1.0 / log.nominal_step_s if len(log) >= 2 else float("nan")
    for fs_log, how in ((data, f" (1 / its median t_s step {log.nominal_step_s:.6g} s)"), (log.sample_rate_hz, "")):
        if np.isfinite(fs_log) and abs(fs_log / fs - 1.0) > FS_TOLERANCE:
            raise ValueError(f"{log.source}: sample rate {fs_log:.6g} Hz{how} does not match the model's "
                             f"nominal fs {fs:.6g} Hz (the rate estimator assumes the nominal period)")


# -- compensated logs where raw ones are needed, modes 1 and 2 swapped ------------------------------

class ModeSwapWarning(UserWarning):
    """A mode-reversal log whose modes 1 and 2 look swapped (the text says against what)."""


def check_raw_logs(logs, command: str) -> None:
    """ValueError for a compensated log (output of `hdrg compensate`, :func:`is_compensated`) among
    ``logs``, which ``command`` needs raw: its ``rate_dph`` is already the compensated output."""
    for log in logs:
        if is_compensated(log):
            raise ValueError(f"{log.source}: this is a compensated log (output of hdrg compensate: metadata "
                             f"'compensated: yes' or a bias_dph/flags column; its rate_dph is the compensated "
                             f"output, not the raw loop output); {command} needs the raw run log it was made from"
                             + (f" (compensation_model: {log.metadata['compensation_model']})"
                                if log.metadata.get("compensation_model") else "")
                             + "; `hdrg metrics` reads a compensated log")


SWAP_NOISE = 10.0   # a sign disagreement counts when the run means differ by this many output std


def _combined(log):
    """(mean, std) [deg/h] of the pair-combined output of a raw mode-reversal log over its valid
    samples, or None (an FTR log, a compensated one, fewer than 10 valid samples)."""
    if not log.reversal or is_compensated(log) or np.any(log.mode == 0):
        return None
    from host_tools.golden import reversal
    comb = reversal.combine(log)
    out = comb.out_dph[comb.valid & np.isfinite(comb.out_dph)]
    return (float(np.mean(out)), float(np.std(out))) if len(out) >= 10 else None


def mode_swap_warnings(logs) -> list:
    """Sentences naming the raw mode-reversal runs (of two or more) whose combined output [deg/h]
    has the sign opposite to the median of the other runs' while its magnitude matches: ``|m_k -
    M| > SWAP_NOISE * sd`` and ``|m_k + M| < |m_k - M| / SWAP_NOISE`` (m_k the run's mean, M the
    others' median, sd the largest output std of the runs).  That is what modes 1 and 2 swapped in
    one run do (the combined output is the true rate plus the non-reversing bias, sign flipped);
    runs near zero, or of a sensor whose bias really changes sign, are not named."""
    stats = [(log, _combined(log)) for log in logs]
    stats = [(log, st) for log, st in stats if st is not None]
    if len(stats) < 2:
        return []
    sd = max(st[1] for _, st in stats)
    out = []
    for k, (log, (mk, _)) in enumerate(stats):
        med = float(np.median([st[0] for j, (_, st) in enumerate(stats) if j != k]))
        if abs(mk - med) > SWAP_NOISE * sd and abs(mk + med) < abs(mk - med) / SWAP_NOISE:
            out.append(f"{log.source}: its combined mode-reversal output averages {mk:.4g} deg/h, the other "
                       f"runs' {med:.4g} deg/h: the same size, the opposite sign, as when modes 1 and 2 are "
                       f"swapped in its mode column (that flips the true rate and the non-reversing bias); "
                       f"check its mode column")
    return out


def compensated_swap_warning(log) -> str | None:
    """A sentence when a compensated mode-reversal log (`hdrg compensate`'s output) looks compensated
    with modes 1 and 2 swapped: its valid output averages about -2x the model's bias (``|mean(out) +
    2 mean(bias)| < |mean(out)| / 4`` and ``|mean(out)| > 4 std(out)``): the raw combined output came
    in with its sign flipped, so the model's bias was added instead of removed.  None otherwise."""
    if not is_compensated(log) or "bias_dph" not in log or "valid" not in log or not log.reversal:
        return None
    v = (np.asarray(log["valid"]) == 1) & np.isin(log.mode, (1, 2))
    out, bias = log.rate_dph[v], log["bias_dph"][v]
    ok = np.isfinite(out) & np.isfinite(bias)
    if ok.sum() < 10:
        return None
    mo, mb, so = float(np.mean(out[ok])), float(np.mean(bias[ok])), float(np.std(out[ok]))
    if abs(mo + 2.0 * mb) < abs(mo) / 4.0 and abs(mo) > 4.0 * so:
        return (f"{log.source}: the compensated output averages {mo:.4g} deg/h, about -2x the model's bias "
                f"({mb:.4g} deg/h): the raw output came in with its sign flipped, as when modes 1 and 2 are "
                f"swapped in the mode column; check the input's mode column")
    return None


def warn_mode_swaps(logs) -> None:
    """Warn (ModeSwapWarning) every sentence of :func:`mode_swap_warnings` and
    :func:`compensated_swap_warning` for ``logs``."""
    for text in mode_swap_warnings(logs) + [t for t in map(compensated_swap_warning, logs) if t]:
        warnings.warn(text, ModeSwapWarning, stacklevel=2)
