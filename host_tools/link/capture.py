"""Run-log capture over the serial link (`hdrg capture`, docs/PROTOCOL.md): :func:`capture` reads
the device's SAMPLE and INFO frames through a :class:`~host_tools.link.host.HostLink` and writes
them with :class:`RunLogWriter` (incremental, fsync'ed, ``# capture: in progress`` until closed)
as a run log of CAPTURE_COLUMNS (shared/formats/run-log.md).  The output's format follows its
name (OUTPUT_SUFFIXES): ``.csv`` is written incrementally; ``.npz`` is recorded incrementally into
``<name>.part.csv`` next to it and converted when the capture ends (the CSV is then removed; a
killed capture leaves it, a valid run log).
"""
from __future__ import annotations

import math
import os
import re
import time
import warnings
from dataclasses import dataclass

from host_tools.link.codec import ST_RUN_ENDED, DeviceInfo, unpack_sample
from host_tools.link.frame import PROTO_MAJOR, T_ACK, T_GET_INFO, T_INFO, T_NACK, T_SAMPLE, T_TABLE, ProtocolError, \
    ProtocolVersionError
from host_tools.link.host import HostLink, open_port
from host_tools.golden.runlog import CAPTURE_DONE, CAPTURE_KEY, CAPTURE_OPEN


class CaptureOutputError(ValueError):
    """The capture's output file cannot be written (missing directory, a directory, no permission)."""


OUTPUT_SUFFIXES = (".csv", ".npz")     # the run-log formats capture writes (golden.runlog reads both)


def output_format(path) -> str:
    """``"csv"`` or ``"npz"`` from the suffix of ``path`` (any case); CaptureOutputError naming the
    supported suffixes for any other name."""
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    if suffix not in OUTPUT_SUFFIXES:
        raise CaptureOutputError(f"{os.fspath(path)}: the run-log format follows the file name: give a name ending "
                                 f"in {' or '.join(OUTPUT_SUFFIXES)} (not {suffix or 'no suffix'!r})")
    return suffix[1:]


def check_output_path(path) -> None:
    """CaptureOutputError unless ``path`` names a file that can be created: its directory exists
    and is writable, ``path`` is not a directory, and its suffix is one of OUTPUT_SUFFIXES."""
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise CaptureOutputError(f"{path}: is a directory (-o names the run-log file to write)")
    output_format(path)
    if not os.path.isdir(directory):
        raise CaptureOutputError(f"{path}: the directory {directory} does not exist")
    if not os.access(directory, os.W_OK):
        raise CaptureOutputError(f"{path}: the directory {directory} is not writable")


_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]")


def meta_text(value, key: bool = False) -> str:
    """``value`` as one metadata line's text: control characters (newlines included) written as
    Python escapes (``\\n``, ``\\x1b``), so a device name or a port cannot end the line, forge a
    metadata line or a row; in a key, ``:`` (the key/value separator) becomes ``_``."""
    text = _CONTROL.sub(lambda m: m.group().encode("unicode_escape").decode("ascii"), str(value))
    return text.replace(":", "_").strip() if key else text


CAPTURE_COLUMNS = ("t_s", "freq_hz", "rate_dph", "mode", "temp_c", "comp_rate_dph", "comp_bias_dph", "comp_valid",
                   "status", "state", "seq")


class RunLogWriter:
    """Writes a run log (shared/formats/run-log.md) row by row: metadata and header with the first
    rows, then appended rows; flushed (and fsync'ed) every ``flush_every`` rows, every
    ``flush_interval_s`` seconds and at :meth:`close`, always at a line boundary, so the file is a
    valid run log at every flush.  The file is created (truncating an existing one) only with the
    first row: a capture that records nothing leaves an existing file as it was.  Metadata keys and
    values pass through :func:`meta_text` (no newline can end a line early).  Its first metadata
    line is ``# capture: in progress`` until :meth:`close` rewrites it in place (same length) to
    ``# capture: complete``: a file left by a killed capture says so, and the run-log reader warns
    about it (docs/RUN_LOG.md)."""

    def __init__(self, path, metadata: dict, columns=CAPTURE_COLUMNS, flush_every: int = 256,
                 flush_interval_s: float = 1.0):
        self.path = os.fspath(path)
        self.metadata = {meta_text(k, key=True): meta_text(v) for k, v in
                         {CAPTURE_KEY: CAPTURE_OPEN, **{k: v for k, v in metadata.items() if k != CAPTURE_KEY}}.items()}
        self.columns = tuple(columns)
        self.flush_every = max(1, int(flush_every))
        self.flush_interval_s = flush_interval_s
        self.rows = 0
        self._pending = []
        self._fh = None             # opened with the first row: a capture of nothing leaves an existing file as it was
        self._header_written = False
        self._last_flush = time.monotonic()

    @property
    def opened(self) -> bool:
        """True once the file was created (it holds the metadata, the header and at least one row)."""
        return self._fh is not None

    def append(self, line: str) -> None:
        self._pending.append(line)
        if len(self._pending) >= self.flush_every or time.monotonic() - self._last_flush >= self.flush_interval_s:
            self.flush()

    def flush(self) -> None:
        if not self._pending:
            return
        parts = []
        if self._fh is None:
            try:
                self._fh = open(self.path, "w", encoding="utf-8", newline="\n")
            except OSError as exc:   # the output, not the port: never reported as "port error"
                raise CaptureOutputError(f"cannot write the run log {self.path}: {exc.strerror or exc}") from None
        if not self._header_written:
            parts += [f"# {k}: {v}\n" for k, v in self.metadata.items()]
            parts.append(",".join(self.columns) + "\n")
            self._header_written = True
        parts += self._pending
        self._fh.write("".join(parts))
        self._fh.flush()
        try:
            os.fsync(self._fh.fileno())
        except OSError:  # pragma: no cover - e.g. a pipe
            pass
        self.rows += len(self._pending)
        self._pending = []
        self._last_flush = time.monotonic()

    def close(self) -> None:
        if self._fh is None and self._pending:
            self.flush()
        if self._fh is None:
            return
        if self._fh.closed:
            return
        try:
            self.flush()
            if self._header_written:
                self._mark_complete()
        finally:
            self._fh.close()

    def _mark_complete(self) -> None:
        old = f"# {CAPTURE_KEY}: {CAPTURE_OPEN}"
        new = f"# {CAPTURE_KEY}: {CAPTURE_DONE}".ljust(len(old))   # same length: rewritten in place
        self._fh.seek(0)
        self._fh.write(new)
        self._fh.flush()
        try:
            os.fsync(self._fh.fileno())
        except OSError:  # pragma: no cover - e.g. a pipe
            pass


@dataclass
class CaptureResult:
    """What a capture did: rows written, the link counters, why it ended, the device's INFO."""

    path: str
    samples: int = 0
    frames: int = 0
    crc_errors: int = 0
    header_errors: int = 0
    resyncs: int = 0
    garbage_bytes: int = 0
    truncated: int = 0
    seq_gaps: int = 0
    gap_events: int = 0
    duplicates: int = 0
    bad_payload: int = 0
    out_of_order: int = 0
    unknown_type: int = 0
    ignored_replies: int = 0
    dropped_no_info: int = 0
    table_changes: int = 0
    first_t_s: float | None = None
    last_t_s: float | None = None
    elapsed_s: float = 0.0
    reason: str = ""
    info: DeviceInfo | None = None
    written: bool = False

    def progress_line(self) -> str:
        rate = self.frames / self.elapsed_s if self.elapsed_s > 0 else 0.0
        t = "" if self.last_t_s is None else f"t={self.last_t_s:.6g} s  "
        return (f"{self.samples} samples  {t}{rate:.0f} frames/s  CRC errors {self.crc_errors + self.header_errors}  "
                f"resyncs {self.resyncs}  seq gaps {self.seq_gaps}")

    def summary(self) -> str:
        lines = [f"capture ended: {self.reason}"]
        if self.written:
            span = "" if self.first_t_s is None else f", t = {self.first_t_s:.6g} .. {self.last_t_s:.6g} s"
            lines.append(f"  {self.path}: {self.samples} samples{span}")
        else:
            lines.append(f"  {self.path}: not written (no sample recorded; an existing file is left as it was)")
        lines.append(f"  frames {self.frames} in {self.elapsed_s:.1f} s; CRC errors {self.crc_errors} (frame) + "
                     f"{self.header_errors} (header); resyncs {self.resyncs} ({self.garbage_bytes} bytes discarded); "
                     f"sequence gaps {self.seq_gaps} frame(s) in {self.gap_events} place(s)")
        extra = [(n, getattr(self, n)) for n in ("truncated", "duplicates", "bad_payload", "out_of_order",
                                                   "unknown_type", "ignored_replies", "dropped_no_info",
                                                   "table_changes")
                 if getattr(self, n)]
        if extra:
            lines.append("  " + ", ".join(f"{n.replace('_', ' ')} {v}" for n, v in extra))
        return "\n".join(lines)


class _SampleFormatter:
    """SAMPLE tuple + seq -> one CSV line of CAPTURE_COLUMNS (dequantized with the INFO's formats;
    floats in shortest round-trip form, so the words are recoverable exactly)."""

    def __init__(self, info: DeviceInfo):
        self.fs = info.fs_hz
        self.lf = 2.0 ** -info.freq_frac
        self.lr = 2.0 ** -info.rate_frac
        self.lt = 2.0 ** -info.temp_frac
        self.lo = 2.0 ** -info.out_frac
        self._high = 0
        self._last32 = None

    def counter(self, c32: int) -> int:
        """Unwrap the uint32 counter (a step back of more than 2^31 is a wrap)."""
        if self._last32 is not None and c32 < self._last32 and self._last32 - c32 > (1 << 31):
            self._high += 1 << 32
        self._last32 = c32
        return self._high + c32

    def line(self, counter: int, s: tuple, seq: int) -> tuple:
        t = counter / self.fs
        return t, (f"{t!r},{s[1] * self.lf!r},{s[2] * self.lr!r},{s[7]},{s[3] * self.lt!r},"
                   f"{s[4] * self.lo!r},{s[5] * self.lo!r},{s[9]},{s[8]},{s[6]},{seq}\n")


MAX_DURATION_S = 1e8        # about 3 years: a longer duration or idle timeout is a typo


def check_limits(duration_s, idle_timeout_s, max_samples=None) -> None:
    """ValueError naming the limit unless ``duration_s`` and ``idle_timeout_s`` are None or a number
    of seconds in (0, MAX_DURATION_S] (negative, zero, NaN and inf refused), and ``max_samples`` None
    or a positive integer."""
    for name, value in (("duration", duration_s), ("idle timeout", idle_timeout_s)):
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                or not 0 < value <= MAX_DURATION_S:
            raise ValueError(f"capture {name} {value!r}: must be a number of seconds in (0, {MAX_DURATION_S:g}]")
    if max_samples is not None and (isinstance(max_samples, bool) or not isinstance(max_samples, int)
                                    or max_samples <= 0):
        raise ValueError(f"capture max_samples {max_samples!r}: must be a positive integer")


def capture(port, path, duration_s: float | None = None, idle_timeout_s: float | None = 10.0,
            max_samples: int | None = None, flush_every: int = 256, flush_interval_s: float = 1.0,
            progress=None, extra_metadata: dict | None = None, stop=None) -> CaptureResult:
    """Record the device's SAMPLE frames on ``port`` (an open port or a URL/path) into the run log
    ``path`` (CAPTURE_COLUMNS, see docs/PROTOCOL.md; CSV or NPZ by its suffix, see the module doc)
    until ``duration_s`` of device time [s from the first sample], ``max_samples``, the device
    reports the end of its run or restarts, ``stop()`` returns True, Ctrl-C, a port error
    (disconnect), or a stall, whatever else the device sends (garbage, partial frames, NACKs, INFO
    without samples): no usable INFO frame within the shorter of ``idle_timeout_s`` and
    ``duration_s`` [s wall time], then no new sample for ``idle_timeout_s`` [s wall time] (None:
    never stop for silence; then ``duration_s`` bounds the stall); both None: wait until stopped.
    The file is written incrementally (see RunLogWriter)
    and only once an INFO frame gave the sample rate and formats; samples before it are kept in
    memory (up to 100000).  ``progress(result)`` is called after every read.  Returns the
    :class:`CaptureResult`; ProtocolVersionError for a device of another protocol major."""
    import serial

    check_output_path(path)
    check_limits(duration_s, idle_timeout_s, max_samples)
    npz = output_format(path) == "npz"
    record_path = os.fspath(path) + ".part.csv" if npz else path
    limits = [v for v in (idle_timeout_s, duration_s) if v is not None]
    info_wait_s = min(limits) if limits else None           # for the first usable INFO [s]
    stall_s = idle_timeout_s if idle_timeout_s is not None else duration_s
    own = isinstance(port, (str, os.PathLike))
    if own:
        port = open_port(os.fspath(port))
    link = HostLink(port)
    res = CaptureResult(path=os.fspath(path))
    writer = None
    fmt = None
    pending = []
    last_counter = None
    first_counter = None
    t0 = time.monotonic()
    last_progress = t0          # wall time of the last new sample or of the first usable INFO
    frames_at_progress = 0      # decoded frames then
    last_info_request = -1e9

    def sync_stats():
        d, s = link.decoder.stats, link.stats
        res.frames, res.crc_errors, res.header_errors = d.frames, d.crc_errors, d.header_errors
        res.resyncs, res.garbage_bytes, res.truncated = d.resyncs, d.garbage_bytes, d.truncated
        res.seq_gaps, res.gap_events, res.duplicates = s.seq_gaps, s.gap_events, s.duplicates
        res.unknown_type = s.unknown_type
        res.elapsed_s = time.monotonic() - t0

    def start_writer(info: DeviceInfo):
        nonlocal writer, fmt
        meta = {"device": info.name or "unknown", "sample_rate_hz": f"{info.fs_hz:g}",
                "source": "hdrg capture", "protocol": f"{info.major}.{info.minor}",
                "capture_port": getattr(port, "port", None) or getattr(port, "name", "?"),
                "capture_started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                "table_crc": f"0x{info.table_crc:08x}", "boot_id": f"0x{info.boot_id:08x}"}
        meta.update(extra_metadata or {})
        writer = RunLogWriter(record_path, meta, flush_every=flush_every, flush_interval_s=flush_interval_s)
        fmt = _SampleFormatter(info)

    def take(s: tuple, seq: int) -> bool:
        """Write one sample; False when the capture should end."""
        nonlocal last_counter, first_counter, last_progress, frames_at_progress
        c = fmt.counter(s[0])
        if last_counter is not None and c <= last_counter:
            res.out_of_order += 1
            return True
        if first_counter is None:
            first_counter = c
        if duration_s is not None and (c - first_counter) / fmt.fs >= duration_s:
            res.reason = f"duration {duration_s:g} s reached"
            return False
        t, line = fmt.line(c, s, seq)
        writer.append(line)
        last_counter = c
        res.samples += 1
        last_progress, frames_at_progress = time.monotonic(), link.decoder.stats.frames
        if res.first_t_s is None:
            res.first_t_s = t
        res.last_t_s = t
        if max_samples is not None and res.samples >= max_samples:
            res.reason = f"{max_samples} samples recorded"
            return False
        return True

    def handle(frames) -> bool:
        """Process device frames; False when the data says the capture ends."""
        nonlocal pending, last_progress, frames_at_progress
        for fr in frames:
            if fr.type in (T_ACK, T_NACK, T_TABLE):
                res.ignored_replies += 1        # capture sends only GET_INFO, answered by INFO
                continue
            if fr.type == T_SAMPLE:
                try:
                    s = unpack_sample(fr.payload)
                except ProtocolError:
                    res.bad_payload += 1
                    continue
                if fmt is None:
                    if len(pending) < 100_000:
                        pending.append((s, fr.seq))
                    else:
                        res.dropped_no_info += 1
                    continue
                if not take(s, fr.seq):
                    return False
            elif fr.type == T_INFO:
                try:
                    info = DeviceInfo.unpack(fr.payload)
                except ProtocolVersionError:
                    raise
                except ProtocolError:
                    res.bad_payload += 1
                    continue
                if res.info is None:
                    res.info = info
                    last_progress, frames_at_progress = time.monotonic(), link.decoder.stats.frames
                    start_writer(info)
                    queued, pending = pending, []
                    for s, seq in queued:
                        if not take(s, seq):
                            return False
                elif info.boot_id != res.info.boot_id or info.fs_q16 != res.info.fs_q16:
                    res.reason = ("the device restarted (boot id or sample rate changed): this run log ends "
                                  "here; start a new capture for the new run")
                    return False
                else:
                    if info.table_crc != res.info.table_crc:
                        res.table_changes += 1
                    res.info = info
                if info.status & ST_RUN_ENDED:          # sent after the run's last sample
                    res.reason = "the device reports the end of its run"
                    return False
        return True

    def stall_reason(limit: float) -> str:
        got = (f"{res.frames} frame(s) received ({res.bad_payload} with a bad payload, {res.ignored_replies} "
               f"ACK/NACK/TABLE, {res.unknown_type} of unknown type, {res.duplicates} repeated), "
               f"{res.garbage_bytes} garbage byte(s), {res.crc_errors + res.header_errors} CRC error(s)")
        if res.info is None:
            return (f"no usable INFO frame from the device within {limit:g} s ({got}; {len(pending)} sample(s) "
                    f"without INFO): is a device of serial protocol {PROTO_MAJOR}.x on this port, at this baud rate?")
        if link.decoder.stats.frames == frames_at_progress:
            return f"no frame from the device for {limit:g} s ({res.garbage_bytes} garbage byte(s) in all)"
        return f"no new sample from the device for {limit:g} s ({got}; {res.out_of_order} sample(s) out of order)"

    data_ended = False
    try:
        while True:
            if res.info is None and time.monotonic() - last_info_request > 1.0:
                last_info_request = time.monotonic()
                try:
                    link.send(T_GET_INFO)
                except serial.SerialTimeoutException:
                    pass        # a read-only link: the device's periodic INFO will do
            if not handle(link.poll()):
                data_ended = True
                break
            sync_stats()
            if progress is not None:
                progress(res)
            if stop is not None and stop():
                res.reason = "stopped"
                break
            limit = stall_s if res.info is not None else info_wait_s
            if limit is not None and time.monotonic() - last_progress > limit:
                res.reason = stall_reason(limit)
                break
    except KeyboardInterrupt:
        res.reason = "interrupted (Ctrl-C)"
    except serial.SerialException as exc:
        res.reason = f"port error (device disconnected?): {exc}"
    except OSError as exc:
        res.reason = f"port error (device disconnected?): {exc}"
    finally:
        try:
            rest = link.finish()
            if not data_ended:
                handle(rest)        # frames a cut frame at the end had hidden
        finally:
            sync_stats()
            res.dropped_no_info += len(pending)
            if writer is not None:
                writer.close()
                res.written = writer.opened
            if own:
                try:
                    port.close()
                except Exception:  # pragma: no cover
                    pass
    if npz and res.written:
        _convert_to_npz(record_path, os.fspath(path))
    return res


def _convert_to_npz(csv_path: str, npz_path: str) -> None:
    """The recorded CSV run log ``csv_path`` written as the NPZ run log ``npz_path`` (atomically),
    then removed; CaptureOutputError (the CSV kept) when that fails.  The reader's warnings (gaps,
    ...) are not repeated here: the capture's summary counts them."""
    from host_tools.golden import runlog as rl

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            log = rl.read_csv(csv_path)
        rl.write_npz(log, npz_path)
    except (OSError, ValueError) as exc:
        raise CaptureOutputError(f"{npz_path}: cannot write the NPZ run log ({exc}); the capture is kept as "
                                 f"{csv_path}") from None
    os.remove(csv_path)
