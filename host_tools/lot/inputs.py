"""The inputs of a lot: the manifest (or the directory convention), the spec and the per-device
input hash (host_tools.lot, module doc).

* :func:`read_manifest` ``(path)`` -> list of :class:`Device`, sorted by id; a manifest CSV, or a
  directory (its ``manifest.csv``, else one sub-directory per device);
* :func:`load_spec` ``(path or None)`` -> the spec dict (:data:`DEFAULT_SPEC` updated by the file);
* :func:`input_hash` ``(device, spec)``: sha256 over the lot format, the device's manifest row and
  the bytes of its run logs and the spec (what decides whether a finished device is reused).

Every problem is a ValueError naming the file, the line and the field.
"""
from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import re
from dataclasses import dataclass

LOT_FORMAT = "hdrg-lot"
LOT_VERSION = 1
DEVICE_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")
DEVICE_ID_RULE = ("1 to 64 characters: letters, digits, '_', '.', '-', starting with a letter or a digit")
COLUMNS = ("device", "train", "holdout", "power_on_s")
REQUIRED = ("device", "train")
RUN_SUFFIXES = (".csv", ".npz")

# Pass/fail figures of a device (host_tools.lot module doc, "Spec"); None disables a check.
DEFAULT_SPEC = {
    "heldout_stability_max_dph": 1.0,   # std of the 100-s means of the compensated held-out run(s)
    "stability_tau_s": 100.0,           # the averaging time of that stability [s]
    "residual_rms_max_dph": 1.0,        # rms of the training residual (FitResult.rms)
    "coverage_min": 0.99,               # share of held-out samples inside the model's proxy and rate ranges
    "valid_share_min": 0.5,             # share of held-out samples from power-on with a valid output
    "fixed_error_max_dph": 0.01,        # the quantizer's bound on |fixed - golden| of the output
    "min_train_s": 3600.0,              # total duration of the training run(s) [s]
    "require_heldout": False,           # a device without a held-out run fails
    "exchange_s": 30.0,                 # sequencer timing of the table (hdrg quantize)
    "dwell_s": 120.0,
    "power_on_s": 0.0,
}
_FLAGS = ("require_heldout",)
_POSITIVE = ("stability_tau_s", "dwell_s")
_SHARES = ("coverage_min", "valid_share_min")
_NULLABLE = ("heldout_stability_max_dph", "residual_rms_max_dph", "coverage_min", "valid_share_min",
             "fixed_error_max_dph", "min_train_s")


@dataclass(frozen=True)
class Run:
    """One run log of a device: ``name`` as the manifest writes it (used in every output),
    ``path`` where it is read from."""

    name: str
    path: str


@dataclass(frozen=True)
class Device:
    """One manifest row: ``id``, training and held-out :class:`Run` tuples, ``power_on_s`` (one
    mark per held-out run, None = the run's first sample), ``where`` (manifest file:line)."""

    id: str
    train: tuple
    holdout: tuple = ()
    power_on_s: tuple = ()
    where: str = ""


def check_device_id(text: str, where: str) -> str:
    """The device id, or ValueError: it names folders and goes into the exported tables."""
    if not DEVICE_ID.fullmatch(text):
        raise ValueError(f"{where}: field 'device': {text!r} is not a device id ({DEVICE_ID_RULE})")
    return text


def _paths(cell: str, base: str, where: str, column: str) -> tuple:
    runs = []
    for part in cell.split(";"):
        name = part.strip()
        if not name:
            raise ValueError(f"{where}: field '{column}': empty path in {cell!r} (separate paths with ';')")
        path = name if os.path.isabs(name) else os.path.join(base, name)
        runs.append(Run(name, os.path.normpath(path)))
    return tuple(runs)


def _marks(cell: str, n_holdout: int, where: str) -> tuple:
    cell = cell.strip()
    if not cell:
        return (None,) * n_holdout
    if n_holdout == 0:
        raise ValueError(f"{where}: field 'power_on_s': {cell!r} given but the device has no held-out run")
    vals = []
    for part in cell.split(";"):
        try:
            v = float(part)
        except ValueError:
            raise ValueError(f"{where}: field 'power_on_s': {part.strip()!r} is not a number of seconds") from None
        if not math.isfinite(v):
            raise ValueError(f"{where}: field 'power_on_s': {part.strip()!r} is not finite")
        vals.append(v)
    if len(vals) == 1:
        vals = vals * n_holdout
    if len(vals) != n_holdout:
        raise ValueError(f"{where}: field 'power_on_s': {len(vals)} marks for {n_holdout} held-out runs "
                         f"(give one per held-out run, or one for all)")
    return tuple(vals)


def _check_unique(devices: list, source: str) -> list:
    seen = {}
    for d in devices:
        key = d.id.lower()      # folders on a case-insensitive file system
        if key in seen:
            raise ValueError(f"{d.where}: field 'device': {d.id!r} repeats the device of {seen[key].where}"
                             + ("" if seen[key].id == d.id else " (ids may not differ only in case)"))
        seen[key] = d
    if not devices:
        raise ValueError(f"{source}: no devices")
    return sorted(devices, key=lambda d: d.id)


def parse_manifest(path) -> list:
    """The devices of a manifest CSV (module doc of host_tools.lot, "Manifest")."""
    path = os.fspath(path)
    base = os.path.dirname(os.path.abspath(path))
    with open(path, "r", encoding="utf-8", newline="") as fh:
        lines = [(i, line) for i, line in enumerate(fh, 1) if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise ValueError(f"{path}: empty manifest (expected a header {','.join(COLUMNS)})")
    rows = list(csv.reader([line for _, line in lines]))
    header = [h.strip() for h in rows[0]]
    hline = lines[0][0]
    unknown = [h for h in header if h not in COLUMNS]
    missing = [h for h in REQUIRED if h not in header]
    dup = sorted({h for h in header if header.count(h) > 1})
    if unknown or missing or dup:
        raise ValueError(f"{path}:{hline}: manifest header: " + "; ".join(
            ([f"unknown column(s) {', '.join(unknown)}"] if unknown else [])
            + ([f"missing column(s) {', '.join(missing)}"] if missing else [])
            + ([f"repeated column(s) {', '.join(dup)}"] if dup else []))
            + f" (columns: {', '.join(COLUMNS)}; required: {', '.join(REQUIRED)})")
    devices = []
    for (lineno, _), row in zip(lines[1:], rows[1:]):
        where = f"{path}:{lineno}"
        if len(row) != len(header):
            raise ValueError(f"{where}: {len(row)} cells, the header has {len(header)}")
        cells = dict(zip(header, (c.strip() for c in row)))
        dev_id = check_device_id(cells["device"], where)
        if not cells["train"]:
            raise ValueError(f"{where}: field 'train': empty (every device needs a training run)")
        train = _paths(cells["train"], base, where, "train")
        holdout = _paths(cells["holdout"], base, where, "holdout") if cells.get("holdout") else ()
        marks = _marks(cells.get("power_on_s", ""), len(holdout), where)
        devices.append(Device(dev_id, train, holdout, marks, where))
    return _check_unique(devices, path)


def scan_directory(path) -> list:
    """The devices of the directory convention: one sub-directory per device (its name the id),
    training runs ``train*.csv|npz``, held-out runs ``holdout*.csv|npz`` (sorted by name); hidden
    entries and plain files in ``path`` are not devices."""
    path = os.fspath(path)
    devices = []
    for entry in sorted(os.scandir(path), key=lambda e: e.name):
        if entry.name.startswith(".") or not entry.is_dir():
            continue
        where = os.path.join(path, entry.name)
        dev_id = check_device_id(entry.name, where)
        files = sorted(f.name for f in os.scandir(entry.path) if f.is_file())
        runs = {role: tuple(Run(os.path.join(entry.name, f), os.path.join(entry.path, f)) for f in files
                            if f.startswith(role) and f.lower().endswith(RUN_SUFFIXES))
                for role in ("train", "holdout")}
        if not runs["train"]:
            raise ValueError(f"{where}: no training run (train*.csv or train*.npz) in the device folder "
                             f"(files: {', '.join(files) or 'none'})")
        devices.append(Device(dev_id, runs["train"], runs["holdout"], (None,) * len(runs["holdout"]), where))
    return _check_unique(devices, path)


def read_manifest(path) -> list:
    """A manifest CSV, or a directory: its manifest.csv when present, else :func:`scan_directory`."""
    path = os.fspath(path)
    if os.path.isdir(path):
        inner = os.path.join(path, "manifest.csv")
        return parse_manifest(inner) if os.path.isfile(inner) else scan_directory(path)
    return parse_manifest(path)


def load_spec(path=None) -> dict:
    """DEFAULT_SPEC updated by the JSON object in ``path`` (None: the defaults); unknown keys and
    values of the wrong kind are errors naming the key."""
    spec = dict(DEFAULT_SPEC)
    if path is None:
        return spec
    path = os.fspath(path)
    with open(path, "r", encoding="utf-8") as fh:
        try:
            given = json.load(fh)
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: not valid JSON (line {exc.lineno}: {exc.msg})") from None
    if not isinstance(given, dict):
        raise ValueError(f"{path}: a spec is a JSON object, not {type(given).__name__}")
    unknown = sorted(set(given) - set(DEFAULT_SPEC))
    if unknown:
        raise ValueError(f"{path}: unknown spec key(s) {', '.join(unknown)} (keys: {', '.join(DEFAULT_SPEC)})")
    for key, val in given.items():
        what = f"{path}: field '{key}'"
        if key in _FLAGS:
            if not isinstance(val, bool):
                raise ValueError(f"{what}: must be true or false, not {val!r}")
        elif val is None:
            if key not in _NULLABLE:
                raise ValueError(f"{what}: may not be null")
        elif isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val) or val < 0:
            raise ValueError(f"{what}: must be a finite number >= 0" + (" or null (no check)" if key in _NULLABLE
                                                                         else "") + f", not {val!r}")
        elif key in _SHARES and val > 1:
            raise ValueError(f"{what}: a share between 0 and 1, not {val!r}")
        elif key in _POSITIVE and val <= 0:
            raise ValueError(f"{what}: must be > 0, not {val!r}")
        spec[key] = float(val) if isinstance(val, (int, float)) and not isinstance(val, bool) else val
    return spec


def file_digest(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def input_hash(device: Device, spec: dict, version: str) -> str:
    """sha256 (hex) of what a device's outputs depend on: the lot format and the toolchain
    ``version``, the device's id, run names, power-on marks, the bytes of its run logs (an
    unreadable file hashes as its error, so it fails again without a refit), and the spec."""
    h = hashlib.sha256()

    def put(text: str) -> None:
        b = text.encode("utf-8")
        h.update(len(b).to_bytes(8, "little") + b)

    put(f"{LOT_FORMAT} {LOT_VERSION} hdrg {version}")
    put(device.id)
    for role, runs in (("train", device.train), ("holdout", device.holdout)):
        for run in runs:
            put(f"{role} {run.name}")
            try:
                put(file_digest(run.path))
            except OSError as exc:
                put(f"unreadable: {exc.strerror or exc}")
    put(json.dumps(list(device.power_on_s)))
    put(json.dumps(spec, sort_keys=True))
    return h.hexdigest()
