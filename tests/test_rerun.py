"""hexbench verify RUN_DIR --rerun: the record's controller plays its episodes again in the sandbox and
must choose every recorded action; a record whose actions came from elsewhere is named, with the step."""

import hashlib
import json
import shutil
import textwrap
from pathlib import Path

import pytest
from leaderboard_records import resummarize
from typer.testing import CliRunner

from hexbench.cli import app
from hexbench.evaluation import sandbox
from hexbench.evaluation.evaluate import evaluate
from hexbench.replay import rerun
from hexbench.suite.tasks import load_suite

REPO = Path(__file__).resolve().parent.parent
CPG = str(REPO / "baselines" / "cpg.py")
needs_bwrap = pytest.mark.skipif(sandbox.bubblewrap_version() is None, reason="bubblewrap is not usable here")


def controller(folder: Path, name: str, act: str, prelude: str = "") -> str:
    """A controller file: the open-loop CPG with `act` (obs and self.seed in scope) as its residual."""
    path = folder / name
    path.write_text(textwrap.dedent(prelude) + textwrap.dedent(f'''
        import numpy as np
        class Probe:
            action_mode = "cpg_residual"
            def reset(self, seed):
                self.seed = seed
                self.rng = np.random.default_rng(seed)
            def act(self, obs):
                return np.asarray({act}, dtype=np.float32)
        def make_controller(task):
            return Probe()
        '''))
    return str(path)


def run_of(controller_file: str, out: Path) -> Path:
    tasks = [load_suite("v1").task("stairs", 2)]
    result = evaluate(controller_file, tasks, out, workers=1, record=False, progress=False)
    assert result.error is None, result.error
    return out


def verify(*args: str):
    return CliRunner().invoke(app, ["verify", *args, "--workers", "1"])


@needs_bwrap
def test_the_recorded_controller_reproduces_every_action(tiny_protocol, tmp_path):
    noisy = controller(tmp_path, "noisy.py", "self.rng.normal(0.0, 0.1, 18)")  # its actions follow its reset() seed
    run = run_of(noisy, tmp_path / "run")
    res = verify(str(run), "--rerun")
    assert res.exit_code == 0, res.output
    assert "with the run's secret, chose every action of all 2 episodes exactly as recorded" in res.output
    sampled = verify(str(run), "--rerun", "--sample", "1")
    assert sampled.exit_code == 0 and "chose every action of 1 of 2 episodes exactly as recorded" in sampled.output

    (run / ".journal" / "run_secret").unlink()  # without it, the reset() seeds differ
    res = verify(str(run), "--rerun")
    assert res.exit_code == 1
    assert "stairs 2cm episode 0: the actions differ from step 0 on" in res.output
    assert "holds no run secret" in res.output


@needs_bwrap
def test_a_record_whose_actions_another_controller_chose_is_named_with_the_step(tiny_protocol, tmp_path):
    """Replay proves that a record's actions make its outcomes; only a re-run shows that the named
    controller chose them. Here the actions come from a controller that steps aside at step 5,
    and the record names the open-loop CPG."""
    other = controller(tmp_path, "other.py", "np.zeros(18) if self.steps_done() < 5 else np.full(18, 0.2)")
    Path(other).write_text(Path(other).read_text().replace(
        "    def act(self, obs):\n",
        "    def steps_done(self):\n        self.n = getattr(self, 'n', -1) + 1\n        return self.n\n"
        "    def act(self, obs):\n"))
    forged = run_of(other, tmp_path / "run")
    record = json.loads((forged / "result.json").read_text())
    record["controller"].update(file=CPG, sha256=hashlib.sha256(Path(CPG).read_bytes()).hexdigest(), checkpoints=[])
    (forged / "result.json").write_text(json.dumps(record))
    replayed = verify(str(forged))
    assert replayed.exit_code == 0, replayed.output  # the physics agrees with the actions
    res = verify(str(forged), "--rerun")
    assert res.exit_code == 1
    assert "stairs 2cm episode 0: the actions differ from step 5 on (max |difference| 0.2 there)" in res.output


@needs_bwrap
def test_the_controller_cannot_read_the_recorded_actions_back(tiny_protocol, tmp_path):
    """The run folder lies inside the controller's folder, which the sandbox shows it: its record,
    episode index, action logs and journal are hidden all the same (a controller that could read
    them could return the recorded actions). Seeing any of them, this one acts out of bounds."""
    run = tmp_path / "run"
    peek = controller(tmp_path, "peek.py", "np.full(18, 5.0) if seen(RUN) else np.zeros(18)", prelude=f'''
        import os
        RUN = {str(run)!r}
        def seen(run):
            for name in ("result.json", "episodes.parquet", os.path.join(".journal", "run_secret")):
                try:
                    open(os.path.join(run, name), "rb").close()
                    return True
                except OSError:
                    pass
            try:
                return any(n.endswith(".actions") for n in os.listdir(os.path.join(run, "episodes")))
            except OSError:
                return False
        ''')
    run_of(peek, run)
    res = verify(str(run), "--rerun")
    assert res.exit_code == 0, res.output


def test_another_file_than_the_recorded_one_is_refused_in_one_line(tiny_protocol, tmp_path):
    run = run_of(CPG, tmp_path / "run")
    other = controller(tmp_path, "other.py", "np.zeros(18)")
    res = verify(str(run), "--rerun", "--controller", other)
    assert res.exit_code == 2
    assert f"{other}: is not the controller the record names" in res.output
    assert [line for line in res.output.splitlines() if line.startswith("error:")] == [res.output.splitlines()[-1]]
    assert "Traceback" not in res.output
    res = verify(str(run), "--rerun", "--controller", str(tmp_path / "missing.py"))
    assert res.exit_code == 2 and "no such controller file here" in res.output


def test_a_sandbox_that_cannot_hide_the_run_folder_is_refused(tiny_protocol, tmp_path, monkeypatch):
    run = run_of(CPG, tmp_path / "run")
    monkeypatch.setattr(rerun, "landlock_abi", lambda: 0)
    record = json.loads((run / "result.json").read_text())
    with pytest.raises(rerun.RerunError, match="needs a sandbox that hides the run folder"):
        rerun.rerun_episodes(run, record, record["episodes"], CPG, isolation="process")


def test_where_two_action_sequences_part():
    import numpy as np

    a = np.zeros((6, 3), dtype=np.float32)
    b = a.copy()
    b[4, 1] = -0.25
    assert rerun.first_action_difference(a, b) == "the actions differ from step 4 on (max |difference| 0.25 there)"
    assert rerun.first_action_difference(a, a[:4]).startswith("the same actions for 4 steps, then the record ends after 6")
    minus_zero = a.copy()
    minus_zero[2, 0] = -0.0  # the same number, another float32: not the recorded action
    assert "from step 2 on" in rerun.first_action_difference(a, minus_zero)


def test_the_shipped_record_reproduces(tmp_path):
    """A committed record's run folder is not shipped (its action logs are not in the repository), so
    this checks the other way round: a short run of the shipped default re-runs exactly."""
    ppo = str(REPO / "baselines" / "ppo_cpg.py")
    out = tmp_path / "run"
    result = evaluate(ppo, [load_suite("v1").task("rough", 3)], out, episodes=1, workers=1, record=False,
                      progress=False)
    assert result.error is None, result.error
    if sandbox.bubblewrap_version() is None and not rerun.landlock_abi():
        pytest.skip("no sandbox here hides files")
    record = json.loads((out / "result.json").read_text())
    report = rerun.rerun_episodes(out, record, record["episodes"], ppo)
    assert report.ok, report.message
    shutil.rmtree(out)


def _forgeries(run: Path, tmp_path: Path):
    """(what, forged copy of `run`, what its one line must say): a self-consistent forged row, a
    flipped action log, a missing one, and two rows' logs swapped with their hashes."""
    def copy(name: str, edit) -> Path:
        dst = tmp_path / name
        shutil.copytree(run, dst)
        record = json.loads((dst / "result.json").read_text())
        edit(dst, record)
        resummarize(record)
        (dst / "result.json").write_text(json.dumps(record))
        return dst

    def forged_row(dst, record):
        record["episodes"][1]["progress_m"] += 0.5

    def flipped_log(dst, record):
        log = dst / "episodes" / record["episodes"][0]["action_log_path"]
        data = bytearray(log.read_bytes())
        data[-5] ^= 0x01
        log.write_bytes(bytes(data))

    def missing_log(dst, record):
        (dst / "episodes" / record["episodes"][0]["action_log_path"]).unlink()

    def swapped_logs(dst, record):
        a, b = record["episodes"][0], record["episodes"][1]
        a["action_log_path"], b["action_log_path"] = b["action_log_path"], a["action_log_path"]
        a["action_log_sha256"], b["action_log_sha256"] = b["action_log_sha256"], a["action_log_sha256"]

    yield "forged row", copy("row", forged_row), "progress_m: recorded"
    yield "flipped log", copy("flipped", flipped_log), "sha256 differs"
    yield "missing log", copy("missing", missing_log), "cannot be read"
    yield "swapped logs", copy("swapped", swapped_logs), "belongs to another episode"


@needs_bwrap
def test_with_a_rerun_the_episodes_are_replayed_once_and_every_forgery_is_still_named(tiny_protocol, tmp_path):
    """With --rerun the replay leaves the physics to the re-run (its evaluator plays the recorded
    actions and must find every row as recorded): an honest run passes, saying so, and each
    forgery a replay catches is caught, in one line."""
    tasks = [load_suite("v1").task("stairs", 2), load_suite("v1").task("rough", 3)]
    run = tmp_path / "run"
    assert evaluate(CPG, tasks, run, workers=1, record=False, progress=False).error is None
    honest = verify(str(run), "--rerun")
    assert honest.exit_code == 0, honest.output
    assert "the action logs of all 4 episodes are intact (not replayed: the re-run replays them)" in honest.output
    assert "chose every action of all 4 episodes exactly as recorded" in honest.output
    for what, forged, says in _forgeries(run, tmp_path):
        res = verify(str(forged), "--rerun")
        errors = [line for line in res.output.splitlines() if line.startswith("error:")]
        assert res.exit_code == 1 and len(errors) == 1 and says in errors[0], (what, res.output)


@needs_bwrap
def test_leaderboard_admission_can_rerun_the_controller(tiny_protocol, tmp_path):
    """`hexbench leaderboard add RUN --rerun`: the admission says the controller was re-run; a record
    naming a controller that did not choose its actions is refused in one line, and nothing joins."""
    tasks = list(load_suite("v1").tasks)
    run = tmp_path / "run"
    assert evaluate(CPG, tasks, run, workers=1, record=False, progress=False).error is None
    board = tmp_path / "lb"
    board.mkdir()
    added = CliRunner().invoke(app, ["leaderboard", "add", str(run), "--dir", str(board), "--workers", "1", "--rerun"])
    assert added.exit_code == 0, added.output
    admission = json.loads((board / "cpg.json").read_text())["admission"]
    assert admission["controller_rerun"] == {"episodes": 6, "isolation": "bubblewrap", "with_run_secret": True}
    assert admission["episodes_replayed"] == 6  # by the re-run, which played the recorded actions
    assert "| sandboxed + replayed + re-run |" in (board / "README.md").read_text()
    replayed_only = CliRunner().invoke(app, ["leaderboard", "add", str(run), "--dir", str(board), "--workers", "1",
                                             "--replace"])
    assert replayed_only.exit_code == 1 and "re-run on 0 episodes" in replayed_only.output

    steps_aside = controller(tmp_path, "aside.py", "np.full(18, 0.05)")
    forged = tmp_path / "forged"
    assert evaluate(steps_aside, tasks, forged, workers=1, record=False, progress=False).error is None
    record = json.loads((forged / "result.json").read_text())
    record["label"] = "Forged"
    record["controller"].update(file=CPG, sha256=hashlib.sha256(Path(CPG).read_bytes()).hexdigest())
    (forged / "result.json").write_text(json.dumps(record))
    refused = CliRunner().invoke(app, ["leaderboard", "add", str(forged), "--dir", str(board), "--workers", "1",
                                       "--rerun"])
    errors = [line for line in refused.output.splitlines() if line.startswith("error:")]
    assert refused.exit_code == 1 and len(errors) == 1, refused.output
    assert "refused:" in errors[0] and "the actions differ from step 0 on" in errors[0]
    assert not (board / "forged.json").exists()
