"""`hexbench export minari RUN`: a run's episodes as Minari datasets (arrow format), one per task.

Minari needs every step's observation, and the observation a controller saw includes the
seeded observation noise, which the logs do not store. So each episode is replayed exactly from
its task, seed and action log (`RUN/episodes/<episode id>.actions`; the controller is never run)
through the one episode loop (hexbench.suite.rollout), and the replay is checked before it is
kept: against the run record's row (every outcome field, exactly) where the run has a
result.json, else against the episode's MCAP log (same number of steps, same per-step rewards to
the logged precision). Every file is found relative to the run folder, so a run exports from any
working directory. Episodes are handed to `minari.create_dataset_from_buffers` (Minari's
DataCollector would need jax); actions are stored as float32 (the action space's dtype).

Each dataset stores the Gymnasium spec of the environment its episodes were played in (the
task's registered id, with the episode rules the run used), so `dataset.recover_environment()`
makes that environment; a spec that does not survive JSON exactly is left out and named in
`ExportedDataset.env_spec_problem`. Datasets go to RUN/minari/ (MINARI_DATASETS_PATH is pointed
there while writing), with ids `hexbench/<run>-<terrain>-<level><unit>-v0`. A failure removes the
datasets this export wrote, so no partial dataset remains.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import re
import shutil
import warnings
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexbench.errors import HexbenchError


class MinariExportError(HexbenchError):
    """A run cannot be exported to Minari (no episodes, an episode that does not replay, a dataset id in use)."""


@dataclass(frozen=True)
class ExportedDataset:
    dataset_id: str
    episodes: int
    steps: int
    gym_id: str
    env_spec_problem: str | None  # None: the spec is stored and recover_environment() works


@dataclass(frozen=True)
class _Episode:
    """One episode to export: what replays it, and what its replay is checked against."""

    where: str  # the file named in messages
    task: object  # TaskSpec
    index: int
    seed: int
    action_mode: str
    actions: object  # ActionLog
    controller_file: str  # as recorded (a name for the dataset's metadata; the file is never run)
    max_steps: int  # the episode's step limit
    row: dict | None  # the run record's row: checked field by field
    mcap: Path | None  # else the MCAP log: steps and logged rewards checked


def datasets_folder(run_dir: Path) -> Path:
    """Where `export_run` writes the datasets of a run (MINARI_DATASETS_PATH for loading them)."""
    return Path(run_dir).resolve() / "minari"


def _task(protocol: str, terrain: str, level: float, where: str):
    from hexbench.suite.tasks import load_suite

    try:
        return load_suite(protocol).task(terrain, level)
    except ValueError as e:
        raise MinariExportError(f"{where}: {e}") from None


def _from_record(run_dir: Path) -> list[_Episode]:
    """The episodes of a run record (RUN/result.json), their action logs under RUN/episodes/."""
    from hexbench.artifacts import action_log
    from hexbench.recording.reader import EpisodeFileError, read_episode
    from hexbench.replay.verify import read_run_record

    record = read_run_record(run_dir)
    logs = run_dir / "episodes"
    controller = record["controller"]
    out = []
    for row in record["episodes"]:
        task = _task(record["protocol"], row["terrain"], float(row["level"]), str(run_dir / "result.json"))
        if not row.get("action_log_path") or not row.get("action_log_sha256"):
            raise MinariExportError(f"{run_dir / 'result.json'}: {task.name} episode {row['index']} names no action "
                                    f"log; cannot be replayed")
        path = logs / row["action_log_path"]
        actions = action_log.read(path, row["action_log_sha256"])
        max_steps = task.max_steps
        mcap = path.with_suffix(".mcap")
        if mcap.is_file():  # the episode's step limit, where it was recorded
            try:
                max_steps = int(read_episode(mcap, validate=False).episode.get("max_steps", max_steps))
            except (EpisodeFileError, ValueError):
                pass
        out.append(_Episode(str(path), task, int(row["index"]), int(row["seed"]), controller["action_mode"], actions,
                            controller["file"], max_steps, row, None))
    return out


def _from_mcap_files(run_dir: Path) -> list[_Episode]:
    """The episodes of a folder of MCAP logs (RUN/episodes/ or RUN itself), each beside its action log."""
    from hexbench.artifacts import action_log
    from hexbench.recording.reader import read_episode

    files = sorted((run_dir / "episodes").glob("*.mcap")) or sorted(run_dir.glob("*.mcap"))
    out = []
    for f in files:
        log = read_episode(f)
        e = log.episode
        missing = [k for k in ("protocol", "terrain", "level", "index", "seed", "episode_id", "action_mode")
                   if k not in e]
        if missing:
            raise MinariExportError(f"{f}: episode metadata lacks {', '.join(missing)}; cannot be replayed")
        try:
            level, index, seed = float(e["level"]), int(e["index"]), int(e["seed"])
            actions_path = f.with_name(f"{e['episode_id']}{action_log.SUFFIX}")
            task = _task(e["protocol"], e["terrain"], level, str(f))
            max_steps = int(e.get("max_steps", task.max_steps))
        except ValueError:
            raise MinariExportError(f"{f}: episode metadata is malformed (level, index, seed, max_steps or episode "
                                    f"id {e['episode_id']!r})") from None
        actions = action_log.read(actions_path, log.outcome.get("action_log_sha256"))
        out.append(_Episode(str(f), task, index, seed, e["action_mode"], actions, e.get("controller_file", "?"),
                            max_steps, None, f))
    return out


def run_episodes(run_dir: Path) -> list[_Episode]:
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise MinariExportError(f"{run_dir}: no such run folder")
    episodes = _from_record(run_dir) if (run_dir / "result.json").is_file() else _from_mcap_files(run_dir)
    if not episodes:
        raise MinariExportError(f"{run_dir}: no episodes to export (no result.json and no .mcap episode logs); "
                                f"write one with `hexbench run FILE --out {run_dir}`")
    return episodes


def _safe_name(text: str) -> str:
    """`text` in the characters a Minari dataset name allows (letters, digits, - and _)."""
    return re.sub(r"[^-\w]+", "_", text).strip("-_") or "run"


def dataset_ids(run_dir: Path, task_names: list[str], dataset_id: str | None) -> dict[str, str]:
    """Task name -> dataset id: `--dataset-id` as given for a single task, with the task's name
    before its version for several; by default hexbench/<run>-<task>-v0."""
    from minari.dataset.minari_dataset import DATASET_ID_RE

    if dataset_id is None:
        run_name = _safe_name(Path(run_dir).resolve().name.lower())
        return {name: f"hexbench/{run_name}-{_safe_name(name)}-v0" for name in task_names}
    if not DATASET_ID_RE.fullmatch(dataset_id) or not re.search(r"-v\d+$", dataset_id):
        raise MinariExportError(f"--dataset-id {dataset_id!r} is not a Minari dataset id; use "
                                f"[namespace/]name-v<version> (letters, digits, - and _), e.g. hexbench/cpg-rough-v0")
    if len(task_names) == 1:
        return {task_names[0]: dataset_id}
    return {name: re.sub(r"-v(\d+)$", f"-{_safe_name(name)}-v\\1", dataset_id) for name in task_names}


def _env_spec(task, action_mode: str, config):
    """A Gymnasium spec under the task's id that makes exactly `config` (the episodes' environment),
    and None or the reason it cannot be stored (Minari keeps it as JSON, so it must survive JSON).

    It is the id's registered spec, or for an id not registered (a protocol from HEXBENCH_TASKS_DIR)
    the flat-ground spec of the same action mode, with the config fields that differ passed as
    keyword arguments (the environment takes any EnvConfig field as one)."""
    import gymnasium as gym
    from gymnasium.envs.registration import EnvSpec

    from hexbench.suite.tasks import MODE_IDS

    gym_id = task.gym_id(action_mode)
    template = gym.registry.get(gym_id) or gym.registry.get(f"hexbench/Flat-{MODE_IDS[action_mode]}-{task.protocol}")
    if template is None:
        return None, f"{gym_id} is not a registered Gymnasium id"

    def made_config(candidate):
        env = gym.make(EnvSpec.from_json(candidate.to_json()))
        try:
            return env.unwrapped.config
        finally:
            env.close()

    try:
        spec = dataclasses.replace(template, id=gym_id)
        made = made_config(spec)
        if made != config:  # another task's spec, or other episode rules than the registered task's
            changed = {f.name: getattr(config, f.name) for f in dataclasses.fields(config)
                       if getattr(made, f.name) != getattr(config, f.name)}
            spec = dataclasses.replace(spec, kwargs={**spec.kwargs, **changed})
            made = made_config(spec)
        if spec.max_episode_steps is not None:  # the registration's time limit: the episodes' own
            spec = dataclasses.replace(spec, max_episode_steps=config.max_steps)
    except Exception as e:  # noqa: BLE001 - any failure to rebuild from JSON means the spec is not storable
        reason = (str(e).strip().splitlines() or [""])[0][:200]
        return None, f"the spec of {gym_id} does not survive JSON ({type(e).__name__}: {reason})"
    if made != config:
        return None, f"the spec of {gym_id} rebuilt from JSON makes another environment than the episodes'"
    return spec, None


def _replay(episode: _Episode, env) -> tuple[np.ndarray, list[float], list[bool], list[bool]]:
    """Observations, rewards and end flags of an episode replayed from its action log, checked."""
    from hexbench.evaluation.episode import first_row_difference
    from hexbench.recording.reader import metrics
    from hexbench.suite.rollout import LoggedActions, play

    steps = _StepCollector()
    played = play(episode.task, episode.seed, _Observed(LoggedActions(episode.actions, episode.where), steps),
                  index=episode.index, recorder=steps, env=env, where=episode.where)
    if episode.row is not None:
        diff = first_row_difference(episode.row, played.row)
        if diff is not None:
            raise MinariExportError(f"{episode.where}: the replayed episode differs from the run record ({diff}); "
                                    f"not exported")
    else:  # /metrics logs every 3rd step and the last one; compare the steps it has, and the count
        logged = {m["step"]: m["reward"] for m in metrics(episode.mcap)}
        if max(logged, default=0) != len(steps.rewards) or any(
                float(f"{steps.rewards[k - 1]:.5g}") != lr for k, lr in logged.items()):
            raise MinariExportError(f"{episode.where}: the replayed episode differs from its log; not exported")
    return np.array(steps.observations), steps.rewards, steps.terminations, steps.truncations


@contextlib.contextmanager
def _datasets_path(folder: Path):
    previous = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(folder)
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = previous


def export_run(run_dir: str | Path, dataset_id: str | None = None, progress: bool = False) -> list[ExportedDataset]:
    """Write one Minari dataset per task of the run into RUN/minari/; return what was written."""
    import minari
    from minari.data_collector.episode_buffer import EpisodeBuffer
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    from hexbench.artifacts.provenance import HEXBENCH_VERSION
    from hexbench.suite.rollout import make_env

    run_dir = Path(run_dir)
    groups: dict[tuple, list[_Episode]] = defaultdict(list)
    for ep in run_episodes(run_dir):
        groups[(ep.task.protocol, ep.task.terrain, ep.task.level, ep.action_mode, ep.max_steps, ep.controller_file)
               ].append(ep)
    ordered = sorted(groups.items(), key=lambda g: g[0][:5])
    task_names = [eps[0].task.name for _, eps in ordered]
    if len(set(task_names)) < len(task_names):
        raise MinariExportError(f"{run_dir}: one task holds episodes of several controllers, action modes or step "
                                f"limits; export each controller's run folder on its own")
    ids = dataset_ids(run_dir, task_names, dataset_id)
    out_root = datasets_folder(run_dir)
    taken = [i for i in ids.values() if (out_root / i).exists()]
    if taken:
        raise MinariExportError(f"dataset {taken[0]} already exists in {out_root}; remove {out_root / taken[0]} "
                                f"or choose another --dataset-id")
    root_existed = out_root.exists()
    written: list[Path] = []
    exported: list[ExportedDataset] = []
    total = sum(len(eps) for _, eps in ordered)
    try:
        with _datasets_path(out_root), warnings.catch_warnings(), \
                Progress(TextColumn("[bold]exporting[/] {task.description}"), BarColumn(), MofNCompleteColumn(),
                         TimeRemainingColumn(), disable=not progress) as bar:
            warnings.simplefilter("ignore")  # Minari's reminders of metadata a replayed run has no value for
            task_bar = bar.add_task("", total=total)
            for (protocol, _, _, mode, max_steps, controller_file), episodes in ordered:
                task = episodes[0].task
                ds_id = ids[task.name]
                bar.update(task_bar, description=ds_id)
                env = make_env(task, mode, max_steps)
                try:
                    spec, spec_problem = _env_spec(task, mode, env.config)
                    buffers = []
                    for ep in sorted(episodes, key=lambda x: x.index):
                        observations, rewards, terminations, truncations = _replay(ep, env)
                        buffers.append(EpisodeBuffer(id=len(buffers), seed=ep.seed, observations=observations,
                                                     actions=ep.actions.actions.astype(np.float32), rewards=rewards,
                                                     terminations=terminations, truncations=truncations))
                        bar.advance(task_bar)
                    written.append(out_root / ds_id)
                    minari.create_dataset_from_buffers(
                        dataset_id=ds_id, buffer=buffers, env=spec, action_space=env.action_space,
                        observation_space=env.observation_space, algorithm_name=Path(controller_file).stem,
                        description=f"hexbench {protocol} {task.name} ({mode}, Gymnasium id {task.gym_id(mode)}): "
                                    f"{len(buffers)} episodes of {controller_file}, replayed exactly from their "
                                    f"action logs; max {max_steps} steps",
                        author="hexbench", requirements=[f"hexbench=={HEXBENCH_VERSION}"], data_format="arrow")
                finally:
                    env.close()
                exported.append(ExportedDataset(ds_id, len(buffers), sum(len(b.rewards) for b in buffers),
                                                task.gym_id(mode), spec_problem))
    except BaseException:
        for path in written:
            shutil.rmtree(path, ignore_errors=True)
        if not root_existed:
            shutil.rmtree(out_root, ignore_errors=True)
        raise
    return exported


class _Observed:
    """An actor that notes the observation it is given before each action (Minari's observations)."""

    camera = None

    def __init__(self, actor, collector: _StepCollector):
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
