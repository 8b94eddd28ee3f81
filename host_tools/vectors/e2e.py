"""The ``e2e`` set's case generator: simulated chamber runs with fitted, quantized models.
"""
from __future__ import annotations

import numpy as np

from host_tools.vectors.spec import E2E_FIELDS, SEQ_INPUTS
from host_tools.vectors.files import VectorSet
from host_tools.vectors.pipeline import Cases, compute_pipeline


# -- end to end --------------------------------------------------------------------------------------

E2E_RUNS = (
    # name, scenario, seed, duration [s], description, reversal (order, combiner) or None
    ("ftr", "paper-ftr-cycle-4dpm", 11, 2400.0, "FTR, -20..20 degC cycles at 4 degC/min", None),
    ("mode_reversal", "paper-mr-cycle-4dpm", 12, 2400.0, "mode reversal 30/120 s, cycles at 4 degC/min, "
     "combine_first pair (legacy)", ("combine_first", "pair")),
    ("regress_first_pair", "paper-mr-cycle-4dpm", 12, 2400.0, "mode reversal, regress_first pair (two banks)",
     ("regress_first", "pair")),
    ("regress_first_none", "paper-mr-cycle-4dpm", 12, 2400.0, "mode reversal, regress_first none (two banks)",
     ("regress_first", "none")),
    ("regress_first_trend", "paper-mr-cycle-4dpm", 12, 2400.0, "mode reversal, regress_first trend (two banks)",
     ("regress_first", "trend")),
) + tuple(
    # the same chamber cycle at other drive frequencies (the F word holds 0 .. 131072 Hz)
    (f"regress_first_pair_{f0 / 1e3:g}khz", "paper-mr-cycle-4dpm", 13, 900.0,
     f"mode reversal, regress_first pair, drive frequency {f0:g} Hz", ("regress_first", "pair"), {"f0_hz": f0})
    for f0 in (3.0e3, 24.0e3, 36.0e3, 65.0e3))


def round_sig(x: float, digits: int = 7) -> float:
    return float(f"{float(x):.{digits}g}")


def jsonable_value(x):
    if isinstance(x, dict):
        return {str(k): jsonable_value(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable_value(v) for v in x]
    if isinstance(x, (float, np.floating)):
        return repr(float(x))
    if isinstance(x, np.integer):
        return int(x)
    return x


def e2e_model(log, reversal=None):
    """The model of a run: fit_config_from_logs (rounded to 7 significant digits; ``reversal`` an
    (order, combiner) pair for a mode-reversal log), fit_logs with it, coefficients (both banks)
    rounded to 7 significant digits; returns (model, table)."""
    from host_tools.golden import compensate as hc
    from host_tools.fitting.fit import fit_logs
    from host_tools.golden.model import BiasModel, ModelConfig
    from host_tools.golden.proxy import ProxyConfig
    from host_tools.fixed.quantize import quantize
    from host_tools.golden.rate import RateConfig

    from host_tools.golden.reversal import ReversalConfig

    rev = None if reversal is None else ReversalConfig(reversal[1], order=reversal[0])
    cfg0 = hc.fit_config_from_logs([log], reversal=rev)
    cfg = ModelConfig(ProxyConfig(cfg0.proxy.kind, round_sig(cfg0.proxy.ref), round_sig(cfg0.proxy.span)),
                      RateConfig(cfg0.rate.estimator, cfg0.rate.n, cfg0.rate.shift, round_sig(cfg0.rate.span),
                                 cfg0.rate.fs), cfg0.reversal, cfg0.aux)
    fitted, _ = fit_logs([log], cfg, terms="all")            # pinned: the default became "auto"
    coef = np.array([round_sig(c) for c in fitted.coef], np.float64)
    coef2 = None if fitted.coef_mode2 is None else np.array([round_sig(c) for c in fitted.coef_mode2], np.float64)
    model = BiasModel(cfg, fitted.terms, coef, source=f"<vectors e2e {log.source}>", coef_mode2=coef2)
    return model, quantize(model, n_random=10).table


def e2e_set() -> tuple:
    """(VectorSet, configuration dict)."""
    from firmware_ref import inputs
    from host_tools.fixed.fixed_point import log_words
    from host_tools.simulation.sim import simulate

    cs = Cases()
    config = {}
    for name, scenario, seed, duration, desc, reversal, *extra in E2E_RUNS:
        overrides = extra[0] if extra else {}
        log = simulate(scenario, seed=seed, duration_s=duration, **overrides)
        model, table = e2e_model(log, reversal)
        w = log_words(log, model.config)
        other = (inputs.temp_words(log["temp_c"]) if table.proxy_kind == 0 else inputs.freq_words(log["freq_hz"]))[0]
        args = "".join(f", {k}={v!r}" for k, v in overrides.items())
        cs.add(name, f"{desc}: host_tools.simulation.sim.simulate({scenario!r}, seed={seed}, duration_s={duration:g}"
               f"{args}), fitted, quantized; log-driven", table, w, t_words=other)
        config[name] = {"scenario": scenario, "seed": seed, "duration_s": repr(duration), **overrides,
                        "model": {"config": model.config.to_dict(), "terms": list(model.terms),
                                  "coef": list(model.coef),
                                  **({"coef_mode2": list(model.coef_mode2)} if model.coef_mode2 is not None
                                     else {})},
                        "input_saturated_samples": int(np.count_nonzero(w["input_sat"]))}
    vs = VectorSet("e2e", "simulated chamber runs through the whole pipeline with every intermediate: the "
                   "sequencer set's columns plus the evaluator's Horner rows (row0..row3, zterm, t at 2^-E)",
                   cs.columns(), SEQ_INPUTS, E2E_FIELDS, cs.cases, cs.tables)
    compute_pipeline(vs, rows=True)
    return vs, jsonable_value(config)
