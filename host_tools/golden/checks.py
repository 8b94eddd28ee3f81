"""Input checks of the CLI stages that would otherwise reinterpret their input silently.

* :func:`check_fit_inputs`: training logs of `hdrg fit` / `hdrg diagnose` - a compensated log
  (output of `hdrg compensate`) is refused; without ``--proxy`` the proxy is ``freq_hz`` when
  every log has it, ``temp_c`` with a named warning when none has it, and a mix is an error
  (never a silent switch from the drive frequency to a temperature sensor).
* :func:`check_sample_rate`: a log to compensate (float golden or fixed point) whose sample rate is
  not the model's nominal fs (within ``FS_TOLERANCE``) is refused.

The run-log reader (host_tools.golden.runlog) refuses metadata that contradicts the data (``reversal:
on`` without modes, ``sample_rate_hz`` against ``t_s``) and non-positive ``freq_hz``.
"""
from __future__ import annotations

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


def check_fit_inputs(logs, proxy: str | None) -> None:
    """ValueError for a compensated training log or a mix of logs with and without ``freq_hz``
    when ``proxy`` is None; ProxyWarning when no log has ``freq_hz`` (temp_c is used)."""
    for log in logs:
        if is_compensated(log):
            raise ValueError(f"{log.source}: this is a compensated log (output of hdrg compensate: metadata "
                             f"'compensated: yes' or a bias_dph/flags column); fit needs raw run logs")
    if proxy is not None:
        return
    lacking = [log.source for log in logs if "freq_hz" not in log]
    if lacking and len(lacking) < len(logs):
        raise ValueError(f"no 'freq_hz' column in {', '.join(lacking)} while the other logs have one: the proxy "
                         f"would switch to temp_c for all; fix the column names or pass --proxy temp")
    if lacking:
        warnings.warn(f"no 'freq_hz' column in {', '.join(lacking)}: the temperature proxy is 'temp_c' "
                      f"(pass --proxy temp to choose it explicitly)", ProxyWarning, stacklevel=2)


def check_sample_rate(log, fs: float) -> None:
    """Refuse a log whose sample rate differs from the model's nominal fs [Hz] by more than
    ``FS_TOLERANCE`` (1 %): the rate estimator assumes the nominal period."""
    fs_log = log.sample_rate_hz
    if np.isfinite(fs_log) and abs(fs_log / fs - 1.0) > FS_TOLERANCE:
        raise ValueError(f"{log.source}: sample rate {fs_log:.6g} Hz does not match the model's "
                         f"nominal fs {fs:.6g} Hz (the rate estimator assumes the nominal period)")
