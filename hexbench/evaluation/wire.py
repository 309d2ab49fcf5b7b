"""The messages between the evaluator and a sandboxed controller process (one owner of the framing).

A message is a 5-byte header (payload length: uint32 little-endian; kind: one byte) and its
payload. The evaluator never unpickles or evaluates anything it receives: a payload is JSON or a
raw float array, parsed strictly, and a message longer than `MAX_MESSAGE_BYTES` is refused
before it is read.

Evaluator -> controller process          controller process -> evaluator
  MAKE   JSON {"file", "task"}              OK      JSON (after MAKE: what the controller declares)
  RESET  JSON {"task", "seed"}              ACTION  JSON header line + raw array bytes
  ACT    raw float32 observation            ERROR   JSON {"message"}: its code raised
  SEE    JSON header line + raw uint8 image
  QUIT   empty
"""

from __future__ import annotations

import json
import os
import struct

HEADER = struct.Struct("<IB")
MAX_MESSAGE_BYTES = 1 << 20  # what a controller process may send in one message [bytes]

MAKE, RESET, ACT, SEE, QUIT = b"M", b"R", b"A", b"S", b"Q"
OK, ACTION, ERROR = b"K", b"a", b"E"


def frame(kind: bytes, payload: bytes = b"") -> bytes:
    return HEADER.pack(len(payload), kind[0]) + payload


def json_payload(value) -> bytes:
    return json.dumps(value, separators=(",", ":")).encode()


def array_payload(header: dict, raw: bytes) -> bytes:
    return json_payload(header) + b"\n" + raw


def split_array_payload(payload: bytes) -> tuple[dict, bytes]:
    """(header, raw bytes) of an ACTION or SEE payload; ValueError if malformed."""
    end = payload.find(b"\n", 0, 4096)
    if end < 0:
        raise ValueError("array message without a header line")
    header = json.loads(payload[:end])
    if not isinstance(header, dict):
        raise ValueError("array message header is not an object")
    return header, payload[end + 1:]


def write_all(fd: int, data: bytes) -> None:
    """Blocking write of the whole buffer (the controller process's side)."""
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def read_exact_blocking(fd: int, n: int) -> bytes:
    """Blocking read of exactly n bytes; EOFError if the other side closed (the controller process's side)."""
    chunks, got = [], 0
    while got < n:
        chunk = os.read(fd, n - got)
        if not chunk:
            raise EOFError
        chunks.append(chunk)
        got += len(chunk)
    return b"".join(chunks)


def recv_blocking(fd: int) -> tuple[bytes, bytes]:
    length, kind = HEADER.unpack(read_exact_blocking(fd, HEADER.size))
    return bytes([kind]), read_exact_blocking(fd, length) if length else b""
