"""The bias model: configuration of the data flow + the 17 coefficients, and its JSON file.

A :class:`BiasModel` holds

* ``config`` (:class:`ModelConfig`): ``proxy`` (host_tools.golden.proxy.ProxyConfig), ``rate``
  (host_tools.golden.rate.RateConfig, incl. the nominal sample rate fs), ``reversal``
  (host_tools.golden.reversal.ReversalConfig: combiner name, max_stale_s, settle_s; or None for an FTR
  model) and ``aux`` (host_tools.golden.regressors.AuxConfig);
* ``terms``: the enabled term indices k (sorted tuple, subset of 0..16);
* ``coef``: float64[17], deg/h, 0 for every disabled term: the one bank of an FTR or
  combine_first model, or bank 1 (mode-1 samples) of a regress_first model;
* ``coef_mode2``: float64[17] or None: bank 2 (mode-2 samples); present iff the model is
  mode reversal with ``order == "regress_first"`` (host_tools.golden.reversal);
* ``fit``: free dict of fit information (stderr, cond, rms, n, ...), JSON-serializable.

``banks`` is float64[n_banks, 17] (1 or 2 rows).  ``evaluate(u, v, z, mode) -> B`` [deg/h] uses the
firmware's Horner form (host_tools.golden.regressors); with two banks ``mode`` (int array, run-log mode
codes) is required: mode 2 samples use ``coef_mode2``, every other sample ``coef``.

JSON file format (version 2; version 1 files, which have no "order" and no second bank, still
read, their reversal as ``order: "combine_first"``)::

    {
      "format": "hdrg-model",
      "version": 2,
      "config": {
        "proxy":    {"kind": "freq"|"temp", "unit": "Hz"|"degC", "ref": float, "span": float},
        "rate":     {"estimator": "diff"|"diffn"|"lsq"|"iir", "n": int, "shift": int,
                     "span": float (proxy units/s), "fs": float (Hz),
                     "divisor": int, "warmup": int},          # the last two derived, checked
        "reversal": null | {"combiner": "pair"|"trend"|"none", "max_stale_s": float, "settle_s": float,
                            "order": "regress_first"|"combine_first"},   # order required in v2
        "aux":      {"generator": "none", "params": {...}}     # params optional
      },
      "terms": [k, ...],                 # sorted, unique, 0..16
      "term_names": ["1", "u", ...],     # informative, one per enabled term
      "coef_dph": [17 floats],           # k0..k16 in deg/h, 0 for disabled terms (bank 1)
      "coef_mode2_dph": [17 floats],     # bank 2: present iff order is regress_first
      "fit": {...}                       # free (non-finite numbers are written as null)
    }

Floats are written in shortest round-trip form, so a model survives write/read bit for bit.
Reading refuses (:class:`ModelError`, a ValueError whose message names the file and the field)
a non-JSON file, a file that is not a regular file or is over 16 MiB, a key repeated in one
object, nesting over 32 levels (host_tools.jsonread), another ``format``, a missing or unknown
``version``, a missing field, an unknown field (at the top level, in ``config``, ``config.proxy``,
``config.rate``, ``config.reversal`` and the aux terms: a misspelt key), a wrong type or an
out-of-range value (a proxy ``span`` below one LSB of the proxy word, a drive-frequency ``ref``
<= 0), a non-zero coefficient of a disabled term, a missing or unexpected second bank, a
``fit.train`` that is not a list of paths; also, naming the field: a number in ``config`` or a
coefficient that is not finite (``1e999``, ``NaN``) or is an integer too large for a float, a
coefficient with |k| above :data:`COEF_LIMIT_DPH` (what the output word holds), and a ``settle_s``
or ``max_stale_s`` over :data:`TIMER_LIMIT_N` samples at the model's sample rate (what the
firmware's timing fields hold), and an aux ``params.fs`` that is not ``rate.fs`` (the k7
generators' time constants use it).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field

import numpy as np

from firmware_ref import formats as F
from firmware_ref.terms import N_TERMS, TERM_NAMES
from host_tools.golden.proxy import ProxyConfig
from host_tools.golden.rate import RateConfig
from host_tools.golden.regressors import AuxConfig, bias_horner
from host_tools.golden.reversal import ReversalConfig
from host_tools.errors import HdrgError

FORMAT = "hdrg-model"
VERSION = 2
READ_VERSIONS = (1, 2)
MAX_BYTES = 16 << 20        # a model file is a few kB; larger is refused before it is parsed
MAX_DEPTH = 32              # a model nests 4 deep (its fit info a few more); deeper is refused
# largest |coefficient| a model file may hold [deg/h]: the range of the output and bias words (int32,
# LSB 2^-OUT_FRAC deg/h: +-2^21 deg/h); one term alone at |u| = |v| = |z| = 1 would saturate them
COEF_LIMIT_DPH = F.INT32_SYM * 2.0 ** -F.OUT_FRAC
TIMER_LIMIT_N = F.TIMER_MAX - 1     # largest settle/staleness time in samples (the table's timing fields)


class ModelError(HdrgError, ValueError):
    """A model file or object that cannot be used: names the file, the field and the problem."""

    def __init__(self, source: str, field_name: str | None, problem: str):
        self.source, self.field, self.problem = source, field_name, problem
        where = f"{source}: field '{field_name}'" if field_name else source
        super().__init__(f"{where}: {problem}")


@dataclass(frozen=True)
class ModelConfig:
    """The data flow of a model: proxy normalization, rate estimator, mode-reversal combination
    (None: FTR) and auxiliary regressor."""

    proxy: ProxyConfig
    rate: RateConfig
    reversal: ReversalConfig | None = None
    aux: AuxConfig = field(default_factory=AuxConfig)

    def to_dict(self) -> dict:
        return {"proxy": self.proxy.to_dict(), "rate": self.rate.to_dict(),
                "reversal": None if self.reversal is None else self.reversal.to_dict(),
                "aux": self.aux.to_dict()}

    @classmethod
    def from_dict(cls, d: dict, source: str = "<dict>") -> "ModelConfig":
        if not isinstance(d, dict):
            raise ModelError(source, "config", f"must be an object, not {type(d).__name__}")
        _refuse_unknown(d, ("proxy", "rate", "reversal", "aux"), source, "config.")
        parts = {}
        for name, make in (("proxy", ProxyConfig.from_dict), ("rate", RateConfig.from_dict),
                           ("reversal", ReversalConfig.from_dict), ("aux", AuxConfig.from_dict)):
            if name not in d:
                if name == "aux":
                    parts[name] = AuxConfig()
                    continue
                raise ModelError(source, f"config.{name}", "missing")
            value = d[name]
            if value is None and name == "reversal":
                parts[name] = None
                continue
            if not isinstance(value, dict):
                raise ModelError(source, f"config.{name}", f"must be an object, not {type(value).__name__}")
            try:
                parts[name] = make(value)
            except KeyError as exc:
                raise ModelError(source, f"config.{name}.{exc.args[0]}", "missing") from None
            except (TypeError, ValueError, OverflowError) as exc:
                raise ModelError(source, f"config.{name}", str(exc)) from None
        return cls(**parts)


@dataclass
class BiasModel:
    """config + enabled terms + 17 coefficients [deg/h] + free fit info (see the module doc)."""

    config: ModelConfig
    terms: tuple
    coef: np.ndarray
    fit: dict = field(default_factory=dict)
    source: str = "<memory>"
    coef_mode2: np.ndarray | None = None

    def __post_init__(self):
        self.terms = _check_terms(self.terms, self.source)
        self.coef = _check_coef(self.coef, self.terms, self.source)
        if not isinstance(self.fit, dict):
            raise ModelError(self.source, "fit", f"must be an object, not {type(self.fit).__name__}")
        rev = self.config.reversal
        two = rev is not None and rev.order == "regress_first"
        if two and self.coef_mode2 is None:
            raise ModelError(self.source, "coef_mode2_dph", "missing: a regress_first mode-reversal model "
                                                            "needs a second coefficient bank (mode 2)")
        if not two and self.coef_mode2 is not None:
            kind = "an FTR" if rev is None else "a combine_first"
            raise ModelError(self.source, "coef_mode2_dph", f"{kind} model has one coefficient bank, "
                                                            f"but a second one was given")
        if two:
            self.coef_mode2 = _check_coef(self.coef_mode2, self.terms, self.source, "coef_mode2_dph")

    @property
    def banks(self) -> np.ndarray:
        """float64[n_banks, 17]: [coef] or [coef, coef_mode2]."""
        return np.array([self.coef] if self.coef_mode2 is None else [self.coef, self.coef_mode2])

    def evaluate(self, u, v, z=None, mode=None) -> np.ndarray:
        """B [deg/h] at normalized (u, v, z) (Horner form, host_tools.golden.regressors.bias_horner).
        With two banks ``mode`` (run-log mode codes, one per sample) is required: mode 2 ->
        ``coef_mode2``, any other -> ``coef``; with one bank it is ignored."""
        b1 = bias_horner(self.coef, u, v, z)
        if self.coef_mode2 is None:
            return b1
        if mode is None:
            raise ValueError(f"{self.source}: the model has two coefficient banks (regress_first): "
                             f"evaluate needs the mode of every sample")
        mode = np.asarray(mode)
        if mode.shape != np.shape(b1):
            raise ValueError(f"{self.source}: mode has shape {mode.shape}, u has {np.shape(b1)}")
        return np.where(mode == 2, bias_horner(self.coef_mode2, u, v, z), b1)

    # -- JSON ------------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        d = {
            "format": FORMAT,
            "version": VERSION,
            "config": self.config.to_dict(),
            "terms": list(self.terms),
            "term_names": [TERM_NAMES[k] for k in self.terms],
            "coef_dph": [float(c) for c in self.coef],
        }
        if self.coef_mode2 is not None:
            d["coef_mode2_dph"] = [float(c) for c in self.coef_mode2]
        d["fit"] = jsonable(self.fit)
        return d

    def to_json(self, path) -> None:
        from host_tools.atomic import atomic_open
        with atomic_open(path, "w", encoding="utf-8") as fh:
            json.dump(self.to_dict(), fh, indent=2, allow_nan=False)
            fh.write("\n")

    @classmethod
    def from_dict(cls, d, source: str = "<dict>") -> "BiasModel":
        if not isinstance(d, dict):
            raise ModelError(source, None, f"not an hdrg model (top level is {type(d).__name__}, not an object)")
        if d.get("format") != FORMAT:
            raise ModelError(source, "format", f"not an hdrg model: expected {FORMAT!r}, found {d.get('format')!r}")
        if "version" not in d:
            raise ModelError(source, "version", "missing")
        version = d["version"]
        if version not in READ_VERSIONS or isinstance(version, bool):
            raise ModelError(source, "version", f"unsupported model format version {version!r} "
                                                f"(this hdrg reads versions {', '.join(map(str, READ_VERSIONS))})")
        for name in ("config", "terms", "coef_dph"):
            if name not in d:
                raise ModelError(source, name, "missing")
        _refuse_unknown(d, ("format", "version", "config", "terms", "term_names", "coef_dph", "coef_mode2_dph",
                            "fit"), source)
        rev = d["config"].get("reversal") if isinstance(d["config"], dict) else None
        if isinstance(rev, dict):
            if version == 1 and "order" in rev:
                raise ModelError(source, "config.reversal.order", "not a field of model format version 1")
            if version >= 2 and "order" not in rev:
                raise ModelError(source, "config.reversal.order", "missing")
        if version == 1 and "coef_mode2_dph" in d:
            raise ModelError(source, "coef_mode2_dph", "not a field of model format version 1")
        _check_numbers(d["config"], "config", source)
        config = ModelConfig.from_dict(d["config"], source)
        _check_timing(config, source)
        _check_aux_fs(config, source)
        for name in ("coef_dph", "coef_mode2_dph"):
            if d.get(name) is not None:
                _check_coef_range(d[name], source, name)
        fit = d.get("fit", {})
        train = fit.get("train") if isinstance(fit, dict) else None
        if train is not None and not (isinstance(train, list) and all(isinstance(p, str) for p in train)):
            raise ModelError(source, "fit.train", "must be a list of run-log paths (strings)")
        return cls(config, d["terms"], d["coef_dph"], d.get("fit", {}) or {}, source,
                   d.get("coef_mode2_dph"))

    @classmethod
    def from_json(cls, path) -> "BiasModel":
        from host_tools.jsonread import InputFileError, read_json

        source = os.fspath(path)
        try:
            d = read_json(source, "model file", MAX_BYTES, MAX_DEPTH)
        except InputFileError as exc:
            raise ModelError(source, None, str(exc).removeprefix(f"{source}: ")) from None
        return cls.from_dict(d, source)


def _refuse_unknown(d: dict, known, source: str, prefix: str = "") -> None:
    """ModelError naming the first key of ``d`` not in ``known`` (a misspelt key must not be ignored
    while its field falls back to a default or goes missing)."""
    unknown = [k for k in d if k not in known]
    if unknown:
        raise ModelError(source, f"{prefix}{unknown[0]}", f"unknown field (fields here: {', '.join(known)})")


def _check_terms(terms, source) -> tuple:
    if isinstance(terms, (str, bytes)) or not hasattr(terms, "__iter__"):
        raise ModelError(source, "terms", f"must be a list of term indices, not {terms!r}")
    out = []
    for k in terms:
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= k < N_TERMS:
            raise ModelError(source, "terms", f"{k!r} is not a term index 0..{N_TERMS - 1}")
        out.append(int(k))
    if len(set(out)) != len(out):
        raise ModelError(source, "terms", f"duplicated term in {out}")
    return tuple(sorted(out))


def _check_numbers(node, path: str, source) -> None:
    """ModelError naming the field of the first number under ``node`` (a parsed JSON value) that is
    not finite or is an integer too large for a float."""
    stack = [(node, path)]
    while stack:
        node, path = stack.pop()
        if isinstance(node, dict):
            stack.extend((v, f"{path}.{k}") for k, v in reversed(list(node.items())))
        elif isinstance(node, list):
            stack.extend((v, f"{path}[{i}]") for i, v in reversed(list(enumerate(node))))
        elif isinstance(node, int) and not isinstance(node, bool):
            try:
                float(node)
            except OverflowError:
                raise ModelError(source, path, f"an integer of {len(str(abs(node)))} digits: too large "
                                               f"for a number") from None
        elif isinstance(node, float) and not math.isfinite(node):
            raise ModelError(source, path, f"must be a finite number, not {node}")


def _check_timing(config: ModelConfig, source) -> None:
    """ModelError when the settling or staleness time [s] is more samples than the firmware's timing
    fields hold (TIMER_LIMIT_N) at the model's sample rate config.rate.fs [Hz]."""
    rev, fs = config.reversal, config.rate.fs
    if rev is None:
        return
    for name in ("settle_s", "max_stale_s"):
        value = float(getattr(rev, name))
        if not math.isfinite(value) or value * fs > TIMER_LIMIT_N:
            raise ModelError(source, f"config.reversal.{name}",
                             f"{value:g} s is more than {TIMER_LIMIT_N} samples at {fs:g} Hz "
                             f"(at most {TIMER_LIMIT_N / fs:.6g} s)")


def _check_aux_fs(config: ModelConfig, source) -> None:
    """ModelError when the k7 generators' sample rate ``config.aux.params.fs`` is not the model's
    nominal rate ``config.rate.fs``: the generators turn their time constants into per-sample
    coefficients with it, so another rate would filter every compensated log with the wrong lag."""
    if config.aux.generator == "none":
        return
    aux_fs, fs = float(config.aux.params["fs"]), float(config.rate.fs)
    if aux_fs != fs:
        raise ModelError(source, "config.aux.params.fs",
                         f"{aux_fs:g} Hz is not the model's sample rate config.rate.fs {fs:g} Hz (the k7 "
                         f"generators' time constants would be converted at the wrong rate)")


def _check_coef_range(coef, source, name) -> None:
    """ModelError naming the coefficient (kN) of a list read from a file whose value is not finite,
    is an integer too large for a float, or has |k| > COEF_LIMIT_DPH [deg/h]."""
    if not isinstance(coef, list):
        return          # its type is refused by _check_coef
    for k, c in enumerate(coef):
        if isinstance(c, bool) or not isinstance(c, (int, float)):
            continue
        try:
            value = float(c)
        except OverflowError:
            value = math.inf
        if not abs(value) <= COEF_LIMIT_DPH:
            shown = f"is a {len(str(abs(c)))}-digit integer" if math.isinf(value) and isinstance(c, int) \
                else f"= {value:g} deg/h"
            kname = f"k{k} (term {TERM_NAMES[k]})" if k < N_TERMS else f"k{k}"
            raise ModelError(source, name, f"{kname} {shown}: |k| must be at most {COEF_LIMIT_DPH:.7g} deg/h "
                                           f"(the output word: int32, LSB 2^-{F.OUT_FRAC} deg/h)")


def _check_coef(coef, terms, source, name="coef_dph") -> np.ndarray:
    try:
        if isinstance(coef, (str, bytes)) or any(isinstance(c, (bool, str, bytes)) for c in coef):
            raise TypeError
        values = [float(c) for c in coef]
    except OverflowError:
        raise ModelError(source, name, "holds an integer too large for a float") from None
    except (TypeError, ValueError):
        raise ModelError(source, name, f"must be a list of {N_TERMS} numbers, not {coef!r}") from None
    if len(values) != N_TERMS:
        raise ModelError(source, name, f"has {len(values)} values, expected {N_TERMS} (k0..k16)")
    arr = np.array(values, np.float64)
    bad = ~np.isfinite(arr)
    if bad.any():
        raise ModelError(source, name, f"k{int(np.argmax(bad))} is not finite ({arr[bad][0]})")
    for k in range(N_TERMS):
        if k not in terms and arr[k] != 0.0:
            raise ModelError(source, name, f"k{k} = {float(arr[k])!r} but term k{k} is not enabled (terms {list(terms)})")
    return arr


def jsonable(obj, skip_private: bool = False):
    """numpy -> plain Python, non-finite floats -> None (strict JSON); with ``skip_private``, dict
    keys starting with '_' are left out.  The one converter of every JSON the host tools write."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v, skip_private) for k, v in obj.items()
                if not (skip_private and str(k).startswith("_"))}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v, skip_private) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist(), skip_private)
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer, int)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    return obj
