"""Training budgets: what a measured controller's shipped weights were trained with (shown, not ranked).

A measured record names its checkpoint files with their sha256; the manifest.json beside them
(paths relative to the repository) states each entry's env-step budget. A checkpoint without a
manifest entry of its sha256 (its weights changed after the record was made) makes the budget
unknown, shown as `?`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from hexbench.artifacts.manifest import entries_by_sha256
from hexbench.leaderboard.records import Row


@dataclass(frozen=True)
class Training:
    """What a measured controller's checkpoints were trained with, read from the checkpoint manifest.

    `budgets` and `env_steps` are sorted distinct values over its checkpoints: () for a controller
    without checkpoints (nothing trained, e.g. the open-loop CPG); `known` is False when some
    checkpoint has no manifest entry with its sha256 (the weights changed since the record, or
    they come from elsewhere), and then nothing is claimed.
    """

    known: bool
    budgets: tuple[int, ...] = ()  # stated env-step budgets [env steps]
    env_steps: tuple[int, ...] = ()  # env steps at the shipped checkpoints [env steps]


def training_of(row: Row, root: Path) -> Training:
    """Training of a measured row from the manifests beside its checkpoints (paths relative to `root`)."""
    manifests: dict[Path, dict[str, dict]] = {}
    entries = []
    for path, sha256 in row.details.get("checkpoint_files", []):
        folder = (Path(root) / path).parent
        if folder not in manifests:
            manifests[folder] = entries_by_sha256(folder)
        entries.append(manifests[folder].get(sha256))
    if any(e is None or not isinstance(e.get("env_step_budget"), int) or not isinstance(e.get("env_steps"), int)
           for e in entries):
        return Training(known=False)
    return Training(known=True, budgets=tuple(sorted({e["env_step_budget"] for e in entries})),
                    env_steps=tuple(sorted({e["env_steps"] for e in entries})))


def fmt_env_steps(n: int) -> str:
    """1000000 -> "1M", 60000 -> "60k", 180502 -> "181k"."""
    if n >= 1_000_000:
        return f"{n / 1_000_000:.3g}M"
    if n >= 1_000:
        return f"{n / 1_000:.3g}k"
    return str(n)


def fmt_steps_range(values: tuple[int, ...]) -> str:
    if not values:
        return "–"
    low, high = fmt_env_steps(values[0]), fmt_env_steps(values[-1])
    return low if low == high else f"{low}–{high}"


def fmt_budget(training: Training | None) -> str:
    if training is None or not training.known:
        return "?"
    return "none" if not training.budgets else fmt_steps_range(training.budgets)


def fmt_checkpoint_steps(training: Training | None) -> str:
    if training is None or not training.known:
        return "?"
    return fmt_steps_range(training.env_steps)
