"""Input checks of the CLI stages that would otherwise reinterpret their input silently.

* :func:`check_fit_inputs`: training logs of `hdrg fit` / `hdrg diagnose` - a compensated log
  (output of `hdrg compensate`) is refused; without ``--proxy`` the proxy is ``freq_hz`` when
  every log has it, ``temp_c`` with a named warning when none has it, and a mix is an error
  (never a silent switch from the drive frequency to a temperature sensor); a run given twice (the
  same data under one or two names; `hdrg diagnose`: also a held-out run that is a training run) is
  refused.
* :func:`coverage_warnings`: a training run (of several) that covers a sliver of the joint proxy
  range is named (leave-one-run-out term selection can keep only the offset).
* :func:`check_sample_rate`: a log to compensate (float golden or fixed point) whose sample rate is
  not the model's nominal fs (within ``FS_TOLERANCE``) is refused.

The run-log reader (host_tools.golden.runlog) refuses metadata that contradicts the data (``reversal:
on`` without modes, ``sample_rate_hz`` against ``t_s``) and non-positive ``freq_hz``.
"""
from __future__ import annotations

import hashlib
import warnings

import numpy as np

FS_TOLERANCE = 0.01  # relative mismatch allowed between the log's sample rate and the model's fs


class ProxyWarning(UserWarning):
    """The temperature proxy was chosen from the columns present (the text says which)."""


def is_compensated(log) -> bool:
    """True for the output of `hdrg compensate` (metadata ``compensated: yes`` or a ``bias_dph``
    or ``flags`` column)."""
    return (str(log.metadata.get("compensated", "")).strip().lower() == "yes"
            or "bias_dph" in log or "flags" in log)


def check_fields(what: str, d: dict, required, optional=()) -> None:
    """ValueError naming every missing key of ``required`` and every key of ``d`` in neither
    ``required`` nor ``optional`` (a hand-edited config must not fall back to a default behind the
    user's back, nor have a misspelled key ignored)."""
    missing = [k for k in required if k not in d]
    unknown = sorted(set(d) - set(required) - set(optional))
    if missing or unknown:
        raise ValueError(f"{what}: " + "; ".join(([f"missing {', '.join(missing)}"] if missing else [])
                                                + ([f"unknown {', '.join(unknown)}"] if unknown else []))
                         + f" (fields: {', '.join(list(required) + list(optional))})")


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
    has ``freq_hz`` (temp_c is used)."""
    for log in logs:
        if is_compensated(log):
            raise ValueError(f"{log.source}: this is a compensated log (output of hdrg compensate: metadata "
                             f"'compensated: yes' or a bias_dph/flags column); fit needs raw run logs")
    lacking = [log.source for log in logs if "freq_hz" not in log] if proxy is None else []
    if lacking and len(lacking) < len(logs):
        raise ValueError(f"no 'freq_hz' column in {', '.join(lacking)} while the other logs have one: the proxy "
                         f"would switch to temp_c for all; fix the column names or pass --proxy temp")
    check_distinct_runs(logs)
    if lacking:
        warnings.warn(f"no 'freq_hz' column in {', '.join(lacking)}: the temperature proxy is 'temp_c' "
                      f"(pass --proxy temp to choose it explicitly)", ProxyWarning, stacklevel=2)


COVERAGE_MIN = 0.25   # a training run covering less than this share of the runs' joint proxy range is named


def coverage_warnings(logs, proxy: str | None = None) -> list:
    """Sentences for the training runs (several) each of which covers less than COVERAGE_MIN of the
    proxy range of all of them together (0.5 .. 99.5 percentiles): leave-one-run-out
    cross-validation must then predict the wide runs from the narrow one, and term selection
    ('auto') can keep nothing but the offset."""
    if len(logs) < 2:
        return []
    lo_hi = []
    for log in logs:
        _, p = log.proxy(proxy)
        p = np.asarray(p, np.float64)
        p = p[np.isfinite(p)]
        lo_hi.append((np.percentile(p, 0.5), np.percentile(p, 99.5)) if len(p) else (np.nan, np.nan))
    joint = max(h for _, h in lo_hi) - min(lo for lo, _ in lo_hi)
    if not np.isfinite(joint) or joint <= 0:
        return []
    return [f"{log.source} covers {100.0 * (h - lo) / joint:.0f} % of the training runs' joint proxy range: the "
            f"cross-validation that leaves it out must predict the other runs from it, and term selection can "
            f"keep only the offset; train on runs that each cover the temperature range, or fix the terms (--terms)"
            for log, (lo, h) in zip(logs, lo_hi) if (h - lo) < COVERAGE_MIN * joint]


def check_sample_rate(log, fs: float) -> None:
    """Refuse a log whose sample rate differs from the model's nominal fs [Hz] by more than
    ``FS_TOLERANCE`` (1 %): the rate estimator assumes the nominal period."""
    fs_log = log.sample_rate_hz
    if np.isfinite(fs_log) and abs(fs_log / fs - 1.0) > FS_TOLERANCE:
        raise ValueError(f"{log.source}: sample rate {fs_log:.6g} Hz does not match the model's "
                         f"nominal fs {fs:.6g} Hz (the rate estimator assumes the nominal period)")
