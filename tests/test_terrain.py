"""Terrain geometry, measured in the physics engine with vertical rays, against the requested level."""

from __future__ import annotations

import math
import random

import numpy as np
import pybullet as p
import pytest

from hexbench.suite.tasks import load_suite
from hexbench.training.wrappers import CURRICULA
from hexbench.world.terrain import (
    COURSE_END_X_M,
    COURSE_HALF_WIDTH_M,
    COURSE_START_X_M,
    OBSTACLE_START_X_M,
    BuiltTerrain,
    RoughTerrain,
    make_terrain,
)

GOAL_X_M = 2.5  # the start is at the origin; the goal 2.5 m ahead (paper 4.1)
MAX_LATERAL_M = 0.8
SUITE = load_suite("v1")


def curriculum_levels(terrain: str) -> list[float]:
    c = CURRICULA[terrain]
    n = int(math.floor((c.max_level - c.start_level) / c.level_step + 1e-9))
    return [round(c.start_level + k * c.level_step, 6) for k in range(n + 1)]


def all_levels(terrain: str) -> list[float]:
    """Paper Table 4 levels, headroom levels and the training curriculum levels of paper 4.1."""
    return sorted(set(SUITE.levels(terrain)) | set(curriculum_levels(terrain)))


@pytest.fixture(scope="module")
def client():
    cid = p.connect(p.DIRECT)
    yield cid
    p.disconnect(cid)


def build(client: int, kind: str, level: float, seed: int = 0) -> BuiltTerrain:
    p.resetSimulation(physicsClientId=client)
    return make_terrain(kind, level).build(client, np.random.default_rng(seed))


def ray_heights(client: int, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Ground height [m] the physics engine sees under each (x, y): shape (len(ys), len(xs))."""
    gx, gy = np.meshgrid(xs, ys)
    starts = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, 5.0)], axis=1)
    ends = starts.copy()
    ends[:, 2] = -5.0
    hits = []
    for k in range(0, len(starts), 8192):
        hits += p.rayTestBatch(starts[k:k + 8192].tolist(), ends[k:k + 8192].tolist(), physicsClientId=client)
    assert all(h[0] >= 0 for h in hits), "a ray found no ground"
    return np.array([h[3][2] for h in hits]).reshape(gx.shape)


def test_levels_cover_paper_headroom_and_curriculum() -> None:
    assert SUITE.levels("rough", include_headroom=False) == [3, 4, 5, 6, 7, 8, 9, 10, 11, 12]
    assert SUITE.levels("slopes", include_headroom=False) == [6, 7, 8, 9, 10, 11, 12, 13, 14, 15]
    assert SUITE.levels("stairs", include_headroom=False) == [2, 3, 4, 5, 5.5, 6, 6.5, 7, 7.5, 8]
    assert max(SUITE.levels("rough")) == 16 and max(SUITE.levels("slopes")) == 24
    assert max(SUITE.levels("stairs")) == 10
    assert curriculum_levels("rough") == [5, 6, 7, 8, 9, 10, 11, 12, 13]
    assert curriculum_levels("slopes") == [5, 8, 11, 14, 17]
    assert curriculum_levels("stairs") == [5, 5.5, 6, 6.5, 7, 7.5, 8]


@pytest.mark.parametrize("level", all_levels("rough"))
def test_rough_height_difference_matches_level(client: int, level: float) -> None:
    built = build(client, "rough", level, seed=int(level * 10))
    res = built.resolution_m
    # the heightfield's own vertices (nudged inside its border so every ray lands on it)
    xs = np.clip(np.arange(COURSE_START_X_M, COURSE_END_X_M + 1e-9, res), COURSE_START_X_M + 1e-4, COURSE_END_X_M - 1e-4)
    ys = np.clip(np.arange(-COURSE_HALF_WIDTH_M, COURSE_HALF_WIDTH_M + 1e-9, res),
                 -COURSE_HALF_WIDTH_M + 1e-4, COURSE_HALF_WIDTH_M - 1e-4)
    z = ray_heights(client, xs, ys)
    h = level / 100.0
    assert z.max() - z.min() == pytest.approx(h, abs=1e-3)
    assert z.min() == pytest.approx(0.0, abs=1e-4)
    # the terrain really is rough: many distinct heights, spread over the course width
    on_course = z[:, (xs > OBSTACLE_START_X_M + 0.25) & (xs < GOAL_X_M - 0.25)]
    assert np.std(on_course) > 0.1 * h
    # the analytic height (used by rewards and recordings) is the surface the physics sees
    xq = np.linspace(COURSE_START_X_M + 0.013, COURSE_END_X_M - 0.017, 90)
    yq = np.linspace(-1.5 + 0.007, 1.5 - 0.011, 40)
    zq = ray_heights(client, xq, yq)
    analytic = np.array([[built.height_at(x, y) for x in xq] for y in yq])
    # rays hit PyBullet's triangles, height_at interpolates bilinearly: they differ by < 3% of h
    np.testing.assert_allclose(zq, analytic, atol=max(0.03 * h, 5e-4))


def test_rough_same_seed_same_ground_other_seed_other_ground() -> None:
    terrain = RoughTerrain(height_difference_cm=8.0)
    a = terrain.heights(np.random.default_rng(42))
    b = terrain.heights(np.random.default_rng(42))
    c = terrain.heights(np.random.default_rng(43))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert a.max() - a.min() == pytest.approx(0.08, abs=1e-12)
    assert c.max() - c.min() == pytest.approx(0.08, abs=1e-12)


def test_building_uses_only_the_given_generator(client: int) -> None:
    np.random.seed(0)
    random.seed(0)
    numpy_state, python_state = np.random.get_state(), random.getstate()
    rng = np.random.default_rng(3)
    for kind, level in (("rough", 7.0), ("slopes", 10.0), ("stairs", 5.0), ("flat", 0.0)):
        build(client, kind, level)
        make_terrain(kind, level).build(client, rng)
    after = np.random.get_state()
    assert after[0] == numpy_state[0] and np.array_equal(after[1], numpy_state[1]) and after[2:] == numpy_state[2:]
    assert random.getstate() == python_state


@pytest.mark.parametrize("level", all_levels("slopes"))
def test_slope_angle_matches_level(client: int, level: float) -> None:
    built = build(client, "slopes", level)
    xs = np.arange(0.0, 3.0, 0.01)
    ys = np.array([-0.6, 0.0, 0.6])
    z = ray_heights(client, xs, ys)
    tan = math.tan(math.radians(level))
    for row in z:
        up = (xs > 0.35) & (xs < 1.05)
        down = (xs > 1.75) & (xs < 2.45)
        top = (xs > 1.15) & (xs < 1.65)
        rise = np.polyfit(xs[up], row[up], 1)[0]
        fall = np.polyfit(xs[down], row[down], 1)[0]
        assert math.degrees(math.atan(rise)) == pytest.approx(level, abs=0.05)
        assert math.degrees(math.atan(-fall)) == pytest.approx(level, abs=0.05)
        np.testing.assert_allclose(row[top], 0.8 * tan, atol=1e-4)  # flat top, 0.8 m of ascent below it
        np.testing.assert_allclose(row[xs < OBSTACLE_START_X_M - 0.01], 0.0, atol=1e-6)
        np.testing.assert_allclose(row[xs > GOAL_X_M + 0.01], 0.0, atol=1e-6)
    analytic = np.array([built.height_at(x, 0.0) for x in xs])
    np.testing.assert_allclose(z[1], analytic, atol=2e-3)
    assert built.slope_deg_at(0.7) == pytest.approx(level)
    assert built.slope_deg_at(2.1) == pytest.approx(-level)
    assert built.slope_deg_at(1.4) == 0.0


@pytest.mark.parametrize("level", all_levels("stairs"))
def test_stair_step_height_and_depth_match_level(client: int, level: float) -> None:
    built = build(client, "stairs", level)
    h = level / 100.0
    treads_x = np.array([0.1, 0.5, 0.9, 1.3, 1.7, 2.5, 3.5])  # before, on each of 4 steps, at goal, beyond
    z = ray_heights(client, treads_x, np.array([-0.6, 0.0, 0.6]))
    for row in z:
        np.testing.assert_allclose(row, [0, h, 2 * h, 3 * h, 4 * h, 4 * h, 4 * h], atol=1e-6)
    xs = np.arange(0.0, 2.5, 0.001)
    line = ray_heights(client, xs, np.array([0.0]))[0]
    risers = xs[1:][np.diff(line) > h / 2]
    np.testing.assert_allclose(risers, [0.3, 0.7, 1.1, 1.5], atol=0.002)
    np.testing.assert_allclose(np.diff(risers), 0.4, atol=0.002)  # steps 0.4 m deep
    analytic = np.array([built.height_at(x, 0.0) for x in xs])
    assert np.mean(np.abs(line - analytic) < 1e-6) > 0.99  # equal except within 1 mm of a riser


@pytest.mark.parametrize("kind, level", [("flat", 0), ("rough", 12), ("slopes", 15), ("stairs", 8)])
def test_start_and_goal_lie_on_the_terrain_with_the_obstacle_between(client: int, kind: str, level: float) -> None:
    build(client, kind, level)
    ys = np.linspace(-MAX_LATERAL_M, MAX_LATERAL_M, 17)
    behind_start = ray_heights(client, np.linspace(COURSE_START_X_M + 0.01, OBSTACLE_START_X_M - 0.001, 40), ys)
    np.testing.assert_allclose(behind_start, 0.0, atol=1e-6)  # the robot starts on flat ground at z = 0
    beyond_goal = ray_heights(client, np.linspace(GOAL_X_M, GOAL_X_M + 1.0, 40), ys)
    assert np.ptp(beyond_goal) < 1e-6  # past the goal the ground is level: the obstacle lies before it
    # the ground extends well past the goal and the lateral limit on both sides
    assert COURSE_END_X_M >= GOAL_X_M + 1.0 and COURSE_HALF_WIDTH_M >= MAX_LATERAL_M + 0.5
    everywhere = ray_heights(client, np.linspace(COURSE_START_X_M + 0.01, COURSE_END_X_M - 0.01, 60),
                             np.linspace(-COURSE_HALF_WIDTH_M + 0.01, COURSE_HALF_WIDTH_M - 0.01, 30))
    assert np.all(np.isfinite(everywhere))
    if kind != "flat":
        course = ray_heights(client, np.linspace(OBSTACLE_START_X_M, GOAL_X_M, 200), np.array([0.0]))
        assert np.ptp(course) > 0.01  # and the obstacle is there


def test_unknown_terrain_names_the_valid_ones() -> None:
    with pytest.raises(ValueError, match="valid terrains: flat, rough, slopes, stairs, mixed"):
        make_terrain("sand", 3)


@pytest.mark.parametrize("level", [1, 2, 3])
def test_mixed_course_is_rough_then_slope_then_stairs(client: int, level: int) -> None:
    from hexbench.world.terrain import (
        MIXED_COURSE_LEVELS,
        MIXED_END_X_M,
        MIXED_GOAL_DISTANCE_M,
        MIXED_ROUGH_END_X_M,
        MIXED_SLOPE_START_X_M,
        MIXED_STAIRS_START_X_M,
    )

    rough_cm, slope_deg, stairs_cm = MIXED_COURSE_LEVELS[level]
    built = build(client, "mixed", level, seed=level)
    ys = np.linspace(-MAX_LATERAL_M, MAX_LATERAL_M, 17)
    # rough part: the height difference of its level, flat ground before it
    rough = ray_heights(client, np.arange(OBSTACLE_START_X_M, MIXED_ROUGH_END_X_M, 0.05), ys)
    assert np.ptp(rough) == pytest.approx(rough_cm / 100, abs=0.005)
    np.testing.assert_allclose(ray_heights(client, np.linspace(-0.5, 0.25, 10), ys), 0.0, atol=1e-6)
    # slope part: ascent at its angle, then level ground between slope and stairs
    xs = np.linspace(MIXED_SLOPE_START_X_M + 0.1, MIXED_SLOPE_START_X_M + 0.7, 20)
    line = ray_heights(client, xs, np.array([0.0]))[0]
    assert math.degrees(math.atan(np.polyfit(xs, line, 1)[0])) == pytest.approx(slope_deg, abs=0.2)
    np.testing.assert_allclose(ray_heights(client, np.array([4.3, 4.4]), ys), 0.0, atol=1e-6)
    # stairs part: four steps of its height, the goal on the top landing, ground to the end
    treads = ray_heights(client, MIXED_STAIRS_START_X_M + np.array([0.2, 0.6, 1.0, 1.4]), np.array([0.0]))[0]
    np.testing.assert_allclose(treads, stairs_cm / 100 * np.arange(1, 5), atol=1e-6)
    top = ray_heights(client, np.linspace(MIXED_STAIRS_START_X_M + 1.25, MIXED_END_X_M - 0.05, 20), ys)
    np.testing.assert_allclose(top, 4 * stairs_cm / 100, atol=1e-6)
    assert MIXED_STAIRS_START_X_M + 1.2 < MIXED_GOAL_DISTANCE_M < MIXED_END_X_M - 0.5
    # the analytic height (rewards, recordings) is the surface the physics sees
    xq = np.linspace(-0.5, MIXED_END_X_M - 0.05, 300)
    seen = ray_heights(client, xq, np.array([0.2]))[0]
    analytic = np.array([built.height_at(x, 0.2) for x in xq])
    assert np.mean(np.abs(seen - analytic) < 2e-3) > 0.97  # equal but within ~1 mm of an edge
    assert built.slope_deg_at(MIXED_SLOPE_START_X_M + 0.4) == pytest.approx(slope_deg)


def test_unknown_mixed_level_names_the_valid_ones() -> None:
    with pytest.raises(ValueError, match="valid levels: 1, 2, 3"):
        make_terrain("mixed", 4)


def test_mixed_segment_splits_the_flat_gaps_at_their_middles() -> None:
    from hexbench.world.terrain import (
        MIXED_ROUGH_END_X_M,
        MIXED_SLOPE_START_X_M,
        MIXED_STAIRS_START_X_M,
        SlopesTerrain,
        mixed_segment_at,
    )

    slope_end = SlopesTerrain(14.0, start_x_m=MIXED_SLOPE_START_X_M).breakpoints_m[3]
    first_gap_middle = (MIXED_ROUGH_END_X_M + MIXED_SLOPE_START_X_M) / 2
    second_gap_middle = (slope_end + MIXED_STAIRS_START_X_M) / 2
    assert [mixed_segment_at(x) for x in (0.0, 1.0, first_gap_middle - 1e-6)] == ["rough"] * 3
    assert [mixed_segment_at(x) for x in (first_gap_middle + 1e-6, 3.0, second_gap_middle - 1e-6)] == ["slopes"] * 3
    assert [mixed_segment_at(x) for x in (second_gap_middle + 1e-6, 5.0, 9.0)] == ["stairs"] * 3
