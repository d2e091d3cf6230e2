"""Peak memory of one model's device side, labelled with what it measures.

Where the device's allocator reports it (GPU, TPU), `memory_stats()['peak_bytes_in_use']`: JAX has
no public way to reset it, so it is the highest since the process started, and a model's figure
is its own only where it raised the peak (families run in the order given). Where it does not (the
CPU), the process's peak resident memory: on Linux its high-water mark is reset before the model
(writing 5 to /proc/self/clear_refs) and read after it (VmHWM), which still counts what earlier
models left resident; elsewhere getrusage's peak since the process started.
"""

from __future__ import annotations

import resource
import sys
from pathlib import Path

CLEAR_REFS = Path("/proc/self/clear_refs")
STATUS = Path("/proc/self/status")
RESET_PEAK_RSS = "5"  # clear_refs: reset the peak resident set size to the current one (Linux >= 4.0)
DEVICE_PEAK = "device memory_stats()['peak_bytes_in_use'] (the allocator's peak since the process started)"
RSS_SINCE_RESET = ("process peak RSS (VmHWM, reset before this model; counts what earlier models left "
                   "resident)")
RSS_SINCE_START = "process peak RSS since the process started (getrusage ru_maxrss)"


def device_peak_bytes(device) -> int | None:
    """The allocator's peak of `device`, None where the backend does not report one."""
    try:
        stats = device.memory_stats()
    except (NotImplementedError, RuntimeError):
        return None
    return None if not stats or "peak_bytes_in_use" not in stats else int(stats["peak_bytes_in_use"])


def reset_peak_rss() -> bool:
    """Reset the process's peak resident memory to its current value; False where that is not possible."""
    try:
        CLEAR_REFS.write_text(RESET_PEAK_RSS)
        return True
    except OSError:
        return False


def vmhwm_bytes() -> int | None:
    """The process's peak resident memory (VmHWM) in bytes, None where /proc does not give it."""
    try:
        for line in STATUS.read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def rusage_peak_bytes() -> int:
    """getrusage's peak resident memory (kilobytes on Linux, bytes on macOS)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak if sys.platform == "darwin" else peak * 1024)


class Probe:
    """Started before a model's device side ran; `peak()` after -> {'bytes', 'source'}."""

    def __init__(self, device):
        self.device = device
        self.by_device = device_peak_bytes(device) is not None
        self.reset = not self.by_device and reset_peak_rss() and vmhwm_bytes() is not None

    def peak(self) -> dict:
        if self.by_device:
            return {"bytes": device_peak_bytes(self.device), "source": DEVICE_PEAK}
        if self.reset:
            return {"bytes": vmhwm_bytes(), "source": RSS_SINCE_RESET}
        return {"bytes": rusage_peak_bytes(), "source": RSS_SINCE_START}
