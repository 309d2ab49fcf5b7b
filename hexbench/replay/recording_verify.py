"""`hexbench verify EPISODE.mcap`: re-simulate a logged episode from its action log and compare it with the log.

The episode is replayed through the one episode loop (hexbench.suite.rollout) from the task and seed
named in the log and the actions of its action log (`<episode id>.actions` beside the .mcap;
the controller is never run, so a controller cannot vouch for itself), recorded again into a
temporary folder, and every message (topic, time, bytes) and the outcome record are compared with
the logged file. Recording is deterministic (simulated time only), so a faithful log matches
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
    from hexbench.artifacts import action_log
    from hexbench.errors import HexbenchError
    from hexbench.recording import make_episode_recorder
    from hexbench.suite.rollout import LoggedActions, play
    from hexbench.suite.tasks import load_suite

    mcap_path = Path(mcap_path)
    try:
        log = read_episode(mcap_path)
    except EpisodeFileError as e:
        return VerifyResult(False, str(e))
    e = log.episode
    missing = [k for k in ("protocol", "terrain", "level", "index", "seed", "episode_id") if k not in e]
    if missing:
        return VerifyResult(False, f"{mcap_path}: episode metadata lacks {', '.join(missing)}; cannot re-simulate")
    try:
        level, index, seed = float(e["level"]), int(e["index"]), int(e["seed"])
        max_steps = int(e["max_steps"]) if "max_steps" in e else None
        # the action log beside the episode file, wherever the run was made or is verified from
        actions_path = mcap_path.with_name(f"{e['episode_id']}{action_log.SUFFIX}")
    except ValueError:
        return VerifyResult(False, f"{mcap_path}: episode metadata is malformed (level, index, seed, max_steps or "
                                   f"episode id {e['episode_id']!r})")
    try:
        actions = action_log.read(actions_path, log.outcome.get("action_log_sha256"))
        task = load_suite(e["protocol"]).task(e["terrain"], level)
    except (HexbenchError, ValueError) as err:
        return VerifyResult(False, f"{mcap_path}: {err}")
    if (actions.terrain, float(actions.level), actions.index, actions.seed) != (e["terrain"], level, index, seed):
        return VerifyResult(False, f"{mcap_path}: its action log {actions_path.name} belongs to another episode")
    with tempfile.TemporaryDirectory(prefix="hexbench_verify_") as tmp:
        meta = {k: v for k, v in e.items() if k not in ("max_steps", "residual_scale", "control_dt_s", "goal_distance_m")}
        try:
            recorder = make_episode_recorder(Path(tmp), e["episode_id"], meta)
        except ValueError as err:  # an episode id that is no safe file name
            return VerifyResult(False, f"{mcap_path}: {err}")
        try:
            episode = play(task, seed, LoggedActions(actions, str(actions_path)), index=index,
                           recorder=recorder, max_steps=None if max_steps in (None, task.max_steps) else max_steps,
                           where=str(actions_path))
        except HexbenchError as err:
            recorder.abort()
            return VerifyResult(False, f"{mcap_path}: {err}")
        row = dict(episode.row)
        for key in ("action_log_path", "action_log_sha256"):
            if key in log.outcome:
                row[key] = log.outcome[key]
        row.update(recorder.on_end(row))
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
    return VerifyResult(True, f"{mcap_path}: {compared} messages match the re-simulation from its action log exactly",
                        compared)
