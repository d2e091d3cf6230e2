"""`python -m search.nas` end to end on the smoke profile: supernet, constrained search, reports,
stand-alone retraining of two subnets with the ranking study, registration of the best stand-alone."""

from __future__ import annotations

import json

import pytest

from search.nas.__main__ import main
from search.nas.space import from_key


def test_nas_command_runs_end_to_end(tmp_path, monkeypatch):
    from dsfec_jax.models.yolo_rd.variants import searched_variants
    import search.nas.register

    run_dir, searched = tmp_path / "nas", tmp_path / "searched.json"
    monkeypatch.setattr(search.nas.register, "SEARCHED", searched)  # never the package's own file
    assert main(["--space", "yolov8n_adapter", "--profile", "smoke", "--max-params", "2.0e6", "--run-dir", str(run_dir),
                 "--no-progress", "--register", "smoke_search", "--standalone", "1", "--spread", "1"]) == 0
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
    assert study["n"] == 2 and study["pairs"][0]["key"] == top["key"] and study["best_inherited"] == top["key"]
    trained = [json.loads(line) for line in (run_dir / "standalone" / "journal.jsonl").read_text().splitlines()]
    assert sorted(r["label"] for r in trained) == sorted(p["key"] for p in study["pairs"])
    assert all(r["status"] == "ok" and r["overrides"]["backbone_width_ratios"] for r in trained)
    assert "## Stand-alone retraining and the ranking study" in report and top["key"] in report
    assert ("Kendall tau between inherited and stand-alone mAP50 over 2 subnets" in report) == (study["tau"] is not None)
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


def test_nas_command_refuses_a_space_without_a_supernet(tmp_path):
    with pytest.raises(NotImplementedError, match="dsfec.*supernet is not built"):
        main(["--space", "dsfec", "--profile", "smoke", "--run-dir", str(tmp_path)])


def test_a_latency_limit_without_a_table_fails_before_training(tmp_path):
    with pytest.raises(FileNotFoundError, match="python -m search.nas.latency --space yolov8n_adapter"):
        main(["--space", "yolov8n_adapter", "--profile", "smoke", "--max-latency-ms", "10",
              "--latency-table", str(tmp_path / "none.json"), "--run-dir", str(tmp_path / "run")])
    assert not (tmp_path / "run").exists()
