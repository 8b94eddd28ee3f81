"""Building, writing and verifying the sets: ``generate`` (refuses changed vectors without a
version bump), ``verify`` (SHA-256s, then every vector recomputed from its inputs), staleness.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from firmware_ref.table import Table, TableError
from host_tools.vectors.spec import (DEFAULT_DIR, FORMAT_VERSION, GENERATOR_VERSION, PRIM_OPS, PY_CHECK, SEED,
                                     SETS, VectorsError)
from host_tools.vectors.files import VectorSet, sha256_of, parse_csv, read_manifest, render_all, source_fingerprint
from host_tools.vectors.primitives import compute_primitives, primitives_set
from host_tools.vectors.evaluator import compute_evaluator, evaluator_set
from host_tools.vectors.pipeline import compute_pipeline
from host_tools.vectors.sequencer import sequencer_set
from host_tools.vectors.e2e import e2e_set
from host_tools.vectors.aux import aux_set
from host_tools.vectors.validity import validity_set


# -- generate -----------------------------------------------------------------------------------------

def build_sets(names=SETS) -> tuple:
    """(list of VectorSet, configuration) for the named sets (deterministic)."""
    unknown = [n for n in names if n not in SETS]
    if unknown:
        raise ValueError(f"unknown vector set(s) {', '.join(unknown)}; sets: {', '.join(SETS)}")
    seeds = {name: SEED + k for k, name in enumerate(SETS)}
    out, config = [], {"seeds": seeds, "py_check_samples_per_case": PY_CHECK}
    for name in SETS:
        if name not in names:
            continue
        rng = np.random.default_rng(seeds[name])
        if name == "primitives":
            out.append(primitives_set(rng))
        elif name == "evaluator":
            out.append(evaluator_set(rng))
        elif name == "sequencer":
            out.append(sequencer_set(rng))
        elif name == "e2e":
            vs, cfg = e2e_set()
            config["e2e"] = cfg
            out.append(vs)
        elif name == "aux":
            vs = aux_set(rng)
            config["aux"] = vs.config
            out.append(vs)
        else:
            out.append(validity_set(rng))
    return out, config


def generate(directory, names=SETS, force: bool = False) -> dict:
    """Write the vectors into ``directory``; returns the manifest.  Refuses (VectorsError) to change
    an existing vector file without a version bump unless ``force``; files of the old manifest
    that the new one does not list are removed."""
    directory = Path(directory)
    sets, config = build_sets(names)
    files = render_all(sets, config)
    new = json.loads(files["manifest.json"])
    old = None
    if (directory / "manifest.json").is_file():
        try:
            old = read_manifest(directory)
        except VectorsError:
            old = None
    if old is not None and not force and (old.get("generator_version"), old.get("format_version")) == \
            (GENERATOR_VERSION, FORMAT_VERSION):
        changed = sorted(name for name, meta in new["files"].items()
                         if name in old.get("files", {}) and old["files"][name]["sha256"] != meta["sha256"])
        if changed:
            raise VectorsError(f"{directory}: the vectors changed ({', '.join(changed)}) but GENERATOR_VERSION "
                               f"{GENERATOR_VERSION} and FORMAT_VERSION {FORMAT_VERSION} are those of the existing "
                               f"manifest: bump GENERATOR_VERSION (host_tools/vectors/spec.py) or pass --force")
    directory.mkdir(parents=True, exist_ok=True)
    if old is not None:
        for name in old.get("files", {}):
            if name not in new["files"] and (directory / name).is_file() and "/" not in name:
                (directory / name).unlink()
    for name, data in files.items():
        (directory / name).write_bytes(data)
    return new


# -- verify -------------------------------------------------------------------------------------------

def set_order(manifest: dict, names=None) -> list:
    """The manifest's sets in SETS order (then any others), restricted to ``names``; ValueError
    for a name the manifest lacks."""
    have = manifest["sets"]
    if names:
        missing = [n for n in names if n not in have]
        if missing:
            raise ValueError(f"set(s) {', '.join(missing)} not in the vectors (sets: {', '.join(have)})")
    order = [n for n in SETS if n in have] + sorted(n for n in have if n not in SETS)
    return [n for n in order if not names or n in names]


def load_set(directory: Path, name: str, meta: dict) -> VectorSet:
    """A set from its files: columns of the CSV, tables of the .tables.mem (checked against the
    manifest's words)."""
    cols = parse_csv((directory / meta["csv"]).read_bytes(), str(directory / meta["csv"]))
    if list(cols) != meta["columns"]:
        raise VectorsError(f"{directory / meta['csv']}: columns {list(cols)} differ from the manifest's")
    tables = []
    if meta.get("tables_mem"):
        text = (directory / meta["tables_mem"]).read_text().split()
        sizes = [len(entry["words"]) for entry in meta["tables"]]
        if len(text) != sum(sizes):
            raise VectorsError(f"{directory / meta['tables_mem']}: {len(text)} words, expected "
                               f"{sum(sizes)} ({len(sizes)} tables)")
        at = 0
        for k, entry in enumerate(meta["tables"]):
            words = [int(w, 16) for w in text[at:at + sizes[k]]]
            at += sizes[k]
            if [f"{w:08x}" for w in words] != entry["words"]:
                raise VectorsError(f"{directory / meta['tables_mem']}: table {k} differs from the manifest's")
            try:
                tables.append(Table.from_words(words, f"{meta['tables_mem']} table {k}"))
            except TableError as exc:
                raise VectorsError(str(exc)) from None
    inputs = tuple(meta["inputs"])
    mem_fields = tuple((f["name"], f["bits"]) for f in meta["mem_record"])
    return VectorSet(name, meta["description"], cols, inputs, mem_fields, meta["cases"], tables)


def _first_diff(name: str, meta: dict, got: dict, want: dict) -> str:
    """Text of the first row where the recomputed columns differ from the file's."""
    n = len(next(iter(want.values())))
    bad = np.zeros(n, bool)
    for col in want:
        if col in got and len(got[col]) == n:
            bad |= got[col] != want[col]
    if not bad.any():
        return f"set {name}: the files differ from the re-rendered values (format, not values)"
    i = int(np.argmax(bad))
    return describe_row(name, meta, want, i) + "\n  " + "; ".join(
        f"{col}: file {want[col][i]}, recomputed {got[col][i]}" for col in want if got[col][i] != want[col][i])


def describe_row(name: str, meta: dict, cols: dict, i: int) -> str:
    ins = " ".join(f"{k}={PRIM_OPS[cols[k][i]] if k == 'op' else cols[k][i]}" for k in meta["inputs"]
                   if k not in ("case", "i"))
    case = ""
    if "case" in cols:
        c = meta["cases"][int(cols["case"][i])]
        case = f" (case {c['name']}"
        case += f", sample {cols['i'][i]})" if "i" in cols else ")"
    return f"set {name}, row {i}{case}: inputs {ins}"


def verify(directory, names=None, log=print) -> list:
    """Check the SHA-256 of every file, then recompute every set from its inputs and diff; returns
    the list of problems (empty: the vectors are correct).  Prints progress with ``log``."""
    directory = Path(directory)
    manifest = read_manifest(directory)
    problems = []
    for fname, meta in manifest["files"].items():
        path = directory / fname
        if not path.is_file():
            problems.append(f"{path}: missing")
            continue
        data = path.read_bytes()
        if sha256_of(data) != meta["sha256"] or len(data) != meta["bytes"]:
            problems.append(f"{path}: SHA-256 {sha256_of(data)[:16]}... differs from the manifest's "
                            f"{meta['sha256'][:16]}... (file changed)")
    fp = source_fingerprint()
    if fp["sha256"] != manifest.get("sources_sha256"):
        changed = sorted(k for k in set(fp["files"]) | set(manifest.get("sources", {}))
                         if fp["files"].get(k) != manifest.get("sources", {}).get(k))
        log(f"note: the algorithm sources differ from those the vectors were generated from "
            f"({', '.join(changed)}); the recomputation below decides")
    for name in set_order(manifest, names):
        meta = manifest["sets"][name]
        try:
            vs = load_set(directory, name, meta)
        except (VectorsError, OSError) as exc:
            problems.append(str(exc))
            continue
        want = dict(vs.columns)
        try:
            if name == "primitives":
                compute_primitives(vs)
            elif name == "evaluator":
                compute_evaluator(vs)
            else:
                compute_pipeline(vs, rows=name == "e2e")
        except VectorsError as exc:
            problems.append(str(exc))
            continue
        same = list(vs.columns) == list(want) and all(np.array_equal(vs.columns[c], want[c]) for c in want)
        files = vs.files()
        disk = {f: (directory / f).read_bytes() for f in files}
        if not same or any(files[f] != disk[f] for f in files):
            problems.append(_first_diff(name, meta, vs.columns, want))
            log(f"{name}: {len(want[next(iter(want))])} rows: MISMATCH")
        else:
            log(f"{name}: {len(vs)} rows, {len(vs.cases)} cases: recomputed, identical")
    return problems


def staleness(directory=DEFAULT_DIR, regenerated: dict | None = None) -> list:
    """Problems that make committed vectors stale: the algorithm sources changed since they were
    generated, or a regeneration (file name -> bytes, default: generate now) differs from them."""
    directory = Path(directory)
    manifest = read_manifest(directory)
    problems = []
    fp = source_fingerprint()
    if fp["sha256"] != manifest.get("sources_sha256"):
        changed = sorted(k for k in set(fp["files"]) | set(manifest.get("sources", {}))
                         if fp["files"].get(k) != manifest.get("sources", {}).get(k))
        problems.append(f"algorithm sources changed since generation: {', '.join(changed)}")
    if regenerated is None:
        regenerated = render_all(*build_sets())
    for fname, data in regenerated.items():
        path = directory / fname
        if not path.is_file():
            problems.append(f"{fname}: not in {directory}")
        elif path.read_bytes() != data:
            problems.append(f"{fname}: regenerated bytes differ from {path}")
    return problems
