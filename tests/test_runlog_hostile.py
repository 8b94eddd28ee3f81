"""Hostile run logs: special files, NPZ files of the wrong structure or types, and fuzzed CSV and NPZ
bytes.  Each case ends in a RunLogError naming the file (or a correct RunLog), never another
exception, a hang or unbounded memory."""
from __future__ import annotations

import contextlib
import io
import json
import os
import re
import threading
import time
import warnings
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from host_tools.errors import HdrgError
from host_tools.golden import runlog
from host_tools.golden.runlog import RunLog, RunLogError

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
GOOD_CSV = ("# device: d\n# sample_rate_hz: 1\n# reversal: on\nt_s,freq_hz,rate_dph,mode,temp_c,aux_v\n" +
            "".join(f"{i}.0,6227.{i}5,{i * 0.37:.5f},{1 + i % 2},20.{i},4.99\n" for i in range(12))).encode()


def _log(n=6, **extra):
    cols = dict(t_s=np.arange(n, dtype=float), freq_hz=np.full(n, 6227.0), rate_dph=np.linspace(0, 1, n),
                mode=np.arange(n) % 2 + 1, temp_c=np.full(n, 20.0))
    cols.update(extra)
    return RunLog.from_arrays({"device": "d"}, **cols)


def _npz_bytes(doc=None, raw_header=None, **arrays) -> bytes:
    """An NPZ made by hand: the header ``doc`` made JSON, or the array ``raw_header`` as it is."""
    buf = io.BytesIO()
    if doc is not None or raw_header is not None:
        arrays["header"] = np.array(json.dumps(doc)) if raw_header is None else raw_header
    np.savez(buf, **arrays)
    return buf.getvalue()


def _good_header(**changes):
    h = {"format": "hdrg-runlog", "version": 1, "columns": ["t_s", "freq_hz", "rate_dph", "mode"],
         "metadata": {"device": "d"}, "notes": []}
    h.update(changes)
    return h


def _cols(mode=(1, 2, 1)):
    return dict(col_0=np.arange(3.0), col_1=np.full(3, 6227.0), col_2=np.ones(3), col_3=np.asarray(mode))


# == special files ==================================================================================

@pytest.mark.parametrize("name", ["r.csv", "r.npz"])
def test_special_files_are_refused_without_blocking(tmp_path, name):
    t0 = time.monotonic()
    fifo = tmp_path / name
    os.mkfifo(fifo)
    with pytest.raises(RunLogError, match=rf"{name}: is a FIFO, not a regular file"):
        runlog.read(fifo)
    d = tmp_path / "dir.npz" if name.endswith("npz") else tmp_path / "dir.csv"
    d.mkdir()
    with pytest.raises(RunLogError, match="is a directory, not a regular file"):
        runlog.read(d)
    reader = runlog.read_npz if name.endswith("npz") else runlog.read_csv
    with pytest.raises(RunLogError, match="/dev/zero: is a device, not a regular file"):
        reader("/dev/zero")
    assert time.monotonic() - t0 < 5


def test_a_fifo_with_a_writer_is_refused_too(tmp_path):
    """Even with a process writing into it (so open() would not block), a FIFO is not read."""
    fifo = tmp_path / "w.csv"
    os.mkfifo(fifo)
    done = threading.Event()

    def feed():
        try:
            fd = os.open(fifo, os.O_WRONLY)
            while not done.is_set():
                try:
                    os.write(fd, b"0,1,2\n" * 1000)
                except OSError:
                    break
            os.close(fd)
        except OSError:
            pass

    t = threading.Thread(target=feed, daemon=True)
    t.start()
    try:
        with pytest.raises(RunLogError, match="is a FIFO"):
            runlog.read(fifo)
    finally:
        done.set()
        try:                                   # unblock the writer if it still waits for a reader
            os.close(os.open(fifo, os.O_RDONLY | os.O_NONBLOCK))
        except OSError:
            pass
        t.join(2)


def test_a_missing_file_is_the_os_error(tmp_path):
    with pytest.raises(FileNotFoundError):
        runlog.read(tmp_path / "none.csv")
    with pytest.raises(FileNotFoundError):
        runlog.read(tmp_path / "none.npz")


# == NPZ: structure and types =========================================================================

NPZ_CASES = [
    (b"not a zip at all", "unreadable NPZ run log"),
    (b"PK\x03\x04" + b"\x00" * 40, "unreadable NPZ run log"),
    (_npz_bytes(None, a=np.arange(3)), "no 'header' member"),
    (_npz_bytes(None, raw_header=np.arange(3), **_cols()), "member 'header': must be one JSON text"),
    (_npz_bytes(None, raw_header=np.array(["a", "b"]), **_cols()), "member 'header': must be one JSON text"),
    (_npz_bytes(None, raw_header=np.array("{not json"), **_cols()), "not valid JSON"),
    (_npz_bytes(None, raw_header=np.array('{"format": "hdrg-runlog", "format": 1}'), **_cols()), "duplicated key"),
    (_npz_bytes(None, raw_header=np.array("[" * 5000 + "]" * 5000), **_cols()), "nested too deep"),
    (_npz_bytes(["hdrg-runlog"], **_cols()), "header 'format' missing"),
    (_npz_bytes(_good_header(columns=4), **_cols()), "header field 'columns': must be a non-empty list"),
    (_npz_bytes(_good_header(columns=[]), **_cols()), "header field 'columns'"),
    (_npz_bytes(_good_header(columns=["t_s", 5]), **_cols()), "header field 'columns'"),
    (_npz_bytes(_good_header(columns=["t_s", "t_s"]), **_cols()), "appears twice"),
    (_npz_bytes(_good_header(columns=["t_s", "a\nb"]), **_cols()), "'a\\nb' is not a column name"),
    (_npz_bytes(_good_header(metadata=["device", "d"]), **_cols()), "header field 'metadata'"),
    (_npz_bytes(_good_header(metadata={"device": 5}), **_cols()), "header field 'metadata'"),
    (_npz_bytes(_good_header(notes="x"), **_cols()), "header field 'notes'"),
    (_npz_bytes(_good_header(version="1"), **_cols()), "header field 'version'"),
    (_npz_bytes(_good_header(version=2), **_cols()), "header field 'version'"),
    (_npz_bytes(_good_header(version=True), **_cols()), "header field 'version'"),
    (_npz_bytes(_good_header(columns=["t_s", "freq_hz", "rate_dph", "mode", "temp_c"]), **_cols()),
     "column 'temp_c': member 'col_4' missing"),
    (_npz_bytes(_good_header(), **{**_cols(), "col_1": np.ones((3, 2))}), "column 'freq_hz': must be 1-D numbers"),
    (_npz_bytes(_good_header(), **{**_cols(), "col_1": np.array(["a", "b", "c"])}), "must be 1-D numbers"),
    (_npz_bytes(_good_header(), **{**_cols(), "col_1": np.array(5.0)}), "must be 1-D numbers"),
    (_npz_bytes(_good_header(), **{**_cols(), "col_1": np.ones(3, complex)}), "dtype complex128"),
    (_npz_bytes(_good_header(), **_cols(mode=[1.0, 1.9999, 2.0])), "row 1: mode 1.9999 is not an integer"),
    (_npz_bytes(_good_header(), **_cols(mode=[1.0, np.inf, 2.0])), "row 1: mode inf is not an integer"),
    (_npz_bytes(_good_header(), **_cols(mode=[1.0, 1e300, 2.0])), "row 1: mode 1e+300 is not an integer"),
    (_npz_bytes(_good_header(), **{**_cols(), "col_1": np.array([6227.0, np.nan, 1.0])}), "row 1: column 'freq_hz' is nan"),
    (_npz_bytes(_good_header(), **{**_cols(), "col_0": np.array([0.0, 2.0, 1.0])}), "t_s not increasing"),
    (_npz_bytes(_good_header(), **{**_cols(), "col_1": np.ones(2)}), "column 'freq_hz' has 2 values"),
]


@pytest.mark.parametrize("data,problem", NPZ_CASES, ids=[f"{i}-{p[:30]}" for i, (_, p) in enumerate(NPZ_CASES)])
def test_npz_structure_and_types_are_checked(tmp_path, data, problem):
    p = tmp_path / "x.npz"
    p.write_bytes(data)
    with pytest.raises(RunLogError, match=re.escape(problem)) as err:
        runlog.read(p)
    assert str(err.value).startswith(f"{p}: ") and "\n" not in str(err.value)


def test_npz_huge_declared_shape_and_zip_bomb_are_refused_before_allocating(tmp_path):
    good = _npz_bytes(_good_header(), **_cols())
    with zipfile.ZipFile(io.BytesIO(good)) as zf:
        members = {i.filename: zf.read(i) for i in zf.infolist()}
    members["col_0.npy"] = members["col_0.npy"].replace(b"(3,)", b"(10000000000000,)")
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    (tmp_path / "shape.npz").write_bytes(out.getvalue())
    with pytest.raises(RunLogError, match=r"member 'col_0.npy': shape \(10000000000000,\) does not fit"):
        runlog.read(tmp_path / "shape.npz")
    bomb = io.BytesIO()
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("header.npy", b"\x00" * (50 << 20))
    (tmp_path / "bomb.npz").write_bytes(bomb.getvalue())
    with pytest.raises(RunLogError, match="bomb.npz: unreadable NPZ run log: the magic string is not correct"):
        runlog.read(tmp_path / "bomb.npz")          # read up to its .npy header only, never inflated whole


def test_npz_written_by_hdrg_reads_back(tmp_path):
    log = _log(flags=np.array([0, 1, 2, 3, 4, 5]))
    runlog.write(log, tmp_path / "ok.npz")
    back = runlog.read(tmp_path / "ok.npz")
    assert back.mode.dtype == np.int64 and back["flags"].tolist() == [0, 1, 2, 3, 4, 5]
    p = tmp_path / "f.npz"
    p.write_bytes(_npz_bytes(_good_header(), **_cols(mode=[1.0, 2.0, 1.0])))   # integral floats: fine
    assert runlog.read(p).mode.tolist() == [1, 2, 1]


# == fuzz ===========================================================================================

@contextlib.contextmanager
def _quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def _check(path):
    """Read ``path``: a RunLogError naming it, or a RunLog that passes the in-memory validation."""
    try:
        log = runlog.read(path)
    except RunLogError as exc:
        assert str(exc).startswith(str(path)) and isinstance(exc, HdrgError)
        return None
    RunLog(dict(log.columns), dict(log.metadata), log.source)       # valid columns of one length
    assert len(log) >= 1 and log.mode.dtype == np.int64
    return log


_mutation = st.one_of(
    st.tuples(st.just("cut"), st.integers(0, len(GOOD_CSV))),
    st.tuples(st.just("flip"), st.integers(0, len(GOOD_CSV) - 1), st.integers(0, 255)),
    st.tuples(st.just("insert"), st.integers(0, len(GOOD_CSV)),
              st.sampled_from([b",", b"\n", b"\r", b"\n\n", b"nan", b"-", b".", b"e", b"#", b"\xff", b" ", b"\x00",
                               b"1e999", b"99999999999999999999999", b",,", b"inf", b"\xef\xbb\xbf"])),
)


@FUZZ
@given(mutations=st.lists(_mutation, min_size=1, max_size=4), chunk=st.sampled_from([None, 31]))
def test_fuzz_csv_reader(tmp_path, monkeypatch, mutations, chunk):
    from host_tools.golden import runlog_csv
    monkeypatch.setattr(runlog_csv, "CHUNK_BYTES", chunk or 4 << 20)
    data = bytearray(GOOD_CSV)
    for m in mutations:
        if m[0] == "cut":
            del data[m[1]:]
        elif m[0] == "flip" and m[1] < len(data):
            data[m[1]] = m[2]
        elif m[0] == "insert":
            data[m[1]:m[1]] = m[2]
    p = tmp_path / "fuzz.csv"
    p.write_bytes(bytes(data))
    with _quiet():
        _check(p)


@FUZZ
@given(data=st.binary(max_size=300))
def test_fuzz_csv_reader_random_bytes(tmp_path, data):
    p = tmp_path / "bytes.csv"
    p.write_bytes(b"t_s,rate_dph,temp_c\n" + data)
    with _quiet():
        _check(p)


GOOD_NPZ = _npz_bytes(_good_header(), **_cols())
_JSON_VALUES = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
                            lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner,
                                                                                       max_size=3), max_leaves=6)


@FUZZ
@given(data=st.data())
def test_fuzz_npz_reader(tmp_path, data):
    """Truncations and byte flips of a good NPZ, and its header's fields swapped for other types."""
    kind = data.draw(st.sampled_from(["bytes", "header", "column"]))
    if kind == "bytes":
        raw = bytearray(GOOD_NPZ)
        for _ in range(data.draw(st.integers(1, 4))):
            k = data.draw(st.integers(0, len(raw) - 1))
            raw[k] = data.draw(st.integers(0, 255))
        raw = raw[:data.draw(st.integers(0, len(raw)))]
    elif kind == "header":
        header = _good_header()
        header[data.draw(st.sampled_from(sorted(header) + ["extra"]))] = data.draw(_JSON_VALUES)
        raw = _npz_bytes(header, **_cols())
    else:
        col = data.draw(st.sampled_from(["col_0", "col_1", "col_3"]))
        value = data.draw(st.sampled_from([np.array([0.0, 1.5, 1.9999]), np.array([[1.0]]), np.array([np.nan] * 3),
                                           np.array([True, False, True]), np.array([2 ** 64 - 1] * 3, np.uint64),
                                           np.array([-1, 0, 1], np.int8), np.array(["1", "2", "3"]), np.zeros(0)]))
        raw = _npz_bytes(_good_header(), **{**_cols(), col: value})
    p = tmp_path / "fuzz.npz"
    p.write_bytes(bytes(raw))
    with _quiet():
        _check(p)


@pytest.mark.parametrize("cell", ["1_000", "1_0.5", "\u0663", "\uff11"])
def test_numbers_python_takes_but_the_format_does_not_are_named_with_their_line(tmp_path, cell):
    p = tmp_path / "u.csv"
    p.write_text(f"t_s,rate_dph,freq_hz\n0,1,6000\n1,{cell},6000\n2,3,6000\n", encoding="utf-8")
    with pytest.raises(runlog.RunLogError, match=r"u\.csv:3: column 'rate_dph'"):
        runlog.read_csv(p)
