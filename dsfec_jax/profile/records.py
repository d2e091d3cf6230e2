"""One record per model: params, GFLOPs, memory and latency, with conventions and machine.

What differs by input modality comes from the caller's Modality record (its `stage_name`,
`latency_stages` and `size_fields`): `size_record(detector, modality)`, and `profile(detectors,
modality_of=...)` with the lookup of a config's record (modalities.registry.modality_of)."""

from __future__ import annotations

from typing import Any, Callable

import jax

from .. import zoo
from . import counting, latency, memory
from ..core import machine_load, progress
from ..core.environment import environment


def size_record(detector, modality, xla: bool = True) -> dict:
    """Everything but latency: params, analytic and XLA GFLOPs, memory (no timing loop), grouped in
    stages and completed with the fields of `modality` (the detector's Modality record).
    xla=False skips the compile behind the XLA columns (a search's light profile)."""
    # sizes read shapes only: tracing init (no compile) is enough, and XLA's columns lower on shapes
    variables = jax.eval_shape(detector.init, jax.random.key(0))
    inputs = detector.dummy_inputs(1)
    params = counting.count_params(variables, modality.stage_name)
    flops = counting.count_gflops(detector, stage_name=modality.stage_name)
    cfg = detector.config
    record = {
        "model": cfg.name,
        "family": zoo.family_of(cfg).name,
        "input": {k: list(v.shape) for k, v in inputs.items()},
        "params": params["total"],
        "params_per_stage": params["per_stage"],
        "params_convention": counting.PARAMS_CONVENTION,
        "gflops": round(flops["total"], 4),
        "gflops_per_stage": {k: round(v, 4) for k, v in flops["per_stage"].items()},
        "gflops_convention": counting.FLOPS_CONVENTION,
        "memory_mb": None if (mem := memory.paper_memory_mb(detector, variables)) is None else round(mem, 4),
        "memory_convention": memory.convention(detector),
        "notes": cfg.notes,
    }
    record.update(modality.size_fields(variables))
    if xla:
        compiled = counting.compile_network(detector, variables, inputs)
        xla_gflops = counting.xla_gflops(compiled)
        record.update(xla_gflops=round(xla_gflops, 4), xla_vs_analytic=round(xla_gflops / flops["total"] - 1, 4),
                      xla_peak_mb=round(memory.xla_peak_mb(compiled), 2))
    return record


def profile(detectors: list, timing: bool = True, repeats: int = 20, warmup: int = 3, light: bool = False, *,
            modality_of: Callable[[Any], Any], announce: bool = False) -> list[dict]:
    """Records for `detectors`; latencies come from one interleaved loop over all of them.
    `modality_of(config)` -> the config's Modality record (modalities.registry.modality_of).
    light=True: no XLA columns and only the whole network timed (one compile per model, not five).
    announce=True: say on stderr what it is doing (the profiler's command; a search's trials have
    their own progress)."""
    modalities = [modality_of(d.config) for d in detectors]
    with progress.stage(f"counting the sizes of {len(detectors)} model{'s' * (len(detectors) > 1)}"
                        + ("" if light else " (XLA compiles each)"), enabled=announce):
        records = [size_record(d, m, xla=not light) for d, m in zip(detectors, modalities)]
    env = environment()
    if timing:
        suites = {}
        for d, m in zip(detectors, modalities):
            variables = latency.timing_variables(d)
            stages = None if light else m.latency_stages
            suites[d.name] = latency.stage_functions(d, variables, d.dummy_inputs(1), stages)
        with machine_load.watch() as load, progress.stage(
                f"timing {len(detectors)} model{'s' * (len(detectors) > 1)}: {warmup} warm-up (compiles) and "
                f"{repeats} timed repeats, interleaved", enabled=announce):
            times = latency.time_interleaved(suites, repeats, warmup)
        machine_load.warn(load.verdict, "the latency timing")
        for rec, d in zip(records, detectors):
            t = times[rec["model"]]
            rec["latency_ms"] = round(t["total"]["median_ms"], 3)
            rec["latency_p10_ms"] = round(t["total"]["p10_ms"], 3)
            rec["latency_p90_ms"] = round(t["total"]["p90_ms"], 3)
            rec["latency_per_stage_ms"] = {s: round(v["median_ms"], 3) for s, v in t.items() if s != "total"}
            rec["latency_per_stage_p10_p90_ms"] = {s: [round(v["p10_ms"], 3), round(v["p90_ms"], 3)]
                                                   for s, v in t.items() if s != "total"}
            rec["machine_load"] = load.verdict
            rec["latency_setup"] = {"batch": 1, "repeats": repeats, "warmup": warmup, "interleaved": True,
                                    "depthwise_impl": getattr(d.config, "depthwise_impl", None), **env}
    else:
        for rec in records:
            rec["latency_ms"] = rec["latency_p10_ms"] = rec["latency_p90_ms"] = rec["machine_load"] = None
    return records


def detectors_for(names: list[str]) -> list:
    return [zoo.create(n) for n in names]

