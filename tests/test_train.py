"""Training machinery: `hexbench train` smoke runs per baseline, resume, checkpoint publish/load round
trip, corrupt or tampered checkpoints refused, epsilon sweep and learning curves."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from hexbench.agents.policy import (
    CheckpointError,
    ConfigError,
    make_policy_controller,
    scale_observation,
    validate_config,
)
from hexbench.cli import app

REPO = Path(__file__).resolve().parent.parent
BASELINES = REPO / "baselines"
# Tiny learner settings so a smoke run takes seconds: one short rollout / a few updates.
TINY_PPO = ["--set", "n_steps=64", "--set", "batch_size=32", "--set", "n_epochs=1"]
TINY_OFF_POLICY = ["--set", "learning_starts=32", "--set", "batch_size=32", "--set", "buffer_size=1000"]
OFF_POLICY = ("sac", "td3", "sac_cpg", "td3_cpg")


def task(terrain: str, level: float):
    from hexbench.suite.tasks import load_suite

    return load_suite().task(terrain, level)


def run_cli(*args: str):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


def train_tiny(method: str, out: Path, steps: int = 64, terrain: str = "rough", extra: tuple[str, ...] = ()):
    tiny = TINY_OFF_POLICY if method in OFF_POLICY else TINY_PPO
    return run_cli("train", BASELINES / f"{method}.py", "--terrain", terrain, "--steps", steps, "--out", out,
                   "--no-progress", *tiny, *extra)


def load_baseline(method: str):
    spec = importlib.util.spec_from_file_location(f"baseline_{method}", BASELINES / f"{method}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def check_run_dir(out: Path, min_steps: int) -> dict:
    run = json.loads((out / "run.json").read_text())
    assert run["env_steps"] >= min_steps
    last = run["checkpoints"][-1]
    assert (out / last["file"]).is_file()
    header = (out / "progress.csv").read_text().splitlines()[0]
    assert header.startswith("env_steps,wall_time_s,env_index,episodes,mean_episode_reward,success_rate,curriculum_level")
    assert run["curriculum"][0]["level"] == 5.0  # rough curriculum starts at 5 cm
    return run


def test_ppo_cpg_smoke_run_writes_checkpoint_csv_and_resumes(tmp_path):
    out = tmp_path / "run"
    result = train_tiny("ppo_cpg", out, steps=64)
    assert result.exit_code == 0, result.output
    run = check_run_dir(out, 64)
    assert run["config"]["learning_rate"] == 1e-4 and run["config"]["net_arch"] == [256, 256, 256, 256]
    assert run["config"]["n_steps"] == 64  # the --set override is recorded
    # Same command with a larger budget resumes from the verified last checkpoint.
    result = train_tiny("ppo_cpg", out, steps=128)
    assert result.exit_code == 0, result.output
    run = check_run_dir(out, 128)
    assert len(run["sessions"]) == 2 and run["sessions"][1]["from_env_steps"] == 64
    assert [c["env_steps"] for c in run["checkpoints"]] == [64, 128]


def test_env_step_checkpoints_fall_at_the_same_steps_with_the_same_weights_on_a_rerun(tmp_path):
    import torch

    from hexbench.agents.policy import algo_class

    runs = []
    for name in ("a", "b"):
        out = tmp_path / name
        result = train_tiny("ppo_cpg", out, steps=256, extra=("--seed", "7", "--checkpoint-every-steps", "128"))
        assert result.exit_code == 0, result.output
        runs.append((out, json.loads((out / "run.json").read_text())))
    (out_a, run_a), (out_b, run_b) = runs
    assert [c["env_steps"] for c in run_a["checkpoints"]] == [128, 256] == [c["env_steps"] for c in run_b["checkpoints"]]
    for ca, cb in zip(run_a["checkpoints"], run_b["checkpoints"]):
        wa = algo_class("ppo").load(out_a / ca["file"], device="cpu").policy.state_dict()
        wb = algo_class("ppo").load(out_b / cb["file"], device="cpu").policy.state_dict()
        assert wa.keys() == wb.keys() and all(torch.equal(wa[k], wb[k]) for k in wa)


def test_reward_normaliser_statistics_are_checkpointed_and_restored(tmp_path):
    from hexbench.training.envs import make_vec_env, restore_reward_normalizer

    out = tmp_path / "run"
    assert train_tiny("ppo_cpg", out, steps=64).exit_code == 0
    stats = json.loads((out / "run.json").read_text())["checkpoints"][-1]["reward_normalizer"]
    assert stats["count"] > 64 and stats["var"] > 0  # it saw the run's returns (count starts at 1e-4)
    assert train_tiny("ppo_cpg", out, steps=128).exit_code == 0
    resumed = json.loads((out / "run.json").read_text())["checkpoints"][-1]["reward_normalizer"]
    assert resumed["count"] == pytest.approx(stats["count"] + 64)  # carried on from the saved statistics
    venv = make_vec_env("rough", "cpg_residual", 1, normalize_reward_gamma=0.99)
    try:
        restore_reward_normalizer(venv, stats)
        assert (float(venv.ret_rms.var), venv.ret_rms.count) == (stats["var"], stats["count"])
    finally:
        venv.close()


def test_run_from_before_a_new_config_field_resumes_only_with_that_field_off(tmp_path):
    out = tmp_path / "run"
    assert train_tiny("ppo_cpg", out, steps=64, extra=("--set", "normalize_reward=False")).exit_code == 0
    run = json.loads((out / "run.json").read_text())
    del run["config"]["normalize_reward"]  # as recorded by a run started before the field existed
    (out / "run.json").write_text(json.dumps(run))
    result = train_tiny("ppo_cpg", out, steps=128)  # the file's default turns it on: not that run
    assert result.exit_code == 2 and "holds a run with config=" in result.output
    result = train_tiny("ppo_cpg", out, steps=128, extra=("--set", "normalize_reward=False"))
    assert result.exit_code == 0, result.output
    assert json.loads((out / "run.json").read_text())["env_steps"] >= 128


def test_resume_refuses_tampered_training_checkpoint(tmp_path):
    out = tmp_path / "run"
    assert train_tiny("ppo_cpg", out, steps=64).exit_code == 0
    run = json.loads((out / "run.json").read_text())
    with open(out / run["checkpoints"][-1]["file"], "ab") as f:
        f.write(b"tampered")
    result = train_tiny("ppo_cpg", out, steps=128)
    assert result.exit_code == 2
    assert "sha256" in result.output and "refusing to load" in result.output


def test_bad_terrain_and_bad_override_give_one_line_and_no_files(tmp_path):
    out = tmp_path / "run"
    result = run_cli("train", BASELINES / "ppo_cpg.py", "--terrain", "moon", "--out", out)
    assert result.exit_code == 2
    assert "unknown terrain 'moon'; valid terrains: rough, slopes, stairs" in result.output
    result = run_cli("train", BASELINES / "ppo_cpg.py", "--terrain", "rough", "--out", out, "--set", "nope=1")
    assert result.exit_code == 2 and "config has no field 'nope'" in result.output
    result = run_cli("train", BASELINES / "ppo_cpg.py", "--terrain", "rough", "--out", out, "--device", "tpu")
    assert result.exit_code == 2 and "unknown --device 'tpu'; valid: cpu, cuda" in result.output
    assert not out.exists()


@pytest.mark.parametrize("method", ["ppo", "hrl", "sac", "td3", "sac_cpg", "td3_cpg"])
def test_every_baseline_trains_through_the_cli(tmp_path, method):
    out = tmp_path / method
    result = train_tiny(method, out, steps=96, terrain="stairs")
    assert result.exit_code == 0, result.output
    run = json.loads((out / "run.json").read_text())
    assert run["config"]["action_mode"] == load_baseline(method).CONFIG.action_mode
    assert run["env_steps"] >= 96


def test_hrl_starts_from_the_cpg_gait_and_walks(tmp_path):
    """A just-started HRL policy (one tiny update) acts near its initial_action and walks 2.5 m."""
    from hexbench.world.env import HexapodEnv

    out, dest = tmp_path / "run", tmp_path / "checkpoints"
    assert train_tiny("hrl", out, steps=64).exit_code == 0
    assert run_cli("checkpoints", "publish", out, "--dest", dest).exit_code == 0
    config = load_baseline("hrl").CONFIG
    rough5 = task("rough", 5)
    ctrl = make_policy_controller(config, dest, "hrl", rough5)
    env = HexapodEnv(rough5.env_config("cpg_params"))
    obs, _ = env.reset(seed=11)
    ctrl.reset(11)
    for _ in range(env.config.max_steps):
        action = ctrl.act(obs)
        np.testing.assert_allclose(action, config.initial_action, atol=0.15)
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    env.close()
    assert info["end_reason"] == "success"


def test_a_decision_interval_counts_control_steps_and_holds_actions_in_selection(tmp_path):
    """With decision_interval_steps K, the budget, run.json and progress.csv count control steps
    (SB3 counts decisions); the run's config carries K, so selection holds actions as training did."""
    out = tmp_path / "run"
    result = train_tiny("hrl", out, steps=600, extra=("--set", "decision_interval_steps=10", "--set", "n_steps=16",
                                                    "--set", "batch_size=16"))
    assert result.exit_code == 0, result.output
    run = json.loads((out / "run.json").read_text())
    assert run["config"]["decision_interval_steps"] == 10
    assert 600 <= run["env_steps"] < 600 + 16 * 10 + 10  # at most one rollout of decisions over the budget
    steps = [int(line.split(",")[0]) for line in (out / "progress.csv").read_text().splitlines()[1:]]
    assert steps and steps[-1] == run["env_steps"]
    result = run_cli("train", BASELINES / "hrl.py", "--terrain", "rough", "--out", tmp_path / "bad",
                     "--set", "decision_interval_steps=0")
    assert result.exit_code != 0 and "decision_interval_steps must be an integer >= 1" in result.output
    assert not (tmp_path / "bad").exists()


def test_initial_action_of_the_wrong_size_or_algo_is_one_line(tmp_path):
    out = tmp_path / "run"
    result = run_cli("train", BASELINES / "hrl.py", "--terrain", "rough", "--out", out, "--set", "initial_action=(0.5,)")
    assert result.exit_code == 2 and "initial_action must be 4 numbers in [-1, 1]" in result.output
    assert not out.exists()
    sac_with_start = dataclasses.make_dataclass("C", [("initial_action", tuple, (0.0,) * 18)],
                                                bases=(type(load_baseline("sac_cpg").CONFIG),), frozen=True)()
    with pytest.raises(ConfigError, match="initial_action is supported for algo 'ppo' only, not 'sac'"):
        validate_config(sac_with_start)


@pytest.mark.parametrize("method", ["ppo_cpg", "sac_cpg", "td3"])
def test_publish_then_controller_acts_like_the_trained_policy(tmp_path, method):
    from stable_baselines3.common.save_util import load_from_zip_file

    from hexbench.agents.policy import algo_class
    from hexbench.suite.tasks import load_suite
    from hexbench.world.env import HexapodEnv

    out, dest = tmp_path / "run", tmp_path / "checkpoints"
    assert train_tiny(method, out, steps=64).exit_code == 0
    result = run_cli("checkpoints", "publish", out, "--dest", dest)
    assert result.exit_code == 0, result.output
    manifest = json.loads((dest / "manifest.json").read_text())
    entry = manifest["checkpoints"][f"{method}-rough"]
    for key in ("sha256", "command", "env_step_budget", "env_steps", "seed", "wall_time_s", "hexbench_commit"):
        assert key in entry
    assert entry["complete"] and entry["env_steps"] == 64
    config = load_baseline(method).CONFIG
    if config.algo in ("sac", "td3"):  # off-policy weights ship without critics and target networks
        _, params, _ = load_from_zip_file(dest / entry["file"], load_data=False, device="cpu")
        assert params["policy"] and all(k.startswith("actor.") for k in params["policy"])

    task = load_suite().task("rough", 5)
    ctrl = make_policy_controller(config, dest, method, task)
    assert ctrl.action_mode == config.action_mode
    env = HexapodEnv(task.env_config(config.action_mode))
    obs, _ = env.reset(seed=3)
    ctrl.reset(3)
    action = ctrl.act(obs)
    env.close()
    assert action.shape == (18,) and np.all(np.abs(action) <= 1.0)
    run = json.loads((out / "run.json").read_text())
    model = algo_class(config.algo).load(out / run["checkpoints"][-1]["file"], device="cpu")
    expected, _ = model.predict(scale_observation(obs), deterministic=True)
    np.testing.assert_allclose(action, np.clip(expected, -1, 1), atol=1e-6)
    assert run_cli("checkpoints", "verify", "--dir", dest).exit_code == 0


def test_corrupt_missing_or_unlisted_shipped_checkpoint_is_refused(tmp_path):
    out, dest = tmp_path / "run", tmp_path / "checkpoints"
    assert train_tiny("ppo_cpg", out, steps=64).exit_code == 0
    assert run_cli("checkpoints", "publish", out, "--dest", dest).exit_code == 0
    config = load_baseline("ppo_cpg").CONFIG
    with pytest.raises(CheckpointError, match="no checkpoint 'ppo_cpg-stairs'"):
        make_policy_controller(config, dest, "ppo_cpg", task("stairs", 2.0))
    zip_path = dest / "ppo_cpg-rough.zip"
    data = bytearray(zip_path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    zip_path.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="corrupt or tampered"):
        make_policy_controller(config, dest, "ppo_cpg", task("rough", 3.0))
    result = run_cli("checkpoints", "verify", "--dir", dest)
    assert result.exit_code == 1 and "does not match the manifest" in result.output
    zip_path.unlink()
    with pytest.raises(CheckpointError, match="checkpoint file missing"):
        make_policy_controller(config, dest, "ppo_cpg", task("rough", 3.0))


def test_init_from_shipped_weights_starts_from_that_policy(tmp_path):
    """A warm-started run acts like the shipped policy before it learns (learning rate 0), with the
    config's own exploration std; the source is recorded in run.json."""
    from hexbench.agents.policy import algo_class
    from hexbench.world.env import HexapodEnv

    shipped = REPO / "baselines" / "checkpoints" / "ppo_cpg-rough.zip"
    out = tmp_path / "warm"
    result = train_tiny("ppo_cpg", out, extra=("--set", "learning_rate=0.0", "--set", "log_std_init=-3.0",
                                               "--init-from", shipped))
    assert result.exit_code == 0, result.output
    run = json.loads((out / "run.json").read_text())
    assert run["init_from"]["manifest_key"] == "ppo_cpg-rough" and run["init_from"]["source_env_steps"] > 0
    config = load_baseline("ppo_cpg").CONFIG
    ctrl = make_policy_controller(config, shipped.parent, "ppo_cpg", task("rough", 9.0))
    env = HexapodEnv(task("rough", 9.0).env_config(config.action_mode))
    obs, _ = env.reset(seed=5)
    ctrl.reset(5)
    model = algo_class("ppo").load(out / run["checkpoints"][-1]["file"], device="cpu")
    for _ in range(20):
        action = ctrl.act(obs)
        warm, _ = model.predict(scale_observation(obs), deterministic=True)
        np.testing.assert_allclose(np.clip(warm, -1, 1), action, atol=1e-6)
        obs, *_ = env.step(action)
    env.close()
    assert float(model.policy.log_std.detach().exp().mean()) == pytest.approx(np.exp(-3.0), rel=1e-5)
    dest = tmp_path / "published"
    assert run_cli("checkpoints", "publish", out, "--dest", dest, "--checkpoint", "last").exit_code == 0
    entry = json.loads((dest / "manifest.json").read_text())["checkpoints"]["ppo_cpg-rough"]
    source = run["init_from"]["source_env_steps"]
    assert entry["env_steps"] == source + run["env_steps"] and entry["run_env_steps"] == run["env_steps"]
    assert entry["init_from"]["sha256"] == run["init_from"]["sha256"]


def test_value_warmup_holds_the_actor_then_lets_it_learn(tmp_path):
    """With --value-warmup N the taken-over actor comes out of the first N env steps (two PPO
    updates here) exactly as shipped; past N, resumed, it learns."""
    import torch

    from hexbench.agents.policy import algo_class, load_policy_weights
    from hexbench.artifacts.manifest import read_manifest

    shipped = REPO / "baselines" / "checkpoints" / "ppo_cpg-rough.zip"
    source = load_policy_weights(shipped, read_manifest(shipped.parent)["checkpoints"]["ppo_cpg-rough"]["sha256"])
    out = tmp_path / "warmup"
    extra = ("--init-from", shipped, "--value-warmup", "128", "--set", "learning_rate=1e-3")

    def actor_after(steps: int) -> dict:
        result = train_tiny("ppo_cpg", out, steps=steps, extra=extra)
        assert result.exit_code == 0, result.output
        run = json.loads((out / "run.json").read_text())
        assert run["value_warmup_steps"] == 128
        state = algo_class("ppo").load(out / run["checkpoints"][-1]["file"], device="cpu").policy.state_dict()
        return {k: v for k, v in state.items() if k.startswith(("action_net.", "mlp_extractor.policy_net."))}

    held = actor_after(128)
    assert held and all(torch.equal(v, torch.as_tensor(source[k])) for k, v in held.items())
    learned = actor_after(256)
    assert any(not torch.equal(v, held[k]) for k, v in learned.items())


def test_value_warmup_holds_a_fresh_actor_too(tmp_path):
    """Without --init-from the warm-up holds the fresh actor (a PPO-CPG residual of about 0: the CPG)
    while the value function learns; off-policy baselines, which have no value function, refuse it."""
    import torch

    from hexbench.agents.policy import algo_class

    def actor(name: str, *extra: str) -> dict:
        out = tmp_path / name
        result = train_tiny("ppo_cpg", out, steps=128, extra=("--set", "learning_rate=1e-3", *extra))
        assert result.exit_code == 0, result.output
        run = json.loads((out / "run.json").read_text())
        state = algo_class("ppo").load(out / run["checkpoints"][-1]["file"], device="cpu").policy.state_dict()
        return {k: v for k, v in state.items() if k.startswith(("action_net.", "mlp_extractor.policy_net."))}

    held, held_longer = actor("held", "--value-warmup", "128"), actor("held-longer", "--value-warmup", "100000")
    learned = actor("learned")
    assert all(torch.equal(v, held_longer[k]) for k, v in held.items())
    assert any(not torch.equal(v, learned[k]) for k, v in held.items())
    result = train_tiny("sac_cpg", tmp_path / "sac", extra=("--value-warmup", "128"))
    assert result.exit_code == 2 and "PPO baselines only" in result.output, result.output
    assert not (tmp_path / "sac").exists()


def test_gsde_trained_weights_act_under_the_plain_config(tmp_path):
    """gSDE changes only how PPO explores (log_std becomes a matrix): its published weights load
    into the baseline's plain config and act as the trained model's deterministic policy."""
    from hexbench.agents.policy import algo_class
    from hexbench.world.env import HexapodEnv

    out, dest = tmp_path / "sde", tmp_path / "checkpoints"
    result = train_tiny("ppo_cpg", out, extra=("--set", "use_sde=True", "--set", "sde_sample_freq=8"))
    assert result.exit_code == 0, result.output
    assert run_cli("checkpoints", "publish", out, "--dest", dest).exit_code == 0
    config = load_baseline("ppo_cpg").CONFIG
    assert not config.use_sde
    ctrl = make_policy_controller(config, dest, "ppo_cpg", task("rough", 5.0))
    env = HexapodEnv(task("rough", 5.0).env_config(config.action_mode))
    obs, _ = env.reset(seed=2)
    ctrl.reset(2)
    run = json.loads((out / "run.json").read_text())
    model = algo_class("ppo").load(out / run["checkpoints"][-1]["file"], device="cpu")
    expected, _ = model.predict(scale_observation(obs), deterministic=True)
    np.testing.assert_allclose(ctrl.act(obs), np.clip(expected, -1, 1), atol=1e-6)
    env.close()


def test_fixed_level_trains_there_and_an_unknown_level_is_refused(tmp_path):
    out = tmp_path / "fixed"
    result = train_tiny("ppo_cpg", out, terrain="slopes", extra=("--level", "20"))
    assert result.exit_code == 0, result.output
    run = json.loads((out / "run.json").read_text())
    assert run["fixed_level"] == 20.0 and run["curriculum"][0]["level"] == 20.0
    bad = tmp_path / "bad"
    result = train_tiny("ppo_cpg", bad, terrain="slopes", extra=("--level", "19"))
    assert result.exit_code == 2 and "valid levels" in result.output and not bad.exists()
    assert len(result.output.strip().splitlines()) == 1, result.output


def test_own_curriculum_starts_at_its_level_and_resume_keeps_it(tmp_path):
    out = tmp_path / "steep"
    result = train_tiny("ppo_cpg", out, terrain="slopes", extra=("--curriculum", "18:0.5:21"))
    assert result.exit_code == 0, result.output
    run = json.loads((out / "run.json").read_text())
    assert run["curriculum"][0]["level"] == 18.0
    assert run["curriculum_levels"] == {"start_level": 18.0, "level_step": 0.5, "max_level": 21.0,
                                        "successes_per_level": 20}
    result = train_tiny("ppo_cpg", out, steps=128, terrain="slopes")  # the paper's curriculum: another run
    assert result.exit_code == 2 and "curriculum_levels" in result.output, result.output


@pytest.mark.parametrize("extra, message", [
    (("--curriculum", "18:x:21"), "is not START:STEP:TOP"),
    (("--curriculum", "21:0.5:18"), "START <= TOP"),
    (("--curriculum", "18:0:21"), "STEP > 0"),
    (("--curriculum", "18:1:21", "--level", "20"), "exclude each other"),
])
def test_bad_curriculum_is_one_line_and_writes_no_run(tmp_path, extra, message):
    out = tmp_path / "run"
    result = train_tiny("ppo_cpg", out, terrain="slopes", extra=extra)
    assert result.exit_code == 2 and message in result.output, result.output
    assert len(result.output.strip().splitlines()) == 1 and not out.exists()


@pytest.mark.parametrize("bad, message", [
    ("unlisted", "not listed in"),
    ("tampered", "corrupt or tampered"),
    ("off_policy", "PPO baselines only"),
])
def test_bad_init_from_is_one_line_and_writes_no_run(tmp_path, bad, message):
    shipped = REPO / "baselines" / "checkpoints" / "ppo_cpg-rough.zip"
    folder = tmp_path / "checkpoints"
    folder.mkdir()
    (folder / "manifest.json").write_bytes((shipped.parent / "manifest.json").read_bytes())
    source, method = folder / "ppo_cpg-rough.zip", "ppo_cpg"
    data = bytearray(shipped.read_bytes())
    if bad == "unlisted":
        source = folder / "mine.zip"
    elif bad == "tampered":
        data[len(data) // 2] ^= 0xFF
    else:
        method = "sac_cpg"
    source.write_bytes(bytes(data))
    out = tmp_path / "run"
    result = train_tiny(method, out, extra=("--init-from", source))
    assert result.exit_code == 2
    assert message in result.output and len(result.output.strip().splitlines()) == 1, result.output
    assert not out.exists()


def test_epsilon_sweep_and_learning_curves(tmp_path):
    sweep_dir = tmp_path / "sweep"
    result = run_cli("sweep", "epsilon", "--terrain", "stairs", "--values", "0.2,0.6", "--steps", 64,
                     "--out", sweep_dir, *TINY_PPO)
    assert result.exit_code == 0, result.output
    assert "best eps" in result.output
    rows = (sweep_dir / "epsilon.csv").read_text().splitlines()
    assert rows[0].startswith("terrain,eps,trial,seed,level") and len(rows) == 3
    assert rows[1].split(",")[4] == "8.0"  # the hardest stairs level of the curriculum

    plot_png = tmp_path / "epsilon" / "epsilon.png"
    result = run_cli("sweep", "plot", sweep_dir, "--out", plot_png)
    assert result.exit_code == 0, result.output
    assert plot_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (plot_png.parent / "epsilon-stairs.csv").read_text() == (sweep_dir / "epsilon.csv").read_text()
    bad = run_cli("sweep", "plot", tmp_path / "nowhere", "--out", plot_png)
    assert bad.exit_code == 2 and "no such sweep folder" in bad.output

    png = tmp_path / "curves" / "stairs.png"
    result = run_cli("curves", sweep_dir / "eps0.20-trial0", sweep_dir / "eps0.60-trial0", "--out", png)
    assert result.exit_code == 0, result.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # one CSV per run, named by its directory (both runs are ppo_cpg stairs seed 0)
    assert (png.parent / "eps0.20-trial0.csv").is_file() and (png.parent / "eps0.60-trial0.csv").is_file()
    bad = run_cli("curves", tmp_path / "nowhere", "--out", png)
    assert bad.exit_code == 2 and "no progress CSV" in bad.output


def test_resume_restores_each_envs_curriculum_level(tmp_path):
    out = tmp_path / "run"
    assert train_tiny("ppo_cpg", out, steps=64).exit_code == 0
    run_path = out / "run.json"
    run = json.loads(run_path.read_text())
    run["curriculum"] = [{"level": 8.0, "successes": 3}]  # as if the run had climbed to 8 cm
    run_path.write_text(json.dumps(run))
    assert train_tiny("ppo_cpg", out, steps=128).exit_code == 0
    run = json.loads(run_path.read_text())
    assert run["curriculum"] == [{"level": 8.0, "successes": 3}]
    last_row = (out / "progress.csv").read_text().splitlines()[-1].split(",")
    assert last_row[0] == "128" and last_row[6] == "8"


def test_training_errors_are_hexbench_errors():
    from hexbench.errors import HexbenchError
    from hexbench.training.curves import CurvesError
    from hexbench.training.selection import SelectionError
    from hexbench.training.settings import TrainError
    from hexbench.training.sweep import SweepError

    for error in (TrainError, SelectionError, SweepError, CurvesError, ConfigError):
        assert issubclass(error, HexbenchError), error
