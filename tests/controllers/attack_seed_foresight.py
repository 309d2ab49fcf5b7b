"""Attack: recognise the protocol's episode seeds in reset(seed) (terrain foresight).

The protocol's episode seeds are public (hexbench.suite.tasks.episode_seed; TaskSpec.seeds()). A
controller told the real seed can rebuild the environment, HexapodEnv(task.env_config(...))
.reset(seed=seed), and see the exact terrain and start pose before the episode. This file checks
whether the seed it is given is one of the task's episode seeds (and rebuilds the environment
with it to show the foresight works); if so it makes the foresight visible by returning an
out-of-range action (np.full(18, 5.0)), which any evaluator rejects with an error.

An honest evaluator must pass reset() a seed derived from the episode seed that the controller
cannot map back (the environment keeps the real one): the check then fails, the controller walks
the open-loop CPG and the run must exit 0 with an honest failed score.
"""

import numpy as np


def _episode_seeds(task) -> set:
    seeds = set()
    try:
        seeds.update(task.seeds(20))
        seeds.update(task.seeds())
    except Exception:  # noqa: BLE001
        pass
    try:
        from hexbench.suite.tasks import episode_seed

        for i in range(100):
            seeds.add(episode_seed(task.protocol, task.terrain, task.level, i))
    except Exception:  # noqa: BLE001
        pass
    return seeds


class Foresight:
    action_mode = "cpg_residual"

    def __init__(self, task):
        self.task = task
        self.seeds = _episode_seeds(task)
        self.knows = False

    def reset(self, seed):
        self.knows = seed in self.seeds
        if self.knows:
            try:  # the foresight: the exact episode the evaluator is about to play
                from hexbench.world.env import HexapodEnv

                env = HexapodEnv(self.task.env_config("cpg_residual"))
                obs, _ = env.reset(seed=seed)
                self.predicted_start_x = float(obs[54])
                env.close()
            except Exception:  # noqa: BLE001
                pass

    def act(self, obs):
        if self.knows:
            return np.full(18, 5.0, dtype=np.float32)
        return np.zeros(18, dtype=np.float32)


def make_controller(task):
    return Foresight(task)
