"""Aggregates over runs with rliable's definitions: IQM, stratified-bootstrap intervals, probability
of improvement, performance profiles (hexbench.leaderboard.statistics)."""

import numpy as np
import pytest

from hexbench.leaderboard.statistics import (
    interquartile_mean,
    interval,
    iqm,
    mean_score,
    performance_profile,
    probability_of_improvement,
    probability_of_improvement_interval,
)


def test_iqm_is_the_mean_of_the_middle_half_of_all_run_task_scores():
    scores = np.arange(1, 9, dtype=float).reshape(4, 2)  # 1..8
    assert interquartile_mean(scores) == pytest.approx(4.5)  # mean of 3, 4, 5, 6
    assert interquartile_mean([0, 0, 0, 10]) == pytest.approx(0.0)  # the outlier is cut


def test_the_bootstrap_resamples_runs_within_each_task():
    """Task 0 always 0, task 1 always 1: every stratified resample keeps four of each, so the IQM
    cannot move (a bootstrap over the pooled scores would)."""
    scores = np.column_stack([np.zeros(4), np.ones(4)])
    estimate = iqm(scores, np.random.default_rng(0))
    assert (estimate.value, estimate.low, estimate.high, estimate.n_runs) == (0.5, 0.5, 0.5, 4)


def test_intervals_hold_their_estimate_are_reproducible_and_narrow_with_more_runs():
    rng = np.random.default_rng(3)
    few, many = rng.uniform(0, 1, (4, 3)), rng.uniform(0, 1, (40, 3))
    a = iqm(few, np.random.default_rng(7))
    assert a.low <= a.value <= a.high and a == iqm(few, np.random.default_rng(7))
    b = iqm(many, np.random.default_rng(7))
    assert (b.high - b.low) < (a.high - a.low)
    m = interval(many, mean_score, np.random.default_rng(7))
    assert m.low < float(np.mean(many)) < m.high


def test_one_run_gives_the_point_and_says_so():
    estimate = iqm([[0.25, 0.75]], np.random.default_rng(0))
    assert (estimate.value, estimate.low, estimate.high, estimate.n_runs) == (0.5, 0.5, 0.5, 1)


def test_probability_of_improvement_counts_pairs_and_ties_half():
    assert probability_of_improvement([[1.0], [2.0]], [[0.0], [2.0]]) == pytest.approx(0.625)
    same = np.random.default_rng(1).uniform(0, 1, (5, 3))
    assert probability_of_improvement(same, same) == pytest.approx(0.5)
    assert probability_of_improvement(same + 2, same) == 1.0
    estimate = probability_of_improvement_interval(same + 2, same, np.random.default_rng(0))
    assert (estimate.value, estimate.low, estimate.high) == (1.0, 1.0, 1.0)
    mixed = probability_of_improvement_interval(same + 0.1, same, np.random.default_rng(0))
    assert 0.0 <= mixed.low <= mixed.value <= mixed.high <= 1.0
    with pytest.raises(ValueError, match="share their tasks"):
        probability_of_improvement(np.ones((3, 2)), np.ones((3, 3)))


def test_performance_profile_is_the_share_above_each_threshold():
    scores = [[0.0, 0.5], [1.0, 0.25]]
    assert performance_profile(scores, [-1, 0.0, 0.3, 1.0]).tolist() == [1.0, 0.75, 0.5, 0.0]


@pytest.mark.parametrize("bad", [[], [[]], [[np.nan, 1.0]], np.ones((2, 2, 2))])
def test_bad_scores_are_refused(bad):
    with pytest.raises(ValueError):
        interquartile_mean(bad)
