"""One dataset image: a terrain instance seen from the JetHexa's own camera.

A *terrain instance* is (class, level, ground colour, terrain rng seed): for rough ground the seed
also fixes the random heightfield; slopes and stairs are fully fixed by their level. Each instance is
photographed from several robot poses (distance to the obstacle, lateral offset, heading), always
standing on the flat approach in front of the obstacle, which is what the HLTA layer sees before it
picks a policy.

Rendering: PyBullet's TinyRenderer through `hexbench.world.camera.robot_camera_image` with a directional
light (`TERRAIN_CAMERA`); every terrain body is repainted one plain colour (the default checker
texture is replaced by a white texel) so the only cue is the shading of the geometry. The colour is
drawn from the same distribution for every class, so it carries no label information.
"""

from __future__ import annotations

import colorsys
import io
import math
from dataclasses import asdict, dataclass
from functools import lru_cache

import numpy as np

from hexbench.world.camera import CameraSpec, Lighting

TERRAIN_CLASSES: tuple[str, ...] = ("rough", "slopes", "stairs")

# Levels sampled uniformly, in the paper's units: Table 4 evaluation levels, the curriculum's
# training range and the protocol's headroom levels, so every level the HLTA layer meets is covered.
LEVEL_RANGES: dict[str, tuple[float, float]] = {
    "rough": (3.0, 16.0),  # height difference [cm]
    "slopes": (5.0, 24.0),  # angle [deg]
    "stairs": (2.0, 10.0),  # step height [cm]
}

TERRAIN_CAMERA = CameraSpec(width_px=96, height_px=72, fov_deg=70.0, pitch_down_deg=25.0,
                            lighting=Lighting(direction=(-1.0, 0.4, 0.5), ambient=0.25, diffuse=0.75))


@dataclass(frozen=True)
class PoseRanges:
    """Where the robot stands when it takes a picture (always on the flat approach)."""

    distance_to_obstacle_m: tuple[float, float] = (0.1, 0.8)  # obstacle starts at x = 0.3 m
    lateral_offset_m: tuple[float, float] = (-0.4, 0.4)
    heading_deg: tuple[float, float] = (-25.0, 25.0)


@dataclass(frozen=True)
class TerrainInstance:
    terrain: str
    level: float  # paper units (cm or deg)
    terrain_seed: int  # seeds the terrain generator (the rough heightfield)
    ground_rgb: tuple[float, float, float]  # [0, 1]


@dataclass(frozen=True)
class View:
    instance: TerrainInstance
    base_x_m: float
    base_y_m: float
    heading_deg: float

    def record(self) -> dict:
        """Flat JSON-able description (for the manifest)."""
        d = asdict(self.instance)
        d["ground_rgb"] = [round(c, 6) for c in self.instance.ground_rgb]
        d.update(base_x_m=self.base_x_m, base_y_m=self.base_y_m, heading_deg=self.heading_deg)
        return d


def sample_instance(terrain: str, rng: np.random.Generator) -> TerrainInstance:
    """A terrain instance of class `terrain`: level, colour and terrain seed drawn from `rng`."""
    if terrain not in LEVEL_RANGES:
        raise ValueError(f"unknown terrain class {terrain!r}; valid: {', '.join(TERRAIN_CLASSES)}")
    lo, hi = LEVEL_RANGES[terrain]
    level = round(float(rng.uniform(lo, hi)), 3)
    hue, sat, val = rng.uniform(0.0, 1.0), rng.uniform(0.0, 0.6), rng.uniform(0.45, 0.95)
    rgb = tuple(round(c, 6) for c in colorsys.hsv_to_rgb(hue, sat, val))
    return TerrainInstance(terrain, level, int(rng.integers(0, 2**63 - 1)), rgb)


def sample_views(instance: TerrainInstance, count: int, rng: np.random.Generator,
                 poses: PoseRanges = PoseRanges()) -> list[View]:
    from hexbench.world.terrain import OBSTACLE_START_X_M

    views = []
    for _ in range(count):
        distance = float(rng.uniform(*poses.distance_to_obstacle_m))
        views.append(View(instance, round(OBSTACLE_START_X_M - distance, 4),
                          round(float(rng.uniform(*poses.lateral_offset_m)), 4),
                          round(float(rng.uniform(*poses.heading_deg)), 3)))
    return views


@lru_cache(maxsize=1)
def _white_texture_file() -> str:
    """A 4x4 white PNG (PyBullet loads textures from files only)."""
    from PIL import Image

    from hexbench.world.sim import process_file

    png = io.BytesIO()
    Image.fromarray(np.full((4, 4, 3), 255, np.uint8)).save(png, format="PNG")
    return process_file("hexbench_white_", ".png", png.getvalue(), "a terrain texture")


def paint_terrain(sim, rgb: tuple[float, float, float]) -> None:
    """Repaint every terrain body of `sim` in one plain colour (replaces the checker texture)."""
    import pybullet as p

    texture = p.loadTexture(_white_texture_file(), physicsClientId=sim.client)
    for body in sim.terrain.body_ids:
        p.changeVisualShape(body, -1, rgbaColor=[*rgb, 1.0], textureUniqueId=texture, physicsClientId=sim.client)


def render_view(sim, view: View, camera: CameraSpec = TERRAIN_CAMERA) -> np.ndarray:
    """Load the view's terrain instance and robot pose into `sim` and return the camera image (H, W, 3) uint8."""
    from hexbench.world.camera import robot_camera_image
    from hexbench.world.terrain import make_terrain

    inst = view.instance
    sim.load(make_terrain(inst.terrain, inst.level), np.random.default_rng(inst.terrain_seed),
             (view.base_x_m, view.base_y_m), math.radians(view.heading_deg))
    paint_terrain(sim, inst.ground_rgb)
    return robot_camera_image(sim, camera)
