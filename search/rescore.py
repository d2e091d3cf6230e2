"""Add per-frame match tables to the finished trials of a journal that lack them, then rewrite its reports:

    python -m search.rescore RUN_DIR [--labels A,B]

A journal written before its family's protocol kept match tables (the range-Doppler tables before
they resampled their headline) has no bootstrap intervals. Each such trial's run resumes at its last
step, so nothing trains, validates its final weights with the match tables on, and the record gains
its "matches" only if the recomputed headline equals the recorded one. Every record is written back
on its own (atomically), so a killed rescore resumes where it stopped.
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that runs XLA: its process settings before anything loads JAX
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import sys

from dsfec_jax import zoo

from .journal import Journal
from .report import write_reports
from .trial import match_classes, rescore


def pending(records: list[dict], labels: set[str] | None) -> list[dict]:
    """Finished train trials of a protocol with match tables whose record has none."""
    return [r for r in records if r.get("status") == "ok" and not r.get("matches")
            and r.get("strategy", "train") == "train" and match_classes(zoo.family_of(r["base"]))
            and (labels is None or r["label"] in labels)]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m search.rescore", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run_dir")
    p.add_argument("--labels", help="comma-separated trial labels (default: every trial without match tables)")
    args = p.parse_args(sys.argv[1:] if argv is None else argv)
    journal = Journal(args.run_dir)
    todo = pending(journal.records(), set(args.labels.split(",")) if args.labels else None)
    print(f"{len(todo)} trial(s) to rescore in {args.run_dir}")
    for n, record in enumerate(todo, 1):
        matches = rescore(record, args.run_dir)
        journal.update({**record, "matches": matches})
        print(f"[{n}/{len(todo)}] {record['label']} ({record['key']}): match tables for {len(matches)} class(es)")
    if journal.records():
        write_reports(args.run_dir)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
