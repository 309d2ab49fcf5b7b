"""Where a terrain classifier errs on a terrain-images split: per walk (or view kind), with the base
position of every wrong image.

    .venv/bin/python bench/classifier_errors.py --data build/terrain-images-v2 \\
        --checkpoint build/terrain_classifier_v2.pt [--split test] [--label stairs]

One line per walk: its kind, terrain seed and level, images, errors and (base x [m], predicted label)
of each error, so that errors clustered on one stretch of one walk (a stall in front of a riser, the
landing after the last step) read apart from errors spread over many walks.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True, help="terrain-images folder (with manifest.json)")
    parser.add_argument("--checkpoint", type=Path, required=True)
    parser.add_argument("--split", default="test")
    parser.add_argument("--label", default=None, help="only images of this label (default: all)")
    args = parser.parse_args()

    import torch
    from PIL import Image

    from hexbench.perception.classifier import load_classifier, predict
    from hexbench.perception.views import TERRAIN_CLASSES

    torch.set_num_threads(1)
    rows = [r for r in json.loads((args.data / "manifest.json").read_text())["files"]
            if r["split"] == args.split and (args.label is None or r["label"] == args.label)]
    if not rows:
        raise SystemExit(f"no {args.split} images{' labelled ' + args.label if args.label else ''} in {args.data}")
    images = np.stack([np.asarray(Image.open(args.data / r["path"]).convert("RGB")) for r in rows])
    predicted = predict(load_classifier(args.checkpoint), images)
    walks: dict[tuple, list] = defaultdict(list)
    for row, label in zip(rows, predicted):
        key = (row.get("walk_kind") or row["view_kind"], row["label"], row.get("terrain_seed"), round(float(row.get("level", 0)), 1))
        walks[key].append((row.get("base_x_m"), TERRAIN_CLASSES[int(label)], row["label"]))
    total_errors = 0
    for (kind, label, seed, level), shots in sorted(walks.items(), key=lambda kv: -len(kv[1])):
        errors = [(x, p) for x, p, truth in shots if p != truth]
        total_errors += len(errors)
        where = ", ".join(f"{x:.2f} m {p}" if x is not None else p for x, p in errors)
        print(f"{kind:<9} {label:<7} seed {seed} level {level:g}: {len(shots)} images, {len(errors)} wrong"
              + (f": {where}" if errors else ""))
    print(f"{len(rows)} images, {total_errors} wrong ({1 - total_errors / len(rows):.1%} right)")


if __name__ == "__main__":
    main()
