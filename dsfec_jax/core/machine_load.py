"""Was the machine busy while something was timed? A verdict with its reasons, for every latency a
command reports.

A timing on a shared box can be several-fold the machine's (issue 51), and nothing in the figure
says so. `watch()` samples the machine before and after a
measurement and `verdict` compares the two:

- the 1-minute load average against the machine's CPU count (more runnable threads than CPUs:
  someone waited for a CPU);
- the CPU time this process got against the wall time that passed (a CPU-bound timing loop that
  got much less than one CPU per wall second was descheduled);
- the CPU time the other processes used (machine-wide busy time from /proc/stat minus this
  process's): when the machine was full and others took part of it, the timing shared the CPUs;
- steal time from /proc/stat (a virtual machine whose host gave its CPUs to another guest).

/proc/stat exists on Linux only; elsewhere the last two are skipped (the verdict names what it
could not check). Nothing here runs at import.

    with machine_load.watch() as load:
        samples = time_chains(...)
    record["machine"] = load.verdict
    machine_load.warn(load.verdict, "the bench's timing")
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import sys
import time
from pathlib import Path
from typing import Iterator, TextIO

PROC_STAT = Path("/proc/stat")
# thresholds of the verdict (why each value: see the module docstring)
LOAD_PER_CPU = 1.0  # 1-minute load above the CPU count: more runnable threads than CPUs
MIN_CPU_SHARE = 0.75  # a CPU-bound timing loop that got under 3/4 of a CPU per wall second was descheduled
FULL_MACHINE = 0.9  # the machine counts as full when 90 % of its CPU time was used...
MIN_OTHERS_CPUS = 0.25  # ...and other processes used at least a quarter of a CPU of it
MAX_STEAL = 0.10  # more than 10 % of the CPU time stolen by the hypervisor


@dataclasses.dataclass(frozen=True)
class Sample:
    """The machine at one instant: monotonic wall clock, this process's CPU time (all threads),
    the 1-minute load average, the CPU count, and /proc/stat's aggregate (busy, steal, total)
    jiffies (None where there is no /proc/stat)."""
    wall_s: float
    process_cpu_s: float
    load1: float | None
    cpus: int
    jiffies: tuple[int, int, int] | None = None


def cpu_count() -> int:
    """The machine's CPUs (the load average and /proc/stat count all of them, whatever this
    process's affinity)."""
    return os.cpu_count() or 1


def affinity() -> int:
    """The CPUs this process may run on (a bench worker is pinned to its thread count)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # macOS, Windows
        return cpu_count()


def read_jiffies(path: Path = PROC_STAT) -> tuple[int, int, int] | None:
    """(busy, steal, total) jiffies of /proc/stat's aggregate 'cpu' line; None without it."""
    try:
        first = path.read_text().splitlines()[0].split()
    except (OSError, IndexError):
        return None
    if not first or first[0] != "cpu":
        return None
    # user nice system idle iowait irq softirq steal [guest guest_nice: already in user and nice]
    fields = [int(x) for x in first[1:9]] + [0] * max(0, 9 - len(first))
    idle, iowait, steal = fields[3], fields[4], fields[7]
    total = sum(fields[:8])
    return total - idle - iowait - steal, steal, total


def sample() -> Sample:
    try:
        load1 = os.getloadavg()[0]
    except (AttributeError, OSError):  # Windows
        load1 = None
    return Sample(time.monotonic(), time.process_time(), load1, cpu_count(), read_jiffies())


def ticks_per_second() -> int:
    try:
        return os.sysconf("SC_CLK_TCK")
    except (AttributeError, ValueError, OSError):
        return 100


def verdict(before: Sample, after: Sample, hz: int | None = None) -> dict:
    """{'busy', 'reasons', 'text', and the figures behind them} for the span between two samples.
    `hz`: /proc/stat's jiffies per second (the system's when None)."""
    wall = max(after.wall_s - before.wall_s, 1e-9)
    cpus = after.cpus
    own = (after.process_cpu_s - before.process_cpu_s) / wall  # CPUs this process used on average
    out = {"wall_s": round(wall, 3), "cpus": cpus, "affinity": affinity(), "process_cpus": round(own, 3)}
    reasons, figures = [], []
    loads = [x for x in (before.load1, after.load1) if x is not None]
    if loads:
        out["load1"] = round(max(loads), 2)  # the average lags: the larger of the two ends
        figures.append(f"load {out['load1']:.1f} on {cpus} CPU{'s' * (cpus > 1)}")
        if out["load1"] > LOAD_PER_CPU * cpus:
            reasons.append(figures[-1])
    if own < MIN_CPU_SHARE:
        reasons.append(f"the timing process got {100 * own:.0f} % of a CPU")
    if before.jiffies and after.jiffies:
        busy, steal, total = (a - b for a, b in zip(after.jiffies, before.jiffies))
        if total > 0:
            seconds = total / (hz or ticks_per_second()) / cpus  # wall time the jiffies cover
            out["steal_percent"] = round(100 * steal / total, 1)
            others = max(0.0, (busy / (hz or ticks_per_second()) - own * wall)) / max(seconds, 1e-9)
            out["others_cpus"] = round(others, 2)
            figures.append(f"other processes used {others:.1f} CPUs")
            if (busy + steal) / total >= FULL_MACHINE and others >= MIN_OTHERS_CPUS:
                reasons.append(f"the CPUs were full and other processes used {others:.1f} of them")
            if steal / total > MAX_STEAL:
                reasons.append(f"{out['steal_percent']:.0f} % steal")
    else:
        out["unchecked"] = "steal and other processes' CPU time (no /proc/stat)"
    out["busy"] = bool(reasons)
    out["reasons"] = reasons
    out["text"] = ("busy: " + "; ".join(reasons)) if reasons else "idle: " + "; ".join(figures or ["no load figures"])
    return out


class Watch:
    """What `watch()` yields: its `verdict` is set when the block ends."""
    verdict: dict | None = None


@contextlib.contextmanager
def watch() -> Iterator[Watch]:
    """Sample the machine around the block; `.verdict` (see `verdict`) once it ends."""
    w, before = Watch(), sample()
    try:
        yield w
    finally:
        w.verdict = verdict(before, sample())


def warn(v: dict | None, what: str, stream: TextIO | None = None) -> None:
    """Print a warning to stderr when `v` (a verdict) says the machine was busy during `what`."""
    if v and v.get("busy"):
        out = stream or sys.stderr
        out.write(f"warning: the machine was busy during {what} ({v['text'][len('busy: '):]}): "
                  "these timings are not the machine's; rerun on an idle machine to quote them\n")
        out.flush()


def note(v: dict | None) -> str:
    """A short mark for a table cell or footer: '' when idle or unknown, else 'busy: ...'."""
    return v["text"] if v and v.get("busy") else ""
