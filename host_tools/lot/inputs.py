"""The inputs of a lot: the manifest (or the directory convention), the spec and the per-device
input hash (host_tools.lot, module doc).

* :func:`read_manifest` ``(path, exclude=None)`` -> list of :class:`Device`, sorted by id (rows of
  one id in manifest order); a manifest CSV, or a directory (its ``manifest.csv``, else one
  sub-directory per device; ``exclude``: a folder that is not a device, the lot's output);
* :func:`manifest_conflicts` ``(devices, digests)`` -> {index: (kind, reason)}: the rows that fail
  before any work (a repeated id, a run shared with another device, a held-out run that is the
  training run);
* :func:`load_spec` ``(path or None)`` -> the spec dict (:data:`DEFAULT_SPEC` updated by the file;
  :data:`SPEC_DOC` gives each key's unit and meaning);
* :func:`input_hash` ``(device, spec, version, digests)``: sha256 over what a device's computation
  depends on (the lot format, the toolchain version, its manifest row, the bytes of its run logs,
  the spec keys that are not :func:`judged_keys`); :func:`judged_spec` the other keys, the limits
  a finished device is judged against again without a refit.

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
    "allow_repaired_logs": False,       # a run log the reader repaired may pass
    "exchange_s": 30.0,                 # sequencer timing of the table (hdrg quantize)
    "dwell_s": 120.0,
    "power_on_s": 0.0,
}
# key -> (unit, meaning): `hdrg lot --help` prints these with DEFAULT_SPEC (one source)
SPEC_DOC = {
    "heldout_stability_max_dph": ("deg/h", "largest std of the stability_tau_s means of the compensated held-out "
                                           "run(s), counted from power-on"),
    "stability_tau_s": ("s", "averaging time of that stability"),
    "residual_rms_max_dph": ("deg/h", "largest rms of the training residual"),
    "coverage_min": ("share 0..1", "smallest share of held-out samples inside the model's proxy range, and inside "
                                   "its rate range"),
    "valid_share_min": ("share 0..1", "smallest share of held-out samples from power-on with a valid output "
                                      "(mode reversal 30 s / 120 s: at most 0.8)"),
    "fixed_error_max_dph": ("deg/h", "largest bound of the quantizer on |fixed - golden| of the output"),
    "min_train_s": ("s", "shortest total duration of the training run(s)"),
    "require_heldout": ("true/false", "a device without a held-out run fails"),
    "allow_repaired_logs": ("true/false", "a device whose run log the reader repaired (truncated last line, gaps, "
                                          "unfinished capture) may pass"),
    "exchange_s": ("s", "sequencer timing written into the table: mode-exchange time"),
    "dwell_s": ("s", "sequencer timing written into the table: dwell time"),
    "power_on_s": ("s", "sequencer timing written into the table: power-on time"),
}
# manifest column -> meaning (`hdrg lot --help`)
COLUMN_DOC = {
    "device": "required: the device id (" + "1 to 64 characters: letters, digits, '_', '.', '-', starting with a "
              "letter or a digit; it names the device's folder and goes into its tables)",
    "train": "required: the training run log(s), CSV or .npz, several separated by ';' (fitted together)",
    "holdout": "optional: the held-out run log(s), ';'-separated (empty: no held-out check)",
    "power_on_s": "optional: t_s [s] of the power-on in each held-out run (one per held-out run, or one for all; "
                  "empty: the run's first sample)",
}
_FLAGS = ("require_heldout", "allow_repaired_logs")
_POSITIVE = ("stability_tau_s", "dwell_s")
_SHARES = ("coverage_min", "valid_share_min")
_NULLABLE = ("heldout_stability_max_dph", "residual_rms_max_dph", "coverage_min", "valid_share_min",
             "fixed_error_max_dph", "min_train_s")
MAX_SPEC_BYTES = 1 << 20       # a spec is a few hundred bytes


@dataclass(frozen=True)
class Run:
    """One run log of a device: ``name`` as the manifest writes it (used in every output),
    ``path`` where it is read from."""

    name: str
    path: str


@dataclass(frozen=True)
class Device:
    """One manifest row: ``id``, training and held-out :class:`Run` tuples, ``power_on_s`` (one
    mark per held-out run, None = the run's first sample), ``where`` (manifest file:line),
    ``order`` (the row's place in the manifest, from 0)."""

    id: str
    train: tuple
    holdout: tuple = ()
    power_on_s: tuple = ()
    where: str = ""
    order: int = 0


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


def _sorted(devices: list, source: str) -> list:
    """``devices`` sorted by id (rows of one id in manifest order); ValueError when there is none.
    A repeated id is not refused here: :func:`manifest_conflicts` fails the later row alone."""
    if not devices:
        raise ValueError(f"{source}: no devices")
    return sorted(devices, key=lambda d: (d.id, d.order))


def _manifest_text(path: str) -> str:
    """The text of the manifest file ``path``: a regular file (a FIFO or a device is refused
    before it is opened), UTF-8 with or without a BOM; else ValueError naming the file and line."""
    from host_tools.jsonread import check_regular

    check_regular(path, "manifest")
    with open(path, "rb") as fh:
        data = fh.read()
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise ValueError(f"{path}:{line}: the manifest is not UTF-8 text (byte 0x{data[exc.start]:02x} at offset "
                         f"{exc.start}); save it as UTF-8") from None


def parse_manifest(path) -> list:
    """The devices of a manifest CSV (module doc of host_tools.lot, "Manifest")."""
    path = os.fspath(path)
    base = os.path.dirname(os.path.abspath(path))
    text = _manifest_text(path)
    lines = [(i, line) for i, line in enumerate(text.splitlines(keepends=True), 1)
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise ValueError(f"{path}: empty manifest (expected a header {','.join(COLUMNS)})")
    try:
        rows = list(csv.reader([line for _, line in lines]))
    except csv.Error as exc:
        raise ValueError(f"{path}: not a CSV manifest ({exc})") from None
    if len(rows) != len(lines):
        raise ValueError(f"{path}: a quoted cell spans lines (one device per line)")
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
    for order, ((lineno, _), row) in enumerate(zip(lines[1:], rows[1:])):
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
        devices.append(Device(dev_id, train, holdout, marks, where, order))
    return _sorted(devices, path)


def _same_dir(a: str, b) -> bool:
    if b is None:
        return False
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(os.fspath(b))


def scan_directory(path, exclude=None) -> list:
    """The devices of the directory convention: one sub-directory per device (its name the id),
    training runs ``train*.csv|npz``, held-out runs ``holdout*.csv|npz`` (sorted by name); hidden
    entries, plain files, the folder ``exclude`` (the lot's output) and any folder holding a lot's
    output (``devices/`` and ``.lot.lock``) are not devices."""
    path = os.fspath(path)
    devices = []
    for entry in sorted(os.scandir(path), key=lambda e: e.name):
        if entry.name.startswith(".") or not entry.is_dir() or _same_dir(entry.path, exclude):
            continue
        if os.path.exists(os.path.join(entry.path, ".lot.lock")) and os.path.isdir(os.path.join(entry.path, "devices")):
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
        devices.append(Device(dev_id, runs["train"], runs["holdout"], (None,) * len(runs["holdout"]), where,
                              len(devices)))
    return _sorted(devices, path)


def read_manifest(path, exclude=None) -> list:
    """A manifest CSV, or a directory: its manifest.csv when present, else :func:`scan_directory`
    (``exclude``: a folder inside it that is not a device, e.g. the lot's output)."""
    path = os.fspath(path)
    if os.path.isdir(path):
        inner = os.path.join(path, "manifest.csv")
        return parse_manifest(inner) if os.path.lexists(inner) else scan_directory(path, exclude)
    return parse_manifest(path)


def manifest_conflicts(devices: list, digests: dict) -> dict:
    """The rows of ``devices`` that fail before any work, ``{index: (kind, reason)}``, in manifest
    order: kind ``repeat``, a device id given again (also in another case: the folders would be one
    on a case-insensitive file system): the later row fails, the first is calibrated; kind
    ``runs``, a run log that is another device's run (the same path, or the same bytes:
    ``digests`` {path: sha256 or None}): the later device fails, naming the other; and a held-out
    run that is the device's own training run (its check would not be independent)."""
    out, first, owner = {}, {}, {}

    def keys(run):
        yield ("the same file", os.path.realpath(run.path))
        if digests.get(run.path):
            yield ("the same bytes", digests[run.path])

    for i in sorted(range(len(devices)), key=lambda k: devices[k].order):
        d = devices[i]
        key = d.id.lower()
        if key in first:
            other = first[key]
            out[i] = ("repeat", f"device id {d.id!r} repeats the device {other.id!r} of {other.where}"
                      + ("" if other.id == d.id else " (ids may not differ only in case)")
                      + f"; this row ({d.where}) is not calibrated, the first one is: fix the manifest")
            continue
        first[key] = d
        why = None
        train_keys = {k: run for run in d.train for k in keys(run)}
        for run in d.holdout:
            hit = next(((k, train_keys[k]) for k in keys(run) if k in train_keys), None)
            if hit:
                why = (f"held-out run {run.name} is the training run {hit[1].name} ({hit[0][0]}): its check would "
                       f"not be independent; give a run recorded apart from the training")
                break
        if why is None:
            for role, runs in (("training", d.train), ("held-out", d.holdout)):
                for run in runs:
                    hit = next(((k, owner[k]) for k in keys(run) if k in owner), None)
                    if hit:
                        o_dev, o_role, o_run = hit[1]
                        why = (f"{role} run {run.name} is {hit[0][0]} as the {o_role} run {o_run.name} of device "
                               f"{o_dev.id!r} ({o_dev.where}): a run belongs to one device")
                        break
                if why:
                    break
        if why:
            out[i] = ("runs", why)
            continue
        for role, runs in (("training", d.train), ("held-out", d.holdout)):
            for run in runs:
                for k in keys(run):
                    owner.setdefault(k, (d, role, run))
    return out


def load_spec(path=None) -> dict:
    """DEFAULT_SPEC updated by the JSON object in ``path`` (None: the defaults); a file that is not
    a regular file, not UTF-8 or not JSON, a repeated key, deep nesting, unknown keys and values of
    the wrong kind are errors naming the file and the key."""
    from host_tools.jsonread import InputFileError, read_json

    spec = dict(DEFAULT_SPEC)
    if path is None:
        return spec
    path = os.fspath(path)
    try:
        given = read_json(path, "spec", max_bytes=MAX_SPEC_BYTES, max_depth=4)
    except InputFileError as exc:
        raise ValueError(str(exc)) from None
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
        elif isinstance(val, bool) or not isinstance(val, (int, float)) or not _finite(val) or val < 0:
            raise ValueError(f"{what}: must be a finite number >= 0" + (" or null (no check)" if key in _NULLABLE
                                                                         else "") + f", not {_short(val)}")
        elif key in _SHARES and val > 1:
            raise ValueError(f"{what}: a share between 0 and 1, not {_short(val)}")
        elif key in _POSITIVE and val <= 0:
            raise ValueError(f"{what}: must be > 0, not {_short(val)}")
        spec[key] = float(val) if isinstance(val, (int, float)) and not isinstance(val, bool) else val
    return spec


def _finite(val) -> bool:
    """True for a number that is a finite float (an int too large for a float is not)."""
    try:
        return math.isfinite(float(val))
    except OverflowError:
        return False


def _short(val) -> str:
    """repr of ``val``, at most 40 characters (a huge number or string in an error line)."""
    try:
        text = repr(val)
    except ValueError:          # an int too long to print
        return "a number too long to print"
    return text if len(text) <= 40 else text[:37] + "..."


def judged_keys(spec: dict) -> tuple:
    """The keys of ``spec`` that only judge a finished device's figures (module doc)."""
    from host_tools.lot.device import JUDGED_KEYS
    return tuple(k for k in spec if k in JUDGED_KEYS)


def judged_spec(spec: dict) -> dict:
    """The part of ``spec`` a finished device is judged against (no refit when only it changes)."""
    return {k: spec[k] for k in judged_keys(spec)}


def file_digest(path: str) -> str:
    """sha256 (hex) of the bytes of the regular file ``path``; OSError for a file that is not
    regular (a FIFO or a device such as /dev/zero is never opened: it would block or never end)."""
    import errno
    import stat

    st = os.stat(path)
    if not stat.S_ISREG(st.st_mode):
        raise OSError(errno.EINVAL, "not a regular file", path)
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def run_digests(devices: list) -> dict:
    """{path: sha256 hex, or None when it cannot be read as a regular file} of every run log of
    ``devices`` (each file read once)."""
    out = {}
    for d in devices:
        for run in d.train + d.holdout:
            if run.path not in out:
                try:
                    out[run.path] = file_digest(run.path)
                except OSError:
                    out[run.path] = None
    return out


def input_hash(device: Device, spec: dict, version: str, digests: dict | None = None) -> str:
    """sha256 (hex) of what a device's computation depends on: the lot format and the toolchain
    ``version``, the device's id, run names, power-on marks, the bytes of its run logs (from
    ``digests`` when given; a file that cannot be read hashes as its error, so it fails again
    without a refit), and the spec keys that are not :func:`judged_keys`."""
    h = hashlib.sha256()

    def put(text: str) -> None:
        b = text.encode("utf-8")
        h.update(len(b).to_bytes(8, "little") + b)

    put(f"{LOT_FORMAT} {LOT_VERSION} hdrg {version}")
    put(device.id)
    for role, runs in (("train", device.train), ("holdout", device.holdout)):
        for run in runs:
            put(f"{role} {run.name}")
            digest = (digests or {}).get(run.path)
            if digest is None:
                try:
                    digest = file_digest(run.path)
                except OSError as exc:
                    digest = f"unreadable: {exc.strerror or exc}"
            put(digest)
    put(json.dumps(list(device.power_on_s)))
    judged = set(judged_keys(spec))
    put(json.dumps({k: v for k, v in spec.items() if k not in judged}, sort_keys=True))
    return h.hexdigest()
