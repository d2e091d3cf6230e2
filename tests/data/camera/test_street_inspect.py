"""`python -m dsfec_jax.data inspect --source street` and `python -m dsfec_jax.data.camera.street`:
statistics, the generation rate, previews with their provenance, a cache."""

import json

import numpy as np

from dsfec_jax.core.png import PNG_SIGNATURE
from dsfec_jax.data.__main__ import main


def test_inspect_street_prints_statistics_and_writes_previews(tmp_path, capsys):
    assert main(["inspect", "--source", "street", "--frames", "2", "--split", "test", "--png", str(tmp_path),
                 "--previews", "1", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    stats, info = summary["stats"], summary["info"]
    assert stats["frames"] == 2 and stats["resolution"] == [[416, 234]] and info["frames_per_s"] > 0
    assert set(stats["objects_per_frame"]) == {"all", "car", "truck", "bus", "pedestrian", "cyclist"}
    assert stats["objects_per_frame"]["all"] > 0 and 0 <= stats["difficult_share"] <= 1
    assert 0 < stats["depth_m"]["nearest"]["median"] < stats["depth_m"]["p99"]["median"]
    assert info["split"] == "test" and info["intrinsics"]["hfov_deg"] == 120.0
    (path,) = summary["previews"]
    assert open(path, "rb").read(8) == PNG_SIGNATURE
    record = json.loads((tmp_path / "previews.json").read_text())
    assert record["command"].endswith("--previews 1 --json") and record["files"] == ["street-test-s0-000000.png"]
    assert record["config"]["camera"] == "paper" and record["versions"]["pymap3d"]


def test_inspect_street_text_table(capsys):
    assert main(["inspect", "--source", "street", "--frames", "1"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("street val") and "pedestrian / frame" in out and "frames_per_s" in out


def test_street_command_writes_a_cache_that_reads_back(tmp_path, capsys):
    from dsfec_jax.data.camera.street import StreetConfig, generate_frame
    from dsfec_jax.data.camera.street.__main__ import main as street_main
    from dsfec_jax.data.camera.street.cache import StreetCachedDataset

    street_main(["--split", "val", "--frames", "2", "--width", "64", "--bench", "1", "--cache", str(tmp_path / "c")])
    out = capsys.readouterr().out
    assert "street val" in out and "frames/s at 64x36" in out
    cached = StreetCachedDataset(tmp_path / "c", split="val", seed=0)
    assert len(cached) == 2 and cached.cfg == StreetConfig(width=64)
    np.testing.assert_array_equal(cached[1].image, generate_frame(StreetConfig(width=64), "val", 1).image)
