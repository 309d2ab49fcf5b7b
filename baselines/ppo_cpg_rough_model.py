"""PPO-CPG's rough-terrain weights on every terrain: the "rough terrain model" of paper Table 5.

    hexbench run baselines/ppo_cpg_rough_model.py --terrain slopes --levels 10,11,12,13,14,15
    hexbench run baselines/ppo_cpg_rough_model.py --terrain stairs --levels 5.5,6,6.5,7,7.5,8

The paper tests the model trained on rough ground on slopes and stairs ("adaptability tests using a
rough terrain model on stairs and slopes", section 4.4, Table 5). The shipped `ppo_cpg-rough`
weights act here on any terrain. They were trained with the rough eps (0.6); the env scales the
residual by the task's eps (paper 3.2: slopes 0.4, stairs 0.3), so the controller sends
a_r x 0.6 / eps_task, clipped to [-1, 1] (as baselines/hlta.py does), and the joints get what the
policy asked for in training wherever that fits the task's residual range.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Config:
    low_level_baseline: str = "ppo_cpg.py"  # the baseline whose shipped weights act
    weights_terrain: str = "rough"  # the weights used on every terrain


CONFIG = Config()


class RoughModelController:
    action_mode = "cpg_residual"

    def __init__(self, policy, scale: float):
        self.policy = policy
        self.scale = scale  # eps_trained / eps_task
        self.checkpoint_paths = list(policy.checkpoint_paths)

    def reset(self, seed: int) -> None:
        self.policy.reset(seed)

    def act(self, obs: np.ndarray) -> np.ndarray:
        return np.clip(np.asarray(self.policy.act(obs)) * self.scale, -1.0, 1.0).astype(np.float32)


def make_controller(task, config: Config = CONFIG) -> RoughModelController:
    from hexbench.agents.policy import make_policy_controller
    from hexbench.suite.controller import load_controller_module
    from hexbench.world.env import DEFAULT_RESIDUAL_SCALE

    low = load_controller_module(HERE / config.low_level_baseline)
    policy = make_policy_controller(low.CONFIG, low.CHECKPOINTS_DIR, "ppo_cpg", task,
                                    weights_terrain=config.weights_terrain)
    trained_eps = DEFAULT_RESIDUAL_SCALE[config.weights_terrain]
    return RoughModelController(policy, trained_eps / DEFAULT_RESIDUAL_SCALE[task.terrain])
