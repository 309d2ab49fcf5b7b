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

import functools
import json
import os
import struct

HEADER = struct.Struct("<IB")
MAX_MESSAGE_BYTES = 1 << 20  # what a controller process may send in one message [bytes]
READ_CHUNK_BYTES = 1 << 16  # the most one read from a pipe takes (a pipe's buffer) [bytes]

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
    line, raw = split_header_line(payload)
    header = _header(line)
    if not isinstance(header, dict):
        raise ValueError("array message header is not an object")
    return header, bytes(raw)


def split_header_line(payload: bytes) -> tuple[bytes, memoryview]:
    """(header line, raw bytes after it) of an ACTION or SEE payload, the header still unparsed;
    ValueError if there is no header line."""
    end = payload.find(b"\n", 0, 4096)
    if end < 0:
        raise ValueError("array message without a header line")
    return bytes(payload[:end]), memoryview(payload)[end + 1:]


@functools.lru_cache(maxsize=64)
def _header(text: bytes):
    """A parsed header line (callers only read it). The same few headers come with every action,
    so they are parsed once."""
    return json.loads(text)


def write_all(fd: int, data: bytes) -> None:
    """Blocking write of the whole buffer (the controller process's side)."""
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


class Inbox:
    """Blocking reads of whole messages from a pipe, a message (header and body) per read where
    it arrived in one piece; bytes beyond a message wait for the next (the controller process's side)."""

    def __init__(self, fd: int):
        self.fd, self.pending = fd, bytearray()

    def take(self, n: int) -> bytes:
        while len(self.pending) < n:
            chunk = os.read(self.fd, max(n - len(self.pending), READ_CHUNK_BYTES))
            if not chunk:
                raise EOFError
            self.pending += chunk
        data = bytes(self.pending[:n])
        del self.pending[:n]
        return data

    def recv(self) -> tuple[bytes, bytes]:
        if not self.pending:  # the usual case: one read holds exactly one whole message
            chunk = os.read(self.fd, READ_CHUNK_BYTES)
            if not chunk:
                raise EOFError
            if len(chunk) >= HEADER.size:
                length, kind = HEADER.unpack_from(chunk)
                if len(chunk) == HEADER.size + length:
                    return KINDS[kind], chunk[HEADER.size:]
            self.pending += chunk
        length, kind = HEADER.unpack(self.take(HEADER.size))
        return KINDS[kind], self.take(length) if length else b""


KINDS = [bytes([k]) for k in range(256)]  # a message's kind byte as the bytes the constants above are
