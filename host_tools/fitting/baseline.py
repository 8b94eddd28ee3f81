"""The baseline to beat: the thermal calibration of the common open-source flight stacks.

A cubic polynomial in a temperature sensor about a reference temperature, with the temperature
clamped to the calibrated range, fitted by least squares (e.g. PX4's gyro thermal calibration:
offset = x0 + x1 dT + x2 dT^2 + x3 dT^3, dT = clamp(T) - T_ref).  No rate terms, no cross terms.

It is expressed as a :class:`host_tools.golden.model.BiasModel` with the ``temp`` proxy (``temp_c``;
the model's own proxy when the logs have no temperature sensor), the proxy range equal to the
training range (so the clamp is the flight stacks' clamp to the calibrated range) and the terms
k0..k3, applied to the same target as the model it is compared with (the FTR output or the
mode-reversal combined output).
"""
from __future__ import annotations

from host_tools.golden.compensate import fit_config_from_logs
from host_tools.golden.model import BiasModel, ModelConfig

BASELINE_TERMS = (0, 1, 2, 3)


def baseline_config(logs, like: ModelConfig | None = None) -> ModelConfig:
    """Config of the flight-stack baseline on ``logs``: temp_c proxy clamped to the training
    range (margin 0), the reversal settings of ``like`` (the model it is compared with); ValueError
    for a log that is FTR where ``like`` is mode reversal, or the reverse."""
    kind = "temp" if all("temp_c" in log for log in logs) else None
    reversal = like.reversal if like is not None else None
    if like is not None:
        other = [log.source for log in logs if log.reversal != (reversal is not None)]
        if other:
            raise ValueError(f"{', '.join(other)}: {'FTR' if reversal is not None else 'mode-reversal'} training "
                             f"run(s) for {'a mode-reversal' if reversal is not None else 'an FTR'} model (the "
                             f"baseline is applied to the model's target)")
    if any(log.reversal for log in logs) and reversal is None:
        reversal = {"combiner": "pair"}
    return fit_config_from_logs(logs, proxy_kind=kind, proxy_margin=0.0,
                                reversal=reversal if any(log.reversal for log in logs) else None,
                                fs=like.rate.fs if like is not None else None)


def fit_baseline(logs, like: ModelConfig | None = None) -> BiasModel:
    """Fit the baseline cubic-in-temperature model to ``logs`` (RunLogs)."""
    from host_tools.fitting.fit import fit_logs

    cfg = baseline_config(logs, like)
    model, _ = fit_logs(logs, cfg, terms=BASELINE_TERMS)
    model.fit["baseline"] = "cubic in temperature sensor about the reference, clamped to the calibrated range (flight-stack style)"
    return model
