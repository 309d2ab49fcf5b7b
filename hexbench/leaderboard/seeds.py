"""Methods across their seeds: seed runs read, validated and aggregated with rliable's statistics.

A seed run is one (method, terrain, seed) trained from scratch by its baseline file's recipe and
nothing else, in a folder of its own under `baselines/seeds/` (baselines/seeds/README.md):

    <method>-<terrain>-seed<S>/checkpoints/manifest.json   the selected checkpoint's manifest entry
                                                          (seed, env-step budget, env steps spent)
    <method>-<terrain>-seed<S>/result-<terrain>.json      its `hexbench run FILE --terrain T` record

The record is validated like a leaderboard record, against every seed of every level of the
terrain it covers (summaries recomputed from its episode rows), and must be bound to the folder's
checkpoint: the sha256 the record names is the one in the manifest. A method is its record label
at one env-step budget; runs at different budgets are different methods and are never compared
as like for like.

Per terrain, each method's runs give a score matrix `scores[run, level]` of success rates over the
paper levels (headroom levels left out, as in the AUC). From it (hexbench.leaderboard.statistics):

  success per level   the IQM over runs of each level's success rate, stratified-bootstrap 95% CI
  success, all levels the IQM over every run x level score, with its CI (rliable's aggregate)
  AUC                 the IQM over runs of the terrain's AUC, with its CI
  profile             the performance profile: the share of run x level scores above each tau
  P(improvement)      P(method X > method Y), the Mann-Whitney probability over runs, averaged over
                      levels, with its CI; shown for the reference method over every other one

Reference controllers without training (the open-loop CPG) take part with their one full-run
record from the leaderboard folder: one run, no interval of their own. Every bootstrap interval
uses a generator of its own, seeded with BOOTSTRAP_SEED and the (terrain, method[, other method])
it describes, so a build is deterministic and adding a run to one method leaves every other
method's intervals as they were.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hexbench.leaderboard import statistics
from hexbench.leaderboard.records import RecordError, Row, measured_row, read_record
from hexbench.suite.tasks import DEFAULT_PROTOCOL, Suite, format_level

SEEDS_DIR = Path("baselines") / "seeds"  # under the repository root
# untrained controllers compared through their full-run record: the open-loop CPG (baselines/cpg.py) and
# the CPG held on its heading (baselines/cpg_heading.py), the start of HRL-hold and HLTA's low level
REFERENCE_METHODS = ("cpg", "cpg_heading")
IMPROVEMENT_OF = "ppo_cpg"  # the method whose P(improvement) over every other one is reported
BOOTSTRAP_SEED = 20211206  # the generator of every bootstrap interval (rliable's NeurIPS 2021 date)
_FOLDER = re.compile(r"^(?P<method>[A-Za-z0-9_.]+)-(?P<terrain>[a-z]+)-seed(?P<seed>\d+)$")


@dataclass(frozen=True)
class SeedRun:
    """One seed run: its validated row (one terrain) and what its manifest says of its training."""

    method: str
    terrain: str
    seed: int | None  # None for a reference controller's full-run record
    budget_env_steps: int | None  # the run's env-step budget; None: no training
    selected_env_steps: int | None  # env steps behind the selected checkpoint
    folder: str
    row: Row

    def scores(self, levels: list[float]) -> list[float]:
        """Success rate at each of `levels` (the paper levels of the terrain)."""
        return [self.row.level(self.terrain, v)["success_rate"] for v in levels]


@dataclass(frozen=True)
class Method:
    """A label at one budget: the unit that runs are aggregated over."""

    label: str
    budget_env_steps: int | None

    @property
    def name(self) -> str:
        if self.budget_env_steps is None:
            return f"{self.label} (no training)"
        return f"{self.label} @ {fmt_budget(self.budget_env_steps)}"


@dataclass(frozen=True)
class TerrainAggregate:
    """One method's runs on one terrain, aggregated."""

    method: Method
    terrain: str
    runs: tuple[SeedRun, ...]
    levels: tuple[float, ...]  # the paper levels (the score matrix's columns)
    scores: np.ndarray  # [run, level] success rates
    per_level: tuple[statistics.Estimate, ...]
    all_levels: statistics.Estimate
    auc: statistics.Estimate
    headroom_auc: statistics.Estimate | None  # over the headroom levels beyond the paper's; None: no such levels

    @property
    def seeds(self) -> list[int]:
        return [r.seed for r in self.runs if r.seed is not None]


@dataclass(frozen=True)
class Improvement:
    """P(`better` > `other`) on one terrain, with its interval."""

    terrain: str
    better: Method
    other: Method
    estimate: statistics.Estimate


@dataclass
class SeedLoad:
    runs: list[SeedRun]
    errors: list[str]  # one line per refused seed run
    skipped: list[str]  # one line per record of another protocol
    unscored: list[str] = field(default_factory=list)  # folders without their result-<terrain>.json yet


def fmt_budget(env_steps: int) -> str:
    if env_steps % 1_000_000 == 0:
        return f"{env_steps // 1_000_000}M env steps"
    if env_steps % 1_000 == 0:
        return f"{env_steps // 1_000}k env steps"
    return f"{env_steps:,} env steps"


# --------------------------------------------------------------------------------- reading
def _manifest_entry(folder: Path, record: dict, where: str) -> dict:
    """The folder's manifest entry of the checkpoint the record names (bound by sha256)."""
    path = folder / "checkpoints" / "manifest.json"
    try:
        manifest = json.loads(path.read_text())
        entries = list(manifest["checkpoints"].values())
    except FileNotFoundError:
        raise RecordError(f"{where}: {path} is missing; a seed run needs its checkpoint's manifest entry") from None
    except (UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError, AttributeError) as e:
        raise RecordError(f"{where}: {path} is not a checkpoint manifest ({e})") from None
    named = {c.get("sha256") for c in record["controller"].get("checkpoints", [])}
    bound = [e for e in entries if isinstance(e, dict) and e.get("sha256") in named]
    if len(bound) != 1:
        raise RecordError(f"{where}: the record's checkpoint sha256 is not exactly one entry of {path}; "
                          f"the record must be the run of the folder's checkpoint")
    return bound[0]


def _folder_match(folder: Path) -> re.Match:
    match = _FOLDER.match(Path(folder).name)
    if not match:
        raise RecordError(f"{folder}: not a seed-run folder name; expected <method>-<terrain>-seed<S>")
    return match


def seed_run_terrain(folder: Path) -> str:
    """The terrain a seed-run folder's name names; RecordError for a name that is not one."""
    return _folder_match(folder)["terrain"]


def read_seed_run(folder: Path, protocol: str = DEFAULT_PROTOCOL) -> SeedRun | None:
    """The seed run in `folder`; None if its record is of another protocol; RecordError if refused."""
    path = Path(folder) / f"result-{seed_run_terrain(folder)}.json"
    record = read_record(path)
    if record.get("protocol") != protocol:
        return None
    return seed_run_of(Path(folder), record, str(path))


def seed_run_of(folder: Path, record: dict, where: str) -> SeedRun:
    """`record` as the seed run of `folder` (its name, terrain, label and manifest entry); RecordError if refused."""
    match = _folder_match(folder)
    terrain = match["terrain"]
    row = measured_row(record, where, terrains_covered=True)
    covered = [t["terrain"] for t in row.terrains]
    if covered != [terrain]:
        raise RecordError(f"{where}: covers {', '.join(covered)}; a seed run's record covers its folder's "
                          f"terrain ({terrain}) alone")
    if row.label != match["method"]:
        raise RecordError(f"{where}: label {row.label!r} is not the folder's method {match['method']!r}")
    entry = _manifest_entry(folder, record, where)
    seed = int(match["seed"])
    if entry.get("seed") != seed or entry.get("terrain") != terrain:
        raise RecordError(f"{where}: the manifest entry is seed {entry.get('seed')!r} on {entry.get('terrain')!r}, "
                          f"not the folder's seed {seed} on {terrain!r}")
    budget = entry.get("env_step_budget")
    if not isinstance(budget, int) or budget <= 0:
        raise RecordError(f"{where}: the manifest entry has no env_step_budget; a seed run states its budget")
    return SeedRun(method=row.label, terrain=terrain, seed=seed, budget_env_steps=budget,
                   selected_env_steps=entry.get("env_steps"), folder=folder.name, row=row)


def load_seed_runs(directory: Path, protocol: str = DEFAULT_PROTOCOL) -> SeedLoad:
    """Every seed-run folder under `directory` (name order): the valid runs, a line per refused one."""
    result = SeedLoad([], [], [])
    for folder in sorted(p for p in Path(directory).iterdir() if p.is_dir() and not p.name.startswith(".")):
        match = _FOLDER.match(folder.name)
        if match and not (folder / f"result-{match['terrain']}.json").exists():
            result.unscored.append(folder.name)  # trained (checkpoint committed), its record not made yet
            continue
        try:
            run = read_seed_run(folder, protocol)
        except RecordError as e:
            result.errors.append(str(e))
            continue
        if run is None:
            result.skipped.append(f"{folder}: protocol not {protocol!r}; not mixed in")
        else:
            result.runs.append(run)
    return result


def reference_runs(rows: list[Row] | tuple[Row, ...], terrains: tuple[str, ...]) -> list[SeedRun]:
    """The untrained reference controllers' full-run rows, one run per terrain."""
    return [SeedRun(method=r.label, terrain=t, seed=None, budget_env_steps=None, selected_env_steps=None,
                    folder=r.source, row=r)
            for r in rows if r.label in REFERENCE_METHODS for t in terrains if r.terrain(t)]


# ----------------------------------------------------------------------------- aggregating
def bootstrap_generator(terrain: str, *methods: Method) -> np.random.Generator:
    """The generator of one interval: BOOTSTRAP_SEED and a stable hash of what the interval describes."""
    import zlib

    key = "/".join([terrain, *(f"{m.label}@{m.budget_env_steps}" for m in methods)])
    return np.random.default_rng([BOOTSTRAP_SEED, zlib.crc32(key.encode())])


def aggregate(runs: list[SeedRun], suite: Suite) -> list[TerrainAggregate]:
    """One aggregate per (terrain, method), in terrain order, then trained methods by label and budget,
    then the references."""
    groups: dict[tuple[str, Method], list[SeedRun]] = {}
    for run in runs:
        groups.setdefault((run.terrain, Method(run.method, run.budget_env_steps)), []).append(run)

    def order(key):
        terrain, method = key
        return (suite.terrains.index(terrain), method.budget_env_steps is None, method.label,
                method.budget_env_steps or 0)

    out = []
    for terrain, method in sorted(groups, key=order):
        members = tuple(sorted(groups[(terrain, method)], key=lambda r: (r.seed is None, r.seed or 0)))
        levels = tuple(suite.levels(terrain, include_headroom=False))
        scores = np.array([r.scores(list(levels)) for r in members])
        aucs = np.array([[r.row.terrain(terrain)["auc"]] for r in members])
        headroom = [r.row.terrain(terrain).get("headroom_auc") for r in members]
        rng = bootstrap_generator(terrain, method)
        out.append(TerrainAggregate(
            method=method, terrain=terrain, runs=members, levels=levels, scores=scores,
            per_level=tuple(statistics.iqm(scores[:, [i]], rng) for i in range(len(levels))),
            all_levels=statistics.iqm(scores, rng), auc=statistics.iqm(aucs, rng),
            headroom_auc=(None if None in headroom else statistics.iqm(np.array([[v] for v in headroom]), rng))))
    return out


def improvements(aggregates: list[TerrainAggregate], of: str = IMPROVEMENT_OF) -> list[Improvement]:
    """P(`of` > every other method) per terrain over the level scores, for each budget of `of`."""
    out = []
    for better in (a for a in aggregates if a.method.label == of):
        for other in (a for a in aggregates if a.terrain == better.terrain and a.method != better.method):
            rng = bootstrap_generator(better.terrain, better.method, other.method)
            out.append(Improvement(better.terrain, better.method, other.method,
                                   statistics.probability_of_improvement_interval(better.scores, other.scores, rng)))
    return out


def profile_thresholds() -> np.ndarray:
    """The tau grid of the performance profiles: success rate 0 to 1 in steps of 0.05."""
    return np.linspace(0.0, 1.0, 21)


def level_name(level: float, unit: str) -> str:
    return f"{format_level(level)} {unit}"
