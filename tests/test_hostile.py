"""Hostile inputs and hostile machines: what leaves hdrg is escaped, outputs never destroy each
other or an existing file, the tool runs for any user, the JSON readers are bounded and typed
(with fuzz tests), check-impl's children are bounded, special files are refused.

Each test names the case it pins: before the change it was a silent wrong result, a traceback,
a destroyed file or a hang; now it is a clear error or a correct result.
"""
from __future__ import annotations

import json
import os
import pwd
import re
import shutil
import stat
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from host_tools import cli
from host_tools.vectors.builders import make_model

ROOT = Path(__file__).resolve().parent.parent
GCC = shutil.which("gcc")
needs_gcc = pytest.mark.skipif(GCC is None, reason="gcc not found on PATH: the header cannot be compiled")
FUZZ = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def hdrg(*argv) -> int:
    return cli.main([str(a) for a in argv])


def small_run(path, n=400, fs=1.0, model=None):
    """An FTR run log (t_s, freq_hz, rate_dph) inside ``model``'s proxy range, written to ``path``."""
    from host_tools.golden import runlog as rl
    t = np.arange(n) / fs
    freq = 6227.0 + 1.0 * np.sin(2 * np.pi * t / 300.0)
    rate = 3.0 + 0.01 * np.cos(2 * np.pi * t / 50.0)
    log = rl.RunLog.from_arrays({"sample_rate_hz": f"{fs:g}"}, str(path), t_s=t, freq_hz=freq, rate_dph=rate)
    rl.write(log, path)
    return path


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("model") / "model.json"
    make_model(combiner=None).to_json(path)
    return path


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    return small_run(tmp_path_factory.mktemp("run") / "run.csv")


# == escaping: C header ==============================================================================

HOSTILE_SOURCE = 'x */\n#include "/etc/passwd"\nint x = 1;\n/* \\\n??/\n\x1b[31m\u00e9 */ int y;'


def _macros(cfile: Path, include_dir: Path) -> set:
    out = subprocess.run([GCC, "-std=c99", "-E", "-dM", "-I", str(include_dir), str(cfile)], capture_output=True,
                         text=True, check=True).stdout
    return {line.split()[1].split("(")[0] for line in out.splitlines() if line.startswith("#define ")}


def _header_defines_only_the_table(header: Path, sym: str, tmp: Path) -> None:
    """gcc -Wall -Werror compiles the header; it adds exactly the include guard and four macros to
    what <stdint.h> defines, and the object defines the array (and our probe) alone; a translation
    unit that defines ``x`` and ``y`` itself still compiles (the header defined neither)."""
    base = tmp / "base.c"
    base.write_text("#include <stdint.h>\n")
    tu = tmp / "tu.c"
    tu.write_text(f'#include "{header.name}"\nint x = 2;\nint y = 3;\n'
                  f"const uint32_t *probe(void) {{ return {sym}; }}\n")
    r = subprocess.run([GCC, "-std=c99", "-Wall", "-Wextra", "-Werror", "-c", "-I", str(header.parent), str(tu),
                        "-o", str(tmp / "tu.o")], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    added = _macros(tu, header.parent) - _macros(base, header.parent)
    assert added == {f"{sym}_H_INCLUDED", f"{sym}_MAGIC", f"{sym}_LAYOUT_VERSION", f"{sym}_WORDS", f"{sym}_CRC32"}
    nm = shutil.which("nm")
    if nm:
        syms = subprocess.run([nm, str(tmp / "tu.o")], capture_output=True, text=True, check=True).stdout.split("\n")
        defined = {line.split()[-1] for line in syms if line.strip() and line.split()[-2] not in ("U", "u")}
        assert defined <= {sym, "probe", "x", "y"} and {"probe", "x", "y"} <= defined, defined


@needs_gcc
def test_header_from_a_hostile_model_file_name_defines_only_the_table(tmp_path, capsys):
    """Case: a model file named `evil*/ int x = 1; /*.json` put live C into the exported header."""
    d = tmp_path / "evil*" / " int x = 1; "
    d.mkdir(parents=True)
    model = d / "*.json"
    make_model(combiner=None).to_json(model)
    weird = tmp_path / 'nl\n#include "passwd"\n#define y 1\n.json'
    make_model(combiner=None).to_json(weird)
    for k, src in enumerate((model, weird)):
        out = tmp_path / f"h{k}"
        out.mkdir()
        assert hdrg("quantize", src, "-o", out / "t.json", "--header", out / "hdrg_table.h") == 0
        text = (out / "hdrg_table.h").read_text()
        code = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)         # what the compiler reads
        assert "int x" not in code and "passwd" not in code and "#define y" not in code
        assert [m.strip() for m in re.findall(r"^[ \t]*#[ \t]*include.*$", code, re.M)] == ["#include <stdint.h>"]
        _header_defines_only_the_table(out / "hdrg_table.h", "HDRG_TABLE", out)
    capsys.readouterr()


@needs_gcc
def test_header_from_a_hostile_table_json_defines_only_the_table(tmp_path, model_file, capsys):
    """Case: a table whose model_source holds a newline and `*/` (and an #include) was compiled by gcc."""
    assert hdrg("quantize", model_file, "-o", tmp_path / "t.json") == 0
    d = json.loads((tmp_path / "t.json").read_text())
    d["model_source"] = HOSTILE_SOURCE
    (tmp_path / "evil.json").write_text(json.dumps(d))
    out = tmp_path / "out"
    assert hdrg("export", tmp_path / "evil.json", "--format", "c", "-o", out, "--name", "fw_tab") == 0
    header = out / "fw_tab.h"
    text = header.read_text()
    assert text.isascii() and "\x1b" not in text and "??" not in text
    comment = next(line for line in text.splitlines() if "Generated by" in line)
    assert "\\n#include" in comment and comment.count("*/") == 0      # quoted on one line, cannot close
    _header_defines_only_the_table(header, "FW_TAB", out)
    capsys.readouterr()


def test_comment_text_and_names():
    from host_tools.fixed.export import check_name, comment_text
    for s in (HOSTILE_SOURCE, "*/*/", "/*", "a*" * 300 + "/", "\u2028x\u2029", "??=??/"):
        c = comment_text(s)
        assert c.isascii() and "*/" not in c and "/*" not in c and "??" not in c and "\n" not in c
        assert all(" " <= ch <= "~" for ch in c) and len(c) <= 200
    assert comment_text("model.json") == "model.json"
    for bad in ("int x", "evil*/", "_x", "__x", "uint32_max", "INT8_C", "9a", "", "a" * 64, "x\n"):
        with pytest.raises(ValueError, match="--name"):
            check_name(bad)
    assert check_name("hdrg_table") == "hdrg_table" and check_name("a" * 63)


def test_table_json_with_a_wrong_type_in_a_float_original_is_refused(tmp_path, model_file, capsys):
    """Case (traceback before): coef_dph an object or a string in a table.json fed to export."""
    assert hdrg("quantize", model_file, "-o", tmp_path / "t.json") == 0
    d = json.loads((tmp_path / "t.json").read_text())
    for key, value in (("coef_dph", {"a": 1}), ("coef_dph", "1, 2"), ("model_source", 5), ("fields", [1])):
        bad = dict(d, **{key: value})
        (tmp_path / "bad.json").write_text(json.dumps(bad))
        assert hdrg("export", tmp_path / "bad.json", "-o", tmp_path / "o") == 2
        err = capsys.readouterr().err
        assert f"field '{key}'" in err and "bad.json" in err and "Traceback" not in err


# == escaping: report.md =============================================================================

def test_markdown_cells_and_notes_are_escaped(tmp_path, model_file, capsys):
    """Case: run names with `|`, HTML or newlines injected rows and markup into report.md."""
    from host_tools.fitting.report import markdown_table, md_text
    from host_tools.golden import runlog as rl
    from host_tools.golden.model import BiasModel
    from host_tools.fitting.report import report

    name = 'a|b\n| forged | row |\n<img src=x onerror=alert(1)>[x](javascript:y)`c`.csv'
    assert "\n" not in md_text(name) and "<" not in md_text(name)
    assert md_text("a|b") == "a\\|b" and md_text("x\\|y") == "x\\\\\\|y" and md_text("model (8 of 17 terms)") == \
        "model (8 of 17 terms)"
    table = markdown_table([{"run": name, "output": "o|p", "std1_dph": 1.0, "pp1_dph": 2.0, "std100_dph": None,
                     "pp100_dph": None}])
    lines = table.splitlines()
    assert len(lines) == 3
    cells = re.split(r"(?<!\\)\|", lines[2])
    assert len(cells) == 8          # 6 cells between 7 unescaped bars
    # end to end: a run whose file name is hostile
    path = tmp_path / name
    small_run(path)
    log = rl.read(path)
    doc = report([log], BiasModel.from_json(model_file), tmp_path / "rep", plots=False)
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "<img" not in md and "| forged |" not in md
    rows = [line for line in md.splitlines() if line.startswith("|")]
    assert len(rows) == 2 + len(doc["rows"])
    assert all(len(re.split(r"(?<!\\)\|", r)) == 8 for r in rows[2:])
    capsys.readouterr()


# == escaping: capture files and CSV metadata =========================================================

def _stream(name: str, n: int, ended: bool = True) -> bytes:
    from host_tools.link.codec import ST_RUN_ENDED, DeviceInfo, pack_sample
    from host_tools.link.frame import T_INFO, T_SAMPLE, encode_frame
    frames = [encode_frame(T_INFO, 0, DeviceInfo(name=name, boot_id=7).pack())]
    frames += [encode_frame(T_SAMPLE, 1 + i, pack_sample(i, 6227 << 16, 1000 + i, 25 << 8, 0, 0, 0, 0, 0, 1))
               for i in range(n)]
    if ended:
        frames.append(encode_frame(T_INFO, n + 1, DeviceInfo(name=name, boot_id=7, status=ST_RUN_ENDED).pack()))
    return b"".join(frames)


def _capture(stream: bytes, path, **kw):
    from host_tools.link.capture import capture
    from host_tools.link.host import open_port
    port = open_port("loop://")
    port.write(stream)
    try:
        return capture(port, path, idle_timeout_s=kw.pop("idle_timeout_s", 1.0), **kw)
    finally:
        port.close()


def test_a_device_name_with_newlines_cannot_forge_rows_or_metadata(tmp_path):
    """Case: a device name with newlines forged rows in a capture file."""
    from host_tools.golden import runlog as rl
    evil = "dev\n# reversal: on\nt_s,freq_hz,rate_dph\n0,1,2\n"
    res = _capture(_stream(evil, 5), tmp_path / "cap.csv")
    assert res.samples == 5 and res.written
    log = rl.read(tmp_path / "cap.csv")
    assert len(log) == 5 and log.metadata["device"] == "dev\\n# reversal_ on\\nt_s,freq_hz,rate_dph\\n0,1,2\\n" \
        .replace("_ on", ": on")
    assert "reversal" not in log.metadata and log.metadata["capture"] == "complete"
    from host_tools.link.capture import meta_text
    assert meta_text("a\r\nb\x00c\u2028") == "a\\r\\nb\\x00c\\u2028" and meta_text("k:v", key=True) == "k_v"


def test_compensate_escapes_metadata_with_newlines_from_an_npz(tmp_path, model_file, capsys):
    """Case: NPZ metadata with newlines gave a CSV hdrg could not read back."""
    from host_tools.golden import runlog as rl
    small_run(tmp_path / "r.csv")
    log = rl.read(tmp_path / "r.csv")
    log.metadata["operator"] = "me\nt_s,freq_hz\n1,2"
    rl.write(log, tmp_path / "r.npz")
    assert hdrg("compensate", tmp_path / "r.npz", "--model", model_file, "-o", tmp_path / "o.csv") == 0
    back = rl.read(tmp_path / "o.csv")
    assert len(back) == len(log) and back.metadata["operator"] == "me\\nt_s,freq_hz\\n1,2"
    capsys.readouterr()


# == outputs never destroy each other or an existing file =============================================

@pytest.mark.parametrize("opts", [("-o", "--header"), ("--memh", "--bin"), ("-o", "--bin"), ("--memh", "--header")])
def test_quantize_refuses_two_outputs_on_one_file(tmp_path, model_file, capsys, opts):
    """Case: `hdrg quantize -o X --header X` (or --memh X --bin X) overwrote one output with another, exit 0."""
    target = tmp_path / "x.out"
    target.write_text("keep")
    argv = ["quantize", model_file] + (["-o", tmp_path / "t.json"] if "-o" not in opts else [])
    for o in opts:
        argv += [o, target]
    assert hdrg(*argv) == 2
    err = capsys.readouterr().err
    assert f"{opts[0]} {target} and {opts[1]} {target} are the same file" in err
    assert target.read_text() == "keep" and not (tmp_path / "t.json").exists()
    # the same file through a symlink and through another spelling of the path
    link = tmp_path / "link.h"
    link.symlink_to(target)
    assert hdrg("quantize", model_file, "-o", target, "--header", link) == 2
    assert hdrg("quantize", model_file, "-o", tmp_path / "new.json", "--header", tmp_path / "." / "new.json") == 2
    assert "same file" in capsys.readouterr().err and target.read_text() == "keep"


def test_export_refuses_outputs_that_resolve_to_one_file(tmp_path, model_file, capsys):
    assert hdrg("quantize", model_file, "-o", tmp_path / "t.json") == 0
    out = tmp_path / "out"
    out.mkdir()
    (out / "hdrg_table.json").write_text("keep")
    (out / "hdrg_table.h").symlink_to(out / "hdrg_table.json")
    assert hdrg("export", tmp_path / "t.json", "-o", out) == 2
    assert "are the same file" in capsys.readouterr().err and (out / "hdrg_table.json").read_text() == "keep"


def test_a_capture_that_records_nothing_leaves_an_existing_file(tmp_path):
    """Case: `hdrg capture` from a device whose run has ended replaced an existing file by a 0-byte file."""
    path = tmp_path / "old.csv"
    path.write_text("precious\n")
    res = _capture(_stream("dev", 0), path)
    assert res.samples == 0 and not res.written and "end of its run" in res.reason
    assert path.read_text() == "precious\n" and "left as it was" in res.summary()
    # a device that sends nothing at all (idle timeout)
    res = _capture(b"", path, idle_timeout_s=0.3)
    assert not res.written and path.read_text() == "precious\n"
    # it is replaced once a sample is recorded
    res = _capture(_stream("dev", 3), path)
    assert res.written and res.samples == 3 and "precious" not in path.read_text()


@pytest.mark.parametrize("option,value", [("--duration", "-5"), ("--duration", "nan"), ("--duration", "inf"),
                                          ("--duration", "0"), ("--idle-timeout", "-1"), ("--idle-timeout", "nan"),
                                          ("--idle-timeout", "1e300")])
def test_capture_durations_are_validated(tmp_path, capsys, option, value):
    """Case: `--duration -5` wrote a 0-byte file; `--duration nan` was accepted and ignored;
    `--idle-timeout -1` waited forever on a silent port."""
    path = tmp_path / "keep.csv"
    path.write_text("keep")
    with pytest.raises(SystemExit) as exc:
        hdrg("capture", "--port", "loop://", "-o", path, option, value)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"{option} {value}" in err and "must be a number of seconds in (0, " in err
    assert path.read_text() == "keep"


def test_capture_idle_timeout_zero_means_never_and_the_library_checks_its_limits(tmp_path):
    import argparse
    from host_tools.cli import capture as capture_cmd
    from host_tools.link.capture import check_limits
    p = argparse.ArgumentParser()
    capture_cmd.configure(p)
    assert p.parse_args(["--port", "x", "-o", "y", "--idle-timeout", "0"]).idle_timeout == 0.0
    assert "0: never stop for silence" in " ".join(p.format_help().split())
    for kw in ({"duration_s": -5.0}, {"duration_s": float("nan")}, {"idle_timeout_s": float("inf")},
               {"idle_timeout_s": 0.0}, {"max_samples": 0}):
        args = {"duration_s": None, "idle_timeout_s": None, **kw}
        with pytest.raises(ValueError, match="must be"):
            check_limits(args["duration_s"], args["idle_timeout_s"], args.get("max_samples"))
    path = tmp_path / "keep.csv"
    path.write_text("keep")
    with pytest.raises(ValueError, match="duration"):
        _capture(_stream("dev", 3), path, duration_s=-5.0)
    assert path.read_text() == "keep"


# == bounded, typed readers ============================================================================

def _nested(depth: int) -> str:
    return '{"format": "hdrg-model", "version": 2, "fit": ' + "[" * depth + "]" * depth + "}"


def test_model_reader_refuses_duplicates_depth_size_and_special_files(tmp_path, model_file):
    """Cases: a duplicated key in a model JSON silently replaced the first; a model nested 5,000
    deep was a RecursionError traceback."""
    from host_tools.golden.model import BiasModel, ModelError
    text = model_file.read_text()
    dup = text.replace('"terms":', '"terms": [0], "terms":', 1)
    (tmp_path / "dup.json").write_text(dup)
    with pytest.raises(ModelError, match=r"dup.json: duplicated key 'terms'"):
        BiasModel.from_json(tmp_path / "dup.json")
    for depth in (40, 5000, 200000):
        (tmp_path / "deep.json").write_text(_nested(depth))
        with pytest.raises(ModelError, match="deep.json: model file nested too deep"):
            BiasModel.from_json(tmp_path / "deep.json")
    big = tmp_path / "big.json"
    with open(big, "wb") as fh:
        fh.truncate((16 << 20) + 1)         # sparse: the size alone refuses it
    with pytest.raises(ModelError, match="limit"):
        BiasModel.from_json(big)
    (tmp_path / "top.json").write_text("[1, 2]")
    with pytest.raises(ModelError, match="top level is list"):
        BiasModel.from_json(tmp_path / "top.json")
    d = json.loads(text)
    d["fit"] = {"train": 5}
    (tmp_path / "train.json").write_text(json.dumps(d))
    with pytest.raises(ModelError, match="field 'fit.train': must be a list"):    # hdrg report read it
        BiasModel.from_json(tmp_path / "train.json")
    (tmp_path / "huge_int.json").write_text('{"format": "hdrg-model", "version": ' + "9" * 5000 + "}")
    with pytest.raises(ModelError, match="huge_int.json"):
        BiasModel.from_json(tmp_path / "huge_int.json")
    t0 = time.monotonic()
    with pytest.raises(ModelError, match="is a device, not a regular file"):
        BiasModel.from_json("/dev/zero")
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    with pytest.raises(ModelError, match="is a FIFO"):
        BiasModel.from_json(fifo)
    assert time.monotonic() - t0 < 5


def test_table_reader_refuses_duplicates_depth_and_wrong_types(tmp_path, model_file, capsys):
    from firmware_ref.table import TableError
    from host_tools.fixed.quantize import read_table
    assert hdrg("quantize", model_file, "-o", tmp_path / "t.json") == 0
    capsys.readouterr()
    text = (tmp_path / "t.json").read_text()
    d = json.loads(text)
    cases = {
        "dup": (text.replace('"crc32":', '"crc32": "0x0", "crc32":', 1), "duplicated key 'crc32'"),
        "deep": (text.rstrip()[:-1] + ', "x": ' + "[" * 3000 + "]" * 3000 + "}", "nested too deep"),
        "words_int": (json.dumps({**d, "words": 5}), "field 'words'"),
        "words_nums": (json.dumps({**d, "words": [1, 2]}), "field 'words'"),
        "fields_list": (json.dumps({**d, "fields": [1]}), "field 'fields'"),
        "top_list": ("[]", "not an hdrg table"),
        "version_bool": (json.dumps({**d, "version": True}), "version"),
    }
    for name, (body, match) in cases.items():
        (tmp_path / f"{name}.json").write_text(body)
        with pytest.raises(TableError, match=match):
            read_table(tmp_path / f"{name}.json")
    with pytest.raises(TableError, match="is a device"):
        read_table("/dev/zero")
    (tmp_path / "zero.bin").symlink_to("/dev/zero")        # the binary reader too
    with pytest.raises(TableError, match="is a device"):
        read_table(tmp_path / "zero.bin")


def _small_manifest() -> dict:
    from host_tools.vectors.files import read_manifest
    return read_manifest(ROOT / "vectors")


def test_manifest_reader_refuses_wrong_shapes(tmp_path):
    """Cases: a vectors manifest that is a list, or has `files` as an int, was a traceback."""
    from host_tools.vectors.files import read_manifest
    from host_tools.vectors.spec import VectorsError
    m = _small_manifest()
    name = next(n for n, s in m["sets"].items() if s.get("tables"))
    bad_case = json.loads(json.dumps(m))
    bad_case["sets"][name]["cases"][0]["table"] = 10 ** 6
    escape = json.loads(json.dumps(m))
    escape["files"]["../outside"] = {"sha256": "0" * 64, "bytes": 1}
    cases = [([], "top level is list"), ({**m, "files": 5}, "field 'files'"), ({**m, "sets": []}, "field 'sets'"),
             (bad_case, f"sets.{name}.cases\\[0\\].table"), (escape, "files.../outside"),
             ({**m, "format_version": True}, "format_version")]
    for doc, match in cases:
        (tmp_path / "manifest.json").write_text(json.dumps(doc))
        with pytest.raises(VectorsError, match=match):
            read_manifest(tmp_path)
    (tmp_path / "manifest.json").write_text('{"format": "hdrg-vectors", "format": "x"}')
    with pytest.raises(VectorsError, match="duplicated key 'format'"):
        read_manifest(tmp_path)


# -- fuzz: random bytes, JSON shapes, truncations, type swaps --------------------------------------------

JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-2 ** 70, 2 ** 70) | st.floats() | st.text(max_size=6),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner, max_size=3),
    max_leaves=8)


def _paths(doc, prefix=()):
    yield prefix
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc[:4]):
            yield from _paths(v, prefix + (i,))


def _swap(doc, path, value):
    if not path:
        return value
    doc = json.loads(json.dumps(doc))
    cur = doc
    for k in path[:-1]:
        cur = cur[k]
    cur[path[-1]] = value
    return doc


@st.composite
def hostile_texts(draw, valid_text: str):
    """Text of a hostile variant of a valid JSON document."""
    kind = draw(st.sampled_from(["bytes", "truncate", "swap", "shape", "dup"]))
    doc = json.loads(valid_text)
    if kind == "bytes":
        return draw(st.binary(max_size=300)).decode("latin-1")
    if kind == "truncate":
        return valid_text[:draw(st.integers(0, len(valid_text)))]
    if kind == "shape":
        return json.dumps(draw(JSON_VALUES))
    if kind == "dup":
        keys = [m.start() for m in re.finditer(r'"[a-z_0-9]+":', valid_text)]
        at = keys[draw(st.integers(0, len(keys) - 1))]
        key = re.match(r'"[a-z_0-9]+":', valid_text[at:]).group()
        return valid_text[:at] + key + json.dumps(draw(JSON_VALUES)) + ", " + valid_text[at:]
    paths = list(_paths(doc))
    path = paths[draw(st.integers(0, len(paths) - 1))]
    return json.dumps(_swap(doc, path, draw(JSON_VALUES)))


def _model_text() -> str:
    from host_tools.golden.regressors import AuxConfig
    from host_tools.golden.model import BiasModel
    m = make_model(order="regress_first")
    m.fit = {"rms": 1.0, "train": ["a.csv"]}
    d = m.to_dict()
    d["config"]["aux"] = AuxConfig("sum", {"fs": 1.0, "terms": [
        {"gen": "decay_on", "weight": -0.5, "tau_s": 30.0, "effect": "turn_on"}]}).to_dict()
    BiasModel.from_dict(d)
    return json.dumps(d)


MODEL_TEXT = _model_text()


@FUZZ
@given(text=hostile_texts(MODEL_TEXT))
def test_fuzz_model_reader(tmp_path, text):
    from host_tools.golden.model import BiasModel, ModelError
    path = tmp_path / "fuzz_model.json"
    path.write_bytes(text.encode("utf-8", "surrogatepass"))
    try:
        m = BiasModel.from_json(path)
    except ModelError as exc:
        assert str(exc).startswith(str(path))
        return
    assert isinstance(m.coef, np.ndarray) and m.coef.shape == (17,) and np.isfinite(m.coef).all()


@pytest.fixture(scope="module")
def table_text(tmp_path_factory, model_file):
    path = tmp_path_factory.mktemp("tab") / "t.json"
    from host_tools.fixed.quantize import quantize
    from host_tools.golden.model import BiasModel
    quantize(BiasModel.from_json(model_file), n_random=20).to_json(path)
    return path.read_text()


@FUZZ
@given(data=st.data())
def test_fuzz_table_reader_and_export(tmp_path, table_text, data):
    from firmware_ref.table import TableError
    from host_tools.fixed.export import c_header, json_dict
    from host_tools.fixed.quantize import read_table_json
    text = data.draw(hostile_texts(table_text))
    path = tmp_path / "fuzz_table.json"
    path.write_bytes(text.encode("utf-8", "surrogatepass"))
    try:
        table, info = read_table_json(path)
    except TableError as exc:
        assert str(exc).startswith(str(path))
        return
    header = c_header(table, info=info)             # the float originals reach the header's comments
    assert header.isascii() and len(re.findall(r"\*/", header)) == header.count("/*")
    json.dumps(json_dict(table, info))


@pytest.fixture(scope="module")
def manifest_text():
    m = _small_manifest()
    keep = {n: s for n, s in m["sets"].items() if n in ("primitives", "evaluator")}
    for s in keep.values():
        s["cases"], s["tables"] = s["cases"][:3], s["tables"][:3]
    files = {s[k] for s in keep.values() for k in ("csv", "mem", "tables_mem") if s.get(k)}
    return json.dumps({**m, "sets": keep, "files": {f: v for f, v in m["files"].items() if f in files},
                       "sources": dict(list(m["sources"].items())[:3]), "configuration": {}})


@FUZZ
@given(data=st.data())
def test_fuzz_manifest_reader(tmp_path, manifest_text, data):
    from host_tools.vectors.build import set_order
    from host_tools.vectors.files import read_manifest
    from host_tools.vectors.spec import VectorsError
    text = data.draw(hostile_texts(manifest_text))
    (tmp_path / "manifest.json").write_bytes(text.encode("utf-8", "surrogatepass"))
    try:
        m = read_manifest(tmp_path)
    except VectorsError as exc:
        assert str(exc).startswith(str(tmp_path / "manifest.json"))
        return
    for name in set_order(m):                      # what check-impl and verify read next
        meta = m["sets"][name]
        for case in meta.get("cases", []):
            if meta.get("tables"):
                lo, hi = case["rows"]
                assert 0 <= lo <= hi <= meta["rows"] and 0 <= case["table"] < len(meta["tables"])
    assert all(isinstance(v["sha256"], str) for v in m["files"].values())


# == bounded children: check-impl =====================================================================

def _vectors_args():
    return ["vectors", "check-impl", str(ROOT / "vectors"), "--sets", "primitives"]


def test_check_impl_kills_a_child_that_sleeps(tmp_path, capsys):
    """Case: `vectors check-impl --cmd "sleep 1000"` waited 600 s per set."""
    pidfile = tmp_path / "pid"
    cmd = f"{sys.executable} -c \"import os, time; open('{pidfile}', 'w').write(str(os.getpid())); time.sleep(1000)\""
    t0 = time.monotonic()
    assert hdrg(*_vectors_args(), "--cmd", cmd, "--timeout", "2") == 2
    took = time.monotonic() - t0
    err = capsys.readouterr().err
    assert "did not finish within 2 s on set primitives" in err and "killed by signal SIGKILL" in err
    assert took < 20
    pid = int(pidfile.read_text())
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)


def test_check_impl_caps_a_child_that_floods(capsys):
    """Case: a check-impl program that floods its output was a MemoryError."""
    from host_tools.vectors.runner import run_bounded
    t0 = time.monotonic()
    assert hdrg(*_vectors_args(), "--cmd", "yes", "--max-output", "100000") == 2
    err = capsys.readouterr().err
    assert "wrote more than 100000 bytes on set primitives" in err and "killed by signal SIGKILL" in err
    assert time.monotonic() - t0 < 30
    out, errb, rc, problem = run_bounded([sys.executable, "-c", "import sys\nwhile True: sys.stderr.write('e' * 65536)"],
                                         b"", 3.0, 1000)
    assert problem.startswith("did not finish") and len(errb) <= 64 << 10 and rc == -9


def test_check_impl_reports_the_signal_and_validates_the_timeout(capsys):
    from host_tools.vectors.runner import check_impl
    lines = []
    rep = check_impl(f"{sys.executable} -c \"import os, signal; os.kill(os.getpid(), signal.SIGSEGV)\"",
                     ROOT / "vectors", ["primitives"], log=lines.append)
    assert "killed by signal SIGSEGV (11)" in lines[0] and rep["sets"]["primitives"]["exit"].startswith("killed")
    assert "killed by signal SIGSEGV" in rep["first"]
    for bad in ("nan", "-1", "0", "inf"):
        with pytest.raises(SystemExit):
            hdrg(*_vectors_args(), "--cmd", "true", "--timeout", bad)
        assert "--timeout" in capsys.readouterr().err
    with pytest.raises(ValueError, match="--timeout"):
        check_impl("true", ROOT / "vectors", ["primitives"], timeout=float("nan"))


# == special files =====================================================================================

def _run_cli(*argv, timeout=60):
    return subprocess.run([sys.executable, "-m", "host_tools.cli", *map(str, argv)], capture_output=True,
                          text=True, timeout=timeout, cwd=ROOT)


def test_compensate_refuses_a_device_input_and_a_fifo_output_without_a_reader(tmp_path, model_file, run_file):
    """Cases: `hdrg compensate /dev/zero` ate 18 GB in 15 s; `-o` onto a FIFO with no reader hung."""
    r = _run_cli("compensate", "/dev/zero", "--model", model_file, "-o", tmp_path / "o.csv")
    assert r.returncode == 2 and "/dev/zero: is a device, not a regular file" in r.stderr
    fifo = tmp_path / "out.fifo"
    os.mkfifo(fifo)
    r = _run_cli("compensate", run_file, "--model", model_file, "-o", fifo)
    assert r.returncode == 2 and "is a FIFO that no process is reading" in r.stderr
    r = _run_cli("compensate", fifo, "--model", model_file, "-o", tmp_path / "o.csv")
    assert r.returncode == 2 and "is a FIFO, not a regular file" in r.stderr
    # a FIFO with a reader is written (in place), as a pipe is
    got = {}
    reader = threading.Thread(target=lambda: got.setdefault("text", open(fifo).read()), daemon=True)
    reader.start()
    time.sleep(0.2)
    r = _run_cli("compensate", run_file, "--model", model_file, "-o", fifo)
    reader.join(30)
    assert r.returncode == 0 and got["text"].count("\n") > 400


# == runs as any user ===================================================================================

def test_numba_cache_choice(tmp_path, monkeypatch):
    import host_tools
    monkeypatch.setattr(host_tools, "_KERNEL_DIRS", ("no/such/dir",))
    env = {"HOME": str(tmp_path / "home")}
    assert host_tools.choose_numba_cache(env) == "home"
    assert env["NUMBA_CACHE_DIR"] == str(tmp_path / "home" / ".cache" / "hdrg" / "numba")
    no_home = tmp_path / "a_file"          # a home that cannot hold a directory, even for root
    no_home.write_text("")
    env = {"HOME": str(no_home), "XDG_CACHE_HOME": str(tmp_path / "xdg")}
    assert host_tools.choose_numba_cache(env) == "home" and env["NUMBA_CACHE_DIR"].startswith(str(tmp_path / "xdg"))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    env = {"HOME": str(no_home)}
    import io
    note = io.StringIO()
    assert host_tools.choose_numba_cache(env, note) == "tmp"
    assert env["NUMBA_CACHE_DIR"] == str(tmp_path / "tmp" / f"hdrg-numba-{os.getuid()}")
    assert note.getvalue().count("\n") == 1 and "note:" in note.getvalue()
    assert host_tools.choose_numba_cache({"NUMBA_CACHE_DIR": "/x"}) == "user"


def _unprivileged_prefix() -> list | None:
    """setpriv argv running as an unprivileged user (nobody, or one made with useradd) who can read
    the interpreter (CAP_DAC_READ_SEARCH only when the interpreter's directory is closed to others:
    it bypasses read and search checks, never write checks), or None."""
    if os.geteuid() != 0 or not shutil.which("setpriv"):
        return None
    try:
        user = pwd.getpwnam("nobody")
    except KeyError:
        if subprocess.run(["useradd", "--system", "--no-create-home", "--home-dir", "/nonexistent", "hdrgrunner"],
                          capture_output=True).returncode not in (0, 9):
            return None
        user = pwd.getpwnam("hdrgrunner")
    base = ["setpriv", f"--reuid={user.pw_uid}", f"--regid={user.pw_gid}", "--clear-groups"]
    if subprocess.run(base + [sys.executable, "-c", "import numpy, numba"], capture_output=True).returncode == 0:
        return base
    caps = base + ["--inh-caps=+dac_read_search", "--ambient-caps=+dac_read_search"]
    if subprocess.run(caps + [sys.executable, "-c", "import numpy, numba"], capture_output=True).returncode == 0:
        return caps
    return None


@pytest.mark.slow
@pytest.mark.skipif(os.name != "posix" or os.geteuid() != 0,
                    reason="needs root to run the tool as another, unprivileged user (setpriv)")
def test_runs_as_an_unprivileged_user_from_a_read_only_install_without_a_home():
    """Case: installed where the user cannot write (HOME=/nonexistent), every numba command died with
    `RuntimeError: cannot cache function ... no locator available`."""
    prefix = _unprivileged_prefix()
    if prefix is None:
        pytest.skip("setpriv cannot run the interpreter as an unprivileged user here")
    top = Path(tempfile.mkdtemp(prefix="hdrg-ro-"))
    try:
        install, work = top / "install", top / "work"
        for pkg in ("host_tools", "firmware_ref"):
            shutil.copytree(ROOT / pkg, install / pkg, ignore=shutil.ignore_patterns("__pycache__"))
        for p in [install, *install.rglob("*")]:
            p.chmod(0o555 if p.is_dir() else 0o444)
        work.mkdir()
        (work / "tmp").mkdir()
        for p in (top, work, work / "tmp"):
            p.chmod(0o777 if p != top else 0o755)
        env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "HOME": "/nonexistent", "PYTHONPATH": str(install),
               "PYTHONNOUSERSITE": "1", "TMPDIR": str(work / "tmp"), "OPENBLAS_NUM_THREADS": "1",
               "NUMBA_NUM_THREADS": "1"}

        def run(*argv):
            return subprocess.run(prefix + [sys.executable, "-m", "host_tools.cli", *argv], capture_output=True,
                                  text=True, cwd=work, env=env, timeout=120)

        probe = subprocess.run(prefix + ["sh", "-c", f"touch {install}/x 2>/dev/null || echo ro"], capture_output=True,
                               text=True, env=env)
        assert probe.stdout.strip() == "ro"           # the install really is read-only for this user
        t0 = time.monotonic()
        r = run("simulate", "--scenario", "paper-mr-cycle-4dpm", "--duration", "3000", "-o", "run.csv")
        assert r.returncode == 0, r.stderr
        assert r.stderr.count("note:") == 1 and "cached in" in r.stderr
        r = run("fit", "run.csv", "-o", "model.json", "--terms", "const,temp")
        assert r.returncode == 0, r.stderr
        r = run("compensate", "run.csv", "--model", "model.json", "-o", "out.csv")
        assert r.returncode == 0, r.stderr
        assert "Traceback" not in r.stderr and (work / "out.csv").stat().st_size > 0
        assert time.monotonic() - t0 < 60
    finally:
        for p in [top, *top.rglob("*")]:
            if not p.is_symlink():
                p.chmod(0o700)
        shutil.rmtree(top, ignore_errors=True)


@pytest.mark.parametrize("cmd", [("simulate", "--scenario", "paper-ftr-cycle-4dpm", "--duration", "50"),
                                 ("fit", "RUN", "--terms", "k0,k1")])
def test_every_atomic_output_refuses_a_fifo_without_a_reader(tmp_path, run_file, cmd):
    """host_tools.atomic.atomic_path checks a FIFO output for a reader, so every command (not only those
    with their own check) fails at once instead of waiting forever."""
    fifo = tmp_path / "out.fifo"
    os.mkfifo(fifo)
    r = _run_cli(*[run_file if c == "RUN" else c for c in cmd], "-o", fifo)
    assert r.returncode == 2 and "is a FIFO that no process is reading" in r.stderr
