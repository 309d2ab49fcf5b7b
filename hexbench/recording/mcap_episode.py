"""One episode as an MCAP file that Foxglove opens directly (reading it back: reader.py).

Channels (log time = publish time = simulated time since reset [ns]; no wall clock anywhere,
so the same episode always gives the same bytes):
  /robot_description  std_msgs/msg/String (ros2msg schema, CDR), the URDF, once at t = 0
  /terrain            foxglove.SceneUpdate: the terrain as one triangle-mesh entity, t = 0
  /joint_states       foxglove.JointStates: 18 joints (position, velocity, effort), every
                      `joint_states_every_n_steps` steps and at the last step
  /base_pose          foxglove.PoseInFrame: the base in frame "world"            } every `tf_every_n_steps`
  /tf                 foxglove.FrameTransforms: world -> base and parent -> child } steps and at the
                      link of each joint                                          } last step
  /metrics            JSON (jsonschema): every `metrics_every_n_steps` steps and at the last step,
                      that step's reward, the return so far, Table 1 terms, the controller's
                      action, a_c, a_r, a_t, oscillator phases, foot contacts, progress, lateral
plus the URDF as an attachment (robot.urdf) and metadata records "episode" (task, seed,
controller, versions), "outcome" (the episode's result row) and "recording" (rates, precision).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from typing import IO

import numpy as np

from hexbench.recording.capture import EpisodeArrays
from hexbench.recording.kinematics import JointFrame, joint_rotations
from hexbench.recording.mcap_bulk import add_messages
from hexbench.recording.numbers import json_bool_cells, json_number_cells, quantize
from hexbench.recording.protobuf_rows import DoubleRowEncoder, timestamp_field, varint

WORLD_FRAME = "world"
BASE_FRAME = "base"
TOPICS = ("/robot_description", "/terrain", "/joint_states", "/base_pose", "/tf", "/metrics")


@dataclass(frozen=True)
class McapPrecision:
    """Binary quantisation of the logged signals (bits after the binary point)."""

    joint_position_bits: int = 10  # 2^-10 rad ~ 0.001 rad
    joint_velocity_bits: int = 6  # 2^-6 rad/s ~ 0.016 rad/s
    joint_torque_bits: int = 8  # 2^-8 N m ~ 0.004 N m
    base_position_bits: int = 14  # 2^-14 m ~ 0.06 mm
    rotation_bits: int = 12  # quaternion components
    # Rates [control steps; 60 Hz control]; each also logs the last step. They must be multiples of the
    # capture's sampling period, which the recorder sets to metrics_every_n_steps.
    metrics_every_n_steps: int = 3  # /metrics at 20 Hz; the capture keeps (and queries foot contacts) only then
    joint_states_every_n_steps: int = 6  # /joint_states at 10 Hz, with /tf; keeps a 4000-step episode < 1 MB
    tf_every_n_steps: int = 6  # /tf and /base_pose at 10 Hz (Foxglove interpolates transforms)
    chunk_size_bytes: int = 8 * 1024 * 1024  # the whole episode in one chunk, channels grouped: best compression


METRICS_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "hexbench.StepMetrics",
    "description": "One control step of a hexbench episode. Arrays over joints follow the joint order "
                   "RF, RM, RB, LB, LM, LF x (hip, knee, ankle); legs (phases, contacts) RF, RM, RB, LB, LM, LF.",
    "type": "object",
    "properties": {
        "step": {"type": "integer", "description": "control step, 1-based"},
        "sim_time_s": {"type": "number", "description": "5 significant digits; the log time is exact"},
        "reward": {"type": "number", "description": "R' = (1 + delta) R (eqs 7-8) of this step"},
        "return": {"type": "number", "description": "sum of the rewards of steps 1..step (every step counted, "
                                                    "also those not logged)"},
        "reward_terms": {"type": "object", "additionalProperties": {"type": "number"},
                         "description": "unweighted Table 1 terms"},
        "progress_m": {"type": "number"}, "lateral_m": {"type": "number"},
        "action": {"type": "array", "items": {"type": "number"}, "description": "controller output in [-1, 1]"},
        "a_c": {"type": "array", "items": {"type": "number"}, "description": "CPG joint angles [rad]"},
        "a_r": {"type": "array", "items": {"type": "number"}, "description": "policy residual [rad]"},
        "a_t": {"type": "array", "items": {"type": "number"}, "description": "joint targets sent [rad]"},
        "phases_rad": {"type": "array", "items": {"type": "number"}},
        "foot_contacts": {"type": "array", "items": {"type": "boolean"}},
        "end_reason": {"type": ["string", "null"]},
    },
    "required": ["step", "sim_time_s", "reward", "return", "reward_terms", "action", "a_c", "a_r", "a_t", "phases_rad",
                 "foot_contacts", "end_reason"],
}


def _ros2_string_cdr(text: str) -> bytes:
    """std_msgs/msg/String in CDR (little-endian encapsulation, uint32 length incl. NUL)."""
    data = text.encode() + b"\x00"
    return b"\x00\x01\x00\x00" + len(data).to_bytes(4, "little") + data


# ----------------------------------------------------------------------------- encoders
@lru_cache(maxsize=4)
def _joint_states_encoder(names: tuple[str, ...]) -> DoubleRowEncoder:
    from foxglove_schemas_protobuf.JointStates_pb2 import JointStates

    def build(v):
        m = JointStates()
        for j, name in enumerate(names):
            m.joints.add(name=name, position=v[3 * j], velocity=v[3 * j + 1], effort=v[3 * j + 2])
        return m

    return DoubleRowEncoder(build, 3 * len(names))


@lru_cache(maxsize=1)
def _pose_encoder() -> DoubleRowEncoder:
    from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame

    def build(v):
        m = PoseInFrame(frame_id=WORLD_FRAME)
        m.pose.position.x, m.pose.position.y, m.pose.position.z = v[0:3]
        o = m.pose.orientation
        o.x, o.y, o.z, o.w = v[3:7]
        return m

    return DoubleRowEncoder(build, 7)


@lru_cache(maxsize=64)
def _transform_encoder(parent: str, child: str) -> DoubleRowEncoder:
    """A foxglove.FrameTransform without its timestamp (field 1), values: translation, rotation."""
    from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform

    def build(v):
        m = FrameTransform(parent_frame_id=parent, child_frame_id=child)
        m.translation.x, m.translation.y, m.translation.z = v[0:3]
        m.rotation.x, m.rotation.y, m.rotation.z, m.rotation.w = v[3:7]
        return m

    return DoubleRowEncoder(build, 7)


def _terrain_scene(vertices: np.ndarray, triangles: np.ndarray) -> bytes:
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    update = SceneUpdate()
    entity = update.entities.add(frame_id=WORLD_FRAME, id="terrain")
    tri = entity.triangles.add()
    tri.pose.orientation.w = 1.0
    tri.color.r, tri.color.g, tri.color.b, tri.color.a = 0.55, 0.5, 0.42, 1.0
    for x, y, z in quantize(vertices, 16).tolist():
        p = tri.points.add()
        p.x, p.y, p.z = x, y, z
    tri.indices.extend(triangles.reshape(-1).tolist())
    return update.SerializeToString()


def _register_protobuf(writer, cache: dict, message_class) -> int:
    from mcap_protobuf.schema import build_file_descriptor_set

    name = message_class.DESCRIPTOR.full_name
    if name not in cache:
        cache[name] = writer.register_schema(name=name, encoding="protobuf",
                                             data=build_file_descriptor_set(message_class).SerializeToString())
    return cache[name]


def _frame_transforms_messages(ts_fields: list[bytes], parts: list[np.ndarray]) -> list[bytes]:
    """foxglove.FrameTransforms messages: per row, each part (a FrameTransform without its timestamp)
    prefixed with the row's timestamp and wrapped as field 1. Rows with equally long timestamps are
    assembled together with numpy."""
    out: list[bytes] = [b""] * len(ts_fields)
    by_length: dict[int, list[int]] = {}
    for i, ts in enumerate(ts_fields):
        by_length.setdefault(len(ts), []).append(i)
    for length, idx in by_length.items():
        ts = np.frombuffer(b"".join(ts_fields[i] for i in idx), dtype=np.uint8).reshape(len(idx), length)
        blocks = []
        for part in parts:
            head = np.frombuffer(b"\x0a" + varint(length + part.shape[1]), dtype=np.uint8)
            blocks += [np.broadcast_to(head, (len(idx), len(head))), ts, part[idx]]
        for i, row in zip(idx, np.concatenate(blocks, axis=1)):
            out[i] = row.tobytes()
    return out


# ------------------------------------------------------------------------------- writing
_TIMESTAMP_CACHE: dict[int, bytes] = {}


def _timestamp_fields(time_ns: np.ndarray) -> list[bytes]:
    """Timestamp fields of the state rows; the control period is fixed, so they repeat across episodes."""
    cache = _TIMESTAMP_CACHE
    out = []
    for ti in time_ns.tolist():
        field = cache.get(ti)
        if field is None:
            field = cache[ti] = timestamp_field(ti)
        out.append(field)
    return out


def write_episode_mcap(stream: IO[bytes], ep: EpisodeArrays, *, urdf: str, joints: list[JointFrame],
                       mesh: tuple[np.ndarray, np.ndarray], episode_meta: dict, outcome: dict,
                       precision: McapPrecision = McapPrecision(), library: str = "hexbench") -> None:
    """Write one episode (see module docstring) to a binary stream."""
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
    from foxglove_schemas_protobuf.JointStates_pb2 import JointStates
    from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
    from mcap.writer import CompressionType, IndexType, Writer

    # All index types: Foxglove's indexed reader (@mcap/core ChunkCursor) rejects a chunk with
    # messages but no message index records, although they cost 16 uncompressed bytes per message.
    writer = Writer(stream, chunk_size=precision.chunk_size_bytes, compression=CompressionType.ZSTD,
                    index_types=IndexType.ALL, enable_crcs=True, enable_data_crcs=True)
    writer.start(profile="", library=library)
    schemas: dict[str, int] = {}
    ch = {
        "/robot_description": writer.register_channel(
            "/robot_description", "cdr",
            writer.register_schema(name="std_msgs/msg/String", encoding="ros2msg", data=b"string data")),
        "/terrain": writer.register_channel("/terrain", "protobuf", _register_protobuf(writer, schemas, SceneUpdate)),
        "/joint_states": writer.register_channel("/joint_states", "protobuf",
                                                 _register_protobuf(writer, schemas, JointStates)),
        "/base_pose": writer.register_channel("/base_pose", "protobuf", _register_protobuf(writer, schemas, PoseInFrame)),
        "/tf": writer.register_channel("/tf", "protobuf", _register_protobuf(writer, schemas, FrameTransforms)),
        "/metrics": writer.register_channel(
            "/metrics", "json",
            writer.register_schema(name="hexbench.StepMetrics", encoding="jsonschema",
                                   data=json.dumps(METRICS_SCHEMA, sort_keys=True).encode())),
    }
    writer.add_attachment(create_time=0, log_time=0, name="robot.urdf", media_type="application/xml",
                          data=urdf.encode())
    writer.add_metadata("episode", {k: str(v) for k, v in sorted(episode_meta.items())})
    writer.add_metadata("recording", {
        "time": "log_time = publish_time = simulated time since reset [ns]",
        "joint_states": f"every {precision.joint_states_every_n_steps} steps and the last step; position 2^-{precision.joint_position_bits} rad, velocity "
                        f"2^-{precision.joint_velocity_bits} rad/s, effort 2^-{precision.joint_torque_bits} N m",
        "base_pose": f"every {precision.tf_every_n_steps} steps and the last step; position 2^-{precision.base_position_bits} m, orientation 2^-{precision.rotation_bits}",
        "tf": f"every {precision.tf_every_n_steps} steps and the last step",
        "metrics": f"every {precision.metrics_every_n_steps} steps and the last step (field step says which); "
                   "arrays to 3 decimals, scalars to 5 significant digits; return sums every step's reward",
        "steps": str(ep.num_steps),
    })

    t = ep.time_ns.tolist()
    ts_fields = _timestamp_fields(ep.time_ns)
    writer.add_message(ch["/robot_description"], 0, _ros2_string_cdr(urdf), 0)
    writer.add_message(ch["/terrain"], 0, _terrain_scene(*mesh), 0)

    # /joint_states: reset state, every joint_states_every_n_steps steps, last step
    js_rows = ep.state_rows(precision.joint_states_every_n_steps).tolist()
    pos = quantize(ep.joint_pos_rad, precision.joint_position_bits)
    vel = quantize(ep.joint_vel_rad_per_s[js_rows], precision.joint_velocity_bits)
    tq = quantize(ep.joint_torque_nm[js_rows], precision.joint_torque_bits)
    names = tuple(j.name for j in joints)
    body = _joint_states_encoder(names).encode(np.stack([pos[js_rows], vel, tq], axis=2).reshape(len(js_rows), -1))
    add_messages(writer, ch["/joint_states"], [t[r] for r in js_rows],
                 [ts_fields[r] + row.tobytes() for r, row in zip(js_rows, body)])

    # /base_pose and /tf at the tf rate: world -> base, then each joint's parent -> child
    rows = ep.state_rows(precision.tf_every_n_steps).tolist()
    t_rows = [t[r] for r in rows]
    base_pos = quantize(ep.base_pos_m[rows], precision.base_position_bits)
    base_quat = quantize(ep.base_quat_xyzw[rows], precision.rotation_bits)
    base = np.concatenate([base_pos, base_quat], axis=1)
    body = _pose_encoder().encode(base)
    add_messages(writer, ch["/base_pose"], t_rows, [ts_fields[r] + row.tobytes() for r, row in zip(rows, body)])
    rot = quantize(joint_rotations(joints, pos[rows]), precision.rotation_bits)  # (r, J, 4)
    parts = [_transform_encoder(WORLD_FRAME, BASE_FRAME).encode(base)]
    for j, jf in enumerate(joints):
        values = np.concatenate([np.broadcast_to(np.array(jf.origin_xyz_m), (len(rows), 3)), rot[:, j]], axis=1)
        parts.append(_transform_encoder(jf.parent_link, jf.child_link).encode(values))
    tf_data = _frame_transforms_messages([ts_fields[r] for r in rows], parts)
    add_messages(writer, ch["/tf"], t_rows, tf_data)

    # /metrics: one JSON object per logged step (every `metrics_every_n_steps` steps and the last),
    # each made by one %-format of a row of pre-formatted cells
    k = ep.state_rows(precision.metrics_every_n_steps)[1:] - 1  # indices into the sampled-step arrays
    logged_steps = ep.steps[k]
    n = len(k)
    returns = np.cumsum(ep.reward)
    scalars = np.column_stack([ep.time_ns[k + 1] / 1e9, ep.reward[logged_steps - 1], returns[logged_steps - 1],
                               ep.reward_terms[k], ep.progress_m[k], ep.lateral_m[k]])
    if not np.all(np.isfinite(scalars)):
        raise ValueError("cannot log NaN or infinite reward, progress or lateral values")
    arrays = [("action", json_number_cells(ep.action[k])), ("a_c", json_number_cells(ep.a_c[k])),
              ("a_r", json_number_cells(ep.a_r[k])), ("a_t", json_number_cells(ep.a_t[k])),
              ("phases_rad", json_number_cells(ep.phases_rad[k])),
              ("foot_contacts", json_bool_cells(ep.foot_contacts[k]))]
    terms = ",".join(f"{json.dumps(name)}:%.5g" for name in ep.reward_term_names)
    template = ('{"step":%d,"sim_time_s":%.5g,"reward":%.5g,"return":%.5g,"reward_terms":{' + terms + '},'
                '"progress_m":%.5g,"lateral_m":%.5g,'
                + ",".join(f'"{name}":[' + ",".join(["%s"] * cells.shape[1]) + "]" for name, cells in arrays)
                + ',"end_reason":%s}')
    end_reasons = np.full((n, 1), "null", dtype=object)
    if n and logged_steps[-1] == ep.num_steps:
        end_reasons[-1, 0] = json.dumps(ep.end_reason)
    cells = np.concatenate([logged_steps.astype(object)[:, None], scalars.astype(object)]
                           + [c for _, c in arrays] + [end_reasons], axis=1)
    texts = [(template % tuple(row)).encode() for row in cells.tolist()]
    add_messages(writer, ch["/metrics"], ep.time_ns[k + 1].tolist(), texts)

    writer.add_metadata("outcome", {k: json.dumps(v) for k, v in sorted(outcome.items())})
    writer.finish()
