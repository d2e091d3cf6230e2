"""Every knob of the street-scene benchmark: camera, mount, stereo rig, GPS, road, traffic, labels.

Sizes (width, length, height; metres) are typical European road users, assumed: a compact car
(VW Golf class, 1.8 x 4.3-4.7 x 1.45-1.5), a rigid box truck (2.5 x 6.5-10 x 3.0-3.6), a 12 m city
bus (2.55 x 12 x 3.1), an adult pedestrian (1.72 +- 0.09 m tall), a bicycle with rider (0.6 x
1.75 x 1.75). Speeds: urban traffic, assumed. The class mix and densities are chosen so that a
416-wide frame of the paper's camera holds a few labelled objects of every class (see the
statistics in the report of `python -m dsfec_jax.data inspect --source street`).

Label rules (labels.py): an object's box is the extent of its visible pixels in the rendered
object-id mask. visible fraction = visible pixels / pixels of the object rendered alone (the
same camera, no other geometry; parts of the object outside the frame count as neither);
truncation = the share of the object's full projected 2D box (its 3D box projected, unclipped)
that lies outside the frame. An object is dropped (no box) when its visible fraction is below
`min_visible_fraction`, it has fewer than `min_visible_pixels` visible pixels, or its box is
lower than `min_box_height_px`; a kept object is difficult when its visible fraction is below
`difficult_visible_fraction`, its truncation exceeds `difficult_truncation`, or its box is
lower than `difficult_box_height_px`. Pixel thresholds apply at the rendered resolution.
"""

from __future__ import annotations

import dataclasses

from .camera import CAMERAS, PinholeCamera

FORMAT_VERSION = 1  # bump when generated frames change for the same (config, split, index, seed)
CLASSES = ("car", "truck", "bus", "pedestrian", "cyclist")
KARLSRUHE = (49.0069, 8.4037, 115.0)  # lat, lon (deg), WGS84 ellipsoidal height (m): KITTI's city


@dataclasses.dataclass(frozen=True)
class ClassSpec:
    size_m: tuple[float, float, float]     # mean (width, length, height)
    size_sd_m: tuple[float, float, float]  # normal spread, clipped at +-2 sd
    speed_mps: tuple[float, float]         # moving objects: speed ~ U(lo, hi)


CLASS_SPECS = (  # in CLASSES order
    ClassSpec((1.82, 4.50, 1.50), (0.08, 0.35, 0.08), (6.0, 14.0)),
    ClassSpec((2.50, 8.00, 3.30), (0.05, 1.30, 0.25), (5.0, 12.0)),
    ClassSpec((2.55, 12.0, 3.10), (0.02, 0.50, 0.08), (5.0, 11.0)),
    ClassSpec((0.55, 0.35, 1.72), (0.05, 0.05, 0.09), (0.9, 1.6)),
    ClassSpec((0.60, 1.75, 1.75), (0.05, 0.10, 0.07), (3.0, 6.5)),
)


@dataclasses.dataclass(frozen=True)
class StreetConfig:
    """Frames are a pure function of (config, split, index, seed)."""

    # camera and mount
    camera: str = "paper"                  # a CAMERAS preset: 'paper' (1920x1080, 120 deg) or 'kitti'
    width: int = 416                       # rendered width; the preset's intrinsics scale with it
    camera_height_m: float = 1.4           # optical centre above the road
    pitch_deg: float = 0.0                 # positive: the optical axis tilts down
    baseline_m: float = 0.54               # right camera this far to the right (KITTI's rig)
    render_right: bool = True              # the right image (off: faster, for detector-only use; docs/camera.md)
    near_m: float = 0.1                    # nothing closer than this along the optical axis is drawn
    draw_distance_m: float = 220.0         # static clutter and objects farther away are not drawn
    # time and GPS
    fps: float = 10.0                      # camera frame rate of drives
    gps_hz: float = 1.0                    # GPS fix rate
    gps_noise_m: float = 0.0               # horizontal sd added to the fixes (0: exact samples of the track)
    origin: tuple[float, float, float] = KARLSRUHE  # ENU origin of every world
    split_area_km: float = 20.0            # each split's worlds start in its own square of this size
    # road
    lanes_per_direction: tuple[int, ...] = (1, 2)
    lane_width_m: tuple[float, float] = (3.2, 3.7)
    bike_strip_m: tuple[float, float] = (1.0, 1.8)
    parking_prob: float = 0.5              # a parking strip (2.2 m) on both sides
    sidewalk_m: tuple[float, float] = (2.0, 4.5)
    setback_m: tuple[float, float] = (0.5, 6.0)
    straight_m: tuple[float, float] = (20.0, 120.0)
    curve_radius_m: tuple[float, float] = (60.0, 350.0)
    curve_angle_deg: tuple[float, float] = (15.0, 80.0)
    ego_speed_mps: tuple[float, float] = (5.0, 14.0)
    # traffic (densities: mean free gap between consecutive objects of one stream)
    classes: tuple[str, ...] = CLASSES
    specs: tuple[ClassSpec, ...] = CLASS_SPECS
    vehicle_mix: tuple[float, float, float] = (0.80, 0.11, 0.09)  # car, truck, bus in a lane
    lane_gap_m: float = 14.0
    parked_gap_m: float = 6.0
    cyclist_gap_m: float = 45.0
    pedestrian_gap_m: float = 9.0
    crossing_prob: float = 0.35            # independent frames: a crosswalk with 1-4 pedestrians
    view_m: float = 90.0                   # objects are placed out to this far ahead
    # look
    noise_sd: tuple[float, float] = (1.0, 4.0)  # sensor noise sd in 8-bit levels, per frame ~ U
    # label rules (module docstring)
    min_visible_fraction: float = 0.1
    min_visible_pixels: int = 12
    min_box_height_px: float = 6.0
    difficult_visible_fraction: float = 0.5
    difficult_truncation: float = 0.3
    difficult_box_height_px: float = 10.0

    def __post_init__(self):
        if self.camera not in CAMERAS:
            raise ValueError(f"StreetConfig.camera={self.camera!r}; expected one of {tuple(CAMERAS)}")
        if self.width < 8 or self.camera_height_m <= 0 or self.baseline_m < 0 or self.near_m <= 0:
            raise ValueError(f"StreetConfig: width={self.width} >= 8, camera_height_m={self.camera_height_m} > 0, "
                             f"baseline_m={self.baseline_m} >= 0, near_m={self.near_m} > 0")
        if self.fps <= 0 or self.gps_hz <= 0 or self.gps_noise_m < 0:
            raise ValueError(f"StreetConfig: fps={self.fps} and gps_hz={self.gps_hz} > 0, gps_noise_m >= 0")
        if not (len(self.classes) == len(self.specs) == 5) or tuple(self.classes) != CLASSES:
            raise ValueError(f"StreetConfig.classes must be {CLASSES} with one spec each")
        if min(self.vehicle_mix) < 0 or sum(self.vehicle_mix) <= 0 or not 0 <= self.crossing_prob <= 1:
            raise ValueError(f"StreetConfig: vehicle_mix={self.vehicle_mix} >= 0 with a positive sum, "
                             f"crossing_prob={self.crossing_prob} in [0, 1]")
        if not 0 <= self.min_visible_fraction <= self.difficult_visible_fraction <= 1:
            raise ValueError("StreetConfig: 0 <= min_visible_fraction <= difficult_visible_fraction <= 1")
        if min(self.lanes_per_direction) < 1 or self.view_m <= 5 or self.draw_distance_m < self.view_m:
            raise ValueError(f"StreetConfig: lanes_per_direction={self.lanes_per_direction} >= 1, view_m="
                             f"{self.view_m} > 5, draw_distance_m >= view_m")

    def camera_model(self) -> PinholeCamera:
        """The preset scaled to `width` (height rounded; intrinsics scaled by the same factor)."""
        return CAMERAS[self.camera].scaled(self.width)

    def spec(self, name: str) -> ClassSpec:
        return self.specs[self.classes.index(name)]

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "StreetConfig":
        d = {k: _tuples(v) for k, v in d.items()}
        d["specs"] = tuple(ClassSpec(**s) if isinstance(s, dict) else ClassSpec(*s) for s in d["specs"])
        return cls(**d)


def _tuples(v):
    if isinstance(v, list):
        return tuple(_tuples(x) for x in v)
    if isinstance(v, dict):
        return {k: _tuples(x) for k, x in v.items()}
    return v
