"""Camera images from PyBullet's CPU renderer (TinyRenderer: no GPU, no display needed).

`robot_camera_image` is the JetHexa's own camera (paper 3.1: the HLTA layer classifies the
terrain from it): mounted at the front of the body, looking ahead and down at the ground the
robot is about to walk on. `follow_camera_image` is a third-person view for `render()`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pybullet as p

from hexbench.world.sim import Simulation


@dataclass(frozen=True)
class Lighting:
    """A directional light for TinyRenderer (without one, its default light shades slopes and flat ground alike)."""

    direction: tuple[float, float, float] = (-1.0, 0.4, 0.5)  # world frame, towards the light
    ambient: float = 0.25
    diffuse: float = 0.75
    specular: float = 0.0


@dataclass(frozen=True)
class CameraSpec:
    width_px: int = 128
    height_px: int = 96
    fov_deg: float = 70.0
    mount_forward_m: float = 0.13  # ahead of the body centre
    mount_up_m: float = 0.06  # above the body centre
    pitch_down_deg: float = 30.0
    near_m: float = 0.02
    far_m: float = 5.0
    lighting: Lighting | None = None  # None: TinyRenderer's default light


def _render(client: int, eye, target, up, spec: CameraSpec) -> np.ndarray:
    view = p.computeViewMatrix(eye, target, up, physicsClientId=client)
    proj = p.computeProjectionMatrixFOV(spec.fov_deg, spec.width_px / spec.height_px, spec.near_m, spec.far_m,
                                        physicsClientId=client)
    light = {} if spec.lighting is None else dict(
        lightDirection=list(spec.lighting.direction), lightAmbientCoeff=spec.lighting.ambient,
        lightDiffuseCoeff=spec.lighting.diffuse, lightSpecularCoeff=spec.lighting.specular)
    _, _, rgba, _, _ = p.getCameraImage(spec.width_px, spec.height_px, view, proj,
                                        renderer=p.ER_TINY_RENDERER, physicsClientId=client, **light)
    return np.asarray(rgba, dtype=np.uint8).reshape(spec.height_px, spec.width_px, 4)[:, :, :3].copy()


def robot_camera_image(sim: Simulation, spec: CameraSpec = CameraSpec()) -> np.ndarray:
    """RGB image (H, W, 3) uint8 from the body-mounted camera."""
    pos, quat = p.getBasePositionAndOrientation(sim.robot_id, physicsClientId=sim.client)
    rot = np.array(p.getMatrixFromQuaternion(quat)).reshape(3, 3)
    forward, up = rot[:, 0], rot[:, 2]
    eye = np.array(pos) + spec.mount_forward_m * forward + spec.mount_up_m * up
    pitch = math.radians(spec.pitch_down_deg)
    look = math.cos(pitch) * forward - math.sin(pitch) * up
    return _render(sim.client, eye.tolist(), (eye + look).tolist(), up.tolist(), spec)


def follow_camera_image(sim: Simulation, spec: CameraSpec = CameraSpec(width_px=320, height_px=240, fov_deg=60.0)) -> np.ndarray:
    """RGB image from behind and beside the robot (for `render()`)."""
    pos, _ = p.getBasePositionAndOrientation(sim.robot_id, physicsClientId=sim.client)
    target = np.array(pos)
    eye = target + np.array([-0.9, -0.9, 0.6])
    return _render(sim.client, eye.tolist(), target.tolist(), [0, 0, 1], spec)
