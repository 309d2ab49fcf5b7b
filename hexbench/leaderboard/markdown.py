"""Markdown that shows record strings as exactly their text (README.md and the courses page).

Strings taken from a record (labels, file names, paths, commands, citations, ...) come from
submitters. In Markdown they go through `md_text` (text) or `md_code` (a code span), so they show as
the literal text: nothing in them can make HTML (GitHub passes inline HTML through), links,
emphasis, code spans, block structure or extra table cells. Plain strings ("ppo_cpg",
"PPO-CPG (paper)") come out unchanged.
"""

from __future__ import annotations

import re

from hexbench.leaderboard.formatting import one_line, pct

_BACKSLASHED = re.compile(r"[\\`*\[\]~$]")  # escapes, code spans, emphasis, links/images, strikethrough, math
# `_` makes emphasis only next to a non-alphanumeric character; inside a word ("ppo_cpg") it cannot
_UNDERSCORE = re.compile(r"(?<![^\W_])_|_(?![^\W_])")
_BLOCK_START = re.compile(r"^(\s*)(?:([#+=-])|(\d+)([.)]))")  # headings, lists, setext/thematic breaks


def md_text(text, block: bool = False) -> str:
    """A record string as Markdown text that renders as exactly that text.

    block=True where the text starts a block (a paragraph or list item): a leading `#`, `-`, `+`, `=`
    or `1.` is escaped too, so it cannot become a heading, list or rule. In a table, `md_table`
    escapes `|`.
    """
    s = _BACKSLASHED.sub(lambda m: "\\" + m.group(0), one_line(text))
    s = s.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    s = _UNDERSCORE.sub(r"\\_", s)
    if block:
        s = _BLOCK_START.sub(lambda m: m.group(1) + (f"\\{m.group(2)}" if m.group(2) else
                                                     f"{m.group(3)}\\{m.group(4)}"), s, count=1)
    return s


def md_code(text) -> str:
    """A record string as a Markdown code span: literal text (HTML and Markdown are not parsed in it);
    the fence is longer than any run of backticks inside. In a table, `md_table` escapes `|` (GFM
    removes that backslash inside code spans too). A string with `<` is written as escaped text
    (`md_text`) instead, so the file never holds a raw tag, even for a reader that does not parse
    Markdown."""
    s = one_line(text)
    if "<" in s:
        return md_text(s)
    fence = "`" * (max((len(run) for run in re.findall(r"`+", s)), default=0) + 1)
    pad = " " if s.startswith("`") or s.endswith("`") or (s.startswith(" ") and s.endswith(" ") and s.strip()) else ""
    return f"{fence}{pad}{s}{pad}{fence}"


def _table_cell(cell: str) -> str:
    return one_line(cell).replace("|", "\\|")


def md_table(header: list[str], rows: list[list[str]], align: list[str] | None = None) -> str:
    """A GFM table; cells are Markdown (record strings already through md_text / md_code), `|` in them is
    escaped so it never splits a cell."""
    align = align or ["l"] + ["r"] * (len(header) - 1)
    sep = ["---:" if a == "r" else ":---:" if a == "c" else "---" for a in align]
    lines = ["| " + " | ".join(_table_cell(c) for c in header) + " |", "| " + " | ".join(sep) + " |"]
    lines += ["| " + " | ".join(_table_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def md_success_cell(lv: dict | None, with_ci: bool) -> str:
    """A level's success rate as a table cell, with its 95% Wilson interval in brackets if `with_ci`."""
    if lv is None:
        return "–"
    if not with_ci:
        return pct(lv["success_rate"])
    return f"{pct(lv['success_rate'])} ({100 * lv['ci95_low']:.0f}–{100 * lv['ci95_high']:.0f})"
