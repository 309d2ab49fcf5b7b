"""`hexbench classifier train|eval`: the LeNet + self-attention terrain classifier (paper 3.1)."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import Optional

import typer

DEFAULT_DATA = Path("build/terrain-images")


def _fail(message: str) -> None:
    typer.secho(f"error: {message}", fg="red", err=True)
    raise typer.Exit(2)


def _print_report(report: dict, title: str) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console()
    console.print(f"{title}: accuracy {100 * report['accuracy']:.2f}% on {report['num_images']} images")
    table = Table()
    for col in ("class", "precision", "recall", "support"):
        table.add_column(col)
    for name, m in report["per_class"].items():
        table.add_row(name, f"{100 * m['precision']:.1f}%", f"{100 * m['recall']:.1f}%", str(m["support"]))
    console.print(table)


def register(app: typer.Typer) -> None:
    group = typer.Typer(no_args_is_help=True, help="Terrain classifier (LeNet + self-attention): train, eval.")
    app.add_typer(group, name="classifier")

    @group.command("train")
    def train_cmd(data: Path = typer.Option(DEFAULT_DATA, "--data", help="terrain-images folder ({train,test}/<class>/*.png)"),
                  out: Optional[Path] = typer.Option(None, "--out", help="checkpoint path (default baselines/checkpoints/terrain_classifier.pt)"),
                  epochs: int = typer.Option(60, "--epochs", min=1),
                  seed: int = typer.Option(0, "--seed", min=0),
                  threads: int = typer.Option(1, "--threads", min=1, help="torch CPU threads")) -> None:
        """Train on the train split, report test-split accuracy, write weights + sha256 sidecar."""
        import time

        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

        from hexbench.artifacts.files import sha256_file
        from hexbench.perception.classifier import (
            DEFAULT_CHECKPOINT,
            TrainConfig,
            evaluate,
            image_sha256s,
            load_split,
            predict,
            save_checkpoint,
            train,
        )
        from hexbench.perception.dataset.build import MANIFEST_NAME

        out = out or DEFAULT_CHECKPOINT
        try:
            train_set, test_set = load_split(data, "train"), load_split(data, "test")
        except FileNotFoundError as err:
            _fail(f"{err}; build the dataset with `hexbench dataset build terrain-images` or download it")
        config = TrainConfig(epochs=epochs, seed=seed, torch_threads=threads)
        start = time.perf_counter()
        with Progress(TextColumn("training"), BarColumn(), MofNCompleteColumn(), TextColumn("{task.description}")) as bar:
            task = bar.add_task("", total=epochs)
            model, history = train(train_set, config, on_epoch=lambda e, loss, acc: bar.update(
                task, completed=e, description=f"loss {loss:.3f}  train acc {100 * acc:.1f}%"))
        wall_s = time.perf_counter() - start
        report = evaluate(test_set.labels, predict(model, test_set.images))
        manifest = Path(data) / MANIFEST_NAME
        provenance = {
            "command": "hexbench classifier " + " ".join(shlex.quote(a) for a in sys.argv[2:]),
            "seed": seed, "train_config": config.__dict__, "train_wall_time_s": round(wall_s, 1),
            "dataset": {"path": str(data), "manifest_sha256": sha256_file(manifest) if manifest.is_file() else None,
                        "train_images": len(train_set.labels), "test_images": len(test_set.labels)},
            "final_train_loss": round(history["loss"][-1], 5),
            # what `classifier eval` checks evaluated images against (no test on training images)
            "train_image_sha256": sorted(set(image_sha256s(data, train_set.paths))),
            "evaluations": {"test_split": {"accuracy": report["accuracy"], "num_images": report["num_images"],
                                           "confusion": report["confusion"]}},
        }
        sidecar = save_checkpoint(model, out, provenance)
        _print_report(report, "test split")
        typer.echo(f"wrote {out} (sha256 {sidecar['sha256']}) in {wall_s:.1f} s of training")

    @group.command("eval")
    def eval_cmd(data: Path = typer.Option(DEFAULT_DATA, "--data", help="terrain-images folder"),
                 split: str = typer.Option("test", "--split", help="train, test or all"),
                 checkpoint: Optional[Path] = typer.Option(None, "--checkpoint", help="weights (default: the shipped ones)"),
                 out: Path = typer.Option(Path("build/classifier-eval"), "--out", help="folder for the report JSON and confusion PNG"),
                 record: Optional[str] = typer.Option(None, "--record", help="also store the result under this key in the checkpoint's sidecar JSON")) -> None:
        """Accuracy, per-class precision/recall and a confusion-matrix PNG."""
        import json

        from hexbench.perception.classifier import (
            DEFAULT_CHECKPOINT,
            ChecksumError,
            evaluate,
            load_classifier,
            load_split,
            plot_confusion,
            predict,
            sidecar_path,
            training_overlap,
        )

        if split not in ("train", "test", "all"):
            _fail(f"unknown split {split!r}; valid: train, test, all")
        checkpoint = checkpoint or DEFAULT_CHECKPOINT
        try:
            model = load_classifier(checkpoint)
            images = load_split(data, split)
        except (FileNotFoundError, ChecksumError, ValueError) as err:
            _fail(str(err))
        report = evaluate(images.labels, predict(model, images.images))
        report.update(data=str(data), split=split, checkpoint=str(checkpoint))
        overlap, how = training_overlap(json.loads(sidecar_path(checkpoint).read_text()), data, images.paths)
        report["training_overlap"] = {"images": None if overlap is None else len(overlap), "checked_against": how}
        if overlap is None:
            typer.secho(f"warning: overlap with the training images not checked: {how}", fg="yellow", err=True)
        elif overlap:
            typer.secho(f"warning: {len(overlap)} of {len(images.paths)} evaluated images are byte-identical to images "
                        f"{checkpoint} trained on ({how}), e.g. {overlap[0]}; this accuracy is not a held-out test",
                        fg="yellow", err=True)
        report["misclassified"] = [p for p, y, q in zip(images.paths, images.labels, predict(model, images.images)) if y != q]
        out.mkdir(parents=True, exist_ok=True)
        stem = f"{Path(data).name}-{split}"
        (out / f"{stem}.json").write_text(json.dumps(report, indent=2) + "\n")
        png = plot_confusion(report, out / f"{stem}-confusion.png", f"{Path(data).name} / {split}")
        _print_report(report, f"{Path(data).name} / {split}")
        typer.echo(f"report {out / (stem + '.json')}, confusion matrix {png}")
        if record:
            side = sidecar_path(checkpoint)
            meta = json.loads(side.read_text())
            meta.setdefault("evaluations", {})[record] = {
                "data": str(data), "split": split, "accuracy": report["accuracy"],
                "num_images": report["num_images"], "confusion": report["confusion"],
                "command": "hexbench classifier " + " ".join(sys.argv[2:])}
            side.write_text(json.dumps(meta, indent=2) + "\n")
