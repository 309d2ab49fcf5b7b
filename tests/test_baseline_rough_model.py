"""baselines/ppo_cpg_rough_model.py: the rough weights on any terrain act as they were trained (paper Table 5)."""

from pathlib import Path

import numpy as np
import pytest

from hexbench.suite.controller import load_controller_module
from hexbench.suite.tasks import load_suite

REPO = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("terrain, level, scale", [("rough", 5, 1.0), ("slopes", 12, 1.5), ("stairs", 6, 2.0)])
def test_the_residual_is_rescaled_from_the_rough_eps_to_the_tasks(terrain, level, scale):
    module = load_controller_module(REPO / "baselines" / "ppo_cpg_rough_model.py")
    ctrl = module.make_controller(load_suite().task(terrain, level))
    assert ctrl.scale == pytest.approx(scale)
    assert [p.name for p in ctrl.checkpoint_paths] == ["ppo_cpg-rough.zip"]  # the rough weights everywhere
    obs = np.zeros(62, np.float32)
    raw = np.asarray(ctrl.policy.act(obs))
    np.testing.assert_allclose(ctrl.act(obs), np.clip(raw * scale, -1, 1), rtol=1e-6)
