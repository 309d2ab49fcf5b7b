"""One episode as a Rerun recording (.rrd) with a default blueprint: 3D view beside the plots.

Contents (one timeline, `sim_time` (duration); no wall-clock timelines):
  /jethexa/visual_geometries/**  the robot from its URDF (Rerun's own URDF loader, visual
                                 geometry only), static
  /joints/<joint>                parent link -> child link transform of each joint: frames and
                                 origin static, rotation over time
  /world/base                    world -> base transform over time (frame "tf#/world" -> "base")
  /world/terrain                 terrain mesh, static
  /world/trajectory              the base path over the whole episode, static
  /world/goal                    the goal line, static
  /plots/*                       reward, Table 1 reward terms, progress / lateral / height, roll / pitch
Per-step data is logged every `every_n_steps` control steps (and at the last step): the .rrd is
the visual companion; the MCAP file holds every step.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from hexbench.recording.capture import EpisodeArrays
from hexbench.recording.kinematics import JointFrame, joint_rotations

APPLICATION_ID = "hexbench"
WORLD_FRAME = "tf#/world"


@dataclass(frozen=True)
class RerunSettings:
    every_n_steps: int = 15  # 4 Hz at 60 Hz control: each row costs ~0.7 kB (19 transforms, 4 plots); 4000 steps < 1 MB


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
def _urdf_chunks(urdf: str) -> tuple:
    """The robot's visual geometry from Rerun's URDF loader, one static chunk per entity.

    The loader emits three single-row chunks per geometry (pose, frame, shape); every chunk
    carries ~1.5 KB of Arrow schema, so the columns of each entity are merged into one chunk
    (the same rows and values), which makes the static robot ~40% smaller.
    """
    import pyarrow as pa
    import rerun.urdf as rru
    from rerun.chunk import Chunk

    fd, path = tempfile.mkstemp(suffix=".urdf", prefix="hexbench_rrd_")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(urdf)
        tree = rru.UrdfTree.from_file_path(path)
        chunks = tree.stream(include_joint_transforms=False).drop(
            content=f"/{tree.name}/collision_geometries/**").to_chunks()
    finally:
        os.unlink(path)
    groups: dict[str, list] = {}
    for c in chunks:
        groups.setdefault(c.entity_path, []).append(c.to_record_batch())
    merged = []
    for batches in groups.values():
        if len(batches) == 1 or any(b.num_rows != 1 for b in batches):
            merged.extend(Chunk.from_record_batch(b)[0] for b in batches)
            continue
        fields, arrays = [batches[0].schema.field(0)], [batches[0].column(0)]
        for b in batches:
            fields.extend(b.schema.field(i) for i in range(1, b.num_columns))
            arrays.extend(b.column(i) for i in range(1, b.num_columns))
        batch = pa.RecordBatch.from_arrays(arrays, schema=pa.schema(fields, metadata=batches[0].schema.metadata))
        merged.extend(Chunk.from_record_batch(batch))
    return tuple(merged)


@lru_cache(maxsize=4)
def _static_archetypes(joints: tuple[JointFrame, ...], reward_term_names: tuple[str, ...]) -> tuple:
    """The static per-entity data that is the same in every episode, built once per process."""
    import rerun as rr

    out = [("/world/base", rr.Transform3D(parent_frame=WORLD_FRAME, child_frame="base"))]
    out += [(f"/joints/{jf.name}", rr.Transform3D(parent_frame=jf.parent_link, child_frame=jf.child_link,
                                                  translation=jf.origin_xyz_m)) for jf in joints]
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
    n_rows = len(ep.time_ns)
    rows = np.array(sorted(set(range(0, n_rows, every_n_steps)) | {n_rows - 1}))
    steps = rows[rows > 0]
    k = steps - 1
    return RerunSeries(
        time_s=ep.time_ns[rows] / 1e9, joint_pos_rad=ep.joint_pos_rad[rows], base_pos_m=ep.base_pos_m[rows],
        base_quat_xyzw=ep.base_quat_xyzw[rows], plot_time_s=ep.time_ns[steps] / 1e9, reward=ep.reward[k],
        reward_term_names=tuple(ep.reward_term_names), reward_terms=ep.reward_terms[k], progress_m=ep.progress_m[k],
        lateral_m=ep.lateral_m[k], plot_base_pos_m=ep.base_pos_m[steps], plot_base_quat_xyzw=ep.base_quat_xyzw[steps])


def write_episode_rrd(path: Path, ep: EpisodeArrays, *, recording_id: str, urdf: str, joints: list[JointFrame],
                      mesh: tuple[np.ndarray, np.ndarray], goal_x_m: float,
                      settings: RerunSettings = RerunSettings()) -> None:
    """Write the episode's .rrd to `path` (the caller renames it into place)."""
    write_series_rrd(path, series_from_episode(ep, settings.every_n_steps), recording_id=recording_id, urdf=urdf,
                     joints=joints, mesh=mesh, goal_x_m=goal_x_m)


def write_series_rrd(path: Path, se: RerunSeries, *, recording_id: str, urdf: str, joints: list[JointFrame],
                     mesh: tuple[np.ndarray, np.ndarray], goal_x_m: float) -> None:
    import rerun as rr
    import rerun_bindings

    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id, send_properties=False)
    blueprint_stream = _save_with_blueprint(rec, path)
    try:
        rec.send_recording_name(recording_id)
        rec.send_chunks(list(_urdf_chunks(urdf)))
        times = [rr.TimeColumn("sim_time", duration=se.time_s)]

        # robot: base pose and joint rotations over time, frames static
        for entity, archetype in _static_archetypes(tuple(joints), se.reward_term_names):
            rec.log(entity, archetype, static=True)
        rec.send_columns("/world/base", times, rr.Transform3D.columns(
            translation=se.base_pos_m.astype(np.float32), quaternion=se.base_quat_xyzw.astype(np.float32)))
        rot = joint_rotations(joints, se.joint_pos_rad).astype(np.float32)
        for j, jf in enumerate(joints):
            rec.send_columns(f"/joints/{jf.name}", times, rr.Transform3D.columns(quaternion=rot[:, j]))

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
        rec.flush()
    finally:
        rec.disconnect()
        if blueprint_stream is not None:
            blueprint_stream.disconnect()
        # Drop both streams so their writer threads end (else they pile up, four per episode, in a worker).
        del rec, blueprint_stream
        rerun_bindings.flush_and_cleanup_orphaned_recordings()


def _save_with_blueprint(rec, path: Path):
    """`rec.save(path, default_blueprint=blueprint())`, keeping hold of the blueprint's stream.

    The public call builds the blueprint in an in-memory stream it never releases (two threads
    leak per call, measured with rerun-sdk 0.41), so it is done here step by step with the same
    calls `rerun.sinks.save` makes, and the caller disconnects the returned stream. Falls back to
    the public call if those internals change.
    """
    import rerun as rr

    try:
        from rerun import bindings

        bp_stream = rr.RecordingStream._from_native(bindings.new_blueprint(
            application_id=APPLICATION_ID, make_default=False, make_thread_default=False, default_enabled=True))
        bp_stream.set_time("blueprint", sequence=0)
        blueprint().to_blueprint()._log_to_stream(bp_stream)
        storage = bp_stream.memory_recording().storage
        bindings.save(path=str(path), default_blueprint=storage, recording=rec.to_native(), write_footer=True)
        return bp_stream
    except (AttributeError, TypeError):
        rec.save(str(path), default_blueprint=blueprint())
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


