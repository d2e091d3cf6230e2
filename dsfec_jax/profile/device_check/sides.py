"""One model run on one device ("a side"): its programs compiled ahead for that device (the
kernel choices their layers made while traced are collected), the compared training steps from
the shared first state, the inference on that state, then the timed steps and calls.

The inputs are committed to the side's device (`place`), so every program runs there whatever the
default device; the compared figures come back as host numpy arrays.
"""

from __future__ import annotations

import dataclasses
import time

import jax
import numpy as np

from ...layers import kernels as kernel_choice
from . import peak_memory
from .workload import Workload


@dataclasses.dataclass(frozen=True)
class Timing:
    """How many steps and calls the device side times after the compared ones."""

    steps: int = 5
    calls: int = 5


@dataclasses.dataclass
class SideResult:
    """What one side computed and measured. `losses`: each compared step's loss; `outputs`: the
    inference's leaves (host arrays, flattened in tree order); `decisions`: the hand_written
    choices made while its programs were traced."""

    platform: str
    device_kind: str
    kernels: str | None
    losses: list[float]
    outputs: list[np.ndarray]
    decisions: list[kernel_choice.Decision]
    compile_s: float
    steps_per_s: float | None = None
    infer_ms: float | None = None
    memory: dict | None = None


def platform_of(device) -> str:
    """The backend a device belongs to ('cpu', 'gpu', 'tpu'): what the kernels rule compares with
    MEASURED_ON (jax reports CUDA and ROCm devices as 'gpu')."""
    return device.platform


def place(tree, device):
    """`tree` committed to `device` (a program then runs there)."""
    return jax.device_put(tree, device)


def compile_programs(workload: Workload, device, kernels: str | None, state, batch):
    """(compiled step, compiled inference, seconds, decisions) of `workload` for `device`."""
    programs = workload.build(kernels)
    start = time.perf_counter()
    with kernel_choice.observed_decisions() as decisions:
        step = programs.step.lower(state, batch).compile()
        infer = programs.infer.lower(state, batch["inputs"]).compile()
    return step, infer, time.perf_counter() - start, list(decisions)


def run_side(workload: Workload, device, kernels: str | None, steps: int, timing: Timing | None,
             compiled: tuple | None = None) -> tuple[SideResult, tuple]:
    """`steps` compared training steps and one inference of `workload` on `device`; with `timing`,
    then the timed steps and inference calls, and the peak memory while all of it ran. `compiled`:
    compile_programs' result to reuse (the same programs on the same device). -> (the result,
    compile_programs' result)."""
    memory_probe = peak_memory.Probe(device) if timing else None
    state = place(workload.initial_state, device)
    batches = [place(b, device) for b in workload.batches]
    compiled = compiled or compile_programs(workload, device, kernels, state, batches[0])
    step, infer, compile_s, decisions = compiled
    outputs = [np.asarray(x) for x in jax.tree.leaves(jax.device_get(infer(state, batches[0]["inputs"])))]
    losses = []
    for k in range(steps):
        state, metrics = step(state, batches[k % len(batches)])
        losses.append(float(metrics["loss"]))
    result = SideResult(platform_of(device), device.device_kind, kernels, losses, outputs, decisions, compile_s)
    if timing:
        result.infer_ms = timed_calls(infer, state, batches[0]["inputs"], timing.calls)
        result.steps_per_s = timed_steps(step, state, batches, timing.steps)  # last: the step donates `state`
        result.memory = memory_probe.peak()
    return result, compiled


def timed_steps(step, state, batches: list, count: int) -> float:
    """Training steps per second over `count` steps (already compiled) run back to back."""
    start = time.perf_counter()
    for k in range(count):
        state, metrics = step(state, batches[k % len(batches)])
    jax.block_until_ready((state, metrics))
    return count / (time.perf_counter() - start)


def timed_calls(infer, state, inputs, count: int) -> float:
    """The median milliseconds of `count` blocking inference calls (already compiled)."""
    samples = []
    for _ in range(count):
        start = time.perf_counter()
        jax.block_until_ready(infer(state, inputs))
        samples.append(1e3 * (time.perf_counter() - start))
    return float(np.median(samples))
