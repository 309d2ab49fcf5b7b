"""Build an episode's Rerun .rrd from its MCAP file (for episodes recorded without one).

The MCAP holds everything the .rrd shows: the URDF (attachment), the terrain mesh (/terrain),
joint positions (/joint_states), the base pose (/base_pose) and the per-step metrics. The robot
and the plots are shown at the rows where both joint states and the base pose were logged
(every `tf_every_n_steps` steps, 10 Hz by default), so the result matches an .rrd written
during the evaluation up to its sampling rate.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from hexbench.errors import OutputError, os_reason
from hexbench.recording.reader import EpisodeFileError, iter_topic, open_episode_file, read_episode


def _attachment(path: Path, name: str) -> bytes:
    from mcap.reader import make_reader

    with open_episode_file(path) as f:
        for a in make_reader(f, validate_crcs=True).iter_attachments():
            if a.name == name:
                return a.data
    raise EpisodeFileError(f"{path}: no {name} attachment")


def rrd_from_mcap(mcap_path: str | Path, rrd_path: str | Path) -> Path:
    """Write `rrd_path` (temporary name, then rename) from an episode's MCAP file; return it.
    An unreadable or incomplete episode file is one EpisodeFileError, a failed write one OutputError."""
    from google.protobuf.message import DecodeError

    from hexbench.recording.rerun_episode import series_rrd_bytes

    mcap_path, rrd_path = Path(mcap_path), Path(rrd_path)
    log = read_episode(mcap_path)
    try:
        series, urdf, joints, mesh = _series(mcap_path)
    except (KeyError, ValueError, IndexError, TypeError, DecodeError) as e:  # a CRC-valid file with odd contents
        raise EpisodeFileError(f"{mcap_path}: not a complete hexbench episode log ({type(e).__name__}: {e})") from None
    episode_id = log.episode.get("episode_id", mcap_path.stem)
    try:
        goal_x_m = float(log.episode.get("goal_distance_m", 2.5))
    except ValueError:
        raise EpisodeFileError(f"{mcap_path}: goal_distance_m {log.episode['goal_distance_m']!r} "
                               f"is not a number") from None
    rrd_bytes = series_rrd_bytes(series, recording_id=episode_id, urdf=urdf, joints=joints, mesh=mesh,
                                 goal_x_m=goal_x_m)
    tmp = rrd_path.with_name(f".{rrd_path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_bytes(rrd_bytes)
        os.replace(tmp, rrd_path)
    except OSError as e:
        raise OutputError(f"{rrd_path}: cannot be written ({os_reason(e)})") from None
    finally:
        tmp.unlink(missing_ok=True)
    return rrd_path


def _series(mcap_path: Path):
    """The episode's Rerun series, URDF, joints and terrain mesh, decoded from its MCAP messages."""
    from foxglove_schemas_protobuf.JointStates_pb2 import JointStates
    from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    from hexbench.recording.kinematics import joint_frames
    from hexbench.recording.rerun_episode import RerunSeries

    urdf = _attachment(mcap_path, "robot.urdf").decode()
    joints = joint_frames(urdf)
    (_, scene_bytes), = list(iter_topic(mcap_path, "/terrain"))
    tri = SceneUpdate.FromString(scene_bytes).entities[0].triangles[0]
    vertices = np.array([(p.x, p.y, p.z) for p in tri.points])
    triangles = np.array(tri.indices, dtype=np.uint32).reshape(-1, 3)

    names = [j.name for j in joints]
    joint_pos = {}
    for t, data in iter_topic(mcap_path, "/joint_states"):
        by_name = {j.name: j.position for j in JointStates.FromString(data).joints}
        joint_pos[t] = [by_name[n] for n in names]
    pose = {}
    for t, data in iter_topic(mcap_path, "/base_pose"):
        m = PoseInFrame.FromString(data).pose
        pose[t] = ([m.position.x, m.position.y, m.position.z],
                   [m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w])
    metrics = {t: json.loads(data) for t, data in iter_topic(mcap_path, "/metrics")}
    rows = sorted(set(joint_pos) & set(pose))
    if not rows:
        raise EpisodeFileError(f"{mcap_path}: no time with both joint states and a base pose")
    plot_rows = [t for t in rows if t in metrics]
    term_names = tuple(metrics[plot_rows[0]]["reward_terms"]) if plot_rows else ()
    series = RerunSeries(
        time_s=np.array(rows) / 1e9, joint_pos_rad=np.array([joint_pos[t] for t in rows]),
        base_pos_m=np.array([pose[t][0] for t in rows]), base_quat_xyzw=np.array([pose[t][1] for t in rows]),
        plot_time_s=np.array(plot_rows) / 1e9, reward=np.array([metrics[t]["reward"] for t in plot_rows]),
        reward_term_names=term_names,
        reward_terms=np.array([[metrics[t]["reward_terms"][k] for k in term_names] for t in plot_rows]).reshape(
            len(plot_rows), len(term_names)),
        progress_m=np.array([metrics[t]["progress_m"] for t in plot_rows]),
        lateral_m=np.array([metrics[t]["lateral_m"] for t in plot_rows]),
        plot_base_pos_m=np.array([pose[t][0] for t in plot_rows]).reshape(-1, 3),
        plot_base_quat_xyzw=np.array([pose[t][1] for t in plot_rows]).reshape(-1, 4),
    )
    return series, urdf, joints, (vertices, triangles)
