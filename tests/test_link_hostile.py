"""The serial link against a device that does not fit or does not behave: a table of another
sample rate or word formats, device texts with control characters, a device that never sends a
usable INFO or sample, the capture's output format, option values out of range, a run too short
for the device's schedule.  Each case ends in a one-line error naming the cause, a warning with
the numbers, or the right result; every wait is bounded (a capture that would not end is stopped
by its ``stop`` callback and the test fails)."""
from __future__ import annotations

import itertools
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from firmware_ref import formats as F
from host_tools import cli
from host_tools import link as SL
from host_tools.golden import runlog
from host_tools.link import device as D
from pty_device import PtyDevice
from host_tools.simulation import sim

SCENARIO = "paper-mr-cycle-4dpm"
EVIL = "gyro\x1b[2K\r\nhdrg upload: uploaded, read back and compared: identical\x07\u202e"


# -- helpers ---------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    """A 1 Hz mode-reversal run with its identity table, and the identity table of the same scenario
    at 10 Hz; both tables also as .bin files."""
    log1 = sim.simulate(SCENARIO, seed=2, duration_s=400.0)
    log10 = sim.simulate(SCENARIO, seed=2, duration_s=400.0, sample_rate_hz=10.0)
    t1, t10 = D.identity_table(log1), D.identity_table(log10)
    d = tmp_path_factory.mktemp("tables")
    (d / "t1.bin").write_bytes(t1.to_bytes())
    (d / "t10.bin").write_bytes(t10.to_bytes())
    return {"log": log1, "t1": t1, "t10": t10, "t1_bin": d / "t1.bin", "t10_bin": d / "t10.bin"}


class Scripted:
    """A fake device on a pty: a thread that writes ``chatter()`` (bytes, may be b"") every
    ``period_s`` and ``answer(frame)`` (bytes) for every request frame it decodes."""

    def __init__(self, answer=None, chatter=None, period_s: float = 0.01):
        master, slave, self.name = D.open_pty()
        self.link = D.FdLink(master, keep=(slave,), name=self.name)
        self.answer, self.chatter, self.period_s = answer, chatter, period_s
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        dec = SL.Decoder()
        try:
            while not self.stop.is_set():
                for fr in dec.feed(self.link.read(self.period_s)):
                    if self.answer is not None:
                        self.link.write(self.answer(fr), self.stop)
                if self.chatter is not None:
                    self.link.write(self.chatter(), self.stop)
        except D.LinkClosed:
            pass

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join(5)
        self.link.close()
        assert not self.thread.is_alive()
        return False


def info_frame(seq=0, **kw) -> bytes:
    kw.setdefault("capabilities", SL.CAP_SAMPLES | SL.CAP_TABLE_UPLOAD | SL.CAP_TABLE_READ)
    return SL.encode_frame(SL.T_INFO, seq, SL.DeviceInfo(**kw).pack())


def bounded_capture(port, path, limit_s=15.0, **kw):
    """SL.capture stopped after ``limit_s`` at the latest (reason 'stopped': it did not end itself)."""
    t0 = time.monotonic()
    res = SL.capture(port, path, stop=lambda: time.monotonic() - t0 > limit_s, **kw)
    return res, time.monotonic() - t0


# -- 1. sample rate and word formats -------------------------------------------------------------------------

def test_upload_of_a_table_of_another_sample_rate_is_refused_with_both_rates(tables, capsys):
    assert tables["t10"].fs_q16 == 10 << 16 and tables["t1"].fs_q16 == 1 << 16
    with PtyDevice(tables["log"], tables["t1"]) as pd:
        rc = cli.main(["upload", str(tables["t10_bin"]), "--port", pd.name, "--timeout", "3"])
        err = capsys.readouterr().err
        assert rc == 2 and err.count("\n") == 1 and "Traceback" not in err
        assert "quantized for 10 Hz" in err and "samples at 1 Hz" in err and "quantize a model" in err
        time.sleep(0.1)
        assert pd.dev.table.crc == tables["t1"].crc and pd.dev.stats.uploads_accepted == 0
        # the device itself refuses it too (a host that skips the check)
        link = SL.HostLink(SL.open_port(pd.name))
        try:
            fr = link.request(SL.T_TABLE, tables["t10"].to_bytes(), lambda f, s: SL.is_reply_to(f, SL.T_TABLE, s), 3.0)
        finally:
            link.port.close()
        reply = SL.Reply.unpack(fr.payload)
        assert fr.type == SL.T_NACK and reply.code == SL.R_TABLE_RANGE and "10 Hz" in reply.text
        assert pd.dev.table.crc == tables["t1"].crc
        # the right rate is still accepted
        assert cli.main(["upload", str(tables["t1_bin"]), "--port", pd.name, "--timeout", "3"]) == 0
        assert "1 Hz" in capsys.readouterr().out


def test_device_with_a_table_of_another_sample_rate_is_refused(tables, capsys):
    rc = cli.main(["device", "--port", "loop://", "--table", str(tables["t10_bin"]), "--rate", "1",
                   "--duration", "200", "--speed", "0", "--exit-at-end"])
    err = capsys.readouterr().err
    assert rc == 2 and "quantized for 10 Hz" in err and "samples at 1 Hz" in err and "Traceback" not in err
    rc = cli.main(["device", "--port", "loop://", "--table", str(tables["t10_bin"]), "--rate", "10",
                   "--duration", "200", "--speed", "0", "--exit-at-end"])
    assert rc == 0, capsys.readouterr().err


@pytest.mark.parametrize("field,delta", [("freq_frac", 3), ("temp_frac", -1), ("rate_frac", 2), ("out_frac", 1)])
def test_upload_to_a_device_of_other_word_formats_is_refused(tables, field, delta):
    host = {"freq_frac": F.FREQ_FRAC, "temp_frac": F.TEMP_FRAC, "rate_frac": F.RATE_FRAC, "out_frac": F.OUT_FRAC}
    port = SL.open_port("loop://")
    try:
        port.write(info_frame(fs_q16=tables["t1"].fs_q16, **{field: host[field] + delta}))
        with pytest.raises(SL.UploadError, match=f"{field} {host[field] + delta} \\(this hdrg: {host[field]}\\)"):
            SL.upload(SL.HostLink(port), tables["t1"], timeout_s=1.0, retries=1)
    finally:
        port.close()
    # the same INFO with the host's formats passes the check (and then waits for an ACK)
    port = SL.open_port("loop://")
    try:
        port.write(info_frame(fs_q16=tables["t1"].fs_q16))
        with pytest.raises(SL.UploadError, match="no ACK/NACK"):
            SL.upload(SL.HostLink(port), tables["t1"], timeout_s=0.3, retries=1)
    finally:
        port.close()


# -- 2. device texts are escaped ---------------------------------------------------------------------------------

def _one_clean_line(text: str) -> None:
    assert text.count("\n") == 1 and text.endswith("\n")
    assert not any(c in text[:-1] for c in "\x1b\r\n\x07\u202e"), repr(text)


def test_device_name_and_nack_text_are_printed_escaped(tables, capsys):
    with PtyDevice(tables["log"], tables["t1"], name=EVIL) as pd:
        assert cli.main(["upload", str(tables["t1_bin"]), "--port", pd.name, "--timeout", "3"]) == 0
    out = capsys.readouterr().out
    _one_clean_line(out)
    assert "gyro\\x1b[2K\\r\\nhdrg upload" in out and "\\u202e" in out

    def nack(fr):
        if fr.type == SL.T_GET_INFO:
            return info_frame(fs_q16=tables["t1"].fs_q16, name=EVIL)
        return SL.encode_frame(SL.T_NACK, 1, SL.Reply(fr.type, SL.R_TABLE_RANGE, fr.seq, text=EVIL).pack())

    with Scripted(answer=nack) as dev:
        rc = cli.main(["upload", str(tables["t1_bin"]), "--port", dev.name, "--timeout", "3"])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("hdrg upload: error: the device refused the table")
    _one_clean_line(err)
    assert "\\x1b[2K\\r\\n" in err and "\\x07" in err
    assert SL.printable("a\\b\x00\x9f\u2028") == "a\\\\b\\x00\\x9f\\u2028"


# -- 3. a capture ends whatever the device sends -------------------------------------------------------------------

FTR_STATE = F.STATE_MODE.index(0)


def _sample(counter, state=FTR_STATE) -> bytes:
    """A SAMPLE of an FTR run (mode 0) at ``counter``; ``state``: the sequencer state it claims."""
    return SL.pack_sample(counter, 6227 << F.FREQ_FRAC, 1000, 25 << F.TEMP_FRAC, 0, 0, state, 0, 0, 1)


CHATTER = {
    "nothing": dict(),
    "garbage": dict(chatter=lambda: bytes(np.random.default_rng().integers(0, 256, 512, dtype=np.uint8))),
    "partial frames": dict(chatter=lambda: info_frame(name="x" * 40)[:30] + SL.SYNC + b"\x10\x02"),
    "repeated NACKs": dict(chatter=lambda: SL.encode_frame(SL.T_NACK, 0, SL.Reply(SL.T_GET_INFO, 1, 0,
                                                                                    text="no").pack()),
                           answer=lambda fr: SL.encode_frame(SL.T_NACK, 0, SL.Reply(fr.type, 1, fr.seq).pack())),
    "bad INFO and samples": dict(chatter=lambda: SL.encode_frame(SL.T_INFO, 0, b"\x01\x00\x01")
                                 + SL.encode_frame(SL.T_SAMPLE, 0, _sample(5))),
}


@pytest.mark.parametrize("kind", list(CHATTER))
def test_capture_without_a_usable_info_ends_on_its_limits(tmp_path, kind):
    with Scripted(**CHATTER[kind]) as dev:
        port = SL.open_port(dev.name)
        try:
            res, took = bounded_capture(port, tmp_path / "c.csv", idle_timeout_s=1.0)
            assert res.reason.startswith("no usable INFO frame from the device within 1 s"), res.reason
            assert took < 5 and not res.written and not (tmp_path / "c.csv").exists()
            res, took = bounded_capture(port, tmp_path / "c.csv", duration_s=1.0, idle_timeout_s=None)
            assert res.reason.startswith("no usable INFO frame from the device within 1 s"), res.reason
            assert took < 5 and not res.written
        finally:
            port.close()
    if kind == "repeated NACKs":
        assert res.ignored_replies > 0 and "ACK/NACK/TABLE" in res.reason


@pytest.mark.parametrize("kind", ["INFO only", "stale samples", "repeated frame"])
def test_capture_after_info_ends_when_no_new_sample_comes(tmp_path, kind):
    seq = itertools.count()

    def chatter():
        if kind == "repeated frame":
            return info_frame(0, boot_id=9)
        fr = info_frame(next(seq), boot_id=9)
        return fr if kind == "INFO only" else fr + SL.encode_frame(SL.T_SAMPLE, next(seq), _sample(3))

    with Scripted(chatter=chatter, period_s=0.02) as dev:
        port = SL.open_port(dev.name)
        try:
            res, took = bounded_capture(port, tmp_path / "s.csv", duration_s=5.0, idle_timeout_s=1.0)
        finally:
            port.close()
    assert res.reason.startswith("no new sample from the device for 1 s"), res.reason
    assert took < 5 and res.samples == (1 if kind == "stale samples" else 0)
    assert (res.out_of_order if kind == "stale samples" else res.duplicates if kind == "repeated frame" else 1) > 0


def test_cli_capture_from_a_silent_device_ends_with_an_error(tmp_path):
    with Scripted() as dev:
        t0 = time.monotonic()
        proc = subprocess.run([sys.executable, "-m", "host_tools.cli", "capture", "--port", dev.name, "-o",
                               str(tmp_path / "c.csv"), "--duration", "1", "--idle-timeout", "0", "--quiet"],
                              capture_output=True, text=True, timeout=60)
        took = time.monotonic() - t0
    assert proc.returncode == 1 and took < 30, proc.stderr
    assert "hdrg capture: error: nothing recorded: no usable INFO frame from the device within 1 s" in proc.stderr


# -- 4. the output format follows the file name --------------------------------------------------------------------

def _stream(n: int) -> bytes:
    frames = [info_frame(boot_id=7, name="npz")]
    frames += [SL.encode_frame(SL.T_SAMPLE, 1 + i, _sample(i)) for i in range(n)]
    frames.append(info_frame(n + 1, boot_id=7, name="npz", status=SL.ST_RUN_ENDED))
    return b"".join(frames)


def test_capture_to_npz_writes_npz_and_other_suffixes_are_refused(tmp_path, capsys, monkeypatch):
    port = SL.open_port("loop://")
    try:
        port.write(_stream(12))
        res = SL.capture(port, tmp_path / "x.npz", idle_timeout_s=2.0)
    finally:
        port.close()
    assert res.written and res.samples == 12
    assert (tmp_path / "x.npz").read_bytes()[:2] == b"PK" and not (tmp_path / "x.npz.part.csv").exists()
    log = runlog.read(tmp_path / "x.npz")
    assert len(log) == 12 and log.metadata["capture"] == "complete" and log.metadata["device"] == "npz"
    assert np.array_equal(log.t_s, np.arange(12.0))
    # the NPZ cannot be written (here: a full disk): the CSV is kept, the error says so
    def full(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(runlog, "write_npz", full)
    port = SL.open_port("loop://")
    try:
        port.write(_stream(12))
        with pytest.raises(SL.CaptureOutputError, match="cannot write the NPZ run log.*kept as .*y.npz.part.csv"):
            SL.capture(port, tmp_path / "y.npz", idle_timeout_s=2.0)
    finally:
        port.close()
    assert not (tmp_path / "y.npz").exists() and len(runlog.read(tmp_path / "y.npz.part.csv")) == 12
    monkeypatch.undo()
    # CSV by name, as before
    port = SL.open_port("loop://")
    try:
        port.write(_stream(5))
        assert SL.capture(port, tmp_path / "x.CSV", idle_timeout_s=2.0).samples == 5
    finally:
        port.close()
    assert (tmp_path / "x.CSV").read_text().startswith("# capture: complete")
    for name in ("x.txt", "x", "x.npz.tmp"):
        rc = cli.main(["capture", "--port", "loop://", "-o", str(tmp_path / name), "--quiet"])
        err = capsys.readouterr().err
        assert rc == 2 and ".csv or .npz" in err and not (tmp_path / name).exists(), err


# -- 5. option values ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("argv,needle", [
    (["upload", "T", "--port", "loop://", "--timeout", "nan"], "--timeout nan"),
    (["upload", "T", "--port", "loop://", "--timeout", "1e9"], "(0, 60]"),
    (["upload", "T", "--port", "loop://", "--timeout", "0"], "--timeout 0"),
    (["upload", "T", "--port", "loop://", "--timeout", "-2"], "--timeout -2"),
    (["upload", "T", "--port", "loop://", "--baud", "-1"], "--baud -1"),
    (["upload", "T", "--port", "loop://", "--baud", "0"], "--baud 0"),
    (["upload", "T", "--port", "loop://", "--retries", "0"], "--retries 0"),
    (["upload", "T", "--port", "nosuch://x"], "--port nosuch://x: cannot open"),
    (["capture", "--port", "nosuch://x", "-o", "OUT"], "--port nosuch://x: cannot open"),
    (["capture", "--port", "loop://", "-o", "OUT", "--baud", "0"], "--baud 0"),
    (["device", "--port", "nosuch://x"], "--port nosuch://x: cannot open"),
    (["device", "--port", "loop://", "--baud", "-1"], "--baud -1"),
    (["device", "--pty", "--speed", "nan"], "--speed nan"),
    (["device", "--pty", "--speed", "inf"], "--speed inf"),
    (["device", "--pty", "--speed", "-1"], "--speed -1"),
    (["device", "--pty", "--rate", "0"], "--rate 0"),
    (["device", "--pty", "--duration", "nan"], "--duration nan"),
])
def test_bad_option_values_are_one_line_errors_naming_the_option(tables, tmp_path, argv, needle):
    argv = [str(tables["t1_bin"]) if a == "T" else str(tmp_path / "o.csv") if a == "OUT" else a for a in argv]
    # in a process: a command that accepted the value could wait or serve until stopped
    proc = subprocess.run([sys.executable, "-m", "host_tools.cli", *argv], capture_output=True, text=True,
                          timeout=60)
    rc, err = proc.returncode, proc.stderr
    assert rc == 2 and needle in err and "Traceback" not in err, err
    assert err.strip().splitlines()[-1].startswith(f"hdrg {argv[0]}: error: ")
    assert "no INFO frame" not in err


def test_library_timeouts_are_checked():
    port = SL.open_port("loop://")
    try:
        link = SL.HostLink(port)
        for bad in (float("nan"), 0.0, -1.0, 1e9, float("inf")):
            with pytest.raises(ValueError, match="timeout .*must be a number of seconds in \\(0, 60\\]"):
                link.get_info(bad)
    finally:
        port.close()
    with pytest.raises(SL.PortError, match="baud rate -1"):
        SL.open_port("loop://", -1)


# -- 6. a run too short for the device's schedule -----------------------------------------------------------------

def test_short_device_runs_name_the_schedule(capsys):
    rc = cli.main(["device", "--port", "loop://", "--duration", "20", "--speed", "0", "--exit-at-end"])
    err = capsys.readouterr().err
    assert rc == 2 and "no training samples" not in err and "Traceback" not in err
    assert "20 samples (20 s)" in err and "power-on exchange" in err and "above 180 s" in err
    rc = cli.main(["device", "--port", "loop://", "--duration", "60", "--speed", "0", "--exit-at-end"])
    err = capsys.readouterr().err
    assert rc == 0 and "hdrg device: warning: none of the run's 60 samples" in err and "180 s" in err
    rc = cli.main(["device", "--port", "loop://", "--duration", "300", "--speed", "0", "--exit-at-end"])
    assert rc == 0 and "warning" not in capsys.readouterr().err
