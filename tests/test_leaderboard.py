"""Leaderboard: validation and refusal of records, Wilson maths, ranking, deterministic build, CLI."""

from __future__ import annotations

import csv
import io
import json
import re
import shutil
from pathlib import Path

import pytest
from leaderboard_records import PAPER_REFERENCE, demo_records, mutated, resummarize, synthetic_record, write_board
from typer.testing import CliRunner

from hexbench import leaderboard as lb
from hexbench.cli import app
from hexbench.leaderboard.markdown import md_code, md_table, md_text
from hexbench.leaderboard.records import TIER_HIDDEN, TIER_SELF_REPORTED
from hexbench.suite import scoring
from hexbench.suite.tasks import load_suite

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def records() -> list[dict]:
    return demo_records()


@pytest.fixture()
def board_dir(tmp_path: Path, records: list[dict]) -> Path:
    return write_board(tmp_path / "board", records)


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


def _level_field_missing(r):
    del r["levels"][0]["mean_cost_of_transport"]


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
    (_level_field_missing, r"summary disagrees with its episodes: level rough 3 mean_cost_of_transport is missing "),
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
    assert "| 1 | strong | self-reported | 1M |" in readme and "| middling | self-reported | none |" in readme \
        and "| weak | self-reported | ? |" in readme
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
    assert "notjson.json: not valid JSON" in result.errors[1]
    assert [r.label for r in result.board.measured] == ["strong", "middling", "weak"]


# ----------------------------------------------------------------------------------------- CLI
def test_cli_add_refuses_a_record_without_its_run_folder(tmp_path, records):
    board = tmp_path / "lb"
    board.mkdir()
    src = tmp_path / "result.json"
    src.write_text(json.dumps(records[1]))  # self-consistent, but invented: no action logs to replay
    res = CliRunner().invoke(app, ["leaderboard", "add", str(src), "--dir", str(board)])
    assert res.exit_code == 1 and "joins only with its run folder" in res.output
    assert list(board.iterdir()) == []


def test_cli_add_replays_a_run_copies_it_with_its_admission_and_rebuilds(tmp_path, tiny_protocol):
    from hexbench.evaluation.evaluate import evaluate
    from hexbench.suite.tasks import load_suite

    run = tmp_path / "run"
    res = evaluate(str(REPO / "baselines" / "cpg.py"), list(load_suite("v1").tasks), run, workers=1, record=False,
                   progress=False)
    assert res.error is None
    board = tmp_path / "lb"
    board.mkdir()
    runner = CliRunner()
    added = runner.invoke(app, ["leaderboard", "add", str(run), "--dir", str(board), "--workers", "1"])
    assert added.exit_code == 0, added.output
    entry = json.loads((board / "cpg.json").read_text())
    assert entry["admission"]["episodes_replayed"] == entry["admission"]["episodes_total"] == 6
    assert lb.record_tier(entry, "cpg.json") == lb.TIER_REPLAYED
    assert all((board / n).exists() for n in lb.GENERATED_FILES)
    again = runner.invoke(app, ["leaderboard", "add", str(run), "--dir", str(board), "--workers", "1"])
    assert again.exit_code == 1 and "already exists; pass --replace" in again.output
    sampled = runner.invoke(app, ["leaderboard", "add", str(run), "--dir", str(board), "--replace", "--sample", "2",
                                  "--workers", "1"])
    assert sampled.exit_code == 1 and "never puts a less proven record" in sampled.output
    assert runner.invoke(app, ["leaderboard", "add", str(run), "--dir", str(board), "--replace",
                               "--workers", "1"]).exit_code == 0

    # the same run folder under another label: its episodes are already on the board
    copied = tmp_path / "copied"
    shutil.copytree(run, copied)
    relabelled = json.loads((copied / "result.json").read_text())
    relabelled["label"] = "Mine"
    relabelled["controller"]["sha256"] = "0" * 64
    (copied / "result.json").write_text(json.dumps(relabelled))
    taken = runner.invoke(app, ["leaderboard", "add", str(copied), "--dir", str(board), "--workers", "1"])
    lines = [ln for ln in taken.output.splitlines() if ln.strip()]
    assert taken.exit_code == 1 and len(lines) == 1, taken.output
    assert "6 of its episodes are those of" in lines[0] and "cpg.json" in lines[0] and "'cpg'" in lines[0]
    assert not (board / "mine.json").exists()

    # a row edited after admission (summaries and digest recomputed too) no longer matches its admission
    forged = json.loads((board / "cpg.json").read_text())
    forged["episodes"][0]["success"] = True
    forged["episodes"][0]["end_reason"] = "success"
    with pytest.raises(lb.RecordError, match="changed after admission"):
        lb.record_tier(forged, "forged.json")


@pytest.mark.parametrize("isolation, tier", [
    ({"mode": "bubblewrap", "sandboxed": True}, TIER_HIDDEN),
    ({"mode": "process", "sandboxed": True, "user": "nobody"}, TIER_HIDDEN),
    ({"mode": "process", "sandboxed": True, "user": "the evaluating user"}, lb.TIER_REPLAYED),
    ({"mode": "process", "sandboxed": True, "user": "the evaluating user", "landlock_abi": 7}, TIER_HIDDEN),
    ({"mode": "process", "sandboxed": True, "user": "root without capabilities (the Python environment is "
                                                    "not readable by nobody)"}, lb.TIER_REPLAYED),
])
def test_hidden_seeds_rank_as_hidden_only_where_the_controller_could_not_read_the_key(isolation, tier):
    from hexbench.artifacts.records import episodes_digest

    digest = episodes_digest([])
    record = {"provenance": {"isolation": isolation, "seed_set": {"kind": "keyed", "key_fingerprint": "0" * 16}},
              "admission": {"episodes_digest": digest}, "episodes_digest": digest, "episodes": []}
    assert lb.record_tier(record, "keyed.json") == tier
    record["provenance"]["seed_set"] = {"kind": "public"}
    assert lb.record_tier(record, "public.json") == lb.TIER_REPLAYED


def test_add_refuses_a_forged_run_and_one_made_in_process(tmp_path, tiny_protocol):
    from hexbench.evaluation.evaluate import evaluate
    from hexbench.suite.tasks import load_suite

    tasks = list(load_suite("v1").tasks)
    run = tmp_path / "run"
    assert evaluate(str(REPO / "baselines" / "cpg.py"), tasks, run, workers=1, record=False, progress=False).error is None
    board = tmp_path / "lb"
    board.mkdir()
    record = json.loads((run / "result.json").read_text())
    # self-consistent forgery: a success flipped, summaries and digest recomputed from the rows
    record["episodes"][0].update(success=True, end_reason="success", time_to_goal_s=0.5)
    resummarize(record)
    (run / "result.json").write_text(json.dumps(record))
    with pytest.raises(lb.RecordError, match="success: recorded True, replayed False"):
        lb.add(run, board)
    debug = tmp_path / "debug"
    assert evaluate(str(REPO / "baselines" / "cpg.py"), tasks, debug, workers=1, record=False, progress=False,
                    isolation="none").error is None
    with pytest.raises(lb.RecordError, match="isolation none"):
        lb.add(debug, board)
    assert list(board.iterdir()) == []


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


def test_build_refuses_a_committed_record_copied_under_another_label(tmp_path):
    """A committed record copied with its admission block and relabelled proves the same episodes
    as the original: build shows them once, under the first label, and names the copy."""
    board = tmp_path / "leaderboard"
    board.mkdir()
    original = json.loads((REPO / "leaderboard" / "cpg.json").read_text())
    (board / "cpg.json").write_text(json.dumps(original))
    copy = dict(original, label="Not CPG")
    (board / "not_cpg.json").write_text(json.dumps(copy))
    result = lb.build(board, root=REPO)
    assert len(result.errors) == 1 and "not_cpg.json" in result.errors[0]
    assert "860 of its episodes are those of" in result.errors[0] and "'cpg'" in result.errors[0]
    assert [row.label for row in result.board.measured] == ["cpg"]


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
    (board / "courses").mkdir(parents=True)
    for label, capability, seed in (("hlta", 2.6, 7), ("ppo_cpg", 1.4, 8)):
        path = board / "courses" / f"{label}.json"
        path.write_text(json.dumps(synthetic_record(label, {"mixed": capability}, seed, courses=True)))
        lb.measured_row(json.loads(path.read_text()), str(path), course=True)  # valid as a course record
        with pytest.raises(lb.RecordError, match="joins only with its run folder"):
            lb.add(path, tmp_path / "board")
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


# ------------------------------------------------------------------ hostile strings in records
# Every string of a record comes from its submitter; the outputs must show it as literal text.
HOSTILE = ('=HYPERLINK("http://x")<img src=x onerror=alert(1)></script><script>alert(1)</script> a|b '
           '[x](javascript:alert(1)) *em* _u_ `c` ~~s~~ $x^2$ &lt; \\| <!-- --> & id="text_1" href="#text_1" '
           'url(#text_1)\r\nnext line')
HOSTILE_FILE = "=1+1 <img src=x onerror=alert(1)> a|b.json"  # becomes the `record`/`Record` column
HOSTILE_COMMAND = "hexbench run `x` ``y`` | tee </script><script>alert(1)</script>\n<img src=x onerror=alert(1)>"
CODE_COMMAND = "hexbench run `x` ``y`` | tee a_b *c* [d](javascript:e) \\| &amp; $f$"  # no `<`: a code span


def _one_line(text: str) -> str:
    """What a one-line output (a Markdown cell) shows for `text`: control characters as spaces."""
    return re.sub(r"[\x00-\x1f\x7f-\x9f]", " ", text)


def _hostile_measured(label: str = HOSTILE, seed: int = 4, **kwargs) -> dict:
    record = synthetic_record("hostile", kwargs.pop("capability", {"rough": 8.0, "slopes": 10.0, "stairs": 5.0}),
                              seed, **kwargs)
    record["label"] = label
    record["controller"].update(file="@SUM(1+1)*cmd|' /C calc'!A0 <img src=x onerror=alert(1)>.py",
                                action_mode="</span><img src=x onerror=alert(1)>",
                                checkpoints=[{"path": "<img src=x>/[a](javascript:1).zip", "sha256": "d" * 64}])
    record["provenance"].update(command=HOSTILE_COMMAND, git_commit="<img src=x>|`*_[",
                                machine={"hostname": "<script>alert(1)</script>"})
    return record


def _hostile_reported() -> dict:
    record = json.loads(PAPER_REFERENCE.read_text())
    series = record["reported"]["series"]
    series[0]["label"] = "-" + HOSTILE + " (paper)"
    series[0]["table"] = '"><img src=x onerror=alert(1)>'
    real = next(s for s in series if s["setting"] == "real robot")
    real["label"] = "+a|b <img src=x onerror=alert(1)> (paper)"
    record["reported"]["citation"] = "# " + HOSTILE
    record["reported"]["note"] = "1. <img src=x onerror=alert(1)>\n- [x](javascript:alert(1))"
    return record


@pytest.fixture()
def hostile_dir(board_dir: Path) -> Path:
    """board_dir with two records of hostile strings added and a hostile paper reference, built."""
    (board_dir / HOSTILE_FILE).write_text(json.dumps(_hostile_measured()))
    code = _hostile_measured("a|b `c`", seed=5)
    code["provenance"]["command"] = CODE_COMMAND
    (board_dir / "code.json").write_text(json.dumps(code))
    (board_dir / "paper_reference.json").write_text(json.dumps(_hostile_reported()))
    result = lb.build(board_dir)
    assert result.errors == [] and HOSTILE in {r.label for r in result.board.measured}
    assert "-" + HOSTILE + " (paper)" in {r.label for r in result.board.reported}
    return board_dir


def _md_table_lines(text: str) -> list[list[str]]:
    """Each Markdown table of `text` as its lines."""
    tables, current = [], []
    for line in text.splitlines() + [""]:
        if line.startswith("|"):
            current.append(line)
        elif current:
            tables.append(current)
            current = []
    return tables


def _unescaped_pipes(line: str) -> int:
    return len(re.findall(r"(?<!\\)\|", line))  # GFM: every `\|` stays in its cell


def _parse_html(text: str):
    """(tags with their attributes, data of each element by tag name) of an HTML text."""
    from html.parser import HTMLParser

    class Parser(HTMLParser):
        def __init__(self):
            super().__init__(convert_charrefs=True)
            self.tags, self.stack, self.data = [], [], {}

        def handle_starttag(self, tag, attrs):
            self.tags.append((tag, dict(attrs)))
            if tag not in ("br", "meta", "img", "hr", "input", "link"):  # void elements hold no data
                self.stack.append(tag)

        def handle_startendtag(self, tag, attrs):
            self.tags.append((tag, dict(attrs)))

        def handle_endtag(self, tag):
            if tag in self.stack:
                while self.stack.pop() != tag:
                    pass

        def handle_data(self, data):
            if self.stack:
                self.data.setdefault(self.stack[-1], []).append(data)

    parser = Parser()
    parser.feed(text)
    parser.close()
    return parser.tags, parser.data


def test_markdown_escaping_leaves_plain_strings_alone_and_defuses_the_rest():
    for plain in ("ppo_cpg", "PPO-CPG (paper)", "PPO-CPG, the paper's method (paper)", "cpg_residual",
                  "baselines/checkpoints/terrain_classifier.pt", "66598280c7e8", "Table 4"):
        assert md_text(plain) == plain and md_text(plain, block=True) == plain
    assert md_text("<img src=x> a&b") == "&lt;img src=x&gt; a&amp;b"
    assert md_text("[x](javascript:alert(1)) *a* _b_ `c` ~d~ $e$ \\") == (
        "\\[x\\](javascript:alert(1)) \\*a\\* \\_b\\_ \\`c\\` \\~d\\~ \\$e\\$ \\\\")
    assert md_text("a\nb\r\tc\x00") == "a b  c "
    assert md_text("# h", block=True) == "\\# h" and md_text("1. x", block=True) == "1\\. x"
    assert md_text("- x", block=True) == "\\- x" and md_text("- x") == "- x"
    assert md_code("hexbench run a_b.py") == "`hexbench run a_b.py`"
    assert md_code("a ``b`` c") == "```a ``b`` c```" and md_code("`a`") == "`` `a` ``"
    assert md_code("a <b>\nc") == "a &lt;b&gt; c"  # no raw tag in the file, not even in a code span
    assert md_table(["h|x"], [["a|b"]]) == "| h\\|x |\n| --- |\n| a\\|b |"


def test_hostile_record_strings_render_as_literal_text_in_readme(hostile_dir):
    markdown_it = pytest.importorskip("markdown_it")
    readme = (hostile_dir / "README.md").read_text()
    assert "<" not in readme  # no raw tag at all (`<` from a record is written as &lt;)
    for table in _md_table_lines(readme):  # no string adds a cell: every line has the header's pipes
        assert {_unescaped_pipes(line) for line in table} == {_unescaped_pipes(table[0])}, table[0]
    # rendered like GitHub (CommonMark + tables + strikethrough, inline HTML passed through)
    page = markdown_it.MarkdownIt("commonmark", {"html": True}).enable(["table", "strikethrough"]).render(readme)
    tags, data = _parse_html(page)
    names = [t for t, _ in tags]
    assert not {"img", "script", "a", "em", "s", "del", "ol", "hr"} & set(names), sorted(set(names))
    assert names.count("strong") == readme.count("**") // 2  # the page's own bold terms only
    assert names.count("h1") == 1 and "h1" not in [t for t, _ in tags[1:]]
    cells = {c.strip() for c in data.get("td", []) + data.get("th", [])}
    assert _one_line(HOSTILE) in cells  # the label is shown as exactly its text
    assert _one_line("-" + HOSTILE + " (paper)") + ": reported, not run here" in cells
    assert "+a|b <img src=x onerror=alert(1)> (paper): Stairs [cm]" in cells
    assert _one_line(HOSTILE_FILE) in cells and "<img src=x>|" in cells and _one_line(HOSTILE_COMMAND) in cells
    assert CODE_COMMAND in data["code"] and "a|b `c`" in cells  # a code span with a ``` fence, in a table
    paragraphs = {p.strip() for p in data.get("p", [])}
    assert _one_line("# " + HOSTILE) in paragraphs
    assert "1. <img src=x onerror=alert(1)> - [x](javascript:alert(1))" in paragraphs


def _lf(text: str) -> str:
    return text.replace("\r\n", "\n")  # HTML parsers (and read_text) read CRLF as LF


def test_hostile_record_strings_are_escaped_in_index_html(hostile_dir):
    page = (hostile_dir / "index.html").read_text()
    assert "<img" not in page and page.count("<script") == 1 and page.count("</script>") == 1
    assert not re.search(r"<(iframe|object|embed|a)\b", page)
    tags, data = _parse_html(page)
    assert [t for t, _ in tags].count("script") == 1
    assert "".join(data["script"]).strip() == (lb.ASSETS_DIR / "sortable.js").read_text().strip()
    for tag, attrs in tags:
        assert not any(name.startswith("on") for name in attrs), (tag, attrs)
        assert not any(str(v).lower().startswith("javascript:") for v in attrs.values()), (tag, attrs)
    # every string comes back as exactly itself: in text, in data-* and title attributes, in the plots
    assert any(attrs.get("data-label") == _lf(HOSTILE) for tag, attrs in tags if tag == "tr")
    assert any(attrs.get("data-sort") == _lf(HOSTILE) for tag, attrs in tags if tag == "td")
    assert any('"><img src=x onerror=alert(1)>' in attrs.get("title", "") for tag, attrs in tags if tag == "td")
    text = "".join(d for chunks in data.values() for d in chunks)
    for s in (HOSTILE, HOSTILE_FILE, HOSTILE_COMMAND, "</span><img src=x onerror=alert(1)>", "# " + HOSTILE,
              "+a|b <img src=x onerror=alert(1)> (paper)"):
        assert _lf(s) in text, s
    # legend entry: the label on one line, literal (no mathtext for `$x^2$`)
    assert data["text"].count(_one_line(HOSTILE)) == len(load_suite("v1").terrains)


def test_hostile_record_strings_are_quoted_and_defused_in_csv(hostile_dir):
    with open(hostile_dir / "leaderboard.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    assert tuple(header) == lb.CSV_COLUMNS and all(len(row) == len(header) for row in body)
    table = [dict(zip(header, row)) for row in body]
    hostile = [row for row in table if row["controller"] == "'" + HOSTILE]
    assert len(hostile) == len([row for row in table if row["controller"] == "strong"]) > 0
    assert {row["record"] for row in hostile} == {"'" + HOSTILE_FILE}
    assert any(row["controller"] == "'-" + HOSTILE + " (paper)" for row in table)
    assert any(row["controller"] == "'+a|b <img src=x onerror=alert(1)> (paper)" for row in table)
    assert {row["controller"] for row in table} >= {"strong", "middling", "weak"}
    text_columns = ("kind", "setting", "controller", "record", "terrain", "unit", "trust")
    for row in table:
        for column, cell in row.items():
            if column in text_columns:
                assert not cell.startswith(("=", "+", "-", "@", "\t", "\r")), (column, cell)
            elif cell not in ("", "true", "false"):
                [float(v) for v in cell.split(";")]  # numbers stay numbers, never apostrophed


def test_hostile_course_record_strings_render_as_literal_text(tmp_path):
    markdown_it = pytest.importorskip("markdown_it")
    board = tmp_path / "board"
    (board / "courses").mkdir(parents=True)
    record = _hostile_measured("# " + HOSTILE, seed=11, capability={"mixed": 2.0}, courses=True)
    (board / "courses" / HOSTILE_FILE).write_text(json.dumps(record))
    assert lb.build(board).errors == []
    readme = (board / "courses" / "README.md").read_text()
    assert "<" not in readme
    for table in _md_table_lines(readme):
        assert {_unescaped_pipes(line) for line in table} == {_unescaped_pipes(table[0])}, table[0]
    page = markdown_it.MarkdownIt("commonmark", {"html": True}).enable(["table", "strikethrough"]).render(readme)
    tags, data = _parse_html(page)
    names = [t for t, _ in tags]
    assert not {"img", "script", "a", "em", "strong", "s", "del", "ol", "hr"} & set(names)
    assert names.count("h1") == 1 and names.count("ul") == 1  # the commands list, no list in a list item
    cells = {c.strip() for c in data.get("td", [])}
    assert _one_line("# " + HOSTILE) in cells and _one_line(HOSTILE_FILE) in cells
    assert _one_line("# " + HOSTILE) + ": " + _one_line(HOSTILE_COMMAND) in {li.strip() for li in data["li"]}


def test_table5_records_show_beside_the_papers_row_on_the_courses_page(tmp_path):
    from hexbench.leaderboard.courses import PAPER_TABLE_5

    board = tmp_path / "board"
    (board / "courses" / "table5").mkdir(parents=True)
    for terrain, capability in (("slopes", 13.5), ("stairs", 6.2)):
        record = synthetic_record("ppo_cpg_rough_model", {terrain: capability}, 21,
                                  levels={terrain: tuple(PAPER_TABLE_5[terrain])})
        (board / "courses" / "table5" / f"rough_model-{terrain}.json").write_text(json.dumps(record))
    result = lb.build(board)
    assert not result.errors, result.errors
    text = (board / "courses" / "README.md").read_text()
    assert "## Paper Table 5: the rough terrain model on slopes and stairs" in text
    assert "| paper Table 5 (reported, not run here) | 100% | 100% | 100% | 100% | 40% | 0% |" in text
    assert text.count("| ppo_cpg_rough_model |") == 2  # one row per terrain
    # a level outside Table 5 is refused with the valid tasks named; the other record still shows
    wrong = synthetic_record("other", {"slopes": 12.0}, 22, levels={"slopes": (6.0,)})
    (board / "courses" / "table5" / "wrong.json").write_text(json.dumps(wrong))
    errors = lb.build(board).errors
    assert len(errors) == 1 and "slopes 6 is not a paper Table 5 task; valid: slopes 10, 11" in errors[0]


def test_a_record_of_paper_table_5_tasks_is_admitted_by_replay_into_its_own_folder(tmp_path, tiny_protocol):
    """Some levels of slopes (Table 5's 10 deg) instead of the full run: replayed, filed under
    courses/table5/ as <label>-<terrain>.json, shown with its tier on the courses page."""
    from conftest import TINY_PROTOCOL

    from hexbench.evaluation.evaluate import evaluate

    (tiny_protocol / "protocol_v1.toml").write_text(TINY_PROTOCOL.replace("levels = [6]", "levels = [6, 10]"))
    table5_task = load_suite("v1").task("slopes", 10)
    run = tmp_path / "run"
    assert evaluate(str(REPO / "baselines" / "cpg.py"), [table5_task], run, workers=1, record=False,
                    progress=False).error is None
    board = tmp_path / "lb"
    board.mkdir()
    dest = lb.add(run, board, workers=1)
    assert dest == board / "courses" / "table5" / "cpg-slopes.json"
    entry = json.loads(dest.read_text())
    assert entry["admission"]["episodes_replayed"] == entry["admission"]["episodes_total"] == 2
    with pytest.raises(lb.RecordError, match="already exists; pass --replace"):
        lb.add(run, board, workers=1)
    lb.build(board)
    page = (board / "courses" / "README.md").read_text()
    assert "| cpg | " in page.split("### slopes")[1] and "sandboxed + replayed" in page.split("### slopes")[1]

    # a self-consistent forgery (a success, summaries and digest recomputed) is refused by the replay
    # (under its own label: under another, its episodes are already those of cpg-slopes.json)
    forged_run = tmp_path / "forged"
    shutil.copytree(run, forged_run)
    record = json.loads((forged_run / "result.json").read_text())
    record["episodes"][0].update(success=True, end_reason="success", time_to_goal_s=0.5)
    resummarize(record)
    (forged_run / "result.json").write_text(json.dumps(record))
    with pytest.raises(lb.RecordError, match="refused: .*success: recorded"):
        lb.add(forged_run, board, replace=True, workers=1)
    assert sorted(p.name for p in (board / "courses" / "table5").iterdir()) == ["cpg-slopes.json"]
    assert json.loads(dest.read_text()) == entry
    record["label"] = "forged"
    (forged_run / "result.json").write_text(json.dumps(record))
    with pytest.raises(lb.RecordError, match="2 of its episodes are those of .*cpg-slopes.json"):
        lb.add(forged_run, board, workers=1)

    # a record of levels outside Table 5 (slopes 6) is no Table 5 record and not a full run: refused
    other = tmp_path / "other"
    assert evaluate(str(REPO / "baselines" / "cpg.py"), [load_suite("v1").task("slopes", 6)], other, workers=1,
                    record=False, progress=False).error is None
    with pytest.raises(lb.RecordError, match=r"missing episode .*joins only on paper Table 5's tasks \(slopes 10, 11"):
        lb.add(other, board, workers=1)


def test_the_trust_column_says_what_was_replayed_and_re_run():
    from types import SimpleNamespace

    from hexbench.leaderboard.formatting import fmt_trust

    def row(admission, tier=lb.TIER_REPLAYED):
        return SimpleNamespace(details={"tier": tier, "admission": admission})

    whole = {"episodes_replayed": 860, "episodes_total": 860}
    rerun = {"isolation": "bubblewrap", "with_run_secret": True}
    assert fmt_trust(row(whole)) == "sandboxed + replayed"
    assert fmt_trust(row({**whole, "controller_rerun": {**rerun, "episodes": 860}})) == "sandboxed + replayed + re-run"
    sampled = {"episodes_replayed": 20, "episodes_total": 860, "controller_rerun": {**rerun, "episodes": 20}}
    assert fmt_trust(row(sampled)) == "sandboxed + replayed (20 of 860 replayed) + re-run (20 of 860)"
    assert fmt_trust(row({**whole, "controller_rerun": {"episodes": True}})) == "sandboxed + replayed"
    assert fmt_trust(row({**whole, "controller_rerun": {**rerun, "episodes": 860}}, TIER_SELF_REPORTED)) == "self-reported"
