"""The training benchmark's batches for point-cloud models (DSFEC, RadarNeXt; profile/training.py
times them), made as modalities/points/fit.py makes them: frames of the family's embedded benchmark, augmented,
pillarized for a training window of `settings.window` cells and given the family's targets by
`data.batches.BatchStream`. The pillar slots are sized on `settings.budget_frames` train frames as
a training run sizes them (unless `settings.size_pillars` is False). A family whose network takes
the window's origin as an input (Family.points.origin_input) trains every window with one network,
so its batches come from several windows; the others compile one step per window (all of one
shape), so their batches all come from the first window.
"""

from __future__ import annotations

import jax

from ... import zoo


def fields(name: str, settings) -> dict:
    """The config fields the bench sets on a point model: its pillar slots."""
    return {"max_pillars": settings.max_pillars}


def training_batches(name: str, overrides: dict, settings) -> tuple[zoo.Detector, list[dict], int]:
    """(the network a step trains, `settings.distinct_batches` device batches {'inputs', 'targets'},
    the number of training windows)."""
    from ...data.batches import BatchStream
    from ...data.points.augment import AugmentConfig
    from ...data.points.pillarize import PillarSpec
    from ...data.points.sources import load_frames
    from .fit import window_detectors

    cfg = zoo.config(name, **overrides)
    family = zoo.family_of(cfg)
    used = settings.batch * settings.distinct_batches
    frames = load_frames(family.benchmark, "train", max(used, settings.budget_frames), settings.seed,
                         features=family.points.input_columns)
    # slots sized as a training run on this benchmark sizes them (modalities/points/fit.py), not on the few frames timed
    windows = window_detectors(cfg, settings.window, frames if settings.size_pillars else None)
    frames = [frames[i] for i in range(used)]
    stream = BatchStream(frames, [PillarSpec.of(w.config) for w in windows], family.points.targets(cfg), settings.batch,
                         settings.seed, AugmentConfig(), origin_input=family.points.origin_input)
    # cycled windows: step s trains window s % n; one network serves all windows only with origin inputs
    stride = 1 if family.points.origin_input else len(windows)
    batches = [stream.batch(k * stride) for k in range(settings.distinct_batches)]
    if not family.points.origin_input and any(b["window"] != 0 for b in batches):
        raise RuntimeError("train bench: expected every batch on the first window (BatchStream cycles windows)")
    return windows[0], [jax.device_put({"inputs": b["inputs"], "targets": b["targets"]}) for b in batches], len(windows)


def note(records: list[dict], settings: dict) -> str:
    """The point models need no footer note: the table's columns are theirs."""
    return ""
