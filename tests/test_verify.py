"""hexbench verify RUN_DIR: replay from action logs alone; forged rows, logs and summaries are named."""

import json
import os
import shutil
import tempfile
import time
from pathlib import Path

import pytest
from leaderboard_records import resummarize
from typer.testing import CliRunner

from hexbench.artifacts.records import MAX_RECORD_BYTES
from hexbench.cli import app
from hexbench.evaluation.evaluate import evaluate
from hexbench.evaluation.isolation import landlock_abi
from hexbench.replay.verify import verify_run
from hexbench.suite.seeds import SeedSet
from hexbench.suite.tasks import load_suite

REPO = Path(__file__).resolve().parent.parent
CPG = str(REPO / "baselines" / "cpg.py")


@pytest.fixture
def run(tmp_path_factory, tiny_protocol):
    """A run of 2 short episodes on each of two tasks of the tiny protocol (tests/conftest.py)."""
    tasks = [load_suite("v1").task("stairs", 2), load_suite("v1").task("rough", 3)]
    out = tmp_path_factory.mktemp("verify") / "run"
    res = evaluate(CPG, tasks, out, workers=1, record=False, progress=False)
    assert res.error is None
    return out


def _copy(run: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "run"
    shutil.copytree(run, dst)
    return dst


def test_an_honest_run_verifies_from_any_directory(run, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(app, ["verify", str(run), "--workers", "1"])
    assert res.exit_code == 0, res.output
    assert "all 4 episodes replay exactly" in res.output


def test_a_self_consistent_forged_row_is_caught_by_replay(run, tmp_path):
    forged = _copy(run, tmp_path)
    record = json.loads((forged / "result.json").read_text())
    record["episodes"][1]["progress_m"] += 0.5
    resummarize(record)
    (forged / "result.json").write_text(json.dumps(record))
    report = verify_run(forged)
    assert not report.ok and "progress_m: recorded" in report.message and "episode 1" in report.message


def test_an_edited_summary_or_digest_is_named(run, tmp_path):
    forged = _copy(run, tmp_path)
    record = json.loads((forged / "result.json").read_text())
    record["episodes_digest"] = "0" * 64
    (forged / "result.json").write_text(json.dumps(record))
    assert "digest does not match" in verify_run(forged).message


def test_a_flipped_or_missing_action_log_is_named(run, tmp_path):
    forged = _copy(run, tmp_path)
    log = sorted((forged / "episodes").glob("*.actions"))[0]
    data = bytearray(log.read_bytes())
    data[-5] ^= 0x01
    log.write_bytes(bytes(data))
    report = verify_run(forged)
    assert not report.ok and "sha256 differs" in report.message
    log.unlink()
    assert "cannot be read" in verify_run(forged).message


def test_a_replaced_log_with_its_hash_updated_is_caught(run, tmp_path):
    """Swap two episodes' logs and fix the rows' hashes: the logs belong to other episodes."""
    forged = _copy(run, tmp_path)
    record = json.loads((forged / "result.json").read_text())
    a, b = record["episodes"][0], record["episodes"][1]
    a["action_log_path"], b["action_log_path"] = b["action_log_path"], a["action_log_path"]
    a["action_log_sha256"], b["action_log_sha256"] = b["action_log_sha256"], a["action_log_sha256"]
    resummarize(record)
    (forged / "result.json").write_text(json.dumps(record))
    assert "belongs to another episode" in verify_run(forged).message


def test_not_a_run_folder_is_one_line(tmp_path):
    res = CliRunner().invoke(app, ["verify", str(tmp_path)])
    assert res.exit_code == 2 and "is" in res.output and "a run folder" in res.output
    assert len([ln for ln in res.output.splitlines() if ln.strip()]) == 1


def test_keyed_seed_sets_are_hidden_and_checked_with_the_key(tmp_path, tiny_protocol):
    key = tmp_path / "key"
    key.write_bytes(b"k" * 32)
    tasks = [load_suite("v1").task("stairs", 2)]
    out = tmp_path / "keyed"
    res = CliRunner().invoke(app, ["run", CPG, "--terrain", "stairs", "--levels", "2", "--episodes", "2",
                                   "--workers", "1", "--no-record", "--out", str(out), "--seed-key", str(key)])
    assert res.exit_code == 0, res.output
    record = json.loads((out / "result.json").read_text())
    seeds = [e["seed"] for e in record["episodes"]]
    assert not set(seeds) & set(tasks[0].seeds(20))  # not the public episodes
    assert seeds == SeedSet(b"k" * 32).seeds(tasks[0], 2)
    assert record["provenance"]["seed_set"] == {"kind": "keyed", "key_fingerprint": SeedSet(b"k" * 32).fingerprint()}
    assert "k" * 32 not in (out / "result.json").read_text()
    assert verify_run(out, seed_set=SeedSet(b"k" * 32)).ok
    assert "fingerprint differs" in verify_run(out, seed_set=SeedSet(b"x" * 32)).message
    short = tmp_path / "short"
    short.write_bytes(b"abc")
    bad = CliRunner().invoke(app, ["run", CPG, "--seed-key", str(short), "--out", str(tmp_path / "o")])
    assert bad.exit_code == 2 and "at least 16 random bytes" in bad.output


def _run_keyed_in_process(controller: str, key: Path, out: Path):
    return CliRunner().invoke(app, ["run", controller, "--terrain", "stairs", "--levels", "2", "--episodes", "1",
                                    "--workers", "1", "--no-record", "--out", str(out), "--seed-key", str(key),
                                    "--isolation", "process"])


def _keyed_run_beside(controller: Path, tmp_path: Path):
    """`hexbench run` of a copy of `controller` with --isolation process and a seed key beside it,
    readable by all, in a folder others may enter (under /tmp)."""
    folder = Path(tempfile.mkdtemp(prefix="hexbench-test-key-"))
    try:
        folder.chmod(0o755)
        copy = folder / controller.name
        shutil.copy(controller, copy)
        key = folder / "key"
        key.write_bytes(b"k" * 32)
        key.chmod(0o644)
        return _run_keyed_in_process(str(copy), key, tmp_path / "keyed")
    finally:
        shutil.rmtree(folder)


@pytest.mark.skipif(bool(landlock_abi()), reason="Landlock leaves the key out of what the controller may open")
def test_a_seed_key_the_controller_could_read_is_refused_before_any_episode(tmp_path, tiny_protocol):
    """Without Landlock, under --isolation process the controller runs as the evaluating user, as
    root without capabilities, or as nobody: a key that its user can read would be no secret."""
    res = _keyed_run_beside(Path(CPG), tmp_path)
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert res.exit_code == 1 and len(lines) == 1, res.output
    assert "cpg.py" in lines[0] and "--seed-key" in lines[0]
    assert not (tmp_path / "keyed").exists()


def test_a_seed_key_is_refused_in_process(tmp_path, tiny_protocol):
    key = tmp_path / "key"
    key.write_bytes(b"k" * 32)
    res = CliRunner().invoke(app, ["run", CPG, "--terrain", "stairs", "--levels", "2", "--episodes", "1",
                                   "--workers", "1", "--no-record", "--out", str(tmp_path / "keyed"),
                                   "--seed-key", str(key), "--isolation", "none"])
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert res.exit_code == 1 and len(lines) == 1 and "--isolation none" in lines[0], res.output
    assert not (tmp_path / "keyed").exists()


@pytest.mark.skipif(not landlock_abi(), reason="needs Landlock (Linux 5.13+) to keep the key from the controller")
def test_landlock_hides_a_seed_key_even_in_the_controllers_own_folder(tmp_path, tiny_protocol):
    """The red-team controller that finds the key through the evaluator's command line and shows
    it with an out-of-range action walks honestly: the key beside it cannot be opened."""
    res = _keyed_run_beside(REPO / "tests" / "controllers" / "attack_read_seed_key.py", tmp_path)
    assert res.exit_code == 0, res.output
    record = json.loads((tmp_path / "keyed" / "result.json").read_text())
    assert record["provenance"]["seed_set"]["kind"] == "keyed"
    assert record["provenance"]["isolation"]["landlock_abi"] == landlock_abi()


def test_resume_takes_a_journal_entry_only_if_its_action_log_replays_into_it(tmp_path, tiny_protocol):
    tasks = [load_suite("v1").task("stairs", 2)]
    out = tmp_path / "run"
    first = evaluate(CPG, tasks, out, workers=1, record=False, progress=False)
    entry_file = sorted((out / ".journal").glob("stairs-*.json"))[0]
    entry = json.loads(entry_file.read_text())
    honest = entry["row"]["progress_m"]
    entry["row"]["progress_m"] = honest + 2.0  # a planted row: the log does not replay into it
    entry_file.write_text(json.dumps(entry))
    again = evaluate(CPG, tasks, out, workers=1, record=False, progress=False)
    assert again.record["episodes"] == first.record["episodes"]  # the planted row was re-run, not taken
    assert json.loads(entry_file.read_text())["row"]["progress_m"] == honest


class _NodesWithoutTheRunFolder:
    """A stand-in for a cluster engine: each item runs where the run folder cannot be seen (it is
    moved away meanwhile), as on a Ray node of another machine."""

    name = "ray"

    def __init__(self, run_dir: Path):
        self.run_dir = run_dir

    def map(self, fn, items, workers, advance, stop=None, resources=None):
        away = self.run_dir.with_name(self.run_dir.name + "-away")
        self.run_dir.rename(away)
        try:
            return [fn(item) for item in items]
        finally:
            away.rename(self.run_dir)


def test_on_a_cluster_the_logs_travel_with_the_episodes_and_a_refused_log_says_why(run, tmp_path):
    from hexbench.evaluation import engines

    copied = _copy(run, tmp_path)
    with engines.using(_NodesWithoutTheRunFolder(copied)):
        assert verify_run(copied).ok
        log = sorted((copied / "episodes").glob("*.actions"))[0]
        log.unlink()
        os.mkfifo(log)
        report = verify_run(copied)
    assert not report.ok and log.name in report.message and "is a pipe" in report.message, report.message


def _make_hostile(path: Path, how: str, size_bytes: int) -> None:
    """Replace `path` by something reading would choke on: a pipe (open waits for a writer), a
    device (endless bytes), a sparse file past its format's bound, or JSON nested past the parser."""
    path.unlink(missing_ok=True)
    if how == "pipe":
        os.mkfifo(path)
    elif how == "device":
        path.symlink_to("/dev/zero")
    elif how == "huge":
        with open(path, "wb") as f:
            f.truncate(size_bytes + 1)
    else:
        path.write_text("[" * 200_000)


@pytest.mark.parametrize("how", ["pipe", "device", "huge", "nested"])
@pytest.mark.parametrize("command", ["verify", "leaderboard add"])
def test_a_hostile_result_file_is_one_line_at_once(run, tmp_path, how, command):
    """A run folder comes from anyone (`hexbench leaderboard add`): a result.json that would make
    reading hang, never end or the parser recurse is refused with one line, in moments."""
    hostile = _copy(run, tmp_path)
    _make_hostile(hostile / "result.json", how, MAX_RECORD_BYTES)
    args = command.split() + [str(hostile)] + (["--dir", str(tmp_path / "board")] if command != "verify" else [])
    t0 = time.monotonic()
    res = CliRunner().invoke(app, args)
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert time.monotonic() - t0 < 10
    assert res.exit_code != 0 and len(lines) == 1 and "result.json" in lines[0], res.output
    assert "Traceback" not in res.output and not (tmp_path / "board").exists()


@pytest.mark.parametrize("how", ["pipe", "device", "huge"])
def test_a_hostile_action_log_names_its_episode_at_once(run, tmp_path, how):
    from hexbench.artifacts.action_log import MAX_FILE_BYTES

    hostile = _copy(run, tmp_path)
    log = sorted((hostile / "episodes").glob("*.actions"))[0]
    _make_hostile(log, how, MAX_FILE_BYTES)
    t0 = time.monotonic()
    report = verify_run(hostile)
    assert time.monotonic() - t0 < 30
    assert not report.ok and log.name in report.message and "episode" in report.message, report.message


def _dropped_failure_and_doubled(record: dict) -> None:
    """Replace episode 1 of a task by a second copy of its episode 0 (same index): with a success
    there, the copy would count it twice."""
    rows = record["episodes"]
    rows[1] = dict(rows[0])


@pytest.mark.parametrize("edit, words", [
    (_dropped_failure_and_doubled, "appears twice"),
    (lambda r: r["episodes"][1].update(index=7), "numbered 0..1"),
    (lambda r: r.update(protocol="v9"), "unknown protocol 'v9'; valid protocols: v1"),
    (lambda r: r["episodes"][0].update(progress_m=float("nan")), "progress_m is nan, not a finite number"),
    (lambda r: r.update(episodes=[]), "holds no episodes"),
])
def test_rows_that_are_not_one_runs_episodes_are_one_line(run, tmp_path, edit, words):
    """Summaries and digest recomputed: each row would replay, yet the rows are not a run's episodes."""
    forged = _copy(run, tmp_path)
    record = json.loads((forged / "result.json").read_text())
    edit(record)
    try:
        resummarize(record)
    except (KeyError, ValueError):  # no summary can be made of it: the digest stays as it was
        pass
    (forged / "result.json").write_text(json.dumps(record))
    res = CliRunner().invoke(app, ["verify", str(forged), "--workers", "1"])
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert res.exit_code == 1 and len(lines) == 1 and words in lines[0], res.output
