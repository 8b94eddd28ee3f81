"""One device of a lot: read, fit, held-out check, quantize, export, pass/fail (host_tools.lot).

:func:`calibrate` ``(job) -> {"result": dict, "files": {name: bytes}}`` runs in a worker (a
process of the pool, or a Dask worker) and writes nothing: the lot's driver writes the files
(host_tools.lot.engine).  A problem of the device's data (unreadable or corrupt log, too short, a
fit or quantization refused, a held-out run outside the model's range) makes the device fail with
its stage and reason; it never raises.  Warnings raised while a device is processed are kept in
its result, never printed.

The fit is :func:`host_tools.fitting.fit_pipeline.fit_default` (what ``hdrg fit RUN...`` does),
with the refusals of ``hdrg fit`` (no degrees of freedom, fewer than MIN_SAMPLES_PER_TERM valid
samples per coefficient); the held-out figures come from host_tools.golden.compensate and
host_tools.fitting.metrics; the table from host_tools.fixed.quantize and host_tools.fixed.export.
"""
from __future__ import annotations

import json
import math
import threading
import warnings

import numpy as np

from firmware_ref.vocabulary import FLAG_PROXY_CLAMPED, FLAG_RATE_CLAMPED

# name of each output file in a device's folder -> what it is
OUTPUTS = {"model.json": "the bias model (hdrg fit's model.json)",
           "table.h": "C99 header of the coefficient table (hdrg export --format c)",
           "table.json": "table.json with the float originals and the quantizer's report (hdrg export --format json)",
           "table.memh": "$readmemh words (hdrg export --format mem)",
           "result.json": "the device's figures, pass/fail and reasons"}
TABLE_SYMBOL = "hdrg_table"     # C symbol of every device's table (the firmware loads the same name)
STAGES = ("read", "check", "fit", "heldout", "quantize", "export", "spec")

# Devices run one at a time per process: the warning capture (warnings.catch_warnings) is
# process-wide, so a Dask worker with several threads must not interleave two devices.
_LOCK = threading.Lock()


class DeviceFailure(Exception):
    """A device cannot go on: ``stage`` (one of STAGES) and the reason (the message)."""

    def __init__(self, stage: str, reason: str):
        super().__init__(reason)
        self.stage = stage


def num(x):
    """A JSON-safe float (None for None, NaN, inf)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _read(runs, names):
    from host_tools.golden import runlog

    logs = []
    for run in runs:
        try:
            log = runlog.read(run.path)
        except FileNotFoundError:
            raise DeviceFailure("read", f"{run.name}: no such file") from None
        except MemoryError:
            raise
        except Exception as exc:       # whatever the reader meets in a damaged file is the file's problem
            raise DeviceFailure("read", f"{run.name}: {_message(exc, names)}") from None
        log.source = run.name
        logs.append(log)
    return logs


def _message(exc: BaseException, names: dict) -> str:
    """The error text with the runs' paths replaced by their manifest names."""
    text = str(exc) or type(exc).__name__
    if isinstance(exc, OSError) and exc.strerror and exc.filename:
        text = f"{exc.filename}: {exc.strerror}"
    for path, name in names.items():
        text = text.replace(path, name)
    return text


def _duration_s(log) -> float:
    t = np.asarray(log.t_s, np.float64)
    if len(t) < 2:
        return 0.0
    return float(t[-1] - t[0] + np.median(np.diff(t)))


def _fit(logs):
    from host_tools.fitting.fit import MIN_SAMPLES_PER_TERM
    from host_tools.fitting.fit_pipeline import fit_default
    from host_tools.golden.checks import check_fit_inputs

    try:
        check_fit_inputs(logs, None)
        model, res = fit_default(logs)
    except (ValueError, LookupError, ArithmeticError, np.linalg.LinAlgError) as exc:
        raise DeviceFailure("fit", str(exc)) from None
    if res.dof <= 0 or not np.all(np.isfinite(res.stderr)):
        raise DeviceFailure("fit", f"{res.n} valid samples for {len(res.terms)} coefficients: no degrees of "
                                   f"freedom left (record a longer training run)")
    if res.n < MIN_SAMPLES_PER_TERM * len(res.terms):
        raise DeviceFailure("fit", f"{res.n} valid samples for {len(res.terms)} coefficients, fewer than "
                                   f"{MIN_SAMPLES_PER_TERM} per coefficient (record a longer training run)")
    model.source = "model.json"
    return model, res


def heldout_figures(log, model, mark, tau_s: float) -> dict:
    """The figures of one held-out run: compensated with ``model`` (float golden model), counted
    from the power-on mark ``mark`` [s] (None: the first sample): the stability (std of the
    ``tau_s`` means), the valid share, and the shares of non-exchange samples inside the model's
    proxy and rate ranges (not clamped)."""
    from host_tools.fitting.metrics import at_tau, bias_metrics, output_of
    from host_tools.golden.compensate import compensate
    from host_tools.golden.flags import problems
    from host_tools.golden.runlog import MODE_EXCHANGE

    try:
        out = compensate(log, model)
    except (ValueError, LookupError, ArithmeticError) as exc:
        raise DeviceFailure("heldout", f"{log.source}: {exc}") from None
    t = np.asarray(out.t_s, np.float64)
    on = t >= (t[0] if mark is None else mark)
    if not on.any():
        raise DeviceFailure("heldout", f"{log.source}: power-on mark {mark:g} s is after the run's last sample "
                                       f"({t[-1]:g} s)")
    _, out_dph, valid, _ = output_of(out)
    row = at_tau(bias_metrics(out_dph, t, valid & on, (tau_s,)), tau_s)
    flags = np.asarray(out["flags"], np.int64)
    meet = on & (np.asarray(out.mode) != MODE_EXCHANGE)
    n_meet = max(int(np.count_nonzero(meet)), 1)
    return {"run": log.source, "samples": int(np.count_nonzero(on)),
            "power_on_s": num(t[0] if mark is None else mark),
            "stability_dph": num(row["stability_dph"]), "stability_note": row["reason"],
            "valid_share": float(np.count_nonzero(valid & on) / np.count_nonzero(on)),
            "proxy_coverage": float(1.0 - np.count_nonzero(meet & ((flags & FLAG_PROXY_CLAMPED) != 0)) / n_meet),
            "rate_coverage": float(1.0 - np.count_nonzero(meet & ((flags & FLAG_RATE_CLAMPED) != 0)) / n_meet),
            "problems": problems(out)}


def _worst(rows, key, pick):
    vals = [r[key] for r in rows if r[key] is not None]
    return pick(vals) if vals else None


def spec_reasons(r: dict, spec: dict) -> list:
    """The reasons a processed device fails ``spec`` (empty: it passes)."""
    why = []
    tau = spec["stability_tau_s"]
    if not r["heldout"]:
        if spec["require_heldout"]:
            why.append("no held-out run (the spec requires one: require_heldout)")
    else:
        lim = spec["heldout_stability_max_dph"]
        if lim is not None:
            if r["heldout_stability_dph"] is None:
                notes = "; ".join(h["stability_note"] for h in r["heldout"] if h["stability_note"])
                why.append(f"held-out stability ({tau:g}-s means) not measurable: {notes}")
            elif r["heldout_stability_dph"] > lim:
                why.append(f"held-out stability {r['heldout_stability_dph']:.4g} deg/h ({tau:g}-s means) > "
                           f"{lim:g} (heldout_stability_max_dph)")
        lim = spec["valid_share_min"]
        if lim is not None and r["valid_share"] < lim:
            why.append(f"valid share from power-on {r['valid_share']:.1%} < {lim:.1%} (valid_share_min)")
        lim = spec["coverage_min"]
        for what in ("proxy", "rate"):
            cov = r[f"{what}_coverage"]
            if lim is not None and cov < lim:
                why.append(f"{what} coverage {cov:.1%} of the held-out samples inside the model's {what} range "
                           f"< {lim:.1%} (coverage_min): the device meets inputs outside its training range")
    lim = spec["residual_rms_max_dph"]
    if lim is not None and r["residual_rms_dph"] > lim:
        why.append(f"training residual rms {r['residual_rms_dph']:.4g} deg/h > {lim:g} (residual_rms_max_dph)")
    lim = spec["fixed_error_max_dph"]
    if lim is not None and r["fixed_bound_dph"] > lim:
        why.append(f"|fixed - golden| bound {r['fixed_bound_dph']:.3g} deg/h > {lim:g} (fixed_error_max_dph)")
    return why


def _export(device_id: str, model, spec: dict) -> tuple:
    from host_tools.fixed.export import c_header, json_dict
    from host_tools.fixed.quantize import QuantizeError, quantize
    from firmware_ref.table import TableError

    try:
        q = quantize(model, exchange_s=spec["exchange_s"], dwell_s=spec["dwell_s"], power_on_s=spec["power_on_s"])
    except (QuantizeError, TableError, ValueError) as exc:
        raise DeviceFailure("quantize", str(exc)) from None
    t = q.table
    crc = f"0x{t.crc:08x}"
    stamp = f"device {device_id}, table CRC-32 {crc}"
    head = c_header(t, TABLE_SYMBOL, q.to_dict())
    anchor = "#include <stdint.h>\n"
    if anchor not in head:      # pragma: no cover - the exporter's layout changed
        raise RuntimeError("the C header has no '#include <stdint.h>' line to put the device id after")
    sym = TABLE_SYMBOL.upper()
    head = (f"/* hdrg lot: {stamp}. */\n"
            + head.replace(anchor, f"{anchor}\n#define {sym}_DEVICE_ID \"{device_id}\"\n", 1))
    info = {**q.to_dict(), "device_id": device_id}
    table_json = json_dict(t, info)
    table_json["exported_by"] = "hdrg lot"
    files = {"table.h": head.encode("utf-8"),
             "table.json": _json_bytes(table_json),
             "table.memh": (f"// hdrg lot: {stamp}\n" + t.to_memh()).encode("utf-8")}
    b, m = q.report["bound_dph"], q.report["measured_dph"]
    figures = {"crc32": crc, "table_words": len(t.to_words()), "fixed_bound_dph": num(b["out"]),
               "fixed_measured_dph": num(max(m["corners"], m["random"])), "quantize_warnings": list(q.report["warnings"])}
    return files, figures


def _json_bytes(d: dict) -> bytes:
    return (json.dumps(d, indent=2, allow_nan=False) + "\n").encode("utf-8")


def _process(job: dict, result: dict, files: dict) -> None:
    dev, spec = job["device"], job["spec"]
    names = {r.path: r.name for r in dev.train + dev.holdout}
    train = _read(dev.train, names)
    holdout = _read(dev.holdout, names)
    result["train_s"] = sum(_duration_s(log) for log in train)
    result["train_samples"] = sum(len(log) for log in train)
    if spec["min_train_s"] is not None and result["train_s"] < spec["min_train_s"]:
        raise DeviceFailure("check", f"too short: the training run(s) cover {result['train_s']:g} s, the spec needs "
                                     f">= {spec['min_train_s']:g} s (min_train_s)")
    model, res = _fit(train)
    files["model.json"] = _json_bytes(model.to_dict())
    result.update({"terms": ",".join(f"k{k}" for k in res.terms), "residual_rms_dph": num(res.rms),
                   "cv_rms_dph": num(res.cv["cv_rms"]) if res.cv else None, "fit_samples": int(res.n)})
    rows = [heldout_figures(log, model, mark, spec["stability_tau_s"]) for log, mark in zip(holdout, dev.power_on_s)]
    result["heldout"] = rows
    result["heldout_stability_dph"] = _worst(rows, "stability_dph", max) if all(
        r["stability_dph"] is not None for r in rows) else None
    for key in ("valid_share", "proxy_coverage", "rate_coverage"):
        result[key] = _worst(rows, key, min)
    tables, figures = _export(dev.id, model, spec)
    files.update(tables)
    result.update(figures)


def _error_text(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


def calibrate(job: dict) -> dict:
    """The outputs of one device (module doc).  ``job``: {"device": Device, "spec": dict,
    "input_hash": str}.  ``result["retry"]`` is True when the failure may not repeat (out of
    memory): the driver then writes no done-marker, so the next run tries the device again."""
    dev = job["device"]
    result = {"device": dev.id, "status": "fail", "stage": None, "reasons": [], "input_hash": job["input_hash"],
              "train": [r.name for r in dev.train], "holdout_runs": [r.name for r in dev.holdout],
              "train_s": None, "train_samples": None, "terms": None, "residual_rms_dph": None, "cv_rms_dph": None,
              "fit_samples": None, "heldout": [], "heldout_stability_dph": None, "valid_share": None,
              "proxy_coverage": None, "rate_coverage": None, "crc32": None, "table_words": None,
              "fixed_bound_dph": None, "fixed_measured_dph": None, "quantize_warnings": [], "warnings": [],
              "retry": False}
    files = {}
    names = {r.path: r.name for r in dev.train + dev.holdout}
    with _LOCK, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            _process(job, result, files)
            why = spec_reasons(result, job["spec"])
            result.update(status="fail" if why else "pass", stage="spec" if why else "done", reasons=why)
        except DeviceFailure as exc:
            result.update(stage=exc.stage, reasons=[_message(exc, names)])
        except MemoryError:
            result.update(stage="memory", reasons=["out of memory (no done-marker: the next run tries again)"],
                          retry=True)
        except Exception as exc:        # a device never stops the lot: an unexpected error is its reason
            result.update(stage="internal", reasons=[f"unexpected {_message(RuntimeError(_error_text(exc)), names)}"])
        msgs = []
        for w in caught:
            text = _message(Warning(str(w.message)), names)
            if text not in msgs:
                msgs.append(text)
        result["warnings"] = msgs
    if result["status"] != "pass" or result["retry"]:   # no table from a failed device (its model is kept)
        files = {k: v for k, v in files.items() if k == "model.json"}
    files["result.json"] = _json_bytes(result)
    return {"result": result, "files": files}
