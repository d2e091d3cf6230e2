"""One synthetic RD sample: scene -> scatterers -> per-channel spectra + noise -> the chain's
integration -> RD map, with boxes from each object's own extent (boxes.py).

Order of random draws (fixed, so a sample is a pure function of its generator): actors, then
per actor its scatterers, clutter, ghosts, benchmark v2's static scene (area clutter, point
reflectors: nothing drawn when they are off, so v1's samples are unchanged), and last the noise.
The Tx->Rx coupling draws nothing: its phase is the device's, fixed.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from ....boxes.boxes2d import Boxes2D
from ....core.blas import single_threaded_blas
from ..processing import noise_floor_gain, spectra_to_rd
from ..sample import RDAxes, RDSample
from ..sensor import FMCWSensor
from .boxes import extent_boxes
from .config import RDSyntheticConfig
from .if_chain import IFChain
from .scatterers import Scatterers, clutter_scatterers, ghost_of, object_scatterers, static_scene_scatterers
from .scene import Actor, sample_actors
from .spectra import SpectralFactors, add_processed_noise, add_static_spectra, fast_time_cycles, snr_db, white_spectrum


@functools.lru_cache(maxsize=8)
def mean_floor_power(cfg: RDSyntheticConfig) -> float:
    """Mean noise power of one cell of the channel-summed power map in the IF chain's pass band (the
    median over cells of the exact expectation of a flat chain, which cells away from range bin 0
    all have; the chain shapes it per range bin by if_chain.noise_power_profile)."""
    gain = noise_floor_gain(cfg.sensor, cfg.processing)
    return float(cfg.sensor.num_channels * cfg.noise_counts_rms ** 2 * np.median(gain))


def coupling_scatterer(if_chain: IFChain, sensor: FMCWSensor) -> Scatterers:
    """The Tx->Rx coupling as a static scatterer at coupling_bin whose RCS gives coupling_snr_db per
    ADC sample after the IF chain (phase 0, boresight); empty without coupling."""
    if if_chain.coupling_snr_db is None:
        return Scatterers.empty()
    one = np.ones(1)
    unit = Scatterers(np.array([if_chain.coupling_bin * sensor.range_resolution_m]), 0 * one, 0 * one, one, 0 * one)
    gain_db = 20 * np.log10(np.maximum(if_chain.tone_gain(fast_time_cycles(unit, sensor)), 1e-15))
    rcs = 10 ** ((if_chain.coupling_snr_db - snr_db(unit, sensor) - gain_db) / 10)
    return dataclasses.replace(unit, rcs_m2=rcs)


def object_boxes(factors: SpectralFactors, members: slice, s: Scatterers, cfg: RDSyntheticConfig) -> list[tuple]:
    """Boxes of one object's extent (its scatterers `members` of `factors`): its own power above
    the mean floor + box_threshold_db, searched within box_margin_bins rows of its scatterers."""
    sensor = cfg.sensor
    bins = s.range_m / sensor.range_resolution_m
    lo = max(0, int(np.floor(bins.min())) - cfg.box_margin_bins)
    hi = min(sensor.num_samples, int(np.ceil(bins.max())) + 1 + cfg.box_margin_bins)
    x = factors.spectra(slice(lo, hi), members)
    flat = x.view(x.real.dtype).reshape(*x.shape[:2], -1)
    power = np.einsum("rmc,rmc->rm", flat, flat)  # sum over channels of |X|^2 (re^2 + im^2)
    return extent_boxes(power > mean_floor_power(cfg) * 10 ** (cfg.box_threshold_db / 10), lo)


def render(rng: np.random.Generator, cfg: RDSyntheticConfig, actors: list[Actor], dtype=np.complex64):
    """-> (spectra (R, D, C), boxes xyxy list, box names, box -> actor index, per-actor scatterers)."""
    per_actor = [object_scatterers(rng, a, cfg.profile(a.name), cfg.body_interior_share) for a in actors]
    static = clutter_scatterers(rng, cfg)
    ghosts = [ghost_of(rng, s, cfg) for s in per_actor if rng.random() < cfg.clutter.ghost_prob]
    static = Scatterers.concat([static, static_scene_scatterers(rng, cfg), coupling_scatterer(cfg.if_chain, cfg.sensor)])
    moving = Scatterers.concat(per_actor + ghosts)
    chain = cfg.if_chain
    factors = SpectralFactors.of(moving, cfg.sensor, cfg.processing, cfg.noise_counts_rms, dtype, chain)
    spectra = factors.spectra()
    add_static_spectra(spectra, static, cfg.sensor, cfg.processing, cfg.noise_counts_rms, chain)
    add_processed_noise(spectra, white_spectrum(rng, cfg.sensor, cfg.noise_counts_rms, dtype), cfg.processing, chain)
    boxes, names, owner = [], [], []
    start = 0
    for i, (a, s) in enumerate(zip(actors, per_actor)):
        for box in object_boxes(factors, slice(start, start + len(s)), s, cfg):
            boxes.append(box)
            names.append(a.name)
            owner.append(i)
        start += len(s)
    return spectra, boxes, names, owner, per_actor


def simulate(rng: np.random.Generator, cfg: RDSyntheticConfig, sample_id: str = "", meta: dict | None = None,
             actors: list[Actor] | None = None) -> RDSample:
    """A sample of a random scene (or of the given `actors`, still with random clutter and noise)."""
    actors = sample_actors(rng, cfg) if actors is None else list(actors)
    with single_threaded_blas():  # small products: BLAS threads only spin (core/blas.py)
        spectra, boxes, names, owner, _ = render(rng, cfg, actors)
        power, scale = spectra_to_rd(spectra, cfg.processing)
    xyxy = np.asarray(boxes, np.float32).reshape(-1, 4)
    labelled = np.zeros(len(actors), bool)
    labelled[owner] = True
    meta = dict(meta or {})
    meta.update(
        box_object=np.asarray(owner, np.int64),
        object_names=np.asarray([a.name for a in actors], "<U16"),
        object_range_m=np.asarray([a.range_m for a in actors], np.float32),
        object_velocity_mps=np.asarray([a.radial_velocity for a in actors], np.float32),
        object_rcs_dbsm=np.asarray([a.rcs_dbsm for a in actors], np.float32),
        object_labelled=labelled)
    return RDSample(power, RDAxes.of_sensor(cfg.sensor), Boxes2D(xyxy, np.asarray(names, "<U16")), cfg.sensor,
                    scale, sample_id=sample_id, source="rd-synthetic", meta=meta)
