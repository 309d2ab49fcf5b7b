"""How well the terrain classifier labels the mixed course while the robot walks it.

The terrain-image dataset photographs each obstacle from the flat approach in front of it; on the
mixed course the HLTA layer sees terrain from everywhere along the way (on rough ground, on a
ramp, from the slope's top). This walks the open-loop CPG (a_r = 0) over the course and, every
`--every` control steps, renders the evaluator's camera image (same camera, painting and period
as `hexbench run`), classifies it, and compares the label with the segment the camera looks at:
the course segment under the point `--lookahead` m ahead of the base (rough before the middle of
the rough-slope gap, slopes before the middle of the slope-stairs gap, stairs after).

    .venv/bin/python experiments/hlta_course_labels.py [--levels 1,2,3] [--episodes 3] [--json out.json]

Prints per-segment accuracy and the confusion counts (rows: truth, columns: label).
"""

from __future__ import annotations

import argparse
import json
import platform
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent


def truth_at(x_m: float) -> str:
    from hexbench.world.terrain import MIXED_ROUGH_END_X_M, MIXED_SLOPE_START_X_M, MIXED_STAIRS_START_X_M, SlopesTerrain

    slope_end = SlopesTerrain(10.0, start_x_m=MIXED_SLOPE_START_X_M).breakpoints_m[3]
    if x_m < (MIXED_ROUGH_END_X_M + MIXED_SLOPE_START_X_M) / 2:
        return "rough"
    if x_m < (slope_end + MIXED_STAIRS_START_X_M) / 2:
        return "slopes"
    return "stairs"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", default="1,2,3")
    parser.add_argument("--episodes", type=int, default=3, help="episodes per level (protocol seeds 0..N-1)")
    parser.add_argument("--every", type=int, default=30, help="control steps between images")
    parser.add_argument("--lookahead", type=float, default=0.4, help="[m] ahead of the base that the label refers to")
    parser.add_argument("--json", default=None)
    args = parser.parse_args()

    import torch

    from hexbench.perception.classifier import load_classifier, predict
    from hexbench.perception.views import TERRAIN_CAMERA, TERRAIN_CLASSES, paint_terrain
    from hexbench.suite.controller import CAMERA_GROUND_RGB
    from hexbench.suite.tasks import load_suite
    from hexbench.world.camera import robot_camera_image
    from hexbench.world.env import HexapodEnv

    torch.set_num_threads(1)
    model = load_classifier(REPO / "baselines" / "checkpoints" / "terrain_classifier.pt")
    suite = load_suite("v1")
    confusion = {t: {c: 0 for c in TERRAIN_CLASSES} for t in TERRAIN_CLASSES}
    for level in [float(v) for v in args.levels.split(",")]:
        task = suite.task("mixed", level)
        env = HexapodEnv(task.env_config("cpg_residual"))
        for seed in task.seeds(args.episodes):
            env.reset(seed=seed)
            paint_terrain(env.sim, CAMERA_GROUND_RGB)
            step, done = 0, False
            while not done:
                if step % args.every == 0:
                    x = float(env.robot_state.base_pos_m[0])
                    image = robot_camera_image(env.sim, TERRAIN_CAMERA)
                    label = TERRAIN_CLASSES[int(predict(model, image[None])[0])]
                    confusion[truth_at(x + args.lookahead)][label] += 1
                _, _, terminated, truncated, _ = env.step(np.zeros(18, np.float32))
                done = terminated or truncated
                step += 1
        env.close()
    per_segment = {t: {"images": sum(row.values()), "accuracy": row[t] / max(1, sum(row.values()))}
                   for t, row in confusion.items()}
    total = sum(v["images"] for v in per_segment.values())
    out = {
        "levels": args.levels, "episodes_per_level": args.episodes, "every_steps": args.every,
        "lookahead_m": args.lookahead, "images": total,
        "accuracy": sum(confusion[t][t] for t in TERRAIN_CLASSES) / max(1, total),
        "per_segment": per_segment, "confusion_truth_by_label": confusion, "machine": platform.platform(),
    }
    text = json.dumps(out, indent=2)
    print(text)
    if args.json:
        Path(args.json).write_text(text + "\n")


if __name__ == "__main__":
    main()
