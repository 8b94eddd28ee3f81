"""Payloads of the serial link (docs/PROTOCOL.md): SAMPLE, INFO (:class:`DeviceInfo`), ACK/NACK
(:class:`Reply`) with their reason codes, and TABLE (:func:`validate_table_payload`).  No I/O.

The fixed-point words of SAMPLE use the formats of firmware_ref/formats.py.  A TABLE payload is
the coefficient table's own binary layout (firmware_ref/table.py); it is checked by that module's
reader and constructor (``Table.from_bytes``: size, magic, version, length word, CRC-32, every
field's range, the Horner interval bounds), plus the one guarantee of the quantizer that the
table does not carry itself (:func:`table_problems`: the sum of |coefficients| fits the output
word).  This module only maps which of those failed to a NACK reason code.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

from firmware_ref import formats as F
from firmware_ref import table as T
from host_tools.link.frame import MAX_PAYLOAD, PROTO_MAJOR, PROTO_MINOR, ProtocolError, ProtocolVersionError, \
    version_message
from host_tools.fixed.quantize import quantized_coef

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
R_TABLE_RANGE = 6        # table: a field outside its legal range or interval bound, or sum |k| beyond OUT
R_UNSUPPORTED = 7        # the device lacks the capability (e.g. upload)
R_TABLE_MODE = 8         # table: its combiner does not match the device's mode (FTR table, reversal run or back)
REASONS = {R_OK: "ok", R_UNKNOWN_TYPE: "unknown frame type", R_BAD_LENGTH: "bad payload length",
           R_VERSION: "unsupported protocol version", R_TABLE_FORMAT: "table format", R_TABLE_CRC: "table CRC-32",
           R_TABLE_RANGE: "table range", R_UNSUPPORTED: "not supported by the device",
           R_TABLE_MODE: "table combiner does not match the device's mode"}

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

# -- ACK / NACK payload -----------------------------------------------------------------------------------
_REPLY = struct.Struct("<BBHII")           # req type, code, req seq, detail, sample; then UTF-8 text
# -- INFO payload -----------------------------------------------------------------------------------------
_INFO = struct.Struct("<BBHIBBBBIHBBII")   # 28 bytes, then the device name (name_len bytes, UTF-8)


# -- device text -------------------------------------------------------------------------------------

def printable(text) -> str:
    """``text`` from the device (its name, a NACK's message) made safe to print on one line:
    every character that is not printable (ESC, CR, LF, other controls, bidi and zero-width marks)
    and the backslash written as a Python escape (``\\x1b``, ``\\n``, ``\\u202e``, ``\\\\``), so
    a device cannot move the cursor, start a line or forge a message of the host."""
    return "".join(repr(ch)[1:-1] if ch == "\\" or not ch.isprintable() else ch for ch in str(text))


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

    def format_differences(self) -> list:
        """The word formats (fractional bits) in which the device differs from this host's
        firmware_ref.formats, as ``"freq_frac 18 (this hdrg: 15)"`` texts; [] when they agree."""
        host = {"freq_frac": F.FREQ_FRAC, "temp_frac": F.TEMP_FRAC, "rate_frac": F.RATE_FRAC, "out_frac": F.OUT_FRAC}
        return [f"{k} {getattr(self, k)} (this hdrg: {v})" for k, v in host.items() if getattr(self, k) != v]


def rate_mismatch(table, fs_q16: int, who: str = "the device"):
    """Why ``table`` (firmware_ref.table.Table) cannot run at the sample rate ``fs_q16`` [Hz x 2^16]
    of ``who``, or None: the table's timing (sample counts) and rate gain hold its own rate, so a
    table quantized at another rate would run with its times and its rate term off by the ratio."""
    if table.fs_q16 == fs_q16:
        return None
    t_hz, d_hz = table.fs_q16 / 65536.0, fs_q16 / 65536.0
    return (f"the table is quantized for {t_hz:g} Hz but {who} samples at {d_hz:g} Hz (its timing and rate gain "
            f"would be {t_hz / d_hz:g}x off): quantize a model fitted on runs at {d_hz:g} Hz, the device's rate")


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


# -- TABLE payload: checked by firmware_ref.table.Table itself ---------------------------------------

def table_problems(table) -> list:
    """Why ``table`` (firmware_ref.table.Table) must not be loaded, or [] (usable): its own checks
    (``Table.validate``: field ranges, Horner interval bounds; run again because a Table object
    can be changed after its construction) and the quantizer's output-word guarantee (the sum of
    |coefficients| within +-2^31 LSB of OUT, as host_tools.fixed.quantize refuses such a model)."""
    try:
        table.validate()
    except T.TableError as exc:
        return [str(exc)]
    total = float(sum(abs(c) for c in quantized_coef(table)))
    out_range = F.INT32_SYM * 2.0 ** -F.OUT_FRAC
    if total > out_range:
        return [f"sum of |coefficients| {total:.6g} deg/h exceeds the output word +-{out_range:.6g} deg/h"]
    return []


def table_mode_problem(table, reversal: bool):
    """Why ``table`` cannot run on a device whose run uses mode reversal (``reversal``) or FTR, or
    None: the combiner of an FTR table is 0 ('ftr'), of a mode-reversal table 1/2 (pair/trend)."""
    name = F.COMBINERS[table.combiner] if 0 <= table.combiner < len(F.COMBINERS) else str(table.combiner)
    if reversal and table.combiner == 0:
        return (f"the table is for force-to-rebalance (combiner {name}) but the device runs mode reversal; "
                f"quantize a model fitted on mode-reversal runs")
    if not reversal and table.combiner != 0:
        return (f"the table is for mode reversal (combiner {name}) but the device runs force-to-rebalance; "
                f"quantize a model fitted on FTR runs")
    return None


def validate_table_payload(payload: bytes):
    """The device's check of an uploaded TABLE payload: ``(table, R_OK, "")`` or
    ``(None, code, message)`` with code R_TABLE_FORMAT, R_TABLE_CRC or R_TABLE_RANGE and the
    message of firmware_ref.table (see the module doc)."""
    try:
        table = T.Table.from_bytes(payload, "uploaded table")
    except T.TableError as exc:
        code = _refusal_code(payload, exc)
        return None, code, (f"not a table: {exc}" if code == R_TABLE_FORMAT else str(exc))
    probs = table_problems(table)
    if probs:
        return None, R_TABLE_RANGE, "; ".join(probs)
    return table, R_OK, ""


def _refusal_code(payload: bytes, exc: T.TableError) -> int:
    """The reason code of ``exc``, raised by ``Table.from_bytes(payload)``: R_TABLE_RANGE when its
    constructor refused a field (``from_words`` re-raises that TableError, which stays the
    context); R_TABLE_FORMAT when the same words with a correct CRC-32 word fail the same way
    (size, magic, version, length word: checked before the CRC); otherwise R_TABLE_CRC."""
    if isinstance(exc.__context__, T.TableError):
        return R_TABLE_RANGE
    if len(payload) % 4 or not payload:
        return R_TABLE_FORMAT
    words = list(struct.unpack(f"<{len(payload) // 4}I", payload))
    words[-1] = T.crc32_words(words[:-1])
    try:
        T.Table.from_words(words, "uploaded table")
    except T.TableError as again:
        if str(again) == str(exc):
            return R_TABLE_FORMAT
    return R_TABLE_CRC
