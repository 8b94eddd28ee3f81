"""The vector file formats and the manifest: CSV, ``$readmemh`` records, table files, the source
fingerprint, ``manifest.json`` (no timestamps; SHA-256 of every file).
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np

from firmware_ref.table import Table
from host_tools.vectors.spec import FORMAT_VERSION, GENERATOR_VERSION, PRIM_OPS, ROOT, SOURCE_GLOBS, VectorsError


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def source_fingerprint(root: Path = ROOT) -> dict:
    """SHA-256 of every algorithm source (SOURCE_GLOBS, CRLF normalized to LF) and of their
    concatenated digests: ``{"sha256": ..., "files": {path: sha256}}``."""
    files = {}
    for pattern in SOURCE_GLOBS:
        for path in sorted(root.glob(pattern)):
            files[path.relative_to(root).as_posix()] = _sha256(path.read_bytes().replace(b"\r\n", b"\n"))
    files = dict(sorted(files.items()))
    total = _sha256("".join(f"{k} {v}\n" for k, v in files.items()).encode())
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
        "files": {name: {"sha256": _sha256(data), "bytes": len(data)} for name, data in sorted(files.items())},
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


def read_manifest(directory) -> dict:
    path = Path(directory) / "manifest.json"
    if not path.is_file():
        raise VectorsError(f"{path}: no manifest (generate the vectors with `hdrg vectors generate -o DIR`)")
    try:
        m = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise VectorsError(f"{path}: not JSON ({exc})") from None
    if m.get("format") != "hdrg-vectors":
        raise VectorsError(f"{path}: format {m.get('format')!r} is not 'hdrg-vectors'")
    if m.get("format_version") != FORMAT_VERSION:
        raise VectorsError(f"{path}: format_version {m.get('format_version')} is not supported (this reads "
                           f"{FORMAT_VERSION})")
    return m
