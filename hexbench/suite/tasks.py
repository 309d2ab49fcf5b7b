"""The task suite as data: `tasks/protocol_*.toml` -> frozen `TaskSpec`s, and Gymnasium ids.

A task is one (protocol, terrain, level): the terrain family at one difficulty level, with the
episode rules of its protocol and a fixed list of episode seeds. Seeds are derived
deterministically: seed_i = first 4 bytes of sha256("hexbench/<protocol>/<terrain>/<level>/<i>")
as an unsigned integer, so they never depend on run order or on any global state.

Gymnasium ids (registered on `import hexbench`):
  hexbench/<Terrain>-<level><unit>-<Mode>-v1    every suite level x action mode, protocol rules
                                                (the mixed course too: hexbench/Mixed-<level>-<Mode>-v1)
  hexbench/<Terrain>-Curriculum-<Mode>-v1       training curriculum of paper 4.1 (no stall rule),
                                                made by hexbench.training.wrappers:make_curriculum_env
  hexbench/Flat-<Mode>-v1                       flat ground, for sanity checks
with <Mode> one of Joint, CpgResidual, CpgParams. Registrations carry plain data (EnvConfig fields
as JSON-able kwargs, so EnvSpec.to_json / from_json round-trip) and the episode's step limit as
`max_episode_steps`.
"""

from __future__ import annotations

import hashlib
import os
import sys
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from hexbench.artifacts.provenance import REPO_ROOT
from hexbench.world.env import ACTION_MODES, MAX_EPISODE_STEPS, EnvConfig

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

DEFAULT_PROTOCOL = "v1"
MODE_IDS: dict[str, str] = {"joint": "Joint", "cpg_residual": "CpgResidual", "cpg_params": "CpgParams",
                            "cpg_params_wide": "CpgParamsWide", "cpg_params_steer": "CpgParamsSteer"}
PROTOCOL_TERRAINS: tuple[str, ...] = ("rough", "slopes", "stairs")
CURRICULUM_TERRAINS: tuple[str, ...] = ("rough", "slopes", "stairs")  # hexbench.training.wrappers.CURRICULA
ENV_ENTRY_POINT = "hexbench.world.env:HexapodEnv"
CURRICULUM_ENTRY_POINT = "hexbench.training.wrappers:make_curriculum_env"


def tasks_dir() -> Path:
    """Where the suite TOML files live: $HEXBENCH_TASKS_DIR, else the repository's tasks/."""
    env = os.environ.get("HEXBENCH_TASKS_DIR")
    return Path(env) if env else REPO_ROOT / "tasks"


def format_level(level: float) -> str:
    """3.0 -> '3', 5.5 -> '5.5' (the spelling used in ids, seeds and tables)."""
    return f"{float(level):g}"


def episode_seed(protocol: str, terrain: str, level: float, index: int) -> int:
    key = f"hexbench/{protocol}/{terrain}/{format_level(level)}/{index}".encode()
    return int.from_bytes(hashlib.sha256(key).digest()[:4], "big")


@dataclass(frozen=True)
class TaskSpec:
    """One scored task: a terrain at one level under one protocol. Passed to `make_controller`."""

    protocol: str
    terrain: str
    level: float  # paper units
    unit: str  # "cm" or "deg"
    headroom: bool  # beyond paper Table 4
    episodes: int
    max_steps: int
    goal_distance_m: float
    max_lateral_deviation_m: float
    fall_tilt_deg: float
    stall_window_s: float
    stall_min_progress_m: float
    in_full_run: bool = True  # False: an extra course (mixed) run only when selected by name

    @property
    def name(self) -> str:
        return f"{self.terrain}-{format_level(self.level)}{self.unit}"

    def seeds(self, episodes: int | None = None) -> list[int]:
        n = self.episodes if episodes is None else episodes
        return [episode_seed(self.protocol, self.terrain, self.level, i) for i in range(n)]

    def env_kwargs(self, action_mode: str) -> dict:
        """The EnvConfig fields of this task in one action mode, as plain (JSON-able) data."""
        return {"terrain": self.terrain, "level": self.level, "action_mode": action_mode, "max_steps": self.max_steps,
                "goal_distance_m": self.goal_distance_m, "max_lateral_deviation_m": self.max_lateral_deviation_m,
                "fall_tilt_deg": self.fall_tilt_deg, "stall_window_s": self.stall_window_s,
                "stall_min_progress_m": self.stall_min_progress_m}

    def env_config(self, action_mode: str, **overrides) -> EnvConfig:
        return EnvConfig(**self.env_kwargs(action_mode), **overrides)

    def gym_id(self, action_mode: str) -> str:
        return f"hexbench/{self.terrain.capitalize()}-{format_level(self.level)}{self.unit}-{MODE_IDS[action_mode]}-{self.protocol}"


@dataclass(frozen=True)
class Suite:
    """A protocol's tasks: `tasks` make the full run (what records and the leaderboard score);
    `extra_tasks` are courses outside it (the mixed course), run only when selected by name."""

    protocol: str
    tasks: tuple[TaskSpec, ...]
    extra_tasks: tuple[TaskSpec, ...] = ()

    @property
    def all_tasks(self) -> tuple[TaskSpec, ...]:
        return self.tasks + self.extra_tasks

    @property
    def terrains(self) -> tuple[str, ...]:
        """The terrains of the full run."""
        return tuple(dict.fromkeys(t.terrain for t in self.tasks))

    @property
    def extra_terrains(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(t.terrain for t in self.extra_tasks))

    @property
    def all_terrains(self) -> tuple[str, ...]:
        return self.terrains + self.extra_terrains

    def levels(self, terrain: str, include_headroom: bool = True) -> list[float]:
        return [t.level for t in self.all_tasks if t.terrain == terrain and (include_headroom or not t.headroom)]

    def task(self, terrain: str, level: float) -> TaskSpec:
        if terrain not in self.all_terrains:
            raise ValueError(f"unknown terrain {terrain!r}; valid terrains: {', '.join(self.all_terrains)}")
        for t in self.all_tasks:
            if t.terrain == terrain and abs(t.level - float(level)) < 1e-9:
                return t
        valid = ", ".join(format_level(v) for v in self.levels(terrain))
        raise ValueError(f"unknown {terrain} level {format_level(level)}; valid levels: {valid}")

    def select(self, terrains: list[str] | None = None, levels: list[float] | None = None) -> list[TaskSpec]:
        """Tasks of the given terrains (default: the full run's) and levels (default all of each terrain).

        Raises ValueError naming the valid choices for an unknown terrain or a level that no
        selected terrain has.
        """
        chosen_terrains = list(terrains) if terrains else list(self.terrains)
        for t in chosen_terrains:
            if t not in self.all_terrains:
                raise ValueError(f"unknown terrain {t!r}; valid terrains: {', '.join(self.all_terrains)}")
        out = [t for t in self.all_tasks if t.terrain in chosen_terrains]
        if levels:
            for lv in levels:
                if not any(abs(t.level - lv) < 1e-9 for t in out):
                    valid = "; ".join(f"{ter}: {', '.join(format_level(v) for v in self.levels(ter))}"
                                      for ter in chosen_terrains)
                    raise ValueError(f"unknown level {format_level(lv)}; valid levels: {valid}")
            out = [t for t in out if any(abs(t.level - lv) < 1e-9 for lv in levels)]
        return out


def load_suite(protocol: str = DEFAULT_PROTOCOL) -> Suite:
    """The suite of `protocol` from the tasks folder in effect now ($HEXBENCH_TASKS_DIR, else tasks/)."""
    return _load_suite(protocol, tasks_dir())


@lru_cache(maxsize=8)
def _load_suite(protocol: str, folder: Path) -> Suite:
    path = folder / f"protocol_{protocol}.toml"
    if not path.exists():
        known = sorted(p.stem.removeprefix("protocol_") for p in folder.glob("protocol_*.toml"))
        raise ValueError(f"unknown protocol {protocol!r}; valid protocols: {', '.join(known) or 'none found'}")
    data = tomllib.loads(path.read_text())
    if data.get("protocol") != protocol:
        raise ValueError(f"{path} declares protocol {data.get('protocol')!r}, expected {protocol!r}")
    tasks = []
    for terrain, spec in data["terrains"].items():
        for headroom, key in ((False, "levels"), (True, "headroom_levels")):
            for level in spec.get(key, []):
                tasks.append(TaskSpec(
                    protocol=protocol, terrain=terrain, level=float(level), unit=spec["unit"], headroom=headroom,
                    episodes=int(data["episodes_per_level"]), max_steps=int(spec.get("max_steps", data["max_steps"])),
                    goal_distance_m=float(spec.get("goal_distance_m", data["goal_distance_m"])),
                    max_lateral_deviation_m=float(data["max_lateral_deviation_m"]),
                    fall_tilt_deg=float(data["fall_tilt_deg"]), stall_window_s=float(data["stall_window_s"]),
                    stall_min_progress_m=float(data["stall_min_progress_m"]),
                    in_full_run=bool(spec.get("in_full_run", True)),
                ))
    return Suite(protocol, tuple(t for t in tasks if t.in_full_run), tuple(t for t in tasks if not t.in_full_run))


def curriculum_id(terrain: str, action_mode: str, protocol: str = DEFAULT_PROTOCOL) -> str:
    """The Gymnasium id of a terrain's training curriculum, e.g. hexbench/Rough-Curriculum-CpgResidual-v1."""
    return f"hexbench/{terrain.capitalize()}-Curriculum-{MODE_IDS[action_mode]}-{protocol}"


def registered_ids() -> list[str]:
    import gymnasium as gym

    return sorted(i for i in gym.registry if i.startswith("hexbench/"))


def register_envs(protocol: str = DEFAULT_PROTOCOL) -> None:
    """Register every suite task x action mode, the curricula and flat ground with Gymnasium."""
    import gymnasium as gym

    def register(gid: str, entry_point: str, kwargs: dict, max_episode_steps: int) -> None:
        if gid not in gym.registry:
            gym.register(gid, entry_point=entry_point, kwargs=kwargs, max_episode_steps=max_episode_steps)

    for mode in ACTION_MODES:
        m = MODE_IDS[mode]
        for task in load_suite(protocol).all_tasks:
            register(task.gym_id(mode), ENV_ENTRY_POINT, task.env_kwargs(mode), task.max_steps)
        for terrain in CURRICULUM_TERRAINS:
            register(curriculum_id(terrain, mode, protocol), CURRICULUM_ENTRY_POINT,
                     {"terrain": terrain, "action_mode": mode, "max_steps": MAX_EPISODE_STEPS}, MAX_EPISODE_STEPS)
        register(f"hexbench/Flat-{m}-{protocol}", ENV_ENTRY_POINT,
                 {"terrain": "flat", "action_mode": mode, "max_steps": MAX_EPISODE_STEPS}, MAX_EPISODE_STEPS)
