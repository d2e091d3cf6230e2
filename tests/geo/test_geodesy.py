"""geo.geodesy against pymap3d's own published values (rd-yolo-camera-facts §4) and round trips."""

import numpy as np
import pytest

from dsfec_jax.data.camera.street import geo as street_geo
from dsfec_jax.geo import geodesy

ORIGIN = (42.0, -82.0, 200.0)
ECEF_ORIGIN = (660675.2518247, -4700948.68316, 4245737.66222)   # geodetic2ecef(42, -82, 200)
ENU_AER = (186.2775, 286.8422, 939.6926)                         # aer2enu(33, 70, 1000)
ECEF_AER = (660930.19276, -4701424.22296, 4246579.60463)        # aer2ecef(33, 70, 1000, 42, -82, 200)


def test_geodetic_to_ecef_matches_the_published_value():
    np.testing.assert_allclose(geodesy.geodetic_to_ecef(*ORIGIN), ECEF_ORIGIN, atol=1e-4)
    lat, lon, alt = geodesy.ecef_to_geodetic(np.array(ECEF_ORIGIN))
    np.testing.assert_allclose((lat, lon), ORIGIN[:2], atol=1e-9)
    assert alt == pytest.approx(ORIGIN[2], abs=1e-4)


def test_ecef_and_enu_pair_the_published_vectors():
    """aer2ecef(33, 70, 1000, origin) is the point aer2enu(33, 70, 1000) in ENU about the origin."""
    np.testing.assert_allclose(geodesy.ecef_to_enu(np.array(ECEF_AER), ORIGIN), ENU_AER, atol=1e-3)
    np.testing.assert_allclose(geodesy.enu_to_ecef(np.array(ENU_AER), ORIGIN), ECEF_AER, atol=1e-3)


def test_vectors_rotate_without_the_origin():
    out = geodesy.ecef_to_enu_vector(np.array([5.0, 3.0, 2.0]), 42.0, -82.0)
    np.testing.assert_allclose(out, (5.368859646588048, 3.008520763668120, -0.352347711524077), atol=1e-12)
    np.testing.assert_allclose(geodesy.enu_to_ecef_vector(out, 42.0, -82.0), (5.0, 3.0, 2.0), atol=1e-12)


def test_round_trips_keep_any_leading_shape():
    rng = np.random.default_rng(0)
    enu = rng.uniform(-5000, 5000, (4, 5, 3))
    lat, lon, alt = geodesy.enu_to_geodetic(enu, ORIGIN)
    assert lat.shape == lon.shape == alt.shape == (4, 5) and lat.dtype == np.float64
    back = geodesy.geodetic_to_enu(lat, lon, alt, ORIGIN)
    assert back.shape == (4, 5, 3) and np.abs(back - enu).max() < 1e-6
    ecef = geodesy.enu_to_ecef(enu, ORIGIN)
    assert np.abs(geodesy.ecef_to_enu(ecef, ORIGIN) - enu).max() < 1e-6
    np.testing.assert_allclose(geodesy.geodetic_to_ecef(lat, lon, alt), ecef, atol=1e-6)
    assert geodesy.geodetic_to_enu(*ORIGIN, ORIGIN) == pytest.approx([0.0, 0.0, 0.0], abs=1e-9)
    empty = geodesy.enu_to_geodetic(np.zeros((0, 3)), ORIGIN)
    assert all(a.shape == (0,) for a in empty)


def test_bad_origins_and_shapes_are_named():
    with pytest.raises(ValueError, match="latitude in"):
        geodesy.enu_to_geodetic(np.zeros(3), (95.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="origin must be"):
        geodesy.geodetic_to_enu(0.0, 0.0, 0.0, (1.0, 2.0))
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        geodesy.ecef_to_enu(np.zeros((2, 2)), ORIGIN)


def test_the_street_benchmark_uses_these_functions():
    """data/camera/street/geo.py keeps its public names, now geodesy's functions."""
    assert street_geo.enu_to_geodetic is geodesy.enu_to_geodetic
    assert street_geo.geodetic_to_enu is geodesy.geodetic_to_enu
