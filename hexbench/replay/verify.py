"""`hexbench verify RUN_DIR`: replay a run's episodes from their action logs alone and check its record.

The physics is deterministic, so (task, episode seed, actions) gives the episode again without the
controller that made it. For every episode row (or a random sample of them), the action log must
hash to the row's sha256 and replay into exactly the row's outcome; the record's per-level and
per-terrain summaries must follow from its rows, its episodes digest must match them, and the
seeds must be the protocol's (public seed set) or the key's (keyed set, given the key). The first
mismatch is named. Leaderboard admission runs the same checks, and the leaderboard checks every
record's summaries with the same `summaries_from_rows` and `summary_disagreement`.
"""

from __future__ import annotations

import json
import math
import tempfile
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexbench.artifacts.action_log import MAX_FILE_BYTES as MAX_ACTION_LOG_BYTES
from hexbench.artifacts.files import read_bytes_bounded
from hexbench.artifacts.records import episodes_digest, read_record_json, validate_record
from hexbench.errors import HexbenchError, InputError
from hexbench.evaluation import engines
from hexbench.evaluation.episode import first_row_difference, replay_row, row_action_log
from hexbench.suite.scoring import summarize_levels, summarize_terrains
from hexbench.suite.seeds import SeedSet
from hexbench.suite.tasks import format_level, load_suite

# Stored summaries may differ from the ones recomputed from the rows by float round-off only.
REL_TOLERANCE = 1e-9
ABS_TOLERANCE = 1e-12


class VerifyError(HexbenchError):
    """A run folder cannot be verified (no record, unreadable, wrong schema)."""


@dataclass(frozen=True)
class VerifyReport:
    ok: bool
    message: str
    episodes_replayed: int
    episodes_total: int
    episodes: tuple[dict, ...] = ()  # the rows replayed (all, or the sample), when every one replayed exactly


def read_run_record(run_dir: Path) -> dict:
    path = Path(run_dir) / "result.json"
    if not Path(run_dir).is_dir():
        raise VerifyError(f"{run_dir}: no such run folder")
    try:
        record = read_record_json(path)
    except InputError as e:
        raise VerifyError(f"{e}; is {run_dir} a run folder?") from None
    try:
        validate_record(record)
    except Exception as e:  # noqa: BLE001 - jsonschema's ValidationError, one line
        raise VerifyError(f"{path}: does not follow the result schema ({str(e).splitlines()[0]})") from None
    return record


def episode_name(row: dict, unit: str) -> str:
    """How a message names an episode row: `stairs 2cm episode 0`."""
    return f"{row['terrain']} {format_level(row['level'])}{unit} episode {row['index']}"


def same_up_to_round_off(a, b) -> bool:
    """Equal values; numbers equal up to float round-off (REL_TOLERANCE, ABS_TOLERANCE), lists item by item."""
    if a is None or b is None:
        return a is None and b is None
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(a, b, rel_tol=REL_TOLERANCE, abs_tol=ABS_TOLERANCE)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(same_up_to_round_off(x, y) for x, y in zip(a, b))
    return a == b


def _show(value) -> str:
    return "null" if value is None else json.dumps(value) if not isinstance(value, float) else f"{value:.6g}"


def summaries_from_rows(rows: list[dict], units: dict[str, str],
                        headroom: dict[tuple[str, float], bool]) -> tuple[list[dict], list[dict]]:
    """The per-level and per-terrain summaries of episode rows (hexbench.suite.scoring)."""
    levels = summarize_levels(rows, units, headroom)
    return levels, summarize_terrains(levels)


def _summaries_disagreement(stored: list[dict], recomputed: list[dict], key_fields: tuple[str, ...],
                            what: str) -> str | None:
    def key(d: dict) -> tuple:
        return tuple(format_level(d[k]) if k == "level" else d[k] for k in key_fields)

    stored_by_key = {}
    for d in stored:
        if key(d) in stored_by_key:
            return f"{what} {' '.join(key(d))} appears twice in the record"
        stored_by_key[key(d)] = d
    fresh_by_key = {key(d): d for d in recomputed}
    for k in sorted(set(stored_by_key) | set(fresh_by_key)):
        label = " ".join(k)
        if k not in stored_by_key:
            return f"summary disagrees with its episodes: {what} {label} is missing from the record"
        if k not in fresh_by_key:
            return f"summary disagrees with its episodes: {what} {label} has no episodes"
        s, f = stored_by_key[k], fresh_by_key[k]
        for name, fresh in f.items():
            if name not in s:
                return f"summary disagrees with its episodes: {what} {label} {name} is missing from the record"
            if not same_up_to_round_off(s[name], fresh):
                return (f"summary disagrees with its episodes: {what} {label} {name} is {_show(s[name])} in the "
                        f"record but {_show(fresh)} recomputed from the episodes")
        extra = sorted(set(s) - set(f))
        if extra:
            return f"summary disagrees with its episodes: {what} {label} {extra[0]} is not a summary of its episodes"
    return None


def summary_disagreement(record: dict, levels: list[dict], terrains: list[dict]) -> str | None:
    """The first way in which the record's stored `levels` and `terrains` summaries differ from the
    ones recomputed from its rows (`summaries_from_rows`): a summary missing, extra or twice, a field
    missing or extra, or a value beyond float round-off; None if they agree."""
    return (_summaries_disagreement(record["levels"], levels, ("terrain", "level"), "level")
            or _summaries_disagreement(record["terrains"], terrains, ("terrain",), "terrain"))


def check_episode_set(record: dict) -> str | None:
    """The first way in which the record's rows are not the episodes of one run: an unknown protocol
    or task, a number that is not finite, an episode twice, or a level whose episode indices are
    not 0..n-1 (a duplicated success would otherwise replay, and count, twice)."""
    try:
        suite = load_suite(record["protocol"])
    except ValueError as e:
        return str(e)
    rows = record["episodes"]
    if not rows:
        return "the record holds no episodes"
    first: dict[tuple, int] = {}  # (terrain, level, index) -> its row
    for n, row in enumerate(rows):
        try:
            task = suite.task(row["terrain"], float(row["level"]))
        except ValueError as e:
            return f"episodes[{n}]: {e}"
        name = episode_name(row, task.unit)
        not_finite = next((k for k, v in row.items() if isinstance(v, float) and not math.isfinite(v)), None)
        if not_finite:
            return f"{name}: {not_finite} is {row[not_finite]}, not a finite number"
        key = (task.terrain, task.level, row["index"])
        if key in first:
            return f"{name} appears twice (episodes[{first[key]}] and episodes[{n}])"
        first[key] = n
    per_task = Counter((terrain, level) for terrain, level, _ in first)
    for (terrain, level, index), n in first.items():
        if index >= per_task[(terrain, level)]:
            return (f"{episode_name(rows[n], suite.task(terrain, level).unit)}: a run's episodes of a task are "
                    f"numbered 0..{per_task[(terrain, level)] - 1}")
    return None


def check_summaries(record: dict) -> str | None:
    """The first way in which the record's summaries or digest do not follow from its rows."""
    rows = record["episodes"]
    units = {lv["terrain"]: lv["unit"] for lv in record["levels"]}
    headroom = {(lv["terrain"], lv["level"]): lv["headroom"] for lv in record["levels"]}
    if any(r["terrain"] not in units or (r["terrain"], r["level"]) not in headroom for r in rows):
        return "an episode row belongs to no level of the record"
    problem = summary_disagreement(record, *summaries_from_rows(rows, units, headroom))
    if problem:
        return problem
    if record.get("episodes_digest") != episodes_digest(rows):
        return "the episodes digest does not match the episode rows"
    return None


def check_seeds(record: dict, seed_set: SeedSet | None) -> str | None:
    declared = record["provenance"].get("seed_set", {"kind": "public"})
    if declared.get("kind") == "keyed":
        if seed_set is None or seed_set.key is None:
            return None  # cannot be checked without the key; the caller says so
        if declared.get("key_fingerprint") != seed_set.fingerprint():
            return "the record's seed key fingerprint differs from the given key's"
    else:
        seed_set = SeedSet()
    suite = load_suite(record["protocol"])
    for row in record["episodes"]:
        task = suite.task(row["terrain"], float(row["level"]))
        expected = seed_set.seeds(task, row["index"] + 1)[row["index"]]
        if row["seed"] != expected:
            return f"{episode_name(row, task.unit)}: seed {row['seed']} is not the seed set's ({expected})"
    return None


def _replay_one(args: tuple) -> str | None:
    """One episode replayed from its action log: None, or the first mismatch as one line. The log is
    read from `log_dir`, or (on a Ray node, which has no run folder) given as bytes, or as the
    reason the driver could not read it."""
    protocol, row, log_dir, log_bytes = args
    task = load_suite(protocol).task(row["terrain"], float(row["level"]))
    if isinstance(log_bytes, str):
        return f"{episode_name(row, task.unit)}: {log_bytes}"
    try:
        if log_bytes is None:
            replayed = replay_row(task, row, Path(log_dir))
        else:
            with tempfile.TemporaryDirectory(prefix="hexbench-replay-") as scratch:
                (Path(scratch) / Path(row["action_log_path"]).name).write_bytes(log_bytes)
                replayed = replay_row(task, {**row, "action_log_path": Path(row["action_log_path"]).name}, Path(scratch))
    except HexbenchError as e:
        return f"{episode_name(row, task.unit)}: {e}"
    diff = first_row_difference(row, replayed)
    return None if diff is None else f"{episode_name(row, task.unit)}: {diff}"


def _check_log_one(protocol: str, row: dict, log_dir: Path) -> str | None:
    """One episode's action log read and checked without replaying it: None, or why not as one line."""
    task = load_suite(protocol).task(row["terrain"], float(row["level"]))
    try:
        row_action_log(task, row, log_dir)
    except HexbenchError as e:
        return f"{episode_name(row, task.unit)}: {e}"
    return None


def _log_bytes(log_dir: Path, row: dict) -> bytes | str | None:
    """The bytes of a row's action log, to ship to a Ray node; why it cannot be read (a pipe, a
    device, too large: the line a local replay gives); None if the row names none (the replay
    says so)."""
    name = row.get("action_log_path")
    path = log_dir / str(name)
    if not name or Path(str(name)).name != name:
        return None
    try:
        return read_bytes_bounded(path, MAX_ACTION_LOG_BYTES, "action log")
    except InputError as e:
        return str(e)


def verify_run(run_dir: str | Path, *, sample: int | None = None, rng: np.random.Generator | None = None,
               workers: int = 1, seed_set: SeedSet | None = None, progress: bool = False,
               replay: bool = True) -> VerifyReport:
    """Check a run folder's record and replay its episodes (all, or `sample` drawn with `rng`).

    `replay=False` checks everything but the physics: the record, its summaries, digest and seeds,
    and every chosen episode's action log (present, intact, its row's sha256, its episode's). That
    is for a re-run of the controller (`hexbench.replay.rerun`), which plays the same episodes
    through the evaluator and compares every action and every row: where its action log is the
    recorded one bit for bit, it has replayed the recorded actions, and a second replay would
    repeat the same physics."""
    run_dir = Path(run_dir)
    record = read_run_record(run_dir)
    rows = record["episodes"]
    total = len(rows)
    problem = check_episode_set(record) or check_summaries(record) or check_seeds(record, seed_set)
    if problem:
        return VerifyReport(False, f"{run_dir}: {problem}", 0, total)
    chosen = rows
    if sample is not None and sample < total:
        rng = rng or np.random.default_rng()
        chosen = [rows[i] for i in sorted(rng.choice(total, size=sample, replace=False))]
    keyed = record["provenance"].get("seed_set", {}).get("kind") == "keyed" and (seed_set is None or seed_set.key is None)
    note = " (keyed seed set: seeds not checked without --seed-key)" if keyed else ""
    what = f"{len(chosen)} of {total}" if len(chosen) < total else f"all {total}"
    if not replay:
        for row in chosen:
            problem = _check_log_one(record["protocol"], row, run_dir / "episodes")
            if problem:
                return VerifyReport(False, f"{run_dir}: {problem}", 0, total)
        return VerifyReport(True, f"{run_dir}: summaries and digest match, and the action logs of {what} episodes "
                                  f"are intact{note} (not replayed: the re-run replays them)", 0, total,
                            tuple(chosen))
    engine = engines.current()
    jobs = [(record["protocol"], row, str(run_dir / "episodes"),
             None if engine.name == "local" else _log_bytes(run_dir / "episodes", row)) for row in chosen]
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    with Progress(TextColumn("[bold]replaying[/]"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                  disable=not progress) as bar:
        task_bar = bar.add_task("episodes", total=len(jobs))
        results = engine.map(_replay_one, jobs, workers, lambda: bar.advance(task_bar), stop=bool)
    failures = [r for r in results if r]
    if failures:
        return VerifyReport(False, f"{run_dir}: {failures[0]}", len(results), total)
    return VerifyReport(True, f"{run_dir}: {what} episodes replay exactly from their action logs; summaries and "
                              f"digest match{note}", len(chosen), total, tuple(chosen))
