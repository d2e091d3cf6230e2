"""ADC cube -> range-Doppler map: the one processing chain every ADC source (the simulator, a TI
capture) goes through.

    adc (num_samples, num_chirps, num_channels) complex
      -> DC removal: subtract the mean over the samples of every chirp and channel (the
         community RADDet ADC->RD recipe, RADDet issue 40; it removes the ADC's offset, which
         would otherwise fill range bin 0). It does not remove the Tx->Rx leakage: that is a tone
         at a small but nonzero beat frequency (about range bin 1 on the TI capture), which stays
         the map's maximum with or without DC removal (docs/range-doppler.md measures it)
      -> window on range (samples) and on Doppler (chirps): 'hann' (default), 'hamming' or 'none'
      -> range FFT over the samples, Doppler FFT over the chirps, fftshift on Doppler
      -> antenna integration over the channels (integration.py): 'power_sum' (default, RADDet's
         visualisation and CARRADA's `to_rd`: sum |X|^2, then log10(. + 1)) or 'log_sum' (DAROD)
      -> optionally RADDet's normalisation (x - 3.2438383) / 6.8367246 of the log10 map.

Choices, and why:
- The windows are *periodic* (DFT-even) cosine windows, w[n] = a0 - a1 cos(2 pi n / N) (what
  scipy.signal.get_window returns with fftbins=True, the spectral-analysis convention), not
  numpy's symmetric np.hanning. Their spectrum has exactly three taps, a0 at 0 and -a1/2 at +-1
  bin, so windowing is a 3-tap circular convolution of the spectrum. The simulator relies on it
  to draw windowed noise spectra directly in the frequency domain (`window_spectrum`), exactly.
- No zero padding: range bin k is k * range resolution and the Doppler columns are the sensor's
  velocity axis (FMCWSensor.range_axis / velocity_axis), so the map is in canonical orientation:
  rows near -> far, columns ascending radial velocity, negative = approaching.
- The FFTs are unnormalised (numpy's default): a tone of amplitude a in ADC counts peaks at
  a * sum(w_r) * sum(w_d) per channel, and the map keeps ADC-count units under log10(. + 1).
- The precision follows the input: complex64 in, complex64 spectra out (the simulator's speed);
  complex128 in, complex128 out (tests, real captures).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .integration import INTEGRATIONS, integrate, normalise_raddet
from .sensor import FMCWSensor

# name -> (a0, a1) of the periodic cosine window a0 - a1 cos(2 pi n / N)
WINDOWS = {"hann": (0.5, 0.5), "hamming": (0.54, 0.46), "none": (1.0, 0.0)}


@dataclasses.dataclass(frozen=True)
class RDProcessing:
    window: str = "hann"
    integration: str = "power_sum"
    raddet_normalise: bool = False
    dc_removal: bool = True

    def __post_init__(self):
        if self.window not in WINDOWS:
            raise ValueError(f"RDProcessing.window={self.window!r}; expected one of {tuple(WINDOWS)}")
        if self.integration not in INTEGRATIONS:
            raise ValueError(f"RDProcessing.integration={self.integration!r}; expected one of {INTEGRATIONS}")
        if self.raddet_normalise and self.integration == "log_sum":
            raise ValueError("RDProcessing: integration='log_sum' already normalises every cell the RADDet way; "
                             "raddet_normalise=True applies only to 'power_sum'")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def window(name: str, n: int, dtype=np.float64) -> np.ndarray:
    """The periodic window of length n: a0 - a1 cos(2 pi k / n)."""
    a0, a1 = WINDOWS[name]
    return (a0 - a1 * np.cos(2 * np.pi * np.arange(n) / n)).astype(dtype)


def window_spectrum(spectrum: np.ndarray, name: str, axis: int, inplace: bool = False,
                    scratch: np.ndarray | None = None) -> np.ndarray:
    """fft(w * x) from X = fft(x) along `axis` (unshifted bins): a0 X[k] - (a1 / 2) (X[k-1] + X[k+1]),
    circularly. With inplace=True it overwrites `spectrum` (and uses `scratch`, an array of the
    same shape and dtype, if given): the simulator runs this on every noise cube, where fresh
    1 MB temporaries cost more than the arithmetic (page faults)."""
    a0, a1 = WINDOWS[name]
    if not inplace:
        spectrum = spectrum.copy()
    if a1 == 0.0:
        if a0 != 1.0:
            spectrum *= a0
        return spectrum
    if spectrum.shape[axis] < 3:
        spectrum[...] = a0 * spectrum - (a1 / 2) * (np.roll(spectrum, 1, axis) + np.roll(spectrum, -1, axis))
        return spectrum
    x = np.moveaxis(spectrum, axis, 0)
    nb = np.moveaxis(np.empty_like(spectrum) if scratch is None else scratch, axis, 0)
    np.add(x[:-2], x[2:], out=nb[1:-1])
    np.add(x[-1], x[1], out=nb[0])
    np.add(x[-2], x[0], out=nb[-1])
    nb *= x.real.dtype.type(a1 / 2)
    x *= x.real.dtype.type(a0)
    x -= nb
    return spectrum


def range_transform(x: np.ndarray, processing: RDProcessing, axis: int = 0) -> np.ndarray:
    """DC removal, range window and range FFT along `axis` (the samples)."""
    x = np.asarray(x)
    if processing.dc_removal:
        x = x - x.mean(axis=axis, keepdims=True)
    shape = [1] * x.ndim
    shape[axis] = x.shape[axis]
    w = window(processing.window, x.shape[axis], x.real.dtype).reshape(shape)
    return np.fft.fft(x * w, axis=axis)


def doppler_transform(x: np.ndarray, processing: RDProcessing, axis: int = 1) -> np.ndarray:
    """Doppler window, FFT and fftshift along `axis` (the chirps)."""
    x = np.asarray(x)
    shape = [1] * x.ndim
    shape[axis] = x.shape[axis]
    w = window(processing.window, x.shape[axis], x.real.dtype).reshape(shape)
    return np.fft.fftshift(np.fft.fft(x * w, axis=axis), axes=axis)


def check_adc(adc: np.ndarray, sensor: FMCWSensor | None, where: str = "adc") -> np.ndarray:
    adc = np.asarray(adc)
    if adc.ndim != 3 or not np.iscomplexobj(adc):
        raise ValueError(f"{where}: expected a complex (num_samples, num_chirps, num_channels) cube; "
                         f"got {adc.dtype} of shape {adc.shape}")
    if sensor is not None:
        want = (sensor.num_samples, sensor.num_chirps, sensor.num_channels)
        if adc.shape != want:
            raise ValueError(f"{where}: shape {adc.shape} does not match the sensor's (num_samples, num_chirps, "
                             f"num_channels) = {want}")
    if not np.all(np.isfinite(adc)):
        raise ValueError(f"{where}: the ADC cube holds non-finite values")
    return adc


def rd_spectra(adc: np.ndarray, sensor: FMCWSensor | None = None,
               processing: RDProcessing = RDProcessing()) -> np.ndarray:
    """Complex per-channel RD spectra (num_samples range bins, num_chirps Doppler bins, channels),
    Doppler fftshifted: everything of the chain before the antenna integration."""
    adc = check_adc(adc, sensor)
    return doppler_transform(range_transform(adc, processing, axis=0), processing, axis=1)


def spectra_to_rd(spectra: np.ndarray, processing: RDProcessing = RDProcessing()) -> tuple[np.ndarray, str]:
    """Antenna integration (and the optional RADDet normalisation): -> (map float32 (R, D), scale)."""
    rd, scale = integrate(spectra, axis=2, method=processing.integration)
    if processing.raddet_normalise:
        rd, scale = normalise_raddet(rd).astype(np.float32), "normalised"
    return rd, scale


def adc_to_rd(adc: np.ndarray, sensor: FMCWSensor | None = None,
              processing: RDProcessing = RDProcessing()) -> tuple[np.ndarray, str]:
    """The whole chain: ADC cube -> (RD map float32 (num_samples, num_chirps), its scale)."""
    return spectra_to_rd(rd_spectra(adc, sensor, processing), processing)


def noise_floor_gain(sensor_or_shape, processing: RDProcessing = RDProcessing()) -> np.ndarray:
    """E|X[k, l]|^2 per unit-variance complex white ADC noise in one channel, (R, D) float64.

    The chain is linear: X = A x B^T per channel, so the expected power of a cell is
    sum |A_k.|^2 * sum |B_l.|^2. Flat (N M mean(w_r^2) mean(w_d^2)) except where DC removal
    takes the noise out (range bin 0 and, by window leakage, its neighbours)."""
    n, m = ((sensor_or_shape.num_samples, sensor_or_shape.num_chirps) if isinstance(sensor_or_shape, FMCWSensor)
            else sensor_or_shape)
    a = range_transform(np.eye(n, dtype=complex), processing, axis=0)   # column j: response to sample j
    b = doppler_transform(np.eye(m, dtype=complex), processing, axis=0)
    return np.outer(np.sum(np.abs(a) ** 2, axis=1), np.sum(np.abs(b) ** 2, axis=1))
