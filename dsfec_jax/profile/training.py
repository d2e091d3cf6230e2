"""Training throughput of zoo models (`dsfec bench --train`): frames/s of the whole jitted train
step, with its parts (eval forward, train-mode forward, fwd + bwd), compile times kept apart,
achieved GFLOP/s against an sgemm peak measured in the same process, and where a step's time goes.

The batches are real training batches, made as training makes them, by the model's modality
(`Modality.train_bench_batches`, which the caller's record supplies: modalities/points/train_bench.py
pillarizes augmented frames of the family's benchmark for a training window of `window` cells,
modalities/rd/train_bench.py makes whole RD maps, modalities/image/train_bench.py letterboxed street
images at `Settings.image_size` on the long side); the point settings (window, pillar slots) apply
to the point models alone, so one `--models` list may hold every kind. A few batches are built
before any timing, so host work is not in the device figures.

Each timed program is compiled ahead (`jax.jit(f).lower(...).compile()`, timed: the compile
time), then every program of every config, and the two sgemm references (XLA's and numpy's
2048^2 float32 matmul), is called once per repetition in one interleaved loop, so box noise hits
all of them alike; the figures are medians after warm-up. The machine peak is the references
called back to back after that loop: between the models' programs they run slower
(docs/profiler.md), which would understate the peak and overstate every '% of peak'. Then a few
steps are traced with the XLA profiler and their time split by module, phase and op
(op_breakdown.py).
`run` measures each (model, thread count) in a fresh worker process (`python -m
dsfec_jax.profile --train-worker`, whose entry point looks the model's modality up) pinned to that many CPUs
before XLA starts (core/threads.py; as deploy/bench/workers.py does), so models do not disturb
each other and the thread count is XLA's pool size.

`--compare FIELD=VALUE` measures a second config of each model (the default with those fields
overridden) in the same interleaved loop, and reports compare / default time ratios: a
formulation switch measured before against after in one run.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import json
import os
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

from .. import zoo
from ..core import atomic, host_memory, machine_load, progress, spread
from ..core.child_process import run_passing_stderr
from ..core import threads as thread_control
from ..core.defaults import RUN_PILLARS
from . import counting, op_breakdown

PROGRAMS = ("eval_forward", "train_forward", "fwd_bwd", "step")
SGEMM_N = 2048
# the family's `quick` schedule: its optimizer is what matters here (the rates do not change the step's
# time): clip + AdamW for the point families, ultralytics' SGD with accumulation for the RD family
STEP_SCHEDULE = "quick"
RECORD = Path(__file__).parent / "records" / "train_bench.json"
README_START, README_END = "<!-- train-bench:start -->", "<!-- train-bench:end -->"

FLOPS_CONVENTION = (
    "forward GFLOPs: the profiler's analytic count (profile/counting.py: 2 x MACs of conv/deconv/linear layers, "
    "MobileOne blocks in their fused form, pillar net on all slots) of one batch; train GFLOPs = 3 x forward "
    "(the backward costs about twice the forward: one product for the input gradient, one for the weight "
    "gradient; Kaplan et al. 2020, arXiv:2001.08361, sec. 2.1); XLA GFLOPs: compiled.cost_analysis() of each "
    "program (includes elementwise work, the loss and the optimizer)")
PEAK_CONVENTION = (f"the faster of two {SGEMM_N} x {SGEMM_N} float32 matmuls (2 n^3 FLOPs), XLA's (jitted) and "
                   "numpy's BLAS, each called back to back after the interleaved loop, in the same process and "
                   "thread count (the record also keeps their times inside the loop, where they run slower)")


BUDGET_FRAMES = 400  # train frames the pillar budget is sized on: the quick search recipe's count
IMAGE_SIZE = 416  # camera models: the long side of the letterboxed training images (the paper's input)


@dataclasses.dataclass(frozen=True)
class Settings:
    """What is measured: `batch` frames per step on `window`-cell training windows (None: the
    whole grid) with at most `max_pillars` slots (sized to the data as training does unless
    `size_pillars` is False; these four fields are the point families', range-Doppler models
    train on whole maps); camera models train on images letterboxed to `image_size` on their long
    side; `repeats` timed repetitions after `warmup`; the timed
    calls cycle through `distinct_batches` pre-built batches; `profile_steps` steps are traced
    for the breakdown (none when `breakdown` is False)."""

    batch: int = 8
    window: int | None = 96
    max_pillars: int = RUN_PILLARS
    repeats: int = 10
    warmup: int = 2
    seed: int = 0
    distinct_batches: int = 4
    breakdown: bool = True
    profile_steps: int = 3
    lead_in: int = 1  # untimed calls of a program right before each timed one (time_interleaved)
    size_pillars: bool = True  # slots sized to the data as modalities/points/fit.py does; False: max_pillars slots
    budget_frames: int = BUDGET_FRAMES  # train frames the slots are sized on
    image_size: int = IMAGE_SIZE  # camera models: the letterbox's long side (a multiple of 32)

    def __post_init__(self):
        for field, low in (("batch", 1), ("max_pillars", 1), ("repeats", 1), ("warmup", 0), ("budget_frames", 1),
                           ("distinct_batches", 1), ("profile_steps", 1), ("lead_in", 0)):
            value = getattr(self, field)
            if not isinstance(value, int) or value < low:
                raise ValueError(f"train bench: {field}={value!r}; expected an integer >= {low}")
        if self.window is not None and (not isinstance(self.window, int) or self.window < 1):
            raise ValueError(f"train bench: window={self.window!r}; expected cells >= 1, or None for the whole grid")
        if not isinstance(self.image_size, int) or self.image_size < 32 or self.image_size % 32:
            raise ValueError(f"train bench: image_size={self.image_size!r}; expected a positive multiple of 32")


# ---- inputs -------------------------------------------------------------------------------------

def model_overrides(name: str, settings: Settings, modality) -> dict:
    """The config fields the settings set on model `name` (its Modality record's
    `train_bench_fields`: a point model's pillar slots, a camera model's benchmark classes)."""
    return modality.train_bench_fields(name, settings)


# ---- programs -----------------------------------------------------------------------------------

def compile_timed(jitted, *args) -> tuple[Any, float]:
    """(the compiled program, seconds to lower and compile it)."""
    start = time.perf_counter()
    compiled = jitted.lower(*args).compile()
    return compiled, time.perf_counter() - start


def xla_gflops(compiled) -> float | None:
    """XLA's FLOP count of a compiled program, or None where the backend gives none."""
    try:
        value = counting.xla_gflops(compiled)
    except (KeyError, TypeError, IndexError, AttributeError, NotImplementedError):
        return None
    return value if np.isfinite(value) and value > 0 else None


@dataclasses.dataclass
class Workload:
    """One config of one model: its compiled programs and the arguments they run on. The step
    donates its state, so it threads its own state and the other programs keep a copy."""

    label: str
    overrides: dict
    detector: zoo.Detector
    windows: int
    batches: list[dict]
    variables: dict
    state: dict
    compiled: dict[str, Any]
    compile_s: dict[str, float]

    def run(self, program: str, rep: int) -> None:
        """One call of `program` on batch `rep` (cycled), blocking until its results are ready."""
        batch = self.batches[rep % len(self.batches)]
        fn = self.compiled[program]
        if program == "eval_forward":
            out = fn(self.variables, batch["inputs"])
        elif program == "step":
            self.state, out = fn(self.state, batch)
        else:
            out = fn(self.variables["params"], self.variables["batch_stats"], batch)
        jax.block_until_ready(out)


def build_workload(name: str, label: str, overrides: dict, settings: Settings, modality) -> Workload:
    """Batches (`modality.train_bench_batches`, made as training makes them), fresh state and the
    four compiled programs of `name` with `overrides`."""
    from ..train.schedules import get_schedule, optimizer
    from ..train.step import init_state, loss_function, make_train_step

    overrides = {**model_overrides(name, settings, modality), **overrides}
    det, batches, windows = modality.train_bench_batches(name, overrides, settings)
    schedule = zoo.family_of(name).schedules[STEP_SCHEDULE]
    tx = optimizer(get_schedule(schedule, batch_size=settings.batch), 1000)
    state = init_state(det, tx, jax.random.key(settings.seed))
    variables = jax.tree.map(jnp.copy, {"params": state["params"], "batch_stats": state["batch_stats"]})
    loss_fn = loss_function(det)  # train/step.py's, the function the step differentiates
    batch = batches[0]
    params, stats = variables["params"], variables["batch_stats"]
    jitted = {
        "eval_forward": (jax.jit(lambda v, x: det.apply(v, x, train=False)), (variables, batch["inputs"])),
        "train_forward": (jax.jit(lambda p, s, b: loss_fn(p, s, b)[0]), (params, stats, batch)),
        "fwd_bwd": (jax.jit(jax.value_and_grad(loss_fn, has_aux=True)), (params, stats, batch)),
        "step": (make_train_step(det, tx), (state, batch)),
    }
    compiled, seconds = {}, {}
    for program, (fn, args) in jitted.items():
        compiled[program], seconds[program] = compile_timed(fn, *args)
    return Workload(label, overrides, det, windows, batches, variables, state, compiled, seconds)


def sgemms(n: int = SGEMM_N) -> dict[str, Callable[[], None]]:
    """Blocking calls of an n x n float32 matmul, jitted by XLA and by numpy's BLAS (the issue
    quotes numpy's): the machine-peak references."""
    a = jax.random.normal(jax.random.key(1), (n, n), jnp.float32)
    b = jax.random.normal(jax.random.key(2), (n, n), jnp.float32)
    compiled = jax.jit(jnp.matmul).lower(a, b).compile()
    a_np, b_np = np.asarray(a), np.asarray(b)
    return {"xla": lambda: jax.block_until_ready(compiled(a, b)), "numpy": lambda: np.matmul(a_np, b_np)}


# ---- timing -------------------------------------------------------------------------------------

def time_interleaved(workloads: list[Workload], references: dict[str, Callable[[], None]], settings: Settings) -> dict:
    """Per repetition: each program of each workload, then each reference, each timed in steady
    state: `lead_in` untimed calls of the same program right before its timed call. -> {label:
    {program: [ms]}, 'sgemm': {reference: [ms]}} after `warmup` repetitions.

    Why the lead-in: a call right after another program pays for that program's buffers (XLA
    frees its temporary buffer after each call and the next one maps and first-touches its own):
    a DSFEC-L eval forward read far slower right after the other config's train step than after
    itself (docs/profiler.md, "The bench"). A training loop runs steps back to back and an
    inference loop forwards back to back, so each program is timed after itself;
    repetitions still alternate the configs, so load drifts hit both alike."""
    samples: dict = {w.label: {p: [] for p in PROGRAMS} for w in workloads}
    samples["sgemm"] = {k: [] for k in references}

    def timed(call: Callable[[], None]) -> float:
        for _ in range(settings.lead_in):
            call()
        start = time.perf_counter()
        call()
        return 1e3 * (time.perf_counter() - start)

    for rep in range(settings.warmup + settings.repeats):
        keep = rep >= settings.warmup
        for w in workloads:
            for program in PROGRAMS:
                ms = timed(functools.partial(w.run, program, rep))
                if keep:
                    samples[w.label][program].append(ms)
        for reference, call in references.items():
            ms = timed(call)
            if keep:
                samples["sgemm"][reference].append(ms)
    return samples


def time_alone(references: dict[str, Callable[[], None]], settings: Settings) -> dict:
    """{reference: [ms]}: each reference called back to back, `warmup` calls then `repeats` timed.
    The machine's peak is this: the same matmul called between the models' programs runs slower
    (docs/profiler.md, "The bench's sgemm peak")."""
    samples = {}
    for reference, call in references.items():
        for _ in range(settings.warmup):
            call()
        samples[reference] = []
        for _ in range(settings.repeats):
            start = time.perf_counter()
            call()
            samples[reference].append(1e3 * (time.perf_counter() - start))
    return samples


def sgemm_rates(samples: dict) -> dict:
    """{reference: GFLOP/s} of the median of each reference's times."""
    return {k: _significant(2 * SGEMM_N**3 / 1e9 / (float(np.median(ms)) / 1e3)) for k, ms in samples.items()}


def summary(ms: list[float]) -> dict:
    return {**spread.percentiles(ms), "n": len(ms)}


def analytic_forward_gflops(detector, inputs: dict) -> float:
    """The profiler's analytic forward count (2 x MACs) of one batch of `inputs`."""
    return sum(2 * macs for _, _, macs in counting.layer_macs(detector, inputs=inputs)) / 1e9


def figures(w: Workload, samples: dict, peak_gflop_per_s: float, batch: int) -> dict:
    """Every figure of one workload from its timing samples."""
    median = {p: float(np.median(samples[p])) for p in PROGRAMS}
    forward = analytic_forward_gflops(w.detector, w.batches[0]["inputs"])
    analytic = {"eval_forward": forward, "train_forward": forward, "fwd_bwd": 3 * forward, "step": 3 * forward}
    xla = {p: xla_gflops(w.compiled[p]) for p in PROGRAMS}

    def rate(gflops: dict) -> dict:
        return {p: None if gflops[p] is None else _significant(gflops[p] / (median[p] / 1e3)) for p in PROGRAMS}

    rates = {"analytic": rate(analytic), "xla": rate(xla)}
    slots = getattr(w.detector.config, "max_pillars", None)  # point models only
    return {
        "label": w.label, "overrides": _jsonable(w.overrides),
        "input": {k: list(v.shape) for k, v in w.batches[0]["inputs"].items()},
        **({} if slots is None else {"pillar_slots": int(slots)}),
        "times_ms": {p: summary(samples[p]) for p in PROGRAMS},
        "compile_s": {p: round(s, 2) for p, s in w.compile_s.items()},
        "frames_per_s": round(batch / (median["step"] / 1e3), 3),
        "fwd_bwd_over_eval": round(median["fwd_bwd"] / median["eval_forward"], 3),
        # the same ratio within each repetition: its spread is the noise of the figure above
        "fwd_bwd_over_eval_by_repetition": summary([b / e for b, e in zip(samples["fwd_bwd"], samples["eval_forward"])]),
        "step_over_fwd_bwd": round(median["step"] / median["fwd_bwd"], 3),
        "gflops": {"analytic": {p: _significant(v) for p, v in analytic.items()},
                   "xla": {p: None if v is None else _significant(v) for p, v in xla.items()}},
        "gflop_per_s": rates,
        "percent_of_peak": {k: {p: None if v is None else _significant(100 * v / peak_gflop_per_s) for p, v in r.items()}
                            for k, r in rates.items()},
    }


def step_breakdown(w: Workload, settings: Settings, threads: int) -> dict:
    """The XLA profiler's breakdown of `profile_steps` traced steps (op_breakdown), with the op
    time as a share of `threads` x the traced wall time (how busy the step kept XLA's pool)."""
    directory = Path(tempfile.mkdtemp(prefix="dsfec-train-trace-"))
    try:
        reps = itertools.count()
        xplane, seconds = op_breakdown.capture(lambda: w.run("step", next(reps)), settings.profile_steps, directory)
        wall_ms = 1e3 * seconds / settings.profile_steps
        result = op_breakdown.breakdown(w.compiled["step"].as_text(), xplane, settings.profile_steps)
    finally:
        shutil.rmtree(directory, ignore_errors=True)
    busy = 100 * result["op_ms_per_step"] / (threads * wall_ms)
    return {**result, "traced_wall_ms_per_step": round(wall_ms, 2), "busy_percent_of_threads": round(busy, 1)}


# ---- one model, in this process -----------------------------------------------------------------

def measure(name: str, settings: Settings, compare: dict | None = None, threads: int | None = None,
            base: dict | None = None, *, modality) -> dict:
    """Every figure of model `name` (and of its `compare` config, interleaved), in this process.
    `base`: config overrides of both configs (the tests' tiny shapes); `modality`: the model's
    Modality record."""
    from ..core.environment import cpu_model, xla_threads
    from ..core.provenance import versions

    base = dict(base or {})
    configs = [("default", base)] + ([("compare", {**base, **compare})] if compare else [])
    workloads = []
    for label, overrides in configs:
        with progress.stage(f"compiling {name}'s {len(PROGRAMS)} programs ({label} config)"):
            workloads.append(build_workload(name, label, overrides, settings, modality))
    references = sgemms()
    with machine_load.watch() as load, progress.stage(  # was the machine busy while the steps were timed?
            f"timing {name}: {settings.warmup} warm-up and {settings.repeats} repetitions, interleaved"):
        samples = time_interleaved(workloads, references, settings)
    machine_load.warn(load.verdict, f"the train bench's timing of {name}")
    alone = time_alone(references, settings)
    rates, interleaved = sgemm_rates(alone), sgemm_rates(samples["sgemm"])
    peak = max(rates.values())
    results = [figures(w, samples[w.label], peak, settings.batch) for w in workloads]
    if settings.breakdown:
        for w, r in zip(workloads, results):
            with progress.stage(f"profiling where {name}'s step time goes ({w.label} config, XLA profiler)"):
                r["breakdown"] = step_breakdown(w, settings, xla_threads())
    return {
        "model": name, "family": zoo.family_of(name).name, "threads": threads, "windows": workloads[0].windows,
        "settings": dataclasses.asdict(settings),
        "sgemm": {"n": SGEMM_N, "gflop_per_s": peak, "by_reference_gflop_per_s": rates,
                  "times_ms": {k: summary(ms) for k, ms in alone.items()},
                  "interleaved_gflop_per_s": interleaved,
                  "interleaved_times_ms": {k: summary(ms) for k, ms in samples["sgemm"].items()}},
        "configs": results, "comparison": comparison(results) if compare else None,
        "environment": {"cpu": cpu_model(), "threads_asked": threads, "xla_threads": xla_threads(),
                        "cpu_affinity": thread_control.available_cpus(), "glibc_hugetlb": host_memory.active(),
                        "keeps_xla_buffers": host_memory.keeps_buffers(), "machine": load.verdict,
                        "versions": versions(("jax", "jaxlib", "flax", "numpy", "optax", "dsfec_jax"))},
    }


def comparison(results: list[dict]) -> dict:
    """compare / default: time ratios per program (> 1: the compare config is slower) and the
    frames/s ratio (> 1: it is faster)."""
    default, other = results
    return {"time_ratio_compare_over_default": {p: round(other["times_ms"][p]["median"] / default["times_ms"][p]["median"], 3)
                                                for p in PROGRAMS},
            "frames_per_s_ratio_compare_over_default": round(other["frames_per_s"] / default["frames_per_s"], 3)}


# ---- workers ------------------------------------------------------------------------------------

def parse_compare(text: str | None) -> dict:
    """'FIELD=VALUE[,FIELD=VALUE]' -> {field: value}; values are Python literals where they parse
    (as `dsfec train --set`), and a comma starts a new pair only before 'FIELD=', so tuple values
    like stage_blocks=(1,1,3,2) stay whole."""
    import ast

    if not text:
        return {}
    out = {}
    for item in re.split(r",(?=\s*[A-Za-z_]\w*\s*=)", text):
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key.isidentifier():
            raise ValueError(f"--compare {text!r}: expected FIELD=VALUE[,FIELD=VALUE], got {item!r}")
        try:
            out[key] = ast.literal_eval(value.strip())
        except (ValueError, SyntaxError):
            out[key] = value.strip()
    return out


def check_models(models: list[str], settings: Settings, compare: dict | None,
                 modality_of: Callable[[str], Any]) -> None:
    """Refuse unknown models and compare fields (naming them) before any worker starts;
    `modality_of(name)` -> the model's Modality record."""
    unknown = [m for m in models if m not in zoo.available()]
    if unknown:
        raise ValueError(f"unknown model(s) {unknown}; available: {zoo.available()}")
    for name in models:
        for label, overrides in (("default config", {}), (f"--compare {_overrides_text(compare)}", compare or {})):
            try:
                zoo.config(name, **{**model_overrides(name, settings, modality_of(name)), **overrides})
            except (TypeError, ValueError) as err:
                raise ValueError(f"{label}: {err}") from None


def worker_main(argv, modality_of: Callable[[str], Any]) -> int:
    """`python -m dsfec_jax.profile --train-worker --model M --threads T --settings JSON [--compare
    JSON] --out PATH` (the entry point passes `modality_of`): one model in this process, pinned to T
    CPUs before XLA starts."""
    import argparse

    p = argparse.ArgumentParser(prog="python -m dsfec_jax.profile --train-worker")
    p.add_argument("--model", required=True)
    p.add_argument("--threads", type=int, required=True)
    p.add_argument("--settings", required=True, help="Settings as JSON")
    p.add_argument("--compare", default=None, help="compare overrides as JSON")
    p.add_argument("--out", required=True)
    a = p.parse_args(argv)
    thread_control.pin(a.threads)  # before the first jax computation: XLA sizes its pool from it
    settings = Settings(**json.loads(a.settings))
    record = measure(a.model, settings, json.loads(a.compare) if a.compare else None, a.threads,
                     modality=modality_of(a.model))
    Path(a.out).write_text(json.dumps(record))
    return 0


def run(models: list[str], threads: list[int], settings: Settings, compare: dict | None = None,
        log: Callable[[str], None] = lambda line: print(line, file=sys.stderr, flush=True), *,
        modality_of: Callable[[str], Any]) -> list[dict]:
    """Each (model, thread count) measured in a fresh worker process (`python -m dsfec_jax.profile
    --train-worker`, which looks the model's modality up itself) -> their records."""
    check_models(models, settings, compare, modality_of)
    for t in threads:
        thread_control.check(t)
    records = []
    for t in threads:
        for name in models:
            log(f"train bench: {name}, {t} thread(s)" + (f", compare {compare}" if compare else ""))
            with tempfile.TemporaryDirectory() as tmp:
                out = Path(tmp) / "record.json"
                cmd = [sys.executable, "-m", "dsfec_jax.profile", "--train-worker", "--model", name,
                       "--threads", str(t), "--settings", json.dumps(dataclasses.asdict(settings)), "--out", str(out)]
                if compare:
                    cmd += ["--compare", json.dumps(_jsonable(compare))]
                # the worker's progress (compiling its programs, timing) reaches the user as it comes
                code, tail = run_passing_stderr(cmd, {**os.environ, "OMP_NUM_THREADS": str(t)})
                if code != 0:
                    raise RuntimeError(f"train bench worker ({name}, {t} threads) failed:\n{tail}")
                records.append(json.loads(out.read_text()))
    return records


def payload(command: str, records: list[dict], settings: Settings, compare: dict | None) -> dict:
    """The record file's content: command, settings, conventions and every model's record."""
    from ..core.provenance import versions

    return {"command": command, "settings": dataclasses.asdict(settings), "compare": _jsonable(compare),
            "flops_convention": FLOPS_CONVENTION, "peak_convention": PEAK_CONVENTION,
            "versions": versions(), "records": records}


def write(path: str | Path, content: dict) -> None:
    atomic.write_json(path, content)


# ---- report -------------------------------------------------------------------------------------

def _f(value, digits: int = 1) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _ratio_text(config: dict) -> str:
    """fwd + bwd / eval of the medians, with the p10-p90 range of the ratio within each
    repetition where the record has it (records written before it do not)."""
    spread = config.get("fwd_bwd_over_eval_by_repetition")
    text = f"{config['fwd_bwd_over_eval']:.2f}"
    return text if spread is None else f"{text} ({spread['p10']:.2f}-{spread['p90']:.2f})"


def _slots_text(settings: dict) -> str:
    if settings.get("size_pillars", False):
        return (f"pillar slots sized to the data as training sizes them (data.points.pillarize.pillar_budget on "
                f"{settings.get('budget_frames', BUDGET_FRAMES)} train frames, at most {settings['max_pillars']})")
    return f"{settings['max_pillars']} pillar slots"


def markdown(content: dict, breakdown_rows: int = 6, full: bool = True, record: str | Path = RECORD, *,
             modality_of: Callable[[str], Any]) -> str:
    """The figures table, the comparison table (with --compare) and each step's breakdown
    (full=False: its module table only); `record`: the file the content was written to;
    `modality_of(name)` -> a model's Modality record (its `train_bench_note` ends the footer)."""
    records = content["records"]
    lines = ["| model | config | threads | pillar slots | train frames/s | step ms | eval fwd ms | train fwd ms | fwd+bwd ms "
             "| fwd+bwd / eval (p10-p90 by repetition) | step GFLOP/s (3 x fwd) | % sgemm | step GFLOP/s (XLA) | % sgemm | sgemm GFLOP/s (XLA / numpy) "
             "| compile s (step) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in records:
        by_ref = r["sgemm"]["by_reference_gflop_per_s"]
        for c in r["configs"]:
            t = {p: c["times_ms"][p]["median"] for p in PROGRAMS}
            config = "default" if c["label"] == "default" else _overrides_text(content["compare"])
            lines.append(
                f"| {r['model']} | {config} | {r['threads']} | {c.get('pillar_slots', '-')} | {c['frames_per_s']:.2f} | {t['step']:.1f} "
                f"| {t['eval_forward']:.1f} | {t['train_forward']:.1f} | {t['fwd_bwd']:.1f} | {_ratio_text(c)} "
                f"| {_f(c['gflop_per_s']['analytic']['step'])} | {_f(c['percent_of_peak']['analytic']['step'])} "
                f"| {_f(c['gflop_per_s']['xla']['step'])} | {_f(c['percent_of_peak']['xla']['step'])} "
                f"| {_f(by_ref.get('xla'), 0)} / {_f(by_ref.get('numpy'), 0)} | {c['compile_s']['step']:.1f} |")
    compared = [r for r in records if r.get("comparison")]
    if compared:
        lines += ["", f"Compare `{_overrides_text(content['compare'])}` against the default config "
                      "(time ratio compare / default, same interleaved loop):", "",
                  "| model | threads | frames/s ratio | step | fwd+bwd | train fwd | eval fwd |", "|---|---|---|---|---|---|---|"]
        for r in compared:
            q = r["comparison"]["time_ratio_compare_over_default"]
            lines.append(f"| {r['model']} | {r['threads']} | {r['comparison']['frames_per_s_ratio_compare_over_default']:.3f} "
                         f"| {q['step']:.3f} | {q['fwd_bwd']:.3f} | {q['train_forward']:.3f} | {q['eval_forward']:.3f} |")
    s = content["settings"]
    env = records[0]["environment"] if records else {}
    lines += ["", f"Measured with `{content['command']}` on {env.get('cpu', '?')}, "
                  f"jax {env.get('versions', {}).get('jax', '?')}: batch {s['batch']}, "
                  f"{'whole-grid' if s['window'] is None else str(s['window']) + '-cell'} training windows, "
                  f"{_slots_text(s)}, median of {s['repeats']} interleaved repetitions after "
                  f"{s['warmup']} warm-up, each program timed right after {s.get('lead_in', 0)} untimed "
                  f"call(s) of itself (steady state). Analytic GFLOP/s count {content['flops_convention']}. Peak: "
                  f"{content['peak_convention']}. Record: `{_record_text(record)}`."
                  + _notes(records, s, modality_of)]
    busy = [r for r in records if (r["environment"].get("machine") or {}).get("busy")]
    if busy:  # the figures above are then not the machine's: say so where they are read
        lines += ["", "Timed on a busy machine: " + "; ".join(
            f"{r['model']} ({r['threads']} threads): {r['environment']['machine']['text'][len('busy: '):]}"
            for r in busy) + ". These figures are not the machine's."]
    for r in records:
        for c in r["configs"]:
            if c.get("breakdown"):
                lines += ["", f"Where a step's time goes, {r['model']} ({c['label']}, {r['threads']} threads):", "",
                          op_breakdown.markdown(c["breakdown"], breakdown_rows, full)]
    return "\n".join(lines)


def _record_text(record: str | Path) -> str:
    """The record's path as the `--readme` page names it: from the repository root when it lies inside it."""
    path = Path(record).resolve()
    root = Path(__file__).resolve().parents[2]
    return str(path.relative_to(root)) if path.is_relative_to(root) else str(record)


def model_names(records: list[dict]) -> str:
    """Each model once, in order (a model measured at several thread counts has several records)."""
    return ", ".join(dict.fromkeys(r["model"] for r in records))


def _notes(records: list[dict], settings: dict, modality_of: Callable[[str], Any]) -> str:
    """What differs for each modality's records (`Modality.train_bench_note`), in the order the
    modalities first appear; records written before they named their family have none."""
    groups: dict[str, tuple[Any, list]] = {}
    for r in records:
        if r.get("family"):
            modality = modality_of(r["model"])
            groups.setdefault(modality.name, (modality, []))[1].append(r)
    return "".join(modality.train_bench_note(recs, settings) for modality, recs in groups.values())


def check_readme(readme: str | Path) -> str:
    """The `--readme` page's text (docs/profiler.md holds the train-bench table), refused (before a
    long run) without the train-bench markers."""
    path = Path(readme)
    text = path.read_text() if path.is_file() else ""
    if README_START not in text or README_END not in text:
        raise ValueError(f"{readme}: expected a file with the markers {README_START} and {README_END} "
                         "around the train-bench table")
    return text


def update_readme(readme: str | Path, content: dict, record: str | Path = RECORD, *,
                  modality_of: Callable[[str], Any]) -> None:
    """Replace the text between the train-bench markers of `readme` with the table."""
    text = check_readme(readme)
    table = markdown(content, breakdown_rows=5, full=False, record=record, modality_of=modality_of)
    block = f"{README_START}\n{table}\n{README_END}"
    text = re.sub(re.escape(README_START) + ".*?" + re.escape(README_END), lambda _: block, text, flags=re.S)
    atomic.write_text(readme, text)


def _significant(x: float, digits: int = 4) -> float:
    """`x` rounded to `digits` significant digits (a tiny test model's GFLOPs do not round to 0)."""
    return float(f"{x:.{digits}g}")


def _overrides_text(overrides: dict | None) -> str:
    return ",".join(f"{k}={v}" for k, v in (overrides or {}).items())


def _jsonable(obj):
    from ..core.provenance import jsonable

    return jsonable(obj)

