"""The serial link: framing and CRCs, the decoder under corruption, capture from the virtual
device over real pseudo-terminals (bit-identical to the offline fixed-point run), table upload
(round trip, refusals), disconnects, Ctrl-C, version negotiation, loop:// URLs, the CLIs.

Every wait is bounded (port read timeout 0.05 s, idle timeouts, joins with timeouts)."""
from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import os
import random
import signal
import struct
import subprocess
import sys
import threading
import time
import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_ref import formats as F
from firmware_ref import inputs
from firmware_ref import table as T
from host_tools.fixed.fixed_point import compensate_log
from firmware_ref.kernel import run_words
from host_tools.link import device as D
from host_tools.golden import runlog
from host_tools import link as SL
import pty_device
from host_tools.simulation import sim
from host_tools.golden.compensate import fit_config_from_logs
from host_tools.golden.model import BiasModel
from host_tools.fixed.quantize import quantize

SCENARIO, SEED, DURATION = "paper-mr-cycle-4dpm", 3, 1200.0


# -- fixtures ----------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def run():
    """A mode-reversal simulation, a model with non-zero coefficients and its table, and a second
    table (another model) for uploads."""
    log = sim.simulate(SCENARIO, seed=SEED, duration_s=DURATION)
    cfg = fit_config_from_logs([log], reversal={"combiner": "pair", "order": "combine_first"})
    coef = np.zeros(17)
    coef[[0, 1, 2, 4, 8]] = [120.0, -35.0, 4.0, 2.5, -1.25]
    model = BiasModel(cfg, (0, 1, 2, 4, 8), coef, source="test model")
    coef2 = coef.copy()
    coef2[0] = -80.0
    model2 = BiasModel(cfg, (0, 1, 2, 4, 8), coef2, source="test model 2")
    return {"log": log, "model": model, "table": quantize(model, n_random=16).table,
            "model2": model2, "table2": quantize(model2, n_random=16).table}


class PtyDevice(pty_device.PtyDevice):
    """A virtual device on a fresh pty and the host's pyserial port on its other end."""

    def __init__(self, log, table, **kw):
        super().__init__(log, table, **kw)
        self.port = SL.open_port(self.name)

    def close(self) -> None:
        self.port.close()


class RecordingLink:
    """A link that records what the device writes (and never receives anything)."""

    name = "record"

    def __init__(self):
        self.data = bytearray()

    def read(self, timeout):
        time.sleep(min(timeout, 0.001))
        return b""

    def write(self, data, stop, deadline=None):
        self.data += data
        return len(data)

    def close(self):
        pass


def record_stream(log, table) -> bytes:
    """Everything a device sends for ``log`` (INFO, SAMPLEs, periodic INFO, end-of-run INFO)."""
    link = RecordingLink()
    dev = D.VirtualDevice(link, D.DeviceRun.from_log(log), table, speed=0.0, boot_id=0x1234)
    dev.start()
    deadline = time.monotonic() + 20
    while not dev.ended and time.monotonic() < deadline:
        time.sleep(0.01)
    assert dev.stop(5.0) and dev.ended and dev.error is None
    return bytes(link.data)


def split_frames(stream: bytes) -> list:
    """Byte strings of the frames of a clean stream (by the header's length field)."""
    out, pos = [], 0
    while pos < len(stream):
        assert stream[pos:pos + 2] == SL.SYNC
        n = SL.OVERHEAD + struct.unpack_from("<H", stream, pos + 6)[0]
        out.append(stream[pos:pos + n])
        pos += n
    return out


def replay(stream: bytes, path, **kw):
    """Write ``stream`` into a pty (writer thread, chunks of 997 bytes) and capture from its other end."""
    master, slave, name = D.open_pty()
    link = D.FdLink(master, keep=(slave,))
    stop = threading.Event()

    def writer():
        for k in range(0, len(stream), 997):
            if stop.is_set() or link.write(stream[k:k + 997], stop) == 0:
                return

    port = SL.open_port(name)          # first: opening flushes the port's input queue
    th = threading.Thread(target=writer, daemon=True)
    th.start()
    kw.setdefault("idle_timeout_s", 2.0)
    try:
        return SL.capture(port, path, **kw)
    finally:
        stop.set()
        th.join(5)
        port.close()
        link.close()
        assert not th.is_alive()


def words_of(cap) -> dict:
    """A captured run log's columns back to words (exact: every value is word * 2^-frac)."""
    return {"freq": np.round(cap["freq_hz"] * 2.0 ** F.FREQ_FRAC).astype(np.int64),
            "rate": np.round(cap.rate_dph * 2.0 ** F.RATE_FRAC).astype(np.int64),
            "temp": np.round(cap["temp_c"] * 2.0 ** F.TEMP_FRAC).astype(np.int64),
            "out": np.round(cap["comp_rate_dph"] * 2.0 ** F.OUT_FRAC).astype(np.int64),
            "bias": np.round(cap["comp_bias_dph"] * 2.0 ** F.OUT_FRAC).astype(np.int64)}


# -- framing ----------------------------------------------------------------------------------------------

def test_crc_check_values():
    assert SL.crc16(b"123456789") == 0x29B1           # CRC-16/CCITT-FALSE
    assert zlib.crc32(b"123456789") == 0xCBF43926     # CRC-32 (IEEE)


def test_frame_layout_offsets():
    payload = bytes(range(7))
    fr = SL.encode_frame(SL.T_SAMPLE, 0x1234, payload)
    assert fr[0:2] == b"\xa5\x5a"
    assert fr[2] == (SL.PROTO_MAJOR << 4) | SL.PROTO_MINOR
    assert fr[3] == SL.T_SAMPLE
    assert struct.unpack_from("<H", fr, 4)[0] == 0x1234
    assert struct.unpack_from("<H", fr, 6)[0] == len(payload)
    assert struct.unpack_from("<H", fr, 8)[0] == SL.crc16(fr[:8])
    assert fr[10:17] == payload
    assert struct.unpack_from("<I", fr, 17)[0] == zlib.crc32(fr[:17])
    assert len(fr) == SL.OVERHEAD + len(payload)
    with pytest.raises(SL.ProtocolError, match="MAX_PAYLOAD"):
        SL.encode_frame(SL.T_TABLE, 0, bytes(SL.MAX_PAYLOAD + 1))


def test_sample_payload_uses_the_firmware_formats():
    s = SL.pack_sample(2 ** 32 + 5, 123, -7, -300, 44, -9, F.ST_MODE_2, 2, F.FLAG_SAT, 1)
    assert len(s) == SL.SAMPLE.size == 28
    assert SL.unpack_sample(s + b"extra bytes of a newer minor") == (5, 123, -7, -300, 44, -9, F.ST_MODE_2, 2,
                                                                     F.FLAG_SAT, 1)
    with pytest.raises(SL.ProtocolError, match="at least 28"):
        SL.unpack_sample(s[:27])
    with pytest.raises(SL.ProtocolError, match="out of range"):
        SL.unpack_sample(SL.pack_sample(0, 0, 0, 0, 0, 0, 0, 4, 0, 0))     # mode 4
    info = SL.DeviceInfo(capabilities=5, fs_q16=100 << 16, table_crc=0xDEADBEEF, boot_id=7, counter=9, name="gyro-7")
    back = SL.DeviceInfo.unpack(info.pack())
    assert back == info and back.fs_hz == 100.0
    assert (back.freq_frac, back.temp_frac, back.rate_frac, back.out_frac) == (F.FREQ_FRAC, F.TEMP_FRAC,
                                                                               F.RATE_FRAC, F.OUT_FRAC)
    r = SL.Reply(SL.T_TABLE, SL.R_TABLE_CRC, 65535, 1, 2, "why")
    assert SL.Reply.unpack(r.pack()) == r


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 255), st.integers(0, 65535), st.binary(max_size=80)), min_size=1,
                max_size=12),
       st.integers(1, 40))
def test_decoder_round_trip_any_chunking(frames, chunk):
    stream = b"".join(SL.encode_frame(t, s, p) for t, s, p in frames)
    dec = SL.Decoder()
    got = []
    for k in range(0, len(stream), chunk):
        got += dec.feed(stream[k:k + chunk])
    assert [(f.type, f.seq, f.payload) for f in got] == frames
    assert dec.stats.crc_errors == dec.stats.header_errors == dec.stats.garbage_bytes == 0


def _damage(frame: bytes, kind: str, rnd: random.Random) -> bytes:
    """One damage.  Cuts whose missing tail the next frame's first bytes (A5 5A ...) would restore
    exactly are not damage (the frame arrives intact and eats the next frame's sync), so a cut
    never removes a tail starting with 0xA5 and a drop never removes a byte of an all-0xA5 tail."""
    b = bytearray(frame)
    if kind == "drop":
        js = [j for j in range(len(b)) if any(x != 0xA5 for x in b[j:])]
        del b[rnd.choice(js)]
    elif kind == "insert":
        b.insert(rnd.randrange(1, len(b)), rnd.randrange(256))
    elif kind == "truncate":
        b = b[:rnd.choice([c for c in range(1, len(b)) if b[c] != 0xA5])]
    else:
        i = rnd.randrange(len(b))
        b[i] ^= 1 << rnd.randrange(8)
    return bytes(b)


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 2 ** 32 - 1), st.lists(st.sampled_from(["flip", "drop", "insert", "truncate", "ok"]),
                                             min_size=4, max_size=30),
       st.binary(max_size=60))
def test_decoder_never_accepts_a_damaged_frame(seed, kinds, garbage):
    """Random payloads (false syncs included), garbage before the first sync, one random damage per
    frame: every decoded frame is an original, every undamaged frame is decoded, in order."""
    rnd = random.Random(seed)
    originals = []
    for i, _ in enumerate(kinds):
        payload = bytes(rnd.randrange(256) for _ in range(rnd.randrange(0, 40)))
        if rnd.random() < 0.3:
            payload = payload[:5] + SL.SYNC + payload[5:]
        originals.append(SL.encode_frame(SL.T_SAMPLE, i, payload))
    stream = garbage + SL.SYNC + b"".join(o if k == "ok" else _damage(o, k, rnd) for o, k in zip(originals, kinds))
    dec = SL.Decoder()
    got = dec.feed(stream)
    got += dec.finish()
    assert not dec.buf
    seqs = [f.seq for f in got]
    assert seqs == sorted(set(seqs))
    for f in got:
        assert SL.encode_frame(f.type, f.seq, f.payload) == originals[f.seq]
    assert set(i for i, k in enumerate(kinds) if k == "ok") <= set(seqs)


# -- capture end to end over a pty ---------------------------------------------------------------------

def test_capture_from_virtual_device_is_bit_identical_to_offline(run, tmp_path):
    log, model, table = run["log"], run["model"], run["table"]
    path = tmp_path / "run.csv"
    lines = []
    with PtyDevice(log, table) as pd:
        res = SL.capture(pd.port, path, idle_timeout_s=5.0, progress=lambda r: lines.append(r.progress_line()))
    assert res.reason == "the device reports the end of its run"
    assert res.samples == len(log) and res.crc_errors == res.seq_gaps == res.resyncs == 0
    assert lines and "samples" in lines[-1] and "CRC errors 0" in lines[-1]
    cap = runlog.read(path)
    assert cap.metadata["sample_rate_hz"] == "1" and cap.metadata["table_crc"] == f"0x{table.crc:08x}"
    # the same run computed offline: hdrg compensate --impl fixed with the same table
    off = compensate_log(log, model, table=table)
    w = words_of(cap)
    assert np.array_equal(w["out"], inputs.rate_words(off.rate_dph)[0])
    assert np.array_equal(cap["comp_rate_dph"], off.rate_dph)            # bit-identical floats too
    assert np.array_equal(cap["comp_bias_dph"], off["bias_dph"])
    assert np.array_equal(cap["comp_valid"], off["valid"])
    assert np.array_equal(w["freq"], inputs.freq_words(log["freq_hz"])[0])
    assert np.array_equal(w["rate"], inputs.rate_words(log.rate_dph)[0])
    assert np.array_equal(w["temp"], inputs.temp_words(log["temp_c"])[0])
    assert np.array_equal(cap.mode, log.mode) and np.array_equal(cap.t_s, log.t_s)
    assert np.array_equal(cap.mode, np.array(F.STATE_MODE)[cap["state"].astype(int)])
    assert np.all(np.diff(cap["seq"]) >= 1)          # INFO frames may sit between samples
    assert np.any(cap["comp_valid"] == 1) and np.any(cap["status"].astype(int) & F.FLAG_EXCHANGE)


def test_capture_duration_and_ctrl_c_keep_everything(run, tmp_path):
    log, table = run["log"], run["table"]
    with PtyDevice(log, table) as pd:
        res = SL.capture(pd.port, tmp_path / "d.csv", duration_s=100.0, idle_timeout_s=5.0)
    assert res.reason.startswith("duration 100") and res.samples == 100
    assert len(runlog.read(tmp_path / "d.csv")) == 100

    def interrupt(r):
        if r.samples >= 250:
            raise KeyboardInterrupt

    with PtyDevice(log, table) as pd:
        res = SL.capture(pd.port, tmp_path / "c.csv", idle_timeout_s=5.0, flush_every=10_000, progress=interrupt)
    assert res.reason == "interrupted (Ctrl-C)" and res.samples >= 250
    cap = runlog.read(tmp_path / "c.csv")
    assert len(cap) == res.samples                    # everything received was flushed at exit
    off = compensate_log(log, run["model"], table=table)
    assert np.array_equal(cap["comp_rate_dph"], off.rate_dph[:len(cap)])


def test_unplugged_mid_run_keeps_the_log_so_far(run, tmp_path):
    log, table = run["log"], run["table"]
    path = tmp_path / "u.csv"
    seen = {}

    def unplug(r):
        if r.samples >= 300 and "rows" not in seen:
            time.sleep(0.05)
            with pytest.warns(runlog.RunLogWarning, match="unfinished capture"):
                seen["rows"] = len(runlog.read(path))    # a valid run log at a flush boundary, mid-capture
            pd.dev.unplug()

    with PtyDevice(log, table) as pd:
        res = SL.capture(pd.port, path, idle_timeout_s=5.0, flush_every=50, flush_interval_s=0.01, progress=unplug)
    assert res.reason.startswith("port error")
    assert 0 < seen["rows"] <= res.samples < len(log)
    cap = runlog.read(path)
    assert len(cap) == res.samples and cap.metadata["capture"] == "complete"   # closed by capture()
    off = compensate_log(log, run["model"], table=table)
    assert np.array_equal(cap["comp_rate_dph"], off.rate_dph[:len(cap)])
    assert np.array_equal(cap.t_s, log.t_s[:len(cap)])


# -- corruption over a pty ---------------------------------------------------------------------------------

def test_corruption_loses_only_damaged_frames(run, tmp_path):
    log = run["log"].select(np.arange(200))
    clean = record_stream(log, run["table"])
    frames = split_frames(clean)
    rnd = random.Random(5)
    dec_all = SL.Decoder().feed(clean)
    sample_idx = [i for i, f in enumerate(dec_all) if f.type == SL.T_SAMPLE]
    victims = {sample_idx[k]: kind for k, kind in
               ((10, "flip_payload"), (20, "flip_sync"), (30, "flip_length"), (40, "drop"), (50, "insert"),
                (60, "truncate"), (80, "flip_crc"))}
    parts = [bytes(rnd.randrange(256) for _ in range(100)) + SL.SYNC + b"\x10\x01\x00\x00" + bytes(150)]  # garbage
    for i, fr in enumerate(frames):
        b = bytearray(fr)
        kind = victims.get(i)
        if kind == "flip_payload":
            b[SL.HEADER_SIZE + 5] ^= 0x10
        elif kind == "flip_sync":
            b[1] ^= 0x01
        elif kind == "flip_length":
            b[6] ^= 0x04
        elif kind == "drop":
            del b[SL.HEADER_SIZE + 3]
        elif kind == "insert":
            b.insert(SL.HEADER_SIZE + 3, 0x5A)
        elif kind == "truncate":
            b = b[:20]
        elif kind == "flip_crc":
            b[-2] ^= 0x80
        parts.append(bytes(b))
        if i == sample_idx[70]:                       # garbage with a false sync between two frames
            parts.append(SL.SYNC + bytes(rnd.randrange(256) for _ in range(30)))
    res = replay(b"".join(parts), tmp_path / "x.csv")
    assert res.reason == "the device reports the end of its run"
    with pytest.warns(runlog.RunLogWarning, match="7 gap"):
        cap = runlog.read(tmp_path / "x.csv")
    lost = {dec_all[i].seq for i in victims}
    expect = [f for f in dec_all if f.type == SL.T_SAMPLE and f.seq not in lost]
    assert cap["seq"].astype(int).tolist() == [f.seq for f in expect]
    assert len(cap) == 200 - len(victims)
    w = words_of(cap)
    samples = [SL.unpack_sample(f.payload) for f in expect]
    assert w["out"].tolist() == [s[4] for s in samples]
    assert w["rate"].tolist() == [s[2] for s in samples]
    assert res.seq_gaps == len(victims) and res.gap_events == len(victims)
    # the sync flip is never seen as a frame; every other damage is a CRC or header-CRC failure
    assert res.crc_errors + res.header_errors >= len(victims) - 1 + 1     # + the false sync in the garbage
    assert res.resyncs >= len(victims) + 2 and res.garbage_bytes > 250


def test_corruption_at_the_end_truncated_last_frame(run, tmp_path):
    log = run["log"].select(np.arange(50))
    frames = split_frames(record_stream(log, run["table"]))
    stream = b"".join(frames[:-1])[:-7]               # no end-of-run INFO; last sample cut short
    res = replay(stream, tmp_path / "t.csv", idle_timeout_s=0.5)
    assert res.reason.startswith("no frame from the device")
    assert res.truncated == 1
    assert len(runlog.read(tmp_path / "t.csv")) == 49


# -- upload ------------------------------------------------------------------------------------------------

def stream_around_upload(pd, table, before, total, timeout_s=20.0):
    """Capture sample frames from the device ``pd`` (a PtyDevice), upload ``table`` after ``before``
    samples and keep capturing up to ``total`` samples (bounded by ``timeout_s``).
    Returns (link, upload result, list of unpacked sample tuples)."""
    got = []

    def keep(fr):
        if fr.type == SL.T_SAMPLE:
            got.append(SL.unpack_sample(fr.payload))

    link = SL.HostLink(pd.port)
    deadline = time.monotonic() + timeout_s
    while len(got) < before and time.monotonic() < deadline:
        for fr in link.poll():
            keep(fr)
    res = SL.upload(link, table, on_frame=keep)
    while len(got) < total and time.monotonic() < deadline:
        for fr in link.poll():
            keep(fr)
    return link, res, got


def test_upload_round_trip_applies_from_the_next_sample(run):
    log, t1, t2 = run["log"], run["table"], run["table2"]
    with PtyDevice(log, t1, speed=400.0) as pd:
        link, res, got = stream_around_upload(pd, t2, before=100, total=400)
        assert pd.dev.table.crc == t2.crc != t1.crc
        assert SL.DeviceInfo.unpack(
            link.request(SL.T_GET_INFO, b"", lambda f, s: f.type == SL.T_INFO).payload).table_crc == t2.crc
    assert res.crc == t2.crc and res.attempts == 1 and 100 <= res.apply_sample <= len(got)
    assert link.stats.seq_gaps == 0
    cnt = np.array([s[0] for s in got])
    assert np.array_equal(cnt, np.arange(len(got)))
    k = res.apply_sample
    dr = D.DeviceRun.from_log(log)
    before = run_words(t1, dr.freq, dr.rate, dr.mode)["out"][:k]
    after = run_words(t2, dr.freq[k:], dr.rate[k:], dr.mode[k:])["out"]     # restart at k with the new table
    expect = np.concatenate([before, after])[:len(got)]
    assert np.array_equal(np.array([s[4] for s in got]), expect)
    assert not np.array_equal(expect, run_words(t1, dr.freq, dr.rate, dr.mode)["out"][:len(got)])


def _raw_table_request(link, data):
    fr = link.request(SL.T_TABLE, data, lambda f, s: SL.is_reply_to(f, SL.T_TABLE, s), 3.0)
    assert fr is not None
    return fr.type, SL.Reply.unpack(fr.payload)


def _with_words(words):
    words = list(words)
    words[-1] = T.crc32_words(words[:-1])
    return struct.pack(f"<{len(words)}I", *words)


def test_device_refuses_bad_crc_and_out_of_range_tables(run):
    log, t1, t2 = run["log"], run["table"], run["table2"]
    good = t2.to_words()
    bad_crc = bytearray(t2.to_bytes())
    bad_crc[-1] ^= 1
    range_words = list(good)
    range_words[T.FIELD_INDEX["combiner"]] = 7
    overflow_words = list(good)
    overflow_words[T.FIELD_INDEX["m_0"]] = F.INT32_SYM
    overflow_words[T.FIELD_INDEX["m_4"]] = F.INT32_SYM
    with PtyDevice(log, t1, speed=200.0) as pd:
        link = SL.HostLink(pd.port)
        cases = [(bytes(bad_crc), SL.R_TABLE_CRC, "CRC-32 mismatch"),
                 (_with_words(range_words), SL.R_TABLE_RANGE, "combiner 7"),
                 (_with_words(overflow_words), SL.R_TABLE_RANGE, "exceeds 2^31 - 1"),
                 (t2.to_bytes()[:-2], SL.R_TABLE_FORMAT, "not a table"),
                 (_with_words([0xDEADBEEF] + good[1:]), SL.R_TABLE_FORMAT, "bad magic")]
        for data, code, text in cases:
            ftype, reply = _raw_table_request(link, data)
            assert ftype == SL.T_NACK and reply.code == code and text in reply.text, (code, reply)
        assert pd.dev.table.crc == t1.crc and len(pd.dev.switches) == 1
        assert pd.dev.stats.uploads_refused == len(cases)
        assert link.read_table() == t1.to_bytes()
        # a request of a newer protocol major is refused with a reason
        seq = link.tx_seq
        link.port.write(SL.encode_frame(SL.T_READ_TABLE, seq, b"", major=2))
        link.tx_seq += 1
        deadline = time.monotonic() + 3
        reply = None
        while reply is None and time.monotonic() < deadline:
            for fr in link.poll():
                if SL.is_reply_to(fr, SL.T_READ_TABLE, seq):
                    reply = SL.Reply.unpack(fr.payload)
        assert reply is not None and reply.code == SL.R_VERSION and "2.0" in reply.text


def test_table_payload_reason_follows_the_first_failing_check_of_table(run):
    """The device's TABLE check is firmware_ref.table.Table's own reader: its message, and a reason
    code for the check that failed first (format before CRC-32 before field ranges), also when
    several are broken at once."""
    t2 = run["table2"]
    good = t2.to_words()
    bad_crc = list(good)
    bad_crc[-1] ^= 1
    bad_field = list(good)
    bad_field[T.FIELD_INDEX["combiner"]] = 7
    bad_field[-1] = T.crc32_words(bad_field[:-1])
    bad_field_and_crc = list(bad_field)
    bad_field_and_crc[-1] ^= 1
    bad_magic_and_crc = [0xDEADBEEF] + bad_crc[1:]
    bad_nparams = list(good)
    bad_nparams[T.FIELD_INDEX["aux_nparams"]] = 3
    bad_nparams[-1] = T.crc32_words(bad_nparams[:-1])
    # a legal table (Table checks pass) whose k0 = (2^31 - 1) * 2^0 deg/h exceeds the OUT word
    big = dataclasses.replace(t2, mant=(F.INT32_SYM,) + (0,) * 16, e_row=(0, 0, 0, 0), e_7=0, e_acc=0)
    pack = lambda w: struct.pack(f"<{len(w)}I", *w)
    cases = [(t2.to_bytes(), SL.R_OK, ""),
             (b"", SL.R_TABLE_FORMAT, "not a table"),
             (t2.to_bytes()[:-1], SL.R_TABLE_FORMAT, "not a whole number of 32-bit words"),
             (pack(good[:10]), SL.R_TABLE_FORMAT, "10 words"),
             (pack(bad_crc), SL.R_TABLE_CRC, "CRC-32 mismatch"),
             (pack(bad_field), SL.R_TABLE_RANGE, "combiner 7"),
             (pack(bad_field_and_crc), SL.R_TABLE_CRC, "CRC-32 mismatch"),
             (pack(bad_magic_and_crc), SL.R_TABLE_FORMAT, "bad magic"),
             (pack(bad_nparams), SL.R_TABLE_FORMAT, "aux_nparams"),
             (big.to_bytes(), SL.R_TABLE_RANGE, "exceeds the output word")]
    for data, code, text in cases:
        table, got, msg = SL.validate_table_payload(data)
        assert got == code and text in msg and (table is None) == (code != SL.R_OK), (code, got, msg)
    assert SL.table_problems(t2) == [] and SL.table_problems(big)


def test_host_refuses_bad_tables_before_sending(run, tmp_path):
    log, t1, t2 = run["log"], run["table"], run["table2"]
    overflow = copy.copy(t2)                # a table object that skipped validation (Table() validates)
    overflow.mant = (F.INT32_SYM,) * 17
    q2 = quantize(run["model2"], n_random=16)
    good_json = tmp_path / "table.json"
    q2.to_json(good_json)
    bad_json = tmp_path / "bad.json"
    d = json.loads(good_json.read_text())
    d["words"][T.FIELD_INDEX["m_0"]] = "0x7fffffff"                   # hand-edited: CRC no longer matches
    bad_json.write_text(json.dumps(d))
    from host_tools.cli import upload as upload_cmd
    parser = argparse.ArgumentParser(prog="hdrg upload")
    upload_cmd.configure(parser)
    with PtyDevice(log, t1, speed=200.0) as pd:
        link = SL.HostLink(pd.port)
        with pytest.raises(T.TableError, match="refused before sending"):
            SL.upload(link, overflow)
        args = parser.parse_args(["--port", pd.name, str(bad_json)])
        with pytest.raises(T.TableError, match="refused before sending.*CRC-32 mismatch"):
            upload_cmd.run(args)
        time.sleep(0.1)
        assert pd.dev.stats.requests == 0 and pd.dev.table.crc == t1.crc     # nothing was sent
        args = parser.parse_args(["--port", pd.name, str(good_json)])
        assert upload_cmd.run(args) == 0
        assert pd.dev.table.crc == t2.crc == q2.table.crc


def test_upload_without_answer_times_out(tmp_path, run):
    master, slave, name = D.open_pty()               # nobody on the other end
    port = SL.open_port(name)
    try:
        with pytest.raises(SL.ProtocolError, match="no INFO frame"):
            SL.upload(SL.HostLink(port), run["table"], timeout_s=0.2, retries=1)
    finally:
        port.close()
        os.close(master)
        os.close(slave)


# -- versions, rates, URLs -----------------------------------------------------------------------------------

def test_version_negotiation(run, tmp_path):
    log = run["log"].select(np.arange(30))
    frames = split_frames(record_stream(log, run["table"]))
    dec = [SL.Decoder().feed(f)[0] for f in frames]
    # a newer minor (1.9): longer payloads (extra trailing fields) are read, extras ignored
    newer = b"".join(SL.encode_frame(f.type, f.seq, f.payload + b"\x01\x02\x03\x04", minor=9) if f.type == SL.T_SAMPLE
                     else SL.encode_frame(f.type, f.seq, bytes([1, 9]) + f.payload[2:], minor=9) for f in dec)
    res = replay(newer, tmp_path / "n.csv")
    assert res.samples == 30 and res.info.minor == 9
    assert words_of(runlog.read(tmp_path / "n.csv"))["out"].tolist() == \
        [SL.unpack_sample(f.payload)[4] for f in dec if f.type == SL.T_SAMPLE]
    # a newer major: refused with a clear message, nothing written
    info2 = SL.DeviceInfo(major=2, minor=0, name="future").pack()
    stream = SL.encode_frame(SL.T_INFO, 0, info2, major=2) + b"".join(frames[1:])
    with pytest.raises(SL.ProtocolVersionError, match="protocol 2.0.*update hdrg"):
        replay(stream, tmp_path / "f.csv")
    assert not (tmp_path / "f.csv").exists() or (tmp_path / "f.csv").read_text() == ""


def test_realtime_device_drops_frames_the_link_cannot_take_and_host_counts_them(tmp_path):
    log = sim.simulate("static", seed=1, duration_s=30000.0)
    table = D.identity_table(log)
    with PtyDevice(log, table, speed=30000.0) as pd:       # 1 s of frames; the host is not reading yet
        deadline = time.monotonic() + 20
        while pd.dev.stats.frames_dropped == 0 and time.monotonic() < deadline:
            time.sleep(0.02)
        res = SL.capture(pd.port, tmp_path / "r.csv", idle_timeout_s=5.0)
    assert res.reason == "the device reports the end of its run"
    dropped = pd.dev.stats.frames_dropped
    assert dropped > 0 and res.seq_gaps == dropped
    assert res.samples + dropped == len(log) and res.crc_errors == 0


def test_device_on_loop_url_and_capture_from_loop_url(run, tmp_path):
    import serial

    port = serial.serial_for_url("loop://", timeout=0)
    dev = D.VirtualDevice(D.PortLink(port), D.DeviceRun.from_log(run["log"].select(np.arange(20))), run["table"],
                          speed=0.0)
    dev.start()
    deadline = time.monotonic() + 10
    while not dev.ended and time.monotonic() < deadline:
        time.sleep(0.01)
    assert dev.stop(5.0) and dev.ended and dev.error is None
    assert dev.stats.requests == 0 and dev.stats.samples_sent == 20      # its own echoed frames are no requests
    port.close()
    # the host side on a loop:// URL: the stream written into the loop is captured back
    stream = record_stream(run["log"].select(np.arange(20)), run["table"])
    loop = SL.open_port("loop://")
    loop.write(stream)
    res = SL.capture(loop, tmp_path / "l.csv", idle_timeout_s=1.0)
    loop.close()
    assert res.samples == 20 and res.reason == "the device reports the end of its run"


# -- CLIs ---------------------------------------------------------------------------------------------------

def test_cli_device_on_pty_capture_and_ctrl_c(tmp_path):
    code = ("import argparse, sys\n"
            "from host_tools.cli import device\n"
            "p = argparse.ArgumentParser(prog='hdrg device'); device.configure(p)\n"
            "sys.exit(device.run(p.parse_args(sys.argv[1:])))\n")
    # Ctrl-C must reach the child even when the tests run as a background job (a shell without
    # job control starts them with SIGINT ignored, the child inherits that and Python then installs
    # no KeyboardInterrupt handler): the child starts with SIGINT's default disposition
    proc = subprocess.Popen([sys.executable, "-c", code, "--pty", "--scenario", "static", "--duration", "600",
                             "--speed", "0", "--name", "cli-gyro"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        import select
        ready, _, _ = select.select([proc.stdout], [], [], 60)
        assert ready, "the device did not print its port within 60 s"
        first = proc.stdout.readline()
        assert first.startswith("hdrg device: virtual gyroscope on /dev/"), first + proc.stderr.read()
        name = first.split(" on ", 1)[1].strip()
        from host_tools.cli import capture as capture_cmd
        parser = argparse.ArgumentParser(prog="hdrg capture")
        capture_cmd.configure(parser)
        args = parser.parse_args(["--port", name, "-o", str(tmp_path / "cli.csv"), "--duration", "200",
                                  "--idle-timeout", "20"])
        assert capture_cmd.run(args) == 0
        cap = runlog.read(tmp_path / "cli.csv")
        assert len(cap) == 200 and cap.metadata["device"] == "cli-gyro"
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=5)
    assert proc.returncode == 0, err
    assert "sent" in out and "samples" in out


def test_device_refuses_a_table_of_the_other_mode(run, tmp_path, capsys):
    """An FTR table on a mode-reversal run is refused with NACK R_TABLE_MODE and a
    reason (offline `hdrg compensate` refuses the same pairing); the CLI says so in one line."""
    from host_tools import cli

    ftr_log = sim.simulate("static", seed=1, duration_s=600)
    ftr_table = D.identity_table(ftr_log)
    assert ftr_table.combiner == 0
    with PtyDevice(run["log"], run["table"], speed=200.0) as pd:
        link = SL.HostLink(pd.port)
        ftype, reply = _raw_table_request(link, ftr_table.to_bytes())
        assert ftype == SL.T_NACK and reply.code == SL.R_TABLE_MODE
        assert "force-to-rebalance" in reply.text and "mode reversal" in reply.text
        assert pd.dev.table.crc == run["table"].crc and pd.dev.stats.uploads_refused == 1
        with pytest.raises(SL.UploadError, match="force-to-rebalance"):
            SL.upload(link, ftr_table, timeout_s=3.0)
        # the matching table is still accepted
        assert SL.upload(link, run["table2"], timeout_s=3.0).crc == run["table2"].crc
    # a device started with a table of the other mode: refused before it runs
    path = tmp_path / "ftr.json"
    from host_tools.fixed.quantize import quantize as q
    cfg = fit_config_from_logs([ftr_log])
    q(BiasModel(cfg, (), np.zeros(17), source="ftr"), n_random=16).to_json(path)
    rc = cli.main(["device", "--port", "loop://", "--table", str(path), "--scenario", SCENARIO, "--duration", "60"])
    err = capsys.readouterr().err
    assert rc == 2 and "force-to-rebalance" in err and "Traceback" not in err
