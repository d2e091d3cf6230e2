"""The RD benchmark's IF chain and Tx->Rx coupling, fitted to the real TI capture:
python -m experiments.rd_capture_fit [--out FILE]

1. The IF chain (data/rd/synthetic/if_chain.py): each range row's floor (the median over its
   Doppler columns, in dB, against the far rows' 70-90 %) of both capture files, averaged, is
   fitted by least squares over rows 1.. (row 0 is emptied by DC removal) with the chain's noise
   profile: high-pass corner and the noise share it shapes, low-pass corner and stop band, for
   each low-pass order of ORDERS (the best is kept).
2. The coupling: the zero-Doppler column of rows 0-2 over the map's median, where the leakage
   sits, fitted per file by the coupling alone through the chain (its fractional bin on a grid,
   its level in closed form: a dB offset), with the fitted IF chain and the file's own channel count.
The defaults of IFChain are these figures rounded; --out writes them with the command and versions.
"""

from __future__ import annotations

if __name__ == "__main__":  # a command that may load JAX through the package: its process settings first
    from dsfec_jax.core.host_memory import prepare_xla_process

    prepare_xla_process()  # may restart this command (core/host_memory.py)

import argparse
import dataclasses
import json
import os
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from dsfec_jax.core.atomic import write_text
from dsfec_jax.core.provenance import versions
from dsfec_jax.data.rd.processing import RDProcessing, spectra_to_rd
from dsfec_jax.data.rd.stats import FAR_ROWS
from dsfec_jax.data.rd.synthetic.if_chain import IFChain
from dsfec_jax.data.rd.synthetic.simulate import coupling_scatterer
from dsfec_jax.data.rd.synthetic.spectra import add_processed_noise, add_static_spectra, white_spectrum
from dsfec_jax.data.rd.ti_adc import CAPTURES, load_ti_sample

ORDERS = (4, 8, 12, 16, 24, 32)
COUPLING_BINS = np.arange(0.5, 2.0, 0.05)
NOISE_COUNTS_RMS = 6.5  # any level: only the coupling's level over the noise is fitted
DEFAULT_CAPTURE = Path(os.environ.get("DSFEC_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")) \
    / "openradar_ti_adc"  # as experiments/camera_tables.py finds the shared data


def far_rows(n: int) -> slice:
    return slice(int(round(FAR_ROWS[0] * n)), int(round(FAR_ROWS[1] * n)))


def floor_profile(power_db: np.ndarray) -> np.ndarray:
    floors = np.median(power_db, axis=1)
    return floors - np.median(floors[far_rows(len(floors))])


def fit_if_chain(profile: np.ndarray) -> tuple[IFChain, float]:
    """The chain whose noise profile (dB against its far rows) best fits `profile` over rows 1..."""
    n, rows = len(profile), np.arange(1, len(profile))

    def chain(p, order) -> IFChain:
        return IFChain(highpass_corner=p[0], highpass_noise_share=p[1], lowpass_corner=p[2], lowpass_order=order,
                       stopband_db=p[3], coupling_snr_db=None)

    best = None
    for order in ORDERS:
        def residual(p):
            return floor_profile(10 * np.log10(chain(p, order).noise_power_profile(n))[:, None])[rows] - profile[rows]
        fit = least_squares(residual, [0.1, 0.7, 0.93, -10.0], bounds=([0.005, 0.0, 0.8, -40.0], [0.5, 1.0, 1.0, 0.0]))
        rms = float(np.sqrt(np.mean(fit.fun ** 2)))
        if best is None or rms < best[1]:
            best = (chain(fit.x, order), rms)
    return best


def fit_coupling(power_db: np.ndarray, sensor, chain: IFChain, processing: RDProcessing) -> dict:
    """Fractional bin and SNR per ADC sample of the coupling that best gives rows 0-2 of the zero column."""
    zero = power_db.shape[1] // 2
    want = power_db[:3, zero] - np.median(power_db)
    shape = (sensor.num_samples, sensor.num_chirps, sensor.num_channels)
    white = white_spectrum(np.random.default_rng(0), sensor, NOISE_COUNTS_RMS, complex)
    noise = add_processed_noise(np.zeros(shape, complex), white, processing, chain)
    median = float(np.median(spectra_to_rd(noise, processing)[0])) * 10
    best = None
    for b in COUPLING_BINS:
        unit = dataclasses.replace(chain, coupling_snr_db=0.0, coupling_bin=float(b))
        spectra = add_static_spectra(np.zeros(shape, complex), coupling_scatterer(unit, sensor), sensor, processing,
                                     NOISE_COUNTS_RMS, unit)
        got = 10 * np.log10(np.sum(np.abs(spectra[:3, zero]) ** 2, axis=1)) - median
        offset = float(np.mean(want - got))
        rms = float(np.sqrt(np.mean((got + offset - want) ** 2)))
        if best is None or rms < best["rms_db"]:
            best = dict(bin=round(float(b), 2), snr_db=round(offset, 2), rms_db=round(rms, 2))
    return best


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m experiments.rd_capture_fit", description=__doc__.splitlines()[0])
    p.add_argument("--capture", default=None, help="the TI capture directory (default $DSFEC_DATA/openradar_ti_adc)")
    p.add_argument("--out", default=None, help="write the fit as JSON here")
    args = p.parse_args(argv)
    capture = args.capture or DEFAULT_CAPTURE
    processing = RDProcessing()
    maps = {name: load_ti_sample(capture, name, processing) for name in CAPTURES}
    profile = np.mean([floor_profile(m.power * 10.0) for m in maps.values()], axis=0)
    chain, rms = fit_if_chain(profile)
    coupling = {name: fit_coupling(m.power * 10.0, m.sensor, chain, processing) for name, m in maps.items()}
    record = {"command": "python -m experiments.rd_capture_fit " + " ".join(sys.argv[1:] if argv is None else argv),
              "if_chain": {k: round(v, 4) if isinstance(v, float) else v for k, v in dataclasses.asdict(chain).items()
                           if not k.startswith("coupling")},
              "floor_fit_rms_db": round(rms, 3), "coupling": coupling,
              "versions": versions(("numpy", "scipy", "dsfec_jax"))}
    text = json.dumps(record, indent=2)
    print(text)
    if args.out:
        write_text(args.out, text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
