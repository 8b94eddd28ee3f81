"""Run-log I/O: the CSV format of shared/formats/run-log.md, NPZ, and every bad input it lists."""
import warnings

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from host_tools.golden import runlog
from host_tools.golden.runlog import RunLog, RunLogError, RunLogWarning

GOOD = """# device: hdrg-01
# sample_rate_hz: 1
# reversal: on
# exchange_s: 30
# dwell_s: 120
t_s,freq_hz,rate_dph,mode,temp_c,aux_vdd
0.0,6227.3862488,397.25391,3,20.095,4.995019
1.0,6227.3852465,274.61107,3,19.957,4.994312
2.0,6227.3842465,12.5,1,19.957,4.994312
"""


def write(tmp_path, text, name="run.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_reads_spec_example(tmp_path):
    log = runlog.read(write(tmp_path, GOOD))
    assert len(log) == 3
    assert log.metadata["device"] == "hdrg-01" and log.metadata["dwell_s"] == "120"
    assert list(log.columns) == ["t_s", "freq_hz", "rate_dph", "mode", "temp_c", "aux_vdd"]
    assert log.mode.dtype == np.int64 and list(log.mode) == [3, 3, 1]
    assert log.freq_hz if False else log["freq_hz"][0] == 6227.3862488
    assert log.aux_columns == ["aux_vdd"] and log.reversal and log.sample_rate_hz == 1.0
    assert log.proxy()[0] == "freq_hz" and log.proxy("temp")[0] == "temp_c"
    assert log.line_of(0) == 7


def test_column_order_free_and_mode_default(tmp_path):
    log = runlog.read(write(tmp_path, "rate_dph,temp_c,t_s\n1.5,20,0\n2.5,20,1\n"))
    assert list(log.t_s) == [0, 1] and list(log.mode) == [0, 0] and not log.reversal
    with pytest.raises(RunLogError, match="freq"):
        log.proxy("freq")


def test_rate_dps_converted(tmp_path):
    log = runlog.read(write(tmp_path, "t_s,rate_dps,temp_c\n0,0.001,20\n1,-0.002,20\n"))
    np.testing.assert_allclose(log.rate_dph, [3.6, -7.2])
    assert any("rate_dps" in n for n in log.notes)


@pytest.mark.parametrize("text,line,problem", [
    ("", 1, "empty file"),
    ("# device: x\n# other: y\n", 2, "no header"),
    ("t_s,rate_dph,temp_c\n", 2, "no data rows"),
    ("t_s,temp_c\n0,1\n", 1, "missing required column 'rate_dph'"),
    ("rate_dph,temp_c\n0,1\n", 1, "missing required column 't_s'"),
    ("t_s,rate_dph\n0,1\n", 1, "temperature proxy"),
    ("t_s,rate_dph,temp_c,t_s\n0,1,2,3\n", 1, "appears twice"),
    ("t_s,rate_dph,temp_c\n0,1,2\n1,abc,2\n2,1,2\n", 3, "'rate_dph': 'abc' is not a number"),
    ("t_s,rate_dph,temp_c\n0,1,2\n1,nan,2\n2,1,2\n", 3, "NaN/inf"),
    ("t_s,rate_dph,temp_c\n0,1,2\n1,1,inf\n2,1,2\n", 3, "NaN/inf"),
    ("t_s,rate_dph,temp_c\n0,1,2\n1,1,2\n1,1,2\n", 4, "duplicated"),
    ("t_s,rate_dph,temp_c\n0,1,2\n2,1,2\n1,1,2\n", 4, "not increasing"),
    ("t_s,rate_dph,temp_c,mode\n0,1,2,1\n1,1,2,7\n", 3, "unknown mode code 7"),
    ("t_s,rate_dph,temp_c,mode\n0,1,2,1\n1,1,2,1.5\n", 3, "not an integer"),
    ("t_s,rate_dph,temp_c\n0,1,2\n\n2,1,2\n", 3, "blank line"),
    ("t_s,rate_dph,temp_c\n0,1,2\n1,1,2,9\n2,1,2\n", 3, "4 cells, the header has 3"),
    ("t_s,rate_dph,temp_c\n0,1,2\n1,1\n2,1,2\n", 3, "2 cells, the header has 3"),
])
def test_bad_input_errors_name_file_line_problem(tmp_path, text, line, problem):
    p = write(tmp_path, text)
    with pytest.raises(RunLogError) as err:
        runlog.read(p)
    assert err.value.line == line, str(err.value)
    assert problem in str(err.value)
    assert str(err.value).startswith(f"{p}:{line}: ")


def test_truncated_last_line_warns_and_repairs(tmp_path):
    p = write(tmp_path, "t_s,rate_dph,temp_c\n0,1,2\n1,1,2\n2,1.2")  # no final newline, 2 of 3 cells
    with pytest.warns(RunLogWarning, match=r":4: truncated last line '2,1.2'"):
        log = runlog.read(p)
    assert len(log) == 2 and any("truncated" in n for n in log.notes)
    # a cut inside a number: the cell still parses but the line is incomplete -> same repair
    p2 = write(tmp_path, "t_s,rate_dph,temp_c\n0,1,2\n1,1,2\n2,1,", "b.csv")
    with pytest.warns(RunLogWarning, match="truncated"):
        assert len(runlog.read(p2)) == 2


def test_last_line_without_line_end_is_dropped_with_a_warning(tmp_path):
    """A last line without its line end may be cut inside its last number ('2.5' of '2.5678'): it is
    discarded, never read as a shorter number; the warning names it and gives the rows kept."""
    p = write(tmp_path, "t_s,rate_dph,temp_c\n0,1,2\n1,1,2\n2,1,2.5")
    with pytest.warns(RunLogWarning, match=r":4: truncated last line '2,1,2.5' \(no line end.*3 of 3 cells\); "
                                           r"repair: the partial line is discarded, the 2 complete rows are kept"):
        log = runlog.read(p)
    assert len(log) == 2 and log["temp_c"][-1] == 2.0
    # trailing blank lines after a complete line are harmless; the line end may be CR LF
    for tail in ("\n", "\n\n  \n", "\r\n", "\n  "):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert len(runlog.read(write(tmp_path, "t_s,rate_dph,temp_c\n0,1,2\n1,1,2.5" + tail))) == 2
    with pytest.warns(RunLogWarning, match="truncated"), pytest.raises(RunLogError, match=r":2: no complete data rows"):
        runlog.read(write(tmp_path, "t_s,rate_dph,temp_c\n0,1,2"))


def test_gaps_warn_and_split_segments(tmp_path):
    rows = "".join(f"{t},1,2\n" for t in [0, 1, 2, 3, 10, 11, 12, 50, 51])
    with pytest.warns(RunLogWarning, match=r"2 gap\(s\).*largest 38 s before line 9"):
        log = runlog.read(write(tmp_path, "t_s,rate_dph,temp_c\n" + rows))
    assert len(log) == 9  # nothing dropped
    assert list(log.segments) == [0, 4, 7]


def test_measured_bursty_file_loads_and_reports_gaps(measured_x, measured_y):
    for path in (measured_x, measured_y):
        with pytest.warns(RunLogWarning, match="24 gap"):
            log = runlog.read(path)
        assert len(log) == 6250 and len(log.segments) == 25
        assert log.proxy()[0] == "temp_c" and not log.reversal
        assert log.sample_rate_hz == 50.0
        assert "LSM6DSM" in log.metadata["device"]


def test_in_memory_validation_names_row():
    with pytest.raises(RunLogError, match=r"row 2: t_s duplicated: 1\.0 after 1\.0$"):   # plain numbers, no numpy repr
        RunLog.from_arrays(t_s=[0, 1, 1], rate_dph=[0, 0, 0], temp_c=[0, 0, 0])
    with pytest.raises(RunLogError, match="row 1: column 'rate_dph' is nan"):
        RunLog.from_arrays(t_s=[0, 1, 2], rate_dph=[0, np.nan, 0], temp_c=[0, 0, 0])


def test_npz_rejects_foreign_file(tmp_path):
    p = tmp_path / "x.npz"
    np.savez(p, a=np.arange(3))
    with pytest.raises(RunLogError, match="not an hdrg run-log NPZ|unreadable"):
        runlog.read(p)


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=40, deadline=None)
@given(data=st.lists(st.tuples(finite, finite.filter(lambda f: f > 0), st.sampled_from([0, 1, 2, 3])),
                     min_size=1, max_size=30),
       meta=st.dictionaries(st.from_regex(r"[a-z_]{1,8}", fullmatch=True).filter(
           lambda k: k not in ("reversal", "capture")), st.from_regex(r"[a-z0-9 .]{0,12}", fullmatch=True), max_size=4))
def test_csv_and_npz_round_trip_lossless(tmp_path_factory, data, meta):
    d = tmp_path_factory.mktemp("rt")
    t = np.cumsum(np.full(len(data), 0.5))
    log = RunLog.from_arrays(meta, t_s=t, rate_dph=[r for r, _, _ in data], freq_hz=[f for _, f, _ in data],
                             mode=[m for _, _, m in data], aux_x=np.arange(len(data)) * 0.1)
    for name in ("a.csv", "a.npz"):
        runlog.write(log, d / name)
        back = runlog.read(d / name)
        assert list(back.columns) == list(log.columns)
        for k in log.columns:
            np.testing.assert_array_equal(back[k], log[k])
            assert back[k].dtype == log[k].dtype
        assert {k: v.strip() for k, v in back.metadata.items()} == {k: v.strip() for k, v in meta.items()}


# -- metadata that contradicts the data, non-physical frequency, flags column ---------------------

def _csv(tmp_path, text, name="x.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_reversal_metadata_must_match_the_modes(tmp_path):
    body = "t_s,rate_dph,temp_c,mode\n0,1,20,{m0}\n1,1,20,{m1}\n2,1,20,0\n"
    with pytest.raises(RunLogError, match=r"x.csv:2: metadata 'reversal: on' but every sample is mode 0"):
        runlog.read(_csv(tmp_path, "# reversal: on\n" + body.format(m0=0, m1=0)))
    with pytest.raises(RunLogError, match=r"x.csv:4: metadata 'reversal: off' but row 1 has mode 1"):
        runlog.read(_csv(tmp_path, "# reversal: off\n" + body.format(m0=0, m1=1)))
    with pytest.raises(RunLogError, match="no 'mode' column"):
        runlog.read(_csv(tmp_path, "# reversal: yes\nt_s,rate_dph,temp_c\n0,1,20\n1,1,20\n"))
    assert runlog.read(_csv(tmp_path, "# reversal: on\n" + body.format(m0=3, m1=1))).reversal
    assert len(runlog.read(_csv(tmp_path, "# reversal: maybe\n" + body.format(m0=0, m1=0)))) == 3


def test_sample_rate_metadata_must_match_t_s(tmp_path):
    rows = "".join(f"{i * 0.5},1,20\n" for i in range(10))
    assert runlog.read(_csv(tmp_path, "# sample_rate_hz: 2.02\nt_s,rate_dph,temp_c\n" + rows)).sample_rate_hz == 2.02
    with pytest.raises(RunLogError, match=r"sample_rate_hz: 1'.*0.5 s = 2 Hz"):
        runlog.read(_csv(tmp_path, "# sample_rate_hz: 1\nt_s,rate_dph,temp_c\n" + rows))
    log = runlog.RunLog.from_arrays({"sample_rate_hz": "5"}, t_s=np.arange(10.0), rate_dph=np.ones(10),
                                    temp_c=np.ones(10))
    runlog.write(log, tmp_path / "x.npz")
    with pytest.raises(RunLogError, match="does not match t_s"):
        runlog.read(tmp_path / "x.npz")


def test_frequency_must_be_positive(tmp_path):
    with pytest.raises(RunLogError, match=r"x.csv:3: freq_hz -6000.0 is not a frequency"):
        runlog.read(_csv(tmp_path, "t_s,rate_dph,freq_hz\n0,1,6000\n1,1,-6000\n"))
    log = runlog.RunLog.from_arrays(t_s=[0.0, 1.0], rate_dph=[0.0, 0.0], freq_hz=[0.0, 1.0])  # in memory: allowed
    runlog.write(log, tmp_path / "z.npz")
    with pytest.raises(RunLogError, match=r"z.npz: row 0: freq_hz 0.0 is not a frequency"):
        runlog.read(tmp_path / "z.npz")


def test_flags_column_is_integer(tmp_path):
    log = runlog.RunLog.from_arrays(t_s=np.arange(3.0), rate_dph=np.ones(3), temp_c=np.ones(3),
                                    flags=np.array([0, 129, 3]))
    assert log["flags"].dtype == np.int64
    for name in ("f.csv", "f.npz"):
        runlog.write(log, tmp_path / name)
        back = runlog.read(tmp_path / name)
        assert back["flags"].dtype == np.int64 and back["flags"].tolist() == [0, 129, 3]
    assert "\n1.0,1.0,1.0,129,0\n" in (tmp_path / "f.csv").read_text()
    with pytest.raises(RunLogError, match=r"x.csv:3: flags '1.5' is not an integer"):
        runlog.read(_csv(tmp_path, "t_s,rate_dph,temp_c,flags\n0,1,20,0\n1,1,20,1.5\n"))


def test_writers_are_atomic(tmp_path, monkeypatch):
    """A failing write leaves the old file and no temporary file (host_tools.atomic)."""
    log = runlog.RunLog.from_arrays(t_s=np.arange(3.0), rate_dph=np.ones(3), temp_c=np.ones(3))
    for name in ("a.csv", "a.npz"):
        dest = tmp_path / name
        dest.write_bytes(b"old")
        monkeypatch.setattr(runlog.np, "savez", lambda *a, **k: (_ for _ in ()).throw(OSError(28, "No space left")))
        monkeypatch.setattr(runlog, "_fmt_column", lambda *a: (_ for _ in ()).throw(OSError(28, "No space left")))
        with pytest.raises(OSError, match="No space left"):
            runlog.write(log, dest)
        monkeypatch.undo()
        assert dest.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "a.npz"]


# -- the fast reader: exact numbers, the same errors, bounded memory, escaped metadata --------------

def _random_doubles(n, seed):
    rng = np.random.default_rng(seed)
    bits = rng.integers(0, 2 ** 63, n, dtype=np.uint64) | (rng.integers(0, 2, n, dtype=np.uint64) << np.uint64(63))
    x = bits.view(np.float64)
    x = x[np.isfinite(x)]
    return np.concatenate([x, rng.standard_normal(n) * 10.0 ** rng.integers(-30, 30, n), [0.0, -0.0, 5e-324,
                           2.2250738585072014e-308, 1.7976931348623157e308, 9007199254740993.0, 0.1, 1e23]])


@pytest.mark.parametrize("chunk", [None, 97])
def test_every_double_reads_back_bit_exact(tmp_path, monkeypatch, chunk):
    """The kernel's conversion (Clinger / Eisel-Lemire, float() for the rest) gives the double
    nearest each decimal, as float(): every double's repr reads back bit for bit, in blocks of any
    size (``chunk``: lines split across blocks)."""
    from host_tools.golden import runlog_csv
    if chunk:
        monkeypatch.setattr(runlog_csv, "CHUNK_BYTES", chunk)
    x = _random_doubles(4000, 7)
    log = RunLog.from_arrays(t_s=np.arange(len(x), dtype=float), rate_dph=np.ones(len(x)), temp_c=np.ones(len(x)),
                             aux_x=x, mode=np.arange(len(x)) % 4)
    runlog.write(log, tmp_path / "x.csv")
    back = runlog.read(tmp_path / "x.csv")
    assert back["aux_x"].view(np.int64).tolist() == x.view(np.int64).tolist()
    assert back.mode.tolist() == log.mode.tolist() and back.mode.dtype == np.int64
    # other spellings of the same numbers: exponents, signs, spaces, digits beyond 19
    cells = ["1e5", "+1.5E-3", " 2.5 ", "\t.5", "5.", "0.000", "-0", "1.0000000000000000000000001", "1e-400", "0e999"]
    text = "t_s,rate_dph,temp_c\n" + "".join(f"{i},{c},0\n" for i, c in enumerate(cells))
    got = runlog.read(write(tmp_path, text, "s.csv")).rate_dph
    assert got.view(np.int64).tolist() == np.array([float(c) for c in cells]).view(np.int64).tolist()


@pytest.mark.parametrize("chunk", [None, 40])
def test_errors_name_the_same_line_in_any_block(tmp_path, monkeypatch, chunk):
    from host_tools.golden import runlog_csv
    if chunk:
        monkeypatch.setattr(runlog_csv, "CHUNK_BYTES", chunk)
    rows = [f"{i},1.5,20.25" for i in range(40)]
    for k, bad, problem in [(30, "30,1x,2", "'rate_dph': '1x' is not a number"), (25, "", "blank line inside"),
                            (33, "33,1,2,3", "4 cells"), (12, "12,1\r,2", "carriage return"),
                            (20, "20,1,\xe9", "not a number"), (38, "38,,1", "'rate_dph': empty cell")]:
        text = "# a: b\nt_s,rate_dph,temp_c\n" + "\n".join(rows[:k] + [bad] + rows[k + 1:]) + "\n"
        with pytest.raises(RunLogError, match=problem) as err:
            runlog.read(write(tmp_path, text))
        assert err.value.line == k + 3
    with pytest.raises(RunLogError, match=r":7: mode '1.9999' is not an integer"):
        runlog.read(write(tmp_path, "t_s,rate_dph,temp_c,mode\n" + "".join(f"{i},1,2,1\n" for i in range(5)) +
                          "5,1,2,1.9999\n"))
    (tmp_path / "u.csv").write_bytes(b"t_s,rate_dph,temp_c\n0,1,2\n1,1,\xff\n")
    with pytest.raises(RunLogError, match=r"u.csv: not a text file \(UTF-8 decoding failed at byte 30\)"):
        runlog.read(tmp_path / "u.csv")


def test_reading_memory_is_proportional_to_the_data(tmp_path):
    """Peak memory (tracemalloc) of reading a 200,000-row CSV: at most 3x the final arrays."""
    import tracemalloc
    n = 200_000
    rng = np.random.default_rng(3)
    log = RunLog.from_arrays({"device": "m"}, t_s=np.arange(n) * 1.0, freq_hz=6227 + rng.standard_normal(n),
                             rate_dph=rng.standard_normal(n), mode=rng.integers(1, 3, n), temp_c=rng.standard_normal(n))
    runlog.write(log, tmp_path / "m.csv")
    runlog.read(tmp_path / "m.csv")                         # compiled / loaded before measuring
    tracemalloc.start()
    try:
        back = runlog.read(tmp_path / "m.csv")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    final = sum(v.nbytes for v in back.columns.values())
    assert peak <= 3 * final, (peak, final)
    assert all(np.array_equal(back[k], log[k]) for k in log.columns)


def test_writer_output_is_unchanged_and_metadata_is_escaped(tmp_path):
    log = RunLog.from_arrays({"device": "d1", "#3": "free text", "note": "a: b"}, t_s=[0.0, 0.5], rate_dph=[1.25, -0.0],
                             temp_c=[20.0, 1e-7], mode=[1, 2])
    runlog.write(log, tmp_path / "n.csv")
    assert (tmp_path / "n.csv").read_text() == ("# device: d1\n# free text\n# note: a: b\nt_s,rate_dph,temp_c,mode\n"
                                                "0.0,1.25,20.0,1\n0.5,-0.0,1e-07,2\n")
    evil = {"op\nt_s,rate_dph,temp_c": "x\r\n0,1,2\n# reversal: on", "esc": "\x1b[31m\x00\u2028", "k:v": "w"}
    runlog.write(RunLog.from_arrays(evil, t_s=[0.0, 1.0], rate_dph=[1.0, 2.0], temp_c=[3.0, 4.0]), tmp_path / "e.csv")
    back = runlog.read(tmp_path / "e.csv")
    assert len(back) == 2 and "reversal" not in back.metadata
    assert back.metadata == {"op\\nt_s,rate_dph,temp_c": "x\\r\\n0,1,2\\n# reversal: on", "esc": "\\x1b[31m\\x00\\u2028",
                             "k_v": "w"}
    runlog.write(back, tmp_path / "e2.csv")                 # escaping is stable: a second round trip changes nothing
    assert (tmp_path / "e2.csv").read_text() == (tmp_path / "e.csv").read_text()
    runlog.write(RunLog.from_arrays(evil, t_s=[0.0, 1.0], rate_dph=[1.0, 2.0], temp_c=[3.0, 4.0]), tmp_path / "e.npz")
    assert runlog.read(tmp_path / "e.npz").metadata == evil  # NPZ keeps the text as it is (JSON)
    with pytest.raises(RunLogError, match="column name 'a,b' cannot be written"):
        runlog.write(RunLog.from_arrays(t_s=[0.0], rate_dph=[1.0], temp_c=[3.0], **{"a,b": [1.0]}), tmp_path / "c.csv")
