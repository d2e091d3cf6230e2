"""The embedded RD benchmark: an FMCW radar simulator that produces range-Doppler maps with boxes.

    from dsfec_jax.data.rd.synthetic import RDSyntheticConfig, generate_sample
    sample = generate_sample(RDSyntheticConfig(), "train", index=0, seed=0)   # an RDSample

Modules: config (every knob, RCS table, sensor, processing; benchmark versions), scene (labelled
actors), scatterers (extended bodies, micro-Doppler, static clutter, multipath ghosts), if_chain
(the IF filters' shape and the Tx->Rx coupling), spectra (frequency-domain
synthesis of the chain's spectra, noise, and a brute-force ADC cube), boxes (extent -> boxes,
Doppler wrap split), simulate (one sample), dataset (splits, determinism, cache).
"""

from .config import (BENCHMARK_VERSIONS, CLASS_MIX, CLASS_PROFILES, FORMAT_VERSION, ClassProfile, ClutterConfig,
                     RDSyntheticConfig, benchmark_config)
from .dataset import SPLITS, RDCachedDataset, RDSyntheticDataset, generate_sample, open_cache, read_manifest, sample_rng, write_cache
from .if_chain import IFChain
from .scene import Actor
from .simulate import simulate

__all__ = ["BENCHMARK_VERSIONS", "CLASS_MIX", "CLASS_PROFILES", "FORMAT_VERSION", "SPLITS", "Actor", "ClassProfile",
           "ClutterConfig", "IFChain", "benchmark_config",
           "RDCachedDataset", "RDSyntheticConfig", "RDSyntheticDataset", "generate_sample", "open_cache",
           "read_manifest", "sample_rng", "simulate", "write_cache"]
