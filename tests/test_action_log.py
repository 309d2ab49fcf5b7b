"""The action-log format: exact round trip, deterministic bytes, and one clear error for damage."""

import numpy as np
import pytest

from hexbench.artifacts import action_log
from hexbench.artifacts.action_log import ActionLog, ActionLogError


def _log(steps=50, dim=18, seed=0):
    rng = np.random.default_rng(seed)
    return ActionLog("v1", "rough", 3.0, 2, 12345, "cpg_residual",
                     rng.uniform(-1, 1, (steps, dim)).astype(np.float32))


def test_round_trip_is_exact_and_bytes_are_deterministic(tmp_path):
    log = _log()
    sha = action_log.write(tmp_path / "a.actions", log)
    back = action_log.read(tmp_path / "a.actions", sha)
    assert np.array_equal(back.actions, log.actions) and back.actions.dtype == np.float32
    assert back.header() == log.header()
    assert action_log.encode(log) == action_log.encode(_log())


@pytest.mark.parametrize("damage", ["magic", "header", "body", "truncated", "steps"])
def test_damaged_logs_are_one_error(tmp_path, damage):
    data = bytearray(action_log.encode(_log()))
    if damage == "magic":
        data[0] ^= 0xFF
    elif damage == "header":
        data[len(action_log.MAGIC) + 2] = ord("#")
    elif damage == "body":
        data[-10] ^= 0xFF
    elif damage == "truncated":
        del data[-30:]
    else:
        data = bytearray(bytes(data).replace(b'"steps":50', b'"steps":51'))
    with pytest.raises(ActionLogError):
        action_log.decode(bytes(data), "x.actions")


def test_a_log_that_does_not_hash_to_its_row_is_refused(tmp_path):
    action_log.write(tmp_path / "a.actions", _log())
    with pytest.raises(ActionLogError, match="sha256 differs"):
        action_log.read(tmp_path / "a.actions", "0" * 64)
    with pytest.raises(ActionLogError, match="cannot be read"):
        action_log.read(tmp_path / "missing.actions")


def test_a_bomb_header_is_refused_before_decompressing():
    import json
    import zlib

    header = json.dumps({"protocol": "v1", "terrain": "rough", "level": 3.0, "index": 0, "seed": 1,
                         "action_mode": "joint", "steps": 10 ** 9, "dim": 18}).encode()
    with pytest.raises(ActionLogError, match="outside"):
        action_log.decode(action_log.MAGIC + header + b"\n" + zlib.compress(b"\0" * 1000), "bomb")
