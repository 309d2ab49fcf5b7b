"""`hexbench dataset build|download|publish|verify`: the terrain-image dataset (paper 3.1)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

DATASETS = ("terrain-images",)


def _fail(message: str) -> None:
    typer.secho(f"error: {message}", fg="red", err=True)
    raise typer.Exit(2)


def _check_name(name: str) -> None:
    if name not in DATASETS:
        _fail(f"unknown dataset {name!r}; valid datasets: {', '.join(DATASETS)}")


def register(app: typer.Typer) -> None:
    group = typer.Typer(no_args_is_help=True, help="Terrain-image dataset: build, download, publish, verify.")
    app.add_typer(group, name="dataset")

    @group.command("build")
    def build(name: str = typer.Argument(..., help="dataset name: terrain-images"),
              per_class: int = typer.Option(200, "--per-class", help="images per terrain class (paper: 200)"),
              out: Path = typer.Option(Path("build/terrain-images"), "--out", help="output folder"),
              seed: int = typer.Option(0, "--seed", help="dataset seed (fixes every terrain, pose and colour)"),
              version: int = typer.Option(2, "--version", help="2: approach + walk views (default); 1: approach views only"),
              force: bool = typer.Option(False, "--force", help="replace an existing output folder")) -> None:
        """Render the dataset from the robot camera: {train,test}/{rough,slopes,stairs}/*.png + manifest.json."""
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        from hexbench.perception.dataset.build import BuildConfig, build_terrain_images

        _check_name(name)
        try:
            config = BuildConfig(per_class=per_class, seed=seed, version=version)
        except ValueError as err:
            _fail(str(err))
        columns = (TextColumn("rendering (approach images, then walks)"), BarColumn(), MofNCompleteColumn(),
                   TimeRemainingColumn())
        with Progress(*columns) as progress:
            task = progress.add_task("render", total=3 * per_class + len(config.planned_walks))
            try:
                manifest = build_terrain_images(out, config, force=force,
                                                on_image=lambda done, total: progress.update(task, completed=done))
            except FileExistsError as err:
                _fail(str(err))
        counts = manifest["counts"]
        typer.echo(f"wrote {len(manifest['files'])} images to {out} "
                   f"(train {sum(counts['train'].values())}, test {sum(counts['test'].values())}; "
                   f"version {manifest['version']}, seed {seed})")

    @group.command("verify")
    def verify(folder: Path = typer.Argument(..., help="a build or downloaded dataset folder")) -> None:
        """Check every file of a dataset folder against its manifest's sha256."""
        from hexbench.perception.dataset.build import DatasetError, verify_build

        try:
            problems = verify_build(folder)
        except DatasetError as err:
            _fail(str(err))
        if problems:
            _fail(f"{folder}: {problems[0]} ({len(problems)} problem(s))")
        typer.echo(f"{folder}: every file matches the manifest")

    @group.command("preview")
    def preview(folder: Path = typer.Argument(Path("build/terrain-images"), help="a dataset folder"),
                out: Path = typer.Option(Path("build/terrain-images-preview.png"), "--out", help="PNG to write"),
                per_class: int = typer.Option(8, "--per-class", min=1, max=32, help="images per class (one row each)")) -> None:
        """A contact sheet: one row per class, one image of each of its first terrain instances."""
        import numpy as np
        from PIL import Image, ImageDraw

        from hexbench.perception.dataset.build import DatasetError, load_manifest
        from hexbench.perception.views import TERRAIN_CLASSES

        try:
            files = load_manifest(folder)["files"]
        except DatasetError as err:
            _fail(str(err))
        scale, label_w = 2, 70
        rows = []
        for terrain in TERRAIN_CLASSES:
            chosen = [f for f in files if f["label"] == terrain and f["view_index"] == 0][:per_class]
            tiles = [np.asarray(Image.open(folder / f["path"]).convert("RGB")) for f in chosen]
            rows.append((terrain, np.concatenate(tiles, axis=1)))
        h, w = rows[0][1].shape[:2]
        sheet = Image.new("RGB", (label_w + w * scale, h * scale * len(rows)), "white")
        draw = ImageDraw.Draw(sheet)
        for i, (terrain, row) in enumerate(rows):
            sheet.paste(Image.fromarray(row).resize((w * scale, h * scale), Image.NEAREST), (label_w, i * h * scale))
            draw.text((6, i * h * scale + h * scale // 2 - 6), terrain, fill="black")
        out.parent.mkdir(parents=True, exist_ok=True)
        sheet.save(out)
        typer.echo(f"wrote {out}")

    @group.command("download")
    def download(name: str = typer.Argument(..., help="dataset name: terrain-images"),
                 url: Optional[str] = typer.Option(None, "--url", help="fetch from this URL instead of the registry's mirrors"),
                 version: Optional[int] = typer.Option(None, "--version", help="major version (default: the highest registered)"),
                 registry: Optional[Path] = typer.Option(None, "--registry", help="registry TOML (default datasets/registry.toml)"),
                 data_dir: Optional[Path] = typer.Option(None, "--data-dir", help="cache folder (default $HEXBENCH_DATA_DIR or the user cache)")) -> None:
        """Download the published archive with pooch, verify its sha256 and extract it safely."""
        from hexbench.perception.dataset.registry import DownloadError
        from hexbench.perception.dataset.registry import download as fetch

        _check_name(name)
        try:
            folder = fetch(name, version=version, registry_path=registry, cache_dir=data_dir, url=url, progressbar=True)
        except DownloadError as err:
            _fail(str(err))
        typer.echo(str(folder))

    @group.command("publish")
    def publish(name: str = typer.Argument(..., help="dataset name: terrain-images"),
                build_dir: Path = typer.Option(Path("build/terrain-images"), "--build", help="a finished build folder"),
                out: Path = typer.Option(Path("build/dist"), "--out", help="where the archive is written"),
                url: list[str] = typer.Option([], "--url", help="mirror URL(s) of the archive (repeatable)"),
                update_registry: bool = typer.Option(False, "--update-registry", help="write the entry into datasets/registry.toml")) -> None:
        """Pack a build into a deterministic .tar.gz and print its registry entry."""
        from hexbench.perception.dataset.archive import pack_build
        from hexbench.perception.dataset.build import DatasetError, load_manifest, verify_build
        from hexbench.perception.dataset.registry import (
            REGISTRY_PATH,
            load_registry,
            registry_entry_for,
            write_registry,
        )

        _check_name(name)
        try:
            manifest = load_manifest(build_dir)
        except DatasetError as err:
            _fail(str(err))
        problems = verify_build(build_dir)
        if problems:
            _fail(f"{build_dir}: {problems[0]} ({len(problems)} problem(s)); rebuild before publishing")
        archive_name = f"{name}-{manifest['version']}.tar.gz"
        archive = pack_build(build_dir, out / archive_name, root_name=f"{name}-{manifest['version']}")
        urls = tuple(url) or (f"{PLACEHOLDER_MIRROR}/{archive_name}",)
        entry = registry_entry_for(archive, name, manifest["version"], urls)
        typer.echo(f"# archive: {archive}")
        typer.echo(entry.toml(), nl=False)
        if update_registry:
            entries = load_registry() if REGISTRY_PATH.is_file() else {}
            entries[entry.key] = entry
            header = REGISTRY_PATH.read_text().split("[", 1)[0] if REGISTRY_PATH.is_file() else ""
            write_registry(entries, header=header)
            typer.echo(f"# updated {REGISTRY_PATH}")


# RFC 2606 reserves .invalid: this host never resolves. Replace with a real mirror when one exists.
PLACEHOLDER_MIRROR = "https://mirror.hexbench.invalid/datasets"
