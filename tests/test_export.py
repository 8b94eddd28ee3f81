"""`hdrg export`: the C header, the JSON and the $readmemh file hold the same layout words as the
table (and as each other), their CRC matches zlib's, the JSON keeps the float originals, and the C
twin runs with the exported header compiled in (bit-identical to the numba kernel)."""
import argparse
import json
import struct
import subprocess
import zlib

import numpy as np
import pytest

from firmware_ref import table as T
from firmware_ref.table import MAGIC, Table, TableError
from host_tools.vectors.builders import make_model, random_model, random_stream
from host_tools.fixed import export as ex
from host_tools.cli import export as export_cmd
from host_tools.fixed.quantize import quantize, read_table
from test_c_twin import C_DIR, CFLAGS, GCC, assert_same, build, kernel, run_bin, run_text

needs_gcc = pytest.mark.skipif(GCC is None, reason="gcc not found on PATH: the C twin cannot be built")


@pytest.fixture(scope="module")
def quantized():
    return quantize(random_model(np.random.default_rng(21), estimator="lsq"), exchange_s=3.0, dwell_s=7.0,
                    n_random=20)


@pytest.fixture(scope="module")
def table_json(quantized, tmp_path_factory):
    path = tmp_path_factory.mktemp("export") / "table.json"
    quantized.to_json(path)
    return path


def cli(argv):
    parser = argparse.ArgumentParser()
    export_cmd.configure(parser)
    return export_cmd.run(parser.parse_args(argv))


def test_three_exports_hold_the_same_words(quantized, table_json, tmp_path, capsys):
    assert cli([str(table_json), "--format", "all", "-o", str(tmp_path / "out")]) == 0
    assert "CRC-32" in capsys.readouterr().out
    words = quantized.table.to_words()
    crc = zlib.crc32(struct.pack(f"<{len(words) - 1}I", *words[:-1])) & 0xFFFFFFFF
    assert words[-1] == crc
    header = (tmp_path / "out" / "hdrg_table.h").read_text()
    memh = (tmp_path / "out" / "hdrg_table.memh").read_text()
    js = json.loads((tmp_path / "out" / "hdrg_table.json").read_text())
    assert ex.decode_c_header(header) == words
    assert [int(line, 16) for line in memh.split()] == words
    assert all(len(line) == 8 for line in memh.splitlines()) and len(memh.splitlines()) == len(words)
    assert [int(w, 16) for w in js["words"]] == words
    assert f"#define HDRG_TABLE_CRC32 0x{crc:08x}u" in header
    assert f"#define HDRG_TABLE_MAGIC 0x{MAGIC:08x}u" in header and f"#define HDRG_TABLE_LAYOUT_VERSION {T.VERSION}u" in header
    assert f"#define HDRG_TABLE_WORDS {len(words)}u" in header
    assert js["crc32"] == f"0x{crc:08x}" and js["layout_version"] == T.VERSION
    # each decodes to the same table through the readers
    assert read_table(tmp_path / "out" / "hdrg_table.json") == quantized.table
    assert read_table(tmp_path / "out" / "hdrg_table.memh") == quantized.table
    assert Table.from_memh(memh) == quantized.table
    # the float originals
    np.testing.assert_array_equal(js["coef_dph"], quantized.model.coef)
    assert js["model"] == quantized.model.to_dict()
    assert len(js["layout"]) == len(words) and js["layout"][-1]["field"] == "crc32"
    k0 = float(quantized.model.coef[0])
    assert f"(float {k0:.9g})" in header


def test_single_formats_and_name(table_json, tmp_path):
    assert cli([str(table_json), "--format", "mem", "-o", str(tmp_path), "--name", "gyro_a"]) == 0
    assert [p.name for p in tmp_path.iterdir()] == ["gyro_a.memh"]
    assert cli([str(table_json), "--format", "c", "-o", str(tmp_path), "--name", "gyro_a"]) == 0
    text = (tmp_path / "gyro_a.h").read_text()
    assert "static const uint32_t GYRO_A[GYRO_A_WORDS]" in text
    assert ex.decode_c_header(text, "gyro_a") == read_table(table_json).to_words()
    with pytest.raises(ValueError, match="C identifier"):
        cli([str(table_json), "-o", str(tmp_path), "--name", "3bad-name"])
    with pytest.raises(ValueError, match="unknown export format"):
        ex.export(read_table(table_json), tmp_path, ("verilog",))


def test_from_memh_and_bin_sources(quantized, tmp_path):
    """A table without its float model (.memh, .bin) exports too; the JSON then has no model."""
    t = quantized.table
    (tmp_path / "t.memh").write_text(t.to_memh())
    (tmp_path / "t.bin").write_bytes(t.to_bytes())
    for src in ("t.memh", "t.bin"):
        out = tmp_path / src.replace(".", "_")
        assert cli([str(tmp_path / src), "-o", str(out)]) == 0
        js = json.loads((out / "hdrg_table.json").read_text())
        assert js["model"] is None and js["coef_dph"] is None
        assert read_table(out / "hdrg_table.json") == t
        assert ex.decode_c_header((out / "hdrg_table.h").read_text()) == t.to_words()


def test_corrupted_source_is_refused(table_json, tmp_path):
    d = json.loads(table_json.read_text())
    d["words"][-1] = f"0x{int(d['words'][-1], 16) ^ 1:08x}"
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(d))
    with pytest.raises(TableError, match="bad.json: CRC-32 mismatch"):
        cli([str(bad), "-o", str(tmp_path / "out")])
    assert not (tmp_path / "out").exists()


def test_cli_registry(table_json, tmp_path):
    from host_tools.cli import COMMANDS, main

    if "export" not in COMMANDS:
        pytest.skip("host_tools.cli has no 'export' entry yet (the lead adds it)")
    assert main(["export", str(table_json), "--format", "all", "-o", str(tmp_path)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hdrg_table.h", "hdrg_table.json", "hdrg_table.memh"]


TINY = r"""
#include <stdio.h>
#include "hdrg_fw.h"
#include "hdrg_table.h"

static hdrg_state_t st;

int main(void)
{
    unsigned bad = 0;
    int e = hdrg_init(&st, HDRG_TABLE, HDRG_TABLE_WORDS, &bad);
    hdrg_input_t in = {0, 0, 1024, 0, -1, 1, 0};
    hdrg_sample_t o;
    if (e != HDRG_OK) {
        printf("init %s word %u\n", hdrg_error_name(e), bad);
        return 1;
    }
    if (hdrg_crc32_words(HDRG_TABLE, HDRG_TABLE_WORDS - 1u) != HDRG_TABLE_CRC32 || st.t.crc != HDRG_TABLE_CRC32
        || HDRG_TABLE[0] != HDRG_TABLE_MAGIC || HDRG_TABLE_MAGIC != HDRG_MAGIC
        || HDRG_TABLE_LAYOUT_VERSION != HDRG_LAYOUT_VERSION) {
        printf("crc/magic/version mismatch\n");
        return 1;
    }
    hdrg_step(&st, &in, &o);
    printf("ok %u %08lx\n", (unsigned)HDRG_TABLE_WORDS, (unsigned long)HDRG_TABLE_CRC32);
    return 0;
}
"""


@needs_gcc
def test_c_program_includes_the_header(quantized, table_json, tmp_path):
    """A tiny C99 program including hdrg_fw.h and the exported header loads the table (CRC
    computed in C == the #define), and the driver built with -DHDRG_TABLE_HEADER runs the
    compiled-in table (`TABLE BUILTIN`) bit-identically to the numba kernel."""
    out = tmp_path / "exp"
    cli([str(table_json), "--format", "c", "-o", str(out)])
    (tmp_path / "tiny.c").write_text(TINY)
    exe = build(tmp_path, "tiny", CFLAGS, include=(out, C_DIR), sources=(tmp_path / "tiny.c", C_DIR / "hdrg_fw.c"))
    pr = subprocess.run([str(exe)], capture_output=True, text=True)
    t = quantized.table
    assert pr.returncode == 0 and pr.stdout == f"ok {len(t.to_words())} {t.crc:08x}\n", pr.stdout
    drv = build(tmp_path, "hdrg_fw_builtin", CFLAGS, defines=('HDRG_TABLE_HEADER="hdrg_table.h"',), include=(out,))
    assert run_text(drv, ["TABLE BUILTIN"]) == [f"T {len(t.to_words())} {t.crc:08x}"]
    s = random_stream(np.random.default_rng(5), t, 5000)
    from test_c_twin import FIELDS, input_records
    rec = input_records(t, s)
    lines = ["TABLE BUILTIN"] + ["S " + " ".join(map(str, row)) for row in rec.tolist()]
    resp = run_text(drv, lines)
    arr = np.array([line.split()[1:] for line in resp[1:]], np.int64)
    assert_same(kernel(t, s), {name: arr[:, c] for c, name in enumerate(FIELDS)}, what="builtin table")
    # and the same as loading the words over the protocol
    got = run_bin(drv, t, s)
    assert_same(kernel(t, s), got, what="TABLE words")


@needs_gcc
def test_every_export_loads_in_c(quantized, table_json, tmp_path):
    """The words of each export (header, JSON, memh) load in the C twin with the same CRC."""
    out = tmp_path / "exp"
    cli([str(table_json), "-o", str(out)])
    drv = build(tmp_path, "hdrg_fw", CFLAGS)
    lists = {"c": ex.decode_c_header((out / "hdrg_table.h").read_text()),
             "json": [int(w, 16) for w in json.loads((out / "hdrg_table.json").read_text())["words"]],
             "mem": [int(w, 16) for w in (out / "hdrg_table.memh").read_text().split()]}
    resp = run_text(drv, ["TABLE " + " ".join(f"{w:08x}" for w in ws) for ws in lists.values()])
    assert resp == [f"T 73 {quantized.table.crc:08x}"] * 3


def test_header_for_another_model(tmp_path):
    """Header comments name the quantized and the float coefficient of every term."""
    q = quantize(make_model(), n_random=10)
    text = ex.c_header(q.table, "hdrg_table", q.to_dict())
    for k in range(17):
        assert f" m_{k} " in text
    assert "k1 (u) = m 2^-" in text and "(float -4)" in text


def test_two_bank_exports(tmp_path):
    """A regress_first model: the three exports hold the v2 words (order 1, two banks), the header
    comments bank 2's coefficients with their float originals, the JSON carries both banks'
    quantized coefficients, and every export reads back to the same table; a version-1 .memh
    (one bank) exports as version 2 with the same fields."""
    model = make_model(combiner="none", order="regress_first")
    q = quantize(model, n_random=10)
    q.to_json(tmp_path / "t.json")
    cli([str(tmp_path / "t.json"), "-o", str(tmp_path / "exp")])
    text = (tmp_path / "exp" / "hdrg_table.h").read_text()
    assert "Order 1 (regress_first), 2 coefficient bank(s), combiner 3 (none)" in text
    assert " m2_1 " in text and "(bank 2) (float 4)" in text          # k1 of bank 2 is -(-4)
    js = json.loads((tmp_path / "exp" / "hdrg_table.json").read_text())
    assert js["fields"]["order"] == 1 and js["fields"]["n_banks"] == 2 and js["coef_mode2_dph"][1] == 4.0
    assert js["coef_quantized_mode2_dph"][1] == pytest.approx(4.0, abs=1e-6)
    t = read_table(tmp_path / "exp" / "hdrg_table.json")
    assert t == q.table == read_table(tmp_path / "exp" / "hdrg_table.memh")
    assert ex.decode_c_header(text) == t.to_words()
    from firmware_ref.table import N_FIXED, N_FIXED_V1, crc32_words
    one = quantize(make_model(kind="temp", ref=20.0, span=40.0, rate_span=0.5), n_random=10).table
    w = one.to_words()
    v1 = [w[0], 1, N_FIXED_V1 + 1] + w[3:N_FIXED_V1]
    (tmp_path / "old.memh").write_text("".join(f"{x:08x}\n" for x in v1 + [crc32_words(v1)]))
    cli([str(tmp_path / "old.memh"), "--format", "mem", "-o", str(tmp_path / "exp1")])
    words = [int(x, 16) for x in (tmp_path / "exp1" / "hdrg_table.memh").read_text().split()]
    assert words[1] == T.VERSION and len(words) == N_FIXED + 1 and Table.from_words(words) == one
