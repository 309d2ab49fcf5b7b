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


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate (..., 3) vectors by (..., 4) xyzw unit quaternions (broadcasting)."""
    u, w = q[..., :3], q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def link_poses(frames: list[JointFrame], base_pos_m: np.ndarray, base_quat_xyzw: np.ndarray,
               angles_rad: np.ndarray, base_link: str = "base") -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """World pose of every link frame: {link: ((n, 3) position, (n, 4) xyzw quaternion)}.

    Forward kinematics over the joints in file order (a parent's joint comes before its
    children's, as in `hexbench.world.robot.urdf_text`), vectorised over the n rows.
    """
    rel = joint_rotations(frames, angles_rad)  # (n, J, 4)
    poses = {base_link: (np.asarray(base_pos_m, dtype=np.float64), np.asarray(base_quat_xyzw, dtype=np.float64))}
    for j, f in enumerate(frames):
        if f.parent_link not in poses:
            raise ValueError(f"joint {f.name}: parent link {f.parent_link} has no pose yet (joints out of order)")
        pos, quat = poses[f.parent_link]
        poses[f.child_link] = (pos + quat_rotate(quat, np.array(f.origin_xyz_m)), quat_multiply(quat, rel[:, j]))
    return poses


@dataclass(frozen=True)
class LinkVisual:
    link: str
    kind: str  # "box" or "sphere"
    origin_xyz_m: tuple[float, float, float]
    origin_quat_xyzw: tuple[float, float, float, float]
    half_size_m: tuple[float, float, float]  # box half sizes; a sphere's radius three times
    rgba: tuple[float, float, float, float]


def link_visuals(urdf: str) -> list[LinkVisual]:
    """The box and sphere <visual> elements of a URDF, in file order (other shapes are skipped)."""
    out = []
    for link in ET.fromstring(urdf).iter("link"):
        for vis in link.findall("visual"):
            origin = vis.find("origin")
            xyz = _floats(origin.get("xyz") if origin is not None else None, (0.0, 0.0, 0.0))
            rpy = _floats(origin.get("rpy") if origin is not None else None, (0.0, 0.0, 0.0))
            color = vis.find("material/color")
            rgba = _floats(color.get("rgba") if color is not None else None, (0.6, 0.6, 0.6, 1.0))
            box, sphere = vis.find("geometry/box"), vis.find("geometry/sphere")
            if box is not None:
                kind, half = "box", tuple(s / 2.0 for s in _floats(box.get("size"), (0.0, 0.0, 0.0)))
            elif sphere is not None:
                kind, half = "sphere", (float(sphere.get("radius")),) * 3
            else:
                continue
            out.append(LinkVisual(link.get("name"), kind, xyz, tuple(quat_from_rpy(*rpy)), half, rgba))
    return out
