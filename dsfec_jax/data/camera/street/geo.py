"""The ego's GPS: local ENU positions to WGS84 latitude, longitude and height with pymap3d.

Every world lives in one local East-North-Up frame whose origin is `StreetConfig.origin`
(default Karlsruhe, 49.0069 N 8.4037 E, 115 m: KITTI's city), with the road on the plane U = 0.
dsfec_jax.geo.geodesy converts through pymap3d (WGS84; reference-spec §2): `enu_to_geodetic` and
`geodetic_to_enu` are its functions, re-exported here under the names this package has always
used. The round trip is exact to far below a millimetre at these distances (tested to 1e-6 m).
The GPS antenna sits at the camera, so a fix is the camera's position (U = camera height). Fixes
come at `gps_hz` (1 Hz, as the paper's module) at t = 0, 1, 2, ... s of the drive; between fixes
the paper interpolates linearly, which dsfec_jax.geo.gps does, against the exact per-frame poses
recorded here.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ....geo.geodesy import enu_to_geodetic, geodetic_to_enu

__all__ = ["EgoPose", "GpsTrack", "enu_to_geodetic", "geodetic_to_enu"]


@dataclasses.dataclass(frozen=True)
class GpsTrack:
    """GPS fixes: time (s since the drive's start), WGS84 lat/lon (deg) and height (m), and the ENU
    position each fix was made from (with the configured noise, if any)."""

    time_s: np.ndarray   # (F,) float64
    lat: np.ndarray      # (F,) float64
    lon: np.ndarray
    alt: np.ndarray
    enu: np.ndarray      # (F, 3) float64

    def __len__(self) -> int:
        return len(self.time_s)

    @classmethod
    def from_enu(cls, time_s, enu, origin) -> "GpsTrack":
        enu = np.asarray(enu, np.float64).reshape(-1, 3)
        lat, lon, alt = enu_to_geodetic(enu, origin)
        return cls(np.asarray(time_s, np.float64), lat, lon, alt, enu)

    def arrays(self, prefix: str = "gps_") -> dict[str, np.ndarray]:
        return {f"{prefix}{f.name}": getattr(self, f.name) for f in dataclasses.fields(self)}


@dataclasses.dataclass(frozen=True)
class EgoPose:
    """The camera's exact pose at a frame: ENU (m, U = camera height), WGS84, compass heading (rad,
    clockwise from north: forward = (sin h, cos h)), ground speed (m/s), time (s)."""

    time_s: float
    enu: tuple[float, float, float]
    lat: float
    lon: float
    alt: float
    heading_rad: float
    speed_mps: float

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "EgoPose":
        return cls(**{**d, "enu": tuple(d["enu"])})
