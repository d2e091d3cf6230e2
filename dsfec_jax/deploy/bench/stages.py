"""The network and decode stages of each runtime for a point model, as plain callables the timing
loop chains (a range-Doppler model's: stages_rd.py).

jax: the detector and the family's decoder, each jitted. onnx / onnx-int8: a network-only and a
decode-only ONNX graph (int8 quantizes the network only, calibrated on synthetic train frames), run
by ONNX Runtime with intra_op_num_threads set to the worker's thread count. Also JAX's throughput
of network + decode at batch sizes above 1, which the batch-1 chains do not show.
"""

from __future__ import annotations

import time
from pathlib import Path

import jax
import numpy as np

RUNTIMES = ("jax", "onnx", "onnx-int8")
JAX_BATCHES = (1, 2, 4, 8)


def jax_stages(det, variables, predictor) -> dict:
    """The JAX predictor's network and decode, apart: the network on the fewest pillar slots that
    hold the frame (predict.fewest_slots, as the predictor runs it)."""
    from ...modalities.points.predict import decoder, fewest_slots

    net = jax.jit(det.apply)
    dec = jax.jit(decoder(det.config, 100))
    return {"network": lambda batch: jax.block_until_ready(net(variables, fewest_slots(batch))),
            "decode": lambda maps: jax.device_get(dec(maps))}


def onnx_graphs(det, variables, predictor, workdir: Path, int8: bool, calib_points: list) -> dict:
    """ONNX network-only and decode-only graphs (the export's grouped depthwise kernel). The
    network graph outputs the leaves of the head-output tree; the decode graph rebuilds the tree
    and runs the family's decoder, so any family's heads pass between the two."""
    from ...data.points.pillarize import PillarSpec, pillarize
    from ...modalities.points.predict import decoder
    from ..export import INPUTS, grouped, onnx_model
    from ..quantize import quantize_model

    g = grouped(det)
    specs = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in (g.dummy_inputs(1)[k] for k in INPUTS)]
    heads = jax.eval_shape(lambda *x: g.apply(variables, dict(zip(INPUTS, x))), *specs)
    leaves, treedef = jax.tree_util.tree_flatten_with_path(heads)
    names = ["_".join(str(getattr(k, "key", k)) for k in path) for path, _ in leaves]  # e.g. car_cls

    def network(points, mask, coords):
        return tuple(jax.tree.leaves(g.apply(variables, {"points": points, "mask": mask, "coords": coords})))

    net_path, dec_path = workdir / f"{det.name}_network.onnx", workdir / f"{det.name}_decode.onnx"
    if not net_path.exists():
        net_path.write_bytes(onnx_model(network, specs, INPUTS, names).SerializeToString())
        map_specs = [jax.ShapeDtypeStruct(s.shape, s.dtype) for s in jax.eval_shape(network, *specs)]
        decode_maps = decoder(det.config, 100)

        def decode(*maps):
            return decode_maps(jax.tree.unflatten(treedef, maps))

        dec_path.write_bytes(onnx_model(decode, map_specs, names, ["boxes", "scores", "labels"]).SerializeToString())
    if int8:
        spec = PillarSpec.of(det.config)
        feeds = [{k: v[None] for k, v in pillarize(p, spec)[0].items()} for p in calib_points]
        int8_path = workdir / f"{det.name}_network_int8.onnx"
        if not int8_path.exists():
            quantize_model(net_path, int8_path, feeds)
        net_path = int8_path
    return {"network": net_path, "decode": dec_path}


def cached_export(workdir: Path, tag: str, export, quantize, int8: bool) -> Path:
    """WORKDIR/TAG (written once per worker by `export(dir)`), or its INT8 copy WORKDIR/TAG_int8
    (`quantize(fp32_dir, int8_dir)`): one worker's runtimes share the files."""
    fp32 = workdir / tag
    if not (fp32 / "model.onnx").exists():
        export(fp32)
    if not int8:
        return fp32
    int8_dir = workdir / f"{tag}_int8"
    if not (int8_dir / "model.onnx").exists():
        quantize(fp32, int8_dir)
    return int8_dir


def ort_stages(paths: dict, threads: int) -> dict:
    from ..ort import ort_session

    net, dec = ort_session(paths["network"], threads), ort_session(paths["decode"], threads)
    names = [i.name for i in dec.get_inputs()]
    return {"network": lambda batch: net.run(None, batch),
            "decode": lambda maps: dec.run(None, dict(zip(names, maps)))}


def jax_throughput(det, variables, fn, repeats: int, hw: tuple[int, int] | None = None) -> dict:
    """Frames/s of the jitted fn(variables, inputs) (network + decode; + NMS for an RD model, whose
    predictor compiles it) at each batch size (batch 1 .. 8) -> {batch: fps}. `hw`: the input size of
    the models whose dummy inputs take one (camera images: the bench's letterboxed size)."""
    out = {}
    for b in JAX_BATCHES:
        x = det.dummy_inputs(b, occupancy=0.25) if hw is None else det.config.dummy_inputs(b, hw=tuple(hw))
        jax.block_until_ready(fn(variables, x))
        times = []
        for _ in range(max(3, repeats // b)):
            t0 = time.perf_counter()
            jax.block_until_ready(fn(variables, x))
            times.append(time.perf_counter() - t0)
        out[str(b)] = round(b / float(np.median(times)), 2)
    return out
