"""The ONNX Runtime machinery every modality's runtime predictor is built on: `read_manifest` (an
export's graph and deploy.json, checked to be of the modality its caller expects), `ort_session` (a
CPU session with a thread count) and `run_fixed_batch` (a fixed-batch graph over any number of
items). The predictors are the modalities': modalities/points/ort.py (OrtPredictor),
modalities/rd/ort.py, modalities/image/ort.py."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def read_manifest(path: str | Path, modality: str | None = None) -> tuple[Path, dict]:
    """DIR or DIR/model.onnx -> (model path, deploy.json contents); with `modality`, a ValueError
    unless the export is of that modality ('points' for manifests written before it was recorded)."""
    path = Path(path)
    model = path / "model.onnx" if path.is_dir() else path
    manifest = model.parent / "deploy.json"
    for p in (model, manifest):
        if not p.is_file():
            raise FileNotFoundError(f"{p}: missing; export with `dsfec export --model NAME --out DIR`")
    info = json.loads(manifest.read_text())
    found = info.get("modality", "points")
    if modality is not None and found != modality:
        raise ValueError(f"{manifest}: an export of the {found!r} model {info.get('model')!r}; expected a "
                         f"{modality!r} model's export")
    return model, info


def ort_session(model_path: str | Path, threads: int | None = None):
    """An onnxruntime CPU session; `threads` sets its intra-op pool (inter-op 1), None leaves ORT's default."""
    import onnxruntime as ort

    options = ort.SessionOptions()
    if threads:
        options.intra_op_num_threads = threads
        options.inter_op_num_threads = 1
    return ort.InferenceSession(str(model_path), options, providers=["CPUExecutionProvider"])


def run_fixed_batch(run, feeds: dict, batch_size: int, model_path) -> tuple:
    """`run(feeds) -> outputs` of a graph exported for a fixed batch: the feeds as they are when
    their batch is that size; item by item when the graph takes batch 1 (outputs concatenated);
    otherwise a ValueError."""
    n = len(next(iter(feeds.values())))
    if n == batch_size:
        return tuple(run(feeds))
    if batch_size != 1:
        raise ValueError(f"{model_path}: exported for batch {batch_size}, got {n} items")
    parts = [run({k: v[i:i + 1] for k, v in feeds.items()}) for i in range(n)]
    return tuple(np.concatenate([p[j] for p in parts]) for j in range(len(parts[0])))
