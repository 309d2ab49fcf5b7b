"""Vision speed: robot-camera images rendered per second, and classifier milliseconds per image.

  .venv/bin/python bench/vision_speed.py [--images 60] [--threads 1] [--checkpoint PATH]

Rendering: the dataset's own path (load terrain instance + robot, repaint, TinyRenderer at 96x72),
and the render call alone on an already-loaded scene (what the HLTA layer pays per decision).
Classifier: torch CPU, batch 1 (per decision) and batch 64 (throughput), after a warm-up.
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", type=int, default=60, help="images to render for the timing")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    parser.add_argument("--checkpoint", default=None, help="classifier weights (default: shipped; random init if absent)")
    args = parser.parse_args()

    import torch

    from hexbench.perception.classifier import DEFAULT_CHECKPOINT, LeNetAttention, load_classifier, to_tensor
    from hexbench.perception.dataset.build import BuildConfig, plan_images
    from hexbench.perception.views import TERRAIN_CAMERA, render_view
    from hexbench.world.camera import robot_camera_image
    from hexbench.world.sim import Simulation

    torch.set_num_threads(args.threads)
    views = [p.view for p in plan_images(BuildConfig(per_class=max(2, args.images // 3), seed=123))][: args.images]
    sim = Simulation()
    start = time.perf_counter()
    images = np.stack([render_view(sim, v) for v in views])
    load_and_render_s = (time.perf_counter() - start) / len(views)
    start = time.perf_counter()
    for _ in range(len(views)):
        robot_camera_image(sim, TERRAIN_CAMERA)
    render_only_s = (time.perf_counter() - start) / len(views)
    sim.close()

    from pathlib import Path

    ckpt = Path(args.checkpoint) if args.checkpoint else DEFAULT_CHECKPOINT
    model = load_classifier(ckpt) if ckpt.is_file() else LeNetAttention().eval()
    x1 = to_tensor(images[:1])
    xb = to_tensor(np.concatenate([images] * (64 // len(images) + 1))[:64])
    with torch.no_grad():
        for _ in range(5):
            model(x1)
        reps = 200
        start = time.perf_counter()
        for _ in range(reps):
            model(x1)
        batch1_ms = (time.perf_counter() - start) / reps * 1e3
        start = time.perf_counter()
        for _ in range(10):
            model(xb)
        batch64_ms = (time.perf_counter() - start) / (10 * 64) * 1e3
    print(json.dumps({
        "images": len(views), "image_size_px": [TERRAIN_CAMERA.width_px, TERRAIN_CAMERA.height_px],
        "render_only_images_per_s": round(1.0 / render_only_s, 1),
        "load_scene_and_render_images_per_s": round(1.0 / load_and_render_s, 1),
        "classifier_ms_per_image_batch1": round(batch1_ms, 3),
        "classifier_ms_per_image_batch64": round(batch64_ms, 3),
        "torch_threads": args.threads, "weights": str(ckpt) if ckpt.is_file() else "random init",
        "machine": f"{platform.machine()} {platform.processor() or ''}".strip(), "torch": torch.__version__,
    }, indent=2))


if __name__ == "__main__":
    main()
