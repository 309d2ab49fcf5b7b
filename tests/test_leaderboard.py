"""Leaderboard: validation and refusal of records, Wilson maths, ranking, deterministic build, CLI."""

from __future__ import annotations

import csv
import io
import json
import re
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from hexbench import leaderboard as lb
from hexbench import scoring
from hexbench.cli import app
from hexbench.tasks import load_suite
from leaderboard_records import demo_records, mutated, synthetic_record

REPO = Path(__file__).resolve().parent.parent
PAPER_REFERENCE = REPO / "leaderboard" / "paper_reference.json"


@pytest.fixture(scope="module")
def records() -> list[dict]:
    return demo_records()


@pytest.fixture()
def board_dir(tmp_path: Path, records: list[dict]) -> Path:
    d = tmp_path / "board"
    d.mkdir()
    for r in records:
        (d / f"{r['label']}.json").write_text(json.dumps(r))
    shutil.copy(PAPER_REFERENCE, d / "paper_reference.json")
    return d


# ------------------------------------------------------------------------------ Wilson maths
@pytest.mark.parametrize("k, n, low, high", [
    (0, 20, 0.0, 0.16113), (20, 20, 0.83887, 1.0), (10, 20, 0.29930, 0.70070), (15, 20, 0.53129, 0.88813),
    (1, 1, 0.20655, 1.0),
])
def test_wilson_interval_matches_published_values(k, n, low, high):
    lo, hi = scoring.wilson_interval(k, n)
    assert lo == pytest.approx(low, abs=5e-5) and hi == pytest.approx(high, abs=5e-5)


def test_leaderboard_level_intervals_are_wilson_of_the_episode_counts(records):
    row = lb.measured_row(records[1], "middling.json")
    for lv in row.levels:
        assert (lv["ci95_low"], lv["ci95_high"]) == scoring.wilson_interval(lv["successes"], lv["episodes"])
        assert lv["ci95_low"] <= lv["success_rate"] <= lv["ci95_high"]


# -------------------------------------------------------------------------- measured records
def test_measured_record_is_accepted_and_summaries_are_recomputed(records):
    record = records[0]
    row = lb.measured_row(record, "strong.json")
    suite = load_suite("v1")
    assert len(row.levels) == len(suite.tasks)
    assert list(row.levels) == record["levels"] and list(row.terrains) == record["terrains"]
    assert row.details["episodes"] == 20 * len(suite.tasks)


def _drop_first_episode(r):
    r["episodes"].pop(0)


def _wrong_seed(r):
    r["episodes"][3]["seed"] += 1


def _duplicate_episode(r):
    r["episodes"][5] = dict(r["episodes"][4])


def _level_rate_off(r):
    r["levels"][2]["success_rate"] = 0.5 if r["levels"][2]["success_rate"] != 0.5 else 0.55


def _terrain_auc_off(r):
    r["terrains"][1]["auc"] = 0.123


def _success_flag_disagrees(r):
    r["episodes"][0]["end_reason"] = "fall"


def _unknown_protocol(r):
    r["protocol"] = "v9"


def _empty_commit(r):
    r["provenance"]["git_commit"] = " "


def _no_machine(r):
    r["provenance"]["machine"] = {}


def _no_controller_sha(r):
    r["controller"]["sha256"] = ""


def _no_episodes_key(r):
    del r["episodes"]


def _foreign_level(r):
    r["episodes"][0]["level"] = 3.5


def _foreign_terrain(r):
    r["episodes"][0]["terrain"] = "ice"


@pytest.mark.parametrize("change, message", [
    (_drop_first_episode, r"missing episode rough 3 index 0 \(seed \d+\); every seed of every level"),
    (_wrong_seed, r"seed \d+ is not the protocol seed \d+"),
    (_duplicate_episode, r"duplicate of episodes\[4\]"),
    (_level_rate_off, r"summary disagrees with its episodes: level rough 5 success_rate is 0\.5+ in the record but "),
    (_terrain_auc_off, r"summary disagrees with its episodes: terrain slopes auc is 0\.123 in the record but"),
    (_success_flag_disagrees, r"success is true but end_reason is 'fall'"),
    (_unknown_protocol, r"unknown protocol 'v9'; valid protocols: v1"),
    (_empty_commit, r"provenance\.git_commit is empty"),
    (_no_machine, r"provenance\.machine is empty"),
    (_no_controller_sha, r"controller\.sha256 is empty"),
    (_no_episodes_key, r"not a valid result record at \(top level\): 'episodes' is a required property"),
    (_foreign_level, r"level 3\.5 is not a rough level of protocol v1; valid levels: 3, 4, 5"),
    (_foreign_terrain, r"terrain 'ice' is not in protocol v1; valid terrains: rough, slopes, stairs"),
])
def test_bad_measured_records_are_refused_with_one_clear_line(records, change, message):
    bad = mutated(records[0], change)
    with pytest.raises(lb.RecordError) as info:
        lb.rows_of(bad, "bad.json")
    text = str(info.value)
    assert "\n" not in text and text.startswith("bad.json: ")
    assert re.search(message, text), text


def test_record_with_fewer_episodes_than_the_protocol_is_refused():
    short = synthetic_record("short", {"rough": 8, "slopes": 10, "stairs": 5}, seed=7, episodes=5)
    with pytest.raises(lb.RecordError, match=r"missing episode rough 3 index 5 .* and \d+ more"):
        lb.rows_of(short, "short.json")


# -------------------------------------------------------------------------- reported records
def test_paper_reference_holds_table_4_and_table_6():
    record = json.loads(PAPER_REFERENCE.read_text())
    assert record["kind"] == "reported" and record["episodes"] == []
    assert lb.REPORTED_NOTE in record["label"] and lb.REPORTED_NOTE in record["reported"]["note"].lower()
    rows = {r.label: r for r in lb.rows_of(record, "paper_reference.json")}
    assert set(rows) == {"CPG (paper)", "HRL (paper)", "PPO-CPG, the paper's method (paper)",
                         "PPO-CPG on the real robot (paper)"}
    cpg, hrl, ours, real = (rows[k] for k in sorted(rows, key=list(rows).index))
    assert cpg.level("rough", 8)["success_rate"] == 0.75 and cpg.level("stairs", 6)["success_rate"] == 0.35
    assert hrl.level("slopes", 13)["success_rate"] == 0.35 and hrl.level("rough", 12)["success_rate"] == 0.2
    assert ours.level("stairs", 8)["success_rate"] == 0.65 and ours.level("slopes", 15)["success_rate"] == 1.0
    assert real.setting == "real robot" and real.level("slopes", 16)["success_rate"] == 0.8
    assert real.level("stairs", 7.5)["success_rate"] == 0.65 and real.terrain("rough") is None
    # every simulated series covers exactly the Table 4 levels
    suite = load_suite("v1")
    for row in (cpg, hrl, ours):
        for t in suite.terrains:
            assert [lv["level"] for lv in row.levels if lv["terrain"] == t] == suite.levels(t, include_headroom=False)
    assert ours.terrain("stairs")["hardest_level_passed"] == 7.5 and cpg.terrain("rough")["hardest_level_passed"] == 7


@pytest.mark.parametrize("change, message", [
    (lambda r: r["reported"]["series"][0]["levels"][0].update(success_rate=0.5), r"is not successes/episodes = 20/20"),
    (lambda r: r["reported"]["series"][0]["levels"][0].update(level=2.5), r"unknown rough level 2\.5; valid levels"),
    (lambda r: r["reported"]["series"][0]["levels"][0].update(unit="mm"), r"rough unit is 'mm'; protocol v1 uses 'cm'"),
    (lambda r: r["episodes"].append({}), r"not a valid result record at episodes"),
    (lambda r: r.pop("reported"), r"'reported' is a required property"),
    (lambda r: r["reported"]["series"][1].update(label="CPG (paper)"), r"duplicate series label"),
])
def test_bad_reported_records_are_refused(change, message):
    bad = mutated(json.loads(PAPER_REFERENCE.read_text()), change)
    with pytest.raises(lb.RecordError, match=message):
        lb.rows_of(bad, "paper.json")


# ----------------------------------------------------------------------------------- ranking
def _row(label: str, terrains: dict[str, tuple[float | None, float | None]]) -> lb.Row:
    summaries = tuple({"terrain": t, "unit": "cm", "hardest_level_passed": h, "auc": a, "headroom_auc": None,
                       "episodes": 20, "successes": 0, "mean_forward_speed_m_per_s": None}
                      for t, (h, a) in terrains.items())
    return lb.Row(label=label, kind="measured", setting="simulation", source=f"{label}.json", levels=(),
                  terrains=summaries)


def test_terrain_rank_is_hardest_level_then_auc_with_shared_ranks():
    rows = [_row("a", {"rough": (8.0, 0.70)}), _row("b", {"rough": (10.0, 0.60)}), _row("c", {"rough": (8.0, 0.75)}),
            _row("d", {"rough": (None, 0.30)}), _row("e", {"rough": (8.0, 0.70)})]
    assert lb.rank_terrain(rows, "rough") == {"b": 1, "c": 2, "a": 3, "e": 3, "d": 5}


def test_overall_rank_is_mean_terrain_rank_then_mean_auc():
    rows = [_row("x", {"rough": (10.0, 0.9), "stairs": (5.0, 0.5)}),   # ranks 1, 3 -> 2.0
            _row("y", {"rough": (9.0, 0.8), "stairs": (6.0, 0.55)}),   # ranks 2, 2 -> 2.0, lowest mean AUC
            _row("z", {"rough": (8.0, 0.7), "stairs": (7.0, 0.9)})]    # ranks 3, 1 -> 2.0, highest mean AUC
    ordered, per_terrain, overall = lb.rank_overall(rows, ("rough", "stairs"))
    assert [r.label for r in ordered] == ["z", "x", "y"]
    assert overall == {"z": 1, "x": 2, "y": 3}
    assert per_terrain["stairs"] == {"z": 1, "y": 2, "x": 3}


def test_build_ranks_demo_controllers_and_keeps_the_paper_apart(board_dir):
    result = lb.build(board_dir)
    board = result.board
    assert result.errors == [] and [r.label for r in board.measured] == ["strong", "middling", "weak"]
    assert [board.overall_ranks[r.label] for r in board.measured] == [1, 2, 3]
    assert {r.kind for r in board.reported} == {"reported"} and len(board.reported) == 4
    assert all(r.label not in board.overall_ranks for r in board.reported)
    table = list(csv.DictReader(io.StringIO((board_dir / "leaderboard.csv").read_text())))
    assert list(table[0])[:6] == ["kind", "setting", "controller", "record", "overall_rank", "terrain_rank"]
    reported_csv = [row for row in table if row["kind"] == "reported"]
    assert len(reported_csv) == 3 * 30 + 12 and all(row["overall_rank"] == "" for row in reported_csv)
    assert {row["overall_rank"] for row in table if row["controller"] == "strong"} == {"1"}
    readme = (board_dir / "README.md").read_text()
    assert "| 1 | strong |" in readme and "CPG (paper): reported, not run here | 100% |" in readme


def test_training_budget_comes_from_the_manifest_entry_with_the_checkpoint_sha256(tmp_path, records):
    strong, middling, weak = records
    root, board = tmp_path / "repo", tmp_path / "repo" / "leaderboard"
    (root / "weights").mkdir(parents=True)
    board.mkdir()
    (root / "weights" / "manifest.json").write_text(json.dumps({"checkpoints": {
        "a-rough": {"sha256": "a" * 64, "env_step_budget": 1_000_000, "env_steps": 180_502},
        "a-slopes": {"sha256": "b" * 64, "env_step_budget": 1_000_000, "env_steps": 827_393}}}))
    trained = mutated(strong, lambda r: r["controller"].update(checkpoints=[
        {"path": "weights/a-rough.zip", "sha256": "a" * 64}, {"path": "weights/a-slopes.zip", "sha256": "b" * 64}]))
    retrained = mutated(weak, lambda r: r["controller"].update(checkpoints=[
        {"path": "weights/a-rough.zip", "sha256": "c" * 64}]))  # weights changed since the record
    for r in (trained, middling, retrained):
        (board / f"{r['label']}.json").write_text(json.dumps(r))
    lb.build(board)
    table = list(csv.DictReader(io.StringIO((board / "leaderboard.csv").read_text())))
    by_label = {row["controller"]: row for row in table}
    assert (by_label["strong"]["training_env_step_budget"], by_label["strong"]["checkpoint_env_steps"]) == (
        "1000000", "180502;827393")
    assert (by_label["middling"]["training_env_step_budget"], by_label["weak"]["training_env_step_budget"]) == (
        "", "")
    readme = (board / "README.md").read_text()
    assert "| 1 | strong | 1M |" in readme and "| middling | none |" in readme and "| weak | ? |" in readme
    assert "181k–827k" in readme


# ------------------------------------------------------------------------------ determinism
def test_building_twice_gives_byte_identical_files(board_dir, tmp_path):
    lb.build(board_dir)
    first = {name: (board_dir / name).read_bytes() for name in lb.GENERATED_FILES}
    other = tmp_path / "copy"
    other.mkdir()
    for p in sorted(board_dir.glob("*.json"), reverse=True):  # different write order, same records
        shutil.copy(p, other / p.name)
    lb.build(board_dir)
    lb.build(other)
    for name in lb.GENERATED_FILES:
        assert (board_dir / name).read_bytes() == first[name], name
        assert (other / name).read_bytes() == first[name], name
    page = first["index.html"].decode()
    assert "<dc:date>" not in page and not re.search(r"20\d\d-\d\d-\d\dT\d\d:\d\d", page)


def test_index_html_is_self_contained(board_dir):
    lb.build(board_dir)
    page = (board_dir / "index.html").read_text()
    assert page.count("<svg") == 3 and page.count("<table") >= 5
    assert not re.search(r"<(link|img|iframe)\b", page)
    assert not re.search(r"\b(src|href)\s*=\s*[\"']?(https?:)?//", page)
    assert "<script src" not in page and "@import" not in page and "url(http" not in page
    assert lb.REPORTED_NOTE in page


def test_other_protocol_records_are_skipped_not_mixed(board_dir, records):
    other = mutated(records[2], lambda r: r.update(protocol="v0", label="old"))
    (board_dir / "old.json").write_text(json.dumps(other))
    result = lb.build(board_dir)
    assert result.errors == [] and len(result.skipped) == 1 and "not mixed into the v1 leaderboard" in result.skipped[0]
    assert "old" not in {r.label for r in result.board.measured}


def test_build_refuses_a_bad_record_but_shows_the_good_ones(board_dir, records):
    (board_dir / "broken.json").write_text(json.dumps(mutated(records[2], _drop_first_episode) | {"label": "broken"}))
    (board_dir / "notjson.json").write_text("{nope")
    result = lb.build(board_dir)
    assert len(result.errors) == 2 and "broken.json: missing episode" in result.errors[0]
    assert "notjson.json: not JSON" in result.errors[1]
    assert [r.label for r in result.board.measured] == ["strong", "middling", "weak"]


# ----------------------------------------------------------------------------------------- CLI
def test_cli_add_validates_copies_and_rebuilds(tmp_path, records):
    board = tmp_path / "lb"
    board.mkdir()
    shutil.copy(PAPER_REFERENCE, board / "paper_reference.json")
    src = tmp_path / "result.json"
    src.write_text(json.dumps(records[1]))
    runner = CliRunner()
    res = runner.invoke(app, ["leaderboard", "add", str(src), "--dir", str(board)])
    assert res.exit_code == 0, res.output
    assert (board / "middling.json").exists() and all((board / n).exists() for n in lb.GENERATED_FILES)
    again = runner.invoke(app, ["leaderboard", "add", str(src), "--dir", str(board)])
    assert again.exit_code == 1 and "already exists; pass --replace" in again.output
    assert runner.invoke(app, ["leaderboard", "add", str(src), "--dir", str(board), "--replace"]).exit_code == 0


def test_cli_add_refuses_a_bad_record_and_writes_nothing(tmp_path, records):
    board = tmp_path / "lb"
    board.mkdir()
    src = tmp_path / "result.json"
    src.write_text(json.dumps(mutated(records[0], _level_rate_off)))
    res = CliRunner().invoke(app, ["leaderboard", "add", str(src), "--dir", str(board)])
    assert res.exit_code == 1
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert len(lines) == 1 and "summary disagrees with its episodes" in lines[0]
    assert list(board.iterdir()) == []


def test_cli_build_bad_dir_and_protocol_give_one_line(tmp_path):
    runner = CliRunner()
    res = runner.invoke(app, ["leaderboard", "build", "--dir", str(tmp_path / "nowhere")])
    assert res.exit_code == 1 and "no such leaderboard directory" in res.output
    res = runner.invoke(app, ["leaderboard", "build", "--dir", str(tmp_path), "--protocol", "v7"])
    assert res.exit_code == 1 and "unknown protocol 'v7'; valid protocols: v1" in res.output
    assert list(tmp_path.iterdir()) == []


def test_committed_leaderboard_is_what_build_produces(tmp_path):
    """The generated files in leaderboard/ must be reproducible byte for byte from its records."""
    committed = REPO / "leaderboard"
    if not all((committed / n).exists() for n in lb.GENERATED_FILES):
        pytest.skip("leaderboard/ has not been generated yet (run `hexbench leaderboard build`)")
    copy = tmp_path / "lb"
    copy.mkdir()
    for p in lb.record_files(committed):
        shutil.copy(p, copy / p.name)
    lb.build(copy, root=REPO)  # checkpoint paths in the records resolve against the repository
    names = list(lb.GENERATED_FILES)
    if f'content="{lb.generator_tag()}"' not in (committed / "index.html").read_text():
        names.remove("index.html")  # plots drawn by another matplotlib version: SVG bytes legitimately differ
    for name in names:
        assert (copy / name).read_bytes() == (committed / name).read_bytes(), f"leaderboard/{name} is stale"


def test_extra_course_records_are_scored_apart_in_their_own_table(tmp_path):
    board = tmp_path / "board"
    board.mkdir()
    for label, capability, seed in (("hlta", 2.6, 7), ("ppo_cpg", 1.4, 8)):
        path = tmp_path / f"{label}.json"
        path.write_text(json.dumps(synthetic_record(label, {"mixed": capability}, seed, courses=True)))
        assert lb.add(path, board) == board / "courses" / f"{label}.json"
    result = lb.build(board)
    assert not result.errors
    text = (board / "courses" / "README.md").read_text()
    assert "| hlta |" in text and "| ppo_cpg |" in text and "level 3" in text
    assert len(result.board.measured) == 0  # not mixed into the full-run ranking
    # a course record missing an episode is refused like any other
    broken = synthetic_record("broken", {"mixed": 2.0}, 9, courses=True)
    broken["episodes"].pop()
    (board / "courses" / "broken.json").write_text(json.dumps(broken))
    assert any("missing episode mixed" in e for e in lb.build(board).errors)
    # and mixed episodes inside a full-run record are refused with the reason
    full = synthetic_record("full", {"rough": 9, "slopes": 11, "stairs": 6}, 10)
    full["episodes"].append(dict(broken["episodes"][0]))
    with pytest.raises(lb.RecordError, match="'mixed' is an extra course, scored apart"):
        lb.measured_row(full, "full.json")
