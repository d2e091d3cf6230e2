"""What each benchmarked model runs on: the detector, its variables, one synthetic frame, and the
Predictor whose host NMS closes every chain.

Shipped weights are used when the model ships them (trained weights give a realistic score
distribution, so a realistic NMS load); otherwise random variables, labelled as such in the records.
"""

from __future__ import annotations

import jax


def model_setup(name: str):
    """(detector, variables, weights label, frame points, Predictor for the host NMS)."""
    from ... import zoo
    from ...core.defaults import RUN_PILLARS
    from ...data.points.pillarize import select_columns
    from ...data.points.sources import load_frames
    from ...predict import Predictor

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
