"""Interleaved timing of the chains, raw input to boxes, one call per stage.

Point models (STAGES): pillarize (host numpy), network (pillar net .. heads), decode (sigmoid, PIXOR
decode, top-k per head), nms (host, rotated, per class). Range-Doppler models (RD_STAGES):
representation (host numpy: the heat / gray maps fitted to the input size), network_decode (network
and DFL decode), nms (class-aware NMS, or YOLOv10's top-k). Camera models (CAMERA_STAGES): letterbox
(host: the image scaled and centred into the network input), network_decode (network and YOLOv3
decode), nms (darknet's host post-processing and the boxes mapped back to the image). Every runtime
runs the same chain on the same frame; within each repeat the models and runtimes alternate
(A B C A B C ...) rather than running one after the other, so a slow spell of a noisy shared
machine hits them all alike and their ratios hold.
"""

from __future__ import annotations

import time

STAGES = ("pillarize", "network", "decode", "nms")
RD_STAGES = ("representation", "network_decode", "nms")
CAMERA_STAGES = ("letterbox", "network_decode", "nms")


def chain(points, spec, stages: dict, predictor) -> list:
    """[(stage, fn(previous output) -> output)] from raw points to Detections."""
    from ...data.points.pillarize import pillarize

    return [("pillarize", lambda _: {k: v[None] for k, v in pillarize(points, spec)[0].items()}),
            ("network", stages["network"]), ("decode", stages["decode"]),
            ("nms", lambda out: predictor._postprocess(out[0][0], out[1][0], out[2][0]))]


def rd_chain(sample, representation, input_names, stages: dict) -> list:
    """[(stage, fn(previous output) -> output)] from an RD sample to padded detections."""
    from ...data.rd.representations import representations

    def represent(_):
        maps = representations(sample, representation)
        return {k: maps[k][None] for k in input_names}

    return [("representation", represent), ("network_decode", stages["network_decode"]), ("nms", stages["nms"])]


def camera_chain(image, pipeline) -> list:
    """[(stage, fn(previous output) -> output)] from a CameraImage to its Boxes2D in image pixels,
    through a predict_camera.CameraPipeline (the JAX predictor or the ONNX Runtime one)."""
    from ...data.camera.letterbox import letterbox

    input_hw = pipeline.input_hw(image.hw)
    affine = letterbox(image.hw, input_hw)  # the map the letterbox stage applies (eval_input's)

    def nms(out):
        return pipeline.in_image(pipeline.postprocess(*out)[0], affine, image.hw)

    return [("letterbox", lambda _: pipeline.letterboxed([image], input_hw)[0]),
            ("network_decode", pipeline.decoded), ("nms", nms)]


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
    samples = {k: {s: [] for s, _ in steps} | {"total": []} for k, steps in chains.items()}
    for _ in range(repeats):
        for key, steps in chains.items():
            run(steps, samples[key])
    return samples
