"""`hexbench export minari`: a run's logged episodes as Minari datasets (arrow format), one per task.

Minari needs every step's observation, and the observation a controller saw includes the
seeded observation noise, which the logs do not store. So each logged episode is replayed
exactly from its task, seed and action log (`<episode id>.actions`; the controller is never run)
through the one episode loop (hexbench.suite.rollout), and the replay is checked against the log (same number of steps, same per-step rewards to the
logged precision) before it is kept. Episodes are handed to `minari.create_dataset_from_buffers`
(Minari's DataCollector would need jax); actions are stored as float32 (the action space's dtype).
Datasets go to RUN/minari/ (MINARI_DATASETS_PATH is pointed there while writing), with ids
`hexbench/<run>-<terrain>-<level><unit>-v0`.
"""

from __future__ import annotations

import os
import re
from collections import defaultdict
from pathlib import Path

import numpy as np

from hexbench.recording.reader import metrics, read_episode


def _episode_files(run_dir: Path) -> list[Path]:
    files = sorted((run_dir / "episodes").glob("*.mcap")) or sorted(run_dir.glob("*.mcap"))
    if not files:
        raise ValueError(f"{run_dir}: no logged episodes (.mcap files) found; run `hexbench run` with recording on")
    return files


def export_run(run_dir: Path, dataset_id: str | None = None) -> Path:
    import minari
    from minari.data_collector.episode_buffer import EpisodeBuffer

    from hexbench.artifacts import action_log
    from hexbench.errors import HexbenchError
    from hexbench.suite.rollout import LoggedActions, make_env, play
    from hexbench.suite.tasks import load_suite

    run_dir = Path(run_dir)
    groups: dict[tuple, list] = defaultdict(list)
    for f in _episode_files(run_dir):
        log = read_episode(f)
        e = log.episode
        try:
            actions = action_log.read(f.with_name(f"{e['episode_id']}{action_log.SUFFIX}"),
                                      log.outcome.get("action_log_sha256"))
        except HexbenchError as err:
            raise ValueError(f"{f}: {err}") from None
        groups[(e["protocol"], e["terrain"], float(e["level"]), e["controller_file"], e["action_mode"])].append(
            (f, e, actions))
    run_name = re.sub(r"[^A-Za-z0-9]+", "-", run_dir.resolve().name).strip("-").lower() or "run"
    out_root = run_dir / "minari"
    previous = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(out_root.resolve())
    try:
        for (protocol, terrain, level, controller_file, mode), episodes in sorted(groups.items(), key=lambda g: g[0]):
            task = load_suite(protocol).task(terrain, level)
            max_steps = int(episodes[0][1].get("max_steps", task.max_steps))
            env = make_env(task, mode, max_steps)
            buffers = []
            for f, e, actions in sorted(episodes, key=lambda x: int(x[1]["index"])):
                seed = int(e["seed"])
                steps = _StepCollector()
                play(task, seed, _Observed(LoggedActions(actions, str(f)), steps), index=int(e["index"]),
                     recorder=steps, env=env, where=str(f))
                observations, rewards = steps.observations, steps.rewards
                # /metrics logs every 3rd step and the last one; compare the steps it has, and the count
                logged = {m["step"]: m["reward"] for m in metrics(f)}
                if max(logged, default=0) != len(rewards) or any(
                        float(f"{rewards[k - 1]:.5g}") != lr for k, lr in logged.items()):
                    raise ValueError(f"{f}: the replayed episode differs from its log; not exported")
                buffers.append(EpisodeBuffer(id=len(buffers), seed=seed, observations=np.array(observations),
                                             actions=actions.actions.astype(np.float32), rewards=rewards,
                                             terminations=steps.terminations, truncations=steps.truncations))
            env.close()
            ds_id = dataset_id or f"hexbench/{run_name}-{task.name}-v0"
            if dataset_id and len(groups) > 1:
                ds_id = re.sub(r"-v(\d+)$", f"-{task.name}-v\\1", dataset_id)
            minari.create_dataset_from_buffers(
                dataset_id=ds_id, buffer=buffers, action_space=env.action_space,
                observation_space=env.observation_space, algorithm_name=Path(controller_file).stem,
                description=f"hexbench {protocol} {task.name} ({mode}): {len(buffers)} logged episodes of "
                            f"{controller_file}, replayed exactly from their logs; max {max_steps} steps",
                author="hexbench", data_format="arrow")
    finally:
        if previous is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = previous
    return out_root


class _Observed:
    """An actor that notes the observation it is given before each action (Minari's observations)."""

    camera = None

    def __init__(self, actor, collector: "_StepCollector"):
        self.actor, self.collector = actor, collector
        self.action_mode = actor.action_mode

    def reset(self, seed: int) -> None:
        self.actor.reset(seed)

    def act(self, obs: np.ndarray, step: int):
        self.collector.observations.append(obs.copy())
        return self.actor.act(obs, step)


class _StepCollector:
    """The rollout's recorder interface: rewards, end flags and the last observation of an episode."""

    def __init__(self):
        self.observations, self.rewards, self.terminations, self.truncations = [], [], [], []

    def on_reset(self, env) -> None:
        pass

    def on_step(self, env, obs, action, reward, info) -> None:
        self.rewards.append(float(reward))
        reason = info["end_reason"]
        self.terminations.append(reason is not None and reason != "step_limit")
        self.truncations.append(reason == "step_limit")
        if reason is not None:
            self.observations.append(obs.copy())
