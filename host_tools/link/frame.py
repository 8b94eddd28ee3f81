"""Framing of the serial link (docs/PROTOCOL.md): the envelope, its CRCs, the frame types and the
protocol-version rules.  No I/O: bytes in, frames out (the pyserial ``threaded.Packetizer`` role).

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
they touch.  The payloads are in host_tools.link.codec.

Public API: :func:`crc16`, :func:`encode_frame`, :class:`Frame`, :class:`Decoder`,
:func:`version_message`, :class:`ProtocolError`, :class:`ProtocolVersionError`.
"""
from __future__ import annotations

import binascii
import struct
import zlib
from dataclasses import dataclass

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


class ProtocolError(ValueError):
    """A frame or payload that breaks the protocol, or a device the host cannot talk to."""


class ProtocolVersionError(ProtocolError):
    """The device speaks a protocol major this host does not read."""


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


def version_message(major: int, minor: int) -> str:
    """Why this host cannot talk to a sender of protocol ``major``.``minor`` (another major)."""
    if major > PROTO_MAJOR:
        return (f"the device speaks serial protocol {major}.{minor}; this hdrg reads protocol {PROTO_MAJOR}.x "
                f"(any minor): update hdrg")
    return (f"the device speaks serial protocol {major}.{minor}, an older major that this hdrg "
            f"(protocol {PROTO_MAJOR}.{PROTO_MINOR}) does not read")
