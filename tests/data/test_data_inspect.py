import json

import pytest

from dsfec_jax.data.__main__ import main


def run(capsys, *argv):
    assert main(list(argv) + ["--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_inspect_vod_reproduces_the_real_counts(shared_data, capsys):
    out = run(capsys, "inspect", "--source", "vod", str(shared_data / "vod" / "example_set"))
    assert [(r["num_boxes_with_points"], r["num_boxes"]) for r in out["frames"]] == [(15, 15), (17, 24), (18, 23)]
    assert out["info"]["pillarize_points_per_s"] > 0


def test_inspect_tj4d_total(shared_data, capsys):
    out = run(capsys, "inspect", "--source", "tj4d", str(shared_data / "tj4dradset" / "Sample"))
    assert out["total"]["frames"] == 41
    assert (out["total"]["num_boxes_with_points"], out["total"]["num_boxes"]) == (123, 152)


def test_inspect_nuscenes_pcd(shared_data, capsys):
    out = run(capsys, "inspect", "--source", "nuscenes-pcd", str(shared_data / "nuscenes_radar"))
    assert [r["points"] for r in out["frames"]] == [125, 125]


def test_inspect_synthetic_split_and_rate(capsys):
    out = run(capsys, "inspect", "--source", "synthetic", "--split", "test", "--frames", "5", "--seed", "3")
    assert out["total"]["frames"] == 5 and out["info"]["split"] == "test" and out["info"]["frames_per_s"] > 0
    assert set(out["total"]["boxes"]) <= {"car", "truck", "pedestrian", "bicycle"}


def test_inspect_missing_path_is_a_clear_error(tmp_path):
    with pytest.raises(SystemExit, match="no such file"):
        main(["inspect", "--source", "vod", str(tmp_path / "nope")])
