"""What a measurement ran on: CPU, threads, software versions."""

from __future__ import annotations

import os
import platform
import re
from importlib import metadata


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def xla_thread_flags(threads: int) -> str:
    """XLA_FLAGS with the CPU backend limited to `threads` intra-op threads (read at start-up)."""
    flag = "--xla_cpu_multi_thread_eigen=false" if threads == 1 else f"intra_op_parallelism_threads={threads}"
    return (os.environ.get("XLA_FLAGS", "") + " " + flag).strip()


def xla_threads() -> int:
    """Intra-op threads XLA's CPU backend uses (1 when multi-threaded Eigen is switched off)."""
    flags = os.environ.get("XLA_FLAGS", "")
    if "--xla_cpu_multi_thread_eigen=false" in flags:
        return 1
    m = re.search(r"intra_op_parallelism_threads=(\d+)", flags)
    return int(m.group(1)) if m else (os.cpu_count() or 1)


def versions(packages=("jax", "jaxlib", "flax", "numpy", "optax", "dsfec_jax")) -> dict:
    out = {"python": platform.python_version()}
    for name in packages:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def environment() -> dict:
    return {"cpu": cpu_model(), "cores": os.cpu_count(), "threads": xla_threads(), "versions": versions()}
