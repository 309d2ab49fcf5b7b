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


def _iqm_batched(matrix: np.ndarray):
    """IQM over the last two axes of a (..., runs, tasks) array (a bootstrap batch)."""
    from scipy.stats import trim_mean

    return trim_mean(matrix.reshape(*matrix.shape[:-2], -1), 0.25, axis=-1)


def _mean_batched(matrix: np.ndarray):
    return np.mean(matrix, axis=(-2, -1))


def interquartile_mean(scores) -> float:
    """The mean of the middle 50% of all scores (scores[run, task] flattened)."""
    return float(_iqm_batched(as_matrix(scores)))


def mean_score(scores) -> float:
    return float(_mean_batched(as_matrix(scores)))


_BATCHED = {interquartile_mean: _iqm_batched, mean_score: _mean_batched}  # all resamples at once


def interval(scores, statistic, rng: np.random.Generator, resamples: int = DEFAULT_RESAMPLES,
             confidence: float = DEFAULT_CONFIDENCE) -> Estimate:
    """statistic(scores) with its stratified-bootstrap percentile interval over runs."""
    matrix = as_matrix(scores)
    value = float(statistic(matrix))
    runs = matrix.shape[0]
    if runs < 2:
        return Estimate(value, value, value, runs, confidence)
    columns = tuple(matrix[:, task] for task in range(matrix.shape[1]))
    batched = _BATCHED.get(statistic)
    if batched is None:  # any other statistic of a (runs, tasks) matrix: one resample at a time
        def batched(stacked):
            flat = stacked.reshape(-1, *stacked.shape[-2:])
            return np.array([statistic(m) for m in flat]).reshape(stacked.shape[:-2])
    low, high = _percentile_interval(columns, lambda *cols, axis=-1: batched(np.stack(cols, axis=-1)), value,
                                     rng, resamples, confidence)
    return Estimate(value, low, high, runs, confidence)


def _percentile_interval(samples: tuple, statistic, value: float, rng: np.random.Generator, resamples: int,
                         confidence: float) -> tuple[float, float]:
    """The percentile interval of statistic(*samples) with each sample resampled on its own (the
    strata), widened to hold `value`; every resample equal (scipy then gives nan): the point.
    `statistic` is vectorized: each sample arrives as (resamples, n)."""
    from scipy.stats import bootstrap

    result = bootstrap(samples, statistic, n_resamples=resamples, vectorized=True, paired=False,
                       confidence_level=confidence, method="percentile", rng=rng)
    low, high = float(result.confidence_interval.low), float(result.confidence_interval.high)
    if not np.isfinite(low) or not np.isfinite(high):
        return value, value
    return min(low, value), max(high, value)


def iqm(scores, rng: np.random.Generator, **options) -> Estimate:
    """The IQM of scores[run, task] with its stratified-bootstrap interval."""
    return interval(scores, interquartile_mean, rng, **options)


def _improvement(a: np.ndarray, b: np.ndarray):
    """P(X > Y) for (..., runs_x, tasks) and (..., runs_y, tasks) arrays, batched over leading axes."""
    diff = a[..., :, None, :] - b[..., None, :, :]  # (..., runs_x, runs_y, tasks)
    per_task = np.mean((diff > 0) + 0.5 * (diff == 0), axis=(-3, -2))
    return np.mean(per_task, axis=-1)


def probability_of_improvement(x, y) -> float:
    """P(X > Y) over tasks: per task, the share of (run of X, run of Y) pairs where X scores higher
    (ties count 1/2), averaged over tasks. x: (runs_x, tasks), y: (runs_y, tasks)."""
    a, b = as_matrix(x), as_matrix(y)
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"x and y must share their tasks: {a.shape[1]} vs {b.shape[1]} columns")
    return float(_improvement(a, b))


def probability_of_improvement_interval(x, y, rng: np.random.Generator, resamples: int = DEFAULT_RESAMPLES,
                                        confidence: float = DEFAULT_CONFIDENCE) -> Estimate:
    """P(X > Y) with a stratified-bootstrap interval: the runs of X and of Y resampled, each within
    every task, independently (both methods' seeds are samples); a method with a single run is
    held fixed."""
    a, b = as_matrix(x), as_matrix(y)
    value = probability_of_improvement(a, b)
    tasks = a.shape[1]
    if a.shape[0] < 2 and b.shape[0] < 2:
        return Estimate(value, value, value, min(a.shape[0], b.shape[0]), confidence)
    # a method with one run (a deterministic reference such as the open-loop CPG) is held fixed:
    # there is nothing to resample in it
    resampled = [m for m in (a, b) if m.shape[0] >= 2]
    samples = tuple(m[:, t] for m in resampled for t in range(tasks))

    def statistic(*cols, axis=-1):
        drawn = iter(np.stack(cols[i * tasks:(i + 1) * tasks], axis=-1) for i in range(len(resampled)))
        return _improvement(next(drawn) if a.shape[0] >= 2 else a, next(drawn) if b.shape[0] >= 2 else b)

    low, high = _percentile_interval(samples, statistic, value, rng, resamples, confidence)
    return Estimate(value, low, high, min(a.shape[0], b.shape[0]), confidence)


def performance_profile(scores, thresholds) -> np.ndarray:
    """For each threshold tau, the share of run x task scores above tau (rliable's score distribution)."""
    flat = as_matrix(scores).ravel()
    return np.array([float(np.mean(flat > tau)) for tau in np.asarray(thresholds, dtype=float)])
