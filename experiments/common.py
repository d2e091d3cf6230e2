"""Shared by the table entries: run a search entry point into RUN_DIR, then print its rows."""

from __future__ import annotations

import sys
from typing import Callable

from search.journal import Journal
from search.report import rows


def fmt(v, digits: int = 2) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def run_table(search_main: Callable, search_args: list[str], default_out: str, header: list[str],
              row: Callable[[dict], list[str]], argv=None) -> int:
    """`argv` may hold --out RUN_DIR and any search flag (e.g. --profile paper, --seeds 3)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    out = argv[argv.index("--out") + 1] if "--out" in argv else default_out
    rest = [a for i, a in enumerate(argv) if a != "--out" and (i == 0 or argv[i - 1] != "--out")]
    search_main(search_args + ["--out", out] + rest)
    print("| " + " | ".join(header) + " |\n|" + "---|" * len(header))
    for r in rows(Journal(out).records()):
        print("| " + " | ".join(row(r)) + " |")
    return 0
