"""What each benchmarked model runs on: the detector, its variables, one synthetic frame (a point
cloud, or a range-Doppler map), and for the point models the Predictor whose host NMS closes every
chain.

Shipped weights are used when the model ships them (trained weights give a realistic score
distribution, so a realistic NMS load); otherwise the detector's own initial variables, labelled
'random' in the records. For YOLO-RD those load the host NMS about as trained weights do: its class
biases start at ultralytics' prior (sigmoid ~1e-4 at stride 8), and 96 of yolov8n's 2016 candidates
pass conf 0.001 at 256 x 64 (a briefly trained yolov8n: a median 60).
"""

from __future__ import annotations

import jax


def bench_variables(det, name: str) -> tuple[dict, str]:
    """(variables, 'shipped' | 'random') of a registered model."""
    from ... import zoo

    shipped = zoo.shipped_weights(name)
    if shipped.is_file():  # trained weights: realistic score distribution, so a realistic NMS load
        v = zoo.load_variables(det, shipped)
        return {"params": v["params"], "batch_stats": v["batch_stats"]}, "shipped"
    return det.init(jax.random.key(0)), "random"


def model_setup(name: str):
    """A point model: (detector, variables, weights label, frame points, Predictor for the host NMS)."""
    from ... import zoo
    from ...core.defaults import RUN_PILLARS
    from ...data.points.pillarize import select_columns
    from ...data.points.sources import load_frames
    from ...predict import Predictor

    det = zoo.create(name, max_pillars=RUN_PILLARS)
    variables, label = bench_variables(det, name)
    frame = load_frames("synthetic", "test", 1, seed=0)[0]
    points = select_columns(frame, det.config.point_features)
    return det, variables, label, points, Predictor(det, variables, score_threshold=0.1)


def rd_model_setup(name: str):
    """An RD model: (detector, variables, weights label, one synthetic test RD sample)."""
    from ... import zoo
    from ...data.rd.sources import load_rd_samples

    det = zoo.create(name)
    variables, label = bench_variables(det, name)
    return det, variables, label, load_rd_samples("synthetic", "test", 1, seed=0)[0]
