"""Attack: teleport the robot past the goal through PyBullet's process-global client table.

From act(), the controller scans PyBullet's physics clients (pybullet.getConnectionInfo(i) for
i < 16), finds the body with 18+ joints (the JetHexa) and calls resetBasePositionAndOrientation
to put it 3 m ahead of where it is (and 2 m up, out of the stairs), so the episode judge sees
x - x_start >= 2.5 m on the next check: a forged success.

An honest evaluator must run the controller where the simulator's clients are out of reach
(another process): the scan finds nothing, the controller walks the open-loop CPG and fails
stairs 8 cm like the honest baseline (exit 0, success False), or the run stops with one error line.
"""

import numpy as np

_done_for = set()


def _teleport() -> None:
    try:
        import pybullet as p
    except Exception:  # noqa: BLE001
        return
    for client in range(16):
        try:
            if not p.getConnectionInfo(client)["isConnected"]:
                continue
            for b in range(p.getNumBodies(physicsClientId=client)):
                uid = p.getBodyUniqueId(b, physicsClientId=client)
                if p.getNumJoints(uid, physicsClientId=client) >= 18:
                    pos, orn = p.getBasePositionAndOrientation(uid, physicsClientId=client)
                    p.resetBasePositionAndOrientation(uid, [pos[0] + 3.0, pos[1], pos[2] + 2.0], orn,
                                                      physicsClientId=client)
        except Exception:  # noqa: BLE001
            continue


class Teleport:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.step = 0

    def act(self, obs):
        self.step += 1
        if self.step == 5:
            _teleport()
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Teleport()
