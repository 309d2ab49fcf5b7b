"""Methods across their seeds (hexbench.leaderboard.seeds): seed-run folders validated, aggregated with
IQM and stratified-bootstrap intervals, and rendered to leaderboard/seeds/."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from leaderboard_records import demo_records, synthetic_record, write_board

from hexbench import leaderboard as lb
from hexbench.leaderboard import seeds as seed_runs
from hexbench.leaderboard import seeds_page, statistics
from hexbench.suite.tasks import load_suite

REPO = Path(__file__).resolve().parent.parent


def write_seed_run(root: Path, method: str, terrain: str, seed: int, capability: float, *,
                   budget: int = 1_000_000, record_seed: int | None = None) -> Path:
    """A seed-run folder: a synthetic one-terrain record bound to a manifest entry by sha256."""
    folder = root / f"{method}-{terrain}-seed{seed}"
    (folder / "checkpoints").mkdir(parents=True)
    record = synthetic_record(method, {terrain: capability}, record_seed if record_seed is not None else 100 + seed,
                              terrains=(terrain,))
    sha = f"{seed:02d}{terrain}".encode().hex().ljust(64, "0")[:64]
    record["controller"]["checkpoints"] = [{"path": f"{method}-{terrain}.zip", "sha256": sha}]
    (folder / f"result-{terrain}.json").write_text(json.dumps(record))
    manifest = {"format": 1, "checkpoints": {f"{method}-{terrain}": {
        "file": f"{method}-{terrain}.zip", "sha256": sha, "method": method, "terrain": terrain, "seed": seed,
        "env_step_budget": budget, "env_steps": 200_000 + seed}}}
    (folder / "checkpoints" / "manifest.json").write_text(json.dumps(manifest))
    return folder


@pytest.fixture
def repo_like(tmp_path):
    """A leaderboard folder (with a 'cpg' reference) beside a baselines/seeds/ folder of 4 + 1 runs."""
    board = write_board(tmp_path / "leaderboard", [synthetic_record("cpg", {"rough": 8.0, "slopes": 12.0,
                                                                            "stairs": 6.0}, seed=5)] + demo_records())
    seeds = tmp_path / "baselines" / "seeds"
    for seed, capability in zip(range(1, 5), (10.0, 10.5, 11.0, 9.5)):
        write_seed_run(seeds, "ppo_cpg", "rough", seed, capability)
    write_seed_run(seeds, "ppo", "rough", 1, 5.0)
    return board, seeds


def test_seed_runs_aggregate_into_iqm_rows_with_intervals_and_improvement(repo_like):
    board, seeds = repo_like
    result = lb.build(board)
    assert not result.errors
    text = (board / "seeds" / "README.md").read_text()
    assert "| ppo_cpg @ 1M env steps | 4 (1, 2, 3, 4) |" in text
    assert "| ppo @ 1M env steps | 1 (1) |" in text and "| cpg (no training) | 1 (one record) |" in text
    assert (board / "seeds" / "rough.svg").read_text().lstrip().startswith("<?xml")
    assert not (board / "seeds" / "slopes.svg").exists()  # no seed run on slopes: only the reference there
    # the numbers are the statistics module's, over the runs' paper-level success rates
    suite = load_suite("v1")
    load = seed_runs.load_seed_runs(seeds)
    aggregates = seed_runs.aggregate(load.runs, suite)
    ppo_cpg = next(a for a in aggregates if a.method.label == "ppo_cpg")
    assert ppo_cpg.scores.shape == (4, len(suite.levels("rough", include_headroom=False)))
    assert ppo_cpg.all_levels.value == pytest.approx(statistics.interquartile_mean(ppo_cpg.scores))
    assert ppo_cpg.all_levels.low <= ppo_cpg.all_levels.value <= ppo_cpg.all_levels.high
    assert ppo_cpg.all_levels.low < ppo_cpg.all_levels.high and ppo_cpg.all_levels.n_runs == 4
    headroom = [r.row.terrain("rough")["headroom_auc"] for r in ppo_cpg.runs]
    assert ppo_cpg.headroom_auc.value == pytest.approx(statistics.interquartile_mean(np.array([headroom]).T))
    assert "Headroom AUC, IQM (95% CI)" in text
    found = {i.other.label: i.estimate for i in seed_runs.improvements(aggregates)}
    assert set(found) == {"ppo"}  # every other method on that terrain; the strong one is clearly better
    assert found["ppo"].value > 0.9 and found["ppo"].low > 0.5
    assert "X better" in text


def test_every_untrained_reference_gets_its_row_and_a_line_style_of_its_own(repo_like):
    board, _ = repo_like
    write_board(board, [synthetic_record("cpg_heading", {"rough": 11.0, "slopes": 16.0, "stairs": 6.5}, seed=6)])
    result = lb.build(board)
    assert not result.errors
    text = (board / "seeds" / "README.md").read_text()
    assert "| cpg (no training) | 1 (one record) |" in text and "| cpg_heading (no training) | 1 (one record) |" in text
    assert "`cpg`, `cpg_heading`" in text  # the page says which records are its references
    better_than = [line for line in text.splitlines() if line.startswith("| X = ppo_cpg")]
    assert any("| cpg_heading (no training) |" in line for line in better_than)
    svg = (board / "seeds" / "rough.svg").read_text()
    dashes = {style[1] for style in seeds_page.REFERENCE_STYLES}
    greys = {style[0] for style in seeds_page.REFERENCE_STYLES}
    assert len(dashes) == len(greys) == 2 and all(g in svg for g in greys)


def test_build_of_seed_runs_is_deterministic(repo_like, tmp_path):
    board, _ = repo_like
    lb.build(board)
    first = {p.name: p.read_bytes() for p in (board / "seeds").iterdir()}
    lb.build(board)
    assert first == {p.name: p.read_bytes() for p in (board / "seeds").iterdir()}


def test_methods_at_different_budgets_are_kept_apart(repo_like):
    board, seeds = repo_like
    write_seed_run(seeds, "ppo_cpg", "rough", 9, 12.0, budget=3_000_000)
    aggregates = seed_runs.aggregate(seed_runs.load_seed_runs(seeds).runs, load_suite("v1"))
    names = [a.method.name for a in aggregates]
    assert "ppo_cpg @ 1M env steps" in names and "ppo_cpg @ 3M env steps" in names
    one_m = next(a for a in aggregates if a.method.name == "ppo_cpg @ 1M env steps")
    assert one_m.seeds == [1, 2, 3, 4]


@pytest.mark.parametrize("break_it, message", [
    (lambda f: (f / "checkpoints" / "manifest.json").unlink(), "manifest.json is missing"),
    (lambda f: (f / "checkpoints" / "manifest.json").write_text("{"), "is not a checkpoint manifest"),
    (lambda f: _edit_record(f, lambda r: r["controller"].update(checkpoints=[{"path": "x.zip", "sha256": "f" * 64}])),
     "checkpoint sha256 is not exactly one entry"),
    (lambda f: _edit_record(f, lambda r: r["episodes"].pop()), "missing episode rough"),
    (lambda f: _edit_record(f, lambda r: r.update(label="other")), "is not the folder's method"),
    (lambda f: _edit_manifest(f, lambda e: e.update(seed=7)), "not the folder's seed 2"),
    (lambda f: _edit_manifest(f, lambda e: e.pop("env_step_budget")), "has no env_step_budget"),
])
def test_a_bad_seed_run_is_refused_with_one_line_and_the_others_still_count(repo_like, break_it, message):
    board, seeds = repo_like
    break_it(seeds / "ppo_cpg-rough-seed2")
    result = lb.build(board)
    assert len(result.errors) == 1 and message in result.errors[0] and "\n" not in result.errors[0]
    text = (board / "seeds" / "README.md").read_text()
    assert "| ppo_cpg @ 1M env steps | 3 (1, 3, 4) |" in text and "## Refused seed runs" in text


def test_a_record_of_another_terrain_than_its_folder_is_refused(repo_like):
    _, seeds = repo_like
    folder = write_seed_run(seeds, "ppo_cpg", "stairs", 1, 6.0)
    shutil.copy(seeds / "ppo_cpg-rough-seed1" / "result-rough.json", folder / "result-stairs.json")
    with pytest.raises(lb.RecordError, match=r"covers rough; a seed run's record covers its folder's terrain"):
        seed_runs.read_seed_run(folder)


def test_improvement_over_a_single_deterministic_run_resamples_the_other_method_only():
    rng = np.random.default_rng(3)
    many = rng.uniform(0.4, 1.0, size=(5, 4))
    one = np.full((1, 4), 0.7)
    estimate = statistics.probability_of_improvement_interval(many, one, np.random.default_rng(0))
    assert estimate.low < estimate.value < estimate.high
    assert estimate.value == pytest.approx(statistics.probability_of_improvement(many, one))


def test_committed_seed_page_is_what_build_produces(tmp_path):
    """leaderboard/seeds/README.md must be reproducible from baselines/seeds/ and the records."""
    committed = REPO / "leaderboard"
    if not (committed / "seeds" / "README.md").exists():
        pytest.skip("leaderboard/seeds/ has not been generated yet (run `hexbench leaderboard build`)")
    copy = tmp_path / "lb"
    copy.mkdir()
    for p in lb.record_files(committed):
        shutil.copy(p, copy / p.name)
    lb.build(copy, root=REPO)
    names = ["README.md"]
    if f'content="{lb.generator_tag()}"' in (committed / "index.html").read_text():
        names += [p.name for p in (committed / "seeds").glob("*.svg")]  # same matplotlib: same SVG bytes
    for name in names:
        assert (copy / "seeds" / name).read_bytes() == (committed / "seeds" / name).read_bytes(), \
            f"leaderboard/seeds/{name} is stale"


def _edit_record(folder: Path, change) -> None:
    path = next(folder.glob("result-*.json"))
    record = json.loads(path.read_text())
    change(record)
    path.write_text(json.dumps(record))


def _edit_manifest(folder: Path, change) -> None:
    path = folder / "checkpoints" / "manifest.json"
    manifest = json.loads(path.read_text())
    change(next(iter(manifest["checkpoints"].values())))
    path.write_text(json.dumps(manifest))


def test_a_trained_run_without_its_record_yet_is_listed_not_refused(repo_like):
    board, seeds = repo_like
    (seeds / "ppo_cpg-rough-seed2" / "result-rough.json").unlink()
    result = lb.build(board)
    assert not result.errors
    text = (board / "seeds" / "README.md").read_text()
    assert "## Trained, not yet scored" in text and "\n- ppo_cpg-rough-seed2\n" in text
    assert "| ppo_cpg @ 1M env steps | 3 (1, 3, 4) |" in text


def test_adding_a_run_to_one_method_leaves_the_other_methods_intervals_alone(repo_like):
    _, seeds = repo_like
    suite = load_suite("v1")

    def ppo_interval():
        aggregates = seed_runs.aggregate(seed_runs.load_seed_runs(seeds).runs, suite)
        ppo = next(a for a in aggregates if a.method.label == "ppo")
        return ppo.all_levels, next(a for a in aggregates if a.method.label == "ppo_cpg").runs

    write_seed_run(seeds, "ppo", "rough", 2, 6.5)  # two runs: an interval that is not a point
    before, cpg_runs_before = ppo_interval()
    assert before.low < before.high
    write_seed_run(seeds, "ppo_cpg", "rough", 5, 10.2)
    after, cpg_runs_after = ppo_interval()
    assert len(cpg_runs_after) == len(cpg_runs_before) + 1
    assert (after.value, after.low, after.high) == (before.value, before.low, before.high)


_SEED_CONTROLLER = '''
"""Open-loop CPG that declares a (dummy) checkpoint, as a trained seed run does."""
from pathlib import Path
import numpy as np
HERE = Path(__file__).resolve().parent

class Gait:
    action_mode = "cpg_residual"
    checkpoint_paths = [HERE / "checkpoints" / "gait-stairs.zip"]
    def reset(self, seed):
        pass
    def act(self, obs):
        return np.zeros(18, np.float32)

def make_controller(task):
    return Gait()
'''


def _scored_seed_run(root: Path, name: str) -> tuple[Path, Path]:
    """(run folder, seed-run folder) of `gait` on the tiny protocol's stairs, its checkpoint in a manifest."""
    from hexbench.artifacts.files import sha256_file
    from hexbench.evaluation.evaluate import evaluate

    folder = root / "seeds" / "gait-stairs-seed1"
    (folder / "checkpoints").mkdir(parents=True, exist_ok=True)
    code = root / name
    (code / "checkpoints").mkdir(parents=True)
    (code / "gait.py").write_text(_SEED_CONTROLLER)
    (code / "checkpoints" / "gait-stairs.zip").write_bytes(b"weights of seed 1")
    entry = {"file": "gait-stairs.zip", "sha256": sha256_file(code / "checkpoints" / "gait-stairs.zip"),
             "method": "gait", "terrain": "stairs", "seed": 1, "env_step_budget": 1000, "env_steps": 800}
    (folder / "checkpoints" / "manifest.json").write_text(json.dumps({"format": 1, "checkpoints": {"gait-stairs": entry}}))
    tasks = [t for t in load_suite("v1").tasks if t.terrain == "stairs"]
    res = evaluate(str(code / "gait.py"), tasks, code / "run", workers=1, record=False, progress=False)
    assert res.error is None
    return code / "run", folder


def _forge(run: Path) -> None:
    """Flip one episode's success and recompute nothing: the rows no longer match the action logs."""
    record = json.loads((run / "result.json").read_text())
    record["episodes"][0]["success"] = not record["episodes"][0]["success"]
    (run / "result.json").write_text(json.dumps(record))


def test_a_seed_run_is_admitted_by_replay_into_its_folder_and_a_forged_one_is_refused(tmp_path, tiny_protocol):
    from hexbench.leaderboard.admission import add_seed_run
    from hexbench.leaderboard.records import TIER_REPLAYED, record_tier

    forged, folder = _scored_seed_run(tmp_path, "forged")
    _forge(forged)
    with pytest.raises(lb.RecordError):
        add_seed_run(forged, folder)
    assert sorted(p.name for p in folder.iterdir()) == ["checkpoints"]

    run, folder = _scored_seed_run(tmp_path, "honest")
    dest = add_seed_run(run, folder)
    assert dest == folder / "result-stairs.json"
    record = json.loads(dest.read_text())
    assert record_tier(record, str(dest)) == TIER_REPLAYED
    assert record["admission"]["episodes_replayed"] == record["admission"]["episodes_total"] == len(record["episodes"])
    (seed_run,) = seed_runs.load_seed_runs(folder.parent).runs
    assert seed_run.seed == 1 and seed_run.method == "gait"

    before = dest.read_bytes()
    _forge(run)
    with pytest.raises(lb.RecordError):
        add_seed_run(run, folder)
    assert dest.read_bytes() == before and not list(folder.glob(".*.tmp"))
