"""Result records as the leaderboard reads them: validation, trust tiers, and one `Row` per controller.

Records (hexbench/artifacts/schemas/result.schema.json) come in two kinds, validated on separate paths:

  measured   produced by `hexbench run`. Accepted only if it is schema-valid, its protocol is known,
             every seed of every level of that protocol is present exactly once (seeds as
             hexbench.suite.tasks.episode_seed derives them), its provenance is filled, and its
             `levels`/`terrains` summaries agree with the ones recomputed from its episode rows
             (hexbench.replay.verify.summaries_from_rows, the check `hexbench verify` makes too). The
             leaderboard always shows the recomputed summaries, never the stored ones.
  reported   numbers transcribed from a publication (leaderboard/paper_reference.json: the paper's
             Table 4 and Table 6), "reported by the paper, not run here". No episodes; each series
             is one reported controller with per-level success rates.

A measured record's trust tier says how far it is proven: self-reported, sandboxed + replayed (its
admission block, bound to its rows by their digest), or + hidden seeds (a keyed seed set whose key
its controller process could not read: `key_was_hidden`).
Records are read in file-name order; records of another protocol are skipped, not mixed in.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from hexbench.artifacts.records import RESULT_SCHEMA, episodes_digest, read_record_json
from hexbench.errors import HexbenchError, InputError
from hexbench.replay.verify import same_up_to_round_off, summaries_from_rows, summary_disagreement
from hexbench.suite import scoring
from hexbench.suite.tasks import DEFAULT_PROTOCOL, Suite, format_level, load_suite

SCHEMA_PATH = RESULT_SCHEMA
SETTINGS = ("simulation", "real robot")

TIER_SELF_REPORTED = "self-reported"
TIER_REPLAYED = "sandboxed + replayed"
TIER_HIDDEN = "sandboxed + replayed + hidden seeds"
TIER_ORDER = {TIER_SELF_REPORTED: 0, TIER_REPLAYED: 1, TIER_HIDDEN: 2}


class RecordError(HexbenchError, ValueError):
    """A record was refused; the message is one line naming the file and the problem."""


class MissingEpisodesError(RecordError):
    """A record lacks episodes its protocol has (a record of some levels only)."""


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


@dataclass
class LoadResult:
    rows: list[Row]
    errors: list[str]  # one line per refused record
    skipped: list[str]  # one line per record of another protocol


class EpisodeClaims:
    """Which label shows each episode already, by the sha256 of its action log: the episodes of one
    run join the leaderboard under one label.

    A log's header names its episode (task, index, seed) and holds every action, so two records
    share a log only if the same actions played the same episode: one run, or one controller's
    behaviour, shown twice. Replay proves the episodes, not which code made them; this stops a
    copy of someone's run folder (or of a committed record with its admission block) from joining
    under another name. Records of the same label may share episodes (a Table 5 record and the
    main table's record of one controller)."""

    def __init__(self):
        self.owner: dict[str, tuple[str, str]] = {}  # action-log sha256 -> (label, where)

    def claim(self, record: dict, where: str) -> None:
        """Take the episodes of a measured record; RecordError (nothing taken) if one of them is
        already shown under another label."""
        if record.get("kind") != "measured":
            return
        label = record.get("label")
        logs = [row.get("action_log_sha256") for row in record.get("episodes", [])]
        logs = [sha for sha in logs if isinstance(sha, str)]
        for sha in logs:
            other = self.owner.get(sha)
            if other is not None and other[0] != label:
                shared = sum(self.owner.get(s, ("", ""))[0] == other[0] for s in logs)
                raise RecordError(f"{where}: {shared} of its episodes are those of {other[1]} (label {other[0]!r}): the "
                                  f"same action logs; a run joins the leaderboard under one label")
        for sha in logs:
            self.owner.setdefault(sha, (label, where))


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


def _unexpected_episode(ep: dict, name: str, suite: Suite, tasks: tuple, where: str) -> RecordError:
    """The refusal of an episode on a terrain or level that `tasks` do not hold."""
    scored = tuple(dict.fromkeys(t.terrain for t in tasks))
    if ep["terrain"] not in scored:
        why = ("is an extra course, scored apart (leaderboard/courses/)" if ep["terrain"] in suite.all_terrains
               else f"is not in protocol {suite.protocol}")
        return RecordError(f"{where}: {name}: terrain {ep['terrain']!r} {why}; valid terrains: {', '.join(scored)}")
    valid = ", ".join(format_level(v) for v in suite.levels(ep["terrain"]))
    return RecordError(f"{where}: {name}: level {format_level(ep['level'])} is not a {ep['terrain']} level of "
                       f"protocol {suite.protocol}; valid levels: {valid}")


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
            raise _unexpected_episode(ep, name, suite, tasks, where)
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
        raise MissingEpisodesError(f"{where}: missing episode {terrain} {level} index {i} (seed {s}){more}; "
                                   f"every seed of every level of protocol {suite.protocol} must be present")


def record_tier(record: dict, where: str) -> str:
    """How far a measured record is proven. Replayed tiers need the admission block that
    `hexbench leaderboard add RUN_DIR` writes after replaying the run, bound to the record's rows by
    their digest; a record made in-process (--isolation none) is refused outright."""
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
    return TIER_HIDDEN if keyed and key_was_hidden(isolation) else TIER_REPLAYED


def episodes_rerun(admission: dict) -> int:
    """How many episodes admission played again with the named controller (0: none)."""
    rerun = admission.get("controller_rerun")
    episodes = rerun.get("episodes") if isinstance(rerun, dict) else None
    return episodes if isinstance(episodes, int) and not isinstance(episodes, bool) and episodes > 0 else 0


def key_was_hidden(isolation: dict) -> bool:
    """Whether the controller process of a keyed run could not read the key: bubblewrap covers it
    up; under process isolation Landlock keeps the controller to its own folders, and without it
    only `nobody` is kept from a key (a key the controller could read is refused at run time,
    hexbench.evaluation.isolation.seed_key_problem). A controller that ran as the evaluating user
    or as root without Landlock could have read it, so its record ranks as public seeds do."""
    if isolation.get("mode") == "bubblewrap":
        return True
    return isolation.get("mode") == "process" and (isolation.get("user") == "nobody"
                                                   or bool(isolation.get("landlock_abi")))


# ---------------------------------------------------------------------------------- rows
def _measured_details(record: dict, tier: str) -> dict:
    prov, ctrl = record["provenance"], record["controller"]
    return {
        "controller_file": ctrl["file"], "controller_sha256": ctrl["sha256"], "action_mode": ctrl["action_mode"],
        "checkpoints": [c["sha256"] for c in ctrl.get("checkpoints", [])],
        "checkpoint_files": [(c["path"], c["sha256"]) for c in ctrl.get("checkpoints", [])], "git_commit": prov["git_commit"],
        "command": prov["command"], "hexbench_version": prov["hexbench_version"], "started_at": prov["started_at"],
        "wall_time_s": prov["wall_time_s"], "workers": prov["workers"], "episodes": len(record["episodes"]),
        "tier": tier, "admission": record.get("admission"),
    }


def measured_row(record: dict, where: str, course: bool = False, terrains_covered: bool = False,
                 levels_covered: bool = False) -> Row:
    """Validate a measured record (see module docstring) and return its row; RecordError if refused.

    course=True validates a record of the extra courses (every seed of every level of the courses
    it covers) instead of the full run; terrains_covered=True a record of some of the full run's
    terrains (every seed of every level of each terrain it covers: a seed run's
    `hexbench run FILE --terrain T` record, hexbench.leaderboard.seeds); levels_covered=True a record
    of some levels of the full run (every seed of each level it covers: paper Table 5's tasks).
    """
    check_schema(record, where)
    if record["kind"] != "measured":
        raise RecordError(f"{where}: kind is {record['kind']!r}; expected 'measured'")
    suite = _suite_for(record, where)
    _check_provenance(record, where)
    if course:
        covered = {e["terrain"] for e in record["episodes"]}
        tasks = tuple(t for t in suite.extra_tasks if t.terrain in covered) or suite.extra_tasks
    elif levels_covered:
        covered = {(e["terrain"], format_level(e["level"])) for e in record["episodes"]}
        tasks = tuple(t for t in suite.tasks if (t.terrain, format_level(t.level)) in covered) or suite.tasks
    elif terrains_covered:
        covered = {e["terrain"] for e in record["episodes"]}
        tasks = tuple(t for t in suite.tasks if t.terrain in covered) or suite.tasks
    else:
        tasks = suite.tasks
    tier = record_tier(record, where)
    # a keyed seed set's seeds are checked against the key at admission; a self-reported one's cannot be
    keyed = tier != TIER_SELF_REPORTED and record["provenance"].get("seed_set", {}).get("kind") == "keyed"
    _check_episodes(record, suite, where, tasks, keyed=keyed)
    units = {t.terrain: t.unit for t in tasks}
    headroom = {(t.terrain, t.level): t.headroom for t in tasks}
    # Episode levels are normalised to the suite's float so the headroom lookup cannot miss.
    suite_level = {(t.terrain, format_level(t.level)): t.level for t in tasks}
    episodes = [{**e, "level": suite_level[(e["terrain"], format_level(e["level"]))]} for e in record["episodes"]]
    levels, terrains = summaries_from_rows(episodes, units, headroom)
    problem = summary_disagreement(record, levels, terrains)
    if problem:
        raise RecordError(f"{where}: {problem}")
    return Row(label=record["label"], kind="measured", setting="simulation", source=Path(where).name,
               levels=tuple(levels), terrains=tuple(terrains), details=_measured_details(record, tier))


def _reported_level(lv: dict, suite: Suite, seen: set, name: str, where: str) -> dict:
    """One reported level checked against the protocol and the series' levels `seen` before it, as a
    level summary (Wilson interval from its counts)."""
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
    if k > n or not same_up_to_round_off(lv["success_rate"], k / n):
        raise RecordError(f"{where}: {name}: {terrain} {format_level(level)}: success_rate "
                          f"{lv['success_rate']:g} is not successes/episodes = {k}/{n}")
    lo, hi = scoring.wilson_interval(k, n)
    return {
        "terrain": terrain, "level": task.level, "unit": task.unit, "headroom": task.headroom,
        "episodes": n, "successes": k, "success_rate": k / n, "ci95_low": lo, "ci95_high": hi, "seeds": [],
        "mean_forward_speed_m_per_s": None, "mean_time_to_goal_s": None, "mean_max_abs_y_m": None,
        "mean_roll_rms_deg": None, "mean_pitch_rms_deg": None, "mean_cost_of_transport": None,
    }


def _reported_row(record: dict, series: dict, name: str, suite: Suite, where: str) -> Row:
    seen: set[tuple[str, str]] = set()
    levels = [_reported_level(lv, suite, seen, name, where) for lv in series["levels"]]
    levels.sort(key=lambda r: (r["terrain"], r["level"]))
    terrains = scoring.summarize_terrains(levels)
    for t in terrains:  # an AUC over some of the paper levels is not comparable; keep it only if complete
        covered = {format_level(r["level"]) for r in levels if r["terrain"] == t["terrain"] and not r["headroom"]}
        if covered != {format_level(v) for v in suite.levels(t["terrain"], include_headroom=False)}:
            t["auc"] = None
        t["headroom_auc"] = None
    details = {"method": series["method"], "table": series["table"], "action_mode": series.get("action_mode", ""),
               "citation": record["reported"]["citation"], "note": record["reported"]["note"]}
    return Row(label=series["label"], kind="reported", setting=series["setting"], source=Path(where).name,
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
        rows.append(_reported_row(record, series, name, suite, where))
    return rows


# ------------------------------------------------------------------------------- reading
def read_record(path: Path) -> dict:
    try:
        record = read_record_json(path)
    except InputError as e:
        raise RecordError(str(e)) from None
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


def load_rows(directory: Path, protocol: str = DEFAULT_PROTOCOL, claims: EpisodeClaims | None = None) -> LoadResult:
    """Every record under `directory` of `protocol`: rows of the valid ones, a line per refused one
    (`claims`: the episodes already shown, shared with the other pages' loaders)."""
    result = LoadResult([], [], [])
    claims = EpisodeClaims() if claims is None else claims
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
            claims.claim(record, where)
        except RecordError as e:
            result.errors.append(str(e))
            continue
        for row in rows:
            labels[row.label] = path.name
        result.rows.extend(rows)
    return result
