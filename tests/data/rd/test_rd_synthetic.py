"""The FMCW RD simulator (data/rd/synthetic): exact frequency-domain synthesis, physics, boxes,
determinism, cache, and the statistics module on its samples."""

import dataclasses
import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from fuzzing import JSON, bitflip, cache_reads_or_names, corruptions, manifest_reads_or_names, mutated

from dsfec_jax.data.rd.classes import RD_CLASSES
from dsfec_jax.data.rd.processing import RDProcessing, rd_spectra, spectra_to_rd
from dsfec_jax.data.rd.sensor import FMCWSensor
from dsfec_jax.boxes.boxes2d import Boxes2D
from dsfec_jax.data.rd.stats import (boxes_under_ridge, dataset_stats, format_stats_table, generation_rate,
                                     structure_summary, zero_doppler_share)
from dsfec_jax.data.rd.synthetic import (Actor, ClutterConfig, RDCachedDataset, RDSyntheticConfig, RDSyntheticDataset,
                                         generate_sample, open_cache, sample_rng, simulate, write_cache)
from dsfec_jax.data.rd.synthetic.boxes import circular_arc, extent_boxes
from dsfec_jax.data.rd.synthetic.config import benchmark_config
from dsfec_jax.data.rd.synthetic.if_chain import NO_IF_CHAIN, IFChain
from dsfec_jax.data.rd.synthetic.scatterers import Scatterers, area_clutter
from dsfec_jax.data.rd.synthetic.simulate import coupling_scatterer, mean_floor_power, render
from dsfec_jax.data.rd.synthetic.spectra import (SpectralFactors, adc_cube, add_static_spectra, complex_gaussian,
                                                 processed_noise, white_spectrum)

CFG = RDSyntheticConfig()
TINY = FMCWSensor(num_samples=16, num_chirps=8, num_tx=2, num_rx=2, range_resolution_m=0.5,
                  velocity_resolution_mps=1.0, sample_rate_hz=1e6)
FUZZ = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
QUIET = ClutterConfig(ground_scatterers=0.0, max_buildings=0, parked_vehicles=0.0, ghost_prob=0.0,
                      area_cells_per_bin=0.0, poles=0.0)
# an IF chain whose every part shows on TINY's 16 range bins, with the coupling at a fractional bin
TINY_CHAIN = IFChain(highpass_corner=0.2, highpass_noise_share=0.7, lowpass_corner=0.8, lowpass_order=4,
                     stopband_db=-10.0, coupling_snr_db=10.0, coupling_bin=0.9)
PROCESSINGS = [RDProcessing(), RDProcessing(window="hamming", dc_removal=False), RDProcessing(window="none")]


def scatterers(rng, k, static=False, sensor=TINY):
    v = np.zeros(k) if static else rng.uniform(-1.5, 1.5, k) * sensor.max_velocity_mps
    return Scatterers(rng.uniform(1, 0.9 * sensor.max_range_m, k), v, rng.uniform(-1, 1, k),
                      10 ** rng.uniform(-1, 2, k), rng.uniform(0, 2 * np.pi, k))


def _same(a, b) -> bool:
    return (np.array_equal(a.power, b.power) and np.array_equal(a.boxes.xyxy, b.boxes.xyxy)
            and np.array_equal(a.boxes.names, b.boxes.names))


# ----------------------------------------------------------------- exact frequency-domain synthesis


@pytest.mark.parametrize("chain", [NO_IF_CHAIN, TINY_CHAIN], ids=["flat", "if_chain"])
@pytest.mark.parametrize("proc", PROCESSINGS)
def test_frequency_domain_synthesis_equals_brute_force_time_domain(proc, chain):
    rng = np.random.default_rng(0)
    moving = scatterers(rng, 5)  # some beyond +-v_max: the Doppler folds in both
    want = rd_spectra(adc_cube(moving, TINY, 2.0, chain), TINY, proc)
    got = SpectralFactors.of(moving, TINY, proc, 2.0, np.complex128, chain).spectra()
    assert np.abs(got - want).max() <= 1e-9 * np.abs(want).max()
    single = SpectralFactors.of(moving, TINY, proc, 2.0, if_chain=chain).spectra()
    assert single.dtype == np.complex64 and np.abs(single - want).max() <= 1e-5 * np.abs(want).max()
    rows = SpectralFactors.of(moving, TINY, proc, 2.0, np.complex128, chain).spectra(slice(3, 9), slice(1, 3))
    part = rd_spectra(adc_cube(moving.select(slice(1, 3)), TINY, 2.0, chain), TINY, proc)[3:9]
    np.testing.assert_allclose(rows, part, atol=1e-9 * np.abs(part).max())
    # static scatterers, with the Tx->Rx coupling among them when the chain has one
    static = Scatterers.concat([scatterers(rng, 4, static=True), coupling_scatterer(chain, TINY)])
    want = rd_spectra(adc_cube(static, TINY, 2.0, chain), TINY, proc)
    got = add_static_spectra(np.zeros((16, 8, 4), complex), static, TINY, proc, 2.0, chain)
    assert np.abs(got - want).max() <= 1e-9 * np.abs(want).max()


def test_the_if_chain_scales_each_tone_and_sets_the_coupling_level():
    rng = np.random.default_rng(5)
    s = scatterers(rng, 6)
    ratio = np.abs(adc_cube(s.select(slice(2, 3)), TINY, 2.0, TINY_CHAIN)[:, 0, 0]) / np.abs(
        adc_cube(s.select(slice(2, 3)), TINY, 2.0)[:, 0, 0])
    from dsfec_jax.data.rd.synthetic.spectra import fast_time_cycles
    np.testing.assert_allclose(ratio, TINY_CHAIN.tone_gain(fast_time_cycles(s, TINY))[2], rtol=1e-9)
    gain = TINY_CHAIN.tone_gain(np.array([0.0, 0.2, 0.5, 0.8, 0.99]))
    assert gain[0] == 0 and gain[1] < gain[2] > gain[3] > gain[4] and gain[2] > 0.9  # high-pass, pass, low-pass
    coupling = adc_cube(coupling_scatterer(TINY_CHAIN, TINY), TINY, 2.0, TINY_CHAIN)  # 10 dB over 2 counts rms
    np.testing.assert_allclose(np.abs(coupling), 2.0 * 10 ** (10 / 20), rtol=1e-9)
    assert len(coupling_scatterer(NO_IF_CHAIN, TINY)) == 0
    profile = TINY_CHAIN.noise_power_profile(100)
    mid = 0.1 + 0.9 * (0.3 + 0.7 * 6.25 / 7.25) / (1 + (0.5 / 0.8) ** 8)  # f = 0.5: both filters' shoulders
    assert profile[0] == pytest.approx(0.3 * (1 - 0.1) + 0.1) and profile[50] == pytest.approx(mid)
    assert profile[99] < 0.3 and profile.min() >= 0.1  # rolled off, down to the stop band's floor at most
    for bad in (dict(highpass_corner=1.0), dict(highpass_noise_share=2.0), dict(coupling_snr_db=float("nan")),
                dict(stopband_db=3.0), dict(lowpass_order=0)):
        with pytest.raises(ValueError, match="IFChain"):
            dataclasses.replace(TINY_CHAIN, **bad)


@pytest.mark.parametrize("chain", [NO_IF_CHAIN, TINY_CHAIN], ids=["flat", "if_chain"])
@pytest.mark.parametrize("proc", PROCESSINGS)
def test_noise_spectra_equal_the_chain_on_the_adc_noise(proc, chain):
    rng = np.random.default_rng(1)
    white = white_spectrum(rng, TINY, 3.0, np.complex128)
    # the ADC noise whose unnormalised 2-D DFT is `white`, shaped per range bin by the IF chain
    adc = np.fft.ifft2(white * np.sqrt(chain.noise_power_profile(16))[:, None, None], axes=(0, 1))
    want = rd_spectra(adc, TINY, proc)
    np.testing.assert_allclose(processed_noise(white.copy(), proc, chain), want, atol=1e-9 * np.abs(want).max())
    # ... and that ADC noise is white with E|n|^2 = sigma^2 (checked on a bigger draw)
    big = FMCWSensor(num_samples=64, num_chirps=64, num_tx=2, num_rx=4)
    n = np.fft.ifft2(white_spectrum(rng, big, 3.0), axes=(0, 1))
    assert abs(np.mean(np.abs(n) ** 2) / 9.0 - 1) < 0.03 and abs(np.mean(n[1:] * n[:-1].conj())) < 0.1


@pytest.mark.parametrize("dtype", [np.complex64, np.complex128])
def test_complex_gaussian_has_the_circular_gaussian_law(dtype):
    z = complex_gaussian(np.random.default_rng(4), (200_000,), 2.0, dtype)
    assert z.dtype == dtype and np.isfinite(z).all()
    power = np.abs(z.astype(complex)) ** 2 / 4.0  # ~ Exp(1)
    for t in (0.1, 1.0, 3.0):
        assert abs(np.mean(power > t) - np.exp(-t)) < 0.005
    x = np.concatenate([z.real, z.imag]) / np.sqrt(2.0)  # ~ N(0, 1) each, independent
    assert abs(np.mean(x ** 2) - 1) < 0.01 and abs(np.mean(x ** 4) - 3) < 0.05
    assert abs(np.mean(np.abs(x) < 1) - 0.6827) < 0.005 and abs(np.mean(z.real * z.imag)) < 0.02


@pytest.mark.parametrize("chain", [NO_IF_CHAIN, IFChain(coupling_snr_db=None)], ids=["flat", "if_chain"])
def test_noise_floor_of_the_maps_is_the_expected_one(chain):
    cfg = dataclasses.replace(CFG, clutter=QUIET, empty_prob=1.0, if_chain=chain)
    spectra, *_ = render(sample_rng(0, "train", 0), cfg, [])
    power = np.sum(np.abs(spectra.astype(complex)) ** 2, axis=2)
    expected = mean_floor_power(cfg) * chain.noise_power_profile(len(power))[:, None]  # the floor's shape
    for rows in (slice(2, 40), slice(40, 200), slice(200, 243), slice(243, -1)):
        assert abs(power[rows].mean() / expected[rows].mean() - 1) < 0.03


# ----------------------------------------------------------------- physics


def test_a_point_target_appears_at_its_range_and_doppler_bin():
    s = CFG.sensor
    point = Scatterers(np.array([40 * s.range_resolution_m]), np.array([-5 * s.velocity_resolution_mps]),
                       np.array([0.3]), np.array([10.0]), np.array([0.0]))
    power, _ = spectra_to_rd(SpectralFactors.of(point, s, CFG.processing, CFG.noise_counts_rms).spectra())
    assert np.unravel_index(np.argmax(power), power.shape) == (40, 32 - 5)
    # the same through the whole simulator: a lone person walking straight at the radar, no clutter
    cfg = dataclasses.replace(CFG, clutter=QUIET)
    person = Actor("person", (10.0, 0.0), math.pi, 1.26, (0.5, 0.5), 5.0)
    sample = simulate(np.random.default_rng(0), cfg, actors=[person])
    (x1, y1, x2, y2), = sample.boxes.xyxy
    row, col = 10.0 / s.range_resolution_m, 32 - 1.26 / s.velocity_resolution_mps
    assert y1 <= row < y2 and x1 <= col < x2 and sample.boxes.names[0] == "person"
    assert sample.axes.velocity_mps[int(col)] < 0  # approaching -> negative velocity column


def _spans(name, heading_rad, speed, seeds=range(6)):
    """Mean (range rows, Doppler columns) of one object at 12 m, 5 dBsm, no clutter."""
    cfg = dataclasses.replace(CFG, clutter=QUIET)
    profile = cfg.profile(name)
    spans = []
    for seed in seeds:
        actor = Actor(name, (12.0, 0.0), heading_rad, speed, (profile.size_m[0], profile.size_m[1]), 5.0)
        boxes = simulate(np.random.default_rng(seed), cfg, actors=[actor]).boxes
        assert len(boxes) >= 1
        spans.append((boxes.wh[:, 1].max(), boxes.wh[:, 0].sum()))
    return np.mean(spans, axis=0)


def test_extended_targets_span_range_and_persons_span_doppler():
    radial = math.pi  # moving straight at the radar: length along the line of sight
    person, car = _spans("person", radial, 1.5), _spans("car", radial, 1.5)
    truck, bus = _spans("truck", radial, 1.5), _spans("bus", radial, 1.5)
    assert car[0] > person[0] + 5 and truck[0] > car[0] and bus[0] > truck[0]
    assert person[1] > car[1] + 1  # limbs: micro-Doppler (~5.8 vs 4.0 columns over 12 seeds)
    assert _spans("bicycle", radial, 4.0)[1] > _spans("car", radial, 4.0)[1] + 2  # wheels


def test_boxes_follow_the_radar_equation():
    cfg = dataclasses.replace(CFG, clutter=QUIET)
    near = Actor("car", (8.0, 0.0), math.pi / 2, 5.0, (1.9, 4.6), 11.0)
    far = Actor("person", (44.0, 0.0), 0.0, 1.0, (0.6, 0.6), -15.0)  # ~ -45 dB weaker: invisible
    sample = simulate(np.random.default_rng(3), cfg, actors=[near, far])
    assert list(sample.meta["object_labelled"]) == [True, False] and set(sample.boxes.names) == {"car"}
    assert sample.meta["box_object"].tolist() == [0] * len(sample.boxes)


# ----------------------------------------------------------------- boxes


def test_circular_arc_and_doppler_wrap_split():
    occ = np.zeros(64, bool)
    assert circular_arc(occ) is None
    occ[[62, 63, 0, 1]] = True
    assert circular_arc(occ) == (62, 2)
    mask = np.zeros((10, 64), bool)
    mask[3:6][:, [62, 63, 0, 1]] = True
    assert extent_boxes(mask, row_offset=100) == [(62.0, 103.0, 64.0, 106.0), (0.0, 103.0, 2.0, 106.0)]
    mask[:] = False
    mask[4, 10:20] = mask[6, 12] = True
    assert extent_boxes(mask) == [(10.0, 4.0, 20.0, 7.0)]
    assert circular_arc(np.ones(8, bool)) == (0, 8)


def test_a_target_at_the_velocity_edge_gets_two_boxes():
    cfg = dataclasses.replace(CFG, clutter=QUIET)
    s = cfg.sensor
    edge = Actor("car", (10.0, 0.0), 0.0, s.max_velocity_mps - 0.1, (1.9, 4.6), 11.0)  # receding at +v_max
    sample = simulate(np.random.default_rng(0), cfg, actors=[edge])
    xyxy = sample.boxes.xyxy
    assert len(xyxy) == 2 and xyxy[0, 2] == s.num_chirps and xyxy[1, 0] == 0
    assert np.array_equal(xyxy[0, [1, 3]], xyxy[1, [1, 3]]) and sample.meta["box_object"].tolist() == [0, 0]
    assert dataset_stats([sample])["objects_per_frame"]["car"] == 1.0  # one object, two boxes


# ----------------------------------------------------------------- dataset


@pytest.fixture(scope="module")
def val_samples():
    return [generate_sample(CFG, "val", i) for i in range(24)]


def test_samples_are_valid_and_varied(val_samples):
    names, counts = set(), []
    for s in val_samples:
        assert s.power.shape == (256, 64) and s.power.dtype == np.float32 and np.isfinite(s.power).all()
        assert s.source == "rd-synthetic" and s.scale == "log10" and s.sensor == CFG.sensor
        xyxy = s.boxes.xyxy
        assert ((xyxy >= 0) & (xyxy[:, [2, 3]] <= [64, 256]).all(1)[:, None]).all()
        assert (s.boxes.wh > 0).all() and set(s.boxes.names) <= set(RD_CLASSES)
        names |= set(s.boxes.names)
        counts.append(len(set(s.meta["box_object"].tolist())))
    assert 0 in counts and max(counts) >= 3 and len(names) >= 4  # empty frames, crowds, a class mix


def test_same_key_same_sample_and_other_keys_differ():
    a, b = generate_sample(CFG, "train", 5, seed=2), generate_sample(CFG, "train", 5, seed=2)
    assert _same(a, b) and a.sample_id == b.sample_id
    assert not _same(a, generate_sample(CFG, "val", 5, seed=2))
    assert not _same(a, generate_sample(CFG, "train", 6, seed=2))
    assert not _same(a, generate_sample(CFG, "train", 5, seed=3))
    ds = RDSyntheticDataset(CFG, "train", seed=2, num_samples=8)
    assert len(ds) == 8 and _same(ds[5], a) and _same(ds[-3], a)
    with pytest.raises(IndexError):
        ds[8]
    first = {s: {sample_rng(0, s, i).integers(2**62) for i in range(200)} for s in ("train", "val", "test")}
    assert len(first["train"] | first["val"] | first["test"]) == 600
    with pytest.raises(ValueError):
        sample_rng(0, "holdout", 0)


def test_config_round_trip_and_checks():
    cfg = dataclasses.replace(CFG, processing=RDProcessing(window="hamming"), clutter=QUIET, fov_deg=90.0)
    back = RDSyntheticConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
    assert back == cfg and hash(back) == hash(cfg)
    v1 = benchmark_config(1)
    assert RDSyntheticConfig.from_dict(json.loads(json.dumps(v1.to_dict()))) == v1 and v1.if_chain.is_flat
    with pytest.raises(ValueError, match="ClutterConfig"):
        ClutterConfig(area_cells_per_bin=-1.0)
    for bad in (dict(class_mix=(1.0,)), dict(min_range_m=60.0), dict(noise_counts_rms=0.0), dict(empty_prob=2.0)):
        with pytest.raises(ValueError):
            dataclasses.replace(CFG, **bad)


def test_cache_round_trip_and_corruption(tmp_path):
    ds = RDSyntheticDataset(CFG, "test", seed=1, num_samples=3)
    write_cache(ds, tmp_path / "c")
    cached = RDCachedDataset(tmp_path / "c", CFG, "test", 1)
    assert len(cached) == 3 and cached.cfg == CFG
    for i in range(3):
        a, b = ds[i], cached[i]
        assert _same(a, b) and a.sample_id == b.sample_id and b.sensor == CFG.sensor and b.scale == a.scale
        np.testing.assert_array_equal(a.axes.velocity_mps, b.axes.velocity_mps)
        assert b.meta["split"] == "test" and np.array_equal(a.meta["box_object"], b.meta["box_object"])
    assert open_cache(tmp_path / "c", CFG, "test", 1, 3).manifest == cached.manifest
    with pytest.raises(ValueError, match="split"):
        RDCachedDataset(tmp_path / "c", split="val")
    manifest = tmp_path / "c" / "manifest.json"
    good = manifest.read_text()
    for text in ("{not json", json.dumps({**json.loads(good), "count": 5}),
                 json.dumps({**json.loads(good), "files": ["../x.npz"] * 3}),
                 json.dumps({**json.loads(good), "config": {"sensor": 1}})):
        manifest.write_text(text)
        with pytest.raises(ValueError, match="manifest.json"):
            RDCachedDataset(tmp_path / "c")
    manifest.write_text(good)
    (tmp_path / "c" / "rd_000001.npz").write_bytes(b"PK\x03\x04garbage")
    with pytest.raises(ValueError, match="rd_000001.npz"):
        cached[1]
    manifest.unlink()
    with pytest.raises(FileNotFoundError):
        RDCachedDataset(tmp_path / "c")


# ----------------------------------------------------------------- statistics


def test_area_clutter_grows_with_range_and_covers_every_range():
    """Beam-limited area clutter: RCS proportional to R (power ~ R^-3 against R^-4), at every range bin."""
    clutter = dataclasses.replace(CFG.clutter, area_sigma0_sd_db=0.0, area_texture_sd_db=0.0)
    s = area_clutter(np.random.default_rng(3), dataclasses.replace(CFG, clutter=clutter))
    np.testing.assert_allclose(s.rcs_m2 / s.range_m, s.rcs_m2[0] / s.range_m[0], rtol=1e-9)
    assert np.all(s.velocity_mps == 0)
    rows = np.unique(np.floor(s.range_m / CFG.sensor.range_resolution_m).astype(int))
    near = int(clutter.area_min_range_m / CFG.sensor.range_resolution_m)
    assert len(rows) > 0.8 * (CFG.sensor.num_samples - near) and rows.max() >= CFG.sensor.num_samples - 2


def test_benchmark_v2_has_the_structure_of_the_real_capture(val_samples):
    """The mechanisms move the map structure into the TI capture's range (ridge, coverage, floor
    shape, leakage peak: docs/range-doppler.md measures the capture); v1 had none of it."""
    new = structure_summary(val_samples[:12])
    old = structure_summary([generate_sample(benchmark_config(1), "val", i) for i in range(4)])
    assert 20 < new["ridge_excess_db"]["median"] < 35 and old["ridge_excess_db"]["median"] < 10
    assert 0.2 < new["strong_ridge_rows"]["median"] / new["rows"] < 0.6
    assert -3 < new["near_minus_far_db"]["median"] < -0.8 and abs(old["near_minus_far_db"]["median"]) < 0.5
    assert -11 < new["edge_minus_far_db"]["median"] < -6 and abs(old["edge_minus_far_db"]["median"]) < 0.5
    assert 52 < new["max_minus_median_db"]["median"] < 60
    assert dataset_stats(val_samples[:12])["boxes_under_ridge"] > 0.3  # objects now meet the static ridge
    with pytest.raises(ValueError, match="version"):
        benchmark_config(3)


def test_benchmark_v1_regenerates_the_samples_it_made_before_issue_54():
    """The shipped RD weights and their records were made on v1: its maps must not move (the sums
    and boxes were read from the code before v2 existed)."""
    for split, index, total, boxes in (("val", 0, 97312.96399307251, 4), ("test", 3, 96885.63277673721, 2)):
        sample = generate_sample(benchmark_config(1), split, index)
        assert float(sample.power.astype(np.float64).sum()) == pytest.approx(total, rel=1e-12)
        assert len(sample.boxes) == boxes
    assert generate_sample(CFG, "val", 0).power.sum() != pytest.approx(97312.96399307251, rel=1e-3)


def test_statistics_of_synthetic_samples(val_samples):
    stats = dataset_stats(val_samples)
    assert stats["frames"] == 24 and stats["boxes"] == sum(len(s.boxes) for s in val_samples)
    assert 0 < stats["empty_frame_share"] < 1
    assert stats["box_range_bins"]["p10"] <= stats["box_range_bins"]["median"] <= stats["box_range_bins"]["p90"]
    floor = stats["noise_floor"]
    expected = 10 * np.log10(mean_floor_power(CFG))  # median of a noise-only cell, ~ its mean in dB
    assert abs(floor["db"]["median"] - expected) < 1.5 and 0 < floor["robust_sd"] < 0.5
    assert stats["peak_above_floor_db"]["median"] > CFG.box_threshold_db
    assert 0 < stats["zero_doppler_share"]["median"] <= 1
    first = val_samples[0]
    empty = dataclasses.replace(first, boxes=first.boxes.select(np.zeros(len(first.boxes), bool)), meta={})
    assert dataset_stats([empty])["box_doppler_bins"] is None and zero_doppler_share(empty) is not None
    assert dataset_stats([empty])["boxes_under_ridge"] is None
    power = np.zeros((256, 64), np.float32)
    power[10:20, 32] = 5.0  # a ridge in rows 10-19 only
    power[12:15, 40:44] = power[40:45, 40:44] = 3.0
    two = dataclasses.replace(first, power=power, meta={},
                              boxes=Boxes2D(np.array([[40, 12, 44, 15], [40, 40, 44, 45]], np.float32),
                                            np.array(["car", "car"])))
    np.testing.assert_array_equal(boxes_under_ridge(two), [True, False])
    assert dataset_stats([two])["boxes_under_ridge"] == 0.5
    assert "box Doppler bins" in format_stats_table({"synthetic": stats, "empty": dataset_stats([empty])})
    assert generation_rate(lambda i: generate_sample(CFG, "val", i), count=2) > 0


# ----------------------------------------------------------------- cache fuzzing (as tests/data/test_fuzz_tables.py)


@pytest.fixture(scope="module")
def fuzz_cache(tmp_path_factory):
    small = dataclasses.replace(CFG, sensor=dataclasses.replace(CFG.sensor, num_samples=32, num_chirps=16))
    return write_cache(RDSyntheticDataset(small, "val", seed=1, num_samples=2), tmp_path_factory.mktemp("rd") / "c")


@FUZZ
@given(key=st.sampled_from(["format", "format_version", "config", "split", "seed", "count", "files", "sensor",
                            "profiles", "class_mix", "clutter"]), value=JSON, how=st.sampled_from(["set", "delete"]))
def test_fuzzed_manifest_reads_or_names_the_manifest(fuzz_cache, key, value, how):
    manifest = json.loads((fuzz_cache / "manifest.json").read_text())
    config_keys = ("sensor", "profiles", "class_mix", "clutter")
    manifest_reads_or_names(RDCachedDataset, fuzz_cache, mutated(manifest, key, value, how, config_keys))


@FUZZ
@given(**corruptions(1 << 20))
def test_fuzzed_sample_file_reads_or_names_the_file(fuzz_cache, cut, pos, byte, truncate):
    bad = bitflip((fuzz_cache / "rd_000001.npz").read_bytes(), cut, pos, byte, truncate)
    cache_reads_or_names(RDCachedDataset, fuzz_cache, "rd_000001.npz", bad)
