"""WGS84 geodetic <-> ECEF <-> local East-North-Up, as thin array wrappers over pymap3d.

pymap3d is the maintained implementation (reference-spec §2: WGS84 a = 6378137 m, b = 6356752.31424518
m; ECEF to geodetic by You (2000), no iteration); these functions only fix the array conventions
the rest of the project uses, so nothing here re-derives a formula:

- points are (..., 3) float64 arrays (any leading shape, including none) of ECEF (x, y, z) metres
  or ENU (east, north, up) metres; geodetic positions are three separate (...) arrays (lat deg,
  lon deg, ellipsoidal height m), the order pymap3d and GeoJSON readers expect to unpack;
- an `origin` is (lat0 deg, lon0 deg, h0 m): the point where the ENU frame touches the ellipsoid
  (its up axis is the ellipsoid normal there, its north axis points to true north there);
- vectors (velocities, directions) rotate without the origin's translation: `ecef_to_enu_vector`
  and `enu_to_ecef_vector` need only (lat0, lon0).

Everything is float64: a float32 ECEF coordinate (~6.4e6 m) has a 0.5 m rounding step.
"""

from __future__ import annotations

import numpy as np
import pymap3d


def _origin(origin) -> tuple[float, float, float]:
    """A checked (lat0, lon0, h0): finite, latitude in [-90, 90], longitude in [-180, 360)."""
    try:
        lat0, lon0, h0 = (float(v) for v in origin)
    except (TypeError, ValueError):
        raise ValueError(f"origin must be (lat deg, lon deg, height m); got {origin!r}") from None
    if not (np.isfinite([lat0, lon0, h0]).all() and -90 <= lat0 <= 90 and -180 <= lon0 < 360):
        raise ValueError(f"origin (lat, lon, height) = {origin!r}; expected finite values with latitude in "
                         "[-90, 90] deg and longitude in [-180, 360) deg")
    return lat0, lon0, h0


def _points(xyz, what: str) -> np.ndarray:
    xyz = np.asarray(xyz, np.float64)
    if xyz.ndim < 1 or xyz.shape[-1] != 3:
        raise ValueError(f"{what} must be a (..., 3) array; got shape {xyz.shape}")
    return xyz


def _stack(a, b, c) -> np.ndarray:
    return np.stack([np.asarray(a, np.float64), np.asarray(b, np.float64), np.asarray(c, np.float64)], -1)


def _triple(a, b, c) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return np.asarray(a, np.float64), np.asarray(b, np.float64), np.asarray(c, np.float64)


def _geodetic(lat, lon, alt) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    lat, lon, alt = np.broadcast_arrays(*_triple(lat, lon, alt))
    return lat, lon, alt


def geodetic_to_ecef(lat, lon, alt) -> np.ndarray:
    """(...) lat deg, lon deg, height m -> (..., 3) ECEF metres."""
    return _stack(*pymap3d.geodetic2ecef(*_geodetic(lat, lon, alt)))


def ecef_to_geodetic(xyz) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(..., 3) ECEF metres -> (lat deg, lon deg, height m), each (...)."""
    xyz = _points(xyz, "ECEF points")
    return _triple(*pymap3d.ecef2geodetic(xyz[..., 0], xyz[..., 1], xyz[..., 2]))


def ecef_to_enu(xyz, origin) -> np.ndarray:
    """(..., 3) ECEF metres -> (..., 3) ENU metres about `origin`."""
    xyz = _points(xyz, "ECEF points")
    return _stack(*pymap3d.ecef2enu(xyz[..., 0], xyz[..., 1], xyz[..., 2], *_origin(origin)))


def enu_to_ecef(enu, origin) -> np.ndarray:
    """(..., 3) ENU metres about `origin` -> (..., 3) ECEF metres."""
    enu = _points(enu, "ENU points")
    return _stack(*pymap3d.enu2ecef(enu[..., 0], enu[..., 1], enu[..., 2], *_origin(origin)))


def geodetic_to_enu(lat, lon, alt, origin) -> np.ndarray:
    """(...) lat deg, lon deg, height m -> (..., 3) ENU metres about `origin`."""
    return _stack(*pymap3d.geodetic2enu(*_geodetic(lat, lon, alt), *_origin(origin)))


def enu_to_geodetic(enu, origin) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(..., 3) ENU metres about `origin` -> (lat deg, lon deg, height m), each (...)."""
    enu = _points(enu, "ENU points")
    return _triple(*pymap3d.enu2geodetic(enu[..., 0], enu[..., 1], enu[..., 2], *_origin(origin)))


def ecef_to_enu_vector(uvw, lat0: float, lon0: float) -> np.ndarray:
    """(..., 3) ECEF vector -> (..., 3) ENU vector at (lat0, lon0): a rotation, no translation."""
    uvw = _points(uvw, "ECEF vectors")
    lat0, lon0, _ = _origin((lat0, lon0, 0.0))
    return _stack(*pymap3d.ecef2enuv(uvw[..., 0], uvw[..., 1], uvw[..., 2], lat0, lon0))


def enu_to_ecef_vector(enu, lat0: float, lon0: float) -> np.ndarray:
    """(..., 3) ENU vector at (lat0, lon0) -> (..., 3) ECEF vector (pymap3d.enu2uvw)."""
    enu = _points(enu, "ENU vectors")
    lat0, lon0, _ = _origin((lat0, lon0, 0.0))
    return _stack(*pymap3d.enu2uvw(enu[..., 0], enu[..., 1], enu[..., 2], lat0, lon0))
