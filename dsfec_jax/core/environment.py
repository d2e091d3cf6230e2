"""What a measurement ran on: CPU, threads, software versions."""

from __future__ import annotations

import os
import platform

from .provenance import versions
from . import host_memory, threads


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def xla_threads() -> int:
    """Threads XLA's CPU backend computes on: its Eigen pool once started (observed), else the
    CPUs the process may use, which is what XLA sizes that pool from (see threads.py)."""
    return threads.eigen_threads() or len(threads.available_cpus())


def environment() -> dict:
    return {"cpu": cpu_model(), "cores": os.cpu_count(), "threads": xla_threads(),
            "cpu_affinity": threads.available_cpus(), "glibc_hugetlb": host_memory.active(),
            "keeps_xla_buffers": host_memory.keeps_buffers(), "versions": versions()}
