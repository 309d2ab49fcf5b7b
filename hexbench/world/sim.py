"""One PyBullet physics client (DIRECT) holding the JetHexa and a terrain.

Rates: physics at 240 Hz (PyBullet's default step, 1/240 s); the controller acts every 4
physics steps, i.e. at 60 Hz. Servos are PyBullet position motors with the stall torque as
force limit; the servo speed limit is enforced on the commanded target (it moves at most
max_speed * dt per control step towards the requested angle).
"""

from __future__ import annotations

import atexit
import contextlib
import os
import tempfile
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

# np.clip's ufunc, called directly: np.clip's Python wrapper costs several times the work (the same
# numbers; used on the hot paths of a control step: here, the env, the action check, policy controllers)
try:
    from numpy._core.umath import clip as clip_ufunc
except ImportError:  # numpy < 2
    from numpy.core.umath import clip as clip_ufunc


def _import_pybullet_quietly():
    """Import pybullet without the 'pybullet build time' banner it writes to stderr on import."""
    import sys

    sys.stderr.flush()
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        import pybullet
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)
    return pybullet


p = _import_pybullet_quietly()

from hexbench.errors import OutputError, os_reason
from hexbench.world.robot import FOOT_LINK_NAMES, NUM_JOINTS, JetHexaSpec, urdf_text
from hexbench.world.terrain import BuiltTerrain, Terrain


@dataclass(frozen=True)
class PhysicsConfig:
    physics_dt_s: float = 1.0 / 240.0
    substeps_per_control: int = 4  # control at 60 Hz
    solver_iterations: int = 20
    gravity_m_per_s2: float = 9.81

    @property
    def control_dt_s(self) -> float:
        return self.physics_dt_s * self.substeps_per_control


class RobotState:
    """The robot's state after a step, read in one go into one float64 vector.

    Fields are views into that vector: joint_pos_rad, joint_vel_rad_per_s, joint_torque_nm
    (18 each), base_pos_m (3, world), base_quat_xyzw (4), base_rpy_rad (3: roll, pitch, yaw);
    up_z is the z component of the body's up axis (cos of its tilt from vertical).
    """

    __slots__ = ("values", "up_z", "client", "robot_id")

    def __init__(self, values: np.ndarray, up_z: float, client: int = -1, robot_id: int = -1):
        self.values = values
        self.up_z = up_z
        self.client = client
        self.robot_id = robot_id

    joint_pos_rad = property(lambda self: self.values[0:18])
    joint_vel_rad_per_s = property(lambda self: self.values[18:36])
    joint_torque_nm = property(lambda self: self.values[36:54])
    base_pos_m = property(lambda self: self.values[54:57])
    base_quat_xyzw = property(lambda self: self.values[57:61])
    base_rpy_rad = property(lambda self: self.values[61:64])

    @property
    def base_lin_vel_m_per_s(self) -> np.ndarray:
        """(3,) world linear velocity of the base [m/s] (read on demand: not needed every step)."""
        lin, _ = p.getBaseVelocity(self.robot_id, physicsClientId=self.client)
        return np.array(lin)


def process_file(prefix: str, suffix: str, content: bytes, what: str) -> str:
    """`content` in a file of the temporary folder for the life of this process (PyBullet loads
    URDFs and textures from files only), removed when the process that made it exits (not by its
    forks); a temporary folder that cannot take it (full, read-only) is one OutputError line
    naming `what`."""
    try:
        fd, path = tempfile.mkstemp(prefix=prefix, suffix=suffix)
    except OSError as e:
        raise OutputError(f"{tempfile.gettempdir()}: cannot write {what} there ({os_reason(e)})") from None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(content)
    except OSError as e:
        os.unlink(path)
        raise OutputError(f"{path}: cannot write {what} ({os_reason(e)})") from None
    atexit.register(_remove_if_made_here, path, os.getpid())
    return path


def _remove_if_made_here(path: str, maker_pid: int) -> None:
    if os.getpid() == maker_pid:
        with contextlib.suppress(OSError):
            os.unlink(path)


@lru_cache(maxsize=4)
def _urdf_file(spec: JetHexaSpec) -> str:
    """The robot URDF, written once per process and spec."""
    return process_file("jethexa_", ".urdf", urdf_text(spec).encode(), "the robot's URDF")


class Simulation:
    """Robot + terrain in one physics client. `load(terrain, rng, pose)` rebuilds the world."""

    def __init__(self, robot: JetHexaSpec = JetHexaSpec(), physics: PhysicsConfig = PhysicsConfig()):
        self.robot_spec = robot
        self.physics = physics
        self.client = p.connect(p.DIRECT)
        self.robot_id = -1
        self.terrain: BuiltTerrain | None = None
        self.joint_indices = list(range(NUM_JOINTS))
        self.foot_link_indices: list[int] = []
        limits = np.array(robot.joint_limits_rad())
        self.joint_lower_rad, self.joint_upper_rad = limits[:, 0], limits[:, 1]
        self._command = np.zeros(NUM_JOINTS)
        self._forces = [robot.servo_stall_torque_nm] * NUM_JOINTS
        self._kp = [robot.servo_position_gain] * NUM_JOINTS
        self._kd = [robot.servo_velocity_gain] * NUM_JOINTS
        self._max_delta_rad = robot.servo_max_speed_rad_per_s * physics.control_dt_s
        # per-joint bounds of one control step's target change (arrays: a little cheaper than scalars)
        self._step_low_rad = np.full(NUM_JOINTS, -self._max_delta_rad)
        self._step_high_rad = np.full(NUM_JOINTS, self._max_delta_rad)
        self._substeps = range(physics.substeps_per_control)

    def load(self, terrain: Terrain, rng: np.random.Generator,
             base_xy_m: tuple[float, float] = (0.0, 0.0), yaw_rad: float = 0.0) -> None:
        """Reset the world: a fresh terrain instance from `rng` and the robot standing on it."""
        c = self.client
        p.resetSimulation(physicsClientId=c)
        p.setGravity(0, 0, -self.physics.gravity_m_per_s2, physicsClientId=c)
        p.setPhysicsEngineParameter(fixedTimeStep=self.physics.physics_dt_s,
                                    numSolverIterations=self.physics.solver_iterations,
                                    deterministicOverlappingPairs=1, physicsClientId=c)
        self.terrain = terrain.build(c, rng)
        x, y = base_xy_m
        z = self.terrain.height_at(x, y) + self.robot_spec.standing_base_height_m + 0.01
        self.robot_id = p.loadURDF(_urdf_file(self.robot_spec), [x, y, z],
                                   p.getQuaternionFromEuler([0, 0, yaw_rad]), physicsClientId=c)
        names = {p.getJointInfo(self.robot_id, j, physicsClientId=c)[12].decode(): j
                 for j in range(p.getNumJoints(self.robot_id, physicsClientId=c))}
        self.foot_link_indices = [names[n] for n in FOOT_LINK_NAMES]
        for link in self.foot_link_indices:
            p.changeDynamics(self.robot_id, link, lateralFriction=self.robot_spec.foot_friction, physicsClientId=c)
        self._command = np.zeros(NUM_JOINTS)
        self.send_targets(self._command)
        for _ in range(24):  # settle onto the ground (0.1 s)
            p.stepSimulation(physicsClientId=c)

    def send_targets(self, targets_rad: np.ndarray) -> np.ndarray:
        """Command joint targets (clipped to limits, rate-limited to servo speed); return what was sent."""
        # The clip ufunc is min(max(x, lower), upper), as np.clip; none of these bounds is +-0.0,
        # so there is not even a sign-of-zero tie where it could differ from np.minimum/np.maximum.
        wanted = clip_ufunc(targets_rad, self.joint_lower_rad, self.joint_upper_rad)
        self._command = self._command + clip_ufunc(wanted - self._command, self._step_low_rad, self._step_high_rad)
        p.setJointMotorControlArray(self.robot_id, self.joint_indices, p.POSITION_CONTROL,
                                    targetPositions=self._command.tolist(), forces=self._forces,
                                    positionGains=self._kp, velocityGains=self._kd, physicsClientId=self.client)
        return self._command

    def step_physics(self) -> None:
        """Advance one control period (substeps_per_control physics steps)."""
        step, c = p.stepSimulation, self.client
        for _ in self._substeps:
            step(physicsClientId=c)

    def state(self) -> RobotState:
        c, r = self.client, self.robot_id
        q, qd, _, tau = zip(*p.getJointStates(r, self.joint_indices, physicsClientId=c))
        pos, quat = p.getBasePositionAndOrientation(r, physicsClientId=c)
        # np.fromiter with a known count over one tuple: the same doubles as np.array(q + qd + ...),
        # without the intermediate tuples, at under half the cost
        return RobotState(np.fromiter((*q, *qd, *tau, *pos, *quat, *p.getEulerFromQuaternion(quat)), np.float64, 64),
                          1.0 - 2.0 * (quat[0] * quat[0] + quat[1] * quat[1]), c, r)

    def foot_contacts(self) -> np.ndarray:
        """Whether each foot (tibia link) touches anything: (6,) bool."""
        c = self.client
        return np.array([
            len(p.getContactPoints(bodyA=self.robot_id, linkIndexA=link, physicsClientId=c)) > 0
            for link in self.foot_link_indices
        ])

    def link_poses(self) -> list[tuple[tuple[float, ...], tuple[float, ...]]]:
        """World (position, quaternion xyzw) of every link, base first."""
        c, r = self.client, self.robot_id
        base = p.getBasePositionAndOrientation(r, physicsClientId=c)
        links = p.getLinkStates(r, list(range(p.getNumJoints(r, physicsClientId=c))),
                                computeForwardKinematics=True, physicsClientId=c)
        return [base] + [(s[4], s[5]) for s in links]

    def close(self) -> None:
        if self.client >= 0 and p.isConnected(self.client):
            p.disconnect(self.client)
        self.client = -1

    def __del__(self) -> None:  # pragma: no cover - best effort at interpreter exit
        try:
            self.close()
        except Exception:
            pass

