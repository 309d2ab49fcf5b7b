"""Where and how the open-loop CPG stalls: a trace of one episode (slopes headroom levels).

Plays the CPG (cpg_residual mode, a_r = 0) on one terrain level under the env's rules and prints,
every `--every` control steps and at the end: base x [m] and z [m], pitch [deg], and which legs'
tibias touch anything (`Sim.foot_contacts`), named as in `hexbench.world.robot.LEG_NAMES`.

    python experiments/stall_trace.py --terrain slopes --level 20 --seed 3
"""

from __future__ import annotations

import argparse
import math

from residual_episode import play_residual, zero_residual

from hexbench.world.env import EnvConfig
from hexbench.world.robot import LEG_NAMES


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--terrain", default="slopes", help="rough, slopes or stairs")
    ap.add_argument("--level", type=float, default=20.0, help="level in the paper's units (cm, deg)")
    ap.add_argument("--seed", type=int, default=3, help="episode seed")
    ap.add_argument("--every", type=int, default=300, help="control steps between trace lines")
    args = ap.parse_args()

    def trace(env, step: int, done: bool) -> None:
        if step % args.every == 0 or done:
            state = env.robot_state
            x, _, z = state.base_pos_m
            pitch_deg = math.degrees(float(state.base_rpy_rad[1]))
            legs = " ".join(leg for leg, touching in zip(LEG_NAMES, env.sim.foot_contacts()) if touching)
            print(f"{step:5d}  {x:6.3f}  {z:5.3f}  {pitch_deg:6.1f}  {legs}")

    print(f"{args.terrain} {args.level:g}, seed {args.seed}: step, x [m], z [m], pitch [deg], legs in contact")
    config = EnvConfig(terrain=args.terrain, level=args.level, action_mode="cpg_residual")
    end = play_residual(config, zero_residual, args.seed, on_step=trace)
    print(f"end: {end.end_reason} after {end.steps} steps, progress {end.progress_m:.2f} m")


if __name__ == "__main__":
    main()
