"""Say what a long wait is doing: a line when a stage starts, a heartbeat while it runs, its time
when it ends.

A stage is anything that can keep a command quiet for more than a few seconds without a progress
bar of its own: compiling a step, generating a benchmark, warming up a benchmark. The heartbeat
runs on a daemon thread, so the stage's own code needs no hooks; it writes to stderr, so a
command's stdout (JSON, tables) stays machine-readable.

    with stage("compiling the training step", usual="60-130 s on 2 CPU cores"):
        state, metrics = step_fn(state, batch)

`DSFEC_QUIET=1` silences every stage (tests that parse stderr, scripted runs).
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
from typing import Iterator, TextIO

HEARTBEAT_S = 10.0  # a command is never quiet for longer than this while a stage runs


def quiet() -> bool:
    return os.environ.get("DSFEC_QUIET", "") not in ("", "0")


def _say(text: str, stream: TextIO | None) -> None:
    out = stream or sys.stderr
    out.write(text + "\n")
    out.flush()


@contextlib.contextmanager
def stage(what: str, usual: str | None = None, *, heartbeat_s: float = HEARTBEAT_S,
          stream: TextIO | None = None, enabled: bool = True) -> Iterator[None]:
    """Announce `what` (and how long it usually takes), repeat '... still <what> (N s)' every
    `heartbeat_s` seconds until the block ends, then say how long it took."""
    if not enabled or quiet():
        yield
        return
    _say(f"{what}..." + (f" (usually {usual})" if usual else ""), stream)
    done = threading.Event()
    t0 = time.perf_counter()

    def beat() -> None:
        while not done.wait(heartbeat_s):
            _say(f"... still {what} ({time.perf_counter() - t0:.0f} s)", stream)

    thread = threading.Thread(target=beat, name=f"progress: {what}", daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()
        _say(f"{what}: done in {time.perf_counter() - t0:.1f} s", stream)
