"""Terrain generators: flat, rough, slopes, stairs. Parameters in the paper's units.

Every course runs along +x: the robot starts at the origin on flat ground facing +x and the
goal lies 2.5 m ahead (paper 4.1). The obstacle lies between start and goal:

  rough   random ground on x in [0.3, 2.5] m with maximum height difference h: a 0.2 m coarse
          grid of uniform random heights, bilinearly interpolated to a 0.05 m heightfield,
          tapered to 0 over one coarse cell at both ends and scaled so max - min == h exactly;
  slopes  ascent at angle theta over a 0.8 m run from x = 0.3 m, a 0.6 m flat top, and a
          descent at theta over 0.8 m ending at x = 2.5 m (paper 4.1: ascent, flat, descent);
  stairs  four steps 0.4 m deep, each h high, risers at x = 0.3, 0.7, 1.1, 1.5 m, then a
          landing past the goal (paper 4.1);
  flat    a plane, for sanity checks;
  mixed   the HLTA course: rough ground, then a slope (ascent, top, descent), then stairs, in
          one episode (levels 1-3 of `MIXED_COURSE_LEVELS`; goal 6.3 m ahead, see below).

Each terrain is a frozen dataclass; `build(client, rng)` creates its static bodies in a
PyBullet client and `height_at(x, y)` gives the ground height analytically (the same surface
the physics sees), used for rewards, geometry tests and recordings. Randomness comes only
from the `np.random.Generator` passed to `build`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

COURSE_HALF_WIDTH_M = 1.6  # terrain extent either side of the course centre line [m]
COURSE_START_X_M = -1.0  # terrain extent behind the start [m]
COURSE_END_X_M = 4.0  # terrain extent beyond the start [m]
OBSTACLE_START_X_M = 0.3  # where every obstacle begins [m]
TERRAIN_FRICTION = 0.5

TERRAIN_KINDS: tuple[str, ...] = ("flat", "rough", "slopes", "stairs", "mixed")
LEVEL_UNITS: dict[str, str] = {"flat": "", "rough": "cm", "slopes": "deg", "stairs": "cm", "mixed": ""}

# The mixed course (paper Table 5's question: one policy, or the classifier dispatching three?).
# Level -> (rough height difference [cm], slope angle [deg], step height [cm]); the ranges of
# paper Table 5 (slopes 10-15 deg, stairs 5.5-8 cm) where the rough policy starts to fail.
MIXED_COURSE_LEVELS: dict[int, tuple[float, float, float]] = {1: (6.0, 10.0, 5.0), 2: (8.0, 12.0, 6.0),
                                                              3: (10.0, 14.0, 7.0)}
MIXED_ROUGH_END_X_M = 1.7  # rough ground on [0.3, 1.7] m
MIXED_SLOPE_START_X_M = 2.0  # slope on [2.0, 4.2] m (0.8 m ascent, 0.6 m top, 0.8 m descent)
MIXED_STAIRS_START_X_M = 4.5  # risers at 4.5, 4.9, 5.3, 5.7 m
MIXED_GOAL_DISTANCE_M = 6.3  # 0.6 m onto the top step
MIXED_END_X_M = 7.3  # terrain extent beyond the start [m]


def mixed_segment_at(x_m: float) -> str:
    """The mixed-course segment ("rough", "slopes", "stairs") that x [m] belongs to: the flat gaps
    are split at their middles (rough before 1.85 m, slopes before 4.35 m, stairs after). The
    slope's end (4.2 m) does not depend on its angle: its ramps have a fixed horizontal run."""
    slope_end_x_m = MIXED_SLOPE_START_X_M + 2 * SlopesTerrain.ramp_run_m + SlopesTerrain.top_length_m
    if x_m < (MIXED_ROUGH_END_X_M + MIXED_SLOPE_START_X_M) / 2:
        return "rough"
    if x_m < (slope_end_x_m + MIXED_STAIRS_START_X_M) / 2:
        return "slopes"
    return "stairs"


class Terrain(Protocol):
    kind: str

    def build(self, client: int, rng: np.random.Generator) -> "BuiltTerrain": ...


@dataclass
class BuiltTerrain:
    """A terrain instance in one physics client: its bodies and its exact height function."""

    kind: str
    level: float
    body_ids: list[int]
    heights_m: np.ndarray | None = None  # rough: heightfield [rows=y, cols=x]
    resolution_m: float = 0.05
    _profile: "Terrain | None" = None
    end_x_m: float = COURSE_END_X_M  # terrain extent beyond the start [m]

    def height_at(self, x_m: float, y_m: float) -> float:
        """Ground height [m] under (x, y)."""
        if self.heights_m is not None:
            return _bilinear(self.heights_m, self.resolution_m, x_m, y_m)
        if isinstance(self._profile, _MixedProfile):
            return self._profile.profile_height(x_m, y_m)
        return self._profile.profile_height(x_m) if self._profile is not None else 0.0

    def slope_deg_at(self, x_m: float) -> float:
        """Course slope along +x under x [deg], ascent positive (0 except on slopes)."""
        slope = getattr(self._profile, "profile_slope_deg", None)
        return slope(x_m) if slope is not None else 0.0

    def height_grid(self, resolution_m: float = 0.05) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Heights on a regular grid over the course: (xs [m], ys [m], z [len(ys), len(xs)] [m])."""
        xs = np.arange(COURSE_START_X_M, self.end_x_m + 1e-9, resolution_m)
        ys = np.arange(-COURSE_HALF_WIDTH_M, COURSE_HALF_WIDTH_M + 1e-9, resolution_m)
        z = np.array([[self.height_at(x, y) for x in xs] for y in ys])
        return xs, ys, z


def _bilinear(heights: np.ndarray, res: float, x: float, y: float) -> float:
    rows, cols = heights.shape
    fx = (x - COURSE_START_X_M) / res
    fy = (y + COURSE_HALF_WIDTH_M) / res
    if fx < 0 or fy < 0 or fx > cols - 1 or fy > rows - 1:
        return 0.0
    i0, j0 = min(int(fy), rows - 2), min(int(fx), cols - 2)
    ty, tx = fy - i0, fx - j0
    h = heights
    return float(
        (1 - ty) * ((1 - tx) * h[i0, j0] + tx * h[i0, j0 + 1]) + ty * ((1 - tx) * h[i0 + 1, j0] + tx * h[i0 + 1, j0 + 1])
    )


def _add_static(client: int, shape: int, position: tuple[float, float, float],
                orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)) -> int:
    import pybullet as p

    body = p.createMultiBody(0, shape, -1, position, orientation, physicsClientId=client)
    p.changeDynamics(body, -1, lateralFriction=TERRAIN_FRICTION, physicsClientId=client)
    return body


def _add_plane(client: int, z_m: float = 0.0) -> int:
    import pybullet as p

    shape = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client)
    return _add_static(client, shape, (0.0, 0.0, z_m))


def _add_box(client: int, x0: float, x1: float, z_top: float, thickness: float = 0.5,
             pitch_rad: float = 0.0) -> int:
    """A static box whose top face spans x0..x1 (along its own axis) across the course width."""
    import pybullet as p

    length = x1 - x0
    half = (length / 2, COURSE_HALF_WIDTH_M, thickness / 2)
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
    return _add_static(client, shape, ((x0 + x1) / 2, 0.0, z_top - thickness / 2),
                       tuple(p.getQuaternionFromEuler((0.0, pitch_rad, 0.0))))


@dataclass(frozen=True)
class FlatTerrain:
    kind: str = "flat"
    level: float = 0.0

    def build(self, client: int, rng: np.random.Generator) -> BuiltTerrain:
        return BuiltTerrain(self.kind, self.level, [_add_plane(client)], _profile=self)

    def profile_height(self, x_m: float) -> float:
        return 0.0


@dataclass(frozen=True)
class RoughTerrain:
    """Random ground whose height difference over the course is exactly `height_difference_cm`."""

    height_difference_cm: float
    feature_size_m: float = 0.2  # coarse random grid spacing
    resolution_m: float = 0.05  # heightfield vertex spacing
    end_x_m: float = 2.5
    kind: str = "rough"

    @property
    def level(self) -> float:
        return self.height_difference_cm

    @property
    def obstacle_end_x_m(self) -> float:
        """Where the obstacle ends: flat ground beyond it [m]."""
        return self.end_x_m

    def heights(self, rng: np.random.Generator) -> np.ndarray:
        """The heightfield [m], rows along y and columns along x, on the course grid."""
        res = self.resolution_m
        xs = np.arange(COURSE_START_X_M, COURSE_END_X_M + 1e-9, res)
        ys = np.arange(-COURSE_HALF_WIDTH_M, COURSE_HALF_WIDTH_M + 1e-9, res)
        f = self.feature_size_m
        x0, x1 = OBSTACLE_START_X_M, self.end_x_m
        n_cx = int(math.ceil((x1 - x0) / f)) + 1
        n_cy = int(math.ceil(2 * COURSE_HALF_WIDTH_M / f)) + 1
        coarse = rng.uniform(0.0, 1.0, size=(n_cy, n_cx))
        # bilinear interpolation of the coarse grid at the fine vertices
        cx = np.clip((xs - x0) / f, 0, n_cx - 1)
        cy = np.clip((ys + COURSE_HALF_WIDTH_M) / f, 0, n_cy - 1)
        jx = np.minimum(cx.astype(int), n_cx - 2)
        iy = np.minimum(cy.astype(int), n_cy - 2)
        tx, ty = cx - jx, cy - iy
        c00 = coarse[np.ix_(iy, jx)]
        c01 = coarse[np.ix_(iy, jx + 1)]
        c10 = coarse[np.ix_(iy + 1, jx)]
        c11 = coarse[np.ix_(iy + 1, jx + 1)]
        z = (1 - ty)[:, None] * ((1 - tx)[None, :] * c00 + tx[None, :] * c01) + ty[:, None] * (
            (1 - tx)[None, :] * c10 + tx[None, :] * c11
        )
        # taper to zero over one coarse cell at both ends of the obstacle, zero outside it
        taper = np.clip(np.minimum(xs - x0, x1 - xs) / f, 0.0, 1.0)
        z = z * taper[None, :]
        peak = float(z.max())
        h = self.height_difference_cm / 100.0
        return (z / peak * h) if peak > 0 and h > 0 else np.zeros_like(z)

    def build(self, client: int, rng: np.random.Generator) -> BuiltTerrain:
        import pybullet as p

        heights = self.heights(rng)
        rows, cols = heights.shape
        res = self.resolution_m
        # PyBullet centres a heightfield on the midpoint of its height range; data is row-major with x fastest.
        shape = p.createCollisionShape(
            p.GEOM_HEIGHTFIELD,
            meshScale=[res, res, 1.0],
            heightfieldData=heights.reshape(-1).tolist(),
            numHeightfieldRows=cols,
            numHeightfieldColumns=rows,
            physicsClientId=client,
        )
        centre = (
            (COURSE_START_X_M + COURSE_END_X_M) / 2,
            0.0,
            (float(heights.max()) + float(heights.min())) / 2,
        )
        body = _add_static(client, shape, centre)
        below = _add_plane(client, z_m=-0.02)  # catches anything that leaves the heightfield
        return BuiltTerrain(self.kind, self.level, [body, below], heights_m=heights, resolution_m=res)


@dataclass(frozen=True)
class SlopesTerrain:
    """Ascent, flat top and descent at `angle_deg` (paper 4.1)."""

    angle_deg: float
    ramp_run_m: float = 0.8  # horizontal length of ascent and of descent
    top_length_m: float = 0.6
    start_x_m: float = OBSTACLE_START_X_M  # foot of the ascent
    kind: str = "slopes"

    @property
    def level(self) -> float:
        return self.angle_deg

    @property
    def breakpoints_m(self) -> tuple[float, float, float, float]:
        x0 = self.start_x_m
        x1 = x0 + self.ramp_run_m
        x2 = x1 + self.top_length_m
        return x0, x1, x2, x2 + self.ramp_run_m

    @property
    def obstacle_end_x_m(self) -> float:
        """Foot of the descent: flat ground beyond it [m]."""
        return self.breakpoints_m[-1]

    @property
    def top_height_m(self) -> float:
        return self.ramp_run_m * math.tan(math.radians(self.angle_deg))

    def profile_height(self, x_m: float) -> float:
        x0, x1, x2, x3 = self.breakpoints_m
        t = math.tan(math.radians(self.angle_deg))
        if x_m <= x0 or x_m >= x3:
            return 0.0
        if x_m < x1:
            return (x_m - x0) * t
        if x_m <= x2:
            return self.top_height_m
        return (x3 - x_m) * t

    def profile_slope_deg(self, x_m: float) -> float:
        x0, x1, x2, x3 = self.breakpoints_m
        if x0 < x_m < x1:
            return self.angle_deg
        if x2 < x_m < x3:
            return -self.angle_deg
        return 0.0

    def build(self, client: int, rng: np.random.Generator) -> BuiltTerrain:
        bodies = [_add_plane(client)] + self.build_bodies(client)
        return BuiltTerrain(self.kind, self.level, bodies, _profile=self)

    def build_bodies(self, client: int) -> list[int]:
        """The ramps and the top (no ground under them)."""
        x0, x1, x2, x3 = self.breakpoints_m
        top = self.top_height_m
        theta = math.radians(self.angle_deg)
        thick = 0.3
        bodies = []
        if top > 0:
            # A tilted box whose top face runs along the ramp: rotate about y by -theta
            # (positive pitch about +y tips +x downwards), centred below the ramp midpoint.
            ramp_len = self.ramp_run_m / math.cos(theta)
            for sign, (xa, xb) in ((1.0, (x0, x1)), (-1.0, (x2, x3))):
                mid_x, mid_z = (xa + xb) / 2, top / 2
                nx, nz = -sign * math.sin(theta), math.cos(theta)  # top-face normal
                cx, cz = mid_x - nx * thick / 2, mid_z - nz * thick / 2
                bodies.append(_add_box(client, cx - ramp_len / 2, cx + ramp_len / 2, cz + thick / 2,
                                       thickness=thick, pitch_rad=-sign * theta))
            bodies.append(_add_box(client, x1, x2, top, thickness=top))
        return bodies


@dataclass(frozen=True)
class StairsTerrain:
    """Four steps 0.4 m deep, each `step_height_cm` high (paper 4.1), then a landing."""

    step_height_cm: float
    step_depth_m: float = 0.4
    num_steps: int = 4
    start_x_m: float = OBSTACLE_START_X_M  # first riser
    end_x_m: float = COURSE_END_X_M  # end of the top landing
    kind: str = "stairs"

    @property
    def level(self) -> float:
        return self.step_height_cm

    def riser_x_m(self, k: int) -> float:
        return self.start_x_m + k * self.step_depth_m

    @property
    def obstacle_end_x_m(self) -> float:
        """One step depth past the last riser: the top landing beyond it [m]."""
        return self.riser_x_m(self.num_steps - 1) + self.step_depth_m

    def profile_height(self, x_m: float) -> float:
        h = self.step_height_cm / 100.0
        steps_up = sum(1 for k in range(self.num_steps) if x_m >= self.riser_x_m(k))
        return steps_up * h

    def build(self, client: int, rng: np.random.Generator) -> BuiltTerrain:
        bodies = [_add_plane(client)] + self.build_bodies(client)
        return BuiltTerrain(self.kind, self.level, bodies, _profile=self)

    def build_bodies(self, client: int) -> list[int]:
        """The steps (no ground under them)."""
        h = self.step_height_cm / 100.0
        if h <= 0:
            return []
        return [_add_box(client, self.riser_x_m(k), self.end_x_m, (k + 1) * h, thickness=(k + 1) * h)
                for k in range(self.num_steps)]


@dataclass(frozen=True)
class MixedCourse:
    """Rough ground, a slope and stairs in one course (the HLTA task); `level` indexes MIXED_COURSE_LEVELS."""

    course_level: int

    kind: str = "mixed"

    def __post_init__(self) -> None:
        if self.course_level not in MIXED_COURSE_LEVELS:
            raise ValueError(f"unknown mixed course level {self.course_level!r}; valid levels: "
                             f"{', '.join(str(k) for k in MIXED_COURSE_LEVELS)}")

    @property
    def level(self) -> float:
        return float(self.course_level)

    @property
    def parts(self) -> tuple[RoughTerrain, SlopesTerrain, StairsTerrain]:
        rough_cm, slope_deg, stairs_cm = MIXED_COURSE_LEVELS[self.course_level]
        return (RoughTerrain(rough_cm, end_x_m=MIXED_ROUGH_END_X_M),
                SlopesTerrain(slope_deg, start_x_m=MIXED_SLOPE_START_X_M),
                StairsTerrain(stairs_cm, start_x_m=MIXED_STAIRS_START_X_M, end_x_m=MIXED_END_X_M))

    @property
    def obstacle_end_x_m(self) -> float:
        """The end of its last obstacle, the stairs [m]."""
        return self.parts[-1].obstacle_end_x_m

    def build(self, client: int, rng: np.random.Generator) -> BuiltTerrain:
        rough, slope, stairs = self.parts
        rough_built = rough.build(client, rng)  # heightfield over [COURSE_START_X_M, COURSE_END_X_M], 0 past the rough part
        ground_beyond = _add_box(client, COURSE_END_X_M, MIXED_END_X_M, 0.0, thickness=0.1)
        bodies = rough_built.body_ids + [ground_beyond] + slope.build_bodies(client) + stairs.build_bodies(client)
        return BuiltTerrain(self.kind, self.level, bodies, _profile=_MixedProfile(rough_built, slope, stairs),
                            end_x_m=MIXED_END_X_M)


@dataclass(frozen=True)
class _MixedProfile:
    """Ground height and slope of a built mixed course: the heightfield before the slope, then the profiles."""

    rough: BuiltTerrain
    slope: SlopesTerrain
    stairs: StairsTerrain

    def profile_height(self, x_m: float, y_m: float = 0.0) -> float:
        if x_m < (MIXED_ROUGH_END_X_M + MIXED_SLOPE_START_X_M) / 2:
            return self.rough.height_at(x_m, y_m)
        return self.slope.profile_height(x_m) + self.stairs.profile_height(x_m)

    def profile_slope_deg(self, x_m: float) -> float:
        return self.slope.profile_slope_deg(x_m)


def make_terrain(kind: str, level: float) -> Terrain:
    """The terrain of `kind` at `level` in the paper's units (cm for rough and stairs, deg for slopes)."""
    if kind == "flat":
        return FlatTerrain()
    if kind == "rough":
        return RoughTerrain(height_difference_cm=float(level))
    if kind == "slopes":
        return SlopesTerrain(angle_deg=float(level))
    if kind == "stairs":
        return StairsTerrain(step_height_cm=float(level))
    if kind == "mixed":
        if float(level) != int(level):
            raise ValueError(f"unknown mixed course level {level!r}; valid levels: "
                             f"{', '.join(str(k) for k in MIXED_COURSE_LEVELS)}")
        return MixedCourse(course_level=int(level))
    raise ValueError(f"unknown terrain {kind!r}; valid terrains: {', '.join(TERRAIN_KINDS)}")
