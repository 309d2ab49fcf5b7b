"""Aggregates over training runs (seeds), with rliable's definitions (Agarwal et al., "Deep RL at
the edge of the statistical precipice", NeurIPS 2021), computed with scipy.

Scores come as a matrix `scores[run, task]`: one row per run (a seed of a method), one column per
task (a level, or a terrain's AUC); every run scored on every task.

    interquartile_mean(scores)               IQM: the mean of the middle 50% of all run x task scores
                                             (scipy.stats.trim_mean, 25% cut at each end)
    interval(scores, statistic, rng)         stratified-bootstrap confidence interval (default 95%):
                                             runs resampled with replacement within each task,
                                             independently per task (scipy.stats.bootstrap with one
                                             sample per task), percentile method, as rliable's
                                             StratifiedBootstrap
    probability_of_improvement(x, y)         P(X > Y): for each task, the Mann-Whitney probability
                                             that a run of X scores above a run of Y (ties count 1/2),
                                             averaged over tasks
    performance_profile(scores, thresholds)  the share of run x task scores above each threshold

Every random function takes an `np.random.Generator`. With a single run the interval collapses to
the point (nothing to resample); `n_runs` is reported beside every interval.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DEFAULT_RESAMPLES = 2000  # rliable's default for its interval estimates
DEFAULT_CONFIDENCE = 0.95


@dataclass(frozen=True)
class Estimate:
    """A point estimate over runs with its stratified-bootstrap interval."""

    value: float
    low: float
    high: float
    n_runs: int
    confidence: float = DEFAULT_CONFIDENCE


def as_matrix(scores) -> np.ndarray:
    """scores as a float (runs, tasks) matrix; a 1-D array is one task. ValueError for an empty or ragged one."""
    matrix = np.asarray(scores, dtype=float)
    if matrix.ndim == 1:
        matrix = matrix[:, None]
    if matrix.ndim != 2 or matrix.size == 0:
        raise ValueError(f"scores must be a non-empty (runs, tasks) matrix, got shape {matrix.shape}")
    if not np.all(np.isfinite(matrix)):
        raise ValueError("scores must be finite")
    return matrix


def interquartile_mean(scores) -> float:
    """The mean of the middle 50% of all scores (scores[run, task] flattened)."""
    from scipy.stats import trim_mean

    return float(trim_mean(as_matrix(scores).ravel(), 0.25))


def mean_score(scores) -> float:
    return float(np.mean(as_matrix(scores)))


def interval(scores, statistic, rng: np.random.Generator, resamples: int = DEFAULT_RESAMPLES,
             confidence: float = DEFAULT_CONFIDENCE) -> Estimate:
    """statistic(scores) with its stratified-bootstrap percentile interval over runs."""
    matrix = as_matrix(scores)
    value = statistic(matrix)
    runs = matrix.shape[0]
    if runs < 2:
        return Estimate(value, value, value, runs, confidence)
    columns = tuple(matrix[:, task] for task in range(matrix.shape[1]))
    low, high = _percentile_interval(columns, lambda *cols: statistic(np.column_stack(cols)), value, rng,
                                     resamples, confidence)
    return Estimate(value, low, high, runs, confidence)


def _percentile_interval(samples: tuple, statistic, value: float, rng: np.random.Generator, resamples: int,
                         confidence: float) -> tuple[float, float]:
    """The percentile interval of statistic(*samples) with each sample resampled on its own (the
    strata), widened to hold `value`; every resample equal (scipy then gives nan): the point."""
    from scipy.stats import bootstrap

    result = bootstrap(samples, statistic, n_resamples=resamples, vectorized=False, paired=False,
                       confidence_level=confidence, method="percentile", rng=rng)
    low, high = float(result.confidence_interval.low), float(result.confidence_interval.high)
    if not np.isfinite(low) or not np.isfinite(high):
        return value, value
    return min(low, value), max(high, value)


def iqm(scores, rng: np.random.Generator, **options) -> Estimate:
    """The IQM of scores[run, task] with its stratified-bootstrap interval."""
    return interval(scores, interquartile_mean, rng, **options)


def probability_of_improvement(x, y) -> float:
    """P(X > Y) over tasks: per task, the share of (run of X, run of Y) pairs where X scores higher
    (ties count 1/2), averaged over tasks. x: (runs_x, tasks), y: (runs_y, tasks)."""
    a, b = as_matrix(x), as_matrix(y)
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"x and y must share their tasks: {a.shape[1]} vs {b.shape[1]} columns")
    per_task = []
    for task in range(a.shape[1]):
        diff = a[:, task][:, None] - b[:, task][None, :]
        per_task.append(float(np.mean((diff > 0) + 0.5 * (diff == 0))))
    return float(np.mean(per_task))


def probability_of_improvement_interval(x, y, rng: np.random.Generator, resamples: int = DEFAULT_RESAMPLES,
                                        confidence: float = DEFAULT_CONFIDENCE) -> Estimate:
    """P(X > Y) with a stratified-bootstrap interval: the runs of X and of Y resampled, each within
    every task, independently (both methods' seeds are samples)."""
    a, b = as_matrix(x), as_matrix(y)
    value = probability_of_improvement(a, b)
    tasks = a.shape[1]
    if a.shape[0] < 2 and b.shape[0] < 2:
        return Estimate(value, value, value, min(a.shape[0], b.shape[0]), confidence)
    samples = tuple(a[:, t] for t in range(tasks)) + tuple(b[:, t] for t in range(tasks))

    def statistic(*cols):
        return probability_of_improvement(np.column_stack(cols[:tasks]), np.column_stack(cols[tasks:]))

    low, high = _percentile_interval(samples, statistic, value, rng, resamples, confidence)
    return Estimate(value, low, high, min(a.shape[0], b.shape[0]), confidence)


def performance_profile(scores, thresholds) -> np.ndarray:
    """For each threshold tau, the share of run x task scores above tau (rliable's score distribution)."""
    flat = as_matrix(scores).ravel()
    return np.array([float(np.mean(flat > tau)) for tau in np.asarray(thresholds, dtype=float)])
