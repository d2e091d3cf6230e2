"""`python -m dsfec_jax.data inspect` on RD sources: statistics, the TI target and PNG previews."""

import json

import numpy as np

import pytest

from dsfec_jax.core.png import PNG_SIGNATURE
from dsfec_jax.data.__main__ import main
from dsfec_jax.data.rd.sources import load_rd_samples
from dsfec_jax.data.rd.synthetic import generate_sample
from dsfec_jax.data.rd.synthetic.config import benchmark_config


def test_inspect_rd_synthetic_prints_statistics_and_writes_previews(tmp_path, capsys):
    assert main(["inspect", "--source", "rd-synthetic", "--frames", "4", "--png", str(tmp_path), "--previews", "2",
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    stats = summary["stats"]
    assert stats["frames"] == 4 and summary["info"]["maps_per_s"] > 0
    assert stats["noise_floor"]["db"]["median"] > 0 and 0 <= stats["zero_doppler_share"]["median"] <= 1
    assert len(summary["previews"]) == 2
    for path in summary["previews"]:
        assert open(path, "rb").read(8) == PNG_SIGNATURE


def test_inspect_ti_capture_finds_the_approaching_target(shared_data, capsys):
    capture = shared_data / "openradar_ti_adc"
    assert main(["inspect", "--source", "ti-adc", str(capture), "--json"]) == 0
    target = json.loads(capsys.readouterr().out)["info"]["targets"]["ti-adc/simple_frame_1"]
    assert target["range_bin"] == 41 and target["approaching"] and target["range_m"] == pytest.approx(2.0, abs=0.05)


def test_inspect_sets_the_map_structure_beside_the_capture_per_channel_count(shared_data, capsys):
    capture = shared_data / "openradar_ti_adc"
    assert main(["inspect", "--source", "rd-synthetic", "--frames", "2", "--benchmark", "1",
                 "--versus", f"ti-adc:{capture}"]) == 0
    out = capsys.readouterr().out
    header = next(line for line in out.splitlines() if "ti-adc 1ch" in line)
    assert header.split() == ["rd-synthetic", "8ch", "ti-adc", "1ch", "ti-adc", "8ch"]  # never pooled
    ridge = next(line for line in out.splitlines() if line.startswith("rows with ridge"))
    assert ridge.endswith("49 of 127   45 of 127") and "benchmark: 1" in out
    floor = next(line for line in out.splitlines() if line.startswith("noise floor (dB)"))
    assert floor.endswith("48.2 (robust sd 5.68)    59.2 (robust sd 2.23)")  # one channel, eight
    with pytest.raises(SystemExit, match="SOURCE:PATH"):
        main(["inspect", "--source", "rd-synthetic", "--frames", "1", "--versus", "ti-adc"])
    with pytest.raises(ValueError, match="versions"):
        load_rd_samples("synthetic:v9", "val", 1)
    old = load_rd_samples("synthetic:v1", "val", 1)[0].power
    np.testing.assert_array_equal(old, generate_sample(benchmark_config(1), "val", 0).power)


def test_inspect_rd_needs_a_path_for_real_sources():
    with pytest.raises(SystemExit, match="needs a PATH"):
        main(["inspect", "--source", "raddet"])
    with pytest.raises(SystemExit, match="no such file"):
        main(["inspect", "--source", "carrada", "/nonexistent/carrada"])


def test_previews_record_the_command_that_made_them(tmp_path, capsys):
    main(["inspect", "--source", "rd-synthetic", "--frames", "1", "--seed", "3", "--png", str(tmp_path)])
    record = json.loads((tmp_path / "previews.json").read_text())
    assert record["command"].endswith("--seed 3 --png " + str(tmp_path)) and record["seed"] == 3
    assert record["files"] == ["rd-synthetic-val-s3-000000.png"] and record["versions"]["numpy"]


def test_synthetic_command_writes_a_cache_that_reads_back(tmp_path, capsys):
    from dsfec_jax.data.rd.synthetic import RDCachedDataset, generate_sample, RDSyntheticConfig
    from dsfec_jax.data.rd.synthetic.__main__ import main as synthetic_main

    synthetic_main(["--split", "val", "--samples", "2", "--bench", "0", "--benchmark", "2", "--cache", str(tmp_path / "c")])
    assert "rd-synthetic val" in capsys.readouterr().out
    cached = RDCachedDataset(tmp_path / "c", RDSyntheticConfig(), "val", 0)
    assert len(cached) == 2
    np.testing.assert_array_equal(cached[1].power, generate_sample(RDSyntheticConfig(), "val", 1).power)
    synthetic_main(["--split", "val", "--samples", "1", "--bench", "0", "--benchmark", "1", "--cache", str(tmp_path / "v1")])
    assert RDCachedDataset(tmp_path / "v1", benchmark_config(1), "val", 0)[0].meta["index"] == 0
    synthetic_main(["--split", "val", "--samples", "1", "--bench", "0", "--cache", str(tmp_path / "plain")])  # plain: v2
    assert RDCachedDataset(tmp_path / "plain", RDSyntheticConfig(), "val", 0)[0].meta["index"] == 0
