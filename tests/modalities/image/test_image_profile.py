"""The profiler on camera models (modality 'image'): sizes per stage (backbone / head) from shapes only,
the paper's memory formula as the record's memory, latency stages that compose to the whole network,
and their own zoo table between their own README markers. Timings are never asserted."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.models.camera.footprint import paper_memory_mib
from dsfec_jax.modalities.image import profile as camera_profile
from dsfec_jax.modalities.registry import MODALITIES, modality_of
from dsfec_jax.profile import latency, zoo_table
from dsfec_jax.profile.records import profile, size_record

TINY = dict(widths=(16, 16, 32, 32, 64), repeats=(1, 1, 1, 1, 1), head_widths=(16, 32, 64), head_units=1)


@pytest.fixture(scope="module")
def shuffle_record():
    return size_record(zoo.create("shuffle_yolov3"), modality_of("shuffle_yolov3"), xla=False)


def test_camera_record_sizes(shuffle_record):
    r = shuffle_record
    assert r["family"] == "camera" and r["input"] == {"image": [1, 416, 416, 3]}
    assert set(r["params_per_stage"]) == set(r["gflops_per_stage"]) == {"backbone", "head"}
    assert r["params"] == sum(r["params_per_stage"].values()) == 1_660_353  # tests/models/camera's pin
    assert r["gflops"] == pytest.approx(3.6404, abs=1e-3)  # 2 x 1,820,192,192 MACs (footprint.py)
    assert r["memory_mb"] == pytest.approx(paper_memory_mib(zoo.config("shuffle_yolov3")), abs=1e-3)
    assert "Sec. 3.4" in r["memory_convention"] and "params_folded" not in r


class TinyImages(zoo.Detector):
    """A zoo camera detector profiled on 64 x 64 images: the profiler's path, quick to compile."""

    def dummy_inputs(self, batch_size=1, seed=0, occupancy=None):
        return self.config.dummy_inputs(batch_size, seed, hw=(64, 64))


def test_latency_stages_compose_to_the_network():
    """features, then the head on them, end where the whole network does; the record times them."""
    det = TinyImages(zoo.config("shuffle_yolov3", **TINY))
    calls = latency.stage_functions(det, latency.timing_variables(det), det.dummy_inputs(1),
                                    modality_of(det.config).latency_stages)
    assert list(calls) == ["total", *camera_profile.LATENCY_STAGES]
    outputs = [np.asarray(o) for o in calls["total"]()]
    assert [o.shape for o in outputs] == [(1, 64 // s, 64 // s, 3, 25) for s in (8, 16, 32)]
    for whole, staged in zip(outputs, calls["head"]()):
        np.testing.assert_allclose(whole, np.asarray(staged), rtol=1e-4, atol=1e-4)
    record = profile([det], timing=True, repeats=1, warmup=0, light=True, modality_of=modality_of)[0]
    assert record["latency_ms"] > 0 and record["family"] == "camera"


def test_zoo_table_puts_camera_records_in_their_own_table(shuffle_record, tmp_path):
    points = json.loads(modality_of("dsfec_s").zoo_table.record.read_text())
    mixed = {**points, "records": points["records"] + [shuffle_record]}
    table = zoo_table.markdown({**points, "records": [shuffle_record]}, modality_of)
    shipped = json.loads((zoo.shipped_weights("shuffle_yolov3").with_suffix(".msgpack.json")).read_text())
    test = shipped["measured"]["test"]  # the mAP columns come from the shipped weights' manifest
    assert table.startswith("| model | VOC07 mAP@0.5 |")
    assert f"| shuffle_yolov3 | {test['mAP50']:.1f} | {test['coco_mAP50_95']:.1f} | 1.660 M | 3.64 |" in table
    assert "zoo_camera.json" in table and "Sec. 3.4" in table
    readme = tmp_path / "README.md"
    blocks = {m: f"{start}\nold {m}\n{end}\n" for m, (start, end) in ((m.name, m.zoo_table.markers) for m in MODALITIES.values())}
    readme.write_text(blocks["points"])
    with pytest.raises(ValueError, match="zoo-camera-table"):  # never writes camera rows into the point table
        zoo_table.update_readme(readme, mixed, modality_of)
    readme.write_text("".join(blocks.values()))
    zoo_table.update_readme(readme, mixed, modality_of)
    text = readme.read_text()
    assert "old rd" in text and "old points" not in text and "old image" not in text  # no RD records: untouched
    start, end = modality_of("shuffle_yolov3").zoo_table.markers
    camera = text[text.index(start):text.index(end)]
    assert camera.count("| shuffle_yolov3 |") == 1 and "| dsfec_s |" not in camera
