"""Terrain classifier (paper 3.1, Fig. 2): LeNet with a self-attention block, in torch.

Input: a robot-camera image (72 x 96 RGB, `hexbench.perception.views.TERRAIN_CAMERA`), output: one of
rough, slopes, stairs. Architecture: per-image standardisation, then LeNet-5's two conv(5x5)+ReLU+maxpool stages (6 and 16 channels),
a self-attention block over the 15 x 21 grid of 16-d feature vectors (multi-head attention with a
learned residual gate, SAGAN style), then LeNet's 120-84-3 fully connected head.

Checkpoints are a plain dict of tensors and primitives (loadable with `torch.load(weights_only=True)`),
with a sidecar `<name>.json` holding their sha256 and provenance; `load_classifier` checks that sha256
before unpickling anything.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from torch import nn

from hexbench.artifacts.files import sha256_bytes, sha256_file, write_bytes_atomic
from hexbench.artifacts.provenance import REPO_ROOT
from hexbench.errors import HexbenchError
from hexbench.perception.views import TERRAIN_CLASSES

IMAGE_HEIGHT_PX, IMAGE_WIDTH_PX = 72, 96


class SelfAttention2d(nn.Module):
    """Self-attention over the spatial positions of a feature map, added back through a learned gate."""

    def __init__(self, channels: int, heads: int = 2):
        super().__init__()
        self.norm = nn.LayerNorm(channels)
        self.attention = nn.MultiheadAttention(channels, heads, batch_first=True)
        self.gate = nn.Parameter(torch.zeros(1))  # starts as identity, as in SAGAN

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, c, h, w = x.shape
        tokens = self.norm(x.flatten(2).transpose(1, 2))  # (b, h*w, c)
        attended, _ = self.attention(tokens, tokens, tokens, need_weights=False)
        return x + self.gate * attended.transpose(1, 2).reshape(b, c, h, w)


class StandardiseImage(nn.Module):
    """Zero mean, unit variance per image: ground colour and brightness are random, shading contrast is the signal."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        mean = x.mean(dim=(1, 2, 3), keepdim=True)
        std = x.std(dim=(1, 2, 3), keepdim=True)
        return (x - mean) / (std + 1e-3)


class LeNetAttention(nn.Module):
    def __init__(self, num_classes: int = len(TERRAIN_CLASSES), height_px: int = IMAGE_HEIGHT_PX,
                 width_px: int = IMAGE_WIDTH_PX):
        super().__init__()
        self.features = nn.Sequential(
            StandardiseImage(),
            nn.Conv2d(3, 6, 5), nn.ReLU(), nn.MaxPool2d(2),
            nn.Conv2d(6, 16, 5), nn.ReLU(), nn.MaxPool2d(2),
        )
        self.attention = SelfAttention2d(16)
        fh, fw = ((height_px - 4) // 2 - 4) // 2, ((width_px - 4) // 2 - 4) // 2
        self.head = nn.Sequential(
            nn.Flatten(), nn.Linear(16 * fh * fw, 120), nn.ReLU(), nn.Dropout(0.3),
            nn.Linear(120, 84), nn.ReLU(), nn.Linear(84, num_classes),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.attention(self.features(x)))


def to_tensor(images: np.ndarray) -> torch.Tensor:
    """(N, H, W, 3) or (H, W, 3) uint8 -> (N, 3, H, W) float in [-1, 1]."""
    if images.ndim == 3:
        images = images[None]
    if images.shape[1:] != (IMAGE_HEIGHT_PX, IMAGE_WIDTH_PX, 3):
        raise ValueError(f"images must be {IMAGE_HEIGHT_PX}x{IMAGE_WIDTH_PX} RGB, got shape {images.shape[1:]}")
    return torch.from_numpy(np.ascontiguousarray(images)).permute(0, 3, 1, 2).float().div(127.5).sub(1.0)


# ---------------------------------------------------------------------------------------- data


@dataclass
class ImageSet:
    images: np.ndarray  # (N, H, W, 3) uint8
    labels: np.ndarray  # (N,) int64, index into TERRAIN_CLASSES
    paths: list[str]


def load_split(root: Path, split: str) -> ImageSet:
    """Images of `split` ("train", "test" or "all") from an ImageFolder tree {split}/{class}/*.png."""
    from PIL import Image

    root = Path(root)
    splits = ("train", "test") if split == "all" else (split,)
    if split not in ("train", "test", "all"):
        raise ValueError(f"unknown split {split!r}; valid: train, test, all")
    images, labels, paths = [], [], []
    for s in splits:
        for label, terrain in enumerate(TERRAIN_CLASSES):
            for path in sorted((root / s / terrain).glob("*.png")):
                images.append(np.asarray(Image.open(path).convert("RGB")))
                labels.append(label)
                paths.append(path.relative_to(root).as_posix())
    if not images:
        raise FileNotFoundError(f"no images under {root}/{'{' + ','.join(splits) + '}'}/{{{','.join(TERRAIN_CLASSES)}}}/*.png")
    return ImageSet(np.stack(images), np.array(labels, dtype=np.int64), paths)


# ---------------------------------------------------------------------------------------- training


@dataclass(frozen=True)
class TrainConfig:
    epochs: int = 60
    batch_size: int = 32
    learning_rate: float = 1e-3
    weight_decay: float = 1e-4
    seed: int = 0
    torch_threads: int = 1  # be a good neighbour on shared CPUs


def augment(batch: torch.Tensor, generator: torch.Generator, max_shift_px: int = 4) -> torch.Tensor:
    """Label-preserving changes: colour carries no label (ground colours are drawn alike for every
    class), so permute RGB channels and jitter brightness/contrast; the course is symmetric in y, so
    mirror left-right; the pose varies, so shift by up to `max_shift_px` (edge pixels repeated)."""
    n, _, h, w = batch.shape
    perms = torch.stack([torch.randperm(3, generator=generator) for _ in range(n)])
    batch = torch.stack([batch[i, perms[i]] for i in range(n)])
    scale = 1.0 + 0.2 * (torch.rand(n, 1, 1, 1, generator=generator) - 0.5)
    shift = 0.2 * (torch.rand(n, 1, 1, 1, generator=generator) - 0.5)
    batch = (batch * scale + shift).clamp(-1.0, 1.0)
    flip = torch.rand(n, generator=generator) < 0.5
    batch = torch.where(flip[:, None, None, None], batch.flip(3), batch)
    if max_shift_px > 0:
        m = max_shift_px
        padded = nn.functional.pad(batch, (m, m, m, m), mode="replicate")
        offsets = torch.randint(0, 2 * m + 1, (n, 2), generator=generator)
        batch = torch.stack([padded[i, :, dy:dy + h, dx:dx + w] for i, (dy, dx) in enumerate(offsets.tolist())])
    return batch


def train(train_set: ImageSet, config: TrainConfig = TrainConfig(),
          on_epoch: Callable[[int, float, float], None] | None = None) -> tuple[LeNetAttention, dict]:
    """Train on `train_set`; return the model (eval mode) and a history {loss, train_accuracy} per epoch."""
    torch.set_num_threads(config.torch_threads)
    torch.manual_seed(config.seed)
    generator = torch.Generator().manual_seed(config.seed)
    model = LeNetAttention()
    optimiser = torch.optim.AdamW(model.parameters(), lr=config.learning_rate, weight_decay=config.weight_decay)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, T_max=max(1, config.epochs))
    x_all, y_all = to_tensor(train_set.images), torch.from_numpy(train_set.labels)
    history = {"loss": [], "train_accuracy": []}
    for epoch in range(config.epochs):
        model.train()
        order = torch.randperm(len(y_all), generator=generator)
        total_loss, correct = 0.0, 0
        for start in range(0, len(order), config.batch_size):
            idx = order[start:start + config.batch_size]
            x, y = augment(x_all[idx], generator), y_all[idx]
            logits = model(x)
            loss = nn.functional.cross_entropy(logits, y)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            total_loss += loss.item() * len(idx)
            correct += int((logits.argmax(1) == y).sum())
        schedule.step()
        history["loss"].append(total_loss / len(y_all))
        history["train_accuracy"].append(correct / len(y_all))
        if on_epoch is not None:
            on_epoch(epoch + 1, history["loss"][-1], history["train_accuracy"][-1])
    model.eval()
    return model, history


@torch.no_grad()
def predict(model: LeNetAttention, images: np.ndarray, batch_size: int = 128) -> np.ndarray:
    """Class indices for (N, H, W, 3) uint8 images."""
    model.eval()
    out = [model(to_tensor(images[i:i + batch_size])).argmax(1).numpy() for i in range(0, len(images), batch_size)]
    return np.concatenate(out)


# ---------------------------------------------------------------------------------------- metrics


def evaluate(labels: np.ndarray, predicted: np.ndarray) -> dict:
    """Accuracy, per-class precision and recall, confusion matrix [true][predicted]."""
    k = len(TERRAIN_CLASSES)
    confusion = np.zeros((k, k), dtype=int)
    np.add.at(confusion, (labels, predicted), 1)
    per_class = {}
    for i, name in enumerate(TERRAIN_CLASSES):
        tp = confusion[i, i]
        per_class[name] = {
            "precision": float(tp / confusion[:, i].sum()) if confusion[:, i].sum() else float("nan"),
            "recall": float(tp / confusion[i].sum()) if confusion[i].sum() else float("nan"),
            "support": int(confusion[i].sum()),
        }
    return {"accuracy": float(np.trace(confusion) / confusion.sum()), "num_images": int(confusion.sum()),
            "per_class": per_class, "confusion": confusion.tolist(), "classes": list(TERRAIN_CLASSES)}


def plot_confusion(report: dict, path: Path, title: str) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = np.array(report["confusion"])
    fig, ax = plt.subplots(figsize=(4.2, 3.8), dpi=120)
    ax.imshow(m, cmap="Blues")
    classes = report["classes"]
    ax.set_xticks(range(len(classes)), classes)
    ax.set_yticks(range(len(classes)), classes)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    for i in range(m.shape[0]):
        for j in range(m.shape[1]):
            ax.text(j, i, str(m[i, j]), ha="center", va="center", color="white" if m[i, j] > m.max() / 2 else "black")
    ax.set_title(f"{title}\naccuracy {100 * report['accuracy']:.1f}% ({report['num_images']} images)", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------------------- checkpoints


class ChecksumError(HexbenchError):
    """A checkpoint whose sha256 differs from the one recorded for it."""


def image_sha256s(root: Path, paths: list[str]) -> list[str]:
    """The sha256 of each image file (paths relative to `root`, as ImageSet.paths)."""
    return [sha256_file(Path(root) / p) for p in paths]


def training_overlap(sidecar: dict, root: Path, paths: list[str]) -> tuple[list[str] | None, str]:
    """The evaluated images (paths under `root`) byte-identical to an image the classifier trained on,
    and how that was known; None when the sidecar cannot tell (then the reason says why).

    The training images are the sidecar's `train_image_sha256` (written by `classifier train`), or,
    for weights trained before it was written, the train split of the dataset manifest the sidecar
    names by its sha256, when the evaluated folder's manifest is that one."""
    trained = sidecar.get("train_image_sha256")
    source = "the sidecar's train_image_sha256"
    if trained is None:
        from hexbench.perception.dataset.build import MANIFEST_NAME, load_manifest

        manifest = Path(root) / MANIFEST_NAME
        recorded = (sidecar.get("dataset") or {}).get("manifest_sha256")
        if not (recorded and manifest.is_file() and sha256_file(manifest) == recorded):
            return None, ("its sidecar lists no training images and this folder is not its training dataset "
                          "(manifest sha256 differs)")
        trained = [f["sha256"] for f in load_manifest(root)["files"] if f.get("split") == "train"]
        source = "the train split of its training dataset's manifest"
    trained = set(trained)
    return [p for p, h in zip(paths, image_sha256s(root, paths)) if h in trained], source


def sidecar_path(checkpoint: Path) -> Path:
    return Path(checkpoint).with_suffix(".json")


def save_checkpoint(model: LeNetAttention, path: Path, provenance: dict) -> dict:
    """Write weights to `path` and `<path>.json` with their sha256 and `provenance`; return the sidecar."""
    import io

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {"state_dict": model.state_dict(), "classes": list(TERRAIN_CLASSES),
               "image_height_px": IMAGE_HEIGHT_PX, "image_width_px": IMAGE_WIDTH_PX}
    buf = io.BytesIO()
    torch.save(payload, buf)
    data = buf.getvalue()
    write_bytes_atomic(path, data)
    sidecar = {"file": path.name, "sha256": sha256_bytes(data), "bytes": len(data),
               "architecture": "LeNetAttention", "classes": list(TERRAIN_CLASSES),
               "input": f"{IMAGE_HEIGHT_PX}x{IMAGE_WIDTH_PX} RGB", **provenance}
    sidecar_path(path).write_text(json.dumps(sidecar, indent=2) + "\n")
    return sidecar


def load_classifier(path: Path, expected_sha256: str | None = None) -> LeNetAttention:
    """Load weights after checking their sha256 (from `expected_sha256` or the `<path>.json` sidecar)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"classifier checkpoint {path} not found")
    if expected_sha256 is None:
        side = sidecar_path(path)
        if not side.is_file():
            raise ChecksumError(f"{path}: no sidecar {side.name} with its sha256; refusing to load unverified weights")
        expected_sha256 = json.loads(side.read_text())["sha256"]
    actual = sha256_file(path)
    if actual != expected_sha256:
        raise ChecksumError(f"{path}: sha256 {actual} does not match the recorded {expected_sha256}; refusing to load")
    payload = torch.load(path, map_location="cpu", weights_only=True)
    if tuple(payload["classes"]) != TERRAIN_CLASSES:
        raise ValueError(f"{path}: classes {payload['classes']} differ from {list(TERRAIN_CLASSES)}")
    model = LeNetAttention(len(payload["classes"]), payload["image_height_px"], payload["image_width_px"])
    model.load_state_dict(payload["state_dict"])
    model.eval()
    return model


DEFAULT_CHECKPOINT = REPO_ROOT / "baselines" / "checkpoints" / "terrain_classifier.pt"

