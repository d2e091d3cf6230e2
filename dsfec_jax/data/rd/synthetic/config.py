"""Every knob of the FMCW range-Doppler simulator: sensor, processing, classes, scene, clutter, noise.

Sources and assumptions (reference-spec §4; ../shared/docs/rd-yolo-camera-facts.md §1):
- RCS (3GPP TR 38.901 §7.9.2.1): human -1.37 dBsm, log-normal sigma 3.94 dB; vehicle 11.25 dBsm,
  sigma 3.41 dB, aspect gains front 15.5 / rear 14.6 / side 20.8 dB, applied around their
  circular mean (front -2.4, rear -3.3, side +2.9 dB) so the class value stays the aspect average.
  rcs_dbsm is the *linear mean*; the log-normal median sits (ln10 / 20) sigma^2 dB below it.
- Assumed (no sourced value): bicycle with rider 0 dBsm (sigma 3.94, human-like), motorcycle with
  rider 5 dBsm (sigma 3.41), truck 25 dBsm and bus 25 dBsm (sigma 3.41, the spec's truck
  assumption for both large vehicles).
- Sizes (width, length): nuScenes class means (car, truck, bus, bicycle, motorcycle, pedestrian).
- Class mix, speeds, object counts, clutter and ghost levels: assumed, street scenes seen by a
  static sensor, as RADDet records them (cars and persons dominate).
- noise_counts_rms: the thermal noise per complex ADC sample in ADC counts, 6.5, the level
  measured on the real TI capture (../shared/data/openradar_ti_adc: the median of its per-channel
  map over the chain's noise gain, ~6.5 counts in both files). The radar equation gives each
  scatterer's SNR against kT B NF (FMCWSensor.noise_power_dbm); counts = noise_counts_rms *
  sqrt(SNR), so maps sit on the same log10 scale as a real TI capture.
- Benchmark versions (issue 54): v1 is the benchmark before the realism below (the first RD
  weights and the records made before issue 54 were made on it; `benchmark_config(1)`, or
  `synthetic:v1`, regenerates its samples exactly); v2, what a plain `synthetic` gives and what
  the shipped RD weights are trained on, adds static clutter at every range, the IF chain's shape and the
  Tx->Rx coupling, each measured against the TI capture through the same chain (the capture is
  an indoor scene of another radar, so the mechanisms are matched, not the room):
  * IFChain (if_chain.py): high-pass corner, its noise share, low-pass corner, order and stop
    band are the least-squares fit of the capture's floor profile over range, and the coupling's
    fractional bin and level per ADC sample the fit of its leakage rows, both by
    `python -m experiments.rd_capture_fit` (experiments/records/rd_synthetic/capture_fit.json;
    the coupling is the mean of its two files). The low-pass corner lands on TI's 0.9 F_s rule.
  * area clutter and point reflectors (ClutterConfig): assumed forms (beam-limited clutter,
    sigma0 R fov dR per range bin; Poisson poles with log-normal RCS), whose levels (sigma0, its
    per-frame and per-scatterer spread, the reflectors' RCS) were set so that 300 v2 validation
    maps give the capture's zero-Doppler ridge over the row floor and the share of rows where it
    reaches 30 dB (docs/range-doppler.md: `inspect --versus` prints both). sigma0 here stands for
    everything static in a street (road, kerbs, walls, vegetation, fences), not a bare road's.
"""

from __future__ import annotations

import dataclasses

from ..classes import RD_CLASSES
from ..processing import RDProcessing
from ..sensor import RADDET_SENSOR, FMCWSensor
from .if_chain import NO_IF_CHAIN, IFChain

FORMAT_VERSION = 2  # bump when generated samples change for the same (config, split, index, seed)
BENCHMARK_VERSIONS = (1, 2)  # 1: the benchmark before issue 54 (its records); 2: issue 54's realism
# What `synthetic` without a version means: the shipped RD weights' benchmark, so that their recorded
# figures reproduce with the plain commands (the RD family's `benchmark` names it explicitly)
DEFAULT_BENCHMARK = 2
MICRO_MOTIONS = ("none", "gait", "wheels")

# Vehicle aspect pattern g(b) = B cos b + C cos 2b through 3GPP's front (b = 0) 15.5, rear 14.6 and
# side 20.8 dB, minus its circular mean (b: angle between the heading and the line to the radar).
ASPECT_COS1_DB = (15.5 - 14.6) / 2
ASPECT_COS2_DB = ((15.5 + 14.6) / 2 - 20.8) / 2


@dataclasses.dataclass(frozen=True)
class ClassProfile:
    size_m: tuple[float, float]        # mean (width, length)
    size_sd_m: tuple[float, float]
    rcs_dbsm: float                    # linear-mean RCS of the whole object
    rcs_sigma_db: float                # log-normal spread
    aspect_depth: float                # how much of the vehicle aspect pattern applies (0: none)
    speed_mps: tuple[float, float]     # speed ~ U(lo, hi); all labelled objects move
    body_scatterers: int               # point scatterers spread over the visible outline
    micro: str                         # 'none' | 'gait' (limbs) | 'wheels' (rims): micro-Doppler
    micro_share: float                 # share of the object's RCS in the limbs / wheels

    def __post_init__(self):
        if self.micro not in MICRO_MOTIONS:
            raise ValueError(f"ClassProfile.micro={self.micro!r}; expected one of {MICRO_MOTIONS}")
        if self.body_scatterers < 1 or not 0 <= self.micro_share < 1 or min(self.size_m) <= 0:
            raise ValueError(f"ClassProfile: body_scatterers={self.body_scatterers} must be >= 1, micro_share="
                             f"{self.micro_share} in [0, 1), sizes {self.size_m} > 0")
        if not 0 <= self.speed_mps[0] <= self.speed_mps[1] or self.rcs_sigma_db < 0:
            raise ValueError(f"ClassProfile: speed_mps={self.speed_mps} must be 0 <= lo <= hi, "
                             f"rcs_sigma_db={self.rcs_sigma_db} >= 0")


# In RD_CLASSES order: person, bicycle, car, motorcycle, bus, truck.
CLASS_PROFILES = (
    ClassProfile((0.67, 0.73), (0.10, 0.15), -1.37, 3.94, 0.0, (0.5, 2.0), 2, "gait", 0.4),
    ClassProfile((0.60, 1.70), (0.10, 0.15), 0.0, 3.94, 0.5, (2.0, 7.0), 3, "wheels", 0.3),
    ClassProfile((1.95, 4.62), (0.19, 0.46), 11.25, 3.41, 1.0, (1.0, 15.0), 8, "none", 0.0),
    ClassProfile((0.77, 2.11), (0.15, 0.20), 5.0, 3.41, 0.5, (2.0, 15.0), 4, "wheels", 0.1),
    ClassProfile((2.95, 11.0), (0.20, 1.50), 25.0, 3.41, 1.0, (1.0, 12.0), 16, "none", 0.0),
    ClassProfile((2.51, 6.93), (0.35, 1.90), 25.0, 3.41, 1.0, (1.0, 12.0), 12, "none", 0.0),
)
CLASS_MIX = (0.30, 0.10, 0.40, 0.04, 0.04, 0.12)


@dataclasses.dataclass(frozen=True)
class ClutterConfig:
    """Static returns (velocity 0: the sensor stands still, as RADDet's does) and multipath ghosts."""
    ground_scatterers: float = 80.0           # Poisson mean: road surface, kerbs, vegetation
    ground_rcs_dbsm: float = -20.0            # per scatterer, ~ N(this, sd) dB; from min_range_m out
    ground_rcs_sd_db: float = 6.0
    max_buildings: int = 3                    # facades per frame ~ U{0..max}
    building_length_m: tuple[float, float] = (5.0, 20.0)
    building_range_m: tuple[float, float] = (8.0, 45.0)
    building_spacing_m: float = 1.0           # one scatterer per this much facade
    building_rcs_dbsm: float = 0.0
    building_rcs_sd_db: float = 6.0
    parked_vehicles: float = 1.0              # Poisson mean; car layouts at zero velocity, never labelled
    ghost_prob: float = 0.3                   # per moving object: a multipath copy
    ghost_extra_range_m: tuple[float, float] = (1.0, 6.0)  # longer path, same Doppler
    ghost_loss_db: tuple[float, float] = (8.0, 15.0)
    # benchmark v2 (scatterers.static_scene_scatterers); 0 cells / 0 poles: off (v1)
    area_cells_per_bin: float = 2.0           # area clutter scatterers per range bin
    area_min_range_m: float = 0.5             # where the ground enters the beam
    area_sigma0_db: float = -5.0              # per-frame sigma0 ~ N(this, sd) dB (m^2 per m^2)
    area_sigma0_sd_db: float = 3.0
    area_texture_sd_db: float = 3.0           # per-scatterer log-normal texture
    poles: float = 5.0                        # Poisson mean: poles, signs, posts
    pole_rcs_dbsm: float = 10.0               # per reflector ~ N(this, sd) dB
    pole_rcs_sd_db: float = 5.0

    def __post_init__(self):
        if self.area_cells_per_bin < 0 or self.poles < 0 or self.area_min_range_m <= 0:
            raise ValueError(f"ClutterConfig: area_cells_per_bin={self.area_cells_per_bin} and poles={self.poles} "
                             f"must be >= 0, area_min_range_m={self.area_min_range_m} > 0")
        if min(self.area_sigma0_sd_db, self.area_texture_sd_db, self.pole_rcs_sd_db) < 0:
            raise ValueError("ClutterConfig: area_sigma0_sd_db, area_texture_sd_db and pole_rcs_sd_db must be >= 0")


@dataclasses.dataclass(frozen=True)
class RDSyntheticConfig:
    """Samples are a pure function of (config, split, index, seed)."""

    sensor: FMCWSensor = RADDET_SENSOR
    processing: RDProcessing = RDProcessing()
    classes: tuple[str, ...] = RD_CLASSES
    profiles: tuple[ClassProfile, ...] = CLASS_PROFILES   # one per class
    class_mix: tuple[float, ...] = CLASS_MIX              # relative weights, one per class
    empty_prob: float = 0.1                   # frames with clutter only
    mean_objects: float = 2.5                 # non-empty frames: 1 + Poisson(mean - 1) objects
    max_objects: int = 8
    min_range_m: float = 2.0
    max_range_fraction: float = 0.9           # of sensor.max_range_m: TI's IF-filter rule (0.9 F_s)
    fov_deg: float = 120.0                    # azimuth field of view, centred on boresight
    clutter: ClutterConfig = ClutterConfig()
    if_chain: IFChain = IFChain()              # the IF filters' shape and the Tx->Rx coupling (if_chain.py)
    body_interior_share: float = 0.5          # body scatterers anywhere on the footprint; the rest on
    #                                           the faces that face the radar (scatterers.body_points)
    noise_counts_rms: float = 6.5             # thermal noise per complex ADC sample, ADC counts
    box_threshold_db: float = 10.0            # a cell belongs to an object's box when the object's own
    #                                           noise-free power there exceeds the mean noise floor by this
    box_margin_bins: int = 24                 # range rows around an object searched for its extent

    def __post_init__(self):
        if not (len(self.classes) == len(self.profiles) == len(self.class_mix)):
            raise ValueError(f"RDSyntheticConfig: classes ({len(self.classes)}), profiles ({len(self.profiles)}) "
                             f"and class_mix ({len(self.class_mix)}) must have one entry per class")
        if min(self.class_mix) < 0 or sum(self.class_mix) <= 0:
            raise ValueError(f"RDSyntheticConfig.class_mix={self.class_mix} must be >= 0 with a positive sum")
        if not 0 <= self.empty_prob <= 1 or self.mean_objects < 1 or self.max_objects < 1:
            raise ValueError(f"RDSyntheticConfig: empty_prob={self.empty_prob} in [0, 1], mean_objects="
                             f"{self.mean_objects} >= 1, max_objects={self.max_objects} >= 1")
        if not 0 < self.min_range_m < self.max_range_m:
            raise ValueError(f"RDSyntheticConfig: min_range_m={self.min_range_m} must be in (0, "
                             f"{self.max_range_m:.2f}) (max_range_fraction * sensor.max_range_m)")
        if not 0 <= self.body_interior_share <= 1:
            raise ValueError(f"RDSyntheticConfig.body_interior_share={self.body_interior_share} must be in [0, 1]")
        if not 0 < self.fov_deg <= 180 or self.noise_counts_rms <= 0 or self.box_margin_bins < 1:
            raise ValueError(f"RDSyntheticConfig: fov_deg={self.fov_deg} in (0, 180], noise_counts_rms="
                             f"{self.noise_counts_rms} > 0, box_margin_bins={self.box_margin_bins} >= 1")

    @property
    def max_range_m(self) -> float:
        return self.max_range_fraction * self.sensor.max_range_m

    def profile(self, name: str) -> ClassProfile:
        return self.profiles[self.classes.index(name)]

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "RDSyntheticConfig":
        d = {k: _tuples(v) for k, v in d.items()}
        d["sensor"] = FMCWSensor(**d["sensor"])
        d["processing"] = RDProcessing(**d["processing"])
        d["clutter"] = ClutterConfig(**d["clutter"])
        d["if_chain"] = IFChain(**d["if_chain"])
        d["profiles"] = tuple(ClassProfile(**p) for p in d["profiles"])
        return cls(**d)


def benchmark_config(version: int = DEFAULT_BENCHMARK) -> RDSyntheticConfig:
    """The benchmark's config by version: 2 is RDSyntheticConfig's defaults; 1 has no area clutter, no point
    reflectors, a flat IF chain and no coupling, and generates exactly the samples it did before
    issue 54 (what the first RD weights and the records of that time were made on)."""
    if version not in BENCHMARK_VERSIONS:
        raise ValueError(f"RD synthetic benchmark version {version!r}; known: {BENCHMARK_VERSIONS}")
    cfg = RDSyntheticConfig()
    if version == 1:
        clutter = dataclasses.replace(cfg.clutter, area_cells_per_bin=0.0, poles=0.0)
        cfg = dataclasses.replace(cfg, clutter=clutter, if_chain=NO_IF_CHAIN)
    return cfg


def _tuples(v):
    """JSON lists back to the tuples the dataclasses hold (recursively, dicts kept)."""
    if isinstance(v, (list, tuple)):
        return tuple(_tuples(x) for x in v)
    if isinstance(v, dict):
        return {k: _tuples(x) for k, x in v.items()}
    return v
