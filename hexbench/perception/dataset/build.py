"""`hexbench dataset build terrain-images`: render the ImageFolder tree and its manifest.

Layout of a build directory:

  train/{rough,slopes,stairs}/*.png   80% of the terrain instances (and, version 2, walks) of each kind
  test/{rough,slopes,stairs}/*.png    the other 20% (no terrain instance or walk appears in both)
  manifest.json                       config, camera, and per file: sha256, split, class, view kind, pose

Version 1 (`--version 1`) holds the approach views only: `<class>_<instance>_<view>.png`, the robot
standing on the flat ground before the obstacle. Version 2 holds the same approach views plus the
walk views of `walks.py` (`walk-<kind>_<walk>_<step>.png`, filed under their label), taken while
the open-loop CPG walks each terrain and the mixed course; its split is by walk (terrain seed).

Everything is a pure function of the seed: instance k of class c draws its level, colour, terrain
seed and poses from `np.random.default_rng([seed, c, k])`, and which instances are test instances
from `np.random.default_rng([seed, c, SPLIT_STREAM])`; the PNG encoder adds no timestamps, so the
same seed gives byte-identical files. The tree is written into a hidden temporary sibling of the
output directory and renamed into place only when complete.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from hexbench.artifacts.files import read_json_bounded, sha256_bytes, sha256_file
from hexbench.errors import HexbenchError, InputError
from hexbench.perception.dataset import DATASET_NAME
from hexbench.perception.dataset.walks import WALK_KINDS, WalkConfig, plan_walks, render_walks
from hexbench.perception.views import (
    LEVEL_RANGES,
    TERRAIN_CAMERA,
    TERRAIN_CLASSES,
    PoseRanges,
    View,
    render_view,
    sample_instance,
    sample_views,
)

# --version -> the manifest's version (2.0.0 kept every walk frame; hexbench/perception/dataset/walks.py)
DATASET_VERSIONS: dict[int, str] = {1: "1.0.0", 2: "2.1.0"}
MANIFEST_NAME = "manifest.json"
MAX_MANIFEST_BYTES = 64 << 20  # a manifest lists every image (a few hundred bytes each); larger is refused unread
SPLITS: tuple[str, ...] = ("train", "test")
SPLIT_STREAM = 1_000_003  # rng stream id for the train/test assignment


@dataclass(frozen=True)
class BuildConfig:
    per_class: int = 200  # images per terrain class, as in the paper (600 in all)
    seed: int = 0
    views_per_instance: int = 5  # camera poses per terrain instance (fewer for tiny builds)
    test_fraction: float = 0.2
    poses: PoseRanges = PoseRanges()
    version: int = 1  # 1: approach views only; 2: approach views + walk views
    walks: WalkConfig = WalkConfig()  # version 2 only

    def __post_init__(self) -> None:
        if self.version not in DATASET_VERSIONS:
            raise ValueError(f"unknown terrain-images version {self.version}; valid versions: "
                             f"{', '.join(str(v) for v in DATASET_VERSIONS)}")
        if self.per_class < 2:
            raise ValueError(f"--per-class must be at least 2 (one train and one test instance), got {self.per_class}")
        if self.seed < 0:
            raise ValueError(f"--seed must be >= 0, got {self.seed}")
        if not 0.0 < self.test_fraction < 1.0:
            raise ValueError(f"test fraction must be in (0, 1), got {self.test_fraction}")

    @property
    def dataset_version(self) -> str:
        return DATASET_VERSIONS[self.version]

    @property
    def planned_walks(self) -> list:
        return plan_walks(self.seed, self.walks) if self.version >= 2 else []

    def manifest_config(self) -> dict:
        config = asdict(self)
        if self.version < 2:
            del config["walks"]  # version 1 manifests stay byte-identical to earlier builds
            del config["version"]
        return config

    @property
    def effective_views_per_instance(self) -> int:
        """Views per instance, reduced for small builds so that there are at least 5 instances per class."""
        return max(1, min(self.views_per_instance, self.per_class // 5))

    @property
    def instances_per_class(self) -> int:
        v = self.effective_views_per_instance
        return -(-self.per_class // v)

    @property
    def test_instances_per_class(self) -> int:
        n = self.instances_per_class
        return min(n - 1, max(1, round(self.test_fraction * n)))


@dataclass(frozen=True)
class PlannedImage:
    relpath: str  # posix path inside the build directory
    split: str
    terrain: str
    instance_index: int
    view_index: int
    view: View


def plan_images(config: BuildConfig) -> list[PlannedImage]:
    """Every image of the build, in a fixed order, without rendering anything."""
    planned: list[PlannedImage] = []
    n_inst, per_view = config.instances_per_class, config.effective_views_per_instance
    for c, terrain in enumerate(TERRAIN_CLASSES):
        split_rng = np.random.default_rng([config.seed, c, SPLIT_STREAM])
        test_ids = set(split_rng.permutation(n_inst)[: config.test_instances_per_class].tolist())
        remaining = config.per_class
        for k in range(n_inst):
            rng = np.random.default_rng([config.seed, c, k])
            instance = sample_instance(terrain, rng)
            views = sample_views(instance, min(per_view, remaining), rng, config.poses)
            remaining -= len(views)
            split = "test" if k in test_ids else "train"
            for v, view in enumerate(views):
                rel = f"{split}/{terrain}/{terrain}_{k:04d}_{v:02d}.png"
                planned.append(PlannedImage(rel, split, terrain, k, v, view))
    return planned


def png_bytes(image: np.ndarray) -> bytes:
    """Deterministic PNG encoding (no timestamps or text chunks)."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(image).save(buf, format="PNG", optimize=False, compress_level=9)
    return buf.getvalue()


def build_terrain_images(out_dir: Path, config: BuildConfig = BuildConfig(), *, force: bool = False,
                         on_image: Callable[[int, int], None] | None = None) -> dict:
    """Render the dataset into `out_dir` (created atomically) and return its manifest.

    `on_image(done, total)` is called after every image (for progress bars)."""
    from hexbench.artifacts.provenance import HEXBENCH_VERSION as __version__
    from hexbench.world.sim import Simulation

    out_dir = Path(out_dir)
    if out_dir.exists() and any(out_dir.iterdir()) and not force:
        raise FileExistsError(f"output directory {out_dir} exists and is not empty; pass --force to replace it")
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    planned = plan_images(config)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.tmp-", dir=out_dir.parent))
    walks = config.planned_walks
    total = len(planned) + len(walks)  # progress units: one per approach image, one per walk
    sim = Simulation()
    try:
        files = []

        def write(relpath: str, image: np.ndarray, row: dict) -> None:
            data = png_bytes(image)
            path = tmp / relpath
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
            files.append({"path": relpath, "sha256": sha256_bytes(data), "bytes": len(data), **row})

        for i, item in enumerate(planned):
            row = {"split": item.split, "label": item.terrain, "instance": item.instance_index,
                   "view_index": item.view_index, **item.view.record()}
            if config.version >= 2:
                row["view_kind"] = "approach"
            write(item.relpath, render_view(sim, item.view), row)
            if on_image is not None:
                on_image(i + 1, total)
        for shot in render_walks(walks, config.walks, on_walk=None if on_image is None else
                                 (lambda done, _n: on_image(len(planned) + done, total))):
            rel = f"{shot.walk.split}/{shot.label}/{shot.walk.name}_{shot.step:05d}.png"
            write(rel, shot.image, {"split": shot.walk.split, "label": shot.label,
                                    **shot.record(config.walks.lookahead_m)})
        manifest = {
            "name": DATASET_NAME,
            "version": config.dataset_version,
            "hexbench_version": __version__,
            "classes": list(TERRAIN_CLASSES),
            "level_ranges": {k: list(v) for k, v in LEVEL_RANGES.items()},
            "config": config.manifest_config(),
            "camera": asdict(TERRAIN_CAMERA),
            "counts": {s: {t: sum(1 for f in files if f["split"] == s and f["label"] == t) for t in TERRAIN_CLASSES}
                       for s in SPLITS},
            "files": files,
        }
        if config.version >= 2:
            manifest["counts_by_view_kind"] = view_kind_counts(files)
        (tmp / MANIFEST_NAME).write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")
        if out_dir.exists():
            trash = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.old-", dir=out_dir.parent))
            os.replace(out_dir, trash / out_dir.name)
            os.replace(tmp, out_dir)
            shutil.rmtree(trash)
        else:
            os.replace(tmp, out_dir)
        return manifest
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        sim.close()


def view_kind_counts(files: list[dict]) -> dict:
    """{split: {view kind (approach, walk-rough, ..., walk-mixed): {label: images}}} of manifest rows."""
    out = {split: {kind: dict.fromkeys(TERRAIN_CLASSES, 0)
                   for kind in ("approach", *(f"walk-{k}" for k in WALK_KINDS))} for split in SPLITS}
    for f in files:
        kind = f"walk-{f['walk_kind']}" if f.get("view_kind") == "walk" else "approach"
        out[f["split"]][kind][f["label"]] += 1
    return out


class DatasetError(HexbenchError):
    """A dataset folder is not a terrain-images build, or its manifest is unreadable or malformed (one line)."""


def load_manifest(build_dir: Path) -> dict:
    """The manifest of a dataset folder; DatasetError unless it is a bounded JSON object whose
    "files" are entries with a relative "path" inside the folder and a "sha256"."""
    path = Path(build_dir) / MANIFEST_NAME
    if not path.is_file():
        raise DatasetError(f"{build_dir} is not a terrain-images build: no {MANIFEST_NAME} (run `hexbench dataset build terrain-images`)")
    try:
        manifest = read_json_bounded(path, MAX_MANIFEST_BYTES, "dataset manifest")
    except InputError as e:
        raise DatasetError(str(e)) from None
    files = manifest.get("files") if isinstance(manifest, dict) else None
    if not isinstance(files, list) or not all(isinstance(f, dict) and isinstance(f.get("path"), str)
                                              and isinstance(f.get("sha256"), str) for f in files):
        raise DatasetError(f"{path}: not a terrain-images manifest (a 'files' list of entries with 'path' and "
                           f"'sha256' is expected)")
    for f in files:
        parts = Path(f["path"]).parts
        if not parts or Path(f["path"]).is_absolute() or ".." in parts or "\0" in f["path"]:
            raise DatasetError(f"{path}: file entry {f['path'][:100]!r} is not a path inside the dataset folder")
    return manifest


def verify_build(build_dir: Path) -> list[str]:
    """Problems found checking every file against the manifest (empty list: the build is intact)."""
    build_dir = Path(build_dir)
    manifest = load_manifest(build_dir)
    problems = []
    listed = {f["path"] for f in manifest["files"]}
    for f in manifest["files"]:
        path = build_dir / f["path"]
        if not path.is_file():
            problems.append(f"missing {f['path']}")
        elif sha256_file(path) != f["sha256"]:
            problems.append(f"sha256 mismatch {f['path']}")
    for path in sorted(build_dir.rglob("*.png")):
        rel = path.relative_to(build_dir).as_posix()
        if rel not in listed:
            problems.append(f"not in manifest {rel}")
    return problems
