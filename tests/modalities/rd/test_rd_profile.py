"""The profiler and the training benchmark on range-Doppler models (the YOLO-RD family): sizes per
stage (backbone / adapter / neck / head) from shapes only, the BN-folded count the paper prints,
ultralytics' published GFLOPs, stages that compose to the whole network, the RD train batches and
the tables. Timings are printed by the commands, never asserted."""

import json
import re

import jax
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.data.rd.representations import RDRepresentation
from dsfec_jax.profile import compare, counting, latency, op_breakdown, training, zoo_table
from dsfec_jax.modalities.rd import profile as rd, train_bench as training_rd
from dsfec_jax.modalities.registry import modality_of
from dsfec_jax.profile.records import profile, size_record

TINY_HW = (64, 32)


@pytest.fixture(scope="module")
def adapter_record():
    return size_record(zoo.create("yolov8n_adapter"), modality_of("yolov8n_adapter"), xla=False)


def test_rd_stages_are_the_networks_parts(adapter_record):
    r = adapter_record
    assert r["input"] == {"heat": [1, 256, 64, 3], "gray": [1, 256, 64, 1]}  # the real input size
    assert set(r["params_per_stage"]) == set(r["gflops_per_stage"]) == {"backbone", "adapter", "neck", "head"}
    assert sum(r["params_per_stage"].values()) == r["params"] == 3_248_056  # tests/models/test_yolo_rd.py's pin
    assert r["params_per_stage"]["adapter"] == 3_248_056 - 3_012_002  # YOLOv8n's count
    assert sum(r["gflops_per_stage"].values()) == pytest.approx(r["gflops"], abs=1e-3)
    assert r["memory_mb"] is None and "no memory figure" in r["memory_convention"]


def test_first_conv_by_hand():
    """YOLOv8n layer 0: 3x3 stride-2 conv, 3 -> 16 channels, 256 x 64 -> 128 x 32."""
    rows = counting.layer_macs(zoo.create("yolov8n"))
    first = [m for path, _, m in rows if path[:2] == ("backbone", "layer0")]
    assert first == [128 * 32 * 9 * 3 * 16]


def test_bn_folded_counts_are_the_papers(adapter_record):
    """paper.py: YOLOv8n 3,006,802 (3.01), YOLOv8n-Adapter about 3.242 M (3.24); the v9t / v10n rules
    (RepConvN, RepVGGDW) are pinned against Table 4 in tests/models/test_yolo_rd_v9_v10.py."""
    assert adapter_record["params_folded"] == 3_241_712
    shapes = jax.eval_shape(zoo.create("yolov9t").init, jax.random.key(0))
    assert rd.folded_params(shapes["params"]) == 1_971_938  # Table 4: 1.97
    rows = compare.rd_rows([adapter_record, {"model": "yolov8n", "params_folded": 3_006_802}])
    assert [(r["config"], round(r["ours"], 2), r["paper"]) for r in rows] == [
        ("yolov8n_adapter", 3.24, 3.24), ("yolov8n", 3.01, 3.01)]


def test_gflops_at_ultralytics_setting_match_its_published_table():
    """ultralytics' YOLOv8 table (640 x 640, nc 80, thop MACs x 2): n 8.7, s 28.6 GFLOPs."""
    assert round(rd.ultralytics_gflops("yolov8n")["total"], 1) == 8.7
    assert round(rd.ultralytics_gflops("yolov8s")["total"], 1) == 28.6


class TinyMaps(zoo.Detector):
    """A zoo detector whose dummy inputs are 64 x 32 maps: the profiler's path, quick to compile."""

    def dummy_inputs(self, batch_size=1, seed=0, occupancy=None):
        return self.config.dummy_inputs(batch_size, seed, hw=TINY_HW)


def test_profile_record_with_latency_stages_that_compose_to_the_network(monkeypatch):
    """YOLOv10n-Adapter (Adapter inside `features`, a dict of two heads' maps): the stages the
    profile timed run on each other's outputs and end where the whole network does."""
    timed = []
    stage_functions = latency.stage_functions
    monkeypatch.setattr(latency, "stage_functions", lambda *a, **k: timed.append(stage_functions(*a, **k)) or timed[-1])
    rec = profile([TinyMaps(zoo.config("yolov10n_adapter"))], timing=True, repeats=2, warmup=1, modality_of=modality_of)[0]
    assert list(rec["latency_per_stage_ms"]) == list(rd.LATENCY_STAGES)
    assert rec["latency_ms"] > 0 and rec["xla_gflops"] > 0 and rec["latency_setup"]["depthwise_impl"] is None
    whole, staged = timed[0]["total"](), timed[0]["head"]()
    assert set(staged) == {"one2many", "one2one"}
    for a, b in zip(jax.tree.leaves(whole), jax.tree.leaves(staged)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-4, atol=1e-4)


def test_zoo_table_puts_rd_records_in_their_own_table(adapter_record, tmp_path):
    points = json.loads(modality_of("dsfec_s").zoo_table.record.read_text())
    only_points = zoo_table.markdown(points, modality_of)
    mixed_payload = {**points, "records": points["records"] + [adapter_record]}
    assert "| yolov8n_adapter |" not in only_points and "Range-Doppler" not in only_points
    assert zoo_table.markdown(mixed_payload, modality_of).startswith(only_points + "\n\n| model | mAP@50 |")
    rd_table = zoo_table.markdown({**points, "records": [adapter_record]}, modality_of)
    # the two mAP cells come from the shipped weights' manifest ('-' without weights)
    sizes = "| 3.248 M | 3.242 M | 0.649 | 0.126 / 0.326 / 0.079 / 0.119 | - | - |"
    assert re.search(r"\| yolov8n_adapter \| [-0-9.]+ \| [-0-9.]+ " + re.escape(sizes), rd_table), rd_table
    (start, end), (rd_start, rd_end) = modality_of("dsfec_s").zoo_table.markers, modality_of("yolov8n").zoo_table.markers
    readme = tmp_path / "README.md"
    readme.write_text(f"{start}\nold\n{end}\n")
    with pytest.raises(ValueError, match="zoo-rd-table"):  # never writes RD rows into the point table
        zoo_table.update_readme(readme, mixed_payload, modality_of)
    readme.write_text(f"{start}\nold\n{end}\n{rd_start}\nold\n{rd_end}\n")
    zoo_table.update_readme(readme, mixed_payload, modality_of)
    text = readme.read_text()
    assert "\nold\n" not in text and text.count("| yolov8n_adapter |") == 1
    assert text.index("| dsfec_s |") < text.index(end) < text.index("| yolov8n_adapter |")


# ---- training benchmark ---------------------------------------------------------------------------

SETTINGS = training.Settings(batch=2, repeats=1, warmup=0, distinct_batches=2, profile_steps=1)


def test_rd_train_batches_are_made_as_training_makes_them(monkeypatch):
    monkeypatch.setattr(training_rd, "REPRESENTATION", RDRepresentation(fit="resize", input_hw=TINY_HW))
    det, batches, windows = modality_of("yolov8n_adapter").train_bench_batches("yolov8n_adapter", {}, SETTINGS)
    assert det.name == "yolov8n_adapter" and windows == 1 and len(batches) == SETTINGS.distinct_batches
    b = batches[0]
    assert {k: v.shape for k, v in b["inputs"].items()} == {"heat": (2, *TINY_HW, 3), "gray": (2, *TINY_HW, 1)}
    assert set(b["targets"]) == {"gt_boxes", "gt_labels", "gt_mask"} and b["targets"]["gt_mask"].any()
    assert not np.array_equal(b["inputs"]["heat"], batches[1]["inputs"]["heat"])  # distinct samples
    forward = training.analytic_forward_gflops(det, b["inputs"])
    assert forward == pytest.approx(2 * counting.count_gflops(det, det.config.dummy_inputs(1, hw=TINY_HW))["total"])


def test_point_settings_do_not_apply_to_rd_models():
    assert training.model_overrides("yolov8n", SETTINGS, modality_of("yolov8n")) == {}
    assert training.model_overrides("dsfec_s", SETTINGS, modality_of("dsfec_s")) == {"max_pillars": SETTINGS.max_pillars}
    training.check_models(["dsfec_s", "yolov8n", "yolov10n_adapter"], SETTINGS, None, modality_of)
    training.check_models(["yolov8n_adapter"], SETTINGS, {"fusion": 2}, modality_of)
    with pytest.raises(ValueError, match="max_pillars"):  # an RD config has no pillar slots to compare
        training.check_models(["yolov8n"], SETTINGS, {"max_pillars": 64}, modality_of)
    assert zoo.family_of("yolov8n").schedules[training.STEP_SCHEDULE] == "yolo_quick"


def fake_record(model: str, inputs: dict) -> dict:
    """A bench record of the layout `measure` writes (figures made up: markdown only reads them)."""
    times = {p: {"median": 10.0 * (i + 1), "p10": 1.0, "p90": 1.0, "n": 1} for i, p in enumerate(training.PROGRAMS)}
    per_program = {p: 1.0 for p in training.PROGRAMS}
    config = {"label": "default", "overrides": {}, "input": inputs, "times_ms": times,
              "compile_s": dict(per_program), "frames_per_s": 200.0, "fwd_bwd_over_eval": 3.0, "step_over_fwd_bwd": 1.3,
              "gflops": {"analytic": dict(per_program), "xla": dict(per_program)},
              "gflop_per_s": {"analytic": dict(per_program), "xla": dict(per_program)},
              "percent_of_peak": {"analytic": dict(per_program), "xla": dict(per_program)}}
    return {"model": model, "family": zoo.family_of(model).name, "threads": 2, "windows": 1,
            "sgemm": {"by_reference_gflop_per_s": {"xla": 100.0, "numpy": 90.0}}, "configs": [config],
            "comparison": None, "environment": {"cpu": "test", "versions": {"jax": "x"}}}


def test_bench_table_says_what_differs_for_rd_models():
    rd_rec = fake_record("yolov8n", {"heat": [8, 256, 64, 3], "gray": [8, 256, 64, 1]})
    content = training.payload("dsfec bench --train", [rd_rec], SETTINGS, None)
    table = training.markdown(content, modality_of=modality_of)
    assert "| yolov8n | default | 2 | - | 200.00 |" in table
    assert "Range-Doppler models (yolov8n): batch 2 whole 256 x 64 RD maps" in table
    assert "Record: `dsfec_jax/profile/records/train_bench.json`" in table
    # one model at two thread counts is named once; the record is the file --out wrote
    two = training.payload("x", [rd_rec, {**rd_rec, "threads": 1}], SETTINGS, None)
    table = training.markdown(two, record="/tmp/elsewhere/rd.json", modality_of=modality_of)
    assert "Range-Doppler models (yolov8n): batch" in table and "Record: `/tmp/elsewhere/rd.json`" in table
    in_repo = training.RECORD.parent / "train_bench_rd.json"
    assert "Record: `dsfec_jax/profile/records/train_bench_rd.json`" in training.markdown(two, record=in_repo, modality_of=modality_of)
    point_rec = fake_record("dsfec_s", {"points": [8, 96, 8, 7]})
    assert "Range-Doppler" not in training.markdown(training.payload("x", [point_rec], SETTINGS, None), modality_of=modality_of)


@pytest.mark.parametrize("op_name, expected", [
    # the Adapter's Exchangers run inside the backbone's loop: their time is the Adapter's, not the backbone's
    ("jit(step)/transpose(jvp(YoloRDNet))/YoloRDNet.features/backbone/adapter.exchange/exchangers_6/project/conv/dot_general",
     ("bwd", "adapter.exchange/exchangers_6")),
    ("jit(step)/jvp(YoloRDNet)/YoloRDNet.features/backbone/layer4/m0/cv1/conv/conv_general_dilated",
     ("fwd", "YoloRDNet.features/backbone")),
    ("jit(step)/jvp(YoloRDNet)/YoloRDNet.features/adapter/stem/conv2/conv/conv_general_dilated",
     ("fwd", "YoloRDNet.features/adapter")),
])
def test_breakdown_gives_the_adapters_hook_its_own_module(op_name, expected):
    assert op_breakdown.phase_and_module(op_name) == expected
