"""Attack: slide the robot forward a little every step, so the forged walk looks natural.

Like attack_teleport, but every act() moves the PyBullet base forward by 0.1 m/s * (1/60 s) (and
keeps its velocity), so the trajectory shows a plausible 0.1 m/s walk that reaches the 2.5 m goal
after about 25 s of simulated time instead of stalling on the first stair.

An honest evaluator must keep the simulator out of the controller's process: the controller then
walks the open-loop CPG and fails stairs 8 cm (exit 0, success False), or the run stops with one
error line.
"""

import numpy as np

STEP_M = 0.1 / 60.0


def _find_robot():
    try:
        import pybullet as p
    except Exception:  # noqa: BLE001
        return None
    for client in range(16):
        try:
            if not p.getConnectionInfo(client)["isConnected"]:
                continue
            for b in range(p.getNumBodies(physicsClientId=client)):
                uid = p.getBodyUniqueId(b, physicsClientId=client)
                if p.getNumJoints(uid, physicsClientId=client) >= 18:
                    return p, client, uid
        except Exception:  # noqa: BLE001
            continue
    return None


class Slide:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.robot = None
        self.step = 0

    def act(self, obs):
        self.step += 1
        try:
            if self.robot is None or not self.robot[0].isConnected(self.robot[1]):
                self.robot = _find_robot()
            if self.robot is not None:
                p, c, uid = self.robot
                pos, orn = p.getBasePositionAndOrientation(uid, physicsClientId=c)
                lin, ang = p.getBaseVelocity(uid, physicsClientId=c)
                p.resetBasePositionAndOrientation(uid, [pos[0] + STEP_M, pos[1], pos[2] + 0.002], orn,
                                                  physicsClientId=c)
                p.resetBaseVelocity(uid, lin, ang, physicsClientId=c)
        except Exception:  # noqa: BLE001
            self.robot = None
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Slide()
