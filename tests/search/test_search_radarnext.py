"""The search tooling on the RadarNeXt family: the paper's Table II/III axes, a real sweep scored
with the VoD protocol and sized in the fused form, and the refusals that come before training."""

import dataclasses
import json

import jax
import numpy as np
import pytest

from dsfec_jax import zoo
from dsfec_jax.core.grid import Grid
from dsfec_jax.profile import counting
from dsfec_jax.models.radarnext.paper import TABLE2, TABLE3
from dsfec_jax.train.schedules import get_schedule
from experiments import radarnext_table2, radarnext_table3
from search import grid, recipes, trial
from search.journal import Journal
from search.space import candidates, parse_axis

GRID = Grid((0.0, 5.12), (-2.56, 2.56), (-3.0, 2.0), 0.16)  # 32 x 32 cells


def test_table_axes_expand_to_the_papers_rows():
    table2 = candidates("radarnext_mdfen", [parse_axis("neck=fpn,pan,mdfen", "radarnext_mdfen"),
                                            parse_axis("backbone=dense,rep_dwc", "radarnext_mdfen")])
    assert sorted(radarnext_table2.paper_key(c["label"]) for c in table2) == sorted(TABLE2)
    for c in table2:  # each candidate is exactly the registered variant of that name
        variant = zoo.config(radarnext_table2.paper_key(c["label"]))
        ours = zoo.config("radarnext_mdfen", **c["overrides"])
        assert ours == dataclasses.replace(variant, name=ours.name, notes=ours.notes)
    table3 = candidates("radarnext_mdfen", [parse_axis(f"dcn_positions={radarnext_table3.POSITIONS}", "radarnext_mdfen")])
    assert [radarnext_table3.positions(c["label"]) for c in table3] == list(TABLE3)


@pytest.fixture
def tiny_radarnext(monkeypatch):
    """A narrow FPN RadarNeXt on a 32 x 32 grid and a 2-step recipe: a real sweep in seconds."""
    cfg = zoo.config("radarnext_fpn", name="tiny_rnx", grid=GRID, max_pillars=128, layer_nums=(1, 1, 1),
                     channels=(16, 32, 64), fpn_channels=16, head_width=16)
    monkeypatch.setitem(zoo.REGISTRY, "tiny_rnx", cfg)
    recipe = recipes.Recipe("quick", get_schedule("radarnext", steps=2, batch_size=2, warmup_steps=1), 4, 2,
                            None, 128, None, 1, supernet_steps=None, light_profile=True, data="synthetic4d")
    monkeypatch.setitem(recipes.RECIPES["radarnext"], "quick", recipe)
    return "tiny_rnx"


def test_sweep_scores_vod_ap_and_sizes_the_fused_form(tiny_radarnext, tmp_path, capsys):
    out = tmp_path / "run"
    assert grid.main(["--base", tiny_radarnext, "--axis", "backbone=rep_dwc", "--out", str(out),
                      "--base-label", "backbone=rep_dwc"]) == 0  # one trial: each costs ~4 compiles
    records = Journal(out).records()
    assert [r["status"] for r in records] == ["ok"], [r.get("error") for r in records]
    for r in records:
        assert r["data"] == "synthetic4d"
        assert {"mAP", "mAP_corridor", "AP_car", "AP_pedestrian", "AP_bicycle"} <= set(r["metrics"])
        det = zoo.create(tiny_radarnext, **r["overrides"])
        shapes = jax.eval_shape(det.init, jax.random.key(0))
        variables = jax.tree.map(lambda s: np.zeros(s.shape, s.dtype), shapes)
        fused = counting.count_params(zoo.deploy(det, variables, fold_batch_norm=False)[1])["total"]
        assert r["costs"]["params"] == fused
        assert fused < counting.count_params(variables)["total"]  # fusion removed BN-identity/scale branches
    report = (out / "report.md").read_text()
    assert "mAP (VoD 3D)" in report and "Cyclist AP" in report and "Car mAP" not in report
    assert "backbone=rep_dwc (base)" in report
    assert json.loads((out / "search.json").read_text())["data"] == "synthetic4d"
    assert "mAP (VoD 3D)" in capsys.readouterr().out


def test_oneshot_and_unknown_fields_are_refused_before_training(tmp_path, monkeypatch):
    monkeypatch.setattr(trial, "measure", lambda *a: pytest.fail("trained a refused search"))
    with pytest.raises(SystemExit, match="oneshot.*radarnext"):
        grid.main(["--base", "radarnext_fpn", "--axis", "layer_nums=3,5,5|1,5,5", "--strategy", "oneshot",
                   "--out", str(tmp_path / "a")])
    with pytest.raises(SystemExit, match="dcn_positions"):  # DCNv3 on a PAN neck
        grid.main(["--base", "radarnext_pan", "--axis", "dcn_positions=4", "--out", str(tmp_path / "b")])
    assert not (tmp_path / "a" / "journal.jsonl").exists() and not (tmp_path / "b" / "journal.jsonl").exists()


def test_accuracy_record_keeps_each_runs_command_evaluations_and_test(tmp_path, capsys):
    from experiments import radarnext_accuracy

    run = tmp_path / "radarnext_fpn"
    run.mkdir()
    (run / "run.json").write_text(json.dumps({"model": "radarnext_fpn", "command": "dsfec train --model radarnext_fpn",
                                              "seed": 0, "steps": 10, "train_frames": 8, "val_frames": 2,
                                              "versions": {"jax": "x"}, "data": {"source": "synthetic4d"}}))
    evals = [{"step": 5, "eval": {"mAP": 1.0, "mAP_corridor": 2.0, "AP": {"car": 1.0}}},
             {"step": 10, "eval": {"mAP": 3.0, "mAP_corridor": 4.0, "AP": {"car": 3.0}}}]
    (run / "metrics.jsonl").write_text("\n".join(json.dumps(e) for e in [{"step": 1, "loss": 9.0}, *evals]))
    (run / "test.json").write_text(json.dumps({"mAP": 5.0, "mAP_corridor": 6.0, "AP": {"car": 5.0}, "frames": 7}))
    out = tmp_path / "record.json"
    assert radarnext_accuracy.main([str(run), "--out", str(out)]) == 0
    assert "| radarnext_fpn | 10 | 3.00 (4.00) | 5.00 (6.00), 7 frames | car 5.00 |" in capsys.readouterr().out
    record = json.loads(out.read_text())["runs"][0]
    assert [e["step"] for e in record["val"]] == [5, 10] and record["command"].startswith("dsfec train")
    (run / "test.json").write_text("")  # an eval interrupted before it printed
    with pytest.raises(SystemExit, match="test.json: not JSON"):
        radarnext_accuracy.read_run(run)
    (run / "metrics.jsonl").write_text(json.dumps({"step": 3, "eval": {"car_mAP": 1.0}}))
    with pytest.raises(SystemExit, match="line 1: evaluation without 'mAP'"):
        radarnext_accuracy.read_run(run)


def test_accuracy_record_appends_a_run_without_the_older_run_directories(tmp_path, capsys):
    from experiments import radarnext_accuracy

    def make_run(name, test_map):
        run = tmp_path / name
        run.mkdir()
        (run / "run.json").write_text(json.dumps({"model": name, "command": f"dsfec train --model {name}", "seed": 0,
                                                  "steps": 10, "train_frames": 8, "val_frames": 2, "versions": {}}))
        (run / "metrics.jsonl").write_text(json.dumps({"step": 10, "eval": {"mAP": 1.0, "mAP_corridor": 1.0}}))
        (run / "test.json").write_text(json.dumps({"mAP": test_map, "mAP_corridor": 0.0, "AP": {}, "frames": 6}))
        return run

    out = tmp_path / "record.json"
    fpn = make_run("radarnext_fpn", 11.0)
    assert radarnext_accuracy.main([str(fpn), "--out", str(out)]) == 0
    fpn.rename(tmp_path / "gone")  # the older run directory is not needed to append
    mdfen = make_run("radarnext_mdfen", 7.0)
    assert radarnext_accuracy.main([str(mdfen), "--out", str(out), "--append"]) == 0
    assert radarnext_accuracy.main([str(mdfen), "--out", str(out), "--append"]) == 0  # same run again: replaced
    record = json.loads(out.read_text())
    assert [(r["model"], r["test"]["mAP"]) for r in record["runs"]] == [("radarnext_fpn", 11.0), ("radarnext_mdfen", 7.0)]
    assert len(record["commands"]) == 3 and record["commands"][-1].endswith("--append")
    assert "| radarnext_fpn |" in capsys.readouterr().out.splitlines()[-2]
    out.write_text("{}")
    with pytest.raises(SystemExit, match="record.json: cannot append"):
        radarnext_accuracy.main([str(mdfen), "--out", str(out), "--append"])
