"""`hexbench leaderboard build`: every output rendered from the records, then all written at once.

The build is deterministic: records are read in file-name order, rows are ordered by rank and
label, nothing depends on the clock, and the plots' SVG bytes are fixed for one matplotlib version.
Every file is rendered completely before any is written; each goes to a temporary name first and
all are renamed into place together, so a reader never sees a mix of two builds.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from hexbench.leaderboard.courses import COURSES_DIR, TABLE5_DIR, load_course_rows, load_table5_rows, render_courses_readme
from hexbench.leaderboard.html_page import render_html
from hexbench.leaderboard.ranking import Board, make_board
from hexbench.leaderboard.readme import render_readme
from hexbench.leaderboard.records import EpisodeClaims, RecordError, load_rows
from hexbench.leaderboard.seeds import SEEDS_DIR, aggregate, improvements, load_seed_runs, reference_runs
from hexbench.leaderboard.seeds_page import SEEDS_PAGE_DIR, render_seeds_page
from hexbench.leaderboard.table_csv import render_csv
from hexbench.suite.tasks import DEFAULT_PROTOCOL, load_suite

GENERATED_FILES = ("README.md", "index.html", "leaderboard.csv")


@dataclass
class BuildResult:
    written: list[Path]
    board: Board
    errors: list[str]
    skipped: list[str]


def write_all_atomically(files: dict[Path, str]) -> None:
    """Write every file to a temporary name first, then rename them all (no partial outputs)."""
    tmps = []
    try:
        for path, text in files.items():
            tmp = path.with_name(f".{path.name}.tmp")
            with open(tmp, "w", encoding="utf-8", newline="\n") as f:
                f.write(text)
            tmps.append((tmp, path))
    except BaseException:
        for tmp, _ in tmps:
            tmp.unlink(missing_ok=True)
        raise
    for tmp, path in tmps:
        os.replace(tmp, path)


def render_all(board: Board) -> dict[str, str]:
    return {"README.md": render_readme(board), "index.html": render_html(board),
            "leaderboard.csv": render_csv(board)}


def build(directory: str | Path = "leaderboard", protocol: str = DEFAULT_PROTOCOL,
          root: str | Path | None = None, seeds: str | Path | None = None) -> BuildResult:
    """Read every record under `directory`, write README.md, index.html and leaderboard.csv there.

    Records' checkpoint paths resolve against `root` (default: the directory's parent, the repository)
    to show each controller's training budget from the checkpoint manifest. Where the seed-run folder
    `seeds` (default: `root`/baselines/seeds) exists, the methods across their seeds are written to
    `directory`/seeds/ (hexbench.leaderboard.seeds).

    Refused records are left out and reported in `errors` (the caller decides the exit status);
    the three files are rendered completely before any is written.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise RecordError(f"{directory}: no such leaderboard directory")
    load_suite(protocol)  # ValueError naming the valid protocols
    claims = EpisodeClaims()  # one run's episodes show under one label, across the pages
    load = load_rows(directory, protocol, claims)
    root = directory.resolve().parent if root is None else Path(root)
    board = make_board(load, protocol, root)
    texts = render_all(board)
    files = {directory / name: texts[name] for name in GENERATED_FILES}
    errors, skipped = list(load.errors), list(load.skipped)
    courses = directory / COURSES_DIR
    if courses.is_dir():
        course_load = load_course_rows(courses, protocol, claims)
        errors += course_load.errors
        skipped += course_load.skipped
        table5 = None
        if (courses / TABLE5_DIR).is_dir():
            table5_load = load_table5_rows(courses / TABLE5_DIR, protocol, claims)
            errors += table5_load.errors
            skipped += table5_load.skipped
            table5 = table5_load.rows
        files[courses / "README.md"] = render_courses_readme(course_load.rows, board.suite, table5, board.measured)
    seeds = root / SEEDS_DIR if seeds is None else Path(seeds)
    if seeds.is_dir():
        seed_load = load_seed_runs(seeds, protocol)
        errors += seed_load.errors
        skipped += seed_load.skipped
        aggregates = aggregate(seed_load.runs + reference_runs(board.measured, board.suite.terrains), board.suite)
        page = render_seeds_page(aggregates, improvements(aggregates), board.suite, seed_load.errors,
                                 seed_load.unscored)
        (directory / SEEDS_PAGE_DIR).mkdir(exist_ok=True)
        files.update({directory / SEEDS_PAGE_DIR / name: text for name, text in page.items()})
    write_all_atomically(files)
    return BuildResult(list(files), board, errors, skipped)
