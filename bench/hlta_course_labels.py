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

Prints accuracy, per-segment recall, the confusion counts (rows: truth, columns: label) and where the
wrong frames lie (level, base x); --json also keeps every wrong frame.
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
    from hexbench.world.terrain import make_terrain, mixed_segment_at

    torch.set_num_threads(1)
    model = load_classifier(args.checkpoint)
    suite = load_suite("v1")
    truths, labels, errors = [], [], []
    on_obstacles = []  # per frame: is the look-ahead point still before the course's last obstacle end?
    start = time.perf_counter()
    for level in [float(v) for v in args.levels.split(",")]:
        task = suite.task("mixed", level)
        obstacle_end_x_m = make_terrain("mixed", level).obstacle_end_x_m
        env = HexapodEnv(task.env_config("cpg_residual"))
        for seed in task.seeds(args.episodes):
            env.reset(seed=seed)
            paint_terrain(env.sim, CAMERA_GROUND_RGB)
            images, steps, xs = [], [], []  # per frame: image, control step, base x [m]
            for step, state, image in cpg_camera_shots(env, args.every):
                images.append(image)
                steps.append(step)
                xs.append(float(state.base_pos_m[0]))
            truth = [TERRAIN_CLASSES.index(mixed_segment_at(x + args.lookahead)) for x in xs]
            predicted = predict(model, np.stack(images)).tolist()
            truths.extend(truth)
            labels.extend(predicted)
            on_obstacles.extend(x + args.lookahead <= obstacle_end_x_m for x in xs)
            errors.extend({"level": level, "seed": int(seed), "step": st, "base_x_m": round(x, 3),
                           "truth": TERRAIN_CLASSES[t], "label": TERRAIN_CLASSES[p]}
                          for st, x, t, p in zip(steps, xs, truth, predicted) if t != p)
        env.close()
    report = evaluate(np.array(truths), np.array(labels))
    kept = np.array(on_obstacles)
    before_end = evaluate(np.array(truths)[kept], np.array(labels)[kept])
    out = {
        "checkpoint": str(args.checkpoint), "checkpoint_sha256": sha256_file(args.checkpoint),
        "levels": args.levels, "episodes_per_level": args.episodes, "every_steps": args.every,
        "lookahead_m": args.lookahead, "images": report["num_images"], "accuracy": report["accuracy"],
        "recall_per_segment": {k: v["recall"] for k, v in report["per_class"].items()},
        "support_per_segment": {k: v["support"] for k, v in report["per_class"].items()},
        "confusion_truth_by_label": report["confusion"], "classes": report["classes"],
        "wall_time_s": round(time.perf_counter() - start, 1), "machine": platform.platform(),
        # the frames terrain-images 2.1.0 would keep: look-ahead not yet past the last obstacle's end
        "before_last_obstacle_end": {"images": before_end["num_images"], "accuracy": before_end["accuracy"]},
        "errors": errors,  # every wrong frame: level, episode seed, control step, base x [m], truth, label
    }
    text = json.dumps(out, indent=2)
    print(json.dumps({k: v for k, v in out.items() if k != "errors"}, indent=2))
    print(f"{len(errors)} wrong frames, by level and base x [m]:")
    for level in sorted({e["level"] for e in errors}):
        xs = sorted(e["base_x_m"] for e in errors if e["level"] == level)
        print(f"  level {level:g}: {len(xs)}: " + ", ".join(f"{x:.2f}" for x in xs))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(text + "\n")
    if args.figure:
        plot_confusion(report, args.figure, f"classifier along the mixed course\nlevels {args.levels}, "
                                            f"{args.episodes} protocol seeds each")


if __name__ == "__main__":
    main()
