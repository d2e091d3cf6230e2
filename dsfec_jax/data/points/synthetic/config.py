"""What the synthetic benchmark is made of: classes, their physics, difficulty levels, the config.

Two sensor profiles: the default `SyntheticConfig()` is a nuScenes-like ARS408 (no elevation,
nuScenes point columns), `radar4d_config()` a View-of-Delft-like 4D imaging radar (elevation,
denser objects, VoD point columns, VoD's grid, class mix and camera-cropped annotation).

RCS follows 3GPP TR 38.901 §7.9.2.1 (human -1.37 dBsm, sigma 3.94 dB; vehicle 11.25 dBsm, sigma
3.41 dB with rear/front/side aspect gains 14.6/15.5/20.8 dB); bicycle ~0 and truck ~25 dBsm are
our assumptions (no sourced value found). Also our assumptions: Poisson point counts cut by an SNR
threshold, clutter RCS ~ N(-13, 9^2) dB (close to the median -12.6 dBsm of clutter in three VoD
example scans) and radial-velocity noise 0.1-0.2 m/s. Sizes are nuScenes class means (w, l, h).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ....core.columns import NUSCENES_FEATURES, VOD_FEATURES
from ....core.grid import DSFEC_GRID, VOD_GRID, Grid

CLASSES = ("car", "truck", "pedestrian", "bicycle")
# The nuScenes radar columns the DSFEC models read (models/dsfec/net.py RADAR_FEATURES; data may not
# import models, so the tuple is repeated here and a test pins the two together).
RADAR_FEATURES = NUSCENES_FEATURES
# point_format -> the point columns a frame carries. "vod": VoD's .bin layout (docs/SENSORS_AND_DATA.md),
# v_r the Doppler relative to the moving sensor, v_r_comp ego-motion compensated, time = -k for sweep k.
POINT_FORMATS = {"nuscenes": RADAR_FEATURES, "vod": VOD_FEATURES}
# traffic_mix names; the tables behind them are scene.TRAFFIC_MIXES (a test pins the two together).
TRAFFIC_MIX_NAMES = ("nuscenes", "vod")
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
    rcs_quantum_db: float = 0.5       # ARS408 reports RCS in 0.5 dBsm steps; 0: continuous
    # The fields below were added for the 4D profile; their defaults reproduce the frames above exactly.
    point_format: str = "nuscenes"    # point columns, a key of POINT_FORMATS
    traffic_mix: str = "nuscenes"     # who is on the road, one of TRAFFIC_MIX_NAMES (scene.TRAFFIC_MIXES)
    density_scale: float = 1.0        # multiplies every class's points_per_m2 (sensitivity)
    resolution_scale: float = 1.0     # multiplies every class's points_per_m (resolution cap)
    clutter_scale: float = 1.0        # multiplies the static-structure scatterer density
    structure_top_m: float = 1.5      # structure scatterers lie 0.3 m .. this above the ground (rails lower)
    camera_fov_deg: float = 360.0     # annotated view: boxes and points outside it are dropped
    annotate_range_m: float | None = None  # boxes farther than this (BEV range) are not annotated

    def __post_init__(self):
        if self.difficulty not in DIFFICULTIES:
            raise ValueError(f"SyntheticConfig.difficulty={self.difficulty!r}; known: {sorted(DIFFICULTIES)}")
        if self.point_format not in POINT_FORMATS:
            raise ValueError(f"SyntheticConfig.point_format={self.point_format!r}; known: {sorted(POINT_FORMATS)}")
        if self.traffic_mix not in TRAFFIC_MIX_NAMES:
            raise ValueError(f"SyntheticConfig.traffic_mix={self.traffic_mix!r}; known: {list(TRAFFIC_MIX_NAMES)}")
        scales = dict(density_scale=self.density_scale, resolution_scale=self.resolution_scale,
                      clutter_scale=self.clutter_scale)
        if min(scales.values()) <= 0 or self.rcs_quantum_db < 0 or self.structure_top_m <= 0.3:
            raise ValueError(f"SyntheticConfig: {scales} must be > 0, rcs_quantum_db={self.rcs_quantum_db} >= 0, "
                             f"structure_top_m={self.structure_top_m} > 0.3")
        if not 0 < self.camera_fov_deg <= 360 or (self.annotate_range_m is not None and self.annotate_range_m <= 0):
            raise ValueError(f"SyntheticConfig: camera_fov_deg={self.camera_fov_deg} must be in (0, 360] and "
                             f"annotate_range_m={self.annotate_range_m} None or > 0")
        if self.num_sweeps < 1 or self.sweep_period_s <= 0:
            raise ValueError(f"SyntheticConfig: num_sweeps={self.num_sweeps} must be >= 1 and "
                             f"sweep_period_s={self.sweep_period_s} > 0")
        if not 0 < self.fov_deg <= 360 or self.max_range_m <= 0:
            raise ValueError(f"SyntheticConfig: fov_deg={self.fov_deg} must be in (0, 360] and max_range_m > 0")

    @property
    def level(self) -> Difficulty:
        return DIFFICULTIES[self.difficulty]

    @property
    def point_features(self) -> tuple[str, ...]:
        return POINT_FORMATS[self.point_format]

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


def radar4d_config(difficulty: str = "normal", **overrides) -> SyntheticConfig:
    """A View-of-Delft-like 4D imaging radar (ZF FRGen21), so RadarNeXt trains without downloads.

    Facts: tudelft-iv/view-of-delft-dataset docs/SENSORS_AND_DATA.md (FRGen21 behind the front
    bumper at ~13 Hz, 5-scan accumulation, camera FOV +-32 deg), docs/ANNOTATION.md (objects
    within 50 m and partly or fully in the camera view are annotated), PP-Radar.md (the VoD
    baseline keeps only points in the camera view, OpenPCDet FOV_POINTS_ONLY). "example set":
    the three public VoD frames in shared/data/vod, measured with data/points/kitti.py. Choices without
    a source are marked "assumed".
    """
    values = dict(
        grid=VOD_GRID, difficulty=difficulty, point_format="vod", traffic_mix="vod",
        num_sweeps=5,                  # VoD's radar_5frames, the input RadarNeXt's VoD config reads
        sweep_period_s=1 / 13,         # FRGen21 at ~13 Hz
        # The radar sees wider than the camera (example-set points reach +-90 deg, 90 % within
        # +-48 deg): simulate +-60 deg (assumed), annotate and keep the camera's +-32 deg only.
        fov_deg=120.0, camera_fov_deg=64.0,
        annotate_range_m=50.0,         # VoD: 50 m from the LiDAR, ~1.4 m behind the radar (calib)
        # Far enough for every kept point: the grid plus the keep margin reaches hypot(55.2, 29.6)
        # = 62.6 m. (The example-set scans reach ~98 m; farther returns would all be dropped.)
        max_range_m=64.0,
        # Behind the bumper: the example-set calibration puts the radar 0.98 m below the camera,
        # and label boxes within 15 m stand at a median z of -0.21 m (on kerbs and roads).
        sensor_height_m=0.4,
        elevation=True, elevation_noise_deg=1.5,  # 3+1D radar; 1.5 deg assumed (no datasheet)
        # Example-set static points have a robust v_r_comp spread of ~0.01 m/s: a far cleaner
        # Doppler and ego estimate than the ARS408 profile's.
        velocity_noise_mps=0.03, ego_velocity_noise_mps=0.02,
        rcs_quantum_db=0.0,            # example-set RCS values are not quantised
        # Example set, single scans, points in label boxes: a car at 7 m 15, pedestrians at 5-20 m
        # 1-7 (mean 4), cyclists at 7-23 m 3-15. Cars are resolution-limited, pedestrians
        # sensitivity-limited, hence two factors; these give a car at 7 m ~15 and a pedestrian
        # ~5 at 7 m, ~3 at 15 m per scan (3.5x and 2-3x the ARS408 profile; pedestrians stay
        # somewhat sparser than in the three example frames).
        density_scale=12.0, resolution_scale=4.0,
        # Example set: 174-217 points per scan in the camera view inside the grid, 80-85 % of
        # them clutter (outside the mapped-class boxes). These give ~215 kept points per scan,
        # ~75 % clutter. Facades and poles return from above the ARS408's 1.5 m too (assumed).
        clutter_scale=8.0, structure_top_m=2.5, false_alarms_per_sweep=60.0,
        # Every example-set pedestrian (9) and cyclist (5) within 20 m has points: shadows cost
        # less than in the ARS408 profile (assumed 0.5; radar passes under cars and by bicycles).
        occlusion_prob=0.5,
    )
    values.update(overrides)
    return SyntheticConfig(**values)


RADAR4D_CONFIG = radar4d_config()
