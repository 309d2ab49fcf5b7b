"""Issue criterion for HRL: at every level where the open-loop CPG succeeds in every episode, HRL
succeeds at least as often. Reads result records (any levels; `hexbench run` output) and compares
level by level on the episodes both cover.

    python bench/hrl_vs_cpg.py RUN_OR_RECORD [RUN_OR_RECORD ...] [--cpg leaderboard/cpg.json]

Prints one line per compared level and a verdict; exit 0 only if HRL is at least the CPG at every
level where the CPG is at 100% (levels HRL's records do not cover are listed as not measured).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def read(path: Path) -> dict:
    path = Path(path)
    return json.loads((path / "result.json" if path.is_dir() else path).read_text())


def successes(record: dict) -> dict[tuple[str, float], tuple[int, int]]:
    return {(lv["terrain"], float(lv["level"])): (lv["successes"], lv["episodes"]) for lv in record["levels"]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("records", nargs="+", type=Path, help="HRL run folders or result records")
    parser.add_argument("--cpg", type=Path, default=REPO / "leaderboard" / "cpg.json")
    args = parser.parse_args(argv)
    cpg = successes(read(args.cpg))
    hrl: dict[tuple[str, float], tuple[int, int]] = {}
    for path in args.records:
        hrl.update(successes(read(path)))
    full = sorted(k for k, (s, n) in cpg.items() if s == n)
    ok, missing = True, []
    for key in full:
        if key not in hrl:
            missing.append(f"{key[0]} {key[1]:g}")
            continue
        (hs, hn), (cs, cn) = hrl[key], cpg[key]
        at_least = hs / hn >= cs / cn
        ok &= at_least
        print(f"{key[0]:7s} {key[1]:>5g}: HRL {hs}/{hn}  CPG {cs}/{cn}  {'ok' if at_least else 'BELOW'}")
    if missing:
        print("not measured (CPG at 100%): " + ", ".join(missing))
    print("HRL >= CPG at every measured level where the CPG is at 100%" if ok else "HRL is below the CPG somewhere")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
