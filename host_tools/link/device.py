"""`hdrg device`: a virtual gyroscope controller on a pseudo-terminal (or any pyserial URL).

The simulator (host_tools.simulation.sim) plays the sensor: its run log is converted to input words
(firmware_ref.inputs: drive-frequency F, temperature T, raw rate R, the logged mode) and fed to
the fixed-point firmware reference (firmware_ref.kernel.run_words, bit-identical to the
per-sample Python reference firmware_ref.compensate.Pipeline), which gives the compensated word
OUT, the bias word BIAS, the valid bit, the status flags and the sequencer state of every sample.
The device streams one SAMPLE frame per sample (host_tools.link.frame and host_tools.link.codec,
docs/PROTOCOL.md), in real time or ``speed`` times faster (0: as fast as the link takes them), sends an INFO frame at
start, every ``info_period_s`` seconds, on GET_INFO and when the run ends, and accepts table
uploads:

* TABLE: checked by firmware_ref.table.Table's own reader and constructor, as the host checks it
  (host_tools.link.codec.validate_table_payload: format, CRC-32, field ranges, interval bounds,
  the output word) and against the run's mode (a table whose combiner does not match - FTR
  table on a mode-reversal run or back - is refused with R_TABLE_MODE, as offline
  `hdrg compensate` refuses that pairing); ACK (detail = the table's CRC-32 word, sample =
  counter of the first sample computed with it) or NACK with the reason code and text.
  An accepted table applies from the next sample not yet sent, which the pipeline processes as a
  restart (its state is reset as at power-on, the OUT/BIAS hold restarts at 0): the run from that
  sample on equals ``run_words(new_table, words[k:])``.
* READ_TABLE: the active table's bytes in a TABLE frame.  GET_INFO: INFO.

A table with aux generators (aux_gen 1) runs on the F and T words of the run; the virtual sensor
has no aux_* channel, so its aux words read 0, and its sample counter K restarts with the table.

Without ``--table`` the device starts with the *identity table*: the data flow of the run
(host_tools.golden.compensate.fit_config_from_logs; the pair combiner for a mode-reversal run) with all
17 coefficients 0, quantized by host_tools.fixed.quantize, so OUT is the combined raw output.

When the simulated run ends the device sends INFO with ST_RUN_ENDED and goes on answering
requests.  Writes are paced: at ``speed`` > 0 a frame the link cannot take within one sample
period is dropped (as a UART without flow control would; its sequence number is still used, so
the host counts the gap); at ``speed`` 0 the device waits for the link (back-pressure).  Every
wait is bounded, so :meth:`VirtualDevice.stop` always returns.
"""
from __future__ import annotations

import math
import os
import threading
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from firmware_ref import formats as F
from firmware_ref import inputs
from host_tools.errors import UserError
from host_tools.link import codec as C
from host_tools.link import frame as FR
from host_tools.link.host import HostLink, open_port
from host_tools.link.transport import FdLink, LinkClosed, PortLink, open_pty


# -- the simulated sensor ------------------------------------------------------------------------------

@dataclass
class DeviceRun:
    """The input words of a simulated run (int64 arrays of n samples) and its sample rate [Hz]."""

    freq: np.ndarray
    temp: np.ndarray
    rate: np.ndarray
    mode: np.ndarray
    sat_freq: np.ndarray
    sat_temp: np.ndarray
    sat_rate: np.ndarray
    fs_hz: float
    metadata: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.freq)

    @classmethod
    def from_log(cls, log) -> "DeviceRun":
        """Words of a run log with ``freq_hz`` and ``temp_c`` (firmware_ref.inputs, RHU + saturation)."""
        for col in ("freq_hz", "temp_c"):
            if col not in log:
                raise ValueError(f"{log.source}: the virtual device needs column '{col}'")
        f, fs_ = inputs.freq_words(log["freq_hz"])
        t, ts_ = inputs.temp_words(log["temp_c"])
        r, rs_ = inputs.rate_words(log.rate_dph)
        return cls(f, t, r, np.asarray(log.mode, np.int64), fs_, ts_, rs_, float(log.sample_rate_hz),
                   dict(log.metadata))

    def compute(self, table, start: int = 0) -> dict:
        """The firmware reference over samples ``start .. n-1`` with ``table`` (sample ``start`` is a
        power-on/restart): ``out``, ``bias``, ``valid``, ``flags`` (with FLAG_INPUT_SAT where the
        proxy or rate word saturated), ``state`` (int64/uint8 arrays of n - start)."""
        from firmware_ref.kernel import run_words

        p, psat = (self.freq, self.sat_freq) if table.proxy_kind == 0 else (self.temp, self.sat_temp)
        # an aux generator (aux_gen 1) reads F and T; the virtual sensor has no aux_* channel: its
        # aux words A_c read 0; the sample counter K counts from the table's power-on (start)
        n = self.n - start
        res = run_words(table, p[start:], self.rate[start:], self.mode[start:], detail=True, f=self.freq[start:],
                        t=self.temp[start:], aux=np.zeros((n, F.AUX_MAX_CHANNELS), np.int64))
        sat = (psat | self.sat_rate)[start:]
        if table.aux_gen == 1:
            from firmware_ref.aux import needed_channels
            read = needed_channels(table)
            if F.CH_F in read:
                sat = sat | self.sat_freq[start:]
            if F.CH_T in read:
                sat = sat | self.sat_temp[start:]
        res["flags"] = res["flags"] | np.where(sat, F.FLAG_INPUT_SAT, 0).astype(np.uint8)
        return res


def identity_table(log):
    """The identity table of a run: its data flow (fit_config_from_logs; pair combiner for mode
    reversal; the exchange/dwell times of its metadata) with all coefficients 0."""
    from firmware_ref.terms import N_TERMS
    from host_tools.golden.compensate import fit_config_from_logs
    from host_tools.golden.model import BiasModel
    from host_tools.fixed.quantize import quantize

    cfg = fit_config_from_logs([log], reversal={"combiner": "pair", "order": "combine_first"} if log.reversal else None)
    model = BiasModel(cfg, (), np.zeros(N_TERMS), source="identity table (all coefficients 0)")
    ex = float(log.metadata.get("exchange_s", 30.0))
    dw = float(log.metadata.get("dwell_s", 120.0))
    return quantize(model, exchange_s=ex, dwell_s=dw, n_random=16).table


# -- the device -----------------------------------------------------------------------------------------

@dataclass
class DeviceStats:
    """Counters of the virtual device: samples and frames sent, SAMPLE frames dropped (link not
    ready at speed > 0), requests received, table uploads accepted and refused (NACK)."""

    samples_sent: int = 0
    frames_sent: int = 0
    frames_dropped: int = 0
    requests: int = 0
    uploads_accepted: int = 0
    uploads_refused: int = 0


class VirtualDevice:
    """The virtual controller (see the module doc) on ``link`` (FdLink or PortLink), in a thread.

    ``run``: DeviceRun; ``table``: the initial firmware_ref.table.Table; ``speed``: times real time
    (0: as fast as the link takes); ``batch``: samples per write at speed 0.  :meth:`start`,
    :meth:`stop` (bounded join), :meth:`unplug` (stop and close the link: the host sees the port
    vanish).  ``switches``: (first sample, table) of every table in force; ``error``: an exception
    that ended the thread (None if it ended normally)."""

    CAPS = C.CAP_SAMPLES | C.CAP_TABLE_UPLOAD | C.CAP_TABLE_READ | C.CAP_VIRTUAL

    def __init__(self, link, run: DeviceRun, table, speed: float = 1.0, name: str = "hdrg-virtual",
                 info_period_s: float = 1.0, batch: int = 64, boot_id: int | None = None):
        if not (math.isfinite(speed) and speed >= 0):
            raise ValueError(f"speed must be a finite number >= 0 (0: as fast as possible), not {speed}")
        self.link = link
        self.run = run
        self.speed = float(speed)
        self.name = name
        self.info_period_s = info_period_s
        self.batch = max(1, int(batch))
        self.boot_id = int.from_bytes(os.urandom(4), "little") if boot_id is None else boot_id & 0xFFFFFFFF
        self.fs_q16 = int(round(run.fs_hz * 65536))
        self.stats = DeviceStats()
        self.decoder = FR.Decoder()
        self.switches = []
        self.error = None
        self.closed_reason = ""
        self.i = 0                      # next sample to send
        self.ended = False
        self._tx_seq = 0
        self._stop = threading.Event()
        self._thread = None
        self._lock = threading.Lock()
        self._set_table(table, 0)
        self._in = (run.freq, run.rate, run.temp, run.mode)

    # -- table ------------------------------------------------------------------------------------
    @property
    def table(self):
        return self._table

    def _set_table(self, table, start: int) -> None:
        res = self.run.compute(table, start) if start < self.run.n else None
        self._table = table
        self._table_bytes = table.to_bytes()
        self._res_start = start
        self._res = None if res is None else tuple(res[k] for k in ("out", "bias", "state", "flags", "valid"))
        self.switches.append((start, table))

    # -- frames -----------------------------------------------------------------------------------
    def _frame(self, ftype: int, payload: bytes) -> bytes:
        fr = FR.encode_frame(ftype, self._tx_seq, payload)
        self._tx_seq = (self._tx_seq + 1) & 0xFFFF
        return fr

    def _send(self, data: bytes, deadline=None) -> bool:
        n = self.link.write(data, self._stop, deadline)
        return n == len(data)

    def info(self) -> C.DeviceInfo:
        status = C.ST_RUN_ENDED if self.i >= self.run.n else C.ST_STREAMING
        return C.DeviceInfo(capabilities=self.CAPS, fs_q16=self.fs_q16, table_crc=self._table.crc,
                             status=status, boot_id=self.boot_id, counter=self.i, name=self.name)

    def _send_control(self, ftype: int, payload: bytes) -> None:
        self._send(self._frame(ftype, payload))
        self.stats.frames_sent += 1

    def _send_samples(self, j: int, deadline=None) -> None:
        """Send samples self.i .. j-1 (one write), or drop them when the link is not ready by
        ``deadline``."""
        i, off = self.i, self._res_start
        freq, rate, temp, mode = (a[i:j].tolist() for a in self._in)
        out, bias, state, flags, valid = (a[i - off:j - off].tolist() for a in self._res)
        pack, enc = C.SAMPLE.pack, FR.encode_frame
        parts = []
        seq = self._tx_seq
        for k in range(j - i):
            parts.append(enc(FR.T_SAMPLE, seq, pack((i + k) & 0xFFFFFFFF, freq[k], rate[k], temp[k], out[k], bias[k],
                                                    state[k], mode[k], flags[k], valid[k])))
            seq = (seq + 1) & 0xFFFF
        self._tx_seq = seq
        ok = self._send(b"".join(parts), deadline)
        if ok:
            self.stats.samples_sent += j - self.i
            self.stats.frames_sent += j - self.i
        else:
            self.stats.frames_dropped += j - self.i
        self.i = j

    # -- requests ---------------------------------------------------------------------------------------
    def _handle(self, data: bytes) -> None:
        for fr in self.decoder.feed(data):
            if fr.type in (FR.T_SAMPLE, FR.T_INFO, FR.T_ACK, FR.T_NACK):
                continue                        # our own frames echoed (loop://): not requests
            self.stats.requests += 1
            if fr.major != FR.PROTO_MAJOR:
                self._reply(FR.T_NACK, fr, C.R_VERSION, text=FR.version_message(fr.major, fr.minor))
            elif fr.type == FR.T_GET_INFO:
                self._send_control(FR.T_INFO, self.info().pack())
            elif fr.type == FR.T_READ_TABLE:
                self._send_control(FR.T_TABLE, self._table_bytes)
            elif fr.type == FR.T_TABLE:
                table, code, text = C.validate_table_payload(fr.payload)
                if table is not None:
                    text = C.table_mode_problem(table, bool(np.any(self.run.mode != 0)))
                    if text is not None:
                        table, code = None, C.R_TABLE_MODE
                if table is not None:
                    text = C.rate_mismatch(table, self.fs_q16, "this device")
                    if text is not None:
                        table, code = None, C.R_TABLE_RANGE
                if table is None:
                    self.stats.uploads_refused += 1
                    self._reply(FR.T_NACK, fr, code, text=text)
                else:
                    with self._lock:
                        self._set_table(table, self.i)
                    self.stats.uploads_accepted += 1
                    self._reply(FR.T_ACK, fr, C.R_OK, detail=table.crc, sample=self.i)
            else:
                self._reply(FR.T_NACK, fr, C.R_UNKNOWN_TYPE, text=f"frame type 0x{fr.type:02x} not handled")

    def _reply(self, ftype, fr, code, detail=0, sample=0, text=""):
        self._send_control(ftype, C.Reply(fr.type, code, fr.seq, detail, sample, text).pack())

    # -- the loop ----------------------------------------------------------------------------------------
    def _loop(self) -> None:
        n = self.run.n
        period = 1.0 / (self.run.fs_hz * self.speed) if self.speed > 0 else 0.0
        self._send_control(FR.T_INFO, self.info().pack())
        last_info = time.monotonic()
        next_due = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            streaming = self.i < n
            if not streaming:
                timeout = 0.05
            elif self.speed == 0:
                timeout = 0.0
            else:
                timeout = min(0.05, max(0.0, next_due - now))
            data = self.link.read(timeout)
            if data:
                self._handle(data)
            now = time.monotonic()
            if now - last_info >= self.info_period_s:
                self._send_control(FR.T_INFO, self.info().pack())
                last_info = now
            if self.i < n:
                if self.speed == 0:
                    self._send_samples(min(n, self.i + self.batch))
                elif now >= next_due:
                    k = min(self.batch, 1 + int((now - next_due) / period), n - self.i)
                    self._send_samples(self.i + k, deadline=now + max(period, 0.001))
                    next_due += k * period
                if self.i >= n:
                    self._send_control(FR.T_INFO, self.info().pack())
            if self.i >= n:
                self.ended = True

    def _main(self) -> None:
        try:
            self._loop()
        except LinkClosed as exc:
            self.closed_reason = str(exc)
        except Exception as exc:  # reported by stop() / the CLI
            self.error = exc

    def start(self) -> "VirtualDevice":
        self._thread = threading.Thread(target=self._main, name=f"hdrg-device {self.name}", daemon=True)
        self._thread.start()
        return self

    @property
    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def stop(self, timeout_s: float = 5.0) -> bool:
        """Stop the thread (bounded join); True if it ended."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            return not self._thread.is_alive()
        return True

    def unplug(self, timeout_s: float = 5.0) -> bool:
        """Stop and close the link (the host's port reports an error / end of data)."""
        ok = self.stop(timeout_s)
        self.link.close()
        return ok

    def close(self) -> None:
        self.unplug()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.unplug()
        return False


def _power_on_samples(mode) -> int:
    """Samples of the exchange (mode 3) that a mode-reversal run starts with (its power-on)."""
    mode = np.asarray(mode)
    other = np.flatnonzero(mode != 3)
    return int(other[0]) if other.size else len(mode)


def short_run_problem(log, table, valid) -> str | None:
    """Why no sample of ``log`` run with ``table`` has a valid compensated output (``valid``: the
    device's valid bits), with the numbers of the run and of the table's schedule; None when
    some sample has one."""
    if np.any(valid):
        return None
    fs = float(log.sample_rate_hz)
    n = len(log)
    head = f"none of the run's {n} samples ({n / fs:g} s at {fs:g} Hz) has a valid compensated output " \
           f"(OUT and BIAS stay held at 0)"
    if table.combiner != 0:
        lead, dwell, exch = _power_on_samples(log.mode), table.dwell_n, table.exchange_n
        need = lead + dwell + exch
        return (f"{head}: the mode-reversal schedule needs the power-on exchange ({lead / fs:g} s), one mode-1 "
                f"window ({dwell / fs:g} s) and one exchange ({exch / fs:g} s), {need / fs:g} s, before its first "
                f"output: give a duration above {need / fs:g} s")
    need = table.power_on_n + max(table.rate_warmup, 1)
    return (f"{head}: the table's power-on ({table.power_on_n} samples) and rate warm-up ({table.rate_warmup} "
            f"samples) cover the whole run: give a duration above {need / fs:g} s")


def make_device(scenario: str = "paper-mr-cycle-4dpm", seed: int = 0, duration_s: float | None = None,
                sample_rate_hz: float = 1.0, table=None, link=None, **kw):
    """A VirtualDevice on a new pty (``link`` None) or on ``link``: ``(device, port_name, log)``.
    ``duration_s`` [s] (None: the scenario's), ``sample_rate_hz`` [Hz].  ``table`` None: the
    identity table of the run; a table of the other mode (FTR / mode reversal) or quantized at
    another sample rate is refused (UserError).  A mode-reversal run that is all power-on exchange
    is refused (nothing to compensate, no data for the identity table); a run too short for any
    valid compensated output is run with a warning that says why."""
    from host_tools.simulation import sim

    fs_q16 = int(round(sample_rate_hz * 65536))
    if table is not None:
        problem = C.rate_mismatch(table, fs_q16, "the device")
        if problem is not None:
            raise UserError(f"--table: {problem} (or run the device at --rate {table.fs_q16 / 65536:g})")
    log = sim.simulate(scenario, seed=seed, duration_s=duration_s, sample_rate_hz=sample_rate_hz)
    fs = float(log.sample_rate_hz)
    if log.reversal and _power_on_samples(log.mode) == len(log):
        ex = float(log.metadata.get("exchange_s", 30.0))
        dw = float(log.metadata.get("dwell_s", 120.0))
        raise UserError(f"the run of {len(log)} samples ({len(log) / fs:g} s) is all the power-on exchange "
                        f"(mode 3, the first {ex:g} s of a mode-reversal run of scenario {scenario}): nothing to "
                        f"compensate and no data for the identity table; give a duration above {2 * ex + dw:g} s "
                        f"(power-on exchange {ex:g} s, one {dw:g} s window, one {ex:g} s exchange) for a first "
                        f"compensated output")
    if table is None:
        table = identity_table(log)
    problem = C.table_mode_problem(table, log.reversal)
    if problem is not None:
        raise ValueError(f"--table: {problem} (scenario {scenario})")
    if link is None:
        master, slave, name = open_pty()
        link = FdLink(master, keep=(slave,), name=name)
    kw.setdefault("name", f"hdrg-virtual ({scenario}, seed {seed})")
    dev = VirtualDevice(link, DeviceRun.from_log(log), table, **kw)
    problem = short_run_problem(log, table, dev._res[4] if dev._res is not None else ())
    if problem is not None:
        warnings.warn(problem, stacklevel=2)
    return dev, link.name, log


# -- benchmark --------------------------------------------------------------------------------------

def link_benchmark(n_frames: int = 20000, batch: int = 64) -> dict:
    """Sustained SAMPLE frames/s from the virtual device (speed 0) to a HostLink over a pty
    (decoding and sequence checks included; setup excluded).  Returns frames, seconds,
    frames_per_s, bytes_per_s, crc_errors, seq_gaps."""
    dev, name, _ = make_device("static", duration_s=float(n_frames), speed=0.0, batch=batch)
    port = open_port(name)
    try:
        link = HostLink(port)
        got = 0
        dev.start()
        t0 = time.perf_counter()
        deadline = time.monotonic() + 120.0
        while got < n_frames and time.monotonic() < deadline:
            got += sum(1 for fr in link.poll() if fr.type == FR.T_SAMPLE)
        dt = time.perf_counter() - t0
    finally:
        dev.unplug()
        port.close()
    frame = FR.OVERHEAD + C.SAMPLE.size
    return {"frames": got, "seconds": dt, "frames_per_s": got / dt, "bytes_per_s": got * frame / dt,
            "crc_errors": link.decoder.stats.crc_errors, "seq_gaps": link.stats.seq_gaps}


def decode_benchmark(n_frames: int = 50000) -> dict:
    """Decoder throughput on an in-memory stream of SAMPLE frames: frames/s."""
    stream = b"".join(FR.encode_frame(FR.T_SAMPLE, i, C.pack_sample(i, 1 << 30, -5, 20 << 16, 7, 3, 2, 1, 0, 1))
                      for i in range(n_frames))
    dec = FR.Decoder()
    t0 = time.perf_counter()
    got = 0
    for k in range(0, len(stream), 4096):
        got += len(dec.feed(stream[k:k + 4096]))
    dt = time.perf_counter() - t0
    return {"frames": got, "seconds": dt, "frames_per_s": got / dt}


def serve(dev: VirtualDevice, exit_at_end: bool = False, poll_s: float = 0.1) -> None:
    """Run ``dev`` (started here) until its link closes, Ctrl-C, or - with ``exit_at_end`` - the
    end of its simulated run; then unplug it.  ``poll_s``: how often the state is looked at [s].
    Returns nothing; ``dev.stats``, ``dev.closed_reason`` and ``dev.error`` tell what happened."""
    dev.start()
    try:
        while dev.alive and not (exit_at_end and dev.ended):
            time.sleep(poll_s)
    except KeyboardInterrupt:
        pass
    finally:
        dev.unplug()
