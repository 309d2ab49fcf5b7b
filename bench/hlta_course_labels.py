"""How well a terrain classifier labels the mixed course while the robot walks it (issue: HLTA).

Walks the open-loop CPG (a_r = 0) over the mixed course on the protocol's own episode seeds
(`hexbench run --terrain mixed` uses the same ones; the terrain-images dataset draws its walks
from other seeds, so these terrains are unseen by the classifier) and, every `--every` control
steps, renders the evaluator's camera image (same camera, `CAMERA_GROUND_RGB` painting and period
as `hexbench run`), classifies it, and compares the label with the segment the camera looks at:
the course segment under the point `--lookahead` m ahead of the base
(`hexbench.world.terrain.mixed_segment_at`: rough before the middle of the rough-slope gap,
slopes before the middle of the slope-stairs gap, stairs after), the label rule of the dataset's
mixed-course walk views.

    .venv/bin/python bench/hlta_course_labels.py [--checkpoint PT] [--levels 1,2,3] [--episodes 20] \\
        [--json out.json] [--figure confusion.png]

Prints accuracy, per-segment recall and the confusion counts (rows: truth, columns: label).
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", type=Path, default=REPO / "baselines" / "checkpoints" / "terrain_classifier_images_v2.pt",
                        help="classifier weights (default: the HLTA's)")
    parser.add_argument("--levels", default="1,2,3")
    parser.add_argument("--episodes", type=int, default=20, help="episodes per level (protocol seeds 0..N-1)")
    parser.add_argument("--every", type=int, default=30, help="control steps between images (the evaluator: 30)")
    parser.add_argument("--lookahead", type=float, default=0.4, help="[m] ahead of the base that the label refers to")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--figure", type=Path, default=None, help="confusion-matrix PNG")
    args = parser.parse_args()

    import torch

    from hexbench.artifacts.files import sha256_file
    from hexbench.perception.classifier import evaluate, load_classifier, plot_confusion, predict
    from hexbench.perception.dataset.walks import cpg_camera_shots
    from hexbench.perception.views import TERRAIN_CLASSES, paint_terrain
    from hexbench.suite.controller import CAMERA_GROUND_RGB
    from hexbench.suite.tasks import load_suite
    from hexbench.world.env import HexapodEnv
    from hexbench.world.terrain import mixed_segment_at

    torch.set_num_threads(1)
    model = load_classifier(args.checkpoint)
    suite = load_suite("v1")
    truths, labels = [], []
    start = time.perf_counter()
    for level in [float(v) for v in args.levels.split(",")]:
        task = suite.task("mixed", level)
        env = HexapodEnv(task.env_config("cpg_residual"))
        for seed in task.seeds(args.episodes):
            env.reset(seed=seed)
            paint_terrain(env.sim, CAMERA_GROUND_RGB)
            images = []
            for _, state, image in cpg_camera_shots(env, args.every):
                images.append(image)
                truths.append(TERRAIN_CLASSES.index(mixed_segment_at(float(state.base_pos_m[0]) + args.lookahead)))
            labels.extend(predict(model, np.stack(images)).tolist())
        env.close()
    report = evaluate(np.array(truths), np.array(labels))
    out = {
        "checkpoint": str(args.checkpoint), "checkpoint_sha256": sha256_file(args.checkpoint),
        "levels": args.levels, "episodes_per_level": args.episodes, "every_steps": args.every,
        "lookahead_m": args.lookahead, "images": report["num_images"], "accuracy": report["accuracy"],
        "recall_per_segment": {k: v["recall"] for k, v in report["per_class"].items()},
        "support_per_segment": {k: v["support"] for k, v in report["per_class"].items()},
        "confusion_truth_by_label": report["confusion"], "classes": report["classes"],
        "wall_time_s": round(time.perf_counter() - start, 1), "machine": platform.platform(),
    }
    text = json.dumps(out, indent=2)
    print(text)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(text + "\n")
    if args.figure:
        plot_confusion(report, args.figure, f"classifier along the mixed course\nlevels {args.levels}, "
                                            f"{args.episodes} protocol seeds each")


if __name__ == "__main__":
    main()
