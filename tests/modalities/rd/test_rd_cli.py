"""`dsfec train | eval | predict | ship` for the range-Doppler family: one round trip on two synthetic
samples (the YOLOv8n compiles dominate: the train step, then one inference program that the
validation, eval, predict and ship runs share through the tests' compilation cache), the files
predict writes score offline exactly as in process, and the flag errors name their flag."""

import json

import numpy as np
import pytest
from PIL import Image

from dsfec_jax import api, cli, zoo
from dsfec_jax.core.run_checkpoints import best_step, read_state
from dsfec_jax.modalities.rd import cli as cli_rd
from dsfec_jax.boxes.boxes2d import Boxes2D
from dsfec_jax.data.rd.sources import load_rd_samples
from dsfec_jax.modalities.rd.evaluate import score_rd
from dsfec_jax.metrics.boxes2d.coco_json import load_coco_dets, load_coco_gt
from builders import tensorboard_events

RD_KEYS = {"mAP50", "mAP50_95", "mAP30", "darod_mAP50"}


def last_json(capsys):
    return json.loads(capsys.readouterr().out)


def test_train_eval_predict_ship_round_trip(tmp_path, capsys, uncompiled_init):
    run = tmp_path / "run"
    assert cli.main(["train", "--model", "yolov8n", "--steps", "1", "--batch-size", "2", "--frames", "2",
                     "--val-frames", "2", "--eval-every", "0", "--run-dir", str(run)]) == 0
    final = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["final"]
    assert RD_KEYS <= set(final) and final["samples"] == 2
    info = json.loads((run / "run.json").read_text())
    assert info["model"] == "yolov8n" and info["schedule"]["name"] == "yolo_quick"  # --schedule quick, mapped
    assert info["train_samples"] == 2 and info["val_samples"] == 2 and info["steps"] == 1
    assert info["data"] == {"source": "synthetic", "split": "train"} and info["command"].startswith("dsfec train")
    best = run / "checkpoints" / "best"  # its one step directory: what --weights reads
    assert best_step(run) is not None
    # the family's weight EMA is on, and TensorBoard holds the picture predict draws and the recipe's rates
    assert info["schedule"]["ema"] is True and "ema" in read_state(best)
    board = tensorboard_events(run)
    assert [e.step for e in board.Images("val/predictions")] == [1] and "train/lr/weight" in board.Tags()["scalars"]

    assert cli.main(["eval", "--model", "yolov8n", "--weights", str(best), "--frames", "2", "--json"]) == 0
    captured = capsys.readouterr()
    result = json.loads(captured.out)
    assert "detecting in 2 maps: 100%" in captured.err  # the bar is on stderr, the JSON alone on stdout
    assert RD_KEYS <= set(result) and result["protocol"] == "rd_coco" and result["frames"] == result["samples"] == 2
    assert result["score_threshold"] == 0.001 and result["split"] == "test"  # the paper's evaluation conf

    pred, gt, png = tmp_path / "dets.json", tmp_path / "gt.json", tmp_path / "png"
    assert cli.main(["predict", "--model", "yolov8n", "--weights", str(best), "--frames", "2", "--out", str(pred),
                     "--gt-out", str(gt), "--png-dir", str(png), "--json"]) == 0
    in_process = last_json(capsys)
    assert in_process["mAP50"] == result["mAP50"]  # the same samples and weights as eval
    truth = load_coco_gt(gt)
    samples = load_rd_samples("synthetic", "test", 2)
    assert [i["file_name"] for i in json.loads(gt.read_text())["images"]] == [s.sample_id for s in samples]
    assert truth.classes == zoo.config("yolov8n").classes
    assert sum(len(b) for b in truth.boxes.values()) == sum(len(s.boxes) for s in samples) > 0
    rows = json.loads(pred.read_text())
    assert rows and set(rows[0]) == {"image_id", "category_id", "bbox", "score"}
    assert min(r["score"] for r in rows) >= 0.001
    offline = score_rd(truth.boxes, load_coco_dets(pred, truth), truth.classes)
    for key in RD_KEYS | {"AP50", "num_gt"}:  # the files carry everything the metric needs
        assert offline[key] == in_process[key], key
    for s in samples:  # one figure per sample (what it draws: test_pngs_draw_only_predictions_above_the_min_score)
        assert Image.open(png / f"{s.sample_id}.png").size == (700, 750)

    shipped = tmp_path / "weights"
    assert cli.main(["ship", "--model", "yolov8n", "--run-dir", str(run), "--frames", "2",
                     "--out-dir", str(shipped)]) == 0
    capsys.readouterr()
    manifest = json.loads((shipped / "yolov8n.msgpack.json").read_text())
    assert manifest["step"] == 1 and manifest["training"]["model"] == "yolov8n" and manifest["versions"]["jax"]
    assert manifest["ship_command"].startswith("dsfec ship --model yolov8n")
    for split in ("val", "test"):
        measured = manifest["measured"][split]
        assert measured["protocol"] == "rd_coco" and measured["data"] == "rd-synthetic:v2" and measured["frames"] == 2
        assert {"mAP50", "mAP50_95", "darod_mAP50"} <= set(measured)
    assert manifest["measured"]["test"]["mAP50"] == result["mAP50"]  # test split, data seed 0: what eval scored
    assert type(api.load("yolov8n", weights=shipped / "yolov8n.msgpack")).__name__ == "RDPredictor"

    # the average's gain: raw and averaged weights of the last checkpoint, the average's scores the shipped ones
    from experiments import ema_gain

    assert ema_gain.main(["--run-dir", str(run), "--frames", "2", "--record", str(tmp_path / "ema.json")]) == 0
    gain = json.loads((tmp_path / "ema.json").read_text())
    assert gain["checkpoint"]["ema_updates"] == 1 and gain["training"]["model"] == "yolov8n"
    shipped_test = {k: v for k, v in manifest["measured"]["test"].items() if k != "data"}  # synthetic = rd-synthetic:v2
    assert {k: gain["measured"]["ema"]["test"][k] for k in shipped_test} == shipped_test
    assert gain["ema_minus_raw"]["test"]["mAP50"] == round(manifest["measured"]["test"]["mAP50"]
                                                           - gain["measured"]["raw"]["test"]["mAP50"], 4)
    one = {"mAP50": 20.0, "frames": 2, "data": "x"}  # after one update the two score alike: the sign on made-up figures
    made_up = {"raw": {"val": one, "test": one}, "ema": {"val": {**one, "mAP50": 21.5}, "test": one}}
    assert ema_gain.gains(made_up) == {"val": {"mAP50": 1.5}, "test": {"mAP50": 0.0}}


def test_the_ema_gain_re_estimates_both_weight_sets_where_the_run_did():
    """A camera run's precise BN re-estimated the average's statistics only: the gain re-estimates
    the raw weights' too (a stand-in re-estimation: statistic = 10 x the weight it sees)."""
    from experiments import ema_gain
    from dsfec_jax.train.ema import evaluated, with_evaluated_batch_stats

    state = {"params": {"w": 1.0}, "batch_stats": {"m": 0.0}, "step": 3,
             "ema": {"params": {"w": 2.0}, "batch_stats": {"m": 0.0}, "updates": 1}}
    recalibrate = lambda s: with_evaluated_batch_stats(s, {"m": 10 * evaluated(s)["params"]["w"]})
    assert ema_gain.weights(state, ("params", "batch_stats"), recalibrate) == {
        "raw": {"params": {"w": 1.0}, "batch_stats": {"m": 10.0}}, "ema": {"params": {"w": 2.0}, "batch_stats": {"m": 20.0}}}
    assert ema_gain.weights(state, ("params", "batch_stats"))["raw"]["batch_stats"] == {"m": 0.0}  # none: as trained


def test_pngs_draw_only_predictions_above_the_min_score(tmp_path, monkeypatch):
    from argparse import Namespace

    from dsfec_jax.data.rd import figure

    sample = load_rd_samples("synthetic", "val", 1)[0]
    found = Boxes2D(np.array([[2, 10, 12, 40], [30, 100, 50, 140]], np.float32), np.array(["car", "person"]),
                    np.array([0.6, 0.1], np.float32))
    drawn = []
    monkeypatch.setattr(figure, "save_rd_figure", lambda s, path, predicted, *rest: drawn.append(predicted))

    class Fake:
        representation, classes = None, ("person", "car")

    for given, scores in ((None, [0.6]), (0.05, [0.6, 0.1])):  # default 0.25; --png-min-score 0.05
        cli_rd.write_pngs(Namespace(png_dir=str(tmp_path), png_min_score=given, model="yolov8n"), [sample],
                          {sample.sample_id: found}, Fake())
        assert drawn.pop().scores.tolist() == pytest.approx(scores)


class Recorder:
    """Stands in for the data loader and fit: records what `dsfec train` asked for."""

    def __init__(self):
        self.loads, self.fit = [], None

    def load(self, data, split, count=None, seed=0):
        self.loads.append((data, split, count))
        return load_rd_samples("synthetic", split, 1)

    def fake_fit(self, cfg, samples, val, schedule, run_dir, seed, steps, augment, eval_every, info, **kw):
        self.fit = {"model": cfg.name, "schedule": schedule.name, **kw}
        return None, None, {"mAP50": 0.0}


@pytest.fixture
def recorder(monkeypatch, tmp_path):
    from dsfec_jax.data.rd import sources
    from dsfec_jax.modalities.rd import fit

    rec = Recorder()
    monkeypatch.setattr(sources, "load_rd_samples", rec.load)
    monkeypatch.setattr(fit, "fit_rd", rec.fake_fit)
    return rec


@pytest.mark.parametrize("extra, data, schedule, train_count", [
    ([], "synthetic", "yolo_quick", cli_rd.TRAIN_SAMPLES),
    (["--schedule", "paper", "--frames", "7"], "synthetic", "yolo_paper", 7),
    (["--schedule", "yolo_paper"], "synthetic", "yolo_paper", cli_rd.TRAIN_SAMPLES),
    (["--schedule", "radarnext", "--data", "raddet:/data/raddet"], "raddet:/data/raddet", "radarnext", None),
])
def test_train_defaults_for_rd_models(recorder, tmp_path, capsys, extra, data, schedule, train_count):
    """Without --frames: the ~1000 samples yolo_quick is sized for (a real source: its whole split);
    the profiles map through Family.schedules; no pillar slots or windows reach fit."""
    assert cli.main(["train", "--model", "yolov8n", "--run-dir", str(tmp_path / "r"), *extra]) == 0
    assert recorder.loads == [(data, "train", train_count), (data, "val", 100)]
    assert recorder.fit == {"model": "yolov8n", "overrides": {}, "schedule": schedule}
    assert json.loads(capsys.readouterr().out)["final"] == {"mAP50": 0.0}


def test_eval_keeps_the_papers_confidence_unless_told(monkeypatch, capsys):
    seen = []

    class Quiet:
        classes = zoo.config("yolov8n").classes

        def predict_samples(self, samples, progress=False):
            return {s.sample_id: Boxes2D.empty(with_scores=True) for s in samples}

    def fake_predictor(detector, variables, score_threshold, **options):
        seen.append(score_threshold)
        return Quiet()

    monkeypatch.setattr(cli_rd, "RDPredictor", fake_predictor)
    for extra in ([], ["--score-threshold", "0.3"]):
        assert cli.main(["eval", "--model", "yolov8n", "--frames", "1", "--json", *extra]) == 0
        assert last_json(capsys)["mAP50"] in (0.0, None)
    assert seen == [0.001, 0.3]


@pytest.mark.parametrize("argv, message", [
    (["train", "--model", "yolov8n", "--run-dir", "r", "--window-sampling", "objects"], "--window-sampling applies to point"),
    (["train", "--model", "yolov8n", "--run-dir", "r", "--window", "0", "--max-pillars", "64"],
     "--window, --max-pillars apply to point"),
    (["eval", "--model", "yolov8n", "--max-pillars", "64"], "--max-pillars applies to point"),
    (["export", "--model", "yolov8n", "--out", "x", "--top-k", "5"], "--top-k applies to point"),
    (["export", "--model", "yolov8n", "--out", "x", "--input-hw", "256"], "--input-hw '256': expected HEIGHT,WIDTH"),
    (["export", "--model", "dsfec_s", "--out", "x", "--input-hw", "256,64"], "--input-hw applies to range-Doppler"),
    (["train", "--model", "yolov8n", "--run-dir", "r", "--schedule", "fast"], "--schedule 'fast': expected a profile"),
    (["train", "--model", "yolov8n", "--run-dir", "r", "--decay-at", "0.5"], "--decay-at: schedule 'yolo_quick'"),
    (["train", "--model", "yolov8n", "--run-dir", "r", "--set", "reg_max_x=3"], "--set: unknown field"),
    (["eval", "--model", "yolov8x"], "--model 'yolov8x': not a zoo model"),
    (["eval", "--model", "yolov8n", "--data", "vod:/x"], "--data 'vod:/x': expected one of"),
    (["eval", "--model", "yolov8n", "--data", "synthetic", "--split", "all"], "--data synthetic: splits are"),
    (["eval", "--model", "yolov8n", "--frames", "1", "--weights", "/no/such.msgpack"], r"no weights at /no/such.msgpack.*\(--weights\)"),
    (["predict", "--model", "yolov8n", "--frames", "1", "--out", "p.json", "--runtime", "onnx"], "--runtime onnx needs --onnx DIR"),
])
def test_flag_errors_name_the_flag(argv, message):
    with pytest.raises(SystemExit, match=message):
        cli.main(argv)


def test_ship_refuses_a_run_of_another_model(tmp_path):
    (tmp_path / "run.json").write_text(json.dumps({"model": "yolov8s"}))
    with pytest.raises(SystemExit, match="trained 'yolov8s', not --model 'yolov8n'"):
        cli.main(["ship", "--model", "yolov8n", "--run-dir", str(tmp_path)])


def test_profiles_map_through_the_family():
    assert cli.schedule_preset("quick", zoo.family_of("yolov8n_adapter")) == "yolo_quick"
    assert cli.schedule_preset("paper", zoo.family_of("yolov10n")) == "yolo_paper"
    assert cli.schedule_preset("quick", zoo.family_of("dsfec_s")) == "quick"
    assert cli.schedule_preset("yolo_quick", zoo.family_of("dsfec_s")) == "yolo_quick"


def test_export_quantize_and_onnx_eval_reach_the_rd_deploy_functions(monkeypatch, tmp_path, capsys):
    """The wiring only (the deploy functions have their own parity tests): export_rd gets the
    checkpoint's variables, --input-hw and the command; quantize dispatches on deploy.json's
    modality and calibrates on synthetic RD train samples; eval --runtime onnx checks the export's model."""
    from conftest import random_variables
    from dsfec_jax.core import checkpoint
    import importlib

    # the modules (the record's wrappers import the functions from them when called)
    export_rd, ort_rd, quantize_rd = (importlib.import_module(f"dsfec_jax.modalities.rd.{m}")
                                      for m in ("export", "ort", "quantize"))

    det = zoo.create("yolov8n")
    weights = tmp_path / "w.msgpack"
    checkpoint.save(weights, random_variables(det, 0), {"step": 1})
    calls = {}

    def fake_export(detector, variables, out_dir, source=None, **kw):
        calls["export"] = (detector.name, set(variables), str(out_dir), source["command"], kw)
        return {"onnx": tmp_path / "x" / "model.onnx"}

    def fake_quantize(export_dir, out_dir, samples, calibration="minmax"):
        calls["quantize"] = (str(export_dir), [s.sample_id for s in samples], calibration)
        return {"onnx": tmp_path / "int8" / "model.onnx", "int8_bytes": 1}

    class FakeOrt:
        classes = det.config.classes
        representation = None

        def __init__(self, export_dir, score_threshold):
            self.manifest = {"model": "yolov8s" if "other" in str(export_dir) else "yolov8n"}
            calls["ort"] = score_threshold

        def predict_samples(self, samples, progress=False):
            return {s.sample_id: Boxes2D.empty(with_scores=True) for s in samples}

    monkeypatch.setattr(export_rd, "export_rd", fake_export)
    monkeypatch.setattr(quantize_rd, "quantize_rd", fake_quantize)
    monkeypatch.setattr(ort_rd, "OrtRDPredictor", FakeOrt)

    assert cli.main(["export", "--model", "yolov8n", "--weights", str(weights), "--out", str(tmp_path / "x"),
                     "--input-hw", "128,64"]) == 0
    assert calls["export"] == ("yolov8n", {"params", "batch_stats"}, str(tmp_path / "x"),
                               f"dsfec export --model yolov8n --weights {weights} --out {tmp_path / 'x'} "
                               f"--input-hw 128,64", {"input_hw": (128, 64)})
    assert json.loads(capsys.readouterr().out)["onnx"].endswith("model.onnx")

    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "deploy.json").write_text(json.dumps({"model": "yolov8n", "modality": "rd"}))
    assert cli.main(["quantize", "--onnx", str(tmp_path / "x"), "--out", str(tmp_path / "int8"),
                     "--calib-frames", "3", "--calibration", "entropy"]) == 0
    assert calls["quantize"] == (str(tmp_path / "x"), [s.sample_id for s in load_rd_samples("synthetic", "train", 3)],
                                 "entropy")
    assert last_json(capsys)["int8_bytes"] == 1

    assert cli.main(["eval", "--model", "yolov8n", "--runtime", "onnx", "--onnx", str(tmp_path / "x"),
                     "--frames", "1", "--json"]) == 0
    result = last_json(capsys)
    assert result["runtime"] == "onnx" and result["weights"] == str(tmp_path / "x") and calls["ort"] == 0.001
    with pytest.raises(SystemExit, match="holds 'yolov8s', not --model 'yolov8n'"):
        cli.main(["eval", "--model", "yolov8n", "--runtime", "onnx", "--onnx", str(tmp_path / "other"), "--frames", "1"])


def test_every_synthetic_benchmark_version_trains_on_the_generated_default():
    for data in ("synthetic", "rd-synthetic", "synthetic:v1", "synthetic:v2"):
        assert cli_rd.default_train_samples(data) == cli_rd.TRAIN_SAMPLES, data
    assert cli_rd.default_train_samples("raddet:/data/raddet") is None  # a real source: its whole split
