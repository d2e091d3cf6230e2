"""geo.gps: reading and cleaning fixes, interpolating the ego's position, heading from the track."""

import json
import math

import numpy as np
import pytest

from dsfec_jax.data.camera.street import StreetConfig, generate_drive
from dsfec_jax.geo.geodesy import enu_to_geodetic
from dsfec_jax.geo.gps import EgoTrack, GpsFixes, clean_fixes, read_gps, write_gps_csv

ORIGIN = (49.0, 8.4, 115.0)


def fixes_from_enu(times, enu, **kw) -> GpsFixes:
    lat, lon, alt = enu_to_geodetic(np.asarray(enu, np.float64), ORIGIN)
    return GpsFixes(np.asarray(times, np.float64), lat, lon, alt, **kw)


def angle_error(a, b):
    return np.abs(np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b)))))


def test_interpolation_is_exact_on_a_straight_constant_speed_track():
    t = np.arange(6.0)
    v = np.array([3.0, 4.0, 0.0])                                  # 5 m/s towards heading atan2(3, 4)
    track = EgoTrack(fixes_from_enu(t, t[:, None] * v + [10.0, -20.0, 1.4]), origin=ORIGIN)
    frames = np.linspace(0, 5, 51)
    np.testing.assert_allclose(track.position(frames), frames[:, None] * v + [10.0, -20.0, 1.4], atol=1e-6)
    np.testing.assert_allclose(track.heading(frames), math.atan2(3, 4), atol=1e-9)
    state = track.state(2.5)
    assert state.to_dict().keys() == {"lat", "lon", "alt", "heading_deg"}
    assert state.heading_deg == pytest.approx(math.degrees(math.atan2(3, 4)))


@pytest.mark.parametrize("direction, heading", [((0, 1), 0.0), ((1, 0), math.pi / 2), ((0, -1), math.pi),
                                                ((-1, 0), 1.5 * math.pi)])
def test_heading_is_a_compass_angle(direction, heading):
    t = np.arange(4.0)
    enu = np.stack([t * 8 * direction[0], t * 8 * direction[1], 0 * t], 1)
    h = EgoTrack(fixes_from_enu(t, enu)).heading([0.0, 1.5, 3.0])
    assert np.all(angle_error(h, heading) < 1e-9)


def test_midpoint_headings_follow_a_curve_the_chord_lags():
    """On a circle the chord heading of a segment is the tangent at its middle time, and the
    heading grows linearly in time, so blending between middles is exact; the chord held over
    its second is off by up to half a second of turning."""
    radius, speed = 60.0, 10.0
    omega = speed / radius                                          # rad/s, clockwise (compass)
    t = np.arange(11.0)
    theta = omega * t                                               # heading at t
    enu = np.stack([radius * (1 - np.cos(theta)), radius * np.sin(theta), 0 * t], 1)
    frames = np.linspace(0.5, 9.5, 91)                              # between the first and last middles
    mid = EgoTrack(fixes_from_enu(t, enu), origin=ORIGIN).heading(frames)
    chord = EgoTrack(fixes_from_enu(t, enu), origin=ORIGIN, heading="chord").heading(frames)
    assert angle_error(mid, omega * frames).max() < 1e-6
    assert angle_error(chord, omega * frames).max() == pytest.approx(omega / 2, rel=0.05)


def test_a_stationary_ego_keeps_its_last_heading():
    # north for 3 s, stopped (20 cm of jitter) for 3 s, then east
    enu = [[0, 0, 0], [0, 10, 0], [0, 20, 0], [0, 30, 0], [0.2, 30, 0], [0.1, 30.1, 0], [0, 30, 0],
           [10, 30, 0], [20, 30, 0]]
    track = EgoTrack(fixes_from_enu(np.arange(9.0), enu), heading="chord")
    h = track.heading([1.5, 3.5, 4.5, 5.5, 7.5])
    assert np.all(angle_error(h[:4], 0.0) < 1e-9)
    assert h[4] == pytest.approx(math.pi / 2)


def test_an_ego_that_has_not_moved_yet_takes_its_first_moving_heading():
    enu = [[0, 0, 0], [0.3, 0, 0], [0, 0.2, 0], [0, 0, 0], [10, 0, 0], [20, 0, 0]]   # waits, then drives east
    h = EgoTrack(fixes_from_enu(np.arange(6.0), enu)).heading([0.0, 1.0, 2.5, 4.0, 5.0])
    np.testing.assert_allclose(h, math.pi / 2, atol=1e-9)
    parked = EgoTrack(fixes_from_enu(np.arange(3.0), [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]]))
    with pytest.raises(ValueError, match="never moves"):
        parked.heading(1.0)


def test_times_outside_the_fixes_or_in_a_gap_are_not_covered():
    t = np.array([0.0, 1.0, 2.0, 7.0, 8.0])                          # 5 s without a fix
    track = EgoTrack(fixes_from_enu(t, t[:, None] * [0, 10, 0]), max_gap_s=3.0)
    np.testing.assert_array_equal(track.covered([-0.1, 0.0, 1.5, 2.0, 4.0, 7.0, 8.0, 8.1]),
                                  [False, True, True, True, False, True, True, False])
    with pytest.raises(ValueError, match=r"not covered.*\[0.0, 8.0\].*1 gap"):
        track.position([1.0, 4.0])
    with pytest.raises(ValueError, match="clean_fixes"):
        EgoTrack(fixes_from_enu([0.0, 2.0, 1.0], np.zeros((3, 3))))


def test_bad_fixes_are_skipped_and_counted():
    t = np.array([0, 1, 2, 3, 1000, 5, 6, 6, 8, 9], np.float64)     # a wild timestamp, a repeat
    lat = np.full(10, 49.0)
    lon = np.full(10, 8.4)
    lat[1], lat[2], lon[3] = np.nan, 95.0, 200.0
    fixes = GpsFixes(t, lat, lon, np.full(10, 100.0), source="drive.csv")
    clean, report = clean_fixes(fixes)
    np.testing.assert_array_equal(clean.time_s, [0, 5, 6, 8, 9])
    assert report.skipped == {"not_finite": 1, "latitude": 1, "longitude": 1, "time_order": 2}
    assert report.total == 10 and report.kept == 5 and report.num_skipped == 5
    assert report.examples[0] == "drive.csv fix 1: lat = nan; expected a finite number"
    assert "kept 5 of 10" in str(report)


def test_strict_cleaning_names_the_file_row_and_field():
    lat = np.array([49.0, 49.0, 95.0])
    with pytest.raises(ValueError, match=r"gps.csv line 4: lat = 95.0; expected a latitude in \[-90, 90\]"):
        clean_fixes(GpsFixes([0, 1, 2], lat, [8.4] * 3, [0] * 3, source="gps.csv", rows=[2, 3, 4], row_name="line"),
                    strict=True)
    with pytest.raises(ValueError, match=r"item 2: time_s = 0.5 is not after 1.0 \(x.json item 1\)"):
        clean_fixes(GpsFixes([0, 1, 0.5], [49.0] * 3, [8.4] * 3, [0] * 3, source="x.json", row_name="item"),
                    strict=True)
    ok, report = clean_fixes(GpsFixes([0, 1], [49.0] * 2, [8.4] * 2, [0] * 2), strict=True)
    assert len(ok) == 2 and report.num_skipped == 0


def test_csv_and_json_files_read_and_name_their_errors(tmp_path):
    fixes = GpsFixes([0.0, 1.0, 2.0], [49.0, 49.0001, 49.0002], [8.4, 8.4, 8.4001], [115.0, 115.5, 116.0])
    path = tmp_path / "gps.csv"
    write_gps_csv(path, fixes)
    back = read_gps(path)
    for f in ("time_s", "lat", "lon", "alt"):
        np.testing.assert_array_equal(getattr(back, f), getattr(fixes, f))
    np.testing.assert_array_equal(back.rows, [2, 3, 4])
    (tmp_path / "odd.csv").write_text("lat,lon,time_s,alt,hdop\n49,8.4,0,100,1\n,8.4,1,100,1\n")
    odd = read_gps(tmp_path / "odd.csv")                          # any column order; empty cell = no fix
    assert odd.time_s.tolist() == [0.0, 1.0] and math.isnan(odd.lat[1])
    (tmp_path / "bad.csv").write_text("time_s,lat,lon,alt\n0,49,8.4,100\n1,49,8.4,100\n2,abc,8.4,100\n")
    with pytest.raises(ValueError, match=r"bad.csv line 4: lat = 'abc'; expected a number"):
        read_gps(tmp_path / "bad.csv")
    (tmp_path / "short.csv").write_text("time_s,lat,lon,alt\n0,49,8.4\n")
    with pytest.raises(ValueError, match=r"short.csv line 2: 3 values; expected 4"):
        read_gps(tmp_path / "short.csv")
    (tmp_path / "head.csv").write_text("t,lat,lon,alt\n0,49,8.4,100\n")
    with pytest.raises(ValueError, match=r"head.csv line 1: .*lacks \['time_s'\]"):
        read_gps(tmp_path / "head.csv")
    (tmp_path / "gps.json").write_text(json.dumps([{"time_s": 0, "lat": 49, "lon": 8.4, "alt": 1},
                                                   {"time_s": 1, "lat": None, "lon": 8.4, "alt": 1}]))
    js = read_gps(tmp_path / "gps.json")
    assert js.time_s.tolist() == [0.0, 1.0] and math.isnan(js.lat[1]) and js.where(1).endswith("gps.json item 1")
    (tmp_path / "bad.json").write_text(json.dumps([{"time_s": 0, "lat": 49, "lon": 8.4}]))
    with pytest.raises(ValueError, match=r"bad.json item 0: missing \['alt'\]"):
        read_gps(tmp_path / "bad.json")


def test_on_the_synthetic_drive_the_errors_stay_within_their_bounds():
    """300 frames (30 s) of a test drive, 1 Hz exact fixes: the position error is the chord's
    sagitta, at most v^2 T^2 / (8 R) = 14^2 / (8 * 60) = 0.41 m (the config's fastest ego on its
    tightest curve); midpoint headings beat chord headings (measured: mean 0.03 vs 0.38 deg)."""
    cfg = StreetConfig()
    drive = generate_drive(cfg, "test", 0, num_frames=300)
    poses = drive.poses()
    exact_enu = np.array([p.enu for p in poses])
    exact_heading = np.array([p.heading_rad for p in poses])
    clean, report = clean_fixes(GpsFixes.from_track(drive.gps))
    assert report.num_skipped == 0 and len(clean) == 31
    errors = {}
    for mode in ("midpoint", "chord"):
        track = EgoTrack(clean, origin=cfg.origin, heading=mode)
        pos = np.hypot(*(track.position(drive.times)[:, :2] - exact_enu[:, :2]).T)
        assert pos.max() < 0.41
        errors[mode] = np.degrees(angle_error(track.heading(drive.times), exact_heading))
    assert errors["midpoint"].mean() < 0.5 * errors["chord"].mean()
    assert np.median(errors["midpoint"]) < 0.05 and errors["midpoint"].max() < 3.0
