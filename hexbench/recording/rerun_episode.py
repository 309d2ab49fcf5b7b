"""One episode as a Rerun recording (.rrd) with a default blueprint: 3D view beside the plots.

Contents (one timeline, `sim_time` (duration); no wall-clock timelines; all in world coordinates):
  /world/robot/links             the robot's visual boxes from its URDF (base, coxa, femur, tibia):
                                 sizes and colours static, centers and rotations over time
  /world/robot/feet              the foot spheres: sizes and colours static, centers over time
  /world/terrain                 terrain mesh, static
  /world/trajectory              the base path over the whole episode, static
  /world/goal                    the goal line, static
  /plots/*                       reward, Table 1 reward terms, progress / lateral / height, roll / pitch
Per-step data is logged every `every_n_steps` control steps (and at the last step): the .rrd is
the visual companion; the MCAP file is the full record.

The robot is placed by forward kinematics here rather than drawn with Rerun's URDF loader and a
transform per joint: every Rerun chunk carries its own Arrow schema (1.5-5 kB), and the loader's
26 geometry entities plus 19 transform entities (two chunks each) cost ~200 kB per file, more
than the robot's whole motion over a typical episode. Two entities hold the same boxes and
spheres (tests/test_recording.py checks the poses against PyBullet's own link states).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from hexbench.recording.capture import EpisodeArrays
from hexbench.recording.kinematics import JointFrame, link_poses, link_visuals, quat_multiply, quat_rotate

APPLICATION_ID = "hexbench"


@dataclass(frozen=True)
class RerunSettings:
    every_n_steps: int = 12  # 5 Hz at 60 Hz control: a row costs ~0.8 kB (19 boxes, 6 feet, 4 plots); 4000 steps < 1 MB


def _rpy_deg(quat_xyzw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x, y, z, w = quat_xyzw.T
    roll = np.degrees(np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)))
    pitch = np.degrees(np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0)))
    return roll, pitch


def blueprint():
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="/", name="robot and terrain"),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="/plots", contents=["/plots/reward", "/plots/reward_terms"],
                                   name="reward and Table 1 terms"),
                rrb.TimeSeriesView(origin="/plots", contents=["/plots/position_m", "/plots/attitude_deg"],
                                   name="progress, lateral, height [m]; roll, pitch [deg]"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


@lru_cache(maxsize=4)
def _robot_geometry(urdf: str) -> tuple:
    """The robot's visual boxes and spheres (from the URDF) as arrays, built once per process."""
    visuals = link_visuals(urdf)
    out = []
    for kind in ("box", "sphere"):
        vs = [v for v in visuals if v.kind == kind]
        out.append((tuple(v.link for v in vs), np.array([v.origin_xyz_m for v in vs]).reshape(-1, 3),
                    np.array([v.origin_quat_xyzw for v in vs]).reshape(-1, 4),
                    np.array([v.half_size_m for v in vs], dtype=np.float32).reshape(-1, 3),
                    np.array([np.round(np.array(v.rgba) * 255) for v in vs], dtype=np.uint8).reshape(-1, 4)))
    return tuple(out)


def robot_poses(urdf: str, joints: list[JointFrame], base_pos_m: np.ndarray, base_quat_xyzw: np.ndarray,
                joint_pos_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World centers (m, B, 3) and rotations (m, B, 4) of the robot's boxes, centers (m, S, 3) of its spheres."""
    poses = link_poses(joints, base_pos_m, base_quat_xyzw, joint_pos_rad)
    (box_links, box_xyz, box_quat, _, _), (sphere_links, sphere_xyz, _, _, _) = _robot_geometry(urdf)

    def place(links, xyz):
        pos = np.stack([poses[link][0] for link in links], axis=1)  # (m, k, 3)
        quat = np.stack([poses[link][1] for link in links], axis=1)  # (m, k, 4)
        return pos + quat_rotate(quat, xyz[None]), quat

    box_centers, link_quat = place(box_links, box_xyz)
    sphere_centers, _ = place(sphere_links, sphere_xyz)
    return box_centers, quat_multiply(link_quat, np.broadcast_to(box_quat[None], link_quat.shape)), sphere_centers


@lru_cache(maxsize=4)
def _static_archetypes(urdf: str, reward_term_names: tuple[str, ...]) -> tuple:
    """The static per-entity data that is the same in every episode, built once per process."""
    import rerun as rr

    (_, _, _, box_half, box_rgba), (_, _, _, sphere_half, sphere_rgba) = _robot_geometry(urdf)
    solid = rr.components.FillMode.Solid
    out = [("/world/robot/links", rr.Boxes3D(half_sizes=box_half, colors=box_rgba, fill_mode=solid)),
           ("/world/robot/feet", rr.Ellipsoids3D(half_sizes=sphere_half, colors=sphere_rgba, fill_mode=solid))]
    out += [("/plots/reward", rr.SeriesLines(names=["reward"])),
            ("/plots/position_m", rr.SeriesLines(names=["progress", "lateral", "base height"])),
            ("/plots/attitude_deg", rr.SeriesLines(names=["roll", "pitch"]))]
    if reward_term_names:
        out.append(("/plots/reward_terms", rr.SeriesLines(names=list(reward_term_names))))
    return tuple(out)


@dataclass(frozen=True)
class RerunSeries:
    """What the .rrd shows over time, already at the logged rate.

    Robot rows (m): the reset state and every `every_n_steps`-th step; plot rows (p): the same
    steps without the reset row (reward and its terms exist only after a step).
    """

    time_s: np.ndarray  # (m,) simulated time of the robot rows
    joint_pos_rad: np.ndarray  # (m, 18)
    base_pos_m: np.ndarray  # (m, 3)
    base_quat_xyzw: np.ndarray  # (m, 4)
    plot_time_s: np.ndarray  # (p,)
    reward: np.ndarray  # (p,)
    reward_term_names: tuple[str, ...]
    reward_terms: np.ndarray  # (p, len(names))
    progress_m: np.ndarray  # (p,)
    lateral_m: np.ndarray  # (p,)
    plot_base_pos_m: np.ndarray  # (p, 3)
    plot_base_quat_xyzw: np.ndarray  # (p, 4)


def series_from_episode(ep: EpisodeArrays, every_n_steps: int) -> RerunSeries:
    rows = ep.state_rows(every_n_steps)  # reset row, every n-th step, the last step
    plot = rows[rows > 0]
    k = plot - 1  # the same steps in the sampled-step arrays
    steps = ep.steps[k]  # 1-based control steps
    return RerunSeries(
        time_s=ep.time_ns[rows] / 1e9, joint_pos_rad=ep.joint_pos_rad[rows], base_pos_m=ep.base_pos_m[rows],
        base_quat_xyzw=ep.base_quat_xyzw[rows], plot_time_s=ep.time_ns[plot] / 1e9, reward=ep.reward[steps - 1],
        reward_term_names=tuple(ep.reward_term_names), reward_terms=ep.reward_terms[k], progress_m=ep.progress_m[k],
        lateral_m=ep.lateral_m[k], plot_base_pos_m=ep.base_pos_m[plot], plot_base_quat_xyzw=ep.base_quat_xyzw[plot])


def episode_rrd_bytes(ep: EpisodeArrays, *, recording_id: str, urdf: str, joints: list[JointFrame],
                      mesh: tuple[np.ndarray, np.ndarray], goal_x_m: float,
                      settings: RerunSettings = RerunSettings()) -> bytes:
    """The episode's .rrd file, whole, in memory (the caller writes it)."""
    return series_rrd_bytes(series_from_episode(ep, settings.every_n_steps), recording_id=recording_id, urdf=urdf,
                            joints=joints, mesh=mesh, goal_x_m=goal_x_m)


def series_rrd_bytes(se: RerunSeries, *, recording_id: str, urdf: str, joints: list[JointFrame],
                     mesh: tuple[np.ndarray, np.ndarray], goal_x_m: float) -> bytes:
    """A whole .rrd file in memory: the default blueprint, then the recording, then Rerun's footer.

    Rerun encodes into memory and the caller writes the bytes with Python's own file calls: Rerun's
    file writer (rerun-sdk 0.41) never returns when it starts a file on a full disk and reports a
    disk that fills under it only as "File-writer thread shut down prematurely", where a write of
    ours fails with the operating system's reason (ENOSPC, EROFS, ...)."""
    import rerun as rr
    import rerun_bindings

    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id, send_properties=False)
    stream = rr.binary_stream(recording=rec)
    blueprint_stream = _send_default_blueprint(rec)
    try:
        rec.send_recording_name(recording_id)
        times = [rr.TimeColumn("sim_time", duration=se.time_s)]
        for entity, archetype in _static_archetypes(urdf, se.reward_term_names):
            rec.log(entity, archetype, static=True)

        # robot: every box and foot sphere in world coordinates over time (forward kinematics from
        # the base pose and joint angles); sizes and colours static
        box_centers, box_quats, sphere_centers = robot_poses(urdf, joints, se.base_pos_m, se.base_quat_xyzw,
                                                             se.joint_pos_rad)
        m, b, f = len(se.time_s), box_centers.shape[1], sphere_centers.shape[1]
        rec.send_columns("/world/robot/links", times, rr.Boxes3D.columns(
            centers=box_centers.reshape(-1, 3).astype(np.float32),
            quaternions=box_quats.reshape(-1, 4).astype(np.float32)).partition([b] * m))
        rec.send_columns("/world/robot/feet", times, rr.Ellipsoids3D.columns(
            centers=sphere_centers.reshape(-1, 3).astype(np.float32)).partition([f] * m))

        # world: terrain, path, goal line
        vertices, triangles = mesh
        rec.log("/world/terrain", rr.Mesh3D(vertex_positions=vertices.astype(np.float32), triangle_indices=triangles,
                                            albedo_factor=[140, 128, 108, 255]), static=True)
        rec.log("/world/trajectory", rr.LineStrips3D([se.base_pos_m.astype(np.float32)], colors=[[230, 80, 30]],
                                                     radii=0.004), static=True)
        y0 = float(se.base_pos_m[0, 1])
        gx = float(se.base_pos_m[0, 0]) + goal_x_m
        gz = float(vertices[:, 2].max()) + 0.01
        rec.log("/world/goal", rr.LineStrips3D([[[gx, y0 - 0.8, gz], [gx, y0 + 0.8, gz]]], colors=[[40, 180, 60]],
                                               radii=0.006), static=True)

        # plots
        p = len(se.plot_time_s)
        step_times = [rr.TimeColumn("sim_time", duration=se.plot_time_s)]
        rec.send_columns("/plots/reward", step_times, rr.Scalars.columns(scalars=se.reward))
        names = list(se.reward_term_names)
        if names:
            rec.send_columns("/plots/reward_terms", step_times,
                             rr.Scalars.columns(scalars=se.reward_terms).partition([len(names)] * p))
        pos = np.stack([se.progress_m, se.lateral_m, se.plot_base_pos_m[:, 2]], axis=1)
        rec.send_columns("/plots/position_m", step_times, rr.Scalars.columns(scalars=pos).partition([3] * p))
        roll, pitch = _rpy_deg(se.plot_base_quat_xyzw)
        rec.send_columns("/plots/attitude_deg", step_times,
                         rr.Scalars.columns(scalars=np.stack([roll, pitch], axis=1)).partition([2] * p))
        rrd = stream.read(flush=True)
    finally:
        rec.disconnect()
        if blueprint_stream is not None:
            blueprint_stream.disconnect()
        # Drop both streams so their threads end (else they pile up, episode after episode, in a worker).
        del rec, stream, blueprint_stream
        rerun_bindings.flush_and_cleanup_orphaned_recordings()
    if not rrd:
        raise RuntimeError("Rerun returned no bytes for the recording")
    return rrd


def _send_default_blueprint(rec):
    """Send `blueprint()` into `rec` as the default blueprint (what `save(default_blueprint=...)` writes
    ahead of a file), and return the blueprint's own stream for the caller to disconnect: the public
    `send_blueprint` builds it in an in-memory stream it never releases (two threads leak per call,
    measured with rerun-sdk 0.41), so this makes the same calls step by step."""
    import rerun as rr

    try:
        from rerun import bindings

        bp_stream = rr.RecordingStream._from_native(bindings.new_blueprint(
            application_id=APPLICATION_ID, make_default=False, make_thread_default=False, default_enabled=True))
        bp_stream.set_time("blueprint", sequence=0)
        blueprint().to_blueprint()._log_to_stream(bp_stream)
        bindings.send_blueprint(bp_stream.memory_recording().storage, make_active=False, make_default=True,
                                recording=rec.to_native())
        return bp_stream
    except (AttributeError, TypeError):  # those internals changed: the public call
        rec.send_blueprint(blueprint(), make_active=False, make_default=True)
        return None


def verify_rrd(path: str | Path) -> None:
    """Run Rerun's own `rerun rrd verify` on a file; RuntimeError with its output if it fails."""
    import shutil
    import subprocess
    import sys

    exe = shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))
    proc = subprocess.run([exe, "rrd", "verify", str(path)], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "RERUN_ANALYTICS": "0"})
    if proc.returncode != 0:
        raise RuntimeError(f"rerun rrd verify failed on {path}: {(proc.stderr or proc.stdout).strip()}")


