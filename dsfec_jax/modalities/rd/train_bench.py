"""The training benchmark's batches for range-Doppler models (modality 'rd': the YOLO-RD family).

Made as modalities/rd/fit.py makes them: samples of the family's embedded benchmark
(data/rd/sources.load_rd_samples, data seed = the bench's seed), augmented, in both representations
(heat and gray), padded to a fixed number of boxes by data.rd.batches.RDBatchStream. The bench
settings of the point families (window, max_pillars, size_pillars, budget_frames) do not apply: an
RD model trains on whole maps with one compiled step (one "window"), and there are no pillar slots
to size, so only the `batch * distinct_batches` samples that are timed are made.
"""

from __future__ import annotations

import jax

from ... import zoo
from ...profile.training import model_names
from ...data.rd.representations import RDRepresentation

# modalities/rd/fit.py's default: the maps as they are (fit='pad'; 256 x 64 is a multiple of the strides)
REPRESENTATION = RDRepresentation()


def training_batches(name: str, overrides: dict, settings) -> tuple[zoo.Detector, list[dict], int]:
    """(the network a step trains, `settings.distinct_batches` device batches {'inputs', 'targets'}, 1)."""
    from ...data.rd.augment import RDAugment
    from ...data.rd.batches import RDBatchStream
    from ...data.rd.sources import load_rd_samples

    det = zoo.create(name, **overrides)
    family = zoo.family_of(det.config)
    samples = load_rd_samples(family.benchmark, "train", settings.batch * settings.distinct_batches, settings.seed)
    stream = RDBatchStream(samples, settings.batch, settings.seed, RDAugment(), REPRESENTATION,
                           det.config.classes)
    batches = [stream.batch(k) for k in range(settings.distinct_batches)]  # one epoch: every sample once
    return det, [jax.device_put({"inputs": b["inputs"], "targets": b["targets"]}) for b in batches], 1


def note(records: list[dict], settings: dict) -> str:
    """What the train-bench table's footer says of its range-Doppler `records` ('' for none)."""
    if not records:
        return ""
    shape = next(iter(records[0]["configs"][0]["input"].values()))
    return (f" Range-Doppler models ({model_names(records)}): batch {settings['batch']} whole "
            f"{shape[1]} x {shape[2]} RD maps (heat and gray) of the synthetic RD benchmark, augmented and with "
            "padded box targets as train/fit_rd.py makes them; windows and pillar slots do not apply; the step is the "
            "family's quick schedule's (ultralytics' SGD summing gradients to a nominal batch of 64).")
