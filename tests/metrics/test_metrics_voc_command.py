"""`python -m dsfec_jax.metrics.voc` on the 100 real VOC images and their detection files, and on
bad input (a message naming the file, not a traceback)."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest
from conftest import shared_data_dir

from dsfec_jax.metrics import voc as command


@pytest.fixture(scope="module")
def args():
    root = shared_data_dir() / "voc_review_od_metrics" / "data" / "database"
    if not (root / "voc.names").is_file():
        pytest.fail(f"VOC sample data not found under {root}; set DSFEC_DATA")
    return ["--gt-xml", str(root / "gts" / "pascalvoc_format"), "--dets", str(root / "dets" / "abs_xyx2y2"),
            "--names", str(root / "voc.names")]


@pytest.mark.parametrize("metric", ["voc07", "all"])
def test_the_command_prints_a_finite_map_per_metric(args, metric, capsys):
    assert command.main([*args, "--metric", metric, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["metric"] == metric and out["iou_threshold"] == 0.5 and len(out["classes"]) == 20
    assert math.isfinite(out["mAP"]) and 0.0 <= out["mAP"] <= 1.0
    aps = [c["ap"] for c in out["classes"].values()]
    assert out["mAP"] == pytest.approx(sum(aps) / 20) and sum(c["npos"] for c in out["classes"].values()) == 235


def test_the_table_and_the_module_entry_point(args):
    run = subprocess.run([sys.executable, "-m", "dsfec_jax.metrics.voc", *args, "--iou", "0.7"],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    assert lines[0].split() == ["class", "npos", "dets", "AP"] and len(lines) == 22
    assert lines[1].split()[:3] == ["aeroplane", "14", "17"]
    assert lines[-1].startswith("mAP 0.") and "voc07, IoU > 0.7" in lines[-1]


def test_bad_files_end_the_command_with_their_message(args, tmp_path):
    (tmp_path / "2007_000027.txt").write_text("14 0.9 1 2 3\n")
    bad = [*args[:2], "--dets", str(tmp_path), *args[4:]]
    with pytest.raises(SystemExit, match=r"2007_000027.txt:1: expected 6 columns"):
        command.main(bad)
    (tmp_path / "2007_000027.txt").write_text("20 0.9 1 2 3 4\n")
    with pytest.raises(SystemExit, match=r"2007_000027.txt:1: class_id: expected an integer in 0..19"):
        command.main(bad)
    (tmp_path / "2007_000027.txt").write_text("")
    (tmp_path / "not_an_image.txt").write_text("")
    with pytest.raises(SystemExit, match=r"without an XML .*not_an_image"):
        command.main(bad)
