"""The host end of the serial link (docs/PROTOCOL.md): open a port, send requests, read the
device's frames with sequence accounting (:class:`HostLink`), and upload a coefficient table with
ACK/NACK, retries and read-back (:func:`upload`).

Layering: host_tools.link.frame (bytes <-> frames) and host_tools.link.codec (payloads) below;
host_tools.link.capture and the commands (host_tools.cli.capture, host_tools.cli.upload) above.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

from firmware_ref import table as T
from host_tools.errors import UserError
from host_tools.link.codec import CAP_TABLE_READ, CAP_TABLE_UPLOAD, R_OK, REASONS, DeviceInfo, Reply, printable, \
    rate_mismatch, table_problems
from host_tools.link.frame import PROTO_MAJOR, T_ACK, T_GET_INFO, T_INFO, T_NACK, T_READ_TABLE, T_SAMPLE, \
    T_TABLE, Decoder, Frame, ProtocolError, ProtocolVersionError, encode_frame, version_message


class UploadError(ValueError):
    """A table upload that did not succeed (refused, no answer, or read-back mismatch)."""


class PortError(UserError):
    """A port that cannot be opened (no such device, busy, an unknown URL scheme, a bad baud rate)."""


MAX_TIMEOUT_S = 60.0        # a longer answer timeout is a typo (a device answers within a second)
MAX_RETRIES = 100


def check_retries(value, name: str = "retries") -> int:
    """``value`` as a number of attempts in 1 .. MAX_RETRIES; UserError naming ``name`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_RETRIES:
        raise UserError(f"{name} {value!r}: must be an integer in 1 .. {MAX_RETRIES}")
    return value


def check_timeout(value, name: str = "timeout") -> float:
    """``value`` as an answer timeout [s] in (0, MAX_TIMEOUT_S]; UserError naming ``name`` for
    anything else (zero, negative, NaN, inf, too long)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or not 0 < value <= MAX_TIMEOUT_S:
        raise UserError(f"{name} {value!r}: must be a number of seconds in (0, {MAX_TIMEOUT_S:g}]")
    return float(value)


def check_baud(value, name: str = "baud rate") -> int:
    """``value`` as a baud rate [bit/s]: a positive integer; UserError naming ``name`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise UserError(f"{name} {value!r}: must be a positive integer (bit/s, e.g. 115200)")
    return value


def open_port(port: str, baud: int = 115200, timeout: float = 0.05, write_timeout: float = 2.0,
              option: str = "port"):
    """Open a serial port or a pyserial URL (``loop://``, ``/dev/ttyUSB0``, ``/dev/pts/5``, ...);
    ``timeout`` and ``write_timeout`` [s].  PortError naming ``option`` (and pyserial's reason)
    when it cannot be opened: a missing or busy device, an unknown URL scheme, a baud rate the
    port refuses."""
    import serial

    try:
        check_baud(baud)
    except UserError as exc:
        raise PortError(f"{option} {port}: cannot open: {exc}") from None
    try:
        return serial.serial_for_url(port, baudrate=baud, timeout=timeout, write_timeout=write_timeout)
    except (serial.SerialException, ValueError) as exc:
        hint = " (pyserial knows a device path or loop://, socket://, rfc2217://, spy://, alt://, hwgrep://)" \
            if "protocol" in str(exc) and "not known" in str(exc) else ""
        raise PortError(f"{option} {port}: cannot open: {exc}{hint}") from None


@dataclass
class LinkStats:
    """Host-side counters on top of the decoder's: ``seq_gaps`` frames missing by sequence number,
    ``gap_events`` places where frames were missing, ``duplicates`` repeated sequence numbers,
    ``bad_payload`` frames whose payload did not decode, ``unknown_type`` frames of types this host
    does not know, ``foreign_version`` frames of a protocol major it does not read."""

    seq_gaps: int = 0
    gap_events: int = 0
    duplicates: int = 0
    bad_payload: int = 0
    unknown_type: int = 0
    foreign_version: int = 0


class HostLink:
    """The host end of a port: sends requests, decodes the device's frames, counts sequence gaps.

    ``port``: an open pyserial port (or anything with ``read(n)``, ``write(b)`` and ``in_waiting``;
    its read timeout bounds :meth:`poll`)."""

    DEVICE_TYPES = (T_SAMPLE, T_INFO, T_TABLE, T_ACK, T_NACK)

    def __init__(self, port):
        self.port = port
        self.decoder = Decoder()
        self.stats = LinkStats()
        self.tx_seq = 0
        self._last_seq = None
        self.last_rx = time.monotonic()
        self._backlog = []          # frames read but not yet returned (after a request's answer)

    def send(self, ftype: int, payload: bytes = b"") -> int:
        """Send one frame; returns its sequence number."""
        seq = self.tx_seq
        self.tx_seq = (self.tx_seq + 1) & 0xFFFF
        self.port.write(encode_frame(ftype, seq, payload))
        return seq

    def poll(self) -> list:
        """Read what the port has (waiting at most its read timeout) and return the accepted
        frames from the device (sequence gaps counted; frames of a foreign major dropped, counted)."""
        if self._backlog:
            frames, self._backlog = self._backlog, []
            return frames
        n = self.port.in_waiting
        data = self.port.read(n if n else 1)
        if not data:
            if not getattr(self.port, "timeout", None):
                time.sleep(0.001)       # a non-blocking port: do not spin
            return []
        return self._accept(self.decoder.feed(data))

    def finish(self) -> list:
        """The stream ended (disconnect, idle, Ctrl-C): the frames left in the decoder's buffer."""
        frames, self._backlog = self._backlog, []
        return frames + self._accept(self.decoder.finish())

    def _accept(self, decoded) -> list:
        frames = []
        st = self.stats
        for fr in decoded:
            if fr.type in (T_GET_INFO, T_READ_TABLE):
                continue            # our own requests echoed (loop://): not from the device
            if self._last_seq is not None:
                d = (fr.seq - self._last_seq - 1) & 0xFFFF
                if d == 0xFFFF:
                    st.duplicates += 1
                    continue
                if d:
                    st.seq_gaps += d
                    st.gap_events += 1
            self._last_seq = fr.seq
            if fr.major != PROTO_MAJOR:
                st.foreign_version += 1
                if fr.type == T_INFO and len(fr.payload) >= 2:
                    raise ProtocolVersionError(version_message(fr.payload[0], fr.payload[1]))
                if st.foreign_version >= 8:
                    raise ProtocolVersionError(version_message(fr.major, fr.minor))
                continue
            if fr.type not in self.DEVICE_TYPES:
                st.unknown_type += 1
                continue
            frames.append(fr)
        if frames:
            self.last_rx = time.monotonic()
        return frames

    def request(self, ftype: int, payload: bytes, match, timeout_s: float = 2.0, on_frame=None):
        """Send a request and return the first frame ``f`` (type, seq) with ``match(f, seq)``;
        other frames go to ``on_frame`` (or are dropped).  None on timeout."""
        seq = self.send(ftype, payload)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            frames = self.poll()
            for i, fr in enumerate(frames):
                if match(fr, seq):
                    self._backlog = frames[i + 1:] + self._backlog
                    return fr
                if on_frame is not None:
                    on_frame(fr)
        return None

    def get_info(self, timeout_s: float = 2.0, on_frame=None) -> DeviceInfo:
        """Ask for INFO (any INFO frame answers) and wait up to ``timeout_s`` [s]; ProtocolError on
        timeout."""
        check_timeout(timeout_s)
        fr = self.request(T_GET_INFO, b"", lambda f, s: f.type == T_INFO, timeout_s, on_frame)
        if fr is None:
            raise ProtocolError(f"no INFO frame from the device within {timeout_s:g} s (is the device on this port?)")
        return DeviceInfo.unpack(fr.payload)

    def read_table(self, timeout_s: float = 2.0, on_frame=None) -> bytes:
        fr = self.request(T_READ_TABLE, b"", lambda f, s: f.type == T_TABLE or is_reply_to(f, T_READ_TABLE, s),
                          timeout_s, on_frame)
        if fr is None:
            raise UploadError(f"no answer to READ_TABLE within {timeout_s:g} s")
        if fr.type != T_TABLE:
            r = Reply.unpack(fr.payload)
            raise UploadError(f"the device refused READ_TABLE: {REASONS.get(r.code, r.code)}: {printable(r.text)}")
        return fr.payload


def is_reply_to(fr: Frame, req_type: int, seq: int) -> bool:
    """``fr`` is the ACK/NACK of the request (``req_type``, ``seq``)."""
    if fr.type not in (T_ACK, T_NACK):
        return False
    try:
        r = Reply.unpack(fr.payload)
    except ProtocolError:
        return False
    return r.req_type == req_type and r.req_seq == seq


# -- upload -----------------------------------------------------------------------------------------------

@dataclass
class UploadResult:
    """A successful upload: the table's CRC-32 word, the counter of the first sample computed with
    it, the attempts it took, and the device's INFO."""

    crc: int
    apply_sample: int
    attempts: int
    info: DeviceInfo


def upload(link: HostLink, table, timeout_s: float = 2.0, retries: int = 3, on_frame=None) -> UploadResult:
    """Upload ``table`` (firmware_ref.table.Table): refuse it before sending if it fails its own
    checks or the output-word bound (codec.table_problems), check the device's INFO (capabilities,
    table layout version, word formats against firmware_ref.formats, sample rate against the
    table's fs_q16), send TABLE until ACK/NACK (``retries`` attempts of ``timeout_s`` [s] each), then
    READ_TABLE and compare the bytes.  Raises UploadError (a device that does not fit the table,
    NACK with its reason, no answer, read-back differs), T.TableError (pre-check), ProtocolError,
    UserError (``timeout_s`` or ``retries`` out of range).  Device texts in messages pass through
    codec.printable."""
    check_timeout(timeout_s)
    check_retries(retries)
    probs = table_problems(table)
    if probs:
        raise T.TableError("table refused before sending: " + "; ".join(probs))
    data = table.to_bytes()
    info = link.get_info(timeout_s, on_frame)
    who = f"device '{printable(info.name)}'"
    need = CAP_TABLE_UPLOAD | CAP_TABLE_READ
    if info.capabilities & need != need:
        raise UploadError(f"{who} does not accept table uploads (capabilities: "
                          f"{', '.join(info.capability_names()) or 'none'})")
    if info.table_version != T.VERSION:
        raise UploadError(f"{who} reads table layout version {info.table_version}, this table is "
                          f"version {T.VERSION}")
    diffs = info.format_differences()
    if diffs:
        raise UploadError(f"{who} uses other word formats than this hdrg (firmware_ref.formats): "
                          f"{', '.join(diffs)}; its table would be read with the wrong scales: use an hdrg "
                          f"and a firmware of the same formats")
    problem = rate_mismatch(table, info.fs_q16, who)
    if problem is not None:
        raise UploadError(f"not sent: {problem}")
    reply = None
    for attempt in range(1, retries + 1):
        fr = link.request(T_TABLE, data, lambda f, s: is_reply_to(f, T_TABLE, s), timeout_s, on_frame)
        if fr is not None:
            reply = Reply.unpack(fr.payload)
            break
    if reply is None:
        raise UploadError(f"no ACK/NACK for the table after {retries} attempt(s) of {timeout_s:g} s")
    if fr.type == T_NACK or reply.code != R_OK:
        raise UploadError(f"the device refused the table ({REASONS.get(reply.code, reply.code)}): "
                          f"{printable(reply.text)}")
    if reply.detail != table.crc:
        raise UploadError(f"the device acknowledged CRC-32 0x{reply.detail:08x}, the table has 0x{table.crc:08x}")
    back = link.read_table(timeout_s, on_frame)
    if back != data:
        raise UploadError(f"read-back differs from the uploaded table ({len(back)} vs {len(data)} bytes, "
                          f"first difference at byte {_first_diff(back, data)})")
    return UploadResult(table.crc, reply.sample, attempt, info)


def _first_diff(a: bytes, b: bytes) -> int:
    for i, (x, y) in enumerate(zip(a, b)):
        if x != y:
            return i
    return min(len(a), len(b))
