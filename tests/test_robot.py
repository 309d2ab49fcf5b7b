"""The simulated JetHexa: URDF structure, paper Table 3 numbers, stance, servos, sign conventions."""

from __future__ import annotations

import dataclasses
import math
import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pybullet as p
import pytest

from hexbench.world.robot import FOOT_LINK_NAMES, JOINT_NAMES, LEG_NAMES, NUM_JOINTS, JetHexaSpec, urdf_text
from hexbench.world.sim import PhysicsConfig, Simulation, _urdf_file
from hexbench.world.terrain import FlatTerrain

SPEC = JetHexaSpec()


@pytest.fixture()
def client():
    cid = p.connect(p.DIRECT)
    yield cid
    p.disconnect(cid)


def load_robot(client: int, spec: JetHexaSpec = SPEC, height_m: float = 1.0, fixed: bool = True) -> int:
    return p.loadURDF(_urdf_file(spec), [0, 0, height_m], useFixedBase=fixed, physicsClientId=client)


def foot_centres(client: int, robot: int, spec: JetHexaSpec = SPEC) -> np.ndarray:
    """World positions of the six foot-sphere centres, legs in order RF..LF: (6, 3) [m]."""
    out = []
    for leg in range(6):
        state = p.getLinkState(robot, 3 * leg + 2, computeForwardKinematics=True, physicsClientId=client)
        rot = np.array(p.getMatrixFromQuaternion(state[5])).reshape(3, 3)
        out.append(np.array(state[4]) + rot @ np.array([0.0, 0.0, -(spec.tibia_length_m - spec.foot_radius_m)]))
    return np.array(out)


def test_urdf_has_18_revolute_joints_in_paper_order() -> None:
    root = ET.fromstring(urdf_text())
    joints = root.findall("joint")
    assert [j.get("name") for j in joints] == list(JOINT_NAMES)
    assert JOINT_NAMES[:3] == ("RF_hip", "RF_knee", "RF_ankle")
    assert [name.split("_")[0] for name in JOINT_NAMES[::3]] == ["RF", "RM", "RB", "LB", "LM", "LF"]
    assert all(j.get("type") == "revolute" for j in joints)
    assert NUM_JOINTS == 18 and LEG_NAMES == ("RF", "RM", "RB", "LB", "LM", "LF")


def test_urdf_uses_only_primitive_collision_shapes() -> None:
    root = ET.fromstring(urdf_text())
    shapes = [child.tag for geom in root.iter("geometry") for child in geom]
    assert shapes and set(shapes) <= {"box", "sphere", "cylinder", "capsule"}
    assert "mesh" not in shapes
    assert len(root.findall("link")) == 1 + 18
    for link in root.findall("link"):
        assert link.find("collision") is not None, link.get("name")


def test_pybullet_joint_order_limits_effort_and_velocity(client: int) -> None:
    robot = load_robot(client)
    assert p.getNumJoints(robot, physicsClientId=client) == NUM_JOINTS
    limits = SPEC.joint_limits_rad()
    for j in range(NUM_JOINTS):
        info = p.getJointInfo(robot, j, physicsClientId=client)
        assert info[1].decode() == JOINT_NAMES[j]
        assert info[2] == p.JOINT_REVOLUTE
        assert (info[8], info[9]) == pytest.approx(limits[j], abs=1e-4)
        assert info[10] == pytest.approx(SPEC.servo_stall_torque_nm, abs=1e-3)
        assert info[11] == pytest.approx(SPEC.servo_max_speed_rad_per_s, abs=1e-3)
    names = [p.getJointInfo(robot, j, physicsClientId=client)[12].decode() for j in range(NUM_JOINTS)]
    assert names[2::3] == list(FOOT_LINK_NAMES)


def test_servo_numbers_are_those_of_jethexa_bus_servos() -> None:
    """Stall 3-4 N m (HX-35H class: 35 kg cm ~= 3.4 N m) and ~0.18 s per 60 deg (~5.8 rad/s)."""
    assert 3.0 <= SPEC.servo_stall_torque_nm <= 4.0
    assert 5.0 <= SPEC.servo_max_speed_rad_per_s <= 7.0
    hip, knee, ankle = SPEC.hip_limits_rad, SPEC.knee_limits_rad, SPEC.ankle_limits_rad
    for lo, hi in (hip, knee, ankle):
        assert lo < 0 < hi
    # the CPG's default output (hip +-A1, knee 0..A2, ankle -A3..0) fits inside the limits
    assert hip[1] >= 0.45 and knee[1] >= 1.2 and ankle[0] <= -1.0


def test_table3_leg_lengths_and_total_mass(client: int) -> None:
    assert (SPEC.coxa_length_m, SPEC.femur_length_m, SPEC.tibia_length_m) == (0.05, 0.08, 0.13)
    free = load_robot(client, fixed=False)  # a fixed base reports mass 0
    masses = [p.getDynamicsInfo(free, link, physicsClientId=client)[0] for link in range(-1, NUM_JOINTS)]
    assert sum(masses) == pytest.approx(2.5, abs=1e-6)
    p.removeBody(free, physicsClientId=client)
    robot = load_robot(client)
    assert SPEC.total_mass_kg == pytest.approx(2.5, abs=1e-9)
    # at zero angles coxa + femur reach straight out and the tibia hangs down its full length
    hip_z = 1.0 + SPEC.hip_height_above_body_centre_m
    feet = foot_centres(client, robot)
    np.testing.assert_allclose(feet[:, 2], hip_z - (SPEC.tibia_length_m - SPEC.foot_radius_m), atol=1e-6)
    for leg, mount in enumerate(SPEC.mounts):
        reach = math.hypot(feet[leg, 0] - mount.x_m, feet[leg, 1] - mount.y_m)
        assert reach == pytest.approx(SPEC.coxa_length_m + SPEC.femur_length_m, abs=1e-6)


def test_stands_with_body_centre_about_12_cm_above_flat_ground() -> None:
    """Paper Table 3: centre of mass 12 cm high. Measured after 2 s of standing on zero targets."""
    sim = Simulation()
    try:
        sim.load(FlatTerrain(), np.random.default_rng(0))
        for _ in range(120):
            sim.send_targets(np.zeros(NUM_JOINTS))
            sim.step_physics()
        state = sim.state()
        assert state.base_pos_m[2] == pytest.approx(0.12, abs=0.01)
        c, r = sim.client, sim.robot_id
        com = np.zeros(3)
        for link in range(-1, NUM_JOINTS):
            mass = p.getDynamicsInfo(r, link, physicsClientId=c)[0]
            pos = (p.getBasePositionAndOrientation(r, physicsClientId=c)[0] if link < 0
                   else p.getLinkState(r, link, computeForwardKinematics=True, physicsClientId=c)[0])
            com += mass * np.array(pos)
        com /= SPEC.total_mass_kg
        assert com[2] == pytest.approx(0.12, abs=0.01)
        assert np.degrees(np.abs(state.base_rpy_rad[:2])).max() < 1.0  # level
        assert sim.foot_contacts().all()  # on all six feet
        assert np.abs(state.base_lin_vel_m_per_s).max() < 0.01  # at rest
        assert np.abs(state.joint_torque_nm).max() < SPEC.servo_stall_torque_nm / 2  # not straining
    finally:
        sim.close()


@pytest.mark.xfail(strict=True, reason="robot.py's leg mounts give an overall footprint of 44.4 x 44.0 cm at the "
                   "zero stance; paper Table 3 lists body length 39.7 cm and width 42.6 cm (see docs/robot.md)")
def test_overall_footprint_matches_table3(client: int) -> None:
    robot = load_robot(client)
    feet = foot_centres(client, robot)
    r = SPEC.foot_radius_m
    length = feet[:, 0].max() - feet[:, 0].min() + 2 * r
    width = feet[:, 1].max() - feet[:, 1].min() + 2 * r
    assert length == pytest.approx(0.397, abs=0.01)
    assert width == pytest.approx(0.426, abs=0.01)


@pytest.mark.parametrize("leg", range(6), ids=LEG_NAMES)
def test_joint_sign_convention_is_the_same_on_every_leg(client: int, leg: int) -> None:
    """hip > 0 moves the foot forward, knee > 0 lifts it, ankle < 0 folds it in under the body."""
    robot = load_robot(client)
    hip_xy = np.array([SPEC.mounts[leg].x_m, SPEC.mounts[leg].y_m])
    rest = foot_centres(client, robot)[leg]

    def moved(joint: int, angle: float) -> np.ndarray:
        p.resetJointState(robot, 3 * leg + joint, angle, physicsClientId=client)
        pos = foot_centres(client, robot)[leg]
        p.resetJointState(robot, 3 * leg + joint, 0.0, physicsClientId=client)
        return pos

    assert moved(0, 0.3)[0] > rest[0] + 0.02
    assert moved(0, -0.3)[0] < rest[0] - 0.02
    assert moved(1, 0.3)[2] > rest[2] + 0.02
    folded = moved(2, -0.3)
    assert np.linalg.norm(folded[:2] - hip_xy) < np.linalg.norm(rest[:2] - hip_xy) - 0.02
    assert folded[2] == pytest.approx(rest[2], abs=0.01)


def test_servo_torque_never_exceeds_stall_torque() -> None:
    """Body held 4 cm lower than its stance: the legs push against the ground at their torque limit."""
    sim = Simulation()
    try:
        sim.load(FlatTerrain(), np.random.default_rng(0))
        c, r = sim.client, sim.robot_id
        p.createConstraint(r, -1, -1, -1, p.JOINT_FIXED, [0, 0, 0], [0, 0, 0], [0, 0, 0.08], physicsClientId=c)
        torques = []
        for _ in range(60):
            sim.send_targets(np.tile([0.0, -0.8, 0.8], 6))  # knees down, ankles out: push the body up
            sim.step_physics()
            torques.append(sim.state().joint_torque_nm)
        torques = np.abs(np.array(torques))
        assert torques.max() <= SPEC.servo_stall_torque_nm + 1e-6
        assert torques.max() >= 0.99 * SPEC.servo_stall_torque_nm  # the limit is actually reached
    finally:
        sim.close()


def test_commanded_joint_speed_is_limited_to_servo_speed() -> None:
    """A far target is approached at no more than max_speed * control_dt per control step."""
    sim = Simulation()
    try:
        sim.load(FlatTerrain(), np.random.default_rng(0))
        c = sim.client
        p.removeBody(sim.robot_id, physicsClientId=c)
        sim.robot_id = load_robot(c, fixed=True)
        dt = PhysicsConfig().control_dt_s
        max_step = SPEC.servo_max_speed_rad_per_s * dt
        target = np.tile([0.8, 1.5, -1.5], 6)
        previous_command = np.zeros(NUM_JOINTS)
        previous_pos = sim.state().joint_pos_rad
        steps_to_arrive = math.ceil(1.5 / max_step)  # knee and ankle travel 1.5 rad
        for k in range(steps_to_arrive + 30):
            command = sim.send_targets(target)
            assert np.abs(command - previous_command).max() <= max_step + 1e-12
            previous_command = command
            sim.step_physics()
            pos = sim.state().joint_pos_rad
            # averaged over a control period the joints move no faster than the servo speed (+10%)
            assert np.abs(pos - previous_pos).max() <= 1.1 * max_step
            previous_pos = pos
        np.testing.assert_allclose(sim.state().joint_pos_rad, target, atol=0.01)
    finally:
        sim.close()


def test_command_is_clipped_to_joint_limits() -> None:
    sim = Simulation()
    try:
        sim.load(FlatTerrain(), np.random.default_rng(0))
        for _ in range(60):
            command = sim.send_targets(np.full(NUM_JOINTS, 10.0))
        np.testing.assert_allclose(command, sim.joint_upper_rad)
        for _ in range(60):
            command = sim.send_targets(np.full(NUM_JOINTS, -10.0))
        np.testing.assert_allclose(command, sim.joint_lower_rad)
    finally:
        sim.close()


def test_spec_is_frozen_and_drives_the_urdf(client: int) -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        SPEC.tibia_length_m = 0.2  # type: ignore[misc]
    longer = dataclasses.replace(SPEC, tibia_length_m=0.15, body_mass_kg=2.0)
    robot = load_robot(client, longer)
    feet = foot_centres(client, robot, longer)
    hip_z = 1.0 + longer.hip_height_above_body_centre_m
    np.testing.assert_allclose(feet[:, 2], hip_z - (0.15 - longer.foot_radius_m), atol=1e-6)
    free = load_robot(client, longer, fixed=False)
    masses = [p.getDynamicsInfo(free, link, physicsClientId=client)[0] for link in range(-1, NUM_JOINTS)]
    assert sum(masses) == pytest.approx(longer.total_mass_kg, abs=1e-6)
    assert longer.total_mass_kg == pytest.approx(2.9)


def test_the_files_pybullet_loads_go_when_the_process_that_wrote_them_exits(tmp_path):
    """PyBullet loads the robot's URDF and the plain terrain texture from files: each process writes
    them once and removes them at exit, and a fork of it that exits leaves them to their owner."""
    script = (
        "import os, sys\n"
        "from hexbench.perception.views import _white_texture_file\n"
        "from hexbench.world.robot import JetHexaSpec\n"
        "from hexbench.world.sim import _urdf_file\n"
        "files = [_urdf_file(JetHexaSpec()), _white_texture_file()]\n"
        "pid = os.fork()\n"
        "if pid == 0:\n"
        "    sys.exit(0)\n"
        "os.waitpid(pid, 0)\n"
        "assert all(os.path.exists(f) for f in files), 'a fork removed its parent files'\n"
        "print(len(files))\n"
    )
    temp = tmp_path / "temp"
    temp.mkdir()
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "TMPDIR": str(temp)})
    assert done.returncode == 0 and done.stdout.strip() == "2", done.stderr
    assert sorted(p.name for p in temp.iterdir()) == []
