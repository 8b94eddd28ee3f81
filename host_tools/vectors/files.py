"""The vector file formats and the manifest: CSV, ``$readmemh`` records, table files, the source
fingerprint, ``manifest.json`` (no timestamps; SHA-256 of every file).
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import re
from pathlib import Path

import numpy as np

from firmware_ref.table import Table
from host_tools.vectors.spec import FORMAT_VERSION, GENERATOR_VERSION, PRIM_OPS, ROOT, SOURCE_GLOBS, VectorsError


def sha256_of(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def source_fingerprint(root: Path = ROOT) -> dict:
    """SHA-256 of every algorithm source (SOURCE_GLOBS, CRLF normalized to LF) and of their
    concatenated digests: ``{"sha256": ..., "files": {path: sha256}}``."""
    files = {}
    for pattern in SOURCE_GLOBS:
        for path in sorted(root.glob(pattern)):
            files[path.relative_to(root).as_posix()] = sha256_of(path.read_bytes().replace(b"\r\n", b"\n"))
    files = dict(sorted(files.items()))
    total = sha256_of("".join(f"{k} {v}\n" for k, v in files.items()).encode())
    return {"sha256": total, "files": files}


# -- a set in memory --------------------------------------------------------------------------------

@dataclasses.dataclass
class VectorSet:
    """One set: ordered int64 columns, the record layout of its .mem file, its cases and tables."""

    name: str
    description: str
    columns: dict                       # name -> int64 array, CSV column order
    inputs: tuple                       # the input columns
    mem_fields: tuple                   # ((name, bits), ...), MSB first
    cases: list = dataclasses.field(default_factory=list)   # dicts: name, rows, table, self_timed, ...
    tables: list = dataclasses.field(default_factory=list)  # Table objects

    def __len__(self):
        return len(next(iter(self.columns.values())))

    def files(self) -> dict:
        """file name -> bytes."""
        out = {f"{self.name}.csv": render_csv(self), f"{self.name}.mem": render_mem(self.columns, self.mem_fields)}
        if self.tables:
            out[f"{self.name}.tables.mem"] = "".join(t.to_memh() for t in self.tables).encode()
        return out


def render_csv(vs: VectorSet) -> bytes:
    cols = []
    for name, arr in vs.columns.items():
        if name == "op":
            cols.append([PRIM_OPS[k] for k in arr.tolist()])
        else:
            cols.append([str(x) for x in arr.tolist()])
    lines = [",".join(vs.columns)] + [",".join(row) for row in zip(*cols)]
    return ("\n".join(lines) + "\n").encode()


def render_mem(columns: dict, fields: tuple) -> bytes:
    """One line per record: the fields' two's complement words concatenated, MSB first, in hex."""
    fmt = "".join(f"%0{bits // 4}x" for _, bits in fields) + "\n"
    masked = [(columns[name].astype(np.uint64) & np.uint64((1 << bits) - 1)).tolist() for name, bits in fields]
    return "".join(fmt % row for row in zip(*masked)).encode()


def parse_csv(data: bytes, source: str) -> dict:
    """CSV bytes -> name -> int64 array (op names back to codes)."""
    lines = data.decode().splitlines()
    if not lines:
        raise VectorsError(f"{source}: empty file")
    header = lines[0].split(",")
    rows = [line.split(",") for line in lines[1:]]
    for k, row in enumerate(rows):
        if len(row) != len(header):
            raise VectorsError(f"{source}:{k + 2}: {len(row)} fields, the header has {len(header)}")
    cols = {}
    for c, name in enumerate(header):
        vals = [row[c] for row in rows]
        try:
            if name == "op":
                cols[name] = np.array([PRIM_OPS.index(x) for x in vals], np.int64)
            else:
                cols[name] = np.array([int(x) for x in vals], np.int64)
        except ValueError:
            raise VectorsError(f"{source}: column {name!r}: a value is not an integer"
                               f"{' or an op name' if name == 'op' else ''}") from None
    return cols


def _table_entry(t: Table) -> dict:
    words = t.to_words()
    return {"crc32": f"{words[-1]:08x}", "words": [f"{w:08x}" for w in words], "fields": t.field_values()}


def _offsets(tables) -> list:
    """First word of each table in <set>.tables.mem (the tables are concatenated)."""
    out, at = [], 0
    for t in tables:
        out.append(at)
        at += len(t.to_words())
    return out


def make_manifest(sets, config, files: dict) -> dict:
    fp = source_fingerprint()
    return {
        "format": "hdrg-vectors",
        "format_version": FORMAT_VERSION,
        "generator": "hdrg vectors (host_tools/vectors/)",
        "generator_version": GENERATOR_VERSION,
        "sources_sha256": fp["sha256"],
        "sources": fp["files"],
        "configuration": config,
        "protocol": "firmware_ref/c/README.md 'Driver protocol' (copied in vectors/README.md)",
        "sets": {vs.name: {
            "description": vs.description,
            "rows": len(vs),
            "csv": f"{vs.name}.csv",
            "columns": list(vs.columns),
            "inputs": list(vs.inputs),
            "mem": f"{vs.name}.mem",
            "mem_record": [{"name": n, "bits": b} for n, b in vs.mem_fields],
            "mem_record_bits": sum(b for _, b in vs.mem_fields),
            "tables_mem": f"{vs.name}.tables.mem" if vs.tables else None,
            # words per table when every table of the set has the same length (aux_gen 0: 48), else None
            # (the aux set: each table's length is its word 2 and the length of its manifest entry)
            "table_words": (len(vs.tables[0].to_words())
                            if vs.tables and len({len(t.to_words()) for t in vs.tables}) == 1 else None),
            "table_offsets": _offsets(vs.tables),
            "op_codes": list(PRIM_OPS) if vs.name == "primitives" else None,
            "cases": vs.cases,
            "tables": [_table_entry(t) for t in vs.tables],
        } for vs in sets},
        "files": {name: {"sha256": sha256_of(data), "bytes": len(data)} for name, data in sorted(files.items())},
    }


def dump_manifest(manifest: dict) -> bytes:
    return (json.dumps(manifest, indent=1, sort_keys=True) + "\n").encode()


def render_all(sets, config) -> dict:
    """file name -> bytes, manifest.json included."""
    files = {}
    for vs in sets:
        files.update(vs.files())
    files["manifest.json"] = dump_manifest(make_manifest(sets, config, files))
    return files


MAX_MANIFEST_BYTES = 64 << 20       # the committed manifest is ~0.5 MB
_HEX64 = re.compile(r"[0-9a-f]{64}")
_HEX8 = re.compile(r"[0-9a-fA-F]{8}")


def read_manifest(directory) -> dict:
    """The checked ``manifest.json`` of ``directory``: VectorsError (naming the file and the field)
    for a file that is not a regular file or is over 64 MiB, not JSON, a repeated key, nesting too
    deep, another format or version, or a field of the wrong type or range (a file name that leaves
    the directory, a case whose rows or table are outside its set)."""
    from host_tools.jsonread import InputFileError, read_json

    path = Path(directory) / "manifest.json"
    if not path.is_file():
        raise VectorsError(f"{path}: no manifest (generate the vectors with `hdrg vectors generate -o DIR`)")
    try:
        m = read_json(path, "vectors manifest", MAX_MANIFEST_BYTES, max_depth=32)
    except InputFileError as exc:
        raise VectorsError(str(exc)) from None
    if not isinstance(m, dict):
        raise VectorsError(f"{path}: not an hdrg vectors manifest (the top level is {type(m).__name__}, not an object)")
    if m.get("format") != "hdrg-vectors":
        raise VectorsError(f"{path}: format {m.get('format')!r} is not 'hdrg-vectors'")
    if m.get("format_version") != FORMAT_VERSION or isinstance(m.get("format_version"), bool):
        raise VectorsError(f"{path}: format_version {m.get('format_version')!r} is not supported (this reads "
                           f"{FORMAT_VERSION})")
    _check_manifest(m, str(path))
    return m


def _check_manifest(m: dict, src: str) -> None:
    """The types and ranges the readers of the manifest rely on (see :func:`read_manifest`)."""
    def need(cond, fld, what):
        if not cond:
            raise VectorsError(f"{src}: field '{fld}': {what}")

    def is_int(v, lo=0):
        return isinstance(v, int) and not isinstance(v, bool) and v >= lo

    def is_name(v):
        return isinstance(v, str) and v != "" and "/" not in v and "\\" not in v and not v.startswith(".")

    def str_list(v):
        return isinstance(v, list) and all(isinstance(x, str) for x in v)

    files = m.get("files")
    need(isinstance(files, dict), "files", "must be an object (file name -> sha256, bytes)")
    for name, meta in files.items():
        need(is_name(name), f"files.{name}", "a file name in the vectors directory (no '/', not hidden)")
        need(isinstance(meta, dict) and isinstance(meta.get("sha256"), str) and _HEX64.fullmatch(meta["sha256"])
             and is_int(meta.get("bytes")), f"files.{name}", "must be an object with sha256 (64 hex digits) and "
             "bytes (an integer >= 0)")
    for key in ("sources",):
        if key in m:
            need(isinstance(m[key], dict) and all(isinstance(v, str) for v in m[key].values()), key,
                 "must be an object of path -> sha256")
    if "sources_sha256" in m:
        need(isinstance(m["sources_sha256"], str), "sources_sha256", "must be a string")
    sets = m.get("sets")
    need(isinstance(sets, dict), "sets", "must be an object (set name -> description)")
    for name, meta in sets.items():
        at = f"sets.{name}"
        need(isinstance(meta, dict), at, "must be an object")
        need(isinstance(meta.get("description", ""), str), f"{at}.description", "must be a string")
        need(is_int(meta.get("rows")), f"{at}.rows", "must be an integer >= 0")
        for key in ("csv", "mem"):
            need(is_name(meta.get(key)) and meta[key] in files, f"{at}.{key}", "must name a file of 'files'")
        tm = meta.get("tables_mem")
        need(tm is None or (is_name(tm) and tm in files), f"{at}.tables_mem", "must be null or name a file of 'files'")
        need(str_list(meta.get("columns")), f"{at}.columns", "must be a list of column names")
        need(str_list(meta.get("inputs")) and set(meta["inputs"]) <= set(meta["columns"]), f"{at}.inputs",
             "must be a list of names of 'columns'")
        rec = meta.get("mem_record")
        need(isinstance(rec, list) and all(isinstance(f, dict) and isinstance(f.get("name"), str)
                                           and is_int(f.get("bits"), 4) and f["bits"] % 4 == 0 and f["bits"] <= 64
                                           for f in rec), f"{at}.mem_record",
             "must be a list of {name, bits (4..64, a multiple of 4)}")
        tables = meta.get("tables", [])
        need(isinstance(tables, list) and all(isinstance(t, dict) and isinstance(t.get("words"), list)
                                              and all(isinstance(w, str) and _HEX8.fullmatch(w) for w in t["words"])
                                              for t in tables), f"{at}.tables",
             "must be a list of {words: [8-digit hex words]}")
        need(tm is not None or not tables, f"{at}.tables_mem", "missing, but the set has tables")
        cases = meta.get("cases", [])
        need(isinstance(cases, list), f"{at}.cases", "must be a list")
        for k, case in enumerate(cases):
            cat = f"{at}.cases[{k}]"
            need(isinstance(case, dict), cat, "must be an object")
            need(isinstance(case.get("name", ""), str), f"{cat}.name", "must be a string")
            rows = case.get("rows")
            need(rows is None and not tables or (isinstance(rows, list) and len(rows) == 2 and all(is_int(r) for r in rows)
                                                 and rows[0] <= rows[1] <= meta["rows"]), f"{cat}.rows",
                 f"must be [first, end] with 0 <= first <= end <= {meta['rows']} (the set's rows)")
            if tables or "table" in case:
                need(is_int(case.get("table")) and case["table"] < len(tables), f"{cat}.table",
                     f"must be a table index 0..{len(tables) - 1}")
