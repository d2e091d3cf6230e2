"""One model through the device check: its device side (compared steps and inference, then the
timed ones and the peak memory), its reference side on the CPU with the textbook kernels, and
the verdict."""

from __future__ import annotations

from .report import model_record
from .sides import Timing, run_side
from .verdict import Tolerance, judge
from .workload import Workload, kernels_override

REFERENCE_KERNELS = "plain"  # the textbook formulations: what every fast form is held equal to


def check_model(workload: Workload, device, reference, steps: int, tolerance: Tolerance,
                timed_steps: int = 5, repeats: int = 5) -> dict:
    """The record of `workload` on `device` against `reference` (a CPU device). Where the two sides
    would run the same programs on the same device (a CPU-only host, a model without `kernels`),
    the reference reuses the device side's compiled programs."""
    device_side, compiled = run_side(workload, device, None, steps, Timing(timed_steps, repeats))
    kernels = kernels_override(workload, REFERENCE_KERNELS)
    same = reference == device and kernels is None
    reference_side, _ = run_side(workload, reference, kernels, steps, None, compiled if same else None)
    return model_record(workload, device_side, reference_side, judge(device_side, reference_side, tolerance))
