"""How much exploration noise the CPG gait survives (issue 5): the open-loop CPG with a zero-mean residual.

A fresh PPO-CPG policy acts as a_t = a_c + eps * a_r with a_r drawn from N(mean ~ 0, std) anew at
every 60 Hz control step (SB3's Gaussian policy; ppo_cpg.py starts at std 0.10). This plays that
policy's noise alone (mean exactly 0) on the CPG, under the env's episode rules, and prints how each
episode ends: whether the stochastic policy of early training can arrive at all at a level, which
the curriculum needs (20 arrivals per level) and the deterministic protocol does not.

    python bench/exploration_noise.py --terrain slopes --levels 11,14,17 --eps 0.4 --std 0,0.05,0.1 --seeds 3
"""

from __future__ import annotations

import argparse

import numpy as np

from hexbench.env import EnvConfig, HexapodEnv


def play(terrain: str, level: float, eps: float, std: float, seed: int) -> tuple[str, float, int]:
    """(end reason, forward progress [m], control steps) of one episode; noise from its own seeded generator."""
    env = HexapodEnv(EnvConfig(terrain=terrain, level=level, action_mode="cpg_residual", residual_scale=eps))
    rng = np.random.default_rng(seed)
    try:
        env.reset(seed=seed)
        steps, info = 0, {}
        for steps in range(1, env.config.max_steps + 1):
            action = np.clip(std * rng.standard_normal(env.action_space.shape), -1.0, 1.0).astype(np.float32)
            _, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        return str(info.get("end_reason")), float(info.get("progress_m", 0.0)), steps
    finally:
        env.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--terrain", default="slopes", choices=["flat", "rough", "slopes", "stairs"])
    parser.add_argument("--levels", default="11,14,17", help="comma-separated levels (cm or deg)")
    parser.add_argument("--eps", type=float, default=0.4, help="residual scale (ppo_cpg.py: 0.6 / 0.4 / 0.3)")
    parser.add_argument("--std", default="0,0.05,0.1", help="comma-separated std of a_r (ppo_cpg.py starts at 0.10)")
    parser.add_argument("--seeds", type=int, default=3, help="episodes per cell, seeds 0..N-1")
    args = parser.parse_args(argv)

    from rich.console import Console
    from rich.table import Table

    levels = [float(v) for v in args.levels.split(",")]
    stds = [float(v) for v in args.std.split(",")]
    table = Table(title=f"CPG + zero-mean residual noise, {args.terrain}, eps {args.eps:g}: "
                        f"arrivals of {args.seeds} (mean progress [m]; how the others ended)")
    table.add_column("level")
    for std in stds:
        table.add_column(f"std {std:g} (joint noise {args.eps * std:.3f} rad)", justify="right")
    for level in levels:
        cells = []
        for std in stds:
            runs = [play(args.terrain, level, args.eps, std, seed) for seed in range(args.seeds)]
            arrived = sum(r[0] == "success" for r in runs)
            others = sorted({r[0] for r in runs if r[0] != "success"})
            cells.append(f"{arrived}/{len(runs)} ({np.mean([r[1] for r in runs]):.2f} m"
                         + (f"; {', '.join(others)}" if others else "") + ")")
        table.add_row(f"{level:g}", *cells)
    Console().print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
