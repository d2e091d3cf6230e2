"""`python -m search.nas` end to end on the smoke profile, for both spaces: supernet, constrained
search, reports, stand-alone retraining with the ranking study (one subnet and the reference for
the YOLO space, two subnets across the ranking and the reference for DSFEC's), registration of the
best stand-alone. Every network starts from uncompiled random weights (conftest.random_init): these
tests are about the command's wiring, and compiling each architecture's `init` is a large part of
each stand-alone trial."""

from __future__ import annotations

import json

import pytest

from search.nas.__main__ import main
from search.nas.space import from_key, key
from search.nas.spaces import get_space


def test_nas_command_runs_end_to_end(tmp_path, monkeypatch, capsys, uncompiled_init):
    from dsfec_jax.models.yolo_rd.variants import searched_variants
    import search.nas.register

    run_dir, searched = tmp_path / "nas", tmp_path / "searched.json"
    monkeypatch.setattr(search.nas.register, "SEARCHED", searched)  # never the package's own file
    assert main(["--space", "yolov8n_adapter", "--profile", "smoke", "--max-params", "2.0e6", "--run-dir", str(run_dir),
                 "--register", "smoke_search", "--standalone", "1",
                 "--record", str(tmp_path / "ranking.json")]) == 0
    err = capsys.readouterr().err  # every long wait says what it is doing, on stderr
    for wait in ("tracing the widths each of yolov8n_adapter's choices sets", "initialising yolov8n_adapter_supernet",
                 "compiling yolov8n_adapter_supernet's training step... (usually", "yolov8n_adapter_supernet: 100%",
                 "generation 1: drawing 6 subnets and tracing their sizes", "compiling the subnet scorer",
                 "scoring subnets", "profiling "):
        assert wait in err, wait
    # one compile serves every subnet of both generations
    assert err.count("compiling the subnet scorer (batch-norm recalibration and the predictor)...") == 1
    records = [json.loads(line) for line in (run_dir / "journal.jsonl").read_text().splitlines()]
    assert len(records) == len({r["key"] for r in records}) >= 6
    assert all(r["costs"]["params"] <= 2.0e6 and 0 <= r["mAP50"] <= 100 and len(from_key(r["key"])) == 18 for r in records)
    state = json.loads((run_dir / "evolution.json").read_text())
    assert len(state["generations"]) == 2 and state["limits"] == {"params": 2.0e6}
    report = (run_dir / "report.md").read_text()
    assert "2,293,235,712 subnets" in report and "| 1 |" in report and "python -m search.nas" in report
    assert (run_dir / "pareto_params.png").stat().st_size > 1000 and (run_dir / "pareto_gflops.png").exists()
    assert (run_dir / "supernet" / "checkpoints").is_dir()
    study = json.loads((run_dir / "ranking.json").read_text())
    top = min(records, key=lambda r: (-r["mAP50"], r["key"]))
    # one subnet (the top) retrained: the ranking across it is the DSFEC test's (--spread)
    assert study["n"] == 1 and study["pairs"][0]["key"] == top["key"] and study["best_inherited"] == top["key"]
    shipped = json.loads((tmp_path / "ranking.json").read_text())  # the record to ship: study + provenance
    assert shipped["ranking"] == study and shipped["seed"] == 0 and "--standalone" in shipped["command"]
    assert shipped["environment"]["versions"]["jax"]
    trained = [json.loads(line) for line in (run_dir / "standalone" / "journal.jsonl").read_text().splitlines()]
    hand = key(get_space("yolov8n_adapter").base_genes())  # over the 2 M limit: trained as the reference only
    assert sorted(r["label"] for r in trained) == sorted([p["key"] for p in study["pairs"]] + [hand])
    assert all(r["status"] == "ok" and r["overrides"]["backbone_width_ratios"] for r in trained)
    assert "## Stand-alone retraining and the ranking study" in report and top["key"] in report
    assert "| yolov8n_adapter (stand-alone, this recipe) |" in report
    assert study["tau"] is None and "1 subnet(s) retrained: too few for a ranking correlation." in report
    best = next(r for r in records if r["key"] == study["best_standalone"])  # registered: the best stand-alone
    cfg = searched_variants(searched)["smoke_search"]
    assert json.loads(searched.read_text())["smoke_search"]["provenance"]["standalone"]["mAP50"] is not None
    # the remedies re-score the study without training; the run's own setting must reproduce its figures
    from search.nas import remedies

    assert remedies.main([str(run_dir), "--profile", "smoke", "--val-samples", "8", "--calibration-batches", "2,4"]) == 0
    rows = json.loads((run_dir / "remedies.json").read_text())["rows"]
    assert [(r["val_samples"], r["calibration_batches"]) for r in rows] == [(8, 2), (8, 4)]
    assert rows[0]["standalone"] == pytest.approx([p["standalone"] for p in study["pairs"]], abs=1e-3)
    assert cfg.name == "smoke_search" and cfg.backbone_width_ratios == tuple(best["choices"][f"backbone{b}"] for b in range(1, 6))


def test_dsfec_space_searches_retrains_and_registers(tmp_path, monkeypatch, capsys, uncompiled_init):
    """The DSFEC width x depth x stem supernet through the same command: searched under a latency
    limit (a table built here from two measured subnets), retrained stand-alone from the base's
    leading channels, registered in the DSFEC family's searched.json."""
    from dsfec_jax.models.dsfec.variants import VARIANTS
    from dsfec_jax.models.searched import searched_variants
    from search.nas.latency import LatencyTable
    import search.nas.register

    space = get_space("dsfec")
    run_dir, searched, table = tmp_path / "nas", tmp_path / "searched.json", tmp_path / "latency.json"
    monkeypatch.setattr(search.nas.register, "DSFEC_SEARCHED", searched)  # never the package's own file
    # a stand-in table (the real one is measured: python -m search.nas.latency --space dsfec): 10 ms,
    # 1 ms less for each step down of any width, stem or depth choice
    LatencyTable("dsfec", 10.0, [[-1.0 * (len(c.options) - 1 - o) for o in range(len(c.options))]
                                 for c in space.choices]).save(table)
    assert main(["--space", "dsfec", "--profile", "smoke", "--max-latency-ms", "2", "--latency-table", str(table),
                 "--run-dir", str(run_dir), "--no-progress", "--register", "dsfec_smoke_search",
                 "--standalone", "1", "--spread", "1"]) == 0
    err = capsys.readouterr().err  # --no-progress: no bar, no stage line (the stand-alone trials' too)
    assert "compiling" not in err and "scoring subnets" not in err and "profiling" not in err
    records = [json.loads(line) for line in (run_dir / "journal.jsonl").read_text().splitlines()]
    assert len(records) >= 6 and all(r["costs"]["latency_ms"] <= 2 and 0 <= r["car_mAP"] <= 100 for r in records)
    run = json.loads((run_dir / "supernet" / "run.json").read_text())
    assert run["init"] == "leading slices of the shipped base" and run["config"]["stage_blocks"] == [3, 3, 3, 3]
    report = (run_dir / "report.md").read_text()
    assert "26,244 subnets" in report and "car_mAP" in report
    trained = [json.loads(line) for line in (run_dir / "standalone" / "journal.jsonl").read_text().splitlines()]
    # two searched subnets and dsfec_m's own architecture (over the 2 ms limit), the same start for all
    assert len(trained) == 3 and all(r["status"] == "ok" and r["init"].startswith("leading:dsfec_m.msgpack@")
                                     for r in trained)
    assert key(space.base_genes()) in {r["label"] for r in trained} and "| dsfec_m (stand-alone, this recipe) |" in report
    study = json.loads((run_dir / "ranking.json").read_text())
    assert study["n"] == 2 and [p["key"] for p in study["pairs"]] == [r["label"] for r in trained[:2]]
    assert ("Kendall tau between inherited and stand-alone car_mAP over 2 subnets" in report) == (study["tau"] is not None)
    cfg = searched_variants(searched, VARIANTS)["dsfec_smoke_search"]
    best = next(r for r in records if r["key"] == study["best_standalone"])
    assert cfg.stage_blocks == tuple(best["choices"][f"stage{s}_blocks"] for s in range(1, 5))
    assert cfg.stem_filters == cfg.fec_filters[-1] == best["choices"]["stem_filters"]


def test_a_latency_limit_without_a_table_fails_before_training(tmp_path):
    with pytest.raises(FileNotFoundError, match="python -m search.nas.latency --space yolov8n_adapter"):
        main(["--space", "yolov8n_adapter", "--profile", "smoke", "--max-latency-ms", "10",
              "--latency-table", str(tmp_path / "none.json"), "--run-dir", str(tmp_path / "run")])
    assert not (tmp_path / "run").exists()
