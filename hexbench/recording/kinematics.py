"""Joint frames of a URDF and the per-joint transforms for given joint angles (numpy, vectorised).

Both recordings show the robot by its links' frames: world -> base (the base pose) and, for
each revolute joint, parent link -> child link = origin (xyz, rpy) followed by a rotation of
the joint angle about the joint axis (URDF semantics). Quaternions are (x, y, z, w).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class JointFrame:
    name: str
    parent_link: str
    child_link: str
    origin_xyz_m: tuple[float, float, float]
    origin_quat_xyzw: tuple[float, float, float, float]
    axis: tuple[float, float, float]  # unit vector in the child frame


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (..., 4) xyzw quaternions (a then b: R = R_a R_b)."""
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ], axis=-1)


def quat_from_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF rpy (fixed axes x, y, z: R = Rz(yaw) Ry(pitch) Rx(roll)) as an xyzw quaternion."""
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    return np.array([
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    ])


def _floats(text: str | None, default: tuple[float, ...]) -> tuple[float, ...]:
    return tuple(float(v) for v in text.split()) if text else default


def joint_frames(urdf: str) -> list[JointFrame]:
    """The revolute joints of a URDF document, in file order."""
    frames = []
    for j in ET.fromstring(urdf).iter("joint"):
        if j.get("type") not in ("revolute", "continuous"):
            continue
        origin = j.find("origin")
        xyz = _floats(origin.get("xyz") if origin is not None else None, (0.0, 0.0, 0.0))
        rpy = _floats(origin.get("rpy") if origin is not None else None, (0.0, 0.0, 0.0))
        axis_el = j.find("axis")
        axis = np.array(_floats(axis_el.get("xyz") if axis_el is not None else None, (1.0, 0.0, 0.0)))
        axis = axis / np.linalg.norm(axis)
        frames.append(JointFrame(j.get("name"), j.find("parent").get("link"), j.find("child").get("link"),
                                 xyz, tuple(quat_from_rpy(*rpy)), tuple(axis)))
    return frames


def joint_rotations(frames: list[JointFrame], angles_rad: np.ndarray) -> np.ndarray:
    """(n, J) joint angles -> (n, J, 4) parent->child rotations (origin rpy, then the joint rotation)."""
    angles = np.asarray(angles_rad, dtype=np.float64)
    axis = np.array([f.axis for f in frames])  # (J, 3)
    half = angles[..., None] / 2.0
    q_joint = np.concatenate([axis[None] * np.sin(half), np.cos(half)], axis=-1)
    q_origin = np.array([f.origin_quat_xyzw for f in frames])[None]
    return quat_multiply(np.broadcast_to(q_origin, q_joint.shape), q_joint)
