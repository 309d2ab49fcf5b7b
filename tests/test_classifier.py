"""Terrain classifier: architecture, metrics, checksum-verified checkpoints, a short training run."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from hexbench.cli import app
from hexbench.perception.classifier import (
    DEFAULT_CHECKPOINT,
    ChecksumError,
    LeNetAttention,
    TrainConfig,
    evaluate,
    load_classifier,
    load_split,
    plot_confusion,
    predict,
    save_checkpoint,
    sidecar_path,
    to_tensor,
    train,
)
from hexbench.perception.dataset.build import BuildConfig, build_terrain_images


def test_model_shapes_and_attention_block():
    model = LeNetAttention()
    x = to_tensor(np.zeros((4, 72, 96, 3), np.uint8))
    assert x.shape == (4, 3, 72, 96) and float(x.min()) == -1.0
    assert model(x).shape == (4, 3)
    assert any(isinstance(m, torch.nn.MultiheadAttention) for m in model.modules())
    with pytest.raises(ValueError, match="72x96"):
        to_tensor(np.zeros((2, 64, 64, 3), np.uint8))


def test_metrics_on_known_predictions(tmp_path):
    labels = np.array([0, 0, 1, 1, 2, 2])
    predicted = np.array([0, 1, 1, 1, 2, 0])
    r = evaluate(labels, predicted)
    assert r["accuracy"] == pytest.approx(4 / 6)
    assert r["confusion"] == [[1, 1, 0], [0, 2, 0], [1, 0, 1]]
    assert r["per_class"]["rough"] == {"precision": 0.5, "recall": 0.5, "support": 2}
    assert r["per_class"]["slopes"]["precision"] == pytest.approx(2 / 3)
    assert r["per_class"]["stairs"]["recall"] == 0.5
    png = plot_confusion(r, tmp_path / "c.png", "t")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_checkpoint_round_trip_and_tamper_refusal(tmp_path):
    torch.manual_seed(0)
    model = LeNetAttention().eval()
    path = tmp_path / "clf.pt"
    side = save_checkpoint(model, path, {"seed": 0})
    assert json.loads(sidecar_path(path).read_text())["sha256"] == side["sha256"]
    x = to_tensor(np.random.default_rng(0).integers(0, 255, (2, 72, 96, 3), dtype=np.uint8))
    with torch.no_grad():
        assert torch.equal(load_classifier(path)(x), model(x))
    data = bytearray(path.read_bytes())
    data[-10] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(ChecksumError, match="does not match"):
        load_classifier(path)
    sidecar_path(path).unlink()
    with pytest.raises(ChecksumError, match="no sidecar"):
        load_classifier(path)


def test_short_training_run_learns_and_cli_evaluates(tmp_path):
    data = tmp_path / "ds"
    build_terrain_images(data, BuildConfig(per_class=10, seed=11))
    train_set = load_split(data, "train")
    assert len(train_set.labels) == 24 and sorted(set(train_set.labels.tolist())) == [0, 1, 2]
    model, history = train(train_set, TrainConfig(epochs=8, batch_size=8, seed=0))
    assert len(history["loss"]) == 8 and history["loss"][-1] < history["loss"][0]
    assert predict(model, train_set.images).shape == (24,)

    ckpt = tmp_path / "clf.pt"
    result = CliRunner().invoke(app, ["classifier", "train", "--data", str(data), "--epochs", "2", "--out", str(ckpt)])
    assert result.exit_code == 0, result.output
    meta = json.loads(ckpt.with_suffix(".json").read_text())
    assert meta["seed"] == 0 and meta["train_wall_time_s"] > 0 and "test_split" in meta["evaluations"]
    result = CliRunner().invoke(app, ["classifier", "eval", "--data", str(data), "--checkpoint", str(ckpt),
                                      "--out", str(tmp_path / "rep"), "--split", "all"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "rep" / "ds-all-confusion.png").is_file()
    report = json.loads((tmp_path / "rep" / "ds-all.json").read_text())
    assert report["num_images"] == 30
    # the train split is in "all": its 24 images are the classifier's own training images, and eval says so
    assert report["training_overlap"]["images"] == 24 and len(meta["train_image_sha256"]) == 24
    assert "24 of 30 evaluated images are byte-identical to images" in result.output
    result = CliRunner().invoke(app, ["classifier", "eval", "--data", str(data), "--checkpoint", str(ckpt),
                                      "--out", str(tmp_path / "rep")])
    assert result.exit_code == 0 and "byte-identical" not in result.output  # the test split is held out
    # weights whose sidecar predates the list: known through the manifest of their own dataset only
    del meta["train_image_sha256"]
    ckpt.with_suffix(".json").write_text(json.dumps(meta))
    result = CliRunner().invoke(app, ["classifier", "eval", "--data", str(data), "--checkpoint", str(ckpt),
                                      "--out", str(tmp_path / "rep"), "--split", "train"])
    assert "24 of 24 evaluated images" in result.output and "training dataset's manifest" in result.output
    other = tmp_path / "other"
    build_terrain_images(other, BuildConfig(per_class=5, seed=12))
    result = CliRunner().invoke(app, ["classifier", "eval", "--data", str(other), "--checkpoint", str(ckpt),
                                      "--out", str(tmp_path / "rep")])
    assert result.exit_code == 0 and "overlap with the training images not checked" in result.output


def test_eval_rejects_bad_input(tmp_path):
    result = CliRunner().invoke(app, ["classifier", "eval", "--split", "val"])
    assert result.exit_code == 2 and "valid: train, test, all" in result.output
    result = CliRunner().invoke(app, ["classifier", "train", "--data", str(tmp_path / "nothing")])
    assert result.exit_code == 2 and "no images under" in result.output


@pytest.mark.skipif(not DEFAULT_CHECKPOINT.is_file(), reason="no shipped classifier weights")
def test_shipped_weights_load_and_meet_the_paper_accuracy_on_record():
    model = load_classifier(DEFAULT_CHECKPOINT)  # checks the sha256 in the sidecar
    meta = json.loads(sidecar_path(DEFAULT_CHECKPOINT).read_text())
    assert meta["evaluations"]["test_split"]["accuracy"] >= 0.975
    assert isinstance(model, LeNetAttention)


@pytest.mark.slow
@pytest.mark.skipif(not DEFAULT_CHECKPOINT.is_file(), reason="no shipped classifier weights")
def test_shipped_weights_on_fresh_terrain_seeds(tmp_path):
    """Render 100 images per class of never-used terrain seeds (seed 7) and classify them."""
    data = tmp_path / "fresh"
    build_terrain_images(data, BuildConfig(per_class=100, seed=7))
    images = load_split(data, "all")
    report = evaluate(images.labels, predict(load_classifier(DEFAULT_CHECKPOINT), images.images))
    assert report["accuracy"] >= 0.95, report
