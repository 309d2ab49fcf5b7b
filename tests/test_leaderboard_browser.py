"""The generated index.html in a real headless Chromium (Debian's `chromium`; `make browser` installs it).

Chromium runs with --dump-dom (the DOM after the page's scripts ran) and --enable-logging=stderr,
which prints every console message and uncaught exception as a `:CONSOLE` line; the page logs
nothing on purpose, so any such line is a failure. A second run takes a screenshot.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from html.parser import HTMLParser
from pathlib import Path

import pytest
from leaderboard_records import demo_records, write_board

from hexbench import leaderboard as lb

CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync")
# Appended to a copy of the page: records the row order, clicks the Rank header twice (descending)
# and records the order again.
SORT_PROBE = """<script>
(function () {
  function order() {
    return Array.prototype.map.call(document.querySelectorAll("#leaderboard tbody tr"),
                                    function (tr) { return tr.getAttribute("data-label"); }).join("|");
  }
  document.documentElement.setAttribute("data-initial", order());
  var th = document.querySelector("#leaderboard thead th");
  th.click(); th.click();
  document.documentElement.setAttribute("data-sorted", order());
}());
</script>"""


def _chromium() -> str:
    found = shutil.which("chromium") or ("/usr/bin/chromium" if os.access("/usr/bin/chromium", os.X_OK) else None)
    if found is None:
        pytest.skip("Debian's chromium is not installed and could not be had (`make browser` runs "
                    "`apt-get install -y chromium`)")
    return found


def _run_chromium(chromium: str, page: Path, *extra: str) -> subprocess.CompletedProcess:
    with tempfile.TemporaryDirectory(prefix="hexbench-chromium-") as profile:
        return subprocess.run([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "--enable-logging=stderr",
                               "--v=0", *extra, page.as_uri()], capture_output=True, text=True, timeout=120)


class _DomSummary(HTMLParser):
    """Counts rows of table#leaderboard's body, inline SVG plots and their drawn paths."""

    def __init__(self) -> None:
        super().__init__()
        self.html_attrs: dict[str, str | None] = {}
        self.table_stack: list[str | None] = []
        self.in_tbody = False
        self.leaderboard_rows: list[str | None] = []
        self.plots = 0
        self.svgs_in_plots = 0
        self.paths = 0
        self.in_plot = False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "html":
            self.html_attrs = a
        elif tag == "table":
            self.table_stack.append(a.get("id"))
        elif tag == "tbody":
            self.in_tbody = True
        elif tag == "tr" and self.in_tbody and self.table_stack and self.table_stack[-1] == "leaderboard":
            self.leaderboard_rows.append(a.get("data-label"))
        elif tag == "figure" and "plot" in (a.get("class") or ""):
            self.plots += 1
            self.in_plot = True
        elif tag == "svg" and self.in_plot:
            self.svgs_in_plots += 1
        elif tag == "path" and self.in_plot:
            self.paths += 1

    def handle_endtag(self, tag):
        if tag == "table" and self.table_stack:
            self.table_stack.pop()
        elif tag == "tbody":
            self.in_tbody = False
        elif tag == "figure":
            self.in_plot = False


@pytest.fixture(scope="module")
def built_page(tmp_path_factory) -> Path:
    d = write_board(tmp_path_factory.mktemp("leaderboard"), demo_records())
    lb.build(d)
    return d / "index.html"


def test_index_html_loads_cleanly_in_headless_chromium(built_page, tmp_path):
    chromium = _chromium()
    probe = tmp_path / "probe.html"
    probe.write_text(built_page.read_text().replace("</body>", SORT_PROBE + "\n</body>"))
    done = _run_chromium(chromium, probe, "--dump-dom")
    assert done.returncode == 0, done.stderr[-2000:]
    console = [line for line in done.stderr.splitlines() if ":CONSOLE" in line]
    assert console == [], "console messages / uncaught errors:\n" + "\n".join(console)
    dom = _DomSummary()
    dom.feed(done.stdout)
    assert dom.html_attrs.get("data-ready") == "1", "the page script did not run to its end"
    # one table row per measured controller, in rank order; the paper rows live in their own table
    assert sorted(dom.leaderboard_rows) == ["middling", "strong", "weak"]
    assert dom.html_attrs.get("data-initial") == "strong|middling|weak"
    assert dom.html_attrs.get("data-sorted") == "weak|middling|strong", "clicking Rank twice sorts descending"
    # a plot per terrain, each an inline SVG with drawn curves
    assert dom.plots == 3 and dom.svgs_in_plots == 3 and dom.paths > 100
    assert re.search(r"reported by the paper, not run here", done.stdout)


def test_index_html_screenshot(built_page, tmp_path):
    chromium = _chromium()
    shot = Path(tempfile.gettempdir()) / "hexbench-leaderboard-screenshot.png"
    shot.unlink(missing_ok=True)
    done = _run_chromium(chromium, built_page, "--hide-scrollbars", "--window-size=1280,4200",
                         f"--screenshot={shot}")
    assert done.returncode == 0, done.stderr[-2000:]
    data = shot.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 50_000, "screenshot missing or blank"
    print(f"screenshot: {shot}")


def test_console_error_detection_works(tmp_path):
    """Guards the check above: a page with an uncaught error does produce a :CONSOLE line."""
    chromium = _chromium()
    page = tmp_path / "broken.html"
    page.write_text("<!DOCTYPE html><html><body><script>notDefinedAnywhere();</script></body></html>")
    done = _run_chromium(chromium, page, "--dump-dom")
    assert any(":CONSOLE" in line and "notDefinedAnywhere" in line for line in done.stderr.splitlines())
