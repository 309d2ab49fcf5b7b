"""How much exploration noise the CPG gait survives: the open-loop CPG with a zero-mean residual.

A fresh PPO-CPG policy acts as a_t = a_c + eps * a_r with a_r drawn from N(mean ~ 0, std) anew at
every 60 Hz control step (SB3's Gaussian policy; ppo_cpg.py starts at std 0.10). This plays that
policy's noise alone (mean exactly 0) on the CPG, under the env's episode rules, and prints how each
episode ends: whether the stochastic policy of early training can arrive at all at a level, which
the curriculum needs (20 arrivals per level) and the deterministic protocol does not.

    python experiments/exploration_noise.py --terrain slopes --levels 11,14,17 --eps 0.4 --std 0,0.05,0.1 --seeds 3

With `--gsde-period N` the noise is state-dependent and smooth in time instead, as SB3's gSDE draws
it: a_r = (f / |f|) W * std, f the last hidden layer of a fresh ppo_cpg.py actor (256 features of
the observation, so it follows the gait phase), W a matrix of standard normals redrawn every N
control steps; every joint's noise then has the given std. (A fresh actor's |f| is about 3.4, so
SB3's log_std_init = ln(std / 3.4): std 0.06 is about -4.0.)

    python experiments/exploration_noise.py --terrain slopes --levels 20 --eps 0.4 --std 0.04,0.06,0.1 --gsde-period 120
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from residual_episode import EpisodeEnd, play_residual

from hexbench.world.env import EnvConfig


def white_noise(std: float, rng: np.random.Generator):
    def draw(obs: np.ndarray, step: int) -> np.ndarray:
        return std * rng.standard_normal(18)
    return draw


def gsde_noise(std: float, period: int, rng: np.random.Generator):
    """SB3-style gSDE noise on a fresh ppo_cpg.py actor's features, scaled to `std` per joint."""
    import dataclasses

    import torch

    from hexbench.agents.policy import build_policy, scale_observation
    from hexbench.training.settings import load_baseline_config

    torch.manual_seed(int(rng.integers(2**31)))
    config = load_baseline_config(Path(__file__).resolve().parent.parent / "baselines" / "ppo_cpg.py")
    policy = build_policy(dataclasses.replace(config, use_sde=True))
    matrix = np.zeros((256, 18))

    def draw(obs: np.ndarray, step: int) -> np.ndarray:
        nonlocal matrix
        if step % period == 0:
            matrix = rng.standard_normal(matrix.shape)
        with torch.no_grad():
            x = torch.as_tensor(scale_observation(obs)[None], dtype=torch.float32)
            features = policy.mlp_extractor.forward_actor(policy.extract_features(x, policy.pi_features_extractor))
        f = features.numpy()[0]
        return std * (f / max(float(np.linalg.norm(f)), 1e-9)) @ matrix
    return draw


def play(terrain: str, level: float, eps: float, std: float, seed: int, gsde_period: int = 0) -> EpisodeEnd:
    """One episode of the CPG plus zero-mean noise; the noise draws from its own generator seeded by `seed`."""
    rng = np.random.default_rng(seed)
    noise = gsde_noise(std, gsde_period, rng) if gsde_period else white_noise(std, rng)
    return play_residual(EnvConfig(terrain=terrain, level=level, action_mode="cpg_residual", residual_scale=eps),
                         noise, seed)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--terrain", default="slopes", choices=["flat", "rough", "slopes", "stairs"])
    parser.add_argument("--levels", default="11,14,17", help="comma-separated levels (cm or deg)")
    parser.add_argument("--eps", type=float, default=0.4, help="residual scale (ppo_cpg.py: 0.6 / 0.4 / 0.3)")
    parser.add_argument("--std", default="0,0.05,0.1", help="comma-separated std of a_r (ppo_cpg.py starts at 0.10)")
    parser.add_argument("--seeds", type=int, default=3, help="episodes per cell, seeds 0..N-1")
    parser.add_argument("--gsde-period", type=int, default=0,
                        help="0: white noise; N: gSDE-like noise, matrix redrawn every N control steps")
    args = parser.parse_args(argv)

    from rich.console import Console
    from rich.table import Table

    levels = [float(v) for v in args.levels.split(",")]
    stds = [float(v) for v in args.std.split(",")]
    kind = f"gSDE-like noise (period {args.gsde_period})" if args.gsde_period else "white noise"
    table = Table(title=f"CPG + zero-mean residual {kind}, {args.terrain}, eps {args.eps:g}: "
                        f"arrivals of {args.seeds} (mean progress \\[m]; how the others ended)")
    table.add_column("level")
    for std in stds:
        table.add_column(f"std {std:g} (joint noise {args.eps * std:.3f} rad)", justify="right")
    for level in levels:
        cells = []
        for std in stds:
            runs = [play(args.terrain, level, args.eps, std, seed, args.gsde_period) for seed in range(args.seeds)]
            arrived = sum(r.end_reason == "success" for r in runs)
            others = sorted({r.end_reason for r in runs if r.end_reason != "success"})
            cells.append(f"{arrived}/{len(runs)} ({np.mean([r.progress_m for r in runs]):.2f} m"
                         + (f"; {', '.join(others)}" if others else "") + ")")
        table.add_row(f"{level:g}", *cells)
    Console().print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
