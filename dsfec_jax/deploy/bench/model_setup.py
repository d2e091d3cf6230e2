"""The variables every benchmarked model runs with, whatever its modality (each modality's bench
module, modalities/<m>/bench.py, adds its detector, its synthetic frame and its chains).

Shipped weights are used when the model ships them (trained weights give a realistic score
distribution, so a realistic NMS load); otherwise the detector's own initial variables, labelled
'random' in the records.
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
