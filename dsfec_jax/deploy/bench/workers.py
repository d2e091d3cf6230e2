"""One worker process per thread count, and `run`, which launches them and gathers their records;
`point_chains` / `rd_chains` / `camera_chains` build each model's chains by the modality its family
reads.

XLA has no thread-count flag and sizes its pool from the CPUs it may use when it starts, so each
--threads value N runs in its own worker process (`python -m dsfec_jax.deploy.bench`) pinned to N
CPUs before XLA starts (core/threads.py); ONNX Runtime gets intra_op_num_threads=N. Within a worker
every (model, runtime) chain is timed in one interleaved loop (timing.py).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import jax
import numpy as np

from ...core import threads as thread_control
from .model_setup import camera_model_setup, model_setup, rd_model_setup
from .stages import jax_stages, jax_throughput, onnx_graphs, ort_stages
from ...modalities.image.bench import camera_pipeline
from ...modalities.rd.bench import rd_jax_stages, rd_onnx_graph, rd_ort_stages
from .timing import camera_chain, chain, rd_chain, time_chains

POINT_CALIBRATION_FRAMES = 32  # synthetic train frames, seed 0


def point_chains(name: str, runtimes: list[str], threads: int, workdir: Path, repeats: int) -> dict:
    """runtime -> (chain of a point model, record fields)."""
    from ...data.points.pillarize import PillarSpec, select_columns
    from ...data.points.sources import load_frames
    from ...modalities.points.predict import decoded_network

    det, variables, label, points, predictor = model_setup(name)
    spec, out = PillarSpec.of(det.config), {}
    for rt in runtimes:
        if rt == "jax":
            stages = jax_stages(det, variables, predictor)
        else:
            calib = [select_columns(f, det.config.point_features)
                     for f in load_frames("synthetic", "train", POINT_CALIBRATION_FRAMES, seed=0)] if rt == "onnx-int8" else []
            stages = ort_stages(onnx_graphs(det, variables, predictor, workdir, rt == "onnx-int8", calib), threads)
        out[rt] = (chain(points, spec, stages, predictor), {"weights": label, "points": int(len(points))})
    if "jax" in out:
        out["jax"][1]["throughput_fps"] = jax_throughput(det, variables, jax.jit(decoded_network(det, 100)), repeats)
    return out


def rd_chains(name: str, runtimes: list[str], threads: int, workdir: Path, repeats: int) -> dict:
    """runtime -> (chain of a range-Doppler model, record fields): the native map, padded as training
    pads it (data/rd representations, fit 'pad'), in one fixed-size graph."""
    from ...data.rd.representations import RDRepresentation, fitted_shape
    from ...modalities.rd.predict import detecting_network

    det, variables, label, sample = rd_model_setup(name)
    representation = RDRepresentation()
    input_hw = fitted_shape(sample.shape, representation)
    out = {}
    for rt in runtimes:
        if rt == "jax":
            stages = rd_jax_stages(det, variables, input_hw)
        else:
            stages = rd_ort_stages(rd_onnx_graph(det, variables, workdir, rt == "onnx-int8", input_hw), threads)
        out[rt] = (rd_chain(sample, representation, det.config.input_names, stages),
                   {"weights": label, "input_hw": list(input_hw)})
    if "jax" in out:
        out["jax"][1]["throughput_fps"] = jax_throughput(det, variables, jax.jit(detecting_network(det)), repeats)
    return out


CAMERA_SIZE = 416  # the long side camera images are letterboxed to (the paper's; street frames: 256 x 416)


def camera_chains(name: str, runtimes: list[str], threads: int, workdir: Path, repeats: int,
                  size: int = CAMERA_SIZE, overrides: dict | None = None) -> dict:
    """runtime -> (chain of a camera model, record fields): one street test image letterboxed as
    CameraPredictor letterboxes it at `size`, into one fixed-size graph for ONNX Runtime.
    `overrides`: config fields (the tests' tiny networks)."""
    from ...modalities.image.predict import decoding_network, letterbox_shape

    det, variables, label, image = camera_model_setup(name, size, overrides)
    input_hw = letterbox_shape(size, True, image.hw)  # CameraPredictor's rectangle: 256 x 416 at 416
    out = {}
    for rt in runtimes:
        pipeline = camera_pipeline(det, variables, rt, size, workdir, threads, input_hw)
        out[rt] = (camera_chain(image, pipeline), {"weights": label, "input_hw": list(input_hw)})
    if "jax" in out:
        network = decoding_network(det)
        out["jax"][1]["throughput_fps"] = jax_throughput(det, variables, jax.jit(lambda v, x: network(v, x["image"])),
                                                         repeats, hw=input_hw)
    return out


CHAINS = {"points": point_chains, "rd": rd_chains, "image": camera_chains}  # modality -> its chains


def worker(models: list[str], runtimes: list[str], threads: int, repeats: int, warmup: int) -> list[dict]:
    """One process, one thread count: every (model, runtime) chain timed in one interleaved loop."""
    from ... import zoo
    from ...core.environment import cpu_model, xla_threads
    from ...core.provenance import versions

    chains, extra = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in models:
            modality = zoo.family_of(name).modality
            if modality not in CHAINS:
                raise ValueError(f"bench: {name!r} reads {modality!r} inputs; the bench times {sorted(CHAINS)} models")
            make = CHAINS[modality]
            for rt, (steps, fields) in make(name, runtimes, threads, Path(tmp), repeats).items():
                chains[(name, rt)], extra[(name, rt)] = steps, fields
        samples = time_chains(chains, repeats, warmup)
    # threads: the count asked for; xla_threads: XLA's pool as observed after the runs (the truth)
    env = {"cpu": cpu_model(), "threads": threads, "xla_threads": xla_threads(),
           "cpu_affinity": thread_control.available_cpus(), "versions": versions(
        ("jax", "jaxlib", "flax", "numpy", "onnxruntime", "jax2onnx", "dsfec_jax"))}
    records = []
    for (name, rt), s in samples.items():
        med = {k: round(float(np.median(v)), 3) for k, v in s.items()}
        records.append({"model": name, "runtime": rt, "threads": threads,
                        "stages_ms": {k: med[k] for k in s if k != "total"}, "total_ms": med["total"],
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


def main(argv=None) -> int:  # the worker entry point (__main__.py); users run `dsfec bench`
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
