"""One `dsfec edge` run for the kill test: edge.run's real loop and the real Uplink, over the cheap
frames and pipeline of edge_fakes (no JAX, no detector: it restarts in half a second).

    python edge_kill_child.py OUT URL FRAMES [--die-at K] [--work-s S]

--die-at K: the process SIGKILLs itself just before its K-th call of os.fsync, os.replace or
os.unlink, in any thread: the edges between the writes that make a frame durable (the queue
file's data, its rename, its folder; the log line; the removal of a delivered file).
Prints one line per frame done, and the summary at the end.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import signal
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from edge_fakes import CheapPipeline, cheap_frames  # noqa: E402

from dsfec_jax.edge.run import run_edge  # noqa: E402
from dsfec_jax.edge.uplink import Uplink  # noqa: E402


def die_at(k: int) -> None:
    calls = itertools.count(1)  # next() on a count is atomic: one numbering across threads

    def wrap(name):
        real = getattr(os, name)

        def call(*args, **kwargs):
            if next(calls) == k:
                os.kill(os.getpid(), signal.SIGKILL)
            return real(*args, **kwargs)
        setattr(os, name, call)

    for name in ("fsync", "replace", "unlink"):
        wrap(name)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("out")
    p.add_argument("url")
    p.add_argument("frames", type=int)
    p.add_argument("--die-at", type=int, default=None)
    p.add_argument("--work-s", type=float, default=0.0)
    a = p.parse_args()
    if a.die_at is not None:
        die_at(a.die_at)
    uplink = Uplink(a.url, Path(a.out) / "queue", timeout_s=2.0, backoff_s=0.02, max_backoff_s=0.1)
    summary = run_edge(cheap_frames(a.frames), CheapPipeline(work_s=a.work_s), a.out, uplink, flush_s=10.0,
                       progress=lambda n, batch: print(batch["frame"], flush=True))
    print(json.dumps(summary["uplink"]), flush=True)


if __name__ == "__main__":
    main()
