"""Per-channel RD spectra of point scatterers and of thermal noise, synthesised in the frequency
domain: exactly what processing.rd_spectra returns for the ADC cube `adc_cube` would simulate,
at a fraction of the cost.

Signal model (TI's FMCW IF signal, reference-spec §4), scatterer i at range R, radial velocity v
(positive = receding), azimuth theta, in ADC sample n of chirp m of virtual channel c = tx N_rx + rx:
    a_i exp(j [phi_i + 2 pi (2 S R / c0 + f_D) n / F_s + 2 pi f_D (m N_tx + tx) T_c
               + 2 pi d sin(theta) c])
with the Doppler frequency f_D = 2 v / lambda, T_c the chirp interval (TDM: Tx `tx` fires tx T_c
after Tx 0, so the channels of the second Tx see the Doppler phase of that delay), d the virtual
ULA spacing in wavelengths. The amplitude a_i = noise_counts_rms sqrt(SNR_i) in ADC counts, with
SNR_i = P_r / (kT B NF) per sample from the radar equation
    P_r = P_t G_t G_r lambda^2 sigma / ((4 pi)^3 R^4 L).
The IF chain (if_chain.py) scales a_i by its steady-state gain at the scatterer's beat frequency
and shapes the noise per range bin; the Tx->Rx coupling is one more static scatterer.
Range migration within a frame is ignored: R is fixed for the frame's 64 x 2 x 36 us = 4.6 ms,
over which 13.4 m/s moves a target 6 cm, a third of a 0.195 m range bin (the fast-time Doppler
term f_D n / F_s, which is even smaller, is kept).

Why the frequency-domain synthesis is exact: each scatterer's signal is separable, r_i[n] d_i[m]
g_i[c]. DC removal (subtracting the mean over n), the windows and the FFTs are linear and act on
one axis each, so the chain maps it to a_i R_i[k] D_i[l] g_i[c] with R_i = range_transform(r_i)
and D_i = doppler_transform(d_i), two 1-D transforms. The cube is the sum over scatterers,
X = R^T (D (x) g), one matrix product (N x K) @ (K x M C). Static scatterers (v = 0) share one
Doppler response D_0, so their part is (R^T g) (x) D_0, which is nonzero only where D_0 is (three
columns for Hann or Hamming, one for no window). tests/data/rd/test_rd_synthetic.py checks the
result against a brute-force time-domain simulation and the chain, with and without the IF chain.

Noise: white circular complex Gaussian ADC noise n (E|n|^2 = sigma^2) has an unnormalised 2-D DFT
W that is again white circular Gaussian with E|W|^2 = N M sigma^2 (the DFT over N M points is
sqrt(N M) times a unitary map, and unitary maps keep that law). So W is drawn directly (by the
polar method, `complex_gaussian`); then the chain's steps are applied in the frequency domain:
DC removal zeros range bin 0 (the mean over samples is bin 0 of the range DFT), each periodic
cosine window is the 3-tap circular convolution of processing.window_spectrum, then the Doppler
fftshift. This equals the chain run on the ADC noise ifft2(W) to float rounding (tested), and
costs a 3-tap stencil per axis instead of two FFTs over the whole cube. The IF chain's noise
shaping multiplies W by a gain per range bin first (the ADC noise is then ifft2 of that product).
Drawing the noise is still the largest single cost of a sample.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..processing import RDProcessing, doppler_transform, range_transform, window_spectrum
from ..sensor import SPEED_OF_LIGHT, FMCWSensor
from .if_chain import NO_IF_CHAIN, IFChain
from .scatterers import Scatterers

FOUR_PI_CUBED_DB = 30 * math.log10(4 * math.pi)


def snr_db(s: Scatterers, sensor: FMCWSensor) -> np.ndarray:
    """Radar-equation SNR of each scatterer in one ADC sample of one channel, dB."""
    received_dbm = (sensor.tx_power_dbm + 2 * sensor.antenna_gain_dbi + 20 * math.log10(sensor.wavelength_m)
                    + 10 * np.log10(np.maximum(s.rcs_m2, 1e-30)) - FOUR_PI_CUBED_DB
                    - 40 * np.log10(np.maximum(s.range_m, 1e-3)) - sensor.system_loss_db)
    return received_dbm - sensor.noise_power_dbm


def complex_amplitudes(s: Scatterers, sensor: FMCWSensor, noise_counts_rms: float,
                       if_chain: IFChain = NO_IF_CHAIN) -> np.ndarray:
    """In ADC counts, after the IF chain's steady-state gain at each scatterer's beat frequency."""
    a = noise_counts_rms * np.power(10.0, snr_db(s, sensor) / 20) * np.exp(1j * s.phase_rad)
    return a if if_chain.is_flat else a * if_chain.tone_gain(fast_time_cycles(s, sensor))


def doppler_hz(s: Scatterers, sensor: FMCWSensor) -> np.ndarray:
    return 2 * s.velocity_mps / sensor.wavelength_m


def tones(cycles: np.ndarray, n: int, block: int = 16) -> np.ndarray:
    """exp(2 pi j cycles_i t) for t = 0..n-1, (K, n) complex128, as the outer product of a coarse
    (t = block q) and a fine (t = r) table: 2 n / block exponentials per row instead of n."""
    q = -(-n // block)
    coarse = np.exp(2j * np.pi * np.outer(cycles, np.arange(q) * block))
    fine = np.exp(2j * np.pi * np.outer(cycles, np.arange(block)))
    return (coarse[:, :, None] * fine[:, None, :]).reshape(len(cycles), q * block)[:, :n]


def fast_time_cycles(s: Scatterers, sensor: FMCWSensor) -> np.ndarray:
    """Beat plus Doppler frequency in cycles per ADC sample."""
    return (2 * sensor.slope_hz_per_s * s.range_m / SPEED_OF_LIGHT + doppler_hz(s, sensor)) / sensor.sample_rate_hz


def range_factors(s: Scatterers, sensor: FMCWSensor, processing: RDProcessing) -> np.ndarray:
    """R_i[k] (K, num_samples): the chain's range transform of each scatterer's fast-time tone."""
    return range_transform(tones(fast_time_cycles(s, sensor), sensor.num_samples), processing, axis=1)


def doppler_factors(s: Scatterers, sensor: FMCWSensor, processing: RDProcessing) -> np.ndarray:
    """D_i[l] (K, num_chirps): the chain's Doppler transform (fftshifted) of each slow-time tone."""
    cycles = doppler_hz(s, sensor) * sensor.chirp_interval_s * sensor.num_tx
    return doppler_transform(tones(cycles, sensor.num_chirps), processing, axis=1)


def channel_factors(s: Scatterers, sensor: FMCWSensor, noise_counts_rms: float,
                    if_chain: IFChain = NO_IF_CHAIN) -> np.ndarray:
    """a_i g_i[c] (K, num_channels): amplitude, angle phase on the virtual ULA, TDM Doppler phase."""
    c = np.arange(sensor.num_channels)
    tx = c // sensor.num_rx
    spatial = 2 * np.pi * sensor.antenna_spacing_wavelengths * np.outer(np.sin(s.azimuth_rad), c)
    tdm = 2 * np.pi * np.outer(doppler_hz(s, sensor) * sensor.chirp_interval_s, tx)
    return complex_amplitudes(s, sensor, noise_counts_rms, if_chain)[:, None] * np.exp(1j * (spatial + tdm))


@dataclasses.dataclass(frozen=True)
class SpectralFactors:
    """The separable factors of K moving scatterers: X = range^T @ doppler_channel."""
    range: np.ndarray            # (K, N) R_i[k]
    doppler_channel: np.ndarray  # (K, M * C) D_i[l] a_i g_i[c]
    shape: tuple[int, int, int]  # (N, M, C)

    @classmethod
    def of(cls, s: Scatterers, sensor: FMCWSensor, processing: RDProcessing, noise_counts_rms: float,
           dtype=np.complex64, if_chain: IFChain = NO_IF_CHAIN) -> "SpectralFactors":
        m, c = sensor.num_chirps, sensor.num_channels
        d = doppler_factors(s, sensor, processing)
        dg = d[:, :, None] * channel_factors(s, sensor, noise_counts_rms, if_chain)[:, None, :]
        return cls(range_factors(s, sensor, processing).astype(dtype), dg.reshape(len(s), m * c).astype(dtype),
                   (sensor.num_samples, m, c))

    def spectra(self, rows: slice = slice(None), scatterers: slice = slice(None)) -> np.ndarray:
        """Sum over `scatterers` of R_i[k] D_i[l] a_i g_i[c] for range bins `rows`: (rows, M, C)."""
        r = self.range[scatterers, rows]
        n_rows = len(range(self.shape[0])[rows])
        return (r.T @ self.doppler_channel[scatterers]).reshape(n_rows, *self.shape[1:])


def moving_spectra(s: Scatterers, sensor: FMCWSensor, processing: RDProcessing, noise_counts_rms: float,
                   rows: slice = slice(None), dtype=np.complex64, if_chain: IFChain = NO_IF_CHAIN) -> np.ndarray:
    """Sum over scatterers of R_i[k] D_i[l] a_i g_i[c] for range bins `rows`: (rows, M, C)."""
    return SpectralFactors.of(s, sensor, processing, noise_counts_rms, dtype, if_chain).spectra(rows)


def add_static_spectra(out: np.ndarray, s: Scatterers, sensor: FMCWSensor, processing: RDProcessing,
                       noise_counts_rms: float, if_chain: IFChain = NO_IF_CHAIN) -> np.ndarray:
    """out += spectra of zero-velocity scatterers, (range_transform(sum_i tone_i g_i)) (x) D_0, on
    the columns where D_0 != 0. The range transform is linear, so the scatterers are summed in
    fast time first: one transform of (N, C) instead of one per scatterer."""
    if len(s) == 0:
        return out
    if np.any(s.velocity_mps != 0):
        raise ValueError("add_static_spectra: every scatterer must have velocity 0")
    d0 = doppler_factors(s.select(slice(0, 1)), sensor, processing)[0]
    cols = np.flatnonzero(np.abs(d0) > 1e-9 * np.abs(d0).max())  # exactly zero elsewhere, up to rounding
    fast = (tones(fast_time_cycles(s, sensor), sensor.num_samples).T
            @ channel_factors(s, sensor, noise_counts_rms, if_chain))
    a = range_transform(fast, processing, axis=0)  # (N, C)
    out[:, cols, :] += (a[:, None, :] * d0[None, cols, None]).astype(out.dtype)
    return out


def complex_gaussian(rng: np.random.Generator, shape: tuple[int, ...], scale: float,
                     dtype=np.complex64) -> np.ndarray:
    """i.i.d. circular complex Gaussian values with E|z|^2 = scale^2, by the polar method: |z|^2 =
    -scale^2 ln u is exponential and arg z = 2 pi v uniform, independent, which is exactly the
    circular complex Gaussian law; u = (hi + 1/2) / 2^32 and v = lo / 2^32 come from the two
    32-bit halves of one 64-bit draw of the generator. The draw's resolution cuts |z|^2 at
    22 scale^2 (probability 2e-10 per value). Faster than standard_normal here (docs/range-doppler.md
    has the timing and the command): drawing the noise is the largest single cost of a sample."""
    n = math.prod(shape)
    real = np.float32 if np.dtype(dtype) == np.complex64 else np.float64
    raw = rng.bit_generator.random_raw(n)
    u = (raw >> np.uint64(32)).astype(real)
    u += real(0.5)
    u *= real(2.0 ** -32)
    np.minimum(u, real(1.0), out=u)  # float32 rounding can reach 1 (|z| = 0), never 0
    np.log(u, out=u)
    np.negative(u, out=u)
    np.sqrt(u, out=u)
    u *= real(scale)
    theta = (raw & np.uint64(0xFFFFFFFF)).astype(real)
    theta *= real(2 * math.pi * 2.0 ** -32)
    out = np.empty(n, dtype)
    parts = out.view(real).reshape(n, 2)
    np.multiply(np.cos(theta), u, out=parts[:, 0])
    np.multiply(np.sin(theta), u, out=parts[:, 1])
    return out.reshape(shape)


def white_spectrum(rng: np.random.Generator, sensor: FMCWSensor, noise_counts_rms: float,
                   dtype=np.complex64) -> np.ndarray:
    """W = unnormalised 2-D DFT (samples, chirps) of white ADC noise with E|n|^2 = noise_counts_rms^2:
    i.i.d. circular complex Gaussian with E|W|^2 = N M noise_counts_rms^2. (N, M, C)."""
    n, m, c = sensor.num_samples, sensor.num_chirps, sensor.num_channels
    return complex_gaussian(rng, (n, m, c), noise_counts_rms * math.sqrt(n * m), dtype)


def add_processed_noise(out: np.ndarray, white: np.ndarray, processing: RDProcessing,
                        if_chain: IFChain = NO_IF_CHAIN) -> np.ndarray:
    """out += the chain's spectra of the ADC noise whose unnormalised 2-D DFT is `white` (which is
    overwritten) shaped by the IF chain (if_chain.py: a gain per range bin of that DFT): DC removal
    zeros range bin 0, the windows are 3-tap circular convolutions, and the Doppler fftshift is
    folded into the addition."""
    if not if_chain.is_flat:
        white *= np.sqrt(if_chain.noise_power_profile(white.shape[0])).astype(white.real.dtype)[:, None, None]
    if processing.dc_removal:
        white[0] = 0
    scratch = np.empty_like(white)
    window_spectrum(white, processing.window, axis=0, inplace=True, scratch=scratch)
    window_spectrum(white, processing.window, axis=1, inplace=True, scratch=scratch)
    m = white.shape[1]
    half = m // 2  # fftshift: bin l goes to column (l + m // 2) % m
    out[:, half:] += white[:, :m - half]
    out[:, :half] += white[:, m - half:]
    return out


def processed_noise(white: np.ndarray, processing: RDProcessing, if_chain: IFChain = NO_IF_CHAIN) -> np.ndarray:
    """The chain's spectra of the ADC noise whose unnormalised 2-D DFT is `white` (overwritten)."""
    return add_processed_noise(np.zeros_like(white), white, processing, if_chain)


def adc_cube(s: Scatterers, sensor: FMCWSensor, noise_counts_rms: float, if_chain: IFChain = NO_IF_CHAIN) -> np.ndarray:
    """Brute-force time-domain ADC cube (num_samples, num_chirps, num_channels) complex128 of the
    scatterers, noise-free, written from physical times (each tone scaled by the IF chain's
    steady-state gain at its beat frequency): for tests on tiny sensors and for anyone who wants
    the raw cube (it costs K N M C complex exponentials)."""
    n, m, ch = sensor.num_samples, sensor.num_chirps, sensor.num_channels
    t_fast = np.arange(n)[:, None, None] / sensor.sample_rate_hz
    tx = (np.arange(ch) // sensor.num_rx)[None, None, :]
    t_chirp = (np.arange(m)[None, :, None] * sensor.num_tx + tx) * sensor.chirp_interval_s
    element = np.arange(ch)[None, None, :]
    out = np.zeros((n, m, ch), np.complex128)
    for a, r, fd, az in zip(complex_amplitudes(s, sensor, noise_counts_rms, if_chain), s.range_m, doppler_hz(s, sensor),
                            s.azimuth_rad):
        beat = 2 * sensor.slope_hz_per_s * r / SPEED_OF_LIGHT
        phase = (beat * t_fast + fd * (t_fast + t_chirp)
                 + sensor.antenna_spacing_wavelengths * np.sin(az) * element)
        out += a * np.exp(2j * np.pi * phase)
    return out
