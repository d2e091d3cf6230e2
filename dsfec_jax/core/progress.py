"""Say what a long wait is doing: a line when a stage starts, a heartbeat while it runs, its time
when it ends.

A stage is anything that can keep a command quiet for more than a few seconds without a progress
bar of its own: compiling a step, generating a benchmark, warming up a benchmark. The heartbeat
runs on a daemon thread, so the stage's own code needs no hooks; it writes to stderr, so a
command's stdout (JSON, tables) stays machine-readable.

    with stage("compiling the training step", usual="60-130 s on 2 CPU cores"):
        state, metrics = step_fn(state, batch)

A loop of known length gets a bar instead (`bar`, tqdm on stderr), whose first item may run
inside a stage: the item that compiles.

    for start in bar(range(0, n, 8), "detecting", first="compiling the predictor"):
        ...

A command runs `watched`: whatever it does between the lines above (importing JAX, loading weights
and folding them, writing its outputs, a bar item slower than the heartbeat on a busy machine),
once stderr has been quiet for a heartbeat the watchdog says what the command is doing, from the
innermost `doing` phase (stages and bars are phases too).

    with watched("dsfec eval"), doing("loading the model"):
        ...

`DSFEC_QUIET=1` silences every stage and bar (tests that parse stderr, scripted runs).
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
from typing import Iterable, Iterator, TextIO

from tqdm import tqdm

HEARTBEAT_S = 8.0  # under the 10 s a command may stay quiet, with room for a busy scheduler
GENERATION_DELAY_S = 2.0  # a generated data set quicker than this needs no bar
# a predictor's first batch: the wait before its bar moves (an ONNX Runtime session has no compile)
FIRST_BATCH = "running the first batch (a JAX predictor compiles its network on it)"


_PHASES: list[str] = []  # what the running command is doing, innermost last (the main thread's)


def quiet() -> bool:
    return os.environ.get("DSFEC_QUIET", "") not in ("", "0")


def _say(text: str, stream: TextIO | None) -> None:
    out = stream or sys.stderr
    # tqdm.write lifts any progress bar drawn on `out`, prints the line and redraws the bar: a
    # heartbeat during a training bar's first (compiling) step lands on a line of its own
    tqdm.write(text, file=out)
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
    t0 = time.perf_counter()

    def beat() -> None:
        _say(f"... still {what} ({time.perf_counter() - t0:.0f} s)", stream)

    try:
        with doing(what), _every(heartbeat_s, beat, f"progress: {what}"):
            yield
    finally:
        _say(f"{what}: done in {time.perf_counter() - t0:.1f} s", stream)


def bar(items: Iterable, desc: str, *, first: str | None = None, usual: str | None = None, enabled: bool = True,
        **options) -> Iterator:
    """`items` through a tqdm bar on stderr (`options` go to tqdm: total, unit, leave, ...); with
    `first`, the caller's work on the first item runs inside stage(first, usual): a bar stands
    still while its first item compiles, so that wait says what it is doing."""
    with doing(desc):
        for i, item in enumerate(tqdm(items, desc=desc, disable=not enabled or quiet(), **options)):
            with stage(first or "", usual, enabled=enabled and first is not None and i == 0):
                yield item  # the stage stays open until the caller asks for the second item


def generating(items: Iterable, desc: str, **options) -> Iterator:
    """A bar over data generated item by item (a synthetic benchmark): drawn only once the
    generation has taken GENERATION_DELAY_S (the tiny sets of tests and scorers stay quiet) and
    cleared when it ends."""
    return bar(items, desc, delay=GENERATION_DELAY_S, leave=False, **options)


@contextlib.contextmanager
def doing(what: str) -> Iterator[None]:
    """Name what the command does inside this block, for the watchdog's line; prints nothing."""
    _PHASES.append(what)
    try:
        yield
    finally:
        _leave(what)


def _leave(what: str) -> None:
    """Drop the innermost `what` (a bar left early is closed whenever its generator is collected,
    so its phase need not be the innermost one by then)."""
    for i in range(len(_PHASES) - 1, -1, -1):
        if _PHASES[i] == what:
            del _PHASES[i]
            return


class _Timed:
    """A text stream that remembers when it was last written to (tqdm's bars included)."""

    def __init__(self, stream: TextIO):
        self.stream = stream
        self.last = time.monotonic()

    def write(self, text: str) -> int:
        self.last = time.monotonic()
        return self.stream.write(text)

    def __getattr__(self, name: str):
        return getattr(self.stream, name)


@contextlib.contextmanager
def watched(command: str, *, heartbeat_s: float = HEARTBEAT_S, poll_s: float = 0.5,
            enabled: bool = True) -> Iterator[None]:
    """Run a command under the silence watchdog: when stderr has been quiet for `heartbeat_s`,
    say '... <command>: still <innermost phase> (N s in)', so that no wait goes unexplained."""
    if not enabled or quiet():
        yield
        return
    timed = _Timed(sys.stderr)
    sys.stderr = timed
    t0 = time.monotonic()

    def watch() -> None:
        if time.monotonic() - timed.last >= heartbeat_s:
            phases = list(_PHASES)
            what = phases[-1] if phases else "starting (importing JAX and the project)"
            _say(f"... {command}: still {what} ({time.monotonic() - t0:.0f} s in)", timed)

    try:
        with _every(poll_s, watch, f"watchdog: {command}"):
            yield
    finally:
        sys.stderr = timed.stream


@contextlib.contextmanager
def _every(interval_s: float, fn, name: str) -> Iterator[None]:
    """Call fn every `interval_s` on a daemon thread while the block runs."""
    done = threading.Event()

    def loop() -> None:
        while not done.wait(interval_s):
            fn()

    thread = threading.Thread(target=loop, name=name, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()
