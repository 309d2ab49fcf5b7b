"""hexbench.training.curves: learning curves from progress CSVs, and plotting runs at one env-step budget."""

import json

import pandas as pd
import pytest

from hexbench.training.curves import CurvesError, line_styles, load_progress, plot_curves
from hexbench.training.runs import CSV_COLUMNS


def write_run(folder, method, total_steps, logged_steps):
    """A progress CSV and run.json as `hexbench train` leaves them, one env, rows at logged_steps."""
    folder.mkdir(parents=True)
    rows = [{"env_steps": n, "wall_time_s": n / 100, "env_index": 0, "episodes": i, "mean_episode_reward": float(i),
             "success_rate": 0.0, "curriculum_level": 5.0 + i, "curriculum_successes": 0}
            for i, n in enumerate(logged_steps)]
    pd.DataFrame(rows, columns=list(CSV_COLUMNS)).to_csv(folder / "progress.csv", index=False)
    run = {"method": method, "terrain": "rough", "seed": 0, "total_steps": total_steps,
           "env_steps": logged_steps[-1], "config": {"early_end_penalty": True}}
    (folder / "run.json").write_text(json.dumps(run))
    return folder


def test_a_window_keeps_each_runs_first_steps_and_says_which_runs_had_a_smaller_budget(tmp_path):
    long_run = write_run(tmp_path / "ppo-long", "ppo", 1_000_000, [20_000, 40_000, 60_000, 80_000, 1_000_000])
    short_run = write_run(tmp_path / "sac-short", "sac", 60_000, [20_000, 40_000, 60_000])
    stopped = write_run(tmp_path / "td3-stopped", "td3", 1_000_000, [20_000, 40_000])

    agg, label, _ = load_progress(long_run, max_env_steps=60_000)
    assert list(agg["env_steps"]) == [20_000, 40_000, 60_000] and "partial" not in label
    _, label, _ = load_progress(short_run, max_env_steps=100_000)
    assert "budget 60,000 steps" in label
    _, label, _ = load_progress(stopped, max_env_steps=100_000)
    assert "partial: 40,000 of 1,000,000 steps" in label
    _, label, _ = load_progress(long_run)  # no window: the whole run, which reached its budget
    assert "partial" not in label

    png = tmp_path / "first60k.png"
    plot_curves([long_run, short_run, stopped], png, max_env_steps=60_000, copy_csv=False)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(CurvesError, match="positive"):
        plot_curves([long_run], png, max_env_steps=0, copy_csv=False)


def test_seeds_of_one_config_share_a_colour_and_an_ablation_of_the_same_method_gets_its_own():
    paper = {"method": "ppo_cpg", "config": {"log_std_init": -2.3}}
    ablation = {"method": "ppo_cpg", "config": {"log_std_init": -3.0}}
    other = {"method": "ppo", "config": {"log_std_init": -1.0}}
    runs = [("ppo_cpg", paper), ("ppo_cpg", paper), ("ppo", other), ("ppo_cpg", ablation), ("ppo_cpg", ablation)]
    s = line_styles(runs)
    assert s[0]["color"] == s[1]["color"] and s[0]["linestyle"] != s[1]["linestyle"]  # two seeds
    assert s[3]["color"] == s[4]["color"] and s[3]["linestyle"] != s[4]["linestyle"]
    assert len({s[0]["color"], s[2]["color"], s[3]["color"]}) == 3  # paper config, other method, ablation
    # a figure of one config per method keeps each method's colour whatever the ablations elsewhere
    assert line_styles([("ppo_cpg", paper)])[0]["color"] == s[0]["color"]


def test_label_names_gsde_a_warm_start_its_warm_up_and_own_curriculum(tmp_path):
    folder = write_run(tmp_path / "ppo_cpg-ft", "ppo_cpg", 100, [50, 100])
    run = json.loads((folder / "run.json").read_text())
    run["config"].update(log_std_init=-3.5, use_sde=True, sde_sample_freq=120, normalize_reward=True)
    run["init_from"] = {"manifest_key": "ppo_cpg-rough", "source_env_steps": 180502}
    run["value_warmup_steps"] = 50000
    run["curriculum_levels"] = {"start_level": 18.0, "level_step": 0.5, "max_level": 21.0, "successes_per_level": 20}
    (folder / "run.json").write_text(json.dumps(run))
    _, label, _ = load_progress(folder)
    assert "gSDE, matrix std 0.03, new every 120 steps" in label and "from ppo_cpg-rough at 180,502" in label
    assert "value warm-up 50,000" in label and "curriculum 18:0.5:21" in label


def test_label_names_an_off_policy_recipes_exploration_update_ratio_and_critics(tmp_path):
    folder = write_run(tmp_path / "td3-rough-seed1", "td3", 100, [50, 100])
    run = json.loads((folder / "run.json").read_text())
    run["config"].update(action_noise_std=0.1, train_freq=4, gradient_steps=1, critic_net_arch=[256, 256],
                         net_arch=[256, 256, 256, 256])
    (folder / "run.json").write_text(json.dumps(run))
    _, label, _ = load_progress(folder)
    assert "action noise std 0.1" in label and "0.25 updates per env step, critics [256, 256]" in label
    run["config"].update(train_freq=1, gradient_steps=-1, critic_net_arch=None)  # SB3: as many as collected
    (folder / "run.json").write_text(json.dumps(run))
    _, label, _ = load_progress(folder)
    assert "1 update per env step, critics [256, 256, 256, 256]" in label
    run["config"].update(action_noise_std=0.0, arrival_bonus=True)  # SAC adds no action noise
    (folder / "run.json").write_text(json.dumps(run))
    _, label, _ = load_progress(folder)
    assert "action noise" not in label and "arrival bonus" in label


def test_bands_average_the_seeds_of_a_recipe_with_a_t_interval_and_need_run_json(tmp_path):
    import numpy as np
    from scipy import stats

    from hexbench.training.curves import plot_bands, seed_band

    values = np.array([[1.0, 2.0, np.nan], [3.0, 4.0, 5.0], [5.0, 9.0, 7.0]])
    mean, low, high = seed_band(values)
    assert list(mean) == [3.0, 5.0, 6.0]  # the NaN (a shorter run) leaves the mean to the others
    half = stats.t.ppf(0.975, 2) * np.std([1.0, 3.0, 5.0], ddof=1) / np.sqrt(3)
    assert low[0] == pytest.approx(3.0 - half) and high[0] == pytest.approx(3.0 + half)
    assert high[2] - low[2] == pytest.approx(2 * stats.t.ppf(0.975, 1) * np.std([5.0, 7.0], ddof=1) / np.sqrt(2))
    one = seed_band(np.array([[1.0, 2.0]]))
    assert list(one[0]) == [1.0, 2.0] and np.all(np.isnan(one[1]))  # one seed: no band

    runs = [write_run(tmp_path / f"ppo_cpg-rough-seed{s}", "ppo_cpg", 100_000, [20_000, 60_000, 100_000])
            for s in (1, 2)]
    png = tmp_path / "bands.png"
    assert plot_bands(runs, png) == [png] and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    (runs[0] / "run.json").unlink()
    with pytest.raises(CurvesError, match="no run.json beside its progress CSV"):
        plot_bands(runs, png)
