"""The evaluator <-> controller messages: framing over a pipe, and the ACTION payload both sides build and read."""

import os

import numpy as np
import pytest

from hexbench.evaluation import wire
from hexbench.evaluation.controller_host import action_message
from hexbench.evaluation.remote import NotAnArray, WrongDtype, WrongShape, action_layout


@pytest.fixture
def pipe():
    read_fd, write_fd = os.pipe()
    yield read_fd, write_fd
    os.close(read_fd)
    os.close(write_fd)


def test_inbox_takes_whole_messages_however_the_reads_cut_them(pipe):
    read_fd, write_fd = pipe
    inbox = wire.Inbox(read_fd)
    first, second = wire.frame(wire.ACT, b"\x01" * 12), wire.frame(wire.RESET, b'{"seed":3}')
    os.write(write_fd, first)  # one read, one message
    assert inbox.recv() == (wire.ACT, b"\x01" * 12)
    os.write(write_fd, first + second[:3])  # a message and the start of the next in one read
    assert inbox.recv() == (wire.ACT, b"\x01" * 12)
    os.write(write_fd, second[3:])
    assert inbox.recv() == (wire.RESET, b'{"seed":3}')
    os.write(write_fd, wire.frame(wire.QUIT))  # an empty body
    assert inbox.recv() == (wire.QUIT, b"")


def test_inbox_says_eof_when_the_channel_closes_inside_a_message():
    read_fd, write_fd = os.pipe()
    try:
        os.write(write_fd, wire.frame(wire.ACT, b"\x01" * 12)[:7])
        os.close(write_fd)
        with pytest.raises(EOFError):
            wire.Inbox(read_fd).recv()
    finally:
        os.close(read_fd)


@pytest.mark.parametrize("action", [
    np.linspace(-1, 1, 18, dtype=np.float32),
    np.linspace(-1, 1, 4).astype(">f8"),  # big-endian: sent as little-endian
    np.ones((2, 3), dtype=np.float32)[:, ::2],  # not contiguous
    np.array(0.5, dtype=np.float32),  # zero-dimensional
])
def test_a_float_action_arrives_as_the_same_values(action):
    line, raw = wire.split_header_line(action_message(action))
    dtype, shape, size_bytes = action_layout(line)
    assert shape == action.shape and len(raw) == size_bytes
    assert np.array_equal(np.frombuffer(raw, dtype=dtype).reshape(shape), action)


def test_the_same_action_layout_gives_the_same_message_step_after_step():
    a, b = np.zeros(18, np.float32), np.ones(18, np.float32)
    line_a, _ = wire.split_header_line(action_message(a))
    line_b, _ = wire.split_header_line(action_message(b))
    assert line_a == line_b
    assert wire.split_header_line(action_message(np.zeros(17, np.float32)))[0] != line_a


@pytest.mark.parametrize("action, expected", [
    ([0.0] * 18, NotAnArray("list")),
    (np.zeros(18, dtype=np.int64), WrongDtype("int64", (18,))),
    (np.zeros(5000, dtype=np.float32), WrongShape((5000,))),
])
def test_anything_but_a_small_float_array_is_described_not_sent(action, expected):
    line, raw = wire.split_header_line(action_message(action))
    assert action_layout(line) == expected and len(raw) == 0


@pytest.mark.parametrize("line", [b"[1, 2]", b"{\"type\": \"ndarray\"}", b"not json", b"[" * 100_000])
def test_a_malformed_header_line_is_an_error_never_a_value(line):
    with pytest.raises((ValueError, KeyError, TypeError, RecursionError)):
        action_layout(line)


def test_an_array_message_needs_its_header_line():
    with pytest.raises(ValueError):
        wire.split_header_line(b"\x00" * 8000)
