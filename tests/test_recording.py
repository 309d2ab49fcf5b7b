"""Episode recordings: MCAP channels read back with CRC checks, .rrd checked by Rerun, identical bytes for
the same episode, no partial files after an abort or a killed worker, and `verify` catching a tampered log."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from typer.testing import CliRunner

from hexbench.cli import app
from hexbench.errors import OutputError
from hexbench.evaluation.episode import EpisodeJob, run_episode
from hexbench.recording import make_episode_recorder
from hexbench.recording.mcap_episode import METRICS_SCHEMA, TOPICS
from hexbench.recording.reader import EpisodeFileError, check_integrity, metrics, read_episode
from hexbench.recording.rerun_episode import verify_rrd
from hexbench.suite.tasks import load_suite
from hexbench.world.env import HexapodEnv
from hexbench.world.robot import JOINT_NAMES, urdf_text

REPO = Path(__file__).resolve().parent.parent
CPG = str(REPO / "baselines" / "cpg.py")
SHORT_STEPS = 46
METRICS_STEPS = list(range(3, SHORT_STEPS + 1, 3)) + [SHORT_STEPS]  # /metrics: every 3rd step and the last
META = {"protocol": "v1", "terrain": "rough", "level": 6.0, "unit": "cm", "index": 0, "seed": 7,
        "action_mode": "cpg_residual", "controller_file": "baselines/cpg.py", "controller_sha256": "0" * 64,
        "hexbench_version": "test"}


def record_short_episode(out_dir: Path, episode_id: str = "rough-6cm-00", steps: int = SHORT_STEPS,
                         terrain: str = "rough", level: float = 6.0, abort_after: int | None = None) -> dict | None:
    """Drive the recorder like the evaluator does, with the open-loop CPG (zero residual)."""
    env = HexapodEnv(terrain=terrain, level=level, max_steps=steps)
    try:
        obs, _ = env.reset(seed=7)
        rec = make_episode_recorder(out_dir, episode_id, {**META, "episode_id": episode_id})
        rec.on_reset(env)
        action = np.zeros(18)
        n = 0
        while True:
            obs, reward, terminated, truncated, info = env.step(action)
            n += 1
            rec.on_step(env, obs, action, reward, info)
            if abort_after is not None and n == abort_after:
                rec.abort()
                return None
            if terminated or truncated:
                break
        return rec.on_end({"steps": n, "end_reason": info["end_reason"], "success": info["end_reason"] == "success",
                           "progress_m": info["progress_m"]})
    finally:
        env.close()


@pytest.fixture(scope="module")
def episode(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec")
    files = record_short_episode(out)
    return out, files


def test_on_end_returns_relative_paths_and_hashes(episode):
    import hashlib

    out, files = episode
    assert set(files) == {"mcap_path", "mcap_sha256", "rrd_path", "rrd_sha256"}
    for kind in ("mcap", "rrd"):
        path = out / files[f"{kind}_path"]
        assert path.parent == out and path.is_file()
        assert hashlib.sha256(path.read_bytes()).hexdigest() == files[f"{kind}_sha256"]
    assert sorted(p.name for p in out.iterdir()) == ["rough-6cm-00.mcap", "rough-6cm-00.rrd"]  # no temporaries


def test_every_mcap_channel_reads_back_with_crc_validation(episode):
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
    from foxglove_schemas_protobuf.JointStates_pb2 import JointStates
    from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    out, files = episode
    path = out / files["mcap_path"]
    check_integrity(path)  # every record, chunk CRCs and the data-section CRC
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert {c.topic for c in summary.channels.values()} == set(TOPICS)
        seen: dict[str, list] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            seen.setdefault(channel.topic, []).append((schema, message))
        assert [a.name for a in reader.iter_attachments()] == ["robot.urdf"]
        assert next(iter(reader.iter_attachments())).data.decode() == urdf_text()
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert meta["episode"]["seed"] == "7" and meta["episode"]["episode_id"] == "rough-6cm-00"
    assert meta["episode"]["max_steps"] == str(SHORT_STEPS)
    assert json.loads(meta["outcome"]["steps"]) == SHORT_STEPS

    # /robot_description: ROS 2 std_msgs/msg/String in CDR holding the URDF
    (schema, msg), = seen["/robot_description"]
    assert schema.name == "std_msgs/msg/String" and schema.encoding == "ros2msg"
    length = int.from_bytes(msg.data[4:8], "little")
    assert msg.data[:4] == b"\x00\x01\x00\x00" and msg.data[8:8 + length - 1].decode() == urdf_text()

    # protobuf channels decode with Foxglove's classes; times are simulated time
    dt_ns = round(1e9 / 60)
    (_, terrain), = seen["/terrain"]
    scene = SceneUpdate.FromString(terrain.data)
    tri = scene.entities[0].triangles[0]
    assert scene.entities[0].frame_id == "world" and len(tri.indices) % 3 == 0 and len(tri.points) > 100
    joint_msgs = [JointStates.FromString(m.data) for _, m in seen["/joint_states"]]
    assert [j.name for j in joint_msgs[0].joints] == list(JOINT_NAMES)
    assert seen["/joint_states"][0][1].log_time == 0 and seen["/joint_states"][-1][1].log_time == SHORT_STEPS * dt_ns
    assert joint_msgs[-1].timestamp.ToNanoseconds() == SHORT_STEPS * dt_ns
    tf = FrameTransforms.FromString(seen["/tf"][-1][1].data)
    assert len(tf.transforms) == 19 and tf.transforms[0].parent_frame_id == "world"
    assert tf.transforms[0].child_frame_id == "base" and tf.transforms[1].child_frame_id == "RF_coxa"
    pose = PoseInFrame.FromString(seen["/base_pose"][-1][1].data)
    assert pose.pose.position.x == pytest.approx(tf.transforms[0].translation.x)

    # /metrics: one JSON object every 3rd step and at the last step, valid against the channel's own JSON schema
    rows = [json.loads(m.data) for _, m in seen["/metrics"]]
    assert [r["step"] for r in rows] == METRICS_STEPS
    assert [m.log_time for _, m in seen["/metrics"]] == [r["step"] * dt_ns for r in rows]
    assert "every 3 steps" in meta["recording"]["metrics"]
    schema = json.loads(seen["/metrics"][0][0].data)
    assert schema == json.loads(json.dumps(METRICS_SCHEMA))
    for r in rows:
        jsonschema.validate(r, schema)
    assert len(rows[0]["a_c"]) == 18 and len(rows[0]["phases_rad"]) == 6 and len(rows[0]["foot_contacts"]) == 6
    assert set(rows[0]["reward_terms"]) == {"distance", "heading", "fall", "tilt", "height", "step_limit"}
    assert rows[-1]["end_reason"] == "step_limit" and rows[0]["end_reason"] is None
    assert any(any(r["foot_contacts"]) for r in rows)


def test_logged_numbers_match_the_simulation(episode):
    """The log holds what the env produced (to the documented precision), not something else."""
    out, files = episode
    env = HexapodEnv(terrain="rough", level=6.0, max_steps=SHORT_STEPS)
    env.reset(seed=7)
    expected = []
    for _ in range(SHORT_STEPS):
        _, reward, _, _, info = env.step(np.zeros(18))
        expected.append((reward, info["a_c"].copy(), info["progress_m"], env.cpg.phases_rad.copy(),
                         env.sim.foot_contacts()))
    env.close()
    rows = metrics(out / files["mcap_path"])
    assert [r["step"] for r in rows] == METRICS_STEPS
    returns = np.cumsum([e[0] for e in expected])
    for row in rows:
        reward, a_c, progress, phases, contacts = expected[row["step"] - 1]
        assert row["reward"] == pytest.approx(reward, rel=1e-4, abs=1e-9)
        assert row["return"] == pytest.approx(returns[row["step"] - 1], rel=1e-4, abs=1e-9)
        assert np.allclose(row["a_c"], a_c, atol=5e-4)
        assert row["progress_m"] == pytest.approx(progress, rel=1e-4, abs=1e-6)
        assert np.allclose(row["phases_rad"], phases, atol=5e-4)
        assert row["foot_contacts"] == contacts.tolist()


def test_rrd_passes_rerun_verify_and_carries_the_episode_id(episode):
    out, files = episode
    path = out / files["rrd_path"]
    verify_rrd(path)  # `rerun rrd verify`
    exe = Path(sys.executable).with_name("rerun")
    printed = subprocess.run([str(exe), "rrd", "print", str(path)], capture_output=True, text=True, timeout=60,
                             env={**os.environ, "RERUN_ANALYTICS": "0"}).stdout
    assert '"rough-6cm-00"' in printed  # recording id
    for entity in ("/world/terrain", "/world/robot/links", "/world/robot/feet", "/plots/reward"):
        assert entity in printed
    # the viewer opens it with hexbench's layout (3D view beside the plots), not one it guesses
    assert "/viewport" in printed and "make_default: true" in printed


def test_rerun_robot_poses_match_pybullet_links():
    """The .rrd draws the robot by forward kinematics: each box and foot sits where PyBullet has its link."""
    import pybullet as p

    from hexbench.recording.kinematics import joint_frames, link_visuals
    from hexbench.recording.rerun_episode import robot_poses

    env = HexapodEnv(terrain="rough", level=6.0, max_steps=100)
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(37):
        env.step(rng.uniform(-1, 1, 18))
    sim, st = env.sim, env.robot_state
    urdf = urdf_text(sim.robot_spec)
    boxes, quats, spheres = robot_poses(urdf, joint_frames(urdf), st.base_pos_m[None], st.base_quat_xyzw[None],
                                        st.joint_pos_rad[None])
    index = {p.getJointInfo(sim.robot_id, i, physicsClientId=sim.client)[12].decode(): i
             for i in range(p.getNumJoints(sim.robot_id, physicsClientId=sim.client))}
    visuals = link_visuals(urdf)
    expected = {"box": [], "sphere": []}
    for v in visuals:
        if v.link == "base":
            pos, quat = p.getBasePositionAndOrientation(sim.robot_id, physicsClientId=sim.client)
        else:
            pos, quat = p.getLinkState(sim.robot_id, index[v.link], computeForwardKinematics=True,
                                       physicsClientId=sim.client)[4:6]
        rot = np.array(p.getMatrixFromQuaternion(quat)).reshape(3, 3)
        expected[v.kind].append((np.array(pos) + rot @ np.array(v.origin_xyz_m), np.array(quat)))
    env.close()
    assert len(expected["box"]) == boxes.shape[1] == 19 and len(expected["sphere"]) == spheres.shape[1] == 6
    for i, (pos, quat) in enumerate(expected["box"]):
        assert np.allclose(boxes[0, i], pos, atol=1e-6)
        assert min(np.abs(quats[0, i] - quat).max(), np.abs(quats[0, i] + quat).max()) < 1e-6
    for i, (pos, _) in enumerate(expected["sphere"]):
        assert np.allclose(spheres[0, i], pos, atol=1e-6)


def test_same_episode_twice_gives_identical_mcap_bytes(tmp_path, episode):
    out, files = episode
    again = record_short_episode(tmp_path)
    assert again["mcap_sha256"] == files["mcap_sha256"]
    assert (tmp_path / again["mcap_path"]).read_bytes() == (out / files["mcap_path"]).read_bytes()


def test_abort_mid_episode_leaves_no_file(tmp_path):
    assert record_short_episode(tmp_path, abort_after=10) is None
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("room_for", ["nothing", "the MCAP"])
def test_a_disk_that_fills_is_one_output_error_and_leaves_no_file(tmp_path, episode, small_disk, room_for):
    """On a disk (a tmpfs) with no room, or room for the episode's MCAP but not its .rrd, the
    recorder raises one OutputError naming the file it could not write, returns (Rerun's own
    file writer never did when it started a file on a full disk), and leaves nothing behind."""
    import subprocess

    _, files = episode
    page_bytes = 4096
    mcap_pages = -(-(episode[0] / files["mcap_path"]).stat().st_size // page_bytes)
    size_bytes = page_bytes if room_for == "nothing" else (mcap_pages + 1) * page_bytes
    disk = tmp_path / "disk"
    prefix = small_disk(disk, size_bytes)
    script = textwrap.dedent(f"""
        import sys
        from pathlib import Path
        sys.path.insert(0, {str(REPO / 'tests')!r})
        from test_recording import record_short_episode
        from hexbench.errors import OutputError
        try:
            record_short_episode(Path({str(disk)!r}))
        except OutputError as e:
            print("error:", e)
        print("left:", sorted(p.name for p in Path({str(disk)!r}).iterdir()))
    """)
    shown = subprocess.run([*prefix, sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True,
                           timeout=120)
    kind = "mcap" if room_for == "nothing" else "rrd"
    assert shown.stdout.splitlines() == [
        f"error: {disk}/rough-6cm-00.{kind}: cannot be written (no space left on device)", "left: []"], shown.stderr


def test_killed_worker_leaves_finished_episodes_readable_and_no_partial_file(tmp_path):
    """A process records one episode, starts a second and is SIGKILLed in the middle of it."""
    script = textwrap.dedent(f"""
        import sys, numpy as np
        from pathlib import Path
        sys.path.insert(0, {str(REPO / 'tests')!r})
        from test_recording import record_short_episode, HexapodEnv, make_episode_recorder, META
        out = Path({str(tmp_path)!r})
        record_short_episode(out, "first", steps=20)
        env = HexapodEnv(terrain="flat", max_steps=100000)
        obs, _ = env.reset(seed=1)
        rec = make_episode_recorder(out, "second", META)
        rec.on_reset(env)
        for k in range(100000):
            obs, r, te, tr, info = env.step(np.zeros(18))
            rec.on_step(env, obs, np.zeros(18), r, info)
            if k == 30:
                print("started", flush=True)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True, cwd=REPO)
    try:
        assert proc.stdout.readline().strip() == "started"
        time.sleep(0.2)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["first.mcap", "first.rrd"]
    check_integrity(tmp_path / "first.mcap")
    verify_rrd(tmp_path / "first.rrd")


def _short_protocol_episode(out: Path) -> Path:
    task = load_suite("v1").task("stairs", 2.0)
    row = run_episode(EpisodeJob(CPG, task, 0, task.seeds(1)[0], record_dir=str(out), max_steps=40, log_dir=str(out)))
    return out / row["mcap_path"]


def _rewrite_with_changed_metric(src: Path, dst: Path, step: int) -> None:
    """A tampered copy: valid MCAP (all CRCs right), one /metrics value changed."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(src, "rb") as f, open(dst, "wb") as g:
        reader = make_reader(f)
        summary = reader.get_summary()
        w = Writer(g)
        w.start()
        schema_ids = {sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        channel_ids = {cid: w.register_channel(c.topic, c.message_encoding, schema_ids[c.schema_id])
                       for cid, c in summary.channels.items()}
        for m in reader.iter_metadata():
            w.add_metadata(m.name, m.metadata)
        found = False
        for _, channel, msg in reader.iter_messages(log_time_order=True):
            data = msg.data
            if channel.topic == "/metrics":
                row = json.loads(data)
                if row["step"] == step:
                    row["reward"] += 0.5
                    found = True
                    data = json.dumps(row).encode()
            w.add_message(channel_ids[msg.channel_id], msg.log_time, data, msg.publish_time)
        w.finish()
    assert found, f"step {step} is not in /metrics"


def test_verify_accepts_the_log_and_detects_tampering(tmp_path):
    path = _short_protocol_episode(tmp_path / "run")
    runner = CliRunner()
    ok = runner.invoke(app, ["verify", str(path)])
    assert ok.exit_code == 0, ok.output
    assert "match the re-simulation from its action log exactly" in ok.output

    actions = path.with_suffix(".actions")
    assert actions.is_file()  # verify replays the action log, never the controller
    tampered = tmp_path / "tampered.mcap"
    (tmp_path / actions.name).write_bytes(actions.read_bytes())
    _rewrite_with_changed_metric(path, tampered, step=18)  # /metrics logs steps 3, 6, ...: message 5
    check_integrity(tampered)  # a consistent file: only re-simulation can tell
    bad = runner.invoke(app, ["verify", str(tampered)])
    assert bad.exit_code == 1
    assert "/metrics message 5" in bad.output and "differs from the re-simulation" in bad.output

    flipped = tmp_path / "flipped.mcap"
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF  # inside the compressed chunk
    flipped.write_bytes(bytes(data))
    with pytest.raises(EpisodeFileError):
        read_episode(flipped)
    res = runner.invoke(app, ["verify", str(flipped)])
    assert res.exit_code == 1 and "corrupt MCAP file" in res.output


def _zstd_bomb(path: Path, uncompressed_bytes: int) -> None:
    """A small MCAP file (header, one zstd chunk of `uncompressed_bytes` zeros, footer) whose one
    chunk declares its true uncompressed size."""
    import zstandard
    from mcap.data_stream import RecordBuilder
    from mcap.records import Chunk
    from mcap.writer import CompressionType, Writer

    empty = __import__("io").BytesIO()
    writer = Writer(empty, compression=CompressionType.NONE, use_chunking=False)
    writer.start("hexbench", "bomb")
    writer.finish()
    data = empty.getvalue()
    header_end = 8 + 9 + int.from_bytes(data[9:17], "little")  # magic, then opcode + length + header
    builder = RecordBuilder()
    Chunk(message_start_time=0, message_end_time=0, uncompressed_size=uncompressed_bytes, uncompressed_crc=0,
          compression="zstd", data=zstandard.ZstdCompressor(level=3).compress(bytes(uncompressed_bytes))).write(builder)
    path.write_bytes(data[:header_end] + builder.end() + data[header_end:])


@pytest.mark.parametrize("command", [["verify"], ["replay", "--summary"]])
def test_a_decompression_bomb_is_refused_before_decompressing(tmp_path, command):
    """A shared episode file whose chunk inflates far past any episode is one line, read in moments."""
    from hexbench.recording.reader import MAX_CHUNK_UNCOMPRESSED_BYTES

    bomb = tmp_path / "bomb.mcap"
    _zstd_bomb(bomb, MAX_CHUNK_UNCOMPRESSED_BYTES + 1)
    assert bomb.stat().st_size < 100_000
    t0 = time.monotonic()
    res = CliRunner().invoke(app, [command[0], str(bomb), *command[1:]])
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert time.monotonic() - t0 < 5
    assert res.exit_code == 1 and len(lines) == 1 and "bytes uncompressed" in lines[0], res.output


def test_an_episode_index_declaring_more_than_its_bound_is_refused_before_reading(tmp_path):
    """A shared run's episodes.parquet that would inflate far past any index is one line: its
    metadata (rows, declared bytes) is checked before anything is decoded. 300,000 rows of one
    repeated value take a few kB on disk."""
    import pandas as pd

    from hexbench.evaluation import evaluate as evaluate_module

    run = tmp_path / "run"
    run.mkdir()
    pd.DataFrame({"episode_id": ["x"] * 300_000, "steps": [0] * 300_000}).to_parquet(
        run / "episodes.parquet", compression="zstd", index=False)
    assert (run / "episodes.parquet").stat().st_size < 100_000
    assert evaluate_module.MAX_EPISODE_INDEX_ROWS == 100_000
    res = CliRunner().invoke(app, ["episodes", str(run)])
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert res.exit_code == 2 and len(lines) == 1 and "declares 300,000 rows" in lines[0], res.output
    assert "an episode index holds at most 100,000 rows" in lines[0]
    (run / "episodes.parquet").write_bytes(b"PAR1 not parquet")
    res = CliRunner().invoke(app, ["episodes", str(run)])
    assert res.exit_code == 2 and "unreadable episode index" in res.output and "Traceback" not in res.output


def test_episode_commands(tmp_path):
    from hexbench.evaluation.evaluate import evaluate

    out = tmp_path / "run"
    result = evaluate(CPG, [load_suite("v1").task("stairs", 2.0)], out, episodes=1, workers=1, progress=False)
    assert result.error is None
    runner = CliRunner()
    listed = runner.invoke(app, ["episodes", str(out)])
    assert listed.exit_code == 0 and "stairs-2cm-00" in listed.output
    paths = runner.invoke(app, ["episodes", str(out), "--outcome", "success", "--paths"])
    assert paths.exit_code == 0
    none = runner.invoke(app, ["episodes", str(out), "--outcome", "fall", "--paths"])
    assert none.exit_code == 0 and none.output.strip() == ""
    bad = runner.invoke(app, ["episodes", str(out), "--outcome", "crashed"])
    assert bad.exit_code == 2 and "valid: success, failure" in bad.output
    mcap = out / "episodes" / "stairs-2cm-00.mcap"
    summary = runner.invoke(app, ["replay", str(mcap), "--summary"])
    assert summary.exit_code == 0, summary.output
    assert "stairs level 2.0" in summary.output and "foot contact" in summary.output
    missing = runner.invoke(app, ["replay", str(tmp_path / "nope.mcap"), "--summary"])
    assert missing.exit_code == 2 and "no such file" in missing.output


def test_export_minari_without_minari_says_how_to_install(tmp_path):
    try:
        import minari  # noqa: F401
        pytest.skip("minari is installed")
    except ImportError:
        pass
    res = CliRunner().invoke(app, ["export", "minari", str(tmp_path)])
    assert res.exit_code == 1 and "pip install 'hexbench[minari]'" in res.output
    assert list(tmp_path.iterdir()) == []


def test_joint_states_template_encoding_matches_protobuf():
    """The vectorised encoder gives exactly what the official classes decode, zeros included."""
    from foxglove_schemas_protobuf.JointStates_pb2 import JointStates

    from hexbench.recording.mcap_episode import _joint_states_encoder
    from hexbench.recording.protobuf_rows import timestamp_field

    rng = np.random.default_rng(0)
    values = rng.normal(size=(5, 54))
    values[2, :5] = 0.0
    rows = _joint_states_encoder(JOINT_NAMES).encode(values)
    for i, row in enumerate(rows):
        msg = JointStates.FromString(timestamp_field(1_234_567_891 * i) + row.tobytes())
        assert msg.timestamp.ToNanoseconds() == 1_234_567_891 * i
        got = [(j.position, j.velocity, j.effort) for j in msg.joints]
        assert np.array_equal(np.array(got).reshape(-1), values[i])
        assert [j.name for j in msg.joints] == list(JOINT_NAMES)


def test_export_minari_replays_logged_episodes(tmp_path, monkeypatch):
    minari = pytest.importorskip("minari")
    from dataclasses import replace

    run = tmp_path / "cpg-run"
    task = load_suite("v1").task("stairs", 2.0)
    for index, seed in enumerate(task.seeds(2)):
        run_episode(EpisodeJob(CPG, task, index, seed, record_dir=str(run / "episodes"), log_dir=str(run / "episodes"),
                               max_steps=30))
    res = CliRunner().invoke(app, ["export", "minari", str(run)])
    assert res.exit_code == 0, res.output
    assert "wrote Minari dataset hexbench/cpg-run-stairs-2cm-v0 (2 episodes, 60 steps)" in res.output
    assert "ds = minari.load_dataset('hexbench/cpg-run-stairs-2cm-v0'); env = ds.recover_environment()" in res.output
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(run / "minari"))
    ds = minari.load_dataset("hexbench/cpg-run-stairs-2cm-v0")
    assert ds.total_episodes == 2 and ds.total_steps == 60
    first = next(ds.iterate_episodes())
    assert first.observations.shape == (31, 62) and first.actions.shape == (30, 18)
    env = ds.recover_environment()  # the environment the episodes were played in, step limit included
    try:
        assert env.unwrapped.config == replace(task.env_config("cpg_residual"), max_steps=30)
        obs, _ = env.reset(seed=task.seeds(2)[first.id])
        assert np.array_equal(obs, first.observations[0])
        for action in first.actions:
            obs, _, terminated, truncated, _ = env.step(action)
        assert truncated and np.array_equal(obs, first.observations[-1])
    finally:
        env.close()


def test_export_minari_refuses_a_bad_dataset_id_and_writes_nothing(tmp_path):
    pytest.importorskip("minari")
    run = tmp_path / "run"
    task = load_suite("v1").task("stairs", 2.0)
    run_episode(EpisodeJob(CPG, task, 0, task.seeds(1)[0], record_dir=str(run / "episodes"),
                           log_dir=str(run / "episodes"), max_steps=10))
    res = CliRunner().invoke(app, ["export", "minari", str(run), "--dataset-id", "my dataset"])
    assert res.exit_code == 2
    expected = ("error: --dataset-id 'my dataset' is not a Minari dataset id; use [namespace/]name-v<version> "
                "(letters, digits, - and _), e.g. hexbench/cpg-rough-v0")
    assert res.output.strip().splitlines() == [expected]
    assert not (run / "minari").exists()


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts threads through /proc")
def test_recording_many_episodes_does_not_pile_up_writer_threads(tmp_path):
    def threads() -> int:
        return len(list(Path("/proc/self/task").iterdir()))

    record_short_episode(tmp_path, "warm", steps=3)
    before = threads()
    for i in range(3):
        record_short_episode(tmp_path, f"e{i}", steps=3)
    # At most as many: a thread left over from an earlier test (a pool or a flush winding down)
    # may end meanwhile, which `==` took for a failure; a leak adds one thread per episode.
    assert threads() <= before


def test_whole_robot_contact_query_agrees_with_per_foot_query():
    from hexbench.recording.capture import foot_contacts

    env = HexapodEnv(terrain="rough", level=8.0, max_steps=200)
    env.reset(seed=3)
    seen = set()
    for _ in range(120):
        env.step(np.zeros(18))
        ours = foot_contacts(env.sim)
        assert np.array_equal(ours, env.sim.foot_contacts())
        seen.add(tuple(ours))
    env.close()
    assert len(seen) > 2  # feet lift and land: the comparison covered changing contacts


def test_message_index_points_at_every_message(episode):
    """Foxglove's indexed reader needs the per-channel message index; it is written by hand in bulk."""
    import struct

    import zstandard
    from mcap.records import Chunk, ChunkIndex, MessageIndex
    from mcap.stream_reader import StreamReader

    out, files = episode
    chunks, indexes, chunk_indexes = [], [], []
    with open(out / files["mcap_path"], "rb") as f:
        for record in StreamReader(f, emit_chunks=True, validate_crcs=True).records:
            if isinstance(record, Chunk):
                chunks.append(record)
            elif isinstance(record, MessageIndex):
                indexes.append(record)
            elif isinstance(record, ChunkIndex):
                chunk_indexes.append(record)
    assert len(chunks) == 1 and len(chunk_indexes) == 1 and chunk_indexes[0].message_index_length > 0
    data = zstandard.decompress(chunks[0].data, chunks[0].uncompressed_size)
    counted = 0
    for index in indexes:
        assert index.channel_id in chunk_indexes[0].message_index_offsets
        for log_time, offset in index.records:
            opcode, _length, channel, _seq, t_log, _t_pub = struct.unpack_from("<BQHIQQ", data, offset)
            assert (opcode, channel, t_log) == (0x05, index.channel_id, log_time)
            assert chunks[0].message_start_time <= log_time <= chunks[0].message_end_time
            counted += 1
    assert counted == sum(1 for _ in _all_message_records(data))


def _all_message_records(data: bytes):
    import struct

    at = 0
    while at < len(data):
        opcode, length = struct.unpack_from("<BQ", data, at)
        if opcode == 0x05:
            yield at
        at += 9 + length


def test_rrd_can_be_built_from_the_mcap(tmp_path):
    """Episodes recorded MCAP-only (RecordingConfig(write_rrd=False)) still get a Rerun file on demand."""
    from hexbench.recording import RecordingConfig
    from hexbench.replay.rrd_from_mcap import rrd_from_mcap

    env = HexapodEnv(terrain="stairs", level=4.0, max_steps=40)
    env.reset(seed=2)
    rec = make_episode_recorder(tmp_path, "stairs-4cm-00", META, RecordingConfig(write_rrd=False))
    rec.on_reset(env)
    while True:
        obs, reward, terminated, truncated, info = env.step(np.zeros(18))
        rec.on_step(env, obs, np.zeros(18), reward, info)
        if terminated or truncated:
            break
    files = rec.on_end({"steps": 40})
    env.close()
    assert set(files) == {"mcap_path", "mcap_sha256"} and [p.name for p in tmp_path.iterdir()] == ["stairs-4cm-00.mcap"]
    rrd = rrd_from_mcap(tmp_path / files["mcap_path"], tmp_path / "stairs-4cm-00.rrd")
    verify_rrd(rrd)
    printed = subprocess.run([str(Path(sys.executable).with_name("rerun")), "rrd", "print", str(rrd)],
                             capture_output=True, text=True, timeout=60, env={**os.environ, "RERUN_ANALYTICS": "0"}).stdout
    assert '"stairs-4cm-00"' in printed and "/world/robot/links" in printed and "/world/terrain" in printed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stairs-4cm-00.mcap", "stairs-4cm-00.rrd"]


def test_an_rrd_built_from_the_mcap_onto_a_full_disk_is_one_output_error(episode, tmp_path, small_disk):
    """The .rrd built on demand for an MCAP-only episode, onto a disk (a tmpfs) with no room for it."""
    out, files = episode
    disk = tmp_path / "disk"
    prefix = small_disk(disk, 4096)
    script = textwrap.dedent(f"""
        from pathlib import Path
        from hexbench.errors import OutputError
        from hexbench.replay.rrd_from_mcap import rrd_from_mcap
        try:
            rrd_from_mcap({str(out / files["mcap_path"])!r}, {str(disk / "episode.rrd")!r})
        except OutputError as e:
            print("error:", e)
        print("left:", sorted(p.name for p in Path({str(disk)!r}).iterdir()))
    """)
    shown = subprocess.run([*prefix, sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True,
                           timeout=120)
    assert shown.stdout.splitlines() == [f"error: {disk}/episode.rrd: cannot be written (no space left on device)",
                                         "left: []"], shown.stderr
