"""The host end of the serial link (docs/PROTOCOL.md): open a port, send requests, read the
device's frames with sequence accounting (:class:`HostLink`), and upload a coefficient table with
ACK/NACK, retries and read-back (:func:`upload`).

Layering: host_tools.link.frame (bytes <-> frames) and host_tools.link.codec (payloads) below;
host_tools.link.capture and the commands (host_tools.cli.capture, host_tools.cli.upload) above.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

from firmware_ref import table as T
from host_tools.link.codec import CAP_TABLE_READ, CAP_TABLE_UPLOAD, R_OK, REASONS, DeviceInfo, Reply, table_problems
from host_tools.link.frame import PROTO_MAJOR, T_ACK, T_GET_INFO, T_INFO, T_NACK, T_READ_TABLE, T_SAMPLE, \
    T_TABLE, Decoder, Frame, ProtocolError, ProtocolVersionError, encode_frame, version_message


class UploadError(ValueError):
    """A table upload that did not succeed (refused, no answer, or read-back mismatch)."""


def open_port(port: str, baud: int = 115200, timeout: float = 0.05, write_timeout: float = 2.0):
    """Open a serial port or a pyserial URL (``loop://``, ``/dev/ttyUSB0``, ``/dev/pts/5``, ...)."""
    import serial

    return serial.serial_for_url(port, baudrate=baud, timeout=timeout, write_timeout=write_timeout)


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
        """Ask for INFO (any INFO frame answers); ProtocolError on timeout."""
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
            raise UploadError(f"the device refused READ_TABLE: {REASONS.get(r.code, r.code)}: {r.text}")
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
    checks or the output-word bound (codec.table_problems), check the device's version and capabilities
    (INFO), send TABLE until ACK/NACK (``retries`` attempts of ``timeout_s``), then READ_TABLE and
    compare the bytes.  Raises UploadError (NACK with its reason, no answer, read-back differs),
    T.TableError (pre-check), ProtocolError."""
    probs = table_problems(table)
    if probs:
        raise T.TableError("table refused before sending: " + "; ".join(probs))
    data = table.to_bytes()
    info = link.get_info(timeout_s, on_frame)
    need = CAP_TABLE_UPLOAD | CAP_TABLE_READ
    if info.capabilities & need != need:
        raise UploadError(f"device {info.name!r} does not accept table uploads (capabilities: "
                          f"{', '.join(info.capability_names()) or 'none'})")
    if info.table_version != T.VERSION:
        raise UploadError(f"device {info.name!r} reads table layout version {info.table_version}, this table is "
                          f"version {T.VERSION}")
    reply = None
    for attempt in range(1, retries + 1):
        fr = link.request(T_TABLE, data, lambda f, s: is_reply_to(f, T_TABLE, s), timeout_s, on_frame)
        if fr is not None:
            reply = Reply.unpack(fr.payload)
            break
    if reply is None:
        raise UploadError(f"no ACK/NACK for the table after {retries} attempt(s) of {timeout_s:g} s")
    if fr.type == T_NACK or reply.code != R_OK:
        raise UploadError(f"the device refused the table ({REASONS.get(reply.code, reply.code)}): {reply.text}")
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
