"""`hexbench verify`: re-simulate a logged episode from its metadata and compare it with the log.

The episode is replayed with the evaluator's own episode function (`hexbench.evaluate.run_episode`)
from the task, seed and controller file named in the log, recorded again into a temporary
folder, and every message (topic, time, bytes) and the outcome record are compared with the
logged file. Recording is deterministic (simulated time only), so a faithful log matches
exactly; any edit to a message, a lost message or a different controller shows up as the first
mismatch. A damaged file fails its CRC check before any simulation.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

from hexbench.recording.reader import EpisodeFileError, all_messages, read_episode


@dataclass(frozen=True)
class VerifyResult:
    ok: bool
    message: str
    messages_compared: int = 0


def _first_difference(logged: dict, replayed: dict) -> tuple[str | None, int]:
    compared = 0
    for topic in sorted(set(logged) | set(replayed)):
        a, b = logged.get(topic, []), replayed.get(topic, [])
        if len(a) != len(b):
            return f"{topic}: {len(a)} messages logged, {len(b)} on re-simulation", compared
        for i, ((ta, da), (tb, db)) in enumerate(zip(a, b)):
            compared += 1
            if ta != tb:
                return f"{topic} message {i}: logged at {ta} ns, re-simulated at {tb} ns", compared
            if da != db:
                return f"{topic} message {i} at t = {ta / 1e9:.4f} s differs from the re-simulation", compared
    return None, compared


def verify_episode(mcap_path: str | Path) -> VerifyResult:
    from hexbench.controller import file_sha256
    from hexbench.evaluate import EpisodeJob, run_episode
    from hexbench.tasks import load_suite

    mcap_path = Path(mcap_path)
    try:
        log = read_episode(mcap_path)
    except EpisodeFileError as e:
        return VerifyResult(False, str(e))
    e = log.episode
    missing = [k for k in ("protocol", "terrain", "level", "index", "seed", "controller_file", "controller_sha256")
               if k not in e]
    if missing:
        return VerifyResult(False, f"{mcap_path}: episode metadata lacks {', '.join(missing)}; cannot re-simulate")
    controller = Path(e["controller_file"])
    if not controller.is_file():
        return VerifyResult(False, f"{mcap_path}: controller file {controller} not found (run from the directory the "
                                   f"evaluation ran in)")
    if file_sha256(controller) != e["controller_sha256"]:
        return VerifyResult(False, f"{mcap_path}: controller file {controller} has changed since the episode was "
                                   f"recorded (sha256 differs)")
    try:
        task = load_suite(e["protocol"]).task(e["terrain"], float(e["level"]))
    except ValueError as err:
        return VerifyResult(False, f"{mcap_path}: {err}")
    max_steps = int(e["max_steps"]) if "max_steps" in e else None
    with tempfile.TemporaryDirectory(prefix="hexbench_verify_") as tmp:
        job = EpisodeJob(str(controller), task, int(e["index"]), int(e["seed"]), record_dir=tmp,
                         max_steps=None if max_steps in (None, task.max_steps) else max_steps)
        row = run_episode(job)
        replay_path = Path(tmp) / row["mcap_path"]
        replay = read_episode(replay_path)
        diff, compared = _first_difference(all_messages(mcap_path), all_messages(replay_path))
    if diff is not None:
        return VerifyResult(False, f"{mcap_path}: {diff}", compared)
    if replay.outcome != log.outcome:
        keys = sorted(k for k in set(replay.outcome) | set(log.outcome)
                      if replay.outcome.get(k) != log.outcome.get(k) and not k.endswith(("_sha256", "_path")))
        if keys:
            return VerifyResult(False, f"{mcap_path}: outcome differs from the re-simulation in {', '.join(keys)}",
                                compared)
    return VerifyResult(True, f"{mcap_path}: {compared} messages match the re-simulation exactly", compared)
