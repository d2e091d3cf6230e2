"""The benchmark chains of a point model (`dsfec bench`; deploy/bench times them), raw points to boxes.

Stages (STAGES): pillarize (host numpy), network (pillar net .. heads), decode (sigmoid, PIXOR
decode, top-k per head), nms (host, rotated, per class). jax: the detector and the family's decoder,
each jitted. onnx / onnx-int8: a network-only and a decode-only ONNX graph (int8 quantizes the
network only, calibrated on synthetic train frames), run by ONNX Runtime with intra_op_num_threads
set to the worker's thread count. The Predictor's host NMS closes every chain. Also JAX's
throughput of network + decode at batch sizes above 1, which the batch-1 chains do not show.
"""

from __future__ import annotations

from pathlib import Path

import jax

from ...deploy.bench.model_setup import bench_variables
from ...deploy.bench.stages import jax_throughput

STAGES = ("pillarize", "network", "decode", "nms")
CALIBRATION_FRAMES = 32  # synthetic train frames, seed 0


def model_setup(name: str):
    """A point model: (detector, variables, weights label, frame points, Predictor for the host NMS)."""
    from ... import zoo
    from ...core.defaults import RUN_PILLARS
    from ...data.points.pillarize import select_columns
    from ...data.points.sources import load_frames
    from .predict import Predictor

    det = zoo.create(name, max_pillars=RUN_PILLARS)
    variables, label = bench_variables(det, name)
    frame = load_frames("synthetic", "test", 1, seed=0)[0]
    points = select_columns(frame, det.config.point_features)
    return det, variables, label, points, Predictor(det, variables, score_threshold=0.1)


def jax_stages(det, variables, predictor) -> dict:
    """The JAX predictor's network and decode, apart: the network on the fewest pillar slots that
    hold the frame (predict.fewest_slots, as the predictor runs it)."""
    from .predict import decoder, fewest_slots

    net = jax.jit(det.apply)
    dec = jax.jit(decoder(det.config, 100))
    return {"network": lambda batch: jax.block_until_ready(net(variables, fewest_slots(batch))),
            "decode": lambda maps: jax.device_get(dec(maps))}


def onnx_graphs(det, variables, predictor, workdir: Path, int8: bool, calib_points: list) -> dict:
    """ONNX network-only and decode-only graphs (the export's grouped depthwise kernel). The
    network graph outputs the leaves of the head-output tree; the decode graph rebuilds the tree
    and runs the family's decoder, so any family's heads pass between the two."""
    from ...data.points.pillarize import PillarSpec, pillarize
    from ...deploy.export import grouped, onnx_model
    from ...deploy.quantize import quantize_model
    from .export import INPUTS
    from .predict import decoder

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


def ort_stages(paths: dict, threads: int) -> dict:
    from ...deploy.ort import ort_session

    net, dec = ort_session(paths["network"], threads), ort_session(paths["decode"], threads)
    names = [i.name for i in dec.get_inputs()]
    return {"network": lambda batch: net.run(None, batch),
            "decode": lambda maps: dec.run(None, dict(zip(names, maps)))}


def chain(points, spec, stages: dict, predictor) -> list:
    """[(stage, fn(previous output) -> output)] from raw points to Detections."""
    from ...data.points.pillarize import pillarize

    return [("pillarize", lambda _: {k: v[None] for k, v in pillarize(points, spec)[0].items()}),
            ("network", stages["network"]), ("decode", stages["decode"]),
            ("nms", lambda out: predictor._postprocess(out[0][0], out[1][0], out[2][0]))]


def point_chains(name: str, runtimes: list[str], threads: int, workdir: Path, repeats: int) -> dict:
    """runtime -> (chain of a point model, record fields)."""
    from ...data.points.pillarize import PillarSpec, select_columns
    from ...data.points.sources import load_frames
    from .predict import decoded_network

    det, variables, label, points, predictor = model_setup(name)
    spec, out = PillarSpec.of(det.config), {}
    for rt in runtimes:
        if rt == "jax":
            stages = jax_stages(det, variables, predictor)
        else:
            frames = load_frames("synthetic", "train", CALIBRATION_FRAMES, seed=0) if rt == "onnx-int8" else []
            calib = [select_columns(f, det.config.point_features) for f in frames]
            stages = ort_stages(onnx_graphs(det, variables, predictor, workdir, rt == "onnx-int8", calib), threads)
        out[rt] = (chain(points, spec, stages, predictor), {"weights": label, "points": int(len(points))})
    if "jax" in out:
        out["jax"][1].update(jax_throughput(det, variables, jax.jit(decoded_network(det, 100)), repeats))
    return out
