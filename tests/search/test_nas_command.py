"""`python -m search.nas` end to end on the smoke profile: supernet, constrained search, reports."""

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
                 "--no-progress", "--register", "smoke_search"]) == 0
    records = [json.loads(line) for line in (run_dir / "journal.jsonl").read_text().splitlines()]
    assert len(records) == len({r["key"] for r in records}) >= 6
    assert all(r["costs"]["params"] <= 2.0e6 and 0 <= r["mAP50"] <= 100 and len(from_key(r["key"])) == 18 for r in records)
    state = json.loads((run_dir / "evolution.json").read_text())
    assert len(state["generations"]) == 2 and state["limits"] == {"params": 2.0e6}
    report = (run_dir / "report.md").read_text()
    assert "2,293,235,712 subnets" in report and "| 1 |" in report and "python -m search.nas" in report
    assert (run_dir / "pareto_params.png").stat().st_size > 1000 and (run_dir / "pareto_gflops.png").exists()
    assert (run_dir / "supernet" / "checkpoints").is_dir()
    best = min(records, key=lambda r: (-r["mAP50"], r["key"]))
    cfg = searched_variants(searched)["smoke_search"]
    assert cfg.name == "smoke_search" and cfg.backbone_width_ratios == tuple(best["choices"][f"backbone{b}"] for b in range(1, 6))


def test_nas_command_refuses_a_space_without_a_supernet(tmp_path):
    with pytest.raises(NotImplementedError, match="dsfec.*supernet is not built"):
        main(["--space", "dsfec", "--profile", "smoke", "--run-dir", str(tmp_path)])


def test_a_latency_limit_without_a_table_fails_before_training(tmp_path):
    with pytest.raises(FileNotFoundError, match="python -m search.nas.latency --space yolov8n_adapter"):
        main(["--space", "yolov8n_adapter", "--profile", "smoke", "--max-latency-ms", "10",
              "--latency-table", str(tmp_path / "none.json"), "--run-dir", str(tmp_path / "run")])
    assert not (tmp_path / "run").exists()
