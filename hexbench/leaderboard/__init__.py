"""The leaderboard: result records in `leaderboard/*.json` -> README.md, index.html, leaderboard.csv.

Records (hexbench/artifacts/schemas/result.schema.json) come in two kinds, validated on separate paths:

  measured   produced by `hexbench run`. Accepted only if it is schema-valid, its protocol is known,
             every seed of every level of that protocol is present exactly once (seeds as
             hexbench.suite.tasks.episode_seed derives them), its provenance is filled, and its
             `levels`/`terrains` summaries agree with the ones recomputed from its episode rows by
             hexbench.suite.scoring.summarize_levels / summarize_terrains. The leaderboard always shows the
             recomputed summaries, never the stored ones.
  reported   numbers transcribed from a publication (leaderboard/paper_reference.json: the paper's
             Table 4 and Table 6), "reported by the paper, not run here". No episodes; each series
             is one reported controller with per-level success rates. Shown as a reference beside
             the measured entries, never ranked with them.

Extra courses (the mixed course) are scored apart: their records live in `leaderboard/courses/`,
are validated the same way against the course's levels and seeds, and render
`leaderboard/courses/README.md`; they are never ranked with the full run.

Training budget (shown, not ranked): a measured record names its checkpoint files with their sha256;
the build reads the manifest.json beside them (paths relative to the repository, `build(root=)`)
and shows the stated env-step budget of the entries with those sha256s, or `?` when a checkpoint
has none (its weights changed after the record was made).

Records of different protocol versions are never mixed: a build shows one protocol; records of
other protocols are skipped with a line saying so.

Ranking rule (measured entries only), per terrain: higher hardest level passed (success >= 80%,
None ranks below every level) first, then higher AUC (area under the success-vs-level curve over
the paper levels); entries equal on both share a rank. Overall: lower mean of the per-terrain
ranks first, then higher mean AUC, then label (alphabetical) as a stable tie-break.

The build is deterministic: records are read in file-name order, rows are ordered by rank and
label, nothing depends on the clock, and matplotlib writes SVG with a fixed hash salt and no date.
"""

from __future__ import annotations

import csv
import html
import io
import json
import math
import os
import re
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from hexbench.artifacts.manifest import entries_by_sha256
from hexbench.artifacts.records import RESULT_SCHEMA
from hexbench.errors import HexbenchError
from hexbench.suite import scoring
from hexbench.suite.tasks import DEFAULT_PROTOCOL, Suite, format_level, load_suite

SCHEMA_PATH = RESULT_SCHEMA
ASSETS_DIR = Path(__file__).parent / "assets"
GENERATED_FILES = ("README.md", "index.html", "leaderboard.csv")
REPORTED_NOTE = "reported by the paper, not run here"
SETTINGS = ("simulation", "real robot")
TERRAIN_TITLES = {"rough": "Rough terrain", "slopes": "Slopes", "stairs": "Stairs"}
TERRAIN_AXES = {"rough": "height difference", "slopes": "slope angle", "stairs": "step height"}
# Stored summaries may differ from the recomputed ones by float round-off only.
REL_TOLERANCE = 1e-9
ABS_TOLERANCE = 1e-12


class RecordError(HexbenchError, ValueError):
    """A record was refused; the message is one line naming the file and the problem."""


@dataclass(frozen=True)
class Row:
    """One controller as the leaderboard shows it: per-level and per-terrain summaries.

    For a measured record, `levels` and `terrains` are recomputed from its episodes; for a reported
    series they are built from the reported rates (Wilson intervals from the stated trial counts).
    """

    label: str
    kind: str  # "measured" | "reported"
    setting: str  # "simulation" | "real robot"
    source: str  # record file name
    levels: tuple[dict, ...]
    terrains: tuple[dict, ...]
    details: dict = field(default_factory=dict, compare=False)

    def level(self, terrain: str, level: float) -> dict | None:
        for lv in self.levels:
            if lv["terrain"] == terrain and format_level(lv["level"]) == format_level(level):
                return lv
        return None

    def terrain(self, terrain: str) -> dict | None:
        for t in self.terrains:
            if t["terrain"] == terrain:
                return t
        return None


@dataclass(frozen=True)
class Board:
    """Everything one build shows: measured rows ranked, reported rows kept apart."""

    protocol: str
    suite: Suite
    measured: tuple[Row, ...]  # in overall rank order
    reported: tuple[Row, ...]  # in record/series order
    terrain_ranks: dict  # terrain -> {label: rank}
    overall_ranks: dict  # label -> rank
    reported_notes: tuple[tuple[str, str], ...] = ()  # (citation, note) per reported record
    training: dict = field(default_factory=dict)  # label -> Training of each measured row


@dataclass
class LoadResult:
    rows: list[Row]
    errors: list[str]  # one line per refused record
    skipped: list[str]  # one line per record of another protocol


# ------------------------------------------------------------------------------ validation
@lru_cache(maxsize=1)
def _schema_validator():
    import jsonschema

    schema = json.loads(SCHEMA_PATH.read_text())
    return jsonschema.Draft202012Validator(schema)


def check_schema(record: object, where: str) -> None:
    """RecordError naming the most relevant schema violation, if any."""
    import jsonschema

    error = jsonschema.exceptions.best_match(_schema_validator().iter_errors(record))
    if error is not None:
        path = "/".join(str(p) for p in error.absolute_path) or "(top level)"
        raise RecordError(f"{where}: not a valid result record at {path}: {error.message}")


def _suite_for(record: dict, where: str) -> Suite:
    try:
        return load_suite(record["protocol"])
    except ValueError as e:
        raise RecordError(f"{where}: {e}") from None


def _close(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(a, b, rel_tol=REL_TOLERANCE, abs_tol=ABS_TOLERANCE)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b))
    return a == b


def _show(value) -> str:
    return "null" if value is None else json.dumps(value) if not isinstance(value, float) else f"{value:.6g}"


def _check_provenance(record: dict, where: str) -> None:
    prov = record["provenance"]
    for key in ("hexbench_version", "git_commit", "command", "started_at"):
        if not str(prov.get(key, "")).strip():
            raise RecordError(f"{where}: provenance.{key} is empty; a measured record must say how it was made")
    if not prov.get("machine"):
        raise RecordError(f"{where}: provenance.machine is empty; a measured record must name the machine it ran on")
    ctrl = record["controller"]
    if not str(ctrl.get("file", "")).strip():
        raise RecordError(f"{where}: controller.file is empty; a measured record must name its controller file")
    if not ctrl.get("sha256"):
        raise RecordError(f"{where}: controller.sha256 is empty; a measured record must carry its controller's sha256")


def _check_episodes(record: dict, suite: Suite, where: str, tasks: tuple | None = None, keyed: bool = False) -> None:
    """Every seed of every level of `tasks` (default: the full run) present exactly once; nothing else;
    outcomes coherent. A keyed seed set's seeds were checked against its key at admission."""
    tasks = suite.tasks if tasks is None else tasks
    expected: dict[tuple[str, str], list[int]] = {
        (t.terrain, format_level(t.level)): t.seeds() for t in tasks
    }
    seen: dict[tuple[str, str, int], int] = {}
    for n, ep in enumerate(record["episodes"]):
        key = (ep["terrain"], format_level(ep["level"]))
        name = f"episodes[{n}] ({ep['terrain']} {format_level(ep['level'])}, index {ep['index']})"
        if key not in expected:
            scored = tuple(dict.fromkeys(t.terrain for t in tasks))
            if ep["terrain"] not in scored:
                why = ("is an extra course, scored apart (leaderboard/courses/)" if ep["terrain"] in suite.all_terrains
                       else f"is not in protocol {suite.protocol}")
                raise RecordError(f"{where}: {name}: terrain {ep['terrain']!r} {why}; valid terrains: "
                                  f"{', '.join(scored)}")
            valid = ", ".join(format_level(v) for v in suite.levels(ep["terrain"]))
            raise RecordError(f"{where}: {name}: level {format_level(ep['level'])} is not a {ep['terrain']} level of "
                              f"protocol {suite.protocol}; valid levels: {valid}")
        seeds = expected[key]
        if ep["index"] >= len(seeds):
            raise RecordError(f"{where}: {name}: index out of range; protocol {suite.protocol} has "
                              f"{len(seeds)} episodes per level (indices 0..{len(seeds) - 1})")
        if not keyed and ep["seed"] != seeds[ep["index"]]:
            raise RecordError(f"{where}: {name}: seed {ep['seed']} is not the protocol seed {seeds[ep['index']]}")
        if (*key, ep["index"]) in seen:
            raise RecordError(f"{where}: {name}: duplicate of episodes[{seen[(*key, ep['index'])]}]")
        seen[(*key, ep["index"])] = n
        if ep["success"] != (ep["end_reason"] == "success"):
            raise RecordError(f"{where}: {name}: success is {str(ep['success']).lower()} but end_reason is "
                              f"{ep['end_reason']!r}")
    missing = [(terrain, level, i, s) for (terrain, level), seeds in expected.items()
               for i, s in enumerate(seeds) if (terrain, level, i) not in seen]
    if missing:
        terrain, level, i, s = missing[0]
        more = f" and {len(missing) - 1} more" if len(missing) > 1 else ""
        raise RecordError(f"{where}: missing episode {terrain} {level} index {i} (seed {s}){more}; every seed of "
                          f"every level of protocol {suite.protocol} must be present")


def _compare_summaries(stored: list[dict], recomputed: list[dict], key_fields: tuple[str, ...], what: str,
                       where: str) -> None:
    def key(d: dict) -> tuple:
        return tuple(format_level(d[k]) if k == "level" else d[k] for k in key_fields)

    stored_by_key = {}
    for d in stored:
        if key(d) in stored_by_key:
            raise RecordError(f"{where}: {what} {' '.join(key(d))} appears twice in the record")
        stored_by_key[key(d)] = d
    fresh_by_key = {key(d): d for d in recomputed}
    for k in sorted(set(stored_by_key) | set(fresh_by_key)):
        label = " ".join(k)
        if k not in stored_by_key:
            raise RecordError(f"{where}: summary disagrees with its episodes: {what} {label} is missing from the record")
        if k not in fresh_by_key:
            raise RecordError(f"{where}: summary disagrees with its episodes: {what} {label} has no episodes")
        s, f = stored_by_key[k], fresh_by_key[k]
        for name, fresh in f.items():
            if name in s and not _close(s[name], fresh):
                raise RecordError(f"{where}: summary disagrees with its episodes: {what} {label} {name} is "
                                  f"{_show(s[name])} in the record but {_show(fresh)} recomputed from the episodes")


# ------------------------------------------------------------------------------ trust tiers
TIER_SELF_REPORTED = "self-reported"
TIER_REPLAYED = "sandboxed + replayed"
TIER_HIDDEN = "sandboxed + replayed + hidden seeds"
TIER_ORDER = {TIER_SELF_REPORTED: 0, TIER_REPLAYED: 1, TIER_HIDDEN: 2}


def record_tier(record: dict, where: str) -> str:
    """How far a measured record is proven. Replayed tiers need the admission block that
    `hexbench leaderboard add RUN_DIR` writes after replaying the run, bound to the record's rows by
    their digest; a record made in-process (--isolation none) is refused outright."""
    from hexbench.artifacts.records import episodes_digest

    isolation = record["provenance"].get("isolation") or {}
    if isolation.get("mode") == "none":
        raise RecordError(f"{where}: was made with --isolation none (the controller ran inside the evaluator); "
                          f"the leaderboard takes sandboxed runs only")
    admission = record.get("admission")
    if not admission:
        return TIER_SELF_REPORTED
    digest = record.get("episodes_digest")
    if admission.get("episodes_digest") != digest or digest != episodes_digest(record["episodes"]):
        raise RecordError(f"{where}: its episode rows changed after admission (episodes digest differs); "
                          f"re-admit the run with `hexbench leaderboard add RUN_DIR`")
    if not isolation.get("sandboxed"):
        return TIER_SELF_REPORTED
    keyed = record["provenance"].get("seed_set", {}).get("kind") == "keyed"
    return TIER_HIDDEN if keyed else TIER_REPLAYED


def measured_row(record: dict, where: str, course: bool = False) -> Row:
    """Validate a measured record (see module docstring) and return its row; RecordError if refused.

    course=True validates a record of the extra courses (every seed of every level of the courses
    it covers) instead of the full run.
    """
    check_schema(record, where)
    if record["kind"] != "measured":
        raise RecordError(f"{where}: kind is {record['kind']!r}; expected 'measured'")
    suite = _suite_for(record, where)
    _check_provenance(record, where)
    if course:
        covered = {e["terrain"] for e in record["episodes"]}
        tasks = tuple(t for t in suite.extra_tasks if t.terrain in covered) or suite.extra_tasks
    else:
        tasks = suite.tasks
    tier = record_tier(record, where)
    _check_episodes(record, suite, where, tasks, keyed=tier.endswith("hidden seeds"))
    units = {t.terrain: t.unit for t in tasks}
    headroom = {(t.terrain, t.level): t.headroom for t in tasks}
    # Episode levels are normalised to the suite's float so the headroom lookup cannot miss.
    suite_level = {(t.terrain, format_level(t.level)): t.level for t in tasks}
    episodes = [{**e, "level": suite_level[(e["terrain"], format_level(e["level"]))]} for e in record["episodes"]]
    levels = scoring.summarize_levels(episodes, units, headroom)
    terrains = scoring.summarize_terrains(levels)
    _compare_summaries(record["levels"], levels, ("terrain", "level"), "level", where)
    _compare_summaries(record["terrains"], terrains, ("terrain",), "terrain", where)
    prov, ctrl = record["provenance"], record["controller"]
    details = {
        "controller_file": ctrl["file"], "controller_sha256": ctrl["sha256"], "action_mode": ctrl["action_mode"],
        "checkpoints": [c["sha256"] for c in ctrl.get("checkpoints", [])],
        "checkpoint_files": [(c["path"], c["sha256"]) for c in ctrl.get("checkpoints", [])], "git_commit": prov["git_commit"],
        "command": prov["command"], "hexbench_version": prov["hexbench_version"], "started_at": prov["started_at"],
        "wall_time_s": prov["wall_time_s"], "workers": prov["workers"], "episodes": len(record["episodes"]),
        "tier": tier, "admission": record.get("admission"),
    }
    return Row(label=record["label"], kind="measured", setting="simulation", source=Path(where).name,
               levels=tuple(levels), terrains=tuple(terrains), details=details)


def reported_rows(record: dict, where: str) -> list[Row]:
    """Validate a reported record and return one row per series; RecordError if refused."""
    check_schema(record, where)
    if record["kind"] != "reported":
        raise RecordError(f"{where}: kind is {record['kind']!r}; expected 'reported'")
    suite = _suite_for(record, where)
    if not record["provenance"].get("source", "").strip():
        raise RecordError(f"{where}: provenance.source is empty; a reported record must name its source")
    rows, labels = [], set()
    for s_index, series in enumerate(record["reported"]["series"]):
        name = f"reported.series[{s_index}] ({series['label']})"
        if series["label"] in labels:
            raise RecordError(f"{where}: {name}: duplicate series label")
        labels.add(series["label"])
        levels, seen = [], set()
        for lv in series["levels"]:
            terrain, level = lv["terrain"], float(lv["level"])
            if terrain not in suite.terrains:
                raise RecordError(f"{where}: {name}: terrain {terrain!r} is not in protocol {suite.protocol}; "
                                  f"valid terrains: {', '.join(suite.terrains)}")
            try:
                task = suite.task(terrain, level)
            except ValueError as e:
                raise RecordError(f"{where}: {name}: {e}") from None
            if lv["unit"] != task.unit:
                raise RecordError(f"{where}: {name}: {terrain} unit is {lv['unit']!r}; protocol {suite.protocol} "
                                  f"uses {task.unit!r}")
            if (terrain, format_level(level)) in seen:
                raise RecordError(f"{where}: {name}: {terrain} level {format_level(level)} appears twice")
            seen.add((terrain, format_level(level)))
            n, k = lv["episodes"], lv["successes"]
            if k > n or not _close(lv["success_rate"], k / n):
                raise RecordError(f"{where}: {name}: {terrain} {format_level(level)}: success_rate "
                                  f"{lv['success_rate']:g} is not successes/episodes = {k}/{n}")
            lo, hi = scoring.wilson_interval(k, n)
            levels.append({
                "terrain": terrain, "level": task.level, "unit": task.unit, "headroom": task.headroom,
                "episodes": n, "successes": k, "success_rate": k / n, "ci95_low": lo, "ci95_high": hi, "seeds": [],
                "mean_forward_speed_m_per_s": None, "mean_time_to_goal_s": None, "mean_max_abs_y_m": None,
                "mean_roll_rms_deg": None, "mean_pitch_rms_deg": None, "mean_cost_of_transport": None,
            })
        levels.sort(key=lambda r: (r["terrain"], r["level"]))
        terrains = scoring.summarize_terrains(levels)
        for t in terrains:  # an AUC over some of the paper levels is not comparable; keep it only if complete
            covered = {format_level(r["level"]) for r in levels if r["terrain"] == t["terrain"] and not r["headroom"]}
            if covered != {format_level(v) for v in suite.levels(t["terrain"], include_headroom=False)}:
                t["auc"] = None
            t["headroom_auc"] = None
        details = {"method": series["method"], "table": series["table"], "action_mode": series.get("action_mode", ""),
                   "citation": record["reported"]["citation"], "note": record["reported"]["note"]}
        rows.append(Row(label=series["label"], kind="reported", setting=series["setting"], source=Path(where).name,
                        levels=tuple(levels), terrains=tuple(terrains), details=details))
    return rows


def read_record(path: Path) -> dict:
    try:
        record = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise RecordError(f"{path}: no such file") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise RecordError(f"{path}: not JSON: {e}") from None
    if not isinstance(record, dict):
        raise RecordError(f"{path}: not a result record (a JSON object is expected, found {type(record).__name__})")
    return record


def rows_of(record: dict, where: str) -> list[Row]:
    """Validate a record on the path of its kind; RecordError if refused."""
    if record.get("kind") == "reported":
        return reported_rows(record, where)
    return [measured_row(record, where)]


def record_files(directory: Path) -> list[Path]:
    return sorted(p for p in Path(directory).glob("*.json") if not p.name.startswith("."))


def load_rows(directory: Path, protocol: str = DEFAULT_PROTOCOL) -> LoadResult:
    """Every record under `directory` of `protocol`: rows of the valid ones, a line per refused one."""
    result = LoadResult([], [], [])
    labels: dict[str, str] = {}
    for path in record_files(directory):
        where = str(path)
        try:
            record = read_record(path)
            if record.get("protocol") != protocol:
                result.skipped.append(f"{where}: protocol {record.get('protocol')!r}, not {protocol!r}; "
                                      f"not mixed into the {protocol} leaderboard")
                continue
            rows = rows_of(record, where)
            for row in rows:
                if row.label in labels:
                    raise RecordError(f"{where}: label {row.label!r} is already used by {labels[row.label]}; "
                                      "labels must be unique")
        except RecordError as e:
            result.errors.append(str(e))
            continue
        for row in rows:
            labels[row.label] = path.name
        result.rows.extend(rows)
    return result


# -------------------------------------------------------------------------- training budget
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


# ---------------------------------------------------------------------------------- ranking
def _terrain_key(summary: dict | None) -> tuple[float, float]:
    if summary is None:
        return (-math.inf, -math.inf)
    hardest = summary["hardest_level_passed"]
    auc = summary["auc"]
    # AUCs are compared at 1e-9 so float round-off can never split a tie
    return (-math.inf if hardest is None else hardest, -math.inf if auc is None else round(auc, 9))


def rank_terrain(rows: list[Row], terrain: str) -> dict[str, int]:
    """Competition ranks (1, 1, 3, ...) by hardest level passed, then AUC (module docstring)."""
    keyed = sorted(((_terrain_key(r.terrain(terrain)), r.label) for r in rows), key=lambda kl: (
        tuple(-v for v in kl[0]), kl[1]))
    ranks, previous, rank = {}, None, 0
    for position, (k, label) in enumerate(keyed, start=1):
        if k != previous:
            rank, previous = position, k
        ranks[label] = rank
    return ranks


def rank_overall(rows: list[Row], terrains: tuple[str, ...]) -> tuple[list[Row], dict[str, dict[str, int]], dict[str, int]]:
    """Rows in overall order, per-terrain ranks and overall ranks (module docstring)."""
    terrain_ranks = {t: rank_terrain(rows, t) for t in terrains}

    def mean_rank(r: Row) -> float:
        return sum(terrain_ranks[t][r.label] for t in terrains) / len(terrains) if terrains else 0.0

    def mean_auc(r: Row) -> float:
        aucs = [(r.terrain(t) or {}).get("auc") for t in terrains]
        return round(sum(a if a is not None else 0.0 for a in aucs) / len(aucs), 9) if aucs else 0.0

    ordered = sorted(rows, key=lambda r: (mean_rank(r), -mean_auc(r), r.label))
    overall, previous, rank = {}, None, 0
    for position, r in enumerate(ordered, start=1):
        k = (mean_rank(r), mean_auc(r))
        if k != previous:
            rank, previous = position, k
        overall[r.label] = rank
    return ordered, terrain_ranks, overall


def make_board(load: LoadResult, protocol: str = DEFAULT_PROTOCOL, root: Path | None = None) -> Board:
    """Rank the loaded rows; `root` is where records' checkpoint paths resolve (None: budgets unknown)."""
    suite = load_suite(protocol)
    measured = [r for r in load.rows if r.kind == "measured"]
    reported = [r for r in load.rows if r.kind == "reported"]
    ordered, terrain_ranks, overall = rank_overall(measured, suite.terrains)
    notes = tuple(dict.fromkeys((r.details["citation"], r.details["note"]) for r in reported))
    training = {r.label: training_of(r, root) if root is not None else Training(known=False) for r in measured}
    return Board(protocol, suite, tuple(ordered), tuple(reported), terrain_ranks, overall, notes, training)


# ------------------------------------------------------------------------------ formatting
def pct(rate: float | None) -> str:
    return "–" if rate is None else f"{100 * rate:.0f}%"


def fmt_level(level: float | None, unit: str) -> str:
    return "none" if level is None else f"{format_level(level)} {unit}"


def fmt_num(value: float | None, digits: int = 2) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def reported_name(row: Row) -> str:
    return f"{row.label}: reported, not run here"


def _mean(values: list[float | None]) -> float | None:
    vals = [v for v in values if v is not None]
    return sum(vals) / len(vals) if vals else None


def overall_metrics(row: Row) -> dict:
    """Means over terrains of the per-terrain means (speed, roll/pitch RMS)."""
    return {
        "mean_forward_speed_m_per_s": _mean([t["mean_forward_speed_m_per_s"] for t in row.terrains]),
        "mean_roll_rms_deg": _mean([t.get("mean_roll_rms_deg") for t in row.terrains]),
        "mean_pitch_rms_deg": _mean([t.get("mean_pitch_rms_deg") for t in row.terrains]),
        "episodes": sum(t["episodes"] for t in row.terrains),
    }


RANKING_RULE = (
    "Per terrain, a controller ranks above another if it passes a harder level (success rate >= 80%; "
    "passing no level ranks last), and on equal hardest level if its AUC (area under the success-vs-level "
    "curve over the paper's Table 4 levels, 1.0 = every level at 100%) is higher; equal on both means an "
    "equal rank. The overall rank orders controllers by the mean of their three terrain ranks, then by "
    "mean AUC. Only measured entries are ranked; the paper's numbers are a reference, "
    f"{REPORTED_NOTE}."
)


# ---------------------------------------------------------------------------------- README
# Strings taken from a record (labels, file names, paths, commands, citations, ...) come from
# submitters. In Markdown they go through _md (text) or _md_code (a code span), so they show as the
# literal text: nothing in them can make HTML (GitHub passes inline HTML through), links, emphasis,
# code spans, block structure or extra table cells. Plain strings ("ppo_cpg", "PPO-CPG (paper)")
# come out unchanged.
_MD_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]")  # newlines would end a table row or paragraph
_MD_BACKSLASHED = re.compile(r"[\\`*\[\]~$]")  # escapes, code spans, emphasis, links/images, strikethrough, math
# `_` makes emphasis only next to a non-alphanumeric character; inside a word ("ppo_cpg") it cannot
_MD_UNDERSCORE = re.compile(r"(?<![^\W_])_|_(?![^\W_])")
_MD_BLOCK_START = re.compile(r"^(\s*)(?:([#+=-])|(\d+)([.)]))")  # headings, lists, setext/thematic breaks


def _one_line(text) -> str:
    """`text` on one line: control characters (newlines included) become spaces (Markdown cells,
    plot legends)."""
    return _MD_CONTROL.sub(" ", str(text))


def _md(text, block: bool = False) -> str:
    """A record string as Markdown text that renders as exactly that text.

    block=True where the text starts a block (a paragraph or list item): a leading `#`, `-`, `+`, `=`
    or `1.` is escaped too, so it cannot become a heading, list or rule. In a table, `_md_table`
    escapes `|`.
    """
    s = _MD_BACKSLASHED.sub(lambda m: "\\" + m.group(0), _one_line(text))
    s = s.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    s = _MD_UNDERSCORE.sub(r"\\_", s)
    if block:
        s = _MD_BLOCK_START.sub(lambda m: m.group(1) + (f"\\{m.group(2)}" if m.group(2) else
                                                        f"{m.group(3)}\\{m.group(4)}"), s, count=1)
    return s


def _md_code(text) -> str:
    """A record string as a Markdown code span: literal text (HTML and Markdown are not parsed in it);
    the fence is longer than any run of backticks inside. In a table, `_md_table` escapes `|` (GFM
    removes that backslash inside code spans too). A string with `<` is written as escaped text
    (`_md`) instead, so the file never holds a raw tag, even for a tool that does not parse Markdown."""
    s = _one_line(text)
    if "<" in s:
        return _md(s)
    fence = "`" * (max((len(run) for run in re.findall(r"`+", s)), default=0) + 1)
    pad = " " if s.startswith("`") or s.endswith("`") or (s.startswith(" ") and s.endswith(" ") and s.strip()) else ""
    return f"{fence}{pad}{s}{pad}{fence}"


def _md_table_cell(cell: str) -> str:
    return _one_line(cell).replace("|", "\\|")


def _md_table(header: list[str], rows: list[list[str]], align: list[str] | None = None) -> str:
    """A GFM table; cells are Markdown (record strings already through _md / _md_code), `|` in them is
    escaped so it never splits a cell."""
    align = align or ["l"] + ["r"] * (len(header) - 1)
    sep = ["---:" if a == "r" else ":---:" if a == "c" else "---" for a in align]
    lines = ["| " + " | ".join(_md_table_cell(c) for c in header) + " |", "| " + " | ".join(sep) + " |"]
    lines += ["| " + " | ".join(_md_table_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _md_cell(lv: dict | None, with_ci: bool) -> str:
    if lv is None:
        return "–"
    if not with_ci:
        return pct(lv["success_rate"])
    return f"{pct(lv['success_rate'])} ({100 * lv['ci95_low']:.0f}–{100 * lv['ci95_high']:.0f})"


TRAINING_NOTE = ("Training budget: the stated env-step budget the controller's shipped weights were trained with, "
                 "read from the manifest beside its checkpoints and matched by sha256 (`none`: no trained weights; "
                 "`?`: a checkpoint has no matching manifest entry). Methods trained with different budgets are "
                 "not a like-for-like comparison.")


TRUST_NOTE = ("Trust: `sandboxed + replayed` entries were made with the controller in its own sandboxed process "
              "and admitted by `hexbench leaderboard add RUN_DIR`, which replayed their episodes from the action "
              "logs alone (all of them, or the stated sample); `+ hidden seeds` were scored on episodes derived "
              "from a maintainer's secret key; `self-reported` entries were not replayed (records made before "
              "sandboxing, or added without their run folder) and are ranked alongside but not proven.")


def fmt_trust(row: Row) -> str:
    tier = row.details.get("tier", TIER_SELF_REPORTED)
    admission = row.details.get("admission") or {}
    replayed, total = admission.get("episodes_replayed"), admission.get("episodes_total")
    if tier != TIER_SELF_REPORTED and replayed is not None and total and replayed < total:
        return f"{tier} ({replayed} of {total} replayed)"
    return tier


def _fmt_checkpoint_steps(training: Training | None) -> str:
    if training is None or not training.known:
        return "?"
    return fmt_steps_range(training.env_steps)


def render_readme(board: Board) -> str:
    suite, out = board.suite, []
    out.append(f"# hexbench leaderboard: protocol {board.protocol}\n")
    out.append("Generated by `hexbench leaderboard build` from the result records in this folder; do not edit by "
               "hand (add a record with `hexbench leaderboard add RESULT.json`). `index.html` is the same "
               "leaderboard as one self-contained page with a sortable table and plots; `leaderboard.csv` has "
               "every number.\n")
    out.append(f"Measured entries: {len(board.measured)}. Paper reference series: {len(board.reported)} "
               f"({REPORTED_NOTE}).\n")
    out.append("## Ranking\n")
    out.append(RANKING_RULE + "\n")
    if board.measured:
        header = ["Rank", "Controller", "Trust", "Training budget [env steps]"]
        for t in suite.terrains:
            header += [f"{TERRAIN_TITLES.get(t, t)}: hardest passed", f"{TERRAIN_TITLES.get(t, t)}: AUC"]
        header += ["Mean speed [m/s]", "Roll RMS [deg]", "Pitch RMS [deg]"]
        rows = []
        for r in board.measured:
            m = overall_metrics(r)
            cells = [str(board.overall_ranks[r.label]), _md(r.label), fmt_trust(r),
                     fmt_budget(board.training.get(r.label))]
            for t in suite.terrains:
                s = r.terrain(t)
                cells += [fmt_level(s["hardest_level_passed"], s["unit"]), fmt_num(s["auc"])]
            cells += [fmt_num(m["mean_forward_speed_m_per_s"], 3), fmt_num(m["mean_roll_rms_deg"], 1),
                      fmt_num(m["mean_pitch_rms_deg"], 1)]
            rows.append(cells)
        out.append(_md_table(header, rows, ["r", "l", "l"] + ["r"] * (len(header) - 3)) + "\n")
        out.append(TRAINING_NOTE + "\n")
        out.append(TRUST_NOTE + "\n")
    else:
        out.append("No measured records yet.\n")
    for terrain in suite.terrains:
        unit = suite.task(terrain, suite.levels(terrain)[0]).unit
        out.append(f"## {TERRAIN_TITLES.get(terrain, terrain)} ({TERRAIN_AXES.get(terrain, 'level')} in {unit})\n")
        ranks = board.terrain_ranks[terrain]
        header = ["Rank", "Controller", "Hardest level passed", "AUC", "Headroom AUC", "Mean speed [m/s]",
                  "Roll RMS [deg]", "Pitch RMS [deg]", "Episodes"]
        rows = []
        for r in sorted(board.measured, key=lambda r: (ranks[r.label], r.label)):
            s = r.terrain(terrain)
            rows.append([str(ranks[r.label]), _md(r.label), fmt_level(s["hardest_level_passed"], unit),
                         fmt_num(s["auc"]), fmt_num(s["headroom_auc"]),
                         fmt_num(s["mean_forward_speed_m_per_s"], 3), fmt_num(s.get("mean_roll_rms_deg"), 1),
                         fmt_num(s.get("mean_pitch_rms_deg"), 1), str(s["episodes"])])
        for r in board.reported:  # beside the measured rows, never ranked
            s = r.terrain(terrain)
            if s is not None:
                rows.append(["ref.", _md(reported_name(r)), fmt_level(s["hardest_level_passed"], unit), fmt_num(s["auc"]),
                             "–", "–", "–", "–", f"{s['episodes']} (paper's trials)"])
        if rows:
            out.append("Ranked summary (measured entries; `ref.` rows are the paper's, unranked; AUC of a reference "
                       "row only where it covers every Table 4 level):\n")
            out.append(_md_table(header, rows, ["r", "l"] + ["r"] * (len(header) - 2)) + "\n")
        paper_levels = suite.levels(terrain, include_headroom=False)
        out.append(f"Success rate per level, laid out like paper Table 4 (level in {unit}); measured entries with "
                   "the 95% Wilson interval in brackets.\n")
        header = ["Controller"] + [format_level(v) for v in paper_levels]
        rows = [[_md(r.label)] + [_md_cell(r.level(terrain, v), True) for v in paper_levels] for r in board.measured]
        rows += [[_md(reported_name(r))] + [_md_cell(r.level(terrain, v), False) for v in paper_levels]
                 for r in board.reported if r.setting == "simulation" and r.terrain(terrain)]
        out.append(_md_table(header, rows) + "\n")
        extra = [v for v in suite.levels(terrain) if v not in paper_levels]
        if extra and board.measured:
            out.append("Headroom levels (beyond the paper, scored separately):\n")
            header = ["Controller"] + [format_level(v) for v in extra]
            rows = [[_md(r.label)] + [_md_cell(r.level(terrain, v), True) for v in extra] for r in board.measured]
            out.append(_md_table(header, rows) + "\n")
    real = [r for r in board.reported if r.setting == "real robot"]
    if real:
        out.append(f"## Real robot ({REPORTED_NOTE})\n")
        for r in real:
            for t in r.terrains:
                levels = [lv for lv in r.levels if lv["terrain"] == t["terrain"]]
                header = [f"{_md(r.label)}: {_md(TERRAIN_TITLES.get(t['terrain'], t['terrain']))} [{_md(t['unit'])}]"]
                header += [format_level(lv["level"]) for lv in levels]
                out.append(_md_table(header, [["success rate"] + [pct(lv["success_rate"]) for lv in levels]]) + "\n")
    if board.reported_notes:
        out.append("## About the paper reference\n")
        for citation, note in board.reported_notes:
            out.append(f"{_md(citation, block=True)}\n\n{_md(note, block=True)}\n")
    out.append("## Records\n")
    if board.measured:
        header = ["Controller", "Trust", "Record", "Controller file", "sha256", "Action mode", "Training budget",
                  "Shipped checkpoints at [env steps]", "git commit", "Episodes", "Wall time [s]", "Command"]
        rows = [[_md(r.label), fmt_trust(r), _md(r.source), _md(r.details["controller_file"]),
                 _md(r.details["controller_sha256"][:12]),
                 _md(r.details["action_mode"]), fmt_budget(board.training.get(r.label)),
                 _fmt_checkpoint_steps(board.training.get(r.label)), _md(str(r.details["git_commit"])[:12]),
                 str(r.details["episodes"]), f"{r.details['wall_time_s']:.0f}", _md_code(r.details["command"])]
                for r in board.measured]
        out.append(_md_table(header, rows, ["l"] * len(header)) + "\n")
    sources = sorted({r.source for r in board.reported})
    if sources:
        out.append(f"Paper reference: {', '.join(_md(s) for s in sources)} (kind `reported`: {REPORTED_NOTE}).\n")
    out.append("## Definitions\n")
    out.append("- **Success**: the base advances 2.5 m along +x within the step limit, never more than 0.8 m off in "
               "y, without falling (protocol details in `tasks/protocol_v1.toml`). 20 seeded episodes per level.\n"
               "- **Success rate**: successes / episodes, with the 95% Wilson score interval.\n"
               "- **Hardest level passed**: the highest level with success rate >= 80%.\n"
               "- **AUC**: trapezoidal area under success rate vs level over the paper levels, divided by the level "
               "span (1.0 = 100% everywhere). Headroom AUC: the same over the levels beyond the paper.\n"
               "- **Mean speed, roll/pitch RMS**: means over all episodes of each level, then over levels "
               "(and over terrains in the ranking table).\n"
               "- Summaries are recomputed from each record's per-episode rows (`hexbench.suite.scoring`); a record whose "
               "stored summary disagrees with its episodes is refused.\n")
    return "\n".join(out)


# ------------------------------------------------------------------------------------- CSV
CSV_COLUMNS = ("kind", "setting", "controller", "record", "overall_rank", "terrain_rank", "terrain", "unit", "level",
               "headroom", "episodes", "successes", "success_rate", "ci95_low", "ci95_high",
               "level_mean_forward_speed_m_per_s", "terrain_hardest_level_passed", "terrain_auc",
               "terrain_headroom_auc", "terrain_mean_forward_speed_m_per_s", "terrain_mean_roll_rms_deg",
               "terrain_mean_pitch_rms_deg", "training_env_step_budget", "checkpoint_env_steps", "trust")


def _csv_value(v) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(round(v, 6))
    return str(v)


# A spreadsheet evaluates a cell starting with one of these as a formula (OWASP "CSV injection").
CSV_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def _csv_text(v) -> str:
    """A free-text cell from a record (label, file name): a leading apostrophe where the text would
    start a spreadsheet formula, so it shows as text. Never for numbers (a negative number stays one)."""
    s = _csv_value(v)
    return "'" + s if s.startswith(CSV_FORMULA_START) else s


def _csv_training(training: Training | None) -> tuple[str | None, str | None]:
    """Budget and checkpoint env steps as CSV cells: distinct values joined by ';', empty if unknown."""
    if training is None or not training.known:
        return None, None
    return ";".join(map(str, training.budgets)), ";".join(map(str, training.env_steps))


def render_csv(board: Board) -> str:
    """Long format: one row per controller x terrain x level, terrain summary columns repeated."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for r in (*board.measured, *board.reported):
        for lv in r.levels:
            t = r.terrain(lv["terrain"])
            measured = r.kind == "measured"
            writer.writerow([r.kind, r.setting, _csv_text(r.label), _csv_text(r.source)] + [_csv_value(v) for v in (
                board.overall_ranks[r.label] if measured else None,
                board.terrain_ranks[lv["terrain"]][r.label] if measured else None,
                lv["terrain"], lv["unit"], lv["level"], lv["headroom"], lv["episodes"], lv["successes"],
                lv["success_rate"], lv["ci95_low"], lv["ci95_high"], lv["mean_forward_speed_m_per_s"],
                t["hardest_level_passed"], t["auc"], t["headroom_auc"], t["mean_forward_speed_m_per_s"],
                t.get("mean_roll_rms_deg"), t.get("mean_pitch_rms_deg"),
                *_csv_training(board.training.get(r.label) if measured else None),
                fmt_trust(r) if measured else "reported")])
    return buf.getvalue()


# ------------------------------------------------------------------------------------ plots
MEASURED_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#e377c2",
                   "#bcbd22", "#7f7f7f")
REPORTED_STYLES = (("#555555", (0, (5, 3)), "s"), ("#555555", (0, (6, 2, 1, 2)), "^"), ("#000000", (0, (3, 2)), "D"),
                   ("#000000", (0, (1, 1.5)), "x"), ("#888888", (0, (4, 1, 1, 1, 1, 1)), "v"))


def measured_color(board: Board, label: str) -> str:
    """A fixed colour per measured controller (by overall order), shared by plots and tables."""
    labels = [r.label for r in board.measured]
    return MEASURED_COLORS[labels.index(label) % len(MEASURED_COLORS)]


def _literal_legend_texts(legend) -> None:
    """Legend entries are record labels: drawn as literal text, never parsed as mathtext (`$...$`).
    matplotlib escapes text for SVG itself (`<`, `&`; `--` in the comments it writes)."""
    for text in legend.get_texts():
        text.set_parse_math(False)


def plot_svg(board: Board, terrain: str) -> str:
    """Success vs level for one terrain as an SVG string (deterministic bytes)."""
    import matplotlib
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    suite = board.suite
    unit = suite.task(terrain, suite.levels(terrain)[0]).unit
    levels_all = suite.levels(terrain)
    paper_levels = suite.levels(terrain, include_headroom=False)
    with matplotlib.rc_context({"svg.hashsalt": f"hexbench-leaderboard-{terrain}", "svg.fonttype": "none",
                                "svg.id": f"plot-{terrain}", "font.family": "DejaVu Sans", "font.size": 9,
                                "axes.spines.top": False, "axes.spines.right": False}):
        fig = Figure(figsize=(8.4, 3.6))
        ax = fig.add_axes((0.075, 0.14, 0.55, 0.78))
        extra = [v for v in levels_all if v not in paper_levels]
        x_max = max(levels_all) + 0.25
        if extra:  # the headroom band starts half-way between the last paper level and the first extra one
            band_start = (max(paper_levels) + min(extra)) / 2
            ax.axvspan(band_start, x_max, color="#f3efe2", zorder=0, lw=0)
            ax.text((band_start + x_max) / 2, 1.075, "headroom (beyond the paper)", ha="center", va="bottom",
                    fontsize=7.5, color="#8a7a4a", clip_on=False)
        ax.axhline(scoring.PASS_THRESHOLD, color="#999999", lw=0.8, ls=(0, (2, 2)), zorder=1)
        ax.text(min(levels_all) - 0.2, scoring.PASS_THRESHOLD - 0.015, "pass (80%)", fontsize=7.5, color="#777777",
                va="top")
        reported_handles, measured_handles = [], []
        for i, r in enumerate(r for r in board.reported if r.terrain(terrain)):
            color, style, marker = REPORTED_STYLES[i % len(REPORTED_STYLES)]
            pts = [lv for lv in r.levels if lv["terrain"] == terrain]
            (line,) = ax.plot([p["level"] for p in pts], [p["success_rate"] for p in pts], color=color, ls=style,
                              lw=1.3, marker=marker, ms=4.5, mfc="white", mew=1.1, zorder=2, label=_one_line(r.label))
            reported_handles.append(line)
        gaps = [b - a for a, b in zip(levels_all, levels_all[1:])]
        dodge = 0.08 * min(gaps) if gaps else 0.0  # side-by-side whiskers so intervals stay readable
        n_measured = len(board.measured)
        for i, r in enumerate(board.measured):
            pts = [lv for lv in r.levels if lv["terrain"] == terrain]
            color = measured_color(board, r.label)
            x = [p["level"] + (i - (n_measured - 1) / 2) * dodge for p in pts]
            y = [p["success_rate"] for p in pts]
            yerr = [[v - p["ci95_low"] for v, p in zip(y, pts)], [p["ci95_high"] - v for v, p in zip(y, pts)]]
            container = ax.errorbar(x, y, yerr=yerr, color=color, lw=2.0, marker="o", ms=4.5, zorder=4,
                                    elinewidth=1.0, capsize=2.0, capthick=1.0, ecolor=color, label=_one_line(r.label))
            for bar in container[2]:
                bar.set_alpha(0.55)
            measured_handles.append(container)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlim(min(levels_all) - 0.25, x_max)
        ax.set_ylim(-0.02, 1.04)
        ax.set_yticks([0, 0.2, 0.4, 0.6, 0.8, 1.0], ["0%", "20%", "40%", "60%", "80%", "100%"])
        ax.set_xlabel(f"{TERRAIN_AXES.get(terrain, 'level')} [{unit}]")
        ax.set_ylabel("success rate")
        ax.grid(axis="y", color="#e6e6e6", lw=0.6, zorder=0)
        legend_style = {"loc": "upper left", "frameon": False, "fontsize": 7.5, "title_fontsize": 8,
                        "handlelength": 2.8, "alignment": "left"}
        top = 0.95
        if measured_handles:
            legend = fig.legend(handles=measured_handles, title="measured here\n(whiskers: 95% Wilson interval)",
                                bbox_to_anchor=(0.655, top), **legend_style)
            legend.get_title().set_fontweight("bold")
            _literal_legend_texts(legend)
            top -= 0.062 * (len(measured_handles) + 2) + 0.05
        if reported_handles:
            legend = fig.legend(handles=reported_handles, title=f"paper reference\n({REPORTED_NOTE})",
                                bbox_to_anchor=(0.655, top), **legend_style)
            legend.get_title().set_fontweight("bold")
            legend.get_title().set_color("#6b5b2e")
            _literal_legend_texts(legend)
        buf = io.StringIO()
        fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None, "Format": None, "Type": None})
    svg = buf.getvalue()
    svg = svg[svg.index("<svg"):]  # drop the XML declaration and DOCTYPE for inlining in HTML
    svg = re.sub(r'<svg([^>]*?) width="[^"]+" height="[^"]+"', r'<svg\1', svg, count=1)
    # Three plots share one page: prefix every element id (and its references) with the terrain.
    # Inside tags only: text (legend entries are record labels) is left exactly as it is; matplotlib
    # escapes `<` and `>` in it, so no text is taken for a tag.
    tag_re = re.compile(r"<(?!!--)[^<>]*>")
    ids = {i for tag in tag_re.findall(svg) for i in re.findall(r'\bid="([^"]+)"', tag)} - {f"plot-{terrain}"}

    def prefix_ids(tag: re.Match) -> str:
        t = re.sub(r'\bid="([^"]+)"', lambda m: f'id="{terrain}-{m.group(1)}"' if m.group(1) in ids else m.group(0),
                   tag.group(0))
        return re.sub(r'(url\(#|href="#)([^)"]+)', lambda m: f"{m.group(1)}{terrain}-{m.group(2)}"
                      if m.group(2) in ids else m.group(0), t)

    svg = tag_re.sub(prefix_ids, svg)
    svg = svg.replace("<svg", f'<svg role="img" aria-label="{TERRAIN_TITLES.get(terrain, terrain)}: success rate '
                      'versus level"', 1)
    return svg.strip() + "\n"


# ------------------------------------------------------------------------------------ HTML
def _e(text) -> str:
    """Text or an attribute value for the page (every string from a record goes through this)."""
    return html.escape(str(text), quote=True)


def _raw_text(text: str) -> str:
    """Contents of a <script> or <style> element: `</` escaped (`<\\/`, the same in JavaScript strings,
    JSON and CSS), so nothing inside can close the element. The page inlines only its own assets there,
    never record data."""
    return text.replace("</", "<\\/")


def _sort_attr(value) -> str:
    return "" if value is None else f' data-sort="{value!r}"' if isinstance(value, float) else f' data-sort="{_e(value)}"'


def _html_summary_table(board: Board, rows: list[Row], table_id: str, ranked: bool) -> str:
    suite = board.suite
    head = ['<th data-type="num" title="overall rank (see the ranking rule)">Rank</th>' if ranked else "",
            '<th data-type="text">Controller</th>']
    if not ranked:
        head.append('<th data-type="text">Setting</th>')
    else:
        head.append('<th data-type="num" title="stated env-step budget of the shipped weights (checkpoint manifest)">'
                    'Training<br><span class="sub">env steps</span></th>')
    for t in suite.terrains:
        name = TERRAIN_TITLES.get(t, t)
        head.append(f'<th data-type="num" title="hardest level with success rate &gt;= 80%">{_e(name)}<br>'
                    '<span class="sub">hardest passed</span></th>')
        head.append(f'<th data-type="num" title="area under the success-vs-level curve (paper levels)">{_e(name)}<br>'
                    '<span class="sub">AUC</span></th>')
    if ranked:
        head += ['<th data-type="num">Speed<br><span class="sub">m/s</span></th>',
                 '<th data-type="num">Roll RMS<br><span class="sub">deg</span></th>',
                 '<th data-type="num">Pitch RMS<br><span class="sub">deg</span></th>',
                 '<th data-type="num">Episodes</th>']
    body = []
    for r in rows:
        cells = []
        if ranked:
            rank = board.overall_ranks[r.label]
            cells.append(f'<td class="num rank"{_sort_attr(float(rank))}>{rank}</td>')
            cells.append(f'<td class="name"{_sort_attr(r.label)}><span class="swatch" style="background:'
                         f'{measured_color(board, r.label)}"></span>{_e(r.label)}'
                         f'<span class="mode">{_e(r.details.get("action_mode", ""))}</span></td>')
            training = board.training.get(r.label)
            budget = max(training.budgets) if training is not None and training.known and training.budgets else -1.0
            cells.append(f'<td class="num"{_sort_attr(float(budget))}>{_e(fmt_budget(training))}</td>')
        else:
            cells.append(f'<td class="name"{_sort_attr(r.label)}>{_e(r.label)}<span class="badge">paper</span></td>')
            cells.append(f'<td{_sort_attr(r.setting)}>{_e(r.setting)}</td>')
        for t in suite.terrains:
            s = r.terrain(t)
            if s is None:
                cells += ['<td class="num na">–</td>', '<td class="num na">–</td>']
                continue
            hardest, auc = s["hardest_level_passed"], s["auc"]
            cells.append(f'<td class="num"{_sort_attr(-1.0 if hardest is None else float(hardest))}>'
                         f'{_e(fmt_level(hardest, s["unit"]))}</td>')
            cells.append(f'<td class="num"{_sort_attr(-1.0 if auc is None else float(auc))}>{fmt_num(auc)}</td>')
        if ranked:
            m = overall_metrics(r)
            for key, digits in (("mean_forward_speed_m_per_s", 3), ("mean_roll_rms_deg", 1),
                                ("mean_pitch_rms_deg", 1)):
                v = m[key]
                cells.append(f'<td class="num"{_sort_attr(-1.0 if v is None else float(v))}>{fmt_num(v, digits)}</td>')
            cells.append(f'<td class="num"{_sort_attr(float(m["episodes"]))}>{m["episodes"]}</td>')
        row_class = "measured" if ranked else "reported"
        body.append(f'<tr class="{row_class}" data-label="{_e(r.label)}">' + "".join(cells) + "</tr>")
    return (f'<table id="{table_id}" class="sortable"><thead><tr>{"".join(head)}</tr></thead>\n<tbody>\n'
            + "\n".join(body) + "\n</tbody></table>")


def _heat(rate: float) -> str:
    """Cell background: pale red (0%) to pale green (100%)."""
    hue = 8 + 112 * rate
    return f"hsl({hue:.0f}, 60%, 92%)"


def _html_level_table(board: Board, terrain: str) -> str:
    suite = board.suite
    levels = suite.levels(terrain)
    paper_levels = set(suite.levels(terrain, include_headroom=False))
    unit = suite.task(terrain, levels[0]).unit
    head = [f'<th class="corner">level [{_e(unit)}]</th>']
    head += [f'<th class="num{"" if v in paper_levels else " headroom"}">{format_level(v)}</th>' for v in levels]
    body = []
    for r in (*board.measured, *(r for r in board.reported if r.setting == "simulation" and r.terrain(terrain))):
        measured = r.kind == "measured"
        name = (f'<span class="swatch" style="background:{measured_color(board, r.label)}"></span>{_e(r.label)}'
                if measured else f'{_e(r.label)}<span class="badge">paper</span>')
        cells = [f'<th class="rowname">{name}</th>']
        for v in levels:
            lv = r.level(terrain, v)
            cls = "num" + ("" if v in paper_levels else " headroom")
            if lv is None:
                cells.append(f'<td class="{cls} na">–</td>')
                continue
            ci = (f'<span class="ci">{100 * lv["ci95_low"]:.0f}–{100 * lv["ci95_high"]:.0f}</span>'
                  if measured else "")
            title = (f'{lv["successes"]}/{lv["episodes"]} episodes; 95% Wilson interval '
                     f'{100 * lv["ci95_low"]:.0f}–{100 * lv["ci95_high"]:.0f}%' if measured
                     else f'reported by the paper ({r.details["table"]}), not run here')
            cells.append(f'<td class="{cls}" style="background:{_heat(lv["success_rate"])}" title="{_e(title)}">'
                         f'{pct(lv["success_rate"])}{ci}</td>')
        body.append(f'<tr class="{"measured" if measured else "reported"}">' + "".join(cells) + "</tr>")
    return ('<table class="levels"><thead><tr>' + "".join(head) + "</tr></thead>\n<tbody>\n" + "\n".join(body)
            + "\n</tbody></table>")


def _html_real_robot(board: Board) -> str:
    parts = []
    for r in (r for r in board.reported if r.setting == "real robot"):
        for t in r.terrains:
            lvs = [lv for lv in r.levels if lv["terrain"] == t["terrain"]]
            head = [f'<th class="corner">{_e(TERRAIN_TITLES.get(t["terrain"], t["terrain"]))} [{_e(t["unit"])}]</th>']
            head += [f'<th class="num">{format_level(lv["level"])}</th>' for lv in lvs]
            cells = [f'<th class="rowname">{_e(r.label)}<span class="badge">paper</span></th>']
            cells += [f'<td class="num" style="background:{_heat(lv["success_rate"])}">{pct(lv["success_rate"])}</td>'
                      for lv in lvs]
            parts.append('<table class="levels"><thead><tr>' + "".join(head) + '</tr></thead><tbody><tr class="reported">'
                         + "".join(cells) + "</tr></tbody></table>")
    return "\n".join(parts)


def _asset(name: str) -> str:
    return (ASSETS_DIR / name).read_text()


def generator_tag() -> str:
    """Names the plotting library version: SVG bytes are reproducible for one matplotlib version."""
    import matplotlib

    return f"hexbench leaderboard build; matplotlib {matplotlib.__version__}"


def render_html(board: Board) -> str:
    suite = board.suite
    title = f"hexbench leaderboard: protocol {board.protocol}"
    out = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
           '<meta name="viewport" content="width=device-width, initial-scale=1">',
           f'<meta name="generator" content="{_e(generator_tag())}">', f"<title>{_e(title)}</title>",
           "<style>", _raw_text(_asset("style.css").strip()), "</style>", "</head>", "<body>", "<main>"]
    out.append(f'<header><h1>hexbench leaderboard <span class="proto">protocol {_e(board.protocol)}</span></h1>'
               f'<p class="lead">Hexapod locomotion on rough terrain, slopes and stairs: success over 20 seeded '
               f'episodes per difficulty level. {len(board.measured)} measured '
               f'{"entry" if len(board.measured) == 1 else "entries"}; the paper\'s own numbers are drawn as a '
               f'reference, <strong>{REPORTED_NOTE}</strong>. Click a column header to sort.</p></header>')
    out.append('<section id="ranking"><h2>Ranking</h2>')
    if board.measured:
        out.append(_html_summary_table(board, list(board.measured), "leaderboard", ranked=True))
    else:
        out.append('<p class="empty">No measured records yet.</p>'
                   '<table id="leaderboard" class="sortable"><thead><tr><th>Controller</th></tr></thead>'
                   "<tbody></tbody></table>")
    out.append(f'<p class="rule"><strong>Ranking rule.</strong> {_e(RANKING_RULE)}</p></section>')
    if board.reported:
        out.append(f'<section id="paper-reference" class="reference"><h2>Paper reference <span class="note">'
                   f'{REPORTED_NOTE}</span></h2>')
        out.append(_html_summary_table(board, list(board.reported), "paper", ranked=False))
        for citation, note in board.reported_notes:
            out.append(f'<p class="cite">{_e(citation)}</p><p class="cite">{_e(note)}</p>')
        out.append("</section>")
    for terrain in suite.terrains:
        out.append(f'<section class="terrain" id="terrain-{_e(terrain)}"><h2>{_e(TERRAIN_TITLES.get(terrain, terrain))}'
                   "</h2>")
        out.append(f'<figure class="plot" data-terrain="{_e(terrain)}">{plot_svg(board, terrain).strip()}'
                   f"<figcaption>Success rate vs {_e(TERRAIN_AXES.get(terrain, 'level'))}. Solid lines: measured here "
                   "(whiskers: 95% Wilson interval). Dashed grey/black lines: the paper's Table 4 (and Table 6, real "
                   f"robot), {REPORTED_NOTE}. The tinted band holds the headroom levels beyond the paper."
                   "</figcaption></figure>")
        out.append(_html_level_table(board, terrain))
        out.append("</section>")
    if any(r.setting == "real robot" for r in board.reported):
        out.append(f'<section id="real-robot" class="reference"><h2>Real robot <span class="note">{REPORTED_NOTE}'
                   "</span></h2>")
        out.append(_html_real_robot(board))
        out.append("</section>")
    if board.measured:
        out.append('<section id="records"><h2>Records</h2><table class="records"><thead><tr><th>Controller</th>'
                   "<th>Trust</th><th>Record</th><th>Controller file</th><th>sha256</th><th>git commit</th><th>Episodes</th>"
                   "<th>Wall time</th><th>Command</th></tr></thead><tbody>")
        for r in board.measured:
            d = r.details
            out.append(f"<tr><td>{_e(r.label)}</td><td>{_e(fmt_trust(r))}</td><td>{_e(r.source)}</td><td><code>{_e(d['controller_file'])}</code>"
                       f"</td><td><code title=\"{_e(d['controller_sha256'])}\">{_e(d['controller_sha256'][:12])}</code>"
                       f"</td><td><code>{_e(str(d['git_commit'])[:12])}</code></td><td>{d['episodes']}</td>"
                       f"<td>{d['wall_time_s']:.0f} s</td><td><code>{_e(d['command'])}</code></td></tr>")
        out.append("</tbody></table></section>")
    out.append('<footer>Generated by <code>hexbench leaderboard build</code> from the records in this folder '
               "(never edited by hand). Success: the base advances 2.5 m along +x without falling and without "
               "straying more than 0.8 m sideways. Summaries are recomputed from each record's per-episode rows. "
               "Every number is also in <code>leaderboard.csv</code>.</footer>")
    out += ["</main>", "<script>", _raw_text(_asset("sortable.js").strip()), "</script>", "</body>", "</html>"]
    return "\n".join(out) + "\n"


# ---------------------------------------------------------------------------------- writing
def _atomic_write_all(files: dict[Path, str]) -> None:
    """Write every file to a temporary name first, then rename them all (no partial outputs)."""
    tmps = []
    try:
        for path, text in files.items():
            tmp = path.with_name(f".{path.name}.tmp")
            with open(tmp, "w", encoding="utf-8", newline="\n") as f:
                f.write(text)
            tmps.append((tmp, path))
    except BaseException:
        for tmp, _ in tmps:
            tmp.unlink(missing_ok=True)
        raise
    for tmp, path in tmps:
        os.replace(tmp, path)


def render_all(board: Board) -> dict[str, str]:
    return {"README.md": render_readme(board), "index.html": render_html(board),
            "leaderboard.csv": render_csv(board)}


@dataclass
class BuildResult:
    written: list[Path]
    board: Board
    errors: list[str]
    skipped: list[str]


# ------------------------------------------------------------------------- extra courses
COURSES_DIR = "courses"  # records of the extra courses (the mixed course), scored apart


def is_course_record(record: dict) -> bool:
    """A measured record whose episodes all lie on extra courses (not the full run)."""
    try:
        suite = load_suite(record["protocol"])
        terrains = {e["terrain"] for e in record["episodes"]}
    except (KeyError, TypeError, ValueError):
        return False
    return bool(terrains) and terrains <= set(suite.extra_terrains)


def load_course_rows(directory: Path, protocol: str = DEFAULT_PROTOCOL) -> LoadResult:
    result = LoadResult([], [], [])
    for path in record_files(directory):
        try:
            record = read_record(path)
            if record.get("protocol") != protocol:
                result.skipped.append(f"{path}: protocol {record.get('protocol')!r}, not {protocol!r}")
                continue
            result.rows.append(measured_row(record, str(path), course=True))
        except RecordError as e:
            result.errors.append(str(e))
    return result


def render_courses_readme(rows: list[Row], suite: Suite) -> str:
    out = [f"# hexbench extra courses: protocol {suite.protocol}\n",
           "Generated by `hexbench leaderboard build` from the result records in this folder (records of "
           "`hexbench run FILE --terrain mixed`); do not edit by hand. These courses are outside the full "
           "run and are not ranked with it. Success rate per level with the 95% Wilson interval; 20 seeded "
           "episodes per level.\n"]
    for terrain in suite.extra_terrains:
        levels = suite.levels(terrain)
        course_rows = sorted((r for r in rows if r.terrain(terrain)), key=lambda r: r.label)
        out.append(f"## {terrain}\n")
        if terrain == "mixed":
            from hexbench.world.terrain import MIXED_COURSE_LEVELS

            out.append("Rough ground, then a slope, then four stairs in one episode; goal 6.3 m ahead "
                       "(docs/protocol.md). Levels: " + "; ".join(
                           f"{k}: rough {r:g} cm, slope {sl:g} deg, stairs {st:g} cm"
                           for k, (r, sl, st) in MIXED_COURSE_LEVELS.items()) + ".\n")
        if not course_rows:
            out.append("No records yet.\n")
            continue
        header = ["Controller"] + [f"level {format_level(v)}" for v in levels] + [
            "Mean speed [m/s]", "Episodes", "Trust", "Record", "Controller file", "git commit"]
        table = [[_md(r.label)] + [_md_cell(r.level(terrain, v), True) for v in levels] + [
            fmt_num(r.terrain(terrain)["mean_forward_speed_m_per_s"], 3), str(r.details["episodes"]), fmt_trust(r),
            _md(r.source),
            _md(r.details["controller_file"]), _md(str(r.details["git_commit"])[:12])] for r in course_rows]
        out.append(_md_table(header, table) + "\n")
        out.append("Commands:\n")
        for r in course_rows:
            out.append(f"- {_md(r.label, block=True)}: {_md_code(r.details['command'])}")
        out.append("")
    return "\n".join(out)


def build(directory: str | Path = "leaderboard", protocol: str = DEFAULT_PROTOCOL,
          root: str | Path | None = None) -> BuildResult:
    """Read every record under `directory`, write README.md, index.html and leaderboard.csv there.

    Records' checkpoint paths resolve against `root` (default: the directory's parent, the repository)
    to show each controller's training budget from the checkpoint manifest.

    Refused records are left out and reported in `errors` (the caller decides the exit status);
    the three files are rendered completely before any is written.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise RecordError(f"{directory}: no such leaderboard directory")
    load_suite(protocol)  # ValueError naming the valid protocols
    load = load_rows(directory, protocol)
    board = make_board(load, protocol, directory.resolve().parent if root is None else Path(root))
    texts = render_all(board)
    files = {directory / name: texts[name] for name in GENERATED_FILES}
    errors, skipped = list(load.errors), list(load.skipped)
    courses = directory / COURSES_DIR
    if courses.is_dir():
        course_load = load_course_rows(courses, protocol)
        errors += course_load.errors
        skipped += course_load.skipped
        files[courses / "README.md"] = render_courses_readme(course_load.rows, board.suite)
    _atomic_write_all(files)
    return BuildResult(list(files), board, errors, skipped)


def slug(label: str) -> str:
    s = re.sub(r"[^a-z0-9]+", "_", label.lower()).strip("_")
    return s or "record"


def _admission_source(source: Path) -> tuple[Path, Path | None]:
    """(record path, run folder or None) of what `leaderboard add` was given."""
    if source.is_dir():
        return source / "result.json", source
    if source.name == "result.json" and (source.parent / "episodes").is_dir():
        return source, source.parent
    return source, None


def admit(record: dict, run_dir: Path | None, where: str, *, sample: int | None = None, workers: int = 1,
          seed_set=None, rng=None, progress: bool = False) -> dict:
    """Replay a measured run before it joins; return the record with its admission block. RecordError if refused."""
    from hexbench.artifacts.provenance import HEXBENCH_VERSION, git_commit
    from hexbench.replay.verify import verify_run

    if run_dir is None:
        raise RecordError(f"{where}: a measured record joins only with its run folder (its action logs), e.g. "
                          f"`hexbench leaderboard add runs/NAME`; a record alone cannot be replayed")
    isolation = record["provenance"].get("isolation") or {}
    if not isolation.get("sandboxed"):
        raise RecordError(f"{where}: was not made in a sandbox (isolation {isolation.get('mode', 'unknown')!r}); "
                          f"re-run it with `hexbench run` (bubblewrap or process isolation)")
    keyed = record["provenance"].get("seed_set", {}).get("kind") == "keyed"
    if keyed and (seed_set is None or seed_set.key is None):
        raise RecordError(f"{where}: has a keyed seed set; admission needs the key (--seed-key FILE) to check its seeds")
    report = verify_run(run_dir, sample=sample, rng=rng, workers=workers, seed_set=seed_set, progress=progress)
    if not report.ok:
        raise RecordError(f"refused: {report.message}")
    admitted = {k: v for k, v in record.items() if k != "admission"}
    admitted["admission"] = {"verified_by": "replay of action logs", "episodes_replayed": report.episodes_replayed,
                             "episodes_total": report.episodes_total, "episodes_digest": record["episodes_digest"],
                             "hexbench_version": HEXBENCH_VERSION, "git_commit": git_commit()}
    return admitted


def add(result_path: str | Path, directory: str | Path = "leaderboard", replace: bool = False,
        protocol: str = DEFAULT_PROTOCOL, *, sample: int | None = None, workers: int = 1, seed_set=None,
        progress: bool = False) -> Path:
    """Validate a record, replay its run (measured records), and copy it into `directory` as
    <slug(label)>.json; RecordError if refused."""
    result_path, run_dir = _admission_source(Path(result_path))
    directory = Path(directory)
    record = read_record(result_path)
    if is_course_record(record):  # extra courses are scored apart, in their own folder
        rows = [measured_row(record, str(result_path), course=True)]
        if not directory.is_dir():
            raise RecordError(f"{directory}: no such leaderboard directory")
        directory = directory / COURSES_DIR
        directory.mkdir(exist_ok=True)
    else:
        rows = rows_of(record, str(result_path))
    if record["protocol"] != protocol:
        raise RecordError(f"{result_path}: record is protocol {record['protocol']}, this leaderboard shows {protocol} "
                          "(records of different protocols are never mixed; pass --protocol to choose)")
    if not directory.is_dir():
        raise RecordError(f"{directory}: no such leaderboard directory")
    name = "paper_reference.json" if record["kind"] == "reported" else f"{slug(record['label'])}.json"
    dest = directory / name
    if name in GENERATED_FILES:
        raise RecordError(f"{result_path}: label {record['label']!r} would overwrite a generated file")
    new_labels = {r.label for r in rows}
    for path in record_files(directory):
        if path.resolve() == dest.resolve():
            continue
        try:
            other = read_record(path)
        except RecordError:
            continue
        other_labels = ({s["label"] for s in other.get("reported", {}).get("series", [])}
                        if other.get("kind") == "reported" else {other.get("label")})
        clash = sorted(new_labels & other_labels)
        if clash and other.get("protocol") == record["protocol"]:
            raise RecordError(f"{result_path}: label {clash[0]!r} is already used by {path}; choose another label")
    if dest.exists() and dest.resolve() != result_path.resolve() and not replace:
        raise RecordError(f"{dest} already exists; pass --replace to overwrite it")
    if record["kind"] == "measured":
        record = admit(record, run_dir, str(result_path), sample=sample, workers=workers, seed_set=seed_set,
                       progress=progress)
        if dest.exists():
            _refuse_downgrade(dest, record, str(result_path))
    if dest.resolve() != result_path.resolve():
        _atomic_write_all({dest: json.dumps(record, indent=1) + "\n"})
    return dest


def _refuse_downgrade(dest: Path, record: dict, where: str) -> None:
    """--replace never puts a less proven record in place of a more proven one."""
    try:
        old = read_record(dest)
        old_tier = record_tier(old, str(dest)) if old.get("kind") == "measured" else TIER_SELF_REPORTED
    except RecordError:
        return
    new_tier = record_tier(record, where)
    if TIER_ORDER[new_tier] < TIER_ORDER[old_tier]:
        raise RecordError(f"{where}: is {new_tier}, {dest} is {old_tier}; --replace never puts a less proven record "
                          f"in its place")
    old_share = (old.get("admission") or {}).get("episodes_replayed", 0) / max(1, len(old.get("episodes", [])))
    new_share = record["admission"]["episodes_replayed"] / max(1, len(record["episodes"]))
    if new_tier == old_tier and new_share < old_share:
        raise RecordError(f"{where}: replayed {new_share:.0%} of its episodes, {dest} {old_share:.0%}; --replace never "
                          f"puts a less proven record in its place (admit it with fewer --sample or none)")
