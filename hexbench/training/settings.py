"""What a training run is asked to do: the frozen `TrainSettings`, the baseline CONFIG it trains, and
the parsing of the `hexbench train` options that are not plain numbers (`--set`, `--curriculum`).

`--curriculum START:STEP:TOP` replaces the paper's curriculum of the terrain with another one
(same rule: level up after 20 arrivals; levels in the paper's units), e.g. slopes 18:0.5:21 to
fine-tune beyond the paper's 18-deg top; run.json records it as `curriculum_levels`. `--level L`
trains at one suite level instead; the two exclude each other.
"""

from __future__ import annotations

import ast
import math
from dataclasses import dataclass, fields, replace
from pathlib import Path

from hexbench.agents.policy import ConfigError, validate_config
from hexbench.errors import HexbenchError
from hexbench.training.wrappers import Curriculum

TRAIN_TERRAINS: tuple[str, ...] = ("rough", "slopes", "stairs")
TRAIN_DEVICES: tuple[str, ...] = ("cpu", "cuda")


class TrainError(HexbenchError):
    """Bad training input or state; the message is one line."""


@dataclass(frozen=True)
class TrainSettings:
    """One `hexbench train` invocation: what to train, where, for how long, and how often to report."""

    baseline_path: Path
    terrain: str
    total_steps: int  # env steps, summed over workers
    seed: int = 0
    workers: int = 1
    out_dir: Path | None = None  # None -> training/<method>-<terrain>-seed<seed>
    checkpoint_every_s: float = 300.0  # [s of wall time]; ignored when checkpoint_every_steps is set
    checkpoint_every_steps: int | None = None  # [env steps]: the same checkpoints on any machine
    csv_every_s: float = 60.0
    overrides: tuple[tuple[str, object], ...] = ()  # config field overrides (name, value)
    command: str = ""
    show_progress: bool = True
    log_lines: bool = True  # one line per progress.csv row on stderr when it is not a terminal (a log file)
    fixed_level: float | None = None  # train at one suite level without the curriculum (--level; epsilon sweep)
    device: str = "cpu"  # torch device of the learner ("cpu" or "cuda"); envs always step on the CPU
    init_from: Path | None = None  # shipped weights (baselines/checkpoints/<method>-<terrain>.zip) to start from
    curriculum: Curriculum | None = None  # replaces the paper's curriculum for the terrain (--curriculum)
    value_warmup_steps: int = 0  # PPO: env steps during which only the value function learns

    @property
    def method(self) -> str:
        return Path(self.baseline_path).stem

    @property
    def run_dir(self) -> Path:
        return Path(self.out_dir) if self.out_dir else Path("training") / f"{self.method}-{self.terrain}-seed{self.seed}"


def parse_curriculum(text: str) -> Curriculum:
    """'18:0.5:21' -> Curriculum(18.0, 0.5, 21.0): start level, level step, top level, in the paper's units."""
    parts = text.split(":")
    try:
        start, step, top = (float(p) for p in parts)
    except ValueError:
        raise TrainError(f"--curriculum {text!r} is not START:STEP:TOP (three numbers in the terrain's unit, "
                         f"e.g. 18:0.5:21)") from None
    if not (step > 0 and start <= top and start >= 0 and all(math.isfinite(v) for v in (start, step, top))):
        raise TrainError(f"--curriculum {text!r}: needs 0 <= START <= TOP and STEP > 0")
    return Curriculum(start, step, top)


def parse_override(text: str) -> tuple[str, object]:
    """'learning_rate=3e-4' -> ('learning_rate', 0.0003); values are Python literals or bare strings."""
    if "=" not in text:
        raise TrainError(f"override {text!r} is not NAME=VALUE")
    name, raw = text.split("=", 1)
    try:
        value = ast.literal_eval(raw)
    except (ValueError, SyntaxError):
        value = raw
    return name.strip(), value


def load_baseline_config(path: Path, overrides: tuple[tuple[str, object], ...] = ()):
    """The CONFIG of a baseline file, with overrides applied and validated."""
    from hexbench.suite.controller import ControllerError, load_controller_module

    try:
        module = load_controller_module(path)
    except ControllerError as e:
        raise TrainError(str(e)) from None
    config = getattr(module, "CONFIG", None)
    _validated(config, path)
    if overrides:
        names = {f.name for f in fields(config)}
        for name, _ in overrides:
            if name not in names:
                raise TrainError(f"{path}: config has no field {name!r}; fields: {', '.join(sorted(names))}")
        config = _validated(replace(config, **dict(overrides)), path)
    return config


def _validated(config, path: Path):
    try:
        validate_config(config, str(path))
    except ConfigError as e:
        raise TrainError(str(e)) from None
    return config


def check_settings(settings: TrainSettings) -> None:
    """TrainError for settings that cannot train, before anything is read or written."""
    import torch

    if settings.terrain not in TRAIN_TERRAINS:
        raise TrainError(f"unknown terrain {settings.terrain!r}; valid terrains: {', '.join(TRAIN_TERRAINS)}")
    if settings.workers < 1:
        raise TrainError(f"--workers must be >= 1 (got {settings.workers})")
    if settings.total_steps < 1:
        raise TrainError(f"--steps must be >= 1 (got {settings.total_steps})")
    if settings.device not in TRAIN_DEVICES:
        raise TrainError(f"unknown --device {settings.device!r}; valid: {', '.join(TRAIN_DEVICES)}")
    if settings.device == "cuda" and not torch.cuda.is_available():
        raise TrainError("--device cuda: this torch sees no CUDA GPU (torch.cuda.is_available() is False); use --device cpu")
    if settings.fixed_level is not None:
        from hexbench.suite.tasks import load_suite

        try:
            load_suite().task(settings.terrain, settings.fixed_level)
        except ValueError as e:
            raise TrainError(f"--level: {e}") from None
        if settings.curriculum is not None:
            raise TrainError("--level and --curriculum exclude each other (one level, or a curriculum of levels)")
    if settings.value_warmup_steps < 0:
        raise TrainError(f"--value-warmup needs a number of env steps >= 0 (got {settings.value_warmup_steps})")


def load_run_config(settings: TrainSettings):
    """The baseline CONFIG the settings train, checked against the options that need a given algorithm."""
    config = load_baseline_config(Path(settings.baseline_path), settings.overrides)
    if settings.value_warmup_steps and config.algo != "ppo":
        raise TrainError(f"--value-warmup works for PPO baselines only, which learn a value function "
                         f"beside the actor (this config's algo is {config.algo!r})")
    return config
