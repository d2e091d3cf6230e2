import json
import re

import numpy as np
import pytest

from dsfec_jax import api, cli, zoo
from dsfec_jax.core import checkpoint
from dsfec_jax.metrics import nuscenes, submission
from builders import tensorboard_events
from conftest import tiny


@pytest.fixture
def tiny_model(monkeypatch):
    monkeypatch.setitem(zoo.REGISTRY, "tiny_s", tiny("dsfec_s", name="tiny_s").config)
    return "tiny_s"


def test_train_eval_predict_round_trip(tiny_model, tmp_path, capsys, uncompiled_init):
    run = tmp_path / "run"
    assert cli.main(["train", "--model", tiny_model, "--steps", "3", "--batch-size", "2", "--frames", "4",
                     "--val-frames", "2", "--eval-every", "3", "--run-dir", str(run), "--max-pillars", "96",
                     "--window", "16"]) == 0
    captured = capsys.readouterr()
    final = json.loads(captured.out.strip().splitlines()[-1])
    # the waits say what they are on stderr (the bar, each window's compile, the first validation's compile)
    assert re.search(r"compiling tiny_s's training step \(training window [1-4] of 4\)\.\.\. \(usually", captured.err)
    assert "validating tiny_s at step 3 (the first validation compiles the predictor): done in" in captured.err
    assert "tiny_s: 100%" in captured.err
    assert set(final["final"]) == {"car_mAP", "car_AP4", "mAP", "class_mAP", "AP@4"}
    info = json.loads((run / "run.json").read_text())
    # DSFEC trains without the weight EMA unless asked; TensorBoard holds the BEV predict picture
    assert info["schedule"]["ema"] is False and [e.step for e in tensorboard_events(run).Images("val/predictions")] == [3]
    assert info["seed"] == 0 and info["config"]["name"] == "tiny_s" and info["versions"]["jax"]
    assert len(info["windows"]) == 4  # 16x16-cell windows of the 32x32 grid
    with pytest.raises(SystemExit, match=r"run.json: this run was started with seed=0, steps=3; the command asks "
                                         r"seed=1, steps=4\. Use a new run directory \(--run-dir\)"):
        cli.main(["train", "--model", tiny_model, "--steps", "4", "--batch-size", "2", "--frames", "4", "--seed", "1",
                  "--val-frames", "2", "--eval-every", "3", "--run-dir", str(run), "--max-pillars", "96", "--window", "16"])
    assert json.loads((run / "run.json").read_text()) == info
    ckpt = run / "checkpoints" / "last" / "step_0000003"  # a training checkpoint is weights too

    assert cli.main(["eval", "--model", tiny_model, "--weights", str(ckpt), "--frames", "3", "--json",
                     "--max-pillars", "96"]) == 0
    captured = capsys.readouterr()
    result = json.loads(captured.out)
    assert "running the first batch (a JAX predictor compiles its network on it)..." in captured.err
    assert "detecting in 3 frames: 100%" in captured.err
    assert result["frames"] == 3 and 0 <= result["car_AP4"] <= 100 and "AP" in result["metrics"]

    pred, gt, png = tmp_path / "pred.json", tmp_path / "gt.json", tmp_path / "png"
    assert cli.main(["predict", "--model", tiny_model, "--weights", str(ckpt), "--frames", "2", "--out", str(pred),
                     "--gt-out", str(gt), "--png-dir", str(png), "--max-pillars", "96", "--json"]) == 0
    in_process = json.loads(capsys.readouterr().out)["metrics"]
    results, meta = submission.read_submission(pred)
    assert len(results) == 2 and meta["use_radar"]
    assert len(list(png.glob("*.png"))) == 2
    assert nuscenes.main(["--gt", str(gt), "--pred", str(pred)]) in (0, None)
    offline = json.loads(capsys.readouterr().out)
    for name in in_process["AP"]:  # the files carry everything the metric needs
        assert offline["AP"][name] == pytest.approx(in_process["AP"][name])
    assert offline["num_gt"] == in_process["num_gt"] and offline["num_pred"] == in_process["num_pred"]
    assert sum(in_process["num_gt"].values()) > 0

    shipped = tmp_path / "weights"
    assert cli.main(["ship", "--model", tiny_model, "--run-dir", str(run), "--checkpoint", "last", "--frames", "2",
                     "--out-dir", str(shipped)]) == 0
    err = capsys.readouterr().err  # ship says while it generates and measures the benchmark's splits
    assert "on 2 val frames of synthetic for the manifest: done in" in err and "2 test frames" in err
    manifest = json.loads((shipped / "tiny_s.msgpack.json").read_text())
    assert manifest["step"] == 3 and manifest["training"]["seed"] == 0 and "car_mAP" in manifest["measured"]["test"]
    detections = api.load(tiny_model, weights=shipped / "tiny_s.msgpack", max_pillars=96)(
        np.zeros((5, 7), np.float32))
    assert len(detections.boxes) == len(detections.scores)


def test_ship_measures_a_radarnext_run_with_the_vod_protocol(monkeypatch, tmp_path, capsys):
    """A RadarNeXt run ships with the VoD 3D AP on the synthetic 4D benchmark (not the nuScenes
    metric) and with the pillar slots the run trained with."""
    from conftest import random_variables
    from dsfec_jax.core.grid import Grid
    from dsfec_jax.core.run_checkpoints import RunCheckpoints

    grid = Grid((0.0, 10.24), (-5.12, 5.12), (-3.0, 2.0), 0.16)
    det = zoo.create("radarnext_fpn", grid=grid, layer_nums=(1, 1, 1), max_points=4, max_pillars=96)
    monkeypatch.setitem(zoo.REGISTRY, "tiny_radarnext", det.config)
    run = tmp_path / "run"
    with RunCheckpoints(run) as checkpoints:
        checkpoints.save(1, random_variables(det, 0), {})
    (run / "run.json").write_text(json.dumps({"seed": 0, "overrides": {"max_pillars": 96}}))
    assert cli.main(["ship", "--model", "tiny_radarnext", "--run-dir", str(run), "--checkpoint", "last",
                     "--frames", "2", "--out-dir", str(tmp_path / "weights")]) == 0
    said = capsys.readouterr().err
    for split in ("val", "test"):  # never silent while it measures (issue 51)
        assert f"measuring vod on 2 {split} frames of synthetic4d for the manifest: done in" in said, said
    measured = json.loads((tmp_path / "weights" / "tiny_radarnext.msgpack.json").read_text())["measured"]
    for split in ("val", "test"):
        assert measured[split]["protocol"] == "vod" and measured[split]["data"] == "synthetic4d"
        assert set(measured[split]["AP"]) == {"car", "pedestrian", "bicycle"} and "car_mAP" not in measured[split]


def test_load_without_shipped_weights_says_how_to_get_them(tiny_model):
    with pytest.raises(FileNotFoundError, match="dsfec train --model tiny_s"):
        api.load(tiny_model)


def test_overrides_parse_literals():
    assert cli.parse_overrides(["stage_blocks=(1,3,3,2)", "act_stem=mish", "stem_filters=16"]) == {
        "stage_blocks": (1, 3, 3, 2), "act_stem": "mish", "stem_filters": 16}
    with pytest.raises(SystemExit, match="FIELD=VALUE"):
        cli.parse_overrides(["oops"])


@pytest.mark.parametrize("argv, flag", [
    (["train", "--model", "dsfec_s", "--run-dir", "r", "--frames", "0"], "--frames"),
    (["train", "--model", "dsfec_s", "--run-dir", "r", "--val-frames", "0"], "--val-frames"),
    (["train", "--model", "dsfec_s", "--run-dir", "r", "--steps", "0"], "--steps"),
    (["train", "--model", "dsfec_s", "--run-dir", "r", "--batch-size", "-2"], "--batch-size"),
    (["train", "--model", "dsfec_s", "--run-dir", "r", "--window", "-1"], "--window"),
    (["eval", "--model", "dsfec_s", "--frames", "0"], "--frames"),
    (["predict", "--model", "dsfec_s", "--out", "p.json", "--max-pillars", "0"], "--max-pillars"),
    (["ship", "--model", "dsfec_s", "--run-dir", "r", "--frames", "0"], "--frames"),
    (["quantize", "--onnx", "x", "--out", "y", "--calib-frames", "0"], "--calib-frames"),
    (["bench", "--repeats", "0"], "--repeats"),
])
def test_non_positive_counts_are_refused_naming_the_flag(argv, flag, capsys):
    """`--frames 0` used to mean 200 frames (train: 100 batches; --steps 0: the whole schedule)."""
    with pytest.raises(SystemExit):
        cli.parse(argv)
    assert f"argument {flag}: expected " in capsys.readouterr().err


def test_the_data_commands_refuse_zero_frames(capsys):
    from dsfec_jax.data import __main__ as data_main
    from dsfec_jax.data.points.synthetic import __main__ as synthetic_main

    with pytest.raises(SystemExit):
        data_main.parse(["inspect", "--source", "synthetic", "--frames", "0"])
    assert "argument --frames: expected a positive integer, got 0" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        synthetic_main.parse(["--frames", "0"])
    assert "argument --frames: expected a positive integer, got 0" in capsys.readouterr().err


def test_bench_refuses_zero_threads(monkeypatch):
    from dsfec_jax.deploy import bench

    monkeypatch.setattr(bench, "run", lambda *a: pytest.fail("benchmarked with 0 threads"))
    with pytest.raises(SystemExit, match="--threads '1,0': thread counts must be positive"):
        cli.main(["bench", "--models", "dsfec_s", "--runtimes", "jax", "--threads", "1,0"])


def test_empty_inputs_get_an_error_not_a_number(shared_data, tiny_model, tmp_path):
    """The VoD example set has 3 frames: its 'test' split (85-100 %) holds none. Scoring it, or
    asking for 0 frames, must say so instead of returning a score of nothing."""
    from dsfec_jax.data.points.sources import NoFrames, load_frames
    from dsfec_jax.modalities.points.fit import fit
    from dsfec_jax.train.schedules import get_schedule

    vod = f"vod:{shared_data / 'vod' / 'example_set'}"
    with pytest.raises(NoFrames, match=r"split 'test' is empty: the source has 3 frames and the split takes 85% to 100%"):
        load_frames(vod, "test")
    assert len(load_frames(vod, "val")) == 1
    for data in ("synthetic", vod):
        with pytest.raises(NoFrames, match="frames=0: expected a positive number of frames"):
            load_frames(data, "all" if data == vod else "train", 0)
    with pytest.raises(SystemExit, match="dsfec eval: --data vod:.*split 'test' is empty"):
        cli.main(["eval", "--model", "dsfec_s", "--data", vod, "--split", "test"])
    frames = load_frames("synthetic", "train", 2)
    with pytest.raises(ValueError, match="fit: 0 validation frames; expected at least 1"):
        fit(zoo.config(tiny_model), frames, [], get_schedule("quick"), tmp_path / "run")
    with pytest.raises(ValueError, match="fit: 0 steps; expected at least 1"):
        fit(zoo.config(tiny_model), frames, frames, get_schedule("quick"), tmp_path / "run", steps=0)


def test_ship_without_a_checkpoint_says_what_is_missing(tiny_model, tmp_path):
    run = tmp_path / "run"
    with pytest.raises(SystemExit, match="run.json missing"):
        cli.main(["ship", "--model", tiny_model, "--run-dir", str(run)])
    run.mkdir()
    (run / "run.json").write_text("{}")
    with pytest.raises(SystemExit, match="checkpoints/last holds no complete checkpoint"):
        cli.main(["ship", "--model", tiny_model, "--run-dir", str(run), "--checkpoint", "last"])
    with pytest.raises(SystemExit, match=r"checkpoints/best holds no checkpoint \(no validation has run yet\)"):
        cli.main(["ship", "--model", tiny_model, "--run-dir", str(run)])
    checkpoint.save(run / "checkpoints" / "step_0000001.msgpack", {"params": {}}, {"step": 1})  # a run from before Orbax
    with pytest.raises(SystemExit, match=r"run/checkpoints holds msgpack checkpoints written before Orbax .*resume the run once"):
        cli.main(["ship", "--model", tiny_model, "--run-dir", str(run)])
