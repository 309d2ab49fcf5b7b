"""`hexbench leaderboard add`: a record joins the leaderboard folder, a measured one only after its run replays.

A measured record comes with its run folder; `admit` replays its episodes from their action logs
(hexbench.replay.verify, all of them or a sample) and adds the admission block that binds the
record's rows, by their digest, to that replay. `--replace` overwrites a record of the same name,
never with a less proven one (a lower trust tier, or the same tier with a smaller share replayed).
Labels are unique across the folder; extra-course records go to `courses/`, records of paper Table 5's
tasks (some slopes and stairs levels) to `courses/table5/`. `add_seed_run` admits a
seed run's record (baselines/seeds/<method>-<terrain>-seed<S>/result-<terrain>.json) the same way.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from hexbench.artifacts.provenance import HEXBENCH_VERSION, git_commit
from hexbench.leaderboard.courses import (
    COURSES_DIR,
    TABLE5_DIR,
    is_course_record,
    is_table5_record,
    table5_file_name,
    table5_row,
    table5_tasks_text,
)
from hexbench.leaderboard.generate import GENERATED_FILES, write_all_atomically
from hexbench.leaderboard.records import (
    TIER_ORDER,
    TIER_SELF_REPORTED,
    EpisodeClaims,
    MissingEpisodesError,
    RecordError,
    Row,
    episodes_rerun,
    measured_row,
    read_record,
    record_files,
    record_tier,
    rows_of,
)
from hexbench.replay.rerun import rerun_episodes
from hexbench.replay.verify import verify_run
from hexbench.suite.tasks import DEFAULT_PROTOCOL


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
          seed_set=None, rng=None, progress: bool = False, rerun_controller: str | Path | None = None) -> dict:
    """Replay a measured run before it joins; return the record with its admission block. RecordError if refused.
    With `rerun_controller` (the file the record names), the replayed episodes are also played again
    with it in the sandbox, and every action must be the recorded one (`hexbench.replay.rerun`)."""
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
    # With a re-run, its evaluator plays every chosen episode and must find the recorded action log
    # and row: that replays them, so the replay here checks all but the physics.
    report = verify_run(run_dir, sample=sample, rng=rng, workers=workers, seed_set=seed_set, progress=progress,
                        replay=rerun_controller is None)
    if not report.ok:
        raise RecordError(f"refused: {report.message}")
    admitted = {k: v for k, v in record.items() if k != "admission"}
    admitted["admission"] = {"verified_by": "replay of action logs", "episodes_replayed": report.episodes_replayed,
                             "episodes_total": report.episodes_total, "episodes_digest": record["episodes_digest"],
                             "hexbench_version": HEXBENCH_VERSION, "git_commit": git_commit()}
    if rerun_controller is not None:
        rerun = rerun_episodes(run_dir, record, list(report.episodes), rerun_controller, workers=workers,
                               progress=progress)
        if not rerun.ok:
            raise RecordError(f"refused: {rerun.message}")
        admitted["admission"]["episodes_replayed"] = rerun.episodes_rerun
        admitted["admission"]["controller_rerun"] = {"episodes": rerun.episodes_rerun, "isolation": rerun.isolation,
                                                     "with_run_secret": rerun.with_run_secret}
    return admitted


def _board_records(board: Path, dest: Path, protocol: str) -> dict[Path, list[tuple[Path, dict]]]:
    """Per folder of the board (main table, courses, Table 5), (path, record) of every readable record
    of `protocol` other than `dest`: read once for all the checks of one admission."""
    found: dict[Path, list[tuple[Path, dict]]] = {}
    for folder in (board, board / COURSES_DIR, board / COURSES_DIR / TABLE5_DIR):
        found[folder] = []
        if not folder.is_dir():
            continue
        for path in record_files(folder):
            if path.resolve() == dest.resolve():
                continue
            try:
                other = read_record(path)
            except RecordError:
                continue
            if other.get("protocol") == protocol:
                found[folder].append((path, other))
    return found


def _check_labels_are_free(rows: list[Row], others: list[tuple[Path, dict]], where: Path) -> None:
    """RecordError if another record of the same protocol in the folder (`others`) already uses one of the labels."""
    new_labels = {r.label for r in rows}
    for path, other in others:
        other_labels = ({s["label"] for s in other.get("reported", {}).get("series", [])}
                        if other.get("kind") == "reported" else {other.get("label")})
        clash = sorted(new_labels & other_labels)
        if clash:
            raise RecordError(f"{where}: label {clash[0]!r} is already used by {path}; choose another label")


def _check_episodes_are_new(record: dict, board_records: dict[Path, list[tuple[Path, dict]]], where: str) -> None:
    """RecordError if one of the record's episodes is already on the board (main table, courses,
    Table 5) under another label: the same action log (EpisodeClaims)."""
    claims = EpisodeClaims()
    for others in board_records.values():
        for path, other in others:
            try:
                claims.claim(other, str(path))
            except RecordError:  # a clash already on the board is `leaderboard build`'s to report
                continue
    claims.claim(record, where)


def _check_table5_terrains_are_free(row: Row, record: dict, others: list[tuple[Path, dict]], where: Path) -> None:
    """On Table 5's page a label appears once per terrain: RecordError if another record of the same
    label and protocol in the folder (`others`) covers one of this record's terrains."""
    terrains = {t["terrain"] for t in row.terrains}
    for path, other in others:
        clash = sorted(terrains & {e.get("terrain") for e in other.get("episodes", [])})
        if other.get("label") == record["label"] and clash:
            raise RecordError(f"{where}: {record['label']!r} on {clash[0]} is already recorded by {path}; "
                              f"pass --replace with a record of the same terrains, or choose another label")


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
    old_rerun, new_rerun = episodes_rerun(old.get("admission") or {}), episodes_rerun(record["admission"])
    if new_tier == old_tier and new_rerun < old_rerun:
        raise RecordError(f"{where}: its controller was re-run on {new_rerun} episodes, {dest}'s on {old_rerun}; "
                          f"--replace never puts a less proven record in its place (admit it with --rerun)")


def add(result_path: str | Path, directory: str | Path = "leaderboard", replace: bool = False,
        protocol: str = DEFAULT_PROTOCOL, *, sample: int | None = None, workers: int = 1, seed_set=None,
        progress: bool = False, rerun_controller: str | Path | None = None) -> Path:
    """Validate a record, replay its run (measured records; with `rerun_controller`, re-run its
    controller on the replayed episodes too), and copy it into `directory` as <slug(label)>.json;
    RecordError if refused."""
    result_path, run_dir = _admission_source(Path(result_path))
    directory = board = Path(directory)
    record = read_record(result_path)
    table5 = is_table5_record(record)
    if is_course_record(record) or table5:  # extra courses and Table 5 are scored apart, in folders of their own
        if not directory.is_dir():
            raise RecordError(f"{directory}: no such leaderboard directory")
        if table5:
            rows = [table5_row(record, str(result_path))]
            directory = directory / COURSES_DIR / TABLE5_DIR
        else:
            rows = [measured_row(record, str(result_path), course=True)]
            directory = directory / COURSES_DIR
        directory.mkdir(parents=True, exist_ok=True)
    else:
        try:
            rows = rows_of(record, str(result_path))
        except MissingEpisodesError as e:
            raise RecordError(f"{e}; a record of some levels joins only on paper Table 5's tasks "
                              f"({table5_tasks_text()})") from None
    if record["protocol"] != protocol:
        raise RecordError(f"{result_path}: record is protocol {record['protocol']}, this leaderboard shows {protocol} "
                          "(records of different protocols are never mixed; pass --protocol to choose)")
    if not directory.is_dir():
        raise RecordError(f"{directory}: no such leaderboard directory")
    if table5:
        name = table5_file_name(slug(record["label"]), rows[0])
        dest = directory / name
        board_records = _board_records(board, dest, protocol)
        _check_table5_terrains_are_free(rows[0], record, board_records[directory], result_path)
    else:
        name = "paper_reference.json" if record["kind"] == "reported" else f"{slug(record['label'])}.json"
        dest = directory / name
        if name in GENERATED_FILES:
            raise RecordError(f"{result_path}: label {record['label']!r} would overwrite a generated file")
        board_records = _board_records(board, dest, protocol)
        _check_labels_are_free(rows, board_records[directory], result_path)
    if dest.exists() and dest.resolve() != result_path.resolve() and not replace:
        raise RecordError(f"{dest} already exists; pass --replace to overwrite it")
    _check_episodes_are_new(record, board_records, str(result_path))
    if rerun_controller is not None and record["kind"] != "measured":
        raise RecordError(f"{result_path}: --rerun re-runs a measured record's controller; this record is {record['kind']}")
    if record["kind"] == "measured":
        record = admit(record, run_dir, str(result_path), sample=sample, workers=workers, seed_set=seed_set,
                       progress=progress, rerun_controller=rerun_controller)
        if dest.exists():
            _refuse_downgrade(dest, record, str(result_path))
    if dest.resolve() != result_path.resolve():
        write_all_atomically({dest: json.dumps(record, indent=1) + "\n"})
    return dest


def add_seed_run(run_dir: str | Path, folder: str | Path, protocol: str = DEFAULT_PROTOCOL, *,
                 sample: int | None = None, workers: int = 1, progress: bool = False) -> Path:
    """Replay the run in `run_dir` and write its record, with the admission block, as the seed-run
    folder's result-<terrain>.json (a record already there must be this run's: the same episodes
    digest); RecordError if refused, and then nothing is written."""
    from hexbench.leaderboard.seeds import seed_run_of, seed_run_terrain

    run_dir, folder = Path(run_dir), Path(folder)
    dest = folder / f"result-{seed_run_terrain(folder)}.json"
    record_path = run_dir / "result.json"
    record = read_record(record_path)
    if record["protocol"] != protocol:
        raise RecordError(f"{record_path}: record is protocol {record['protocol']}, not {protocol}")
    if dest.exists() and read_record(dest).get("episodes_digest") != record.get("episodes_digest"):
        raise RecordError(f"{record_path}: its episodes are not those of {dest} (the episodes digests differ); "
                          f"admit the run that made that record")
    seed_run_of(folder, record, str(record_path))  # the folder's method, terrain and checkpoint, before replaying
    record = admit(record, run_dir, str(record_path), sample=sample, workers=workers, progress=progress)
    if dest.exists():
        _refuse_downgrade(dest, record, str(record_path))
    write_all_atomically({dest: json.dumps(record, indent=1) + "\n"})
    return dest
