"""The serial link to the gyroscope's controller (docs/PROTOCOL.md), in layers, each using only
those below it (as pyserial separates transport, framing and tools):

* :mod:`~host_tools.link.frame`: the envelope, CRC-16/CRC-32, frame types, :class:`Decoder`,
  version rules (no I/O);
* :mod:`~host_tools.link.codec`: SAMPLE / INFO / TABLE / ACK / NACK payloads, reason codes; a TABLE
  is checked by firmware_ref.table.Table itself;
* :mod:`~host_tools.link.host`: :class:`HostLink`, :func:`open_port`, :func:`upload`;
* :mod:`~host_tools.link.capture`: :class:`RunLogWriter` and :func:`capture`;
* :mod:`~host_tools.link.transport` and :mod:`~host_tools.link.device`: the virtual controller
  (`hdrg device`) on a pty or a pyserial port;
* the commands `hdrg capture`, `hdrg upload` and `hdrg device` are in host_tools.cli.

This package namespace gathers the host-side API of the layers (not the device's).
"""
from host_tools.link.capture import CAPTURE_COLUMNS, OUTPUT_SUFFIXES, CaptureOutputError, CaptureResult, \
    RunLogWriter, capture, check_output_path
from host_tools.link.codec import CAP_NAMES, CAP_SAMPLES, CAP_TABLE_READ, CAP_TABLE_UPLOAD, CAP_VIRTUAL, R_BAD_LENGTH, \
    R_OK, R_TABLE_CRC, R_TABLE_FORMAT, R_TABLE_MODE, R_TABLE_RANGE, R_UNKNOWN_TYPE, R_UNSUPPORTED, R_VERSION, \
    REASONS, SAMPLE, SAMPLE_FIELDS, ST_RUN_ENDED, ST_STREAMING, DeviceInfo, Reply, pack_sample, printable, \
    rate_mismatch, table_mode_problem, table_problems, unpack_sample, validate_table_payload
from host_tools.link.frame import CRC_SIZE, HEADER_SIZE, MAX_PAYLOAD, OVERHEAD, PROTO_MAJOR, PROTO_MINOR, SYNC, \
    T_ACK, T_GET_INFO, T_INFO, T_NACK, T_READ_TABLE, T_SAMPLE, T_TABLE, TYPE_NAMES, Decoder, DecoderStats, Frame, \
    ProtocolError, ProtocolVersionError, crc16, encode_frame, version_byte, version_message
from host_tools.link.host import MAX_TIMEOUT_S, HostLink, LinkStats, PortError, UploadError, UploadResult, \
    is_reply_to, open_port, upload
