"""The receiver's analogue IF chain and its Tx->Rx coupling, as the ADC sees them.

TI's receivers (AR1243/AR1642 digital baseband application note; the AWR/IWR data sheets) pass
the mixer output through a high-pass filter (a two-stage one on the AWR parts, selectable corners
of a few hundred kHz: it tames the strong near returns) and an anti-alias / decimation low-pass
whose usable band ends near 0.9 F_s (TI's IF-bandwidth rule, sensor.py). So, with f the beat
frequency as a fraction of the sample rate (range bin k sits at f = k / N):

- a scatterer's tone reaches the ADC scaled by the steady-state gain |H_hp(f)| |H_lp(f)|;
- the noise floor of bin k is stopband + (1 - stopband) |H_lp|^2 (white + (1 - white) |H_hp|^2):
  only the front end's noise passes the high-pass (the ADC's own noise is added after it, hence
  the `white` share, which keeps the near floor from falling away), the digital low-pass shapes
  both, and its stop band has a floor (`stopband_db`: the aliased and quantisation noise it
  cannot remove). Pass band = 1, so the far floor, which the box threshold uses, is unchanged.

Magnitudes are Butterworth-like, |H_hp|^2 = x^2n / (1 + x^2n) with x = f / highpass_corner and
|H_lp|^2 = 1 / (1 + (f / lowpass_corner)^2m): steady-state responses, a function of the beat
frequency only, so the frequency-domain synthesis stays exact (spectra.py). Corners are fractions
of the sample rate because a range bin is a fixed fraction of it for any chirp (f = k / N), so the
floor's shape in range bins carries over between radars. The defaults are fitted to the floor
profile of the real TI capture (docs/range-doppler.md gives the command and the fit); a corner of
0 switches that filter off.

Tx->Rx coupling: the transmitter's direct path into the receivers, a static tone at a small
fractional range bin (`coupling_bin`), at `coupling_snr_db` over the thermal noise per ADC sample
*after* the IF chain (what the capture shows). It is added as a static scatterer whose RCS gives
that SNR, so the brute-force ADC check covers it. Its fractional bin is taken from the capture;
RADDet's radar has its own, unknown, value.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np


@dataclasses.dataclass(frozen=True)
class IFChain:
    highpass_corner: float = 0.166    # -3 dB corner, fraction of the sample rate; 0: no high-pass
    highpass_order: int = 1
    highpass_noise_share: float = 0.757  # share of the noise floor that passes the high-pass
    lowpass_corner: float = 0.913     # -3 dB corner, fraction of the sample rate; 0: no low-pass
    lowpass_order: int = 32
    stopband_db: float = -8.7         # noise floor of the low-pass's stop band, relative to the pass band
    coupling_snr_db: float | None = 17.0  # Tx->Rx coupling per ADC sample over the noise; None: none
    coupling_bin: float = 0.9         # its apparent range in (fractional) range bins

    def __post_init__(self):
        if not (0 <= self.highpass_corner < 1 and 0 <= self.lowpass_corner and self.highpass_order >= 1
                and self.lowpass_order >= 1):
            raise ValueError(f"IFChain: highpass_corner={self.highpass_corner} in [0, 1), lowpass_corner="
                             f"{self.lowpass_corner} >= 0, orders {self.highpass_order}, {self.lowpass_order} >= 1")
        if not 0 <= self.highpass_noise_share <= 1 or not -300 <= self.stopband_db <= 0:
            raise ValueError(f"IFChain: highpass_noise_share={self.highpass_noise_share} in [0, 1], "
                             f"stopband_db={self.stopband_db} in [-300, 0]")
        if self.coupling_snr_db is not None and not (math.isfinite(self.coupling_snr_db) and self.coupling_bin > 0):
            raise ValueError(f"IFChain: coupling_snr_db={self.coupling_snr_db} must be finite (or None) and "
                             f"coupling_bin={self.coupling_bin} > 0")

    def _highpass_power(self, f: np.ndarray) -> np.ndarray:
        if self.highpass_corner == 0:
            return np.ones_like(f)
        x = (f / self.highpass_corner) ** (2 * self.highpass_order)
        return x / (1 + x)

    def _lowpass_power(self, f: np.ndarray) -> np.ndarray:
        if self.lowpass_corner == 0:
            return np.ones_like(f)
        return 1 / (1 + (f / self.lowpass_corner) ** (2 * self.lowpass_order))

    def tone_gain(self, cycles: np.ndarray) -> np.ndarray:
        """Amplitude gain of tones at `cycles` per ADC sample (taken modulo 1: a complex ADC's band)."""
        f = np.mod(np.asarray(cycles, np.float64), 1.0)
        return np.sqrt(self._highpass_power(f) * self._lowpass_power(f))

    def noise_power_profile(self, num_samples: int) -> np.ndarray:
        """Noise power gain of each range bin (num_samples,), 1 in the pass band."""
        f = np.arange(num_samples) / num_samples
        white = 1 - self.highpass_noise_share
        shaped = self._lowpass_power(f) * (white + self.highpass_noise_share * self._highpass_power(f))
        stop = 10 ** (self.stopband_db / 10)
        return stop + (1 - stop) * shaped

    @property
    def is_flat(self) -> bool:
        return self.highpass_corner == 0 and self.lowpass_corner == 0 and self.stopband_db <= -200


# benchmark v1: flat IF response, no coupling
NO_IF_CHAIN = IFChain(highpass_corner=0.0, lowpass_corner=0.0, stopband_db=-200.0, coupling_snr_db=None)
