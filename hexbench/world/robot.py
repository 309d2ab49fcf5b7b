"""The simulated JetHexa hexapod: body parameters as a frozen dataclass, rendered to URDF text.

Frames: body x forward, y left, z up. Each leg has a hip (yaw, about z), knee (femur pitch)
and ankle (tibia pitch) joint. Joint order is the paper's leg order RF, RM, RB, LB, LM, LF,
each leg as (hip, knee, ankle): 18 joints.

Sign convention, the same for all six legs (so one CPG output means the same on every leg):
  hip   > 0: foot moves forward (+x);
  knee  > 0: femur lifts (foot up);
  ankle > 0: tibia swings outward; < 0 folds it in under the femur.
At all-zero joint angles the robot stands: coxa and femur horizontal, pointing outward, and
the tibia vertical, so the body stands on the tibia length.

Where the numbers come from (see also docs/robot.md):
  coxa 5 cm, femur 8 cm, tibia 13 cm, total mass 2.5 kg, body centre of mass ~12 cm high,
  overall length 39.7 cm and width 42.6 cm with legs: paper Table 3.
  Servo stall torque 3.5 N m and no-load speed ~6 rad/s: JetHexa uses Hiwonder HX-35H class
  bus servos (35 kg cm stall at 7.4 V ~= 3.4 N m, 0.18 s / 60 deg ~= 5.8 rad/s).
  Mass split, leg mount points and joint limits: our estimates from JetHexa photos and
  drawings. The overall footprint at the zero stance is 44.4 x 44.0 cm, larger than Table 3's
  39.7 x 42.6 cm (a known mismatch, kept for protocol v1; see docs/robot.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

LEG_NAMES: tuple[str, ...] = ("RF", "RM", "RB", "LB", "LM", "LF")
JOINT_KINDS: tuple[str, ...] = ("hip", "knee", "ankle")
JOINT_NAMES: tuple[str, ...] = tuple(f"{leg}_{kind}" for leg in LEG_NAMES for kind in JOINT_KINDS)
NUM_JOINTS = len(JOINT_NAMES)  # 18
FOOT_LINK_NAMES: tuple[str, ...] = tuple(f"{leg}_tibia" for leg in LEG_NAMES)


@dataclass(frozen=True)
class LegMount:
    """Where a leg attaches to the body and which way it points."""

    x_m: float  # mount point, body frame [m]
    y_m: float  # [m]
    yaw_rad: float  # outward direction of the leg at hip angle 0 [rad]


def _default_mounts() -> tuple[LegMount, ...]:
    d = math.radians
    return (
        LegMount(0.12, -0.06, d(-45.0)),  # RF
        LegMount(0.00, -0.08, d(-90.0)),  # RM
        LegMount(-0.12, -0.06, d(-135.0)),  # RB
        LegMount(-0.12, 0.06, d(135.0)),  # LB
        LegMount(0.00, 0.08, d(90.0)),  # LM
        LegMount(0.12, 0.06, d(45.0)),  # LF
    )


@dataclass(frozen=True)
class JetHexaSpec:
    """Body, leg and servo parameters of the JetHexa (paper Table 3 plus servo data)."""

    coxa_length_m: float = 0.05
    femur_length_m: float = 0.08
    tibia_length_m: float = 0.13  # knee-to-sole, foot sphere included
    foot_radius_m: float = 0.01
    body_size_m: tuple[float, float, float] = (0.26, 0.14, 0.05)  # length, width, height
    hip_height_above_body_centre_m: float = 0.01
    body_mass_kg: float = 1.60
    coxa_mass_kg: float = 0.04
    femur_mass_kg: float = 0.05
    tibia_mass_kg: float = 0.06  # foot included
    mounts: tuple[LegMount, ...] = field(default_factory=_default_mounts)
    hip_limits_rad: tuple[float, float] = (-0.8, 0.8)
    knee_limits_rad: tuple[float, float] = (-0.8, 1.5)
    ankle_limits_rad: tuple[float, float] = (-1.5, 0.8)
    servo_stall_torque_nm: float = 3.5
    servo_max_speed_rad_per_s: float = 6.0
    servo_position_gain: float = 0.3  # PyBullet POSITION_CONTROL kp (dimensionless)
    servo_velocity_gain: float = 1.0  # PyBullet POSITION_CONTROL kd (dimensionless)
    foot_friction: float = 1.0

    @property
    def total_mass_kg(self) -> float:
        return self.body_mass_kg + 6 * (self.coxa_mass_kg + self.femur_mass_kg + self.tibia_mass_kg)

    @property
    def standing_base_height_m(self) -> float:
        """Body-centre height above flat ground at the all-zero stance (before servo sag)."""
        return self.tibia_length_m - self.hip_height_above_body_centre_m

    def joint_limits_rad(self) -> tuple[tuple[float, float], ...]:
        per_leg = (self.hip_limits_rad, self.knee_limits_rad, self.ankle_limits_rad)
        return tuple(per_leg[i % 3] for i in range(NUM_JOINTS))

    def hip_axis_sign(self, leg_index: int) -> float:
        """+1 for right legs, -1 for left legs, so that hip > 0 moves every foot forward."""
        return 1.0 if LEG_NAMES[leg_index].startswith("R") else -1.0


def _box_inertia(mass: float, sx: float, sy: float, sz: float) -> tuple[float, float, float]:
    return (
        mass * (sy * sy + sz * sz) / 12.0,
        mass * (sx * sx + sz * sz) / 12.0,
        mass * (sx * sx + sy * sy) / 12.0,
    )


def _inertial(mass: float, xyz: tuple[float, float, float], size: tuple[float, float, float]) -> str:
    ixx, iyy, izz = _box_inertia(mass, *size)
    x, y, z = xyz
    return (
        f'<inertial><origin xyz="{x:.5f} {y:.5f} {z:.5f}"/><mass value="{mass:.5f}"/>'
        f'<inertia ixx="{ixx:.3e}" ixy="0" ixz="0" iyy="{iyy:.3e}" iyz="0" izz="{izz:.3e}"/></inertial>'
    )


def _box_geometry(xyz: tuple[float, float, float], size: tuple[float, float, float], rgba: str) -> str:
    x, y, z = xyz
    sx, sy, sz = size
    origin = f'<origin xyz="{x:.5f} {y:.5f} {z:.5f}"/>'
    geom = f'<geometry><box size="{sx:.5f} {sy:.5f} {sz:.5f}"/></geometry>'
    return (
        f'<visual>{origin}{geom}<material name="c{rgba.replace(" ", "_")}"><color rgba="{rgba}"/></material></visual>'
        f"<collision>{origin}{geom}</collision>"
    )


def urdf_text(spec: JetHexaSpec = JetHexaSpec()) -> str:
    """Render the robot as URDF (primitive boxes and spheres only: fast in PyBullet)."""
    bl, bw, bh = spec.body_size_m
    links: list[str] = []
    joints: list[str] = []
    links.append(
        '<link name="base">'
        + _inertial(spec.body_mass_kg, (0, 0, 0), spec.body_size_m)
        + _box_geometry((0, 0, 0), spec.body_size_m, "0.2 0.2 0.25 1")
        + "</link>"
    )
    limits = (spec.hip_limits_rad, spec.knee_limits_rad, spec.ankle_limits_rad)
    effort = spec.servo_stall_torque_nm
    vel = spec.servo_max_speed_rad_per_s
    thick = 0.02  # cross-section of coxa and femur links [m]
    for i, (leg, mount) in enumerate(zip(LEG_NAMES, spec.mounts)):
        coxa, femur, tibia = f"{leg}_coxa", f"{leg}_femur", f"{leg}_tibia"
        lc, lf, lt = spec.coxa_length_m, spec.femur_length_m, spec.tibia_length_m
        sole_to_centre = lt - spec.foot_radius_m
        links.append(
            f'<link name="{coxa}">'
            + _inertial(spec.coxa_mass_kg, (lc / 2, 0, 0), (lc, thick, thick))
            + _box_geometry((lc / 2, 0, 0), (lc, thick, thick), "0.6 0.6 0.6 1")
            + "</link>"
        )
        links.append(
            f'<link name="{femur}">'
            + _inertial(spec.femur_mass_kg, (lf / 2, 0, 0), (lf, thick, thick))
            + _box_geometry((lf / 2, 0, 0), (lf, thick, thick), "0.1 0.4 0.8 1")
            + "</link>"
        )
        tib_w = 0.016
        r = spec.foot_radius_m
        foot = (
            f'<origin xyz="0 0 {-sole_to_centre:.5f}"/><geometry><sphere radius="{r:.5f}"/></geometry>'
        )
        links.append(
            f'<link name="{tibia}">'
            + _inertial(spec.tibia_mass_kg, (0, 0, -sole_to_centre / 2), (tib_w, tib_w, sole_to_centre))
            + _box_geometry((0, 0, -sole_to_centre / 2), (tib_w, tib_w, sole_to_centre), "0.1 0.4 0.8 1")
            + f'<visual>{foot}<material name="foot"><color rgba="0.1 0.1 0.1 1"/></material></visual>'
            + f"<collision>{foot}</collision>"
            + "</link>"
        )
        hip_axis = spec.hip_axis_sign(i)
        mz = spec.hip_height_above_body_centre_m
        joint_defs = (
            (f"{leg}_hip", "base", coxa, f"{mount.x_m:.5f} {mount.y_m:.5f} {mz:.5f}",
             f"0 0 {mount.yaw_rad:.6f}", f"0 0 {hip_axis:.0f}", limits[0]),
            (f"{leg}_knee", coxa, femur, f"{lc:.5f} 0 0", "0 0 0", "0 -1 0", limits[1]),
            (f"{leg}_ankle", femur, tibia, f"{lf:.5f} 0 0", "0 0 0", "0 -1 0", limits[2]),
        )
        for name, parent, child, xyz, rpy, axis, (lo, hi) in joint_defs:
            joints.append(
                f'<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
                f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>'
                f'<limit lower="{lo:.4f}" upper="{hi:.4f}" effort="{effort:.3f}" velocity="{vel:.3f}"/>'
                f'<dynamics damping="0.01" friction="0.0"/></joint>'
            )
    body = "\n".join(links + joints)
    return f'<?xml version="1.0"?>\n<robot name="jethexa">\n{body}\n</robot>\n'
