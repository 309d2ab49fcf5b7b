"""The leaderboard: result records in `leaderboard/*.json` -> README.md, index.html, leaderboard.csv.

Measured records (made by `hexbench run`) are validated, their summaries recomputed from their
episode rows, and ranked; reported records (the paper's numbers, leaderboard/paper_reference.json)
are shown beside them, never ranked. Records of different protocol versions are never mixed: a
build shows one protocol. Extra courses (the mixed course) are scored apart, in
`leaderboard/courses/`. Each measured entry shows its trust tier and its training budget.

  records     reading records, schema and protocol validation, trust tiers, one `Row` per controller
  budget      training budgets from the checkpoint manifests (shown, not ranked)
  ranking     the ranking rule, per-controller statistics, the `Board` a build shows
  formatting  how numbers, levels, trust tiers and names read in every output
  markdown    record strings as literal Markdown text (escaping, tables)
  readme      leaderboard/README.md
  table_csv   leaderboard.csv
  plots       the success-vs-level plots (SVG)
  html_page   the self-contained index.html (with hexbench/leaderboard/assets/)
  courses     the extra courses' records and leaderboard/courses/README.md
  generate    `hexbench leaderboard build`: everything rendered, then written atomically
  admission   `hexbench leaderboard add`: replay before a record joins; `--replace` never downgrades
  statistics  aggregates over runs (seeds): IQM, stratified-bootstrap intervals, probability of improvement
  seeds       seed runs (baselines/seeds/) read, validated, bound to their manifests and aggregated per method
  seeds_page  leaderboard/seeds/: the methods across their seeds (tables and SVG figures)
"""

from hexbench.leaderboard.admission import add
from hexbench.leaderboard.formatting import REPORTED_NOTE
from hexbench.leaderboard.generate import GENERATED_FILES, build
from hexbench.leaderboard.html_page import ASSETS_DIR, generator_tag
from hexbench.leaderboard.ranking import rank_overall, rank_terrain
from hexbench.leaderboard.records import (
    TIER_REPLAYED,
    RecordError,
    Row,
    measured_row,
    record_files,
    record_tier,
    rows_of,
)
from hexbench.leaderboard.table_csv import CSV_COLUMNS

__all__ = ["ASSETS_DIR", "CSV_COLUMNS", "GENERATED_FILES", "REPORTED_NOTE", "TIER_REPLAYED", "RecordError", "Row",
           "add", "build", "generator_tag", "measured_row", "rank_overall", "rank_terrain", "record_files",
           "record_tier", "rows_of"]
