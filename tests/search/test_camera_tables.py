"""The Shuffle-YOLOv3 paper-layout tables (experiments/camera_tables.py): cells from made-up records
(ratios, '-' where a figure is missing, the paper's constants beside ours), the command's files and
its errors naming the file, and one real evaluation of a tiny random Shuffle-YOLOv3 through
`dsfec eval` on two street frames and two real VOC images at 64 px."""

from __future__ import annotations

import json

import jax
import pytest
from conftest import shared_data_dir

from dsfec_jax import zoo
from dsfec_jax.core import checkpoint
from experiments import camera_tables as tables

STREET = ("car", "truck", "bus", "pedestrian", "cyclist")
TINY = {"widths": (16, 16, 32, 32, 64), "repeats": (1, 1, 1, 1, 1), "head_widths": (16, 32, 64), "head_units": 1}
FAKE_FP = {  # footprint() figures, made up: size_mb and the paper-formula MB
    "yolov3_darknet53": {"params": 50_000_000, "size_mb": 200.0, "paper_memory_mb": {"all_total_bytes": 400.0, "conv_total_bytes": 300.0,
                                                                "param_bytes": 200.0, "all_output_bytes": 200.0}},
    "shuffle_yolov3": {"params": 2_500_000, "size_mb": 10.0, "paper_memory_mb": {"all_total_bytes": 100.0, "conv_total_bytes": 60.0,
                                                             "param_bytes": 10.0, "all_output_bytes": 90.0}},
}


def lat(model, ms, threads=1, runtime="jax"):
    return {(model, runtime, threads): {"model": model, "runtime": runtime, "threads": threads, "ms": ms,
                                        "cpu": "Test CPU", "source": "profile fake.json"}}


def row(table: dict, label: str) -> list[str]:
    return next(r for r in table["rows"] if r[0] == label)


def test_cells_put_ours_beside_the_paper_with_ratios_and_dashes():
    latency = {**lat("yolov3_darknet53", 800.0), **lat("shuffle_yolov3", 100.0), **lat("shuffle_yolov3", 60.0, 2)}
    street = {"mAP50": 40.0, "frames": 200, "source": "--eval s.json"}
    evals = {("shuffle_yolov3", "street"): street,
             ("shuffle_yolov3", "voc"): {"mAP50": 12.5, "mAP50_all": 13.25, "frames": 100, "source": "--eval v.json",
                                         "classes_scored": ["car", "bus", "person", "bicycle"],
                                         "AP50": {"car": 20.0, "person": 5.0}}}
    finetune = {"model": "shuffle_yolov3", "mAP50": 55.0, "mAP50_all": 56.0, "frames": 100, "source": "--finetune-eval f"}
    t = tables.build(FAKE_FP, evals, latency, {}, finetune)

    t2 = t["table2"]
    assert row(t2, "YOLOv3") == ["YOLOv3", "Darknet-53", "416x416 (416x416)", "200.0 (243)", "- (71.8)", "1.25 (1.25)"]
    assert row(t2, "Shuffle-YOLOv3")[3:] == ["10.0 (45.5)", "40.0 (70.8)", "10.00 (4)"]
    assert row(t2, "Shuffle / YOLOv3")[3:] == ["5.0% (18.7%)", "- (-1.0)", "8.00x (3.20x)"]
    assert any("YOLOv3 mAP: '-'" in n for n in t2["notes"])  # the missing darknet figure is explained

    t4 = t["table4"]
    assert t4["header"][-2:] == ["ours, jax, 1 thread", "ours, jax, 2 threads"]
    assert row(t4, "YOLOv3")[1:] == ["1500", "800", "33", "800.0", "-"]  # no 2-thread darknet record
    assert row(t4, "Shuffle-YOLOv3")[-2:] == ["100.0", "60.0"]
    assert row(t4, "Darknet53 / Shuffle") == ["Darknet53 / Shuffle", "3.00x", "3.20x", "1.98x", "8.00x", "-"]

    t3 = t["table3"]
    assert row(t3, "Shuffle-YOLOv3")[3:6] == ["81.8 (07+12)", "82.6 (07+12)", "52.0"]  # the paper's row
    assert row(t3, "YOLOv3")[3:5] == ["-", "85.5 (07+12+coco*)"]
    ours = row(t3, "Shuffle-YOLOv3 (ours, street-trained)")
    assert ours[3:] == ["12.5 (all-pt 13.2)", "-", "-", "100 images: car, bus, person, bicycle", "car 20.0, person 5.0"]
    assert row(t3, "Shuffle-YOLOv3 (ours, fine-tuned)")[3] == "55.0 (all-pt 56.0)"
    assert not any(r[0].startswith("YOLOv3 (ours") for r in t3["rows"])  # no darknet eval: no row

    mem = t["memory"]
    assert row(mem, "Shuffle-YOLOv3")[1] == "100.0 (220)" and row(mem, "YOLOv3")[1] == "400.0 (450.8, implied)"
    assert row(mem, "Shuffle / YOLOv3")[1:3] == ["25.0% (48.8%)", "20.0%"]


def test_without_evaluations_the_ours_cells_are_dashes_with_a_reason():
    t = tables.build(FAKE_FP, {}, {}, {}, None)
    assert row(t["table3"], "Shuffle-YOLOv3 (ours, street-trained)")[3] == "-"
    assert row(t["table4"], "Darknet53 / Shuffle")[-2:] == ["-", "-"]
    assert any("no VOC evaluation" in n for n in t["table3"]["notes"])
    assert any("no 1-thread JAX latency record" in n for n in t["table2"]["notes"])


@pytest.fixture
def fake_footprint(monkeypatch):
    monkeypatch.setattr(tables, "footprint", lambda cfg: FAKE_FP[cfg.name])


def test_command_writes_markdown_and_a_provenance_record(tmp_path, capsys, monkeypatch, fake_footprint):
    bench = tmp_path / "bench.json"
    bench.write_text(json.dumps({"command": "dsfec bench", "records": [
        {"model": m, "runtime": "jax", "threads": 2, "total_ms": ms, "cpu": "Bench CPU"}
        for m, ms in (("yolov3_darknet53", 500.0), ("shuffle_yolov3", 50.0))]}))
    street_eval = tmp_path / "darknet_street.json"  # `dsfec eval --json` of a darknet run
    street_eval.write_text(json.dumps({"model": "yolov3_darknet53", "data": "street", "frames": 50, "mAP50": 50.0}))
    shipped = tmp_path / "weights" / "shuffle_yolov3.msgpack"  # shipped weights: the manifest's test figure
    shipped.parent.mkdir()
    shipped.write_bytes(b"x" * 2_000_000)
    (tmp_path / "weights" / "shuffle_yolov3.msgpack.json").write_text(
        json.dumps({"measured": {"test": {"mAP50": 33.3, "frames": 200, "data": "street"}}}))
    monkeypatch.setattr(zoo, "shipped_weights", lambda m: tmp_path / "weights" / f"{m}.msgpack")
    finetune = tmp_path / "finetune.json"  # experiments.camera_voc_finetune's record: its fine-tuned row
    finetune.write_text(json.dumps({"rows": [
        {"row": "zero-shot (street weights)", "scores": {"mAP50": 1.0, "images": 50}},
        {"row": "fine-tuned 150 steps on the 50 tune images",
         "scores": {"mAP50": 21.5, "mAP50_all": 22.0, "images": 50, "classes": ["car", "person"], "AP50": {}}}]}))
    profile = tmp_path / "profile.json"  # a 1-thread profile record, not the package's (which re-measuring changes)
    profile.write_text(json.dumps({"command": "python -m dsfec_jax.profile", "records": [
        {"model": m, "latency_ms": ms, "latency_setup": {"threads": 1, "cpu": "Profile CPU"}}
        for m, ms in (("yolov3_darknet53", 772.8), ("shuffle_yolov3", 60.1))]}))
    out = tmp_path / "out"
    assert tables.main(["--out", str(out), "--bench", str(bench), "--no-eval", "--seed", "3", "--profile", str(profile),
                        "--eval", str(street_eval), "--finetune-eval", str(finetune)]) == 0
    printed = capsys.readouterr().out
    assert printed == (out / "camera_tables.md").read_text()
    assert "| Darknet53 / Shuffle | 3.00x | 3.20x | 1.98x | 12.86x | 10.00x |" in printed  # record + bench
    assert "| Shuffle-YOLOv3 | Modified shuffle | 416x416 (416x416) | 10.0 [file 2.0] (45.5) | 33.3 (70.8) |" in printed
    assert "| 5.0% (18.7%) | -16.7 (-1.0) |" in printed
    assert "Shuffle-YOLOv3 mAP: from manifest " in printed and "200 frames" in printed
    assert "| Shuffle-YOLOv3 (ours, fine-tuned) | Modified shuffle | letterboxed | 21.5 (all-pt 22.0) | - | - " \
           "| 50 images: car, person |" in printed
    record = json.loads((out / "camera_tables.json").read_text())
    assert record["command"].startswith("python -m experiments.camera_tables --out ")
    assert record["seed"] == 3 and record["environment"]["versions"]["jax"] == jax.__version__
    assert record["inputs"]["bench"] == [str(bench)]
    assert record["tables"]["table4"]["rows"][-1][-1] == "10.00x"


@pytest.mark.parametrize("flag,content,message", [
    ("--bench", None, "no such file"),
    ("--profile", "{not json", "not JSON"),
    ("--profile", '{"records": [{"latency_ms": 3}]}', "unreadable latency record"),
    ("--eval", '{"model": "shuffle_yolov3"}', "no 'model', 'data' and 'mAP50'"),
    ("--finetune-eval", '{"model": "shuffle_yolov3", "data": "raddet:x", "mAP50": 1}', "expected street or voc"),
    ("--weights", None, "no such file"),
])
def test_bad_inputs_exit_naming_the_file(tmp_path, flag, content, message, fake_footprint):
    path = tmp_path / "input.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(SystemExit) as err:
        tables.main(["--out", str(tmp_path / "out"), flag, str(path), "--no-eval"])
    assert str(path) in str(err.value) and message in str(err.value) and flag in str(err.value)


def test_memory_table_of_the_registered_models():
    """The real footprints: the README's 144.2 MB and 467.1 MB, 30.9 % against the paper's 48.8 %."""
    fp = {m: tables.footprint(zoo.config(m)) for m in tables.MODELS}
    mem = tables.memory_table(fp)
    assert row(mem, "Shuffle-YOLOv3")[1] == "144.2 (220)" and row(mem, "YOLOv3")[1] == "467.1 (450.8, implied)"
    assert row(mem, "Shuffle / YOLOv3")[1] == "30.9% (48.8%)"


def test_real_evaluation_through_dsfec_eval(tmp_path, capsys, fake_footprint):
    """A tiny random Shuffle-YOLOv3 with the street classes: the command evaluates it with `dsfec eval`
    on 2 street test frames and 2 real VOC images and fills Tables 2 and 3 from what it printed."""
    voc = shared_data_dir() / "voc_review_od_metrics" / "data" / "database"
    if not voc.is_dir():
        pytest.skip(f"no VOC sample images at {voc}")
    det = zoo.create("shuffle_yolov3", **TINY, num_classes=5, class_names=STREET)
    variables = det.init(jax.random.key(0))
    weights = tmp_path / "tiny.msgpack"
    checkpoint.save(weights, {"params": variables["params"], "batch_stats": variables["batch_stats"]},
                    {"training": {"overrides": {"num_classes": 5, "class_names": list(STREET)}}})
    sets = [a for k, v in TINY.items() for a in ("--set", f"{k}={v!r}")]
    out = tmp_path / "out"
    assert tables.main(["--out", str(out), "--weights", str(weights), "--frames", "2", "--voc", str(voc),
                        "--voc-frames", "2", "--size", "64", *sets]) == 0
    capsys.readouterr()
    record = json.loads((out / "camera_tables.json").read_text())
    street, real = record["evals"]["shuffle_yolov3/street"], record["evals"]["shuffle_yolov3/voc"]
    assert street["command"].startswith("dsfec eval --model shuffle_yolov3 --weights ") and street["frames"] == 2
    assert street["split"] == "test" and real["classes_scored"] == ["car", "bus", "person", "bicycle"]
    t2, t3 = record["tables"]["table2"], record["tables"]["table3"]
    size_mb = weights.stat().st_size / 1e6
    assert row(t2, "Shuffle-YOLOv3")[3] == f"10.0 [file {size_mb:.1f}] (45.5)"
    assert row(t2, "Shuffle-YOLOv3")[4] == f"{tables.fmt(street['mAP50'], 1)} (70.8)"
    assert row(t3, "Shuffle-YOLOv3 (ours, street-trained)")[6] == "2 images: car, bus, person, bicycle"
