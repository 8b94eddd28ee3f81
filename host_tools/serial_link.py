"""The serial link to the gyroscope's controller: a framed binary protocol (docs/PROTOCOL.md),
run-log capture (`hdrg capture`) and coefficient-table upload (`hdrg upload`).

Frame (little-endian; offsets in bytes)::

    0  sync     2   0xA5 0x5A
    2  version  1   protocol major (high nibble) and minor (low nibble) of the sender
    3  type     1   frame type (T_* below)
    4  seq      2   uint16 sequence number of the sender, +1 per frame, wraps 65535 -> 0
    6  length   2   payload length L, 0 .. MAX_PAYLOAD (1024)
    8  hcrc     2   CRC-16/CCITT-FALSE of bytes 0..7 (the header CRC)
    10 payload  L
    10+L crc    4   CRC-32 (IEEE 802.3, zlib.crc32) of bytes 0 .. 9+L (header and payload)

A frame is accepted only when both CRCs match; after a failure the decoder scans again from the
byte after the rejected sync, so garbage, dropped, inserted or flipped bytes cost only the frames
they touch.  Payload formats (SAMPLE, INFO, TABLE, ACK/NACK) are in :data:`SAMPLE`,
:class:`DeviceInfo`, :class:`Reply` and docs/PROTOCOL.md; the fixed-point words use the formats of
firmware_ref/formats.py.

Public API: :func:`encode_frame`, :class:`Decoder`, :func:`pack_sample` / :func:`unpack_sample`,
:class:`DeviceInfo`, :class:`Reply`, :func:`validate_table_payload`, :func:`table_problems`,
:class:`HostLink` (host side of a port), :func:`capture`, :func:`upload`, :func:`open_port`.
"""
from __future__ import annotations

import argparse
import binascii
import os
import struct
import sys
import time
import zlib
from dataclasses import dataclass

from firmware_ref import formats as F
from firmware_ref import table as T

# -- envelope --------------------------------------------------------------------------------------
SYNC = b"\xa5\x5a"
PROTO_MAJOR = 1
PROTO_MINOR = 0
HEADER_SIZE = 10
CRC_SIZE = 4
OVERHEAD = HEADER_SIZE + CRC_SIZE
MAX_PAYLOAD = 1024
_HDR = struct.Struct("<BBHHH")          # version, type, seq, length, hcrc (after the sync)
_HDR_BODY = struct.Struct("<BBHH")
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")

# -- frame types (device -> host: SAMPLE, INFO, TABLE (read-back), ACK, NACK;
#    host -> device: TABLE (upload), GET_INFO, READ_TABLE) ---------------------------------------
T_SAMPLE = 0x01
T_INFO = 0x02
T_TABLE = 0x03
T_ACK = 0x04
T_NACK = 0x05
T_GET_INFO = 0x10
T_READ_TABLE = 0x11
TYPE_NAMES = {T_SAMPLE: "SAMPLE", T_INFO: "INFO", T_TABLE: "TABLE", T_ACK: "ACK", T_NACK: "NACK",
              T_GET_INFO: "GET_INFO", T_READ_TABLE: "READ_TABLE"}

# -- capabilities (INFO, uint16 bit mask) -------------------------------------------------------------
CAP_SAMPLES = 1          # streams SAMPLE frames
CAP_TABLE_UPLOAD = 2     # accepts TABLE uploads (ACK/NACK)
CAP_TABLE_READ = 4       # answers READ_TABLE with its active table
CAP_VIRTUAL = 8          # a simulated device (hdrg device)
CAP_NAMES = {CAP_SAMPLES: "samples", CAP_TABLE_UPLOAD: "table_upload", CAP_TABLE_READ: "table_read",
             CAP_VIRTUAL: "virtual"}

# -- INFO status bits ---------------------------------------------------------------------------------
ST_STREAMING = 1         # SAMPLE frames are being sent
ST_RUN_ENDED = 2         # the run has ended: no further SAMPLE frames will come

# -- ACK/NACK reason codes --------------------------------------------------------------------------------
R_OK = 0
R_UNKNOWN_TYPE = 1       # the device does not handle this frame type
R_BAD_LENGTH = 2         # payload length wrong for the type
R_VERSION = 3            # the request's protocol major is not the device's
R_TABLE_FORMAT = 4       # table: not whole words, bad magic / layout version / length word
R_TABLE_CRC = 5          # table: its own CRC-32 word does not match
R_TABLE_RANGE = 6        # table: a field outside its legal range, or the quantizer's interval checks fail
R_UNSUPPORTED = 7        # the device lacks the capability (e.g. upload)
R_TABLE_MODE = 8         # table: its combiner does not match the device's mode (FTR table, reversal run or back)
REASONS = {R_TABLE_MODE: "table combiner does not match the device's mode", R_OK: "ok", R_UNKNOWN_TYPE: "unknown frame type", R_BAD_LENGTH: "bad payload length",
           R_VERSION: "unsupported protocol version", R_TABLE_FORMAT: "table format", R_TABLE_CRC: "table CRC-32",
           R_TABLE_RANGE: "table range", R_UNSUPPORTED: "not supported by the device"}

# -- SAMPLE payload (28 bytes in 1.0) ------------------------------------------------------------------
SAMPLE = struct.Struct("<IIiiiiBBBB")
SAMPLE_FIELDS = (
    ("counter", "uint32", "sample counter since power-on (t = counter / fs); wraps at 2^32"),
    ("freq", "uint32", f"drive-frequency word F, LSB 2^-{F.FREQ_FRAC} Hz (formats.FREQ_FRAC)"),
    ("rate", "int32", f"raw rate word R, LSB 2^-{F.RATE_FRAC} deg/h (formats.RATE_FRAC), as the loop reports it"),
    ("temp", "int32", f"temperature word T, LSB 2^-{F.TEMP_FRAC} degC (formats.TEMP_FRAC)"),
    ("out", "int32", f"compensated rate word OUT, LSB 2^-{F.OUT_FRAC} deg/h (formats.OUT_FRAC)"),
    ("bias", "int32", f"bias word BIAS, LSB 2^-{F.OUT_FRAC} deg/h"),
    ("state", "uint8", "sequencer state 0..5 (formats.STATE_NAMES)"),
    ("mode", "uint8", "run-log mode 0..3 (formats.STATE_MODE of the state)"),
    ("flags", "uint8", "status flags (formats.FLAGS)"),
    ("valid", "uint8", "1: OUT/BIAS computed at this sample; 0: held"),
)
_SAMPLE_OFFSETS = {}
_off = 0
for _name, _typ, _ in SAMPLE_FIELDS:
    _SAMPLE_OFFSETS[_name] = _off
    _off += 4 if _typ.endswith("32") else 1
assert _off == SAMPLE.size

# -- ACK / NACK payload -----------------------------------------------------------------------------------
_REPLY = struct.Struct("<BBHII")           # req type, code, req seq, detail, sample; then UTF-8 text
# -- INFO payload -----------------------------------------------------------------------------------------
_INFO = struct.Struct("<BBHIBBBBIHBBII")   # 28 bytes, then the device name (name_len bytes, UTF-8)


class ProtocolError(ValueError):
    """A frame or payload that breaks the protocol, or a device the host cannot talk to."""


class ProtocolVersionError(ProtocolError):
    """The device speaks a protocol major this host does not read."""


class CaptureOutputError(ValueError):
    """The capture's output file cannot be written (missing directory, a directory, no permission)."""


def check_output_path(path) -> None:
    """CaptureOutputError unless ``path`` names a file that can be created: its directory exists
    and is writable, and ``path`` is not a directory."""
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise CaptureOutputError(f"{path}: is a directory (-o names the run-log file to write)")
    if not os.path.isdir(directory):
        raise CaptureOutputError(f"{path}: the directory {directory} does not exist")
    if not os.access(directory, os.W_OK):
        raise CaptureOutputError(f"{path}: the directory {directory} is not writable")


class UploadError(ValueError):
    """A table upload that did not succeed (refused, no answer, or read-back mismatch)."""


def crc16(data) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no xor-out; check 0x29B1)."""
    return binascii.crc_hqx(data, 0xFFFF)


def version_byte(major: int = PROTO_MAJOR, minor: int = PROTO_MINOR) -> int:
    return ((major & 15) << 4) | (minor & 15)


def encode_frame(ftype: int, seq: int, payload: bytes = b"", major: int = PROTO_MAJOR,
                 minor: int = PROTO_MINOR) -> bytes:
    """One frame (see the module doc): header, header CRC, payload, CRC-32."""
    if len(payload) > MAX_PAYLOAD:
        raise ProtocolError(f"{TYPE_NAMES.get(ftype, ftype)} payload of {len(payload)} bytes exceeds "
                            f"MAX_PAYLOAD {MAX_PAYLOAD}")
    head = SYNC + _HDR_BODY.pack(version_byte(major, minor), ftype, seq & 0xFFFF, len(payload))
    body = head + _U16.pack(crc16(head)) + payload
    return body + _U32.pack(zlib.crc32(body))


@dataclass
class Frame:
    """A decoded frame: type, sequence number, payload, the sender's protocol major/minor."""

    type: int
    seq: int
    payload: bytes
    major: int = PROTO_MAJOR
    minor: int = PROTO_MINOR


@dataclass
class DecoderStats:
    """Counters of the byte-stream decoder.

    ``frames`` accepted; ``header_errors`` syncs whose header CRC failed (or a length beyond
    MAX_PAYLOAD); ``crc_errors`` frames whose CRC-32 failed; ``resyncs`` hunts for a sync (each run of
    discarded bytes counts once); ``garbage_bytes`` bytes discarded; ``truncated`` an incomplete frame
    left when the stream ended."""

    bytes: int = 0
    frames: int = 0
    header_errors: int = 0
    crc_errors: int = 0
    resyncs: int = 0
    garbage_bytes: int = 0
    truncated: int = 0


class Decoder:
    """Incremental frame decoder: ``feed(bytes) -> [Frame]``; partial frames wait for more bytes.

    A sync alone is never trusted: the header CRC-16 must match (then the length is believed) and
    the CRC-32 of the whole frame must match; on either failure one byte (the false sync's first)
    is dropped and the scan resumes from the next byte."""

    def __init__(self):
        self.buf = bytearray()
        self.stats = DecoderStats()
        self._hunting = False

    def _discard(self, k: int) -> None:
        if k > 0:
            self.stats.garbage_bytes += k
            if not self._hunting:
                self.stats.resyncs += 1
                self._hunting = True

    def feed(self, data) -> list:
        buf = self.buf
        buf += data
        st = self.stats
        st.bytes += len(data)
        out = []
        pos = 0
        n = len(buf)
        while True:
            i = buf.find(SYNC, pos)
            if i < 0:
                keep = n - 1 if n > pos and buf[n - 1] == SYNC[0] else n
                self._discard(keep - pos)
                pos = keep
                break
            if i > pos:
                self._discard(i - pos)
                pos = i
            if n - pos < HEADER_SIZE:
                break
            ver, ftype, seq, length, hcrc = _HDR.unpack_from(buf, pos + 2)
            if hcrc != crc16(buf[pos:pos + 8]) or length > MAX_PAYLOAD:
                st.header_errors += 1
                self._discard(1)
                pos += 1
                continue
            end = pos + HEADER_SIZE + length + CRC_SIZE
            if end > n:
                break
            if _U32.unpack_from(buf, end - CRC_SIZE)[0] != zlib.crc32(buf[pos:end - CRC_SIZE]):
                st.crc_errors += 1
                self._discard(1)
                pos += 1
                continue
            out.append(Frame(ftype, seq, bytes(buf[pos + HEADER_SIZE:end - CRC_SIZE]), ver >> 4, ver & 15))
            st.frames += 1
            self._hunting = False
            pos = end
        del buf[:pos]
        return out

    def finish(self) -> list:
        """The stream ended: an incomplete frame at the front (``truncated``) is dropped and the
        bytes after it are decoded (a cut frame's claimed length may have covered whole frames);
        returns those frames.  Leaves the buffer empty."""
        out = []
        while self.buf:
            if self.buf.startswith(SYNC):
                self.stats.truncated += 1
            self._discard(1)
            del self.buf[:1]
            out += self.feed(b"")
        return out


# -- payloads ------------------------------------------------------------------------------------------

def pack_sample(counter, freq, rate, temp, out, bias, state, mode, flags, valid) -> bytes:
    """SAMPLE payload (1.0: 28 bytes, SAMPLE_FIELDS order)."""
    return SAMPLE.pack(counter & 0xFFFFFFFF, freq, rate, temp, out, bias, state, mode, flags, valid)


def unpack_sample(payload: bytes) -> tuple:
    """SAMPLE payload -> (counter, freq, rate, temp, out, bias, state, mode, flags, valid); trailing
    bytes of a newer minor are ignored.  ProtocolError when too short or a code is out of range."""
    if len(payload) < SAMPLE.size:
        raise ProtocolError(f"SAMPLE payload of {len(payload)} bytes, at least {SAMPLE.size} expected")
    s = SAMPLE.unpack_from(payload)
    if s[6] >= len(F.STATE_NAMES) or s[7] > 3 or s[9] > 1:
        raise ProtocolError(f"SAMPLE: state {s[6]}, mode {s[7]} or valid {s[9]} out of range")
    return s


@dataclass
class DeviceInfo:
    """The INFO payload: who the device is and how to read its samples.

    ``fs_q16`` sample rate x 2^16 [Hz]; ``*_frac`` fractional bits of the SAMPLE words (the host
    dequantizes with these, so they are the device's, not the host's); ``table_crc`` CRC-32 word of
    the active table (0: none); ``boot_id`` random per power-on (a change means the device
    restarted); ``counter`` the next sample's counter; ``status`` ST_* bits."""

    major: int = PROTO_MAJOR
    minor: int = PROTO_MINOR
    capabilities: int = 0
    fs_q16: int = 1 << 16
    freq_frac: int = F.FREQ_FRAC
    temp_frac: int = F.TEMP_FRAC
    rate_frac: int = F.RATE_FRAC
    out_frac: int = F.OUT_FRAC
    table_crc: int = 0
    table_version: int = T.VERSION
    status: int = 0
    boot_id: int = 0
    counter: int = 0
    name: str = ""

    @property
    def fs_hz(self) -> float:
        return self.fs_q16 / 65536.0

    def pack(self) -> bytes:
        name = self.name.encode("utf-8")[:255]
        return _INFO.pack(self.major, self.minor, self.capabilities, self.fs_q16, self.freq_frac, self.temp_frac,
                          self.rate_frac, self.out_frac, self.table_crc, self.table_version, self.status,
                          len(name), self.boot_id, self.counter & 0xFFFFFFFF) + name

    @classmethod
    def unpack(cls, payload: bytes) -> "DeviceInfo":
        if len(payload) < 2:
            raise ProtocolError(f"INFO payload of {len(payload)} bytes")
        if payload[0] != PROTO_MAJOR:
            raise ProtocolVersionError(version_message(payload[0], payload[1]))
        if len(payload) < _INFO.size:
            raise ProtocolError(f"INFO payload of {len(payload)} bytes, at least {_INFO.size} expected")
        v = _INFO.unpack_from(payload)
        name_len = v[11]
        name = payload[_INFO.size:_INFO.size + name_len].decode("utf-8", "replace")
        info = cls(*v[:11], boot_id=v[12], counter=v[13], name=name)
        if info.fs_q16 == 0:
            raise ProtocolError("INFO: sample rate 0")
        return info

    def capability_names(self) -> list:
        return [n for bit, n in CAP_NAMES.items() if self.capabilities & bit]


def version_message(major: int, minor: int) -> str:
    if major > PROTO_MAJOR:
        return (f"the device speaks serial protocol {major}.{minor}; this hdrg reads protocol {PROTO_MAJOR}.x "
                f"(any minor): update hdrg")
    return (f"the device speaks serial protocol {major}.{minor}, an older major that this hdrg "
            f"(protocol {PROTO_MAJOR}.{PROTO_MINOR}) does not read")


@dataclass
class Reply:
    """ACK / NACK payload: the request's type and seq, a reason code (R_*), ``detail`` (ACK of a
    TABLE: the table's CRC-32 word), ``sample`` (ACK of a TABLE: counter of the first sample computed
    with the new table), and a UTF-8 message (NACK: why)."""

    req_type: int
    code: int
    req_seq: int
    detail: int = 0
    sample: int = 0
    text: str = ""

    def pack(self) -> bytes:
        return _REPLY.pack(self.req_type, self.code, self.req_seq & 0xFFFF, self.detail & 0xFFFFFFFF,
                           self.sample & 0xFFFFFFFF) + self.text.encode("utf-8")[:MAX_PAYLOAD - _REPLY.size]

    @classmethod
    def unpack(cls, payload: bytes) -> "Reply":
        if len(payload) < _REPLY.size:
            raise ProtocolError(f"ACK/NACK payload of {len(payload)} bytes, at least {_REPLY.size} expected")
        v = _REPLY.unpack_from(payload)
        return cls(*v, text=payload[_REPLY.size:].decode("utf-8", "replace"))


# -- table checks (shared by the host's pre-check and the device) ------------------------------------

def table_problems(table) -> list:
    """The quantizer's guarantees checked on a decoded table (firmware_ref.table.Table, whose field
    ranges its constructor already checked): every Horner group's sum of |mantissas| and the
    aligned accumulator bound (host_tools.quantize's interval analysis) within 2^31 - 1, and the
    sum of |coefficients| within the output word.  Returns the problems (empty: usable)."""
    from host_tools.quantize import GROUP_NAMES, GROUPS, quantized_coef, rhu_shift

    probs = []
    e_g = list(table.e_row) + [table.e_7]
    for g, ks in enumerate(GROUPS):
        s = sum(abs(table.mant[k]) for k in ks)
        if s > F.ACC_LIMIT:
            probs.append(f"{GROUP_NAMES[g]}: sum of |mantissas| {s} exceeds 2^31 - 1")
    bounds = [rhu_shift(sum(abs(table.mant[k]) for k in GROUPS[g]), e_g[g] - table.e_acc) for g in range(4)]
    bounds.append(rhu_shift(abs(table.mant[GROUPS[4][0]]) << F.Q, F.Q + table.e_7 - table.e_acc))
    if sum(bounds) > F.ACC_LIMIT:
        probs.append(f"accumulator bound {sum(bounds)} exceeds 2^31 - 1 (an intermediate could overflow)")
    total = float(sum(abs(c) for c in quantized_coef(table)))
    out_range = F.INT32_SYM * 2.0 ** -F.OUT_FRAC
    if total > out_range:
        probs.append(f"sum of |coefficients| {total:.6g} deg/h exceeds the output word +-{out_range:.6g} deg/h")
    return probs


def table_mode_problem(table, reversal: bool):
    """Why ``table`` cannot run on a device whose run uses mode reversal (``reversal``) or FTR, or
    None: the combiner of an FTR table is 0 ('ftr'), of a mode-reversal table 1/2 (pair/trend)."""
    from firmware_ref.formats import COMBINERS

    name = COMBINERS[table.combiner] if 0 <= table.combiner < len(COMBINERS) else str(table.combiner)
    if reversal and table.combiner == 0:
        return (f"the table is for force-to-rebalance (combiner {name}) but the device runs mode reversal; "
                f"quantize a model fitted on mode-reversal runs")
    if not reversal and table.combiner != 0:
        return (f"the table is for mode reversal (combiner {name}) but the device runs force-to-rebalance; "
                f"quantize a model fitted on FTR runs")
    return None


def validate_table_payload(payload: bytes):
    """The device's check of an uploaded TABLE payload: ``(table, R_OK, "")`` or
    ``(None, code, message)`` with code R_TABLE_FORMAT, R_TABLE_CRC or R_TABLE_RANGE."""
    nwords = len(payload) // 4
    if len(payload) % 4 or nwords < T.N_FIXED + 1:
        return None, R_TABLE_FORMAT, f"{len(payload)} bytes is not a table (whole 32-bit words, >= {T.N_FIXED + 1})"
    words = struct.unpack(f"<{nwords}I", payload)
    if words[0] != T.MAGIC:
        return None, R_TABLE_FORMAT, f"bad magic 0x{words[0]:08x}"
    if words[1] != T.VERSION:
        return None, R_TABLE_FORMAT, f"table layout version {words[1]}, the device reads {T.VERSION}"
    if words[2] != nwords:
        return None, R_TABLE_FORMAT, f"length word {words[2]}, payload has {nwords} words"
    crc = T.crc32_words(words[:-1])
    if crc != words[-1]:
        return None, R_TABLE_CRC, f"table CRC-32 mismatch (stored 0x{words[-1]:08x}, computed 0x{crc:08x})"
    try:
        table = T.Table.from_words(words, "uploaded table")
    except T.TableError as exc:
        return None, R_TABLE_RANGE, str(exc)
    probs = table_problems(table)
    if probs:
        return None, R_TABLE_RANGE, "; ".join(probs)
    return table, R_OK, ""


# -- host side ----------------------------------------------------------------------------------------

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
        fr = self.request(T_READ_TABLE, b"", lambda f, s: f.type == T_TABLE or _is_reply_to(f, T_READ_TABLE, s),
                          timeout_s, on_frame)
        if fr is None:
            raise UploadError(f"no answer to READ_TABLE within {timeout_s:g} s")
        if fr.type != T_TABLE:
            r = Reply.unpack(fr.payload)
            raise UploadError(f"the device refused READ_TABLE: {REASONS.get(r.code, r.code)}: {r.text}")
        return fr.payload


def _is_reply_to(fr: Frame, req_type: int, seq: int) -> bool:
    if fr.type not in (T_ACK, T_NACK) or len(fr.payload) < _REPLY.size:
        return False
    r = Reply.unpack(fr.payload)
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
    """Upload ``table`` (firmware_ref.table.Table): refuse it before sending if it fails the
    quantizer's checks (:func:`table_problems`), check the device's version and capabilities
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
        fr = link.request(T_TABLE, data, lambda f, s: _is_reply_to(f, T_TABLE, s), timeout_s, on_frame)
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


# -- capture ----------------------------------------------------------------------------------------------

CAPTURE_COLUMNS = ("t_s", "freq_hz", "rate_dph", "mode", "temp_c", "comp_rate_dph", "comp_bias_dph", "comp_valid",
                   "status", "state", "seq")


class RunLogWriter:
    """Writes a run log (shared/formats/run-log.md) row by row: metadata and header with the first
    rows, then appended rows; flushed (and fsync'ed) every ``flush_every`` rows, every
    ``flush_interval_s`` seconds and at :meth:`close`, always at a line boundary, so the file is a
    valid run log at every flush.  Its first metadata line is ``# capture: in progress`` until
    :meth:`close` rewrites it in place (same length) to ``# capture: complete``: a file left by a
    killed capture says so, and the run-log reader warns about it (docs/RUN_LOG.md)."""

    def __init__(self, path, metadata: dict, columns=CAPTURE_COLUMNS, flush_every: int = 256,
                 flush_interval_s: float = 1.0):
        self.path = os.fspath(path)
        from host_tools.runlog import CAPTURE_KEY, CAPTURE_OPEN

        self.metadata = {CAPTURE_KEY: CAPTURE_OPEN, **{k: v for k, v in metadata.items() if k != CAPTURE_KEY}}
        self.columns = tuple(columns)
        self.flush_every = max(1, int(flush_every))
        self.flush_interval_s = flush_interval_s
        self.rows = 0
        self._pending = []
        self._fh = open(self.path, "w", encoding="utf-8", newline="\n")
        self._header_written = False
        self._last_flush = time.monotonic()

    def append(self, line: str) -> None:
        self._pending.append(line)
        if len(self._pending) >= self.flush_every or time.monotonic() - self._last_flush >= self.flush_interval_s:
            self.flush()

    def flush(self) -> None:
        if not self._pending:
            return
        parts = []
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
        if self._fh.closed:
            return
        try:
            self.flush()
            if self._header_written:
                self._mark_complete()
        finally:
            self._fh.close()

    def _mark_complete(self) -> None:
        from host_tools.runlog import CAPTURE_DONE, CAPTURE_KEY, CAPTURE_OPEN

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
            lines.append(f"  {self.path}: not written (no sample could be converted)")
        lines.append(f"  frames {self.frames} in {self.elapsed_s:.1f} s; CRC errors {self.crc_errors} (frame) + "
                     f"{self.header_errors} (header); resyncs {self.resyncs} ({self.garbage_bytes} bytes discarded); "
                     f"sequence gaps {self.seq_gaps} frame(s) in {self.gap_events} place(s)")
        extra = [(n, getattr(self, n)) for n in ("truncated", "duplicates", "bad_payload", "out_of_order",
                                                   "unknown_type", "dropped_no_info", "table_changes")
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


def capture(port, path, duration_s: float | None = None, idle_timeout_s: float | None = 10.0,
            max_samples: int | None = None, flush_every: int = 256, flush_interval_s: float = 1.0,
            progress=None, extra_metadata: dict | None = None, stop=None) -> CaptureResult:
    """Record the device's SAMPLE frames on ``port`` (an open port or a URL/path) into the run log
    ``path`` (CSV: CAPTURE_COLUMNS, see docs/PROTOCOL.md) until ``duration_s`` of device time
    [s from the first sample], ``max_samples``, no frame for ``idle_timeout_s`` [s wall time; None:
    wait forever], the device reports the end of its run or restarts, ``stop()`` returns True,
    Ctrl-C, or a port error (disconnect).  The file is written incrementally (see RunLogWriter)
    and only once an INFO frame gave the sample rate and formats; samples before it are kept in
    memory (up to 100000).  ``progress(result)`` is called after every read.  Returns the
    :class:`CaptureResult`; ProtocolVersionError for a device of another protocol major."""
    import serial

    check_output_path(path)
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
        try:
            writer = RunLogWriter(path, meta, flush_every=flush_every, flush_interval_s=flush_interval_s)
        except OSError as exc:   # the output, not the port: never reported as "port error"
            raise CaptureOutputError(f"cannot write the run log {os.fspath(path)}: {exc.strerror or exc}") from None
        fmt = _SampleFormatter(info)
        res.written = True

    def take(s: tuple, seq: int) -> bool:
        """Write one sample; False when the capture should end."""
        nonlocal last_counter, first_counter
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
        if res.first_t_s is None:
            res.first_t_s = t
        res.last_t_s = t
        if max_samples is not None and res.samples >= max_samples:
            res.reason = f"{max_samples} samples recorded"
            return False
        return True

    def handle(frames) -> bool:
        """Process device frames; False when the data says the capture ends."""
        nonlocal pending
        for fr in frames:
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
            if idle_timeout_s is not None and time.monotonic() - link.last_rx > idle_timeout_s:
                res.reason = f"no frame from the device for {idle_timeout_s:g} s"
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
            if own:
                try:
                    port.close()
                except Exception:  # pragma: no cover
                    pass
    return res


# -- CLI ----------------------------------------------------------------------------------------------------

def _add_port_args(parser) -> None:
    parser.add_argument("--port", required=True, help="serial port or pyserial URL (/dev/ttyUSB0, /dev/pts/5, loop://)")
    parser.add_argument("--baud", type=int, default=115200, help="baud rate (default 115200)")


def configure_capture_cli(parser: argparse.ArgumentParser) -> None:
    _add_port_args(parser)
    parser.add_argument("-o", "--output", required=True, help="run log (CSV) to write")
    parser.add_argument("--duration", type=float, default=None, metavar="S",
                        help="stop after S seconds of device time (default: until the device stops or Ctrl-C)")
    parser.add_argument("--idle-timeout", type=float, default=30.0, metavar="S",
                        help="stop when no frame arrives for S seconds (default 30; 0: never)")
    parser.add_argument("--flush-every", type=int, default=256, metavar="N", help="flush every N rows (and every second)")
    parser.add_argument("--quiet", action="store_true", help="no live progress line")


def configure_upload_cli(parser: argparse.ArgumentParser) -> None:
    _add_port_args(parser)
    parser.add_argument("table", metavar="TABLE", help="coefficient table: table.json (hdrg quantize), .bin or .memh")
    parser.add_argument("--timeout", type=float, default=2.0, metavar="S", help="answer timeout per attempt (default 2)")
    parser.add_argument("--retries", type=int, default=3, help="TABLE attempts without an answer (default 3)")


def _command_of(parser) -> str:
    return parser.prog.rsplit(" ", 1)[-1]


def configure_cli(parser: argparse.ArgumentParser) -> None:
    """Both `hdrg capture` and `hdrg upload` live here: the subcommand name (the parser's prog)
    selects the arguments."""
    if _command_of(parser) == "upload":
        configure_upload_cli(parser)
    else:
        configure_capture_cli(parser)
    parser.set_defaults(_serial_command=_command_of(parser))


class _Progress:
    def __init__(self, stream=sys.stderr, interval_s: float = 0.25):
        self.stream, self.interval_s, self._last = stream, interval_s, 0.0

    def __call__(self, res: CaptureResult) -> None:
        now = time.monotonic()
        if now - self._last >= self.interval_s:
            self._last = now
            self.stream.write("\r" + res.progress_line() + "   ")
            self.stream.flush()


def run_capture_cli(args) -> int:
    import serial

    check_output_path(args.output)
    try:
        port = open_port(args.port, args.baud)
    except serial.SerialException as exc:
        print(f"hdrg capture: error: cannot open {args.port}: {exc}", file=sys.stderr)
        return 2
    idle = None if not args.idle_timeout or args.idle_timeout <= 0 else args.idle_timeout
    prog = None if args.quiet else _Progress()
    try:
        res = capture(port, args.output, duration_s=args.duration, idle_timeout_s=idle,
                      flush_every=args.flush_every, progress=prog)
    finally:
        port.close()
    if prog is not None:
        sys.stderr.write("\n")
    print(res.summary())
    return 0 if res.written else 1


def run_upload_cli(args) -> int:
    import serial

    from host_tools.quantize import read_table

    try:
        table = read_table(args.table)
    except T.TableError as exc:
        raise T.TableError(f"refused before sending: {exc}") from None
    probs = table_problems(table)
    if probs:
        raise T.TableError(f"{args.table}: refused before sending: " + "; ".join(probs))
    try:
        port = open_port(args.port, args.baud)
    except serial.SerialException as exc:
        print(f"hdrg upload: error: cannot open {args.port}: {exc}", file=sys.stderr)
        return 2
    try:
        link = HostLink(port)
        r = upload(link, table, timeout_s=args.timeout, retries=args.retries)
    except serial.SerialException as exc:
        print(f"hdrg upload: error: port error: {exc}", file=sys.stderr)
        return 2
    finally:
        port.close()
    print(f"{args.table}: uploaded to {r.info.name or 'the device'} (protocol {r.info.major}.{r.info.minor}): "
          f"CRC-32 0x{r.crc:08x} acknowledged, applied from sample {r.apply_sample}; read back and compared: "
          f"identical ({len(table.to_bytes())} bytes, {r.attempts} attempt(s))")
    return 0


def run_cli(args) -> int:
    cmd = getattr(args, "_serial_command", None) or getattr(args, "command", "capture")
    return run_upload_cli(args) if cmd == "upload" else run_capture_cli(args)
