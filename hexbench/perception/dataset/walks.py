"""Walk views (terrain-images version 2): the robot's camera while it walks a terrain or the mixed course.

Version 1 photographs each obstacle only from the flat approach in front of it; the HLTA layer also
looks from on top of rough ground, from a ramp, from the slope's top and from between stairs. A
*walk* is one episode of the open-loop CPG (a_r = 0, no observation noise) on one terrain
instance, with a wide start jitter (position and heading), photographed every
`image_every_steps` control steps from a random phase on, until the episode ends (goal, fall,
lateral deviation, stall or step limit). Failing walks are kept: a falling or stalled robot is
part of what the HLTA layer sees.

Label rule, written into every manifest row as `label_rule`:
  * a single-terrain walk (rough, slopes or stairs at a level drawn from LEVEL_RANGES): the
    walk's terrain, at every step (there is no other terrain on that course);
  * a mixed-course walk (levels 1-3): the course segment under the point `lookahead_m` (0.4 m)
    ahead of the base along x (`hexbench.world.terrain.mixed_segment_at`), the rule
    `bench/hlta_course_labels.py` scores the classifier by.

Which frames become images (version 2.1.0; 2.0.0 kept every frame):
  * none once the look-ahead point has passed the end of the walk's last obstacle
    (`obstacle_end_x_m` of the terrain: the foot of the descent, one step past the last riser,
    the end of the rough ground): the camera then shows the flat ground beyond, which is no
    terrain class, and 2.0.0's classifier took such frames for a slope;
  * none whose pose is within `min_image_spacing_m` and `min_image_turn_deg` of an image the walk
    already took: a robot stalled in front of a riser it cannot climb gave some twenty
    near-identical frames of one riser face (its heading rocking +-11 deg with the gait, so that
    every second frame repeats), one view weighted twenty times.

Every walk is a pure function of (dataset seed, kind, walk index): its level, episode seed,
ground colour and image phase come from `np.random.default_rng([seed, WALK_STREAM, kind, index])`.
The episode seed rebuilds the terrain (the rough heightfield) and the start pose; the physics is
deterministic, so the same seed renders the same images.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np

from hexbench.perception.views import TERRAIN_CAMERA, TERRAIN_CLASSES, paint_terrain

WALK_KINDS: tuple[str, ...] = (*TERRAIN_CLASSES, "mixed")
WALK_STREAM = 2_000_003  # rng stream id of the walks (the approach views use [seed, class, instance])
WALK_SPLIT_STREAM = 2_000_029  # rng stream id of the walks' train/test assignment
MIXED_LEVELS: tuple[int, ...] = (1, 2, 3)
LABEL_RULE_SINGLE = "walk terrain"
LABEL_RULE_MIXED = "mixed segment under base x + lookahead"


@dataclass(frozen=True)
class WalkConfig:
    """How many walks of each kind, and how they are run and photographed."""

    walks_per_terrain: int = 60  # per single terrain (rough, slopes, stairs); 2.0.0: 20
    mixed_walks: int = 24  # mixed course, spread evenly over its levels 1-3
    image_every_steps: int = 60  # control steps between images [1/60 s] (the evaluator: 30)
    lookahead_m: float = 0.4  # mixed-course label: the segment this far ahead of the base
    start_xy_jitter_m: float = 0.25  # uniform +- start position (the protocol: 0.02)
    start_yaw_jitter_rad: float = 0.35  # uniform +- start heading, about 20 deg (the protocol: 0.05) ...
    start_yaw_jitter_mixed_rad: float = 0.12  # ... about 7 deg on the 6.3 m mixed course, so walks reach its end
    max_lateral_deviation_m: float = 1.4  # the terrain is 1.6 m wide either side (the protocol ends at 0.8 m)
    max_steps_single: int = 4000  # episode rules as protocol v1: 66.7 s, 2.5 m goal ...
    max_steps_mixed: int = 8000  # ... and 8000 steps, 6.3 m goal on the mixed course
    stall_window_s: float = 20.0  # a walk that advances less than 5 cm in 20 s ends (protocol v1)
    stop_past_obstacle: bool = True  # no images once base x + lookahead_m is past the last obstacle (2.1.0)
    min_image_spacing_m: float = 0.03  # a frame within this distance [m] ...
    min_image_turn_deg: float = 5.0  # ... and heading [deg] of an earlier image is skipped (2.1.0; 0, 0: none)
    test_fraction: float = 0.2

    def __post_init__(self) -> None:
        if self.walks_per_terrain < 0 or self.mixed_walks < 0:
            raise ValueError("walk counts must be >= 0")
        if self.image_every_steps < 1:
            raise ValueError(f"image_every_steps must be >= 1, got {self.image_every_steps}")
        if self.min_image_spacing_m < 0 or self.min_image_turn_deg < 0:
            raise ValueError("min_image_spacing_m and min_image_turn_deg must be >= 0")

    def count(self, kind: str) -> int:
        return self.mixed_walks if kind == "mixed" else self.walks_per_terrain

    def test_walks(self, kind: str) -> int:
        n = self.count(kind)
        return 0 if n < 2 else min(n - 1, max(1, round(self.test_fraction * n)))


@dataclass(frozen=True)
class Walk:
    kind: str  # rough, slopes, stairs or mixed
    index: int
    level: float  # paper units; the mixed course: 1, 2 or 3
    episode_seed: int  # HexapodEnv.reset(seed=...): terrain instance and start pose
    ground_rgb: tuple[float, float, float]
    image_phase_steps: int  # first image at this control step
    split: str

    @property
    def name(self) -> str:
        return f"walk-{self.kind}_{self.index:04d}"


@dataclass(frozen=True)
class WalkImage:
    walk: Walk
    step: int  # control step of the episode
    base_x_m: float
    base_y_m: float
    heading_deg: float
    label: str
    image: np.ndarray  # (H, W, 3) uint8

    def record(self, lookahead_m: float) -> dict:
        w = self.walk
        return {"view_kind": "walk", "walk_kind": w.kind, "walk": w.index, "level": w.level,
                "terrain_seed": w.episode_seed, "ground_rgb": [round(c, 6) for c in w.ground_rgb],
                "step": self.step, "base_x_m": round(self.base_x_m, 4), "base_y_m": round(self.base_y_m, 4),
                "heading_deg": round(self.heading_deg, 3),
                "label_rule": LABEL_RULE_MIXED if w.kind == "mixed" else LABEL_RULE_SINGLE,
                **({"lookahead_m": lookahead_m} if w.kind == "mixed" else {})}


def plan_walks(seed: int, config: WalkConfig) -> list[Walk]:
    """Every walk of the build, in a fixed order, without simulating anything."""
    from hexbench.perception.views import sample_instance

    walks = []
    for c, kind in enumerate(WALK_KINDS):
        n = config.count(kind)
        split_rng = np.random.default_rng([seed, WALK_SPLIT_STREAM, c])
        test_ids = set(split_rng.permutation(n)[: config.test_walks(kind)].tolist()) if n else set()
        for k in range(n):
            rng = np.random.default_rng([seed, WALK_STREAM, c, k])
            if kind == "mixed":
                level, rgb = float(MIXED_LEVELS[k % len(MIXED_LEVELS)]), sample_instance("rough", rng).ground_rgb
            else:
                instance = sample_instance(kind, rng)  # level uniform over LEVEL_RANGES, colour as version 1
                level, rgb = instance.level, instance.ground_rgb
            walks.append(Walk(kind, k, level, int(rng.integers(0, 2**31 - 1)), rgb,
                              int(rng.integers(0, config.image_every_steps)), "test" if k in test_ids else "train"))
    return walks


def walk_env_config(walk: Walk, config: WalkConfig):
    from hexbench.world.env import NO_NOISE, EnvConfig
    from hexbench.world.terrain import MIXED_GOAL_DISTANCE_M

    mixed = walk.kind == "mixed"
    return EnvConfig(terrain=walk.kind, level=walk.level, action_mode="cpg_residual", noise=NO_NOISE,
                     max_steps=config.max_steps_mixed if mixed else config.max_steps_single,
                     goal_distance_m=MIXED_GOAL_DISTANCE_M if mixed else 2.5,
                     max_lateral_deviation_m=config.max_lateral_deviation_m,
                     stall_window_s=config.stall_window_s, init_xy_jitter_m=config.start_xy_jitter_m,
                     init_yaw_jitter_rad=config.start_yaw_jitter_mixed_rad if mixed else config.start_yaw_jitter_rad)


def cpg_camera_shots(env, every_steps: int, phase_steps: int = 0, camera=TERRAIN_CAMERA) -> Iterator[tuple]:
    """Walk a freshly reset `env` with the open-loop CPG (a_r = 0) until its episode ends, yielding
    (control step, robot state, camera image) at `phase_steps` and every `every_steps` after it.
    The one camera loop of the walk views and of bench/hlta_course_labels.py."""
    from hexbench.world.camera import robot_camera_image

    zero = np.zeros(env.action_space.shape, np.float32)
    step, done = 0, False
    while not done:
        if step >= phase_steps and (step - phase_steps) % every_steps == 0:
            yield step, env.robot_state, robot_camera_image(env.sim, camera)
        _, _, terminated, truncated, _ = env.step(zero)
        done = terminated or truncated
        step += 1


def walk_images(walk: Walk, config: WalkConfig) -> Iterator[WalkImage]:
    """Run the walk and yield its images in step order (the frames the rules above keep)."""

    from hexbench.world.env import HexapodEnv
    from hexbench.world.terrain import make_terrain, mixed_segment_at

    env = HexapodEnv(walk_env_config(walk, config))
    obstacle_end_x_m = make_terrain(walk.kind, walk.level).obstacle_end_x_m
    taken: list[tuple[float, float, float]] = []  # (x [m], y [m], heading [deg]) of every image so far
    try:
        env.reset(seed=walk.episode_seed)
        paint_terrain(env.sim, walk.ground_rgb)
        for step, state, image in cpg_camera_shots(env, config.image_every_steps, walk.image_phase_steps):
            x, y = float(state.base_pos_m[0]), float(state.base_pos_m[1])
            heading_deg = math.degrees(float(state.values[63]))
            if config.stop_past_obstacle and x + config.lookahead_m > obstacle_end_x_m:
                return
            if any(_near_identical(pose, (x, y, heading_deg), config) for pose in taken):
                continue
            taken.append((x, y, heading_deg))
            label = mixed_segment_at(x + config.lookahead_m) if walk.kind == "mixed" else walk.kind
            yield WalkImage(walk, step, x, y, heading_deg, label, image)
    finally:
        env.close()


def _near_identical(a: tuple[float, float, float], b: tuple[float, float, float], config: WalkConfig) -> bool:
    turn_deg = abs((b[2] - a[2] + 180.0) % 360.0 - 180.0)
    return (math.hypot(b[0] - a[0], b[1] - a[1]) < config.min_image_spacing_m
            and turn_deg < config.min_image_turn_deg)


def render_walks(walks: list[Walk], config: WalkConfig,
                 on_walk: Callable[[int, int], None] | None = None) -> Iterator[WalkImage]:
    """Every image of `walks`, walk after walk; `on_walk(done, total)` after each walk."""
    for i, walk in enumerate(walks):
        yield from walk_images(walk, config)
        if on_walk is not None:
            on_walk(i + 1, len(walks))
