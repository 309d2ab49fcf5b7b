"""Variants of the HLTA's low level on the mixed course, on tuning seeds (never the protocol's).

Each variant is baselines/hlta.py's Config with some fields changed: which controller each label
dispatches (`low_level`: that terrain's PPO-CPG policy or the open-loop CPG), the heading hold
(hexbench.agents.heading) and where it applies (`steer_on`), the vote window. Episodes run in this
process (the controller is our own), on episode seeds 900000 + 17 i, which no protocol task uses, so
choosing a variant here does not tune it to the seeds its record is scored on
(`hexbench run baselines/hlta.py --terrain mixed`).

    .venv/bin/python bench/hlta_variants.py                          # every variant, levels 1-3, 10 episodes each
    .venv/bin/python bench/hlta_variants.py --variants shipped,policies --levels 3 --episodes 20

Prints one line per episode and a success count per variant and level; --json writes them all.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
TUNING_SEED_BASE, TUNING_SEED_STRIDE = 900_000, 17

POLICIES = (("rough", "policy"), ("slopes", "policy"), ("stairs", "policy"))
VARIANTS: dict[str, dict] = {
    "shipped": {},  # baselines/hlta.py as it is
    "policies": {"low_level": POLICIES, "heading_hold": None},  # the paper's dispatch: a policy per label, no hold
    "policies+hold": {"low_level": POLICIES, "steer_on": ("rough", "slopes")},
    "policies+hold-everywhere": {"low_level": POLICIES, "steer_on": ("rough", "slopes", "stairs"), "max_turn": 0.15},
    "policies+hold+vote5": {"low_level": POLICIES, "steer_on": ("rough", "slopes"), "vote_window": 5},
    "cpg-rough": {"low_level": (("rough", "cpg"), ("slopes", "policy"), ("stairs", "policy"))},
    # baselines/cpg_heading.py: no classifier decision matters
    "cpg+hold-only": {"low_level": (("rough", "cpg"), ("slopes", "cpg"), ("stairs", "cpg")),
                      "steer_on": ("rough", "slopes", "stairs")},
}


class CameraActor:
    """The HLTA object behind the episode loop's actor interface (act/see with the step)."""

    def __init__(self, ctrl):
        self.ctrl, self.action_mode = ctrl, ctrl.action_mode
        self.camera, self.camera_every_steps = ctrl.camera, ctrl.camera_every_steps

    def reset(self, seed: int) -> None:
        self.ctrl.reset(seed)

    def see(self, image, step: int) -> None:
        self.ctrl.see(image)

    def act(self, obs, step: int):
        return self.ctrl.act(obs.copy())


def config_for(hlta, name: str):
    changes = dict(VARIANTS[name])
    max_turn = changes.pop("max_turn", None)
    config = replace(hlta.CONFIG, **changes)
    if max_turn is not None and config.heading_hold is not None:
        config = replace(config, heading_hold=replace(config.heading_hold, max_turn=max_turn))
    return config


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", default=",".join(VARIANTS), help=f"comma-separated, of: {', '.join(VARIANTS)}")
    parser.add_argument("--levels", default="1,2,3")
    parser.add_argument("--episodes", type=int, default=10, help="episodes per level and variant")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    names = [v for v in args.variants.split(",") if v]
    unknown = [v for v in names if v not in VARIANTS]
    if unknown:
        raise SystemExit(f"unknown variant(s) {', '.join(unknown)}; valid: {', '.join(VARIANTS)}")

    import torch

    from hexbench.suite.controller import load_controller_module
    from hexbench.suite.numerics import use_controller_math
    from hexbench.suite.rollout import play
    from hexbench.suite.tasks import load_suite

    use_controller_math()
    torch.set_num_threads(1)
    hlta = load_controller_module(REPO / "baselines" / "hlta.py")
    suite = load_suite("v1")
    results = []
    for name in names:
        config = config_for(hlta, name)
        for level in [float(v) for v in args.levels.split(",")]:
            task = suite.task("mixed", level)
            actor = CameraActor(hlta.make_controller(task, config))
            t0, ends = time.perf_counter(), []
            for i in range(args.episodes):
                seed = TUNING_SEED_BASE + TUNING_SEED_STRIDE * i
                row = play(task, seed, actor, index=i, controller_seed=seed).row
                ends.append(row["end_reason"])
                results.append({"variant": name, "level": level, "seed": seed, **{k: row[k] for k in (
                    "end_reason", "progress_m", "max_abs_y_m", "steps")}, "switches": actor.ctrl.switches})
                print(f"{name} level {level:g} #{i}: {row['end_reason']}, {row['progress_m']:.2f} m, "
                      f"max |y| {row['max_abs_y_m']:.2f} m, {actor.ctrl.switches} switches", flush=True)
            counts = {k: ends.count(k) for k in sorted(set(ends))}
            print(f"== {name} level {level:g}: {ends.count('success')} of {len(ends)} ({counts}), "
                  f"{time.perf_counter() - t0:.0f} s", flush=True)
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"variants": {n: repr(config_for(hlta, n)) for n in names}, "episodes": results},
                                        indent=1))


if __name__ == "__main__":
    main()
