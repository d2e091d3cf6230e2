"""Batch-1 latency from raw points to boxes, per stage and runtime (`dsfec bench`).

Stages: pillarize (host numpy), network (pillar net .. heads), decode (sigmoid, PIXOR decode,
top-k per head), nms (host, rotated, per class). Every runtime runs the same chain of four
calls on the same frame; within each repeat the models and runtimes alternate (A B C A B C ...)
so their ratios hold on a noisy shared machine. XLA has no thread-count flag and sizes its pool
from the CPUs it may use when it starts, so each --threads value N runs in its own worker process
pinned to N CPUs before XLA starts (profile/threads.py); ONNX Runtime gets intra_op_num_threads=N.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

from ..profile import threads as thread_control

RUNTIMES = ("jax", "onnx", "onnx-int8")
STAGES = ("pillarize", "network", "decode", "nms")
JAX_BATCHES = (1, 2, 4, 8)


def model_setup(name: str):
    """(detector, variables, weights label, frame points, Predictor for the host NMS)."""
    from .. import zoo
    from ..data.pillarize import select_columns
    from ..data.sources import load_frames
    from ..predict import Predictor

    from ..core.defaults import RUN_PILLARS

    det = zoo.create(name, max_pillars=RUN_PILLARS)
    shipped = zoo.shipped_weights(name)
    if shipped.is_file():  # trained weights: realistic score distribution, so a realistic NMS load
        v = zoo.load_variables(det, shipped)
        variables, label = {"params": v["params"], "batch_stats": v["batch_stats"]}, "shipped"
    else:
        variables, label = det.init(jax.random.key(0)), "random"
    frame = load_frames("synthetic", "test", 1, seed=0)[0]
    points = select_columns(frame, det.config.point_features)
    return det, variables, label, points, Predictor(det, variables, score_threshold=0.1)


def jax_stages(det, variables, predictor) -> dict:
    from ..predict import decoder

    net = jax.jit(det.apply)
    dec = jax.jit(decoder(det.config, 100))
    return {"network": lambda batch: jax.block_until_ready(net(variables, batch)),
            "decode": lambda maps: jax.device_get(dec(maps))}


def onnx_graphs(det, variables, predictor, workdir: Path, int8: bool, calib_points: list) -> dict:
    """ONNX network-only and decode-only graphs (the export's grouped depthwise kernel)."""
    from ..boxes.decode import decode_heads
    from ..boxes.pixor import cell_centres
    from ..data.pillarize import PillarSpec, pillarize
    from ..models.dsfec import HEAD_NAMES
    from .export import INPUTS, grouped, onnx_model
    from .quantize import quantize_model

    g = grouped(det)
    specs = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in (g.dummy_inputs(1)[k] for k in INPUTS)]
    keys = [(h, k) for h in HEAD_NAMES for k in ("cls", "box")]

    def network(points, mask, coords):
        maps = g.apply(variables, {"points": points, "mask": mask, "coords": coords})
        return tuple(maps[h][k] for h, k in keys)

    net_path, dec_path = workdir / f"{det.name}_network.onnx", workdir / f"{det.name}_decode.onnx"
    if not net_path.exists():
        net_path.write_bytes(onnx_model(network, specs, INPUTS, [f"{h}_{k}" for h, k in keys]).SerializeToString())
        map_specs = [jax.ShapeDtypeStruct(s.shape, s.dtype) for s in jax.eval_shape(network, *specs)]
        cells = cell_centres(det.config.grid, det.config.output_stride)

        def decode(*maps):
            return decode_heads({h: {"cls": maps[2 * i], "box": maps[2 * i + 1]} for i, h in enumerate(HEAD_NAMES)},
                                predictor.head_classes, cells, 100)

        dec_path.write_bytes(onnx_model(decode, map_specs, [f"{h}_{k}" for h, k in keys],
                                        ["boxes", "scores", "labels"]).SerializeToString())
    if int8:
        spec = PillarSpec.of(det.config)
        feeds = [{k: v[None] for k, v in pillarize(p, spec)[0].items()} for p in calib_points]
        int8_path = workdir / f"{det.name}_network_int8.onnx"
        if not int8_path.exists():
            quantize_model(net_path, int8_path, feeds)
        net_path = int8_path
    return {"network": net_path, "decode": dec_path}


def ort_stages(paths: dict, threads: int) -> dict:
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.intra_op_num_threads, opts.inter_op_num_threads = threads, 1
    net = ort.InferenceSession(str(paths["network"]), opts, providers=["CPUExecutionProvider"])
    dec = ort.InferenceSession(str(paths["decode"]), opts, providers=["CPUExecutionProvider"])
    names = [i.name for i in dec.get_inputs()]
    return {"network": lambda batch: net.run(None, batch),
            "decode": lambda maps: dec.run(None, dict(zip(names, maps)))}


def chain(points, spec, stages: dict, predictor) -> list:
    """[(stage, fn(previous output) -> output)] from raw points to Detections."""
    from ..data.pillarize import pillarize

    return [("pillarize", lambda _: {k: v[None] for k, v in pillarize(points, spec)[0].items()}),
            ("network", stages["network"]), ("decode", stages["decode"]),
            ("nms", lambda out: predictor._postprocess(out[0][0], out[1][0], out[2][0]))]


def time_chains(chains: dict, repeats: int, warmup: int) -> dict:
    """Interleaved timing: key -> stage -> list of ms (plus 'total')."""
    def run(steps, sink=None):
        x, total = None, 0.0
        for stage, fn in steps:
            t0 = time.perf_counter()
            x = fn(x)
            ms = 1e3 * (time.perf_counter() - t0)
            total += ms
            if sink is not None:
                sink[stage].append(ms)
        if sink is not None:
            sink["total"].append(total)

    for steps in chains.values():
        for _ in range(warmup):
            run(steps)
    samples = {k: {s: [] for s in STAGES + ("total",)} for k in chains}
    for _ in range(repeats):
        for key, steps in chains.items():
            run(steps, samples[key])
    return samples


def jax_throughput(det, variables, predictor, repeats: int) -> dict:
    """Frames/s of network + decode at each batch size (batch 1 .. 8) -> {batch: fps}."""
    from ..predict import decoded_network

    fn = jax.jit(decoded_network(det, 100))
    out = {}
    for b in JAX_BATCHES:
        x = det.dummy_inputs(b, occupancy=0.25)
        jax.block_until_ready(fn(variables, x))
        times = []
        for _ in range(max(3, repeats // b)):
            t0 = time.perf_counter()
            jax.block_until_ready(fn(variables, x))
            times.append(time.perf_counter() - t0)
        out[str(b)] = round(b / float(np.median(times)), 2)
    return out


def worker(models: list[str], runtimes: list[str], threads: int, repeats: int, warmup: int) -> list[dict]:
    """One process, one thread count: every (model, runtime) chain timed in one interleaved loop."""
    from ..data.pillarize import PillarSpec
    from ..data.sources import load_frames
    from ..core.provenance import versions
    from ..profile.environment import cpu_model, xla_threads

    calib = None
    chains, extra = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in models:
            det, variables, label, points, predictor = model_setup(name)
            spec = PillarSpec.of(det.config)
            for rt in runtimes:
                if rt == "jax":
                    stages = jax_stages(det, variables, predictor)
                else:
                    if rt == "onnx-int8" and calib is None:
                        from ..data.pillarize import select_columns
                        calib = [select_columns(f, det.config.point_features)
                                 for f in load_frames("synthetic", "train", 32, seed=0)]
                    stages = ort_stages(onnx_graphs(det, variables, predictor, Path(tmp), rt == "onnx-int8", calib or []),
                                        threads)
                chains[(name, rt)] = chain(points, spec, stages, predictor)
                extra[(name, rt)] = {"weights": label, "points": int(len(points))}
            if "jax" in runtimes:
                extra[(name, "jax")]["throughput_fps"] = jax_throughput(det, variables, predictor, repeats)
        samples = time_chains(chains, repeats, warmup)
    # threads: the count asked for; xla_threads: XLA's pool as observed after the runs (the truth)
    env = {"cpu": cpu_model(), "threads": threads, "xla_threads": xla_threads(),
           "cpu_affinity": thread_control.available_cpus(), "versions": versions(
        ("jax", "jaxlib", "flax", "numpy", "onnxruntime", "jax2onnx", "dsfec_jax"))}
    records = []
    for (name, rt), s in samples.items():
        med = {k: round(float(np.median(v)), 3) for k, v in s.items()}
        records.append({"model": name, "runtime": rt, "threads": threads,
                        "stages_ms": {k: med[k] for k in STAGES}, "total_ms": med["total"],
                        "total_p90_ms": round(float(np.percentile(s["total"], 90)), 3),
                        "fps_batch1": round(1e3 / med["total"], 2), "repeats": repeats, "warmup": warmup,
                        **extra[(name, rt)], **env})
    return records


def run(models: list[str], runtimes: list[str], threads: list[int], repeats: int = 20, warmup: int = 3) -> list[dict]:
    """Each thread count in a worker process pinned to that many CPUs (XLA's pool is fixed at
    start-up) -> all records."""
    for t in threads:  # refuse a count the machine cannot give before any worker starts
        thread_control.check(t)
    records = []
    for t in threads:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "records.json"
            cmd = [sys.executable, "-m", "dsfec_jax.deploy.bench", "--models", ",".join(models),
                   "--runtimes", ",".join(runtimes), "--threads", str(t), "--repeats", str(repeats),
                   "--warmup", str(warmup), "--records-out", str(out)]
            env = {**os.environ, "OMP_NUM_THREADS": str(t)}
            proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
            if proc.returncode != 0:
                raise RuntimeError(f"bench worker (threads={t}) failed:\n{proc.stderr[-3000:]}")
            records += json.loads(out.read_text())
    return records


def ratios(records: list[dict]) -> list[str]:
    """The figures to quote: DSFEC-S / Baseline per runtime, JAX / ONNX Runtime per model."""
    by = {(r["model"], r["runtime"], r["threads"]): r["total_ms"] for r in records}
    lines = []
    for (m, rt, t), ms in sorted(by.items()):
        if m == "dsfec_s" and ("baseline", rt, t) in by:
            lines.append(f"DSFEC-S / Baseline ({rt}, {t} thread{'s' * (t > 1)}): {ms / by[('baseline', rt, t)]:.3f}")
        if rt == "jax" and (m, "onnx", t) in by:
            lines.append(f"JAX / ONNX Runtime ({m}, {t} thread{'s' * (t > 1)}): {ms / by[(m, 'onnx', t)]:.3f}")
    return lines


def markdown(records: list[dict]) -> str:
    head = ["model", "runtime", "threads"] + [f"{s} ms" for s in STAGES] + ["total ms (p90)", "frames/s (batch 1)",
                                                                           "JAX frames/s by batch"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in records:
        tp = r.get("throughput_fps")
        tp_text = ", ".join(f"{b}: {v}" for b, v in tp.items()) if tp else "-"
        lines.append("| " + " | ".join([r["model"], r["runtime"], str(r["threads"])]
                                       + [f"{r['stages_ms'][s]:.2f}" for s in STAGES]
                                       + [f"{r['total_ms']:.1f} ({r['total_p90_ms']:.1f})", f"{r['fps_batch1']:.1f}",
                                          tp_text]) + " |")
    env = records[0]
    return "\n".join(lines + [""] + ratios(records) + ["", f"CPU: {env['cpu']}; versions: {env['versions']}"]) + "\n"


def plot(records: list[dict], path: Path) -> None:
    import io

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .. import atomic

    labels = [f"{r['model']}\n{r['runtime']} x{r['threads']}" for r in records]
    fig, ax = plt.subplots(figsize=(max(6, 0.7 * len(records)), 4.2), dpi=120)
    bottom = np.zeros(len(records))
    for stage in STAGES:
        vals = np.array([r["stages_ms"][stage] for r in records])
        ax.bar(labels, vals, bottom=bottom, label=stage)
        bottom += vals
    ax.set_ylabel("ms, batch 1 (median)")
    ax.set_title("raw points -> boxes, per stage")
    ax.legend(fontsize=7)
    ax.tick_params(axis="x", labelsize=6)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    atomic.write_bytes(path, buf.getvalue())


def main(argv=None) -> int:  # the worker entry point; users run `dsfec bench`
    import argparse

    p = argparse.ArgumentParser(prog="python -m dsfec_jax.deploy.bench")
    p.add_argument("--models", required=True)
    p.add_argument("--runtimes", required=True)
    p.add_argument("--threads", type=int, required=True)
    p.add_argument("--repeats", type=int, default=20)
    p.add_argument("--warmup", type=int, default=3)
    p.add_argument("--records-out", required=True)
    a = p.parse_args(argv)
    thread_control.pin(a.threads)  # before the first jax computation: XLA sizes its pool from it
    records = worker(a.models.split(","), a.runtimes.split(","), a.threads, a.repeats, a.warmup)
    Path(a.records_out).write_text(json.dumps(records))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
