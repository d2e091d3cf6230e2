"""What the synthetic benchmark is made of: classes, their physics, difficulty levels, the config.

Numbers follow ../shared/docs/reference-spec.md §4: 3GPP TR 38.901 RCS (human -1.37 dBsm, sigma
3.94 dB; vehicle 11.25 dBsm, sigma 3.41 dB with rear/front/side aspect gains 14.6/15.5/20.8 dB;
assumed bicycle ~0 and truck ~25 dBsm), Poisson point counts cut by an SNR threshold, clutter RCS
~ N(-13, 9^2) dB, radial-velocity noise 0.1-0.2 m/s. Sizes are nuScenes class means (w, l, h).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...grid import DSFEC_GRID, Grid

CLASSES = ("car", "truck", "pedestrian", "bicycle")
# The nuScenes radar columns the DSFEC models read (models/dsfec.py RADAR_FEATURES; data may not
# import models, so the tuple is repeated here and a test pins the two together).
RADAR_FEATURES = ("x", "y", "z", "rcs", "vx_comp", "vy_comp", "dt")
# Where each point came from (Frame.meta["point_source"]); everything but "object" is clutter.
SOURCES = ("object", "structure", "false_alarm", "ghost")
FORMAT_VERSION = 1  # bump when generated frames change for the same (config, seed, index)


@dataclasses.dataclass(frozen=True)
class ClassProfile:
    size_mean: tuple[float, float, float]  # (w, l, h) m, nuScenes class means
    size_std: tuple[float, float, float]
    rcs_dbsm: float          # linear-mean RCS; the log-normal median sits (ln10/20) sigma^2 below
    rcs_sigma_db: float
    aspect_depth: float      # how strongly the vehicle front/rear/side pattern applies (0: none)
    points_per_m2: float     # expected detections per sweep per m^2 of RCS at 10 m (c_cls)
    points_per_m: float      # resolution limit: detections per metre of visible outline


CLASS_PROFILES = {
    "car": ClassProfile((1.95, 4.62, 1.73), (0.19, 0.46, 0.25), 11.25, 3.41, 1.0, 0.30, 0.8),
    "truck": ClassProfile((2.51, 6.93, 2.84), (0.35, 1.90, 0.60), 25.0, 3.41, 1.0, 0.05, 0.8),
    "pedestrian": ClassProfile((0.67, 0.73, 1.77), (0.10, 0.15, 0.18), -1.37, 3.94, 0.0, 0.60, 1.5),
    "bicycle": ClassProfile((0.60, 1.70, 1.28), (0.10, 0.15, 0.12), 0.0, 3.94, 0.5, 0.60, 1.2),
}

# Vehicle aspect pattern g(b) = mean + B cos b + C cos 2b through 3GPP's front (b=0) 15.5, rear
# (b=pi) 14.6 and side (b=pi/2) 20.8 dB, minus its circular mean so the class RCS stays the
# average over aspects: front -2.4, rear -3.3, side +2.9 dB.
ASPECT_COS1_DB = (15.5 - 14.6) / 2
ASPECT_COS2_DB = ((15.5 + 14.6) / 2 - 20.8) / 2


@dataclasses.dataclass(frozen=True)
class Difficulty:
    traffic: float        # actor density multiplier
    clutter: float        # static-structure scatterer density multiplier
    false_alarms: float   # per-sweep false-alarm rate multiplier
    ghosts: float         # multipath ghost probability multiplier
    noise: float          # position and velocity noise multiplier
    snr_offset_db: float  # sensitivity change: negative = fewer, weaker detections


DIFFICULTIES = {
    "easy": Difficulty(traffic=0.7, clutter=0.5, false_alarms=0.4, ghosts=0.5, noise=0.7, snr_offset_db=2.0),
    "normal": Difficulty(traffic=1.0, clutter=1.0, false_alarms=1.0, ghosts=1.0, noise=1.0, snr_offset_db=0.0),
    "hard": Difficulty(traffic=1.3, clutter=1.6, false_alarms=2.0, ghosts=2.0, noise=1.5, snr_offset_db=-3.0),
}


@dataclasses.dataclass(frozen=True)
class SyntheticConfig:
    """Every knob of the generator. Frames are a pure function of (config, split, index, seed)."""

    grid: Grid = DSFEC_GRID
    difficulty: str = "normal"        # 'easy' | 'normal' | 'hard'
    num_sweeps: int = 6               # accumulated radar sweeps per frame (nuScenes training habit)
    sweep_period_s: float = 1 / 13    # ARS408 cycle, ~13 Hz; dt of sweep k is k * period
    fov_deg: float = 180.0            # the front radars together cover the front half-plane
    max_range_m: float = 100.0
    keep_margin_m: float = 4.0        # points kept up to this far outside the grid (for augmentation)
    sensor_height_m: float = 0.5      # the sensor (origin) above the ground: ground is z = -this
    elevation: bool = False           # ARS408 measures no elevation: z = 0 like nuScenes radar
    range_noise_m: float = 0.15
    azimuth_noise_deg: float = 0.5    # lateral error grows with range: R * this
    elevation_noise_deg: float = 1.0  # only with elevation=True
    velocity_noise_mps: float = 0.15  # radial velocity noise
    ego_velocity_noise_mps: float = 0.05  # odometry error in the ego-motion compensation
    snr_ref_db: float = 25.0          # SNR of a 0 dBsm target at 10 m, above the threshold below
    snr_threshold_db: float = 0.0     # SNR falls 40 dB per decade of range (radar equation)
    false_alarms_per_sweep: float = 35.0
    ghost_prob: float = 0.06          # per object point, when a reflecting wall or rail is present
    ghost_loss_db: float = 8.0        # extra path loss of a multipath ghost
    occlusion_prob: float = 0.8       # a shadowed point is lost (some leak under/around cars)
    rcs_quantum_db: float = 0.5       # ARS408 reports RCS in 0.5 dBsm steps

    def __post_init__(self):
        if self.difficulty not in DIFFICULTIES:
            raise ValueError(f"SyntheticConfig.difficulty={self.difficulty!r}; known: {sorted(DIFFICULTIES)}")
        if self.num_sweeps < 1 or self.sweep_period_s <= 0:
            raise ValueError(f"SyntheticConfig: num_sweeps={self.num_sweeps} must be >= 1 and "
                             f"sweep_period_s={self.sweep_period_s} > 0")
        if not 0 < self.fov_deg <= 360 or self.max_range_m <= 0:
            raise ValueError(f"SyntheticConfig: fov_deg={self.fov_deg} must be in (0, 360] and max_range_m > 0")

    @property
    def level(self) -> Difficulty:
        return DIFFICULTIES[self.difficulty]

    @property
    def sweep_offsets(self) -> np.ndarray:
        """(S,) dt of each sweep, seconds before the current one (nuScenes time_lag, >= 0)."""
        return np.arange(self.num_sweeps) * self.sweep_period_s

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "SyntheticConfig":
        d = dict(d)
        d["grid"] = Grid(**{k: tuple(v) if isinstance(v, list) else v for k, v in d["grid"].items()})
        return cls(**d)
