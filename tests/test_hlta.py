"""HLTA controller (baselines/hlta.py): vote, dispatch and eps rescaling, with stub low-level policies."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

HLTA_PATH = Path(__file__).resolve().parents[1] / "baselines" / "hlta.py"


def _hlta():
    from hexbench.suite.controller import load_controller_module

    return load_controller_module(HLTA_PATH)


class ConstantPolicy:
    action_mode = "cpg_residual"

    def __init__(self, value: float):
        self.value = value
        self.seeds = []

    def reset(self, seed: int) -> None:
        self.seeds.append(seed)

    def act(self, obs):
        return np.full(18, self.value, np.float32)


def _controller(labels):
    hlta = _hlta()
    feed = iter(labels)
    policies = {"rough": ConstantPolicy(1.0), "slopes": ConstantPolicy(0.5), "stairs": ConstantPolicy(-1.0)}
    return hlta.HLTAController(policies, lambda image: next(feed), env_eps=0.6)


def test_refuses_to_act_before_seeing():
    ctrl = _controller([])
    ctrl.reset(0)
    with pytest.raises(RuntimeError, match="call see"):
        ctrl.act(np.zeros(62, np.float32))


def test_majority_vote_and_eps_rescaling():
    ctrl = _controller(["rough", "stairs", "rough", "stairs", "stairs", "slopes"])
    ctrl.reset(3)
    obs = np.zeros(62, np.float32)
    assert ctrl.see(None) == "rough"
    np.testing.assert_allclose(ctrl.act(obs), 1.0)  # eps 0.6 / env 0.6
    assert ctrl.see(None) == "rough"  # 1-1 tie keeps the current terrain
    assert ctrl.see(None) == "rough"
    assert ctrl.see(None) == "stairs"  # window (stairs, rough, stairs)
    np.testing.assert_allclose(ctrl.act(obs), -1.0 * 0.3 / 0.6)
    assert ctrl.see(None) == "stairs"
    assert ctrl.see(None) == "stairs"  # one odd "slopes" frame does not switch
    assert ctrl.switches == 1
    assert all(p.seeds == [3] for p in ctrl.policies.values())


def test_needs_a_policy_per_terrain():
    hlta = _hlta()
    with pytest.raises(ValueError, match="missing: stairs"):
        hlta.HLTAController({"rough": ConstantPolicy(0), "slopes": ConstantPolicy(0)}, lambda i: "rough", 0.6)


@pytest.mark.parametrize("weights", ["terrain_classifier.pt", "terrain_classifier_images_v2.pt"])
def test_shipped_classifiers_see_each_terrain_from_the_robot_camera(weights):
    from hexbench.perception.views import TerrainInstance, View, render_view
    from hexbench.world.sim import Simulation

    classify = _hlta().make_classify(HLTA_PATH.parent / "checkpoints" / weights)
    sim = Simulation()
    try:
        for terrain, level in (("stairs", 6.0), ("slopes", 15.0), ("rough", 10.0)):
            view = View(TerrainInstance(terrain, level, 12345, (0.7, 0.6, 0.45)), -0.2, 0.0, 0.0)
            assert classify(render_view(sim, view)) == terrain
    finally:
        sim.close()


def test_the_hlta_classifier_is_the_one_trained_on_walk_views_and_labels_the_course():
    """The HLTA's classifier was trained on terrain-images 2 (walk views) and its sidecar holds what
    bench/hlta_course_labels.py measured for it; version 1's stays shipped for the dataset's own test."""
    import json

    from hexbench.perception.classifier import sidecar_path

    meta = json.loads(sidecar_path(HLTA_PATH.parent / _hlta().CONFIG.classifier_checkpoint).read_text())
    assert meta["dataset"]["train_images"] > 3000  # version 1 has 480 training images
    assert meta["evaluations"]["test_split"]["accuracy"] >= 0.975  # terrain-images 2.1.0's test split
    assert meta["evaluations"]["mixed_course"]["accuracy"] >= 0.95


def test_shipped_config_walks_rough_and_slopes_with_the_held_cpg_and_climbs_stairs_with_the_policy():
    """Config.low_level: rough and slopes labels send a_r = the heading hold alone (the open-loop CPG
    steered); a stairs label sends the stairs policy's residual without the hold."""
    from dataclasses import replace

    from hexbench.agents.heading import BASE_Y_INDEX, HeadingSteering
    from hexbench.suite.tasks import load_suite

    hlta = _hlta()
    task = load_suite("v1").task("mixed", 1)
    config = hlta.CONFIG
    assert dict(config.low_level) == {"rough": "cpg", "slopes": "cpg", "stairs": "policy"}
    feed = iter(["rough", "stairs", "stairs", "stairs"])
    policies = {t: hlta.ZeroResidual() if kind == "cpg" else ConstantPolicy(0.5) for t, kind in config.low_level}
    ctrl = hlta.HLTAController(policies, lambda image: next(feed), 0.6, config,
                               HeadingSteering.for_task(config.heading_hold, task))
    twin = HeadingSteering.for_task(config.heading_hold, task)
    ctrl.reset(0)
    obs = np.zeros(62, np.float32)
    obs[BASE_Y_INDEX] = -0.3  # right of the centre line: the hold turns left
    ctrl.see(None)
    for _ in range(20):
        np.testing.assert_allclose(ctrl.act(obs), twin.residual(obs).astype(np.float32))
    assert np.abs(ctrl.act(obs)).max() > 0  # the hold steers
    for _ in range(3):
        ctrl.see(None)
    assert ctrl.terrain == "stairs"
    np.testing.assert_allclose(ctrl.act(obs), 0.5 * 0.3 / 0.6)  # the policy alone, rescaled to its eps
    with pytest.raises(ValueError, match="Config.low_level"):
        hlta.make_controller(task, replace(config, low_level=(("rough", "cpg"), ("slopes", "learned"), ("stairs", "policy"))))
