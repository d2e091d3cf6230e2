"""The ego's track and GPS: ENU <-> WGS84 through pymap3d, 1 Hz fixes on the same track, heading
along the track, objects that persist across the frames of a drive."""

import dataclasses
import math

import numpy as np
import pymap3d
import pytest

from dsfec_jax.data.camera.street.config import KARLSRUHE
from dsfec_jax.data.camera.street.generate import generate_drive, generate_frame
from dsfec_jax.data.camera.street.geo import GpsTrack, enu_to_geodetic

from street_scenes import TINY


@pytest.fixture(scope="module")
def drive():
    return generate_drive(TINY, "val", 0, num_frames=201)  # 20 s at 10 Hz, poses only unless rendered


def test_pymap3d_oracle_holds():
    """reference-spec §2 / rd-yolo-camera-facts §4: geodetic2ecef(42, -82, 200)."""
    x, y, z = pymap3d.geodetic2ecef(42, -82, 200)
    np.testing.assert_allclose((x, y, z), (660675.2518247, -4700948.68316, 4245737.66222), atol=1e-4)


def test_frame_positions_convert_to_lat_lon_and_back(drive):
    poses = drive.poses()
    enu = np.array([p.enu for p in poses])
    lat, lon, alt = np.array([p.lat for p in poses]), np.array([p.lon for p in poses]), np.array([p.alt for p in poses])
    back = np.stack(pymap3d.geodetic2enu(lat, lon, alt, *KARLSRUHE), 1)
    assert np.abs(back - enu).max() < 1e-6
    assert np.all(np.abs(lat - KARLSRUHE[0]) < 0.2) and np.all(np.abs(lon - KARLSRUHE[1]) < 0.3)
    np.testing.assert_allclose(enu[:, 2], TINY.camera_height_m)  # the antenna sits at the camera


def test_one_hz_fixes_are_samples_of_the_same_track(drive):
    gps, poses = drive.gps, drive.poses()
    np.testing.assert_array_equal(gps.time_s, np.arange(21.0))
    for j, t in enumerate(gps.time_s):
        pose = poses[int(round(t * TINY.fps))]
        assert pose.time_s == pytest.approx(t)
        np.testing.assert_allclose(gps.enu[j], pose.enu, atol=1e-9)
        assert (gps.lat[j], gps.lon[j], gps.alt[j]) == pytest.approx((pose.lat, pose.lon, pose.alt), abs=1e-12)


def test_heading_is_the_direction_of_the_track_and_the_road_turns(drive):
    poses = drive.poses()
    enu = np.array([p.enu for p in poses])
    heading = np.unwrap([p.heading_rad for p in poses])
    chord = np.arctan2(enu[2:, 0] - enu[:-2, 0], enu[2:, 1] - enu[:-2, 1])  # compass: atan2(dE, dN)
    err = np.angle(np.exp(1j * (chord - heading[1:-1])))
    assert np.abs(err).max() < 2e-3
    assert np.ptp(heading) > math.radians(5)  # the drive goes round a curve
    speed = np.linalg.norm(np.diff(enu[:, :2], axis=0), axis=1) * TINY.fps
    ratio = speed / np.array([p.speed_mps for p in poses[:-1]])
    assert np.median(np.abs(ratio - 1)) < 1e-3  # off only across a change of curvature


def test_gps_noise_moves_the_fixes_not_the_poses():
    cfg = dataclasses.replace(TINY, gps_noise_m=3.0)
    noisy, exact = generate_drive(cfg, "val", 0, num_frames=31), generate_drive(TINY, "val", 0, num_frames=31)
    assert [p.enu for p in noisy.poses()] == [p.enu for p in exact.poses()]
    shift = np.linalg.norm(noisy.gps.enu[:, :2] - exact.gps.enu[:, :2], axis=1)
    assert 0 < shift.mean() < 10


def test_single_frames_carry_the_fixes_around_them():
    frame = generate_frame(TINY, "test", 2)
    np.testing.assert_array_equal(frame.gps.time_s, [0.0, 1.0])
    np.testing.assert_allclose(frame.gps.enu[0], frame.ego.enu)
    lat, lon, _ = enu_to_geodetic(np.array(frame.ego.enu), TINY.origin)
    assert (frame.ego.lat, frame.ego.lon) == pytest.approx((float(lat), float(lon)), abs=1e-12)


def test_objects_persist_across_the_frames_of_a_drive(drive):
    cfg = dataclasses.replace(TINY, width=160)
    d = generate_drive(cfg, "val", 0, num_frames=5)
    a, b = d.frame(0), d.frame(1)
    common = np.intersect1d(a.objects.id, b.objects.id)
    assert len(common) >= 2
    for oid in common:
        moved = np.linalg.norm(b.objects.center_enu[list(b.objects.id).index(oid)]
                               - a.objects.center_enu[list(a.objects.id).index(oid)])
        assert moved <= max(s.speed_mps[1] for s in cfg.specs) / cfg.fps + 1e-6
    assert b.ego.time_s == pytest.approx(0.1) and b.gps is d.gps
    assert b.frame_id.endswith("0000-0001")


def test_gps_track_keeps_its_inputs():
    track = GpsTrack.from_enu([0.0, 1.0], [[0, 0, 0], [100.0, 0, 0]], KARLSRUHE)
    assert track.lat[0] == pytest.approx(KARLSRUHE[0]) and track.lon[1] > track.lon[0] and len(track) == 2
