"""The real OpenRadar TI capture through the chain (data/rd/ti_adc.py), and its reader's errors."""

import dataclasses

import numpy as np
import pytest
from conftest import shared_data_dir
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dsfec_jax.data.rd.processing import RDProcessing
from dsfec_jax.data.rd.stats import dataset_stats, format_stats_table, structure_stats
from dsfec_jax.data.rd.ti_adc import (CAPTURES, RANGE_RESOLUTION_M, VELOCITY_RESOLUTION_MPS, find_capture,
                                      load_ti_sample, read_ti_adc, strongest_moving_target, ti_sensor)

FUZZ = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
TI_DIR = shared_data_dir() / "openradar_ti_adc"
SMALL = dataclasses.replace(ti_sensor(1, 1), num_samples=8, num_chirps=4)  # an (4 chirps, 8 samples) file


def test_sensor_matches_the_notebook_formulas():
    s = ti_sensor()
    assert abs(RANGE_RESOLUTION_M - 0.0488) < 1e-4 and abs(VELOCITY_RESOLUTION_MPS - 0.0823) < 1e-4
    assert abs(s.slope_hz_per_s - 60e12) < 1e6 and abs(s.chirp_interval_s - 92e-6) < 1e-9
    assert abs(s.adc_time_s - 51.2e-6) < 1e-12 and s.num_channels == 8
    single = CAPTURES["simple_frame_1.npy"][1]
    assert single.num_channels == 1 and abs(single.chirp_interval_s - 184e-6) < 1e-9
    np.testing.assert_allclose(single.velocity_axis(), s.velocity_axis())


def test_strongest_moving_target_is_the_approaching_one_at_two_metres():
    sample = load_ti_sample(TI_DIR)
    assert sample.source == "ti-adc" and sample.shape == (128, 128) and len(sample.boxes) == 0
    target = strongest_moving_target(sample)
    assert target["range_bin"] == 41 and abs(target["range_m"] - 2.0) < 0.05
    assert target["doppler_bin"] == 56 and target["approaching"] and target["velocity_mps"] < 0
    assert target["peak_db_above_floor"] > 40
    # the zero-Doppler ridge (static leakage at range bin 1) wins when nothing is excluded
    assert strongest_moving_target(sample, 0)["velocity_mps"] == 0


def test_eight_channel_capture_and_statistics_without_boxes():
    sample = load_ti_sample(TI_DIR, "doppler_example_1.npy")
    assert sample.sensor.num_channels == 8 and sample.shape == (128, 128)
    target = strongest_moving_target(sample, exclude_zero_doppler_bins=2)
    assert target["range_bin"] == 60 and not target["approaching"]
    stats = dataset_stats([sample, load_ti_sample(TI_DIR)])
    assert stats["boxes"] == 0 and stats["box_range_bins"] is None and stats["peak_above_floor_db"] is None
    assert 0.5 < stats["zero_doppler_share"]["median"] < 1 and stats["noise_floor"]["db"]["median"] > 40
    assert "ti" in format_stats_table({"ti": stats})
    hamming = load_ti_sample(TI_DIR, processing=RDProcessing(window="hamming", integration="log_sum"))
    assert hamming.scale == "normalised" and strongest_moving_target(hamming)["peak_db_above_floor"] is None


def test_map_structure_of_the_capture():
    """The figures the RD benchmark's v2 is measured against (docs/range-doppler.md): a zero-Doppler
    ridge at every range, the IF chain's floor shape, the Tx->Rx leakage as the map's maximum."""
    eight = structure_stats(load_ti_sample(TI_DIR, "doppler_example_1.npy"))
    assert eight["ridge_excess_db"] == pytest.approx(27.96, abs=0.05) and eight["strong_ridge_rows"] == 45
    assert eight["rows"] == 127 and eight["floor_std_db"] == pytest.approx(2.08, abs=0.01)
    assert eight["near_minus_far_db"] == pytest.approx(-1.51, abs=0.01)
    assert eight["edge_minus_far_db"] == pytest.approx(-8.03, abs=0.01)
    assert eight["max_minus_median_db"] == pytest.approx(55.88, abs=0.01)
    assert eight["p99_minus_median_db"] == pytest.approx(27.48, abs=0.01)
    one = structure_stats(load_ti_sample(TI_DIR))
    assert one["strong_ridge_rows"] == 49 and one["max_minus_median_db"] == pytest.approx(56.97, abs=0.01)


def test_unsigned_words_are_read_as_int16(tmp_path):
    words = np.array([[0, 1, 32767, 32768, 65535, 65400, 7, 8]] * 4, np.float64)
    path = tmp_path / "capture.npy"
    np.save(path, words + 1j * words[:, ::-1])
    adc, sensor = read_ti_adc(path, SMALL)
    assert adc.shape == (8, 4, 1) and sensor is SMALL
    np.testing.assert_array_equal(adc[:, 0, 0].real, [0, 1, 32767, -32768, -1, -136, 7, 8])
    np.testing.assert_array_equal(adc[:, 0, 0].imag, [8, 7, -136, -1, -32768, 32767, 1, 0])
    np.save(path, (words - 32768 * (words > 32767) * 2 + 0j))  # signed already: no change
    np.testing.assert_array_equal(read_ti_adc(path, SMALL)[0][:, 0, 0].real, [0, 1, 32767, -32768, -1, -136, 7, 8])


def test_missing_files_raise_filenotfound(tmp_path):
    with pytest.raises(FileNotFoundError, match="simple_frame_1"):
        load_ti_sample(tmp_path)
    with pytest.raises(FileNotFoundError):
        read_ti_adc(tmp_path / "simple_frame_1.npy")


@pytest.mark.parametrize("array, match", [
    (np.zeros((4, 8)), "dtype"),                                  # real, not complex words
    (np.zeros((4, 7), complex), "shape"),
    (np.full((4, 8), 70000 + 0j), r"\[0, 65535\]"),
    (np.full((4, 8), 0.5 + 0j), "integers"),
    (np.array([[-1, 40000] * 4] * 4, complex), "mix"),
])
def test_bad_captures_raise_valueerror_naming_the_file(tmp_path, array, match):
    path = tmp_path / "bad.npy"
    np.save(path, array)
    with pytest.raises(ValueError, match=match) as err:
        read_ti_adc(path, SMALL)
    assert "bad.npy" in str(err.value)


def test_unknown_file_needs_a_sensor(tmp_path):
    path = tmp_path / "other.npy"
    np.save(path, np.zeros((4, 8), complex))
    with pytest.raises(ValueError, match="other.npy.*FMCWSensor"):
        read_ti_adc(path)
    assert find_capture(path) == path


@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


@pytest.fixture(scope="module")
def good_bytes(tmp_path_factory):
    path = tmp_path_factory.mktemp("ti") / "good.npy"
    np.save(path, np.arange(32, dtype=np.float64).reshape(4, 8) * (1 + 1j))
    return path.read_bytes()


@FUZZ
@given(cut=st.integers(0, 128 + 32 * 16 - 1))
def test_truncated_capture_raises_valueerror(fuzz_dir, good_bytes, cut):
    path = fuzz_dir / "cut.npy"
    path.write_bytes(good_bytes[:cut])
    with pytest.raises(ValueError, match="cut.npy"):
        read_ti_adc(path, SMALL)


@FUZZ
@given(pos=st.integers(0, 127), byte=st.integers(0, 255))
def test_corrupt_header_reads_or_raises_valueerror(fuzz_dir, good_bytes, pos, byte):
    data = bytearray(good_bytes)
    data[pos] = byte
    path = fuzz_dir / "flip.npy"
    path.write_bytes(bytes(data))
    try:
        adc, _ = read_ti_adc(path, SMALL)
    except ValueError as e:
        assert "flip.npy" in str(e)
    else:
        assert adc.shape == (8, 4, 1)
