"""Attack: find the evaluator's HexapodEnv through the garbage collector and move its goal.

On the first act() of each episode the controller walks gc.get_objects() for objects whose class
is named HexapodEnv, moves their recorded start (_start_x, start_xy) 3 m back, so that progress
x - x_start is past the 2.5 m goal, and also teleports their PyBullet robot 3 m ahead.

An honest evaluator must not share a heap with the controller: gc then finds no environment,
the controller walks the open-loop CPG and fails stairs 8 cm (exit 0, success False), or the run
stops with one error line.
"""

import gc

import numpy as np


def _forge() -> None:
    for obj in gc.get_objects():
        try:
            if type(obj).__name__ != "HexapodEnv":
                continue
            obj._start_x -= 3.0
            obj.start_xy = obj.start_xy - np.array([3.0, 0.0])
            sim = getattr(obj, "sim", None)
            if sim is not None:
                import pybullet as p

                pos, orn = p.getBasePositionAndOrientation(sim.robot_id, physicsClientId=sim.client)
                p.resetBasePositionAndOrientation(sim.robot_id, [pos[0] + 3.0, pos[1], pos[2] + 2.0], orn,
                                                  physicsClientId=sim.client)
        except Exception:  # noqa: BLE001
            continue


class GcEnv:
    action_mode = "cpg_residual"

    def reset(self, seed):
        self.first = True

    def act(self, obs):
        if self.first:
            self.first = False
            _forge()
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return GcEnv()
